// `teachsim bench recognize` from the command line: several render seeds pooled into one data set
// (the figures are the sums of the seeds' own), teachsim alone without the peer, the peer compared
// with teachsim on the blocks both found, each method's untimed warm-up, a damaged template cache built
// again, and bad arguments answered with exit
// status 2 and a message naming them. Skipped where the benchmarks are not built (the sanitizer build) or the
// dev set is missing.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "teachsim/base/json.h"
#include "tests/command_run.h"

namespace teachsim::worksite {
namespace {

using testing::CommandRun;
using testing::Teachsim;

class BenchRecognizeCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (Teachsim("bench --list").out.find("recognize") == std::string::npos) {
      GTEST_SKIP() << "the benchmarks are not built here";
    }
    const std::string shared = TEACHSIM_SHARED_DIR;
    if (!std::filesystem::exists(shared + "/data/vision-dev/truth.json"))
      GTEST_SKIP() << shared << " has no dev set";
    cache_ = ::testing::TempDir() + "/bench_recognize_cache";
    ::setenv("TEACHSIM_SHARED", shared.c_str(), 1);
    ::setenv("TEACHSIM_CACHE_DIR", cache_.c_str(), 1);
    ::unsetenv("TEACHSIM_RECOGNIZE_RENDER_SEED");
    ::unsetenv("TEACHSIM_RECOGNIZE_NO_PEER");
  }

  // The JSON document of `bench recognize --quick --json --no-peer ARGS`.
  static json::Json Run(const std::string& args) {
    const CommandRun run = Teachsim("bench recognize --quick --json --no-peer " + args);
    EXPECT_EQ(run.status, 0) << run.err;
    auto document = json::ParseText(run.out, "bench output");
    EXPECT_TRUE(document.ok()) << document.status().message();
    return document.ok() ? *document : json::Json::object();
  }

  std::string cache_;
};

// In one data set's bin: the blocks a shorter model would show alike and the rest (the identifiable)
// add up to the bin's blocks, and what teachsim found of each to what it found; the rest's recall is
// their ratio; teachsim's false detections that are such a shorter model are among its false ones.
void ExpectIdentifiableAddsUp(const json::Json& set, const char* bin) {
  const json::Json& m = set["methods"]["teachsim"];
  const json::Json& rest = m["recall_identifiable"][bin];
  const int explained = set["explained_by_shorter_model_per_bin"][bin].get<int>();
  EXPECT_GE(explained, 0) << bin;
  EXPECT_EQ(rest["objects"].get<int>() + explained, m["recall"][bin]["objects"].get<int>()) << bin;
  EXPECT_EQ(rest["found"].get<int>() + m["found_of_explained_by_shorter"][bin].get<int>(),
            m["recall"][bin]["found"].get<int>())
      << bin;
  EXPECT_LE(m["found_of_explained_by_shorter"][bin].get<int>(), explained) << bin;
  if (rest["objects"].get<int>() > 0) {
    EXPECT_DOUBLE_EQ(rest["recall"].get<double>(),
                     rest["found"].get<double>() / rest["objects"].get<double>())
        << bin;
  } else {
    EXPECT_TRUE(rest["recall"].is_null()) << bin;
  }
  EXPECT_GE(set["teachsim_false_positives_as_shorter_model"].get<int>(), 0);
  EXPECT_LE(set["teachsim_false_positives_as_shorter_model"].get<int>(), m["false_positives"].get<int>());
}

TEST_F(BenchRecognizeCliTest, SeveralRenderSeedsArePooledIntoOneDataSet) {
  const json::Json pooled = Run("--render-seeds 3-4");
  const json::Json three = Run("--render-seeds 3");
  const json::Json four = Run("--render-seeds=4");
  ASSERT_EQ(pooled["data_sets"].size(), 2u);
  EXPECT_EQ(pooled["render_seeds"], json::Json::array({3, 4}));
  EXPECT_EQ(four["render_seeds"], json::Json::array({4, 4}));
  EXPECT_EQ(pooled["peer"], false);
  const json::Json& set = pooled["data_sets"][1];
  const json::Json& a = three["data_sets"][1];
  const json::Json& b = four["data_sets"][1];
  EXPECT_EQ(set["name"], "rendered");
  EXPECT_NE(set["description"].get<std::string>().find("seeds 3-4"), std::string::npos) << set["description"];
  EXPECT_EQ(set["images"].get<int>(), 6);  // 3 per seed with --quick
  EXPECT_EQ(set["images"].get<int>(), a["images"].get<int>() + b["images"].get<int>());
  // Teachsim alone: the peer's methods are not reported (rather than reported as finding nothing).
  EXPECT_TRUE(set["methods"].contains("teachsim"));
  EXPECT_FALSE(set["methods"].contains("linemod"));
  EXPECT_FALSE(set["methods"].contains("linemod_fit"));
  // Every count of the pooled set is the sum of the two seeds' own.
  const json::Json& m = set["methods"]["teachsim"];
  const json::Json& ma = a["methods"]["teachsim"];
  const json::Json& mb = b["methods"]["teachsim"];
  for (const char* bin : {">=0.7", "0.4-0.7", "<0.4"}) {
    for (const char* key : {"objects", "found"}) {
      EXPECT_EQ(m["recall"][bin][key].get<int>(),
                ma["recall"][bin][key].get<int>() + mb["recall"][bin][key].get<int>())
          << bin << " " << key;
    }
  }
  for (const char* key : {"objects", "found"}) {
    EXPECT_EQ(m["recall_unoccluded"][key].get<int>(),
              ma["recall_unoccluded"][key].get<int>() + mb["recall_unoccluded"][key].get<int>())
        << key;
  }
  EXPECT_GT(m["recall"][">=0.7"]["objects"].get<int>(), 0);
  EXPECT_EQ(m["false_positives"].get<int>(),
            ma["false_positives"].get<int>() + mb["false_positives"].get<int>());
  // The false positives by where they stand account for every one of them, pooled as the rest.
  for (const json::Json* s : {&set, &a, &b}) {
    const json::Json& fp = (*s)["teachsim_false_positives"];
    int stages = 0;
    for (const auto& [stage, n] : fp["at_missed_block"].items()) {
      if (stage != "total") stages += n.get<int>();
    }
    EXPECT_EQ(stages, fp["at_missed_block"]["total"].get<int>()) << fp;
    EXPECT_EQ(fp["at_missed_block"]["total"].get<int>() + fp["at_found_block"].get<int>() +
                  fp["at_unscored_block"].get<int>() + fp["elsewhere"].get<int>(),
              (*s)["methods"]["teachsim"]["false_positives"].get<int>())
        << fp;
  }
  EXPECT_EQ(set["teachsim_false_positives"]["elsewhere"].get<int>(),
            a["teachsim_false_positives"]["elsewhere"].get<int>() +
                b["teachsim_false_positives"]["elsewhere"].get<int>());
  // The blocks missed at verification by the occlusion pass's second look account for every one of
  // them, pooled as the rest.
  for (const char* bin : {">=0.7", "0.4-0.7", "<0.4"}) {
    for (const json::Json* s : {&set, &a, &b}) {
      int looks = 0;
      for (const auto& [verdict, n] : (*s)["teachsim_verification_losses"][bin].items())
        looks += n.get<int>();
      const json::Json& lost = (*s)["teachsim_losses"][bin]["verification"];
      EXPECT_EQ(looks, lost["objects"].get<int>() - lost["found"].get<int>()) << bin;
    }
    for (const auto& [verdict, n] : set["teachsim_verification_losses"][bin].items()) {
      EXPECT_EQ(n.get<int>(), a["teachsim_verification_losses"][bin][verdict].get<int>() +
                                  b["teachsim_verification_losses"][bin][verdict].get<int>())
          << bin << " " << verdict;
    }
    // Of them, those cut by the image border: per verdict, no more than it has, pooled the same way.
    for (const json::Json* s : {&set, &a, &b}) {
      for (const auto& [verdict, n] : (*s)["teachsim_verification_losses_at_border"][bin].items()) {
        EXPECT_GE(n.get<int>(), 0) << bin << " " << verdict;
        EXPECT_LE(n.get<int>(), (*s)["teachsim_verification_losses"][bin][verdict].get<int>())
            << bin << " " << verdict;
      }
    }
    for (const auto& [verdict, n] : set["teachsim_verification_losses_at_border"][bin].items()) {
      EXPECT_EQ(n.get<int>(), a["teachsim_verification_losses_at_border"][bin][verdict].get<int>() +
                                  b["teachsim_verification_losses_at_border"][bin][verdict].get<int>())
          << bin << " " << verdict;
    }
    // The blocks a shorter model would show alike and the rest add up to the bin, found and all,
    // pooled as the rest.
    ExpectIdentifiableAddsUp(set, bin);
    ExpectIdentifiableAddsUp(a, bin);
    ExpectIdentifiableAddsUp(b, bin);
    EXPECT_EQ(set["explained_by_shorter_model_per_bin"][bin].get<int>(),
              a["explained_by_shorter_model_per_bin"][bin].get<int>() +
                  b["explained_by_shorter_model_per_bin"][bin].get<int>())
        << bin;
  }
  EXPECT_EQ(set["teachsim_false_positives_as_shorter_model"].get<int>(),
            a["teachsim_false_positives_as_shorter_model"].get<int>() +
                b["teachsim_false_positives_as_shorter_model"].get<int>());
  // Where the time went: every image's stages, and the slowest image named with its seed and its
  // counts (which of the pooled images it was; the times themselves differ from run to run).
  EXPECT_LE(m["images_over_time_goal"].get<int>(), 6);
  EXPECT_EQ(m["time_goal_ms"].get<double>(), 50.0);
  for (const char* stage : {"lines", "groups", "index", "support_hypotheses", "fit_verify", "total"}) {
    ASSERT_TRUE(m["stage_time_ms"].contains(stage)) << stage;
    EXPECT_EQ(m["stage_time_ms"][stage]["count"].get<int>(), 6) << stage;
    EXPECT_LE(m["stage_time_ms"][stage]["mean"].get<double>(),
              m["stage_time_ms"]["total"]["mean"].get<double>());
  }
  const json::Json& slowest = m["slowest_image"];
  ASSERT_TRUE(slowest.is_object()) << slowest;
  EXPECT_EQ(slowest["image"].get<std::string>().rfind("seed", 0), 0u) << slowest;
  EXPECT_DOUBLE_EQ(slowest["ms"].get<double>(), m["time_per_image_ms"]["max"].get<double>());
  EXPECT_GT(slowest["counts"]["lines"].get<int>(), 0) << slowest;
  EXPECT_TRUE(slowest["stage_ms"].contains("fit_verify")) << slowest;
  // The dev set is measured once, whatever the seeds.
  EXPECT_EQ(pooled["data_sets"][0]["methods"]["teachsim"]["recall"],
            three["data_sets"][0]["methods"]["teachsim"]["recall"]);
  // Before any image is timed, teachsim ran twice, untimed, on the dev set's first image; the peer,
  // left out, did not.
  ASSERT_TRUE(pooled["setup"].contains("warmup")) << pooled["setup"];
  const json::Json& warmup = pooled["setup"]["warmup"];
  ASSERT_TRUE(warmup.contains("image") && warmup.contains("teachsim_ms")) << warmup;
  EXPECT_EQ(warmup["image"], "case_000.png") << warmup;
  EXPECT_EQ(warmup["teachsim_ok"], true) << warmup;
  ASSERT_EQ(warmup["teachsim_ms"].size(), 2u) << warmup;
  for (const json::Json& ms : warmup["teachsim_ms"]) EXPECT_GT(ms.get<double>(), 0) << warmup;
  EXPECT_FALSE(warmup.contains("linemod_ms")) << warmup;
  const CommandRun table = Teachsim("bench recognize --quick --no-peer --render-seeds 4");
  ASSERT_EQ(table.status, 0) << table.err;
  EXPECT_NE(table.out.find("warm-up, untimed: teachsim twice on case_000.png first"), std::string::npos)
      << table.out;
}

// With the peer, each of its methods is compared with teachsim on the blocks both found (render seed 4
// has one such block in --quick): the pairs are no more than either found, each figure is counted on
// every pair, and no block is won by both.
TEST_F(BenchRecognizeCliTest, EachPeerIsComparedWithTeachsimOnTheBlocksBothFound) {
  const CommandRun run = Teachsim("bench recognize --quick --json --render-seeds 4");
  ASSERT_EQ(run.status, 0) << run.err;
  auto document = json::ParseText(run.out, "bench output");
  ASSERT_TRUE(document.ok()) << document.status().message();
  EXPECT_EQ((*document)["peer"], true);
  int pairs = 0;
  for (const json::Json& set : (*document)["data_sets"]) {
    const json::Json& methods = set["methods"];
    auto found = [](const json::Json& method) {
      int n = 0;
      for (const auto& [bin, figures] : method["recall"].items()) n += figures["found"].get<int>();
      return n;
    };
    EXPECT_FALSE(methods["teachsim"].contains("paired_with_teachsim"));
    for (const char* peer : {"linemod", "linemod_fit"}) {
      ASSERT_TRUE(methods[peer].contains("paired_with_teachsim")) << set["name"] << " " << peer;
      const json::Json& paired = methods[peer]["paired_with_teachsim"];
      const int objects = paired["objects"].get<int>();
      pairs += objects;
      EXPECT_LE(objects, std::min(found(methods["teachsim"]), found(methods[peer]))) << paired;
      for (const char* side : {"teachsim", "peer"}) {
        EXPECT_EQ(paired[side]["rotation_error_deg"]["count"].get<int>(), objects) << paired;
        EXPECT_EQ(paired[side]["truth_projection_rms_px"]["count"].get<int>(), objects) << paired;
      }
      for (const char* figure : {"rotation_error_deg", "reprojection_rms_px", "truth_projection_rms_px"}) {
        EXPECT_LE(paired["teachsim_smaller"][figure].get<int>() + paired["peer_smaller"][figure].get<int>(),
                  objects)
            << paired;
      }
      // LINE-MOD's raw poses report no residual: none of its pairs has one.
      if (std::string(peer) == "linemod") {
        EXPECT_EQ(paired["peer"]["reprojection_rms_px"]["count"].get<int>(), 0);
      }
    }
  }
  EXPECT_GT(pairs, 0);
  // Both methods ran twice, untimed, before any image was timed.
  ASSERT_TRUE((*document)["setup"].contains("warmup")) << (*document)["setup"];
  const json::Json& warmup = (*document)["setup"]["warmup"];
  ASSERT_TRUE(warmup.contains("teachsim_ms") && warmup.contains("linemod_ms")) << warmup;
  EXPECT_EQ(warmup["teachsim_ms"].size(), 2u) << warmup;
  ASSERT_EQ(warmup["linemod_ms"].size(), 2u) << warmup;
  for (const json::Json& ms : warmup["linemod_ms"]) EXPECT_GT(ms.get<double>(), 0) << warmup;
  // The table names the comparison and the warm-up.
  const CommandRun table = Teachsim("bench recognize --quick --render-seeds 4");
  ASSERT_EQ(table.status, 0) << table.err;
  EXPECT_NE(table.out.find("blocks teachsim and linemod_fit both found"), std::string::npos) << table.out;
  EXPECT_NE(table.out.find("warm-up, untimed: teachsim and LINE-MOD twice on case_000.png first"),
            std::string::npos)
      << table.out;
}

// LINE-MOD's templates come from the cache only when the file holds together: a damaged count of a
// template's features (2^31 - 1, which was once read and allocated as it stood) or a feature's
// orientation label past LINE-MOD's 8 makes the benchmark build the templates again, and the rebuilt
// file then loads.
TEST_F(BenchRecognizeCliTest, ADamagedTemplateCacheIsBuiltAgain) {
  auto setup = [](const std::string& args) {
    const CommandRun run = Teachsim("bench recognize --quick --json --render-seeds 4 " + args);
    EXPECT_EQ(run.status, 0) << run.err;
    auto document = json::ParseText(run.out, "bench output");
    EXPECT_TRUE(document.ok()) << document.status().message();
    return document.ok() ? (*document)["setup"] : json::Json::object();
  };
  setup("");  // the cache made (or already there)
  // The newest template file: the one just used (an older one of another key may lie beside it).
  std::string path;
  std::filesystem::file_time_type newest;
  for (const auto& file : std::filesystem::directory_iterator(cache_)) {
    if (file.path().filename().string().rfind("linemod_", 0) != 0) continue;
    if (path.empty() || file.last_write_time() > newest)
      path = file.path().string(), newest = file.last_write_time();
  }
  ASSERT_FALSE(path.empty()) << "no LINE-MOD template cache in " << cache_;
  auto read = [&] {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  };
  auto u32 = [](const std::string& bytes, std::size_t at) {
    std::uint32_t v = 0;
    std::memcpy(&v, bytes.data() + at, sizeof(v));
    return v;
  };
  // The layout (LinemodPeer::Create): magic (29 bytes), key size, key, class count, then the first
  // class: name size, name, template count; its first template: 10 doubles, the level count, the
  // first level's header (width, height, level, feature count) and its features (x, y, label).
  for (const int damage : {0, 1}) {
    std::string bytes = read();
    std::size_t at = 29;
    at += 4 + u32(bytes, at);  // the key
    at += 4;                   // the class count
    at += 4 + u32(bytes, at);  // the first class's name
    at += 4 + 80 + 4;          // its template count, the first template's numbers and level count
    ASSERT_GT(u32(bytes, at + 12), 0u) << "the first level has no features";
    const std::uint32_t value = damage == 0 ? 0x7fffffffu : 9u;
    std::memcpy(bytes.data() + (damage == 0 ? at + 12 : at + 16 + 8), &value, sizeof(value));
    {
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    }
    EXPECT_FALSE(setup("")["linemod_templates_from_cache"].get<bool>()) << "damage " << damage;
  }
  EXPECT_TRUE(setup("")["linemod_templates_from_cache"].get<bool>());
}

TEST_F(BenchRecognizeCliTest, BadArgumentsAreNamed) {
  struct Bad {
    std::string args, message;
  };
  for (const Bad& bad :
       {Bad{"--render-seeds 5-3", "'5-3' ends before it starts"},
        Bad{"--render-seeds x", "'x' is not a seed"}, Bad{"--render-seeds 3-", "'3-' is not a seed"},
        Bad{"--render-seeds 99999999999", "is not a seed"},
        Bad{"--render-seeds", "--render-seeds needs a value"},
        Bad{"--frobnicate", "unknown argument '--frobnicate'"}}) {
    const CommandRun run = Teachsim("bench recognize --quick --no-peer " + bad.args);
    EXPECT_EQ(run.status, 2) << bad.args;
    EXPECT_NE(run.err.find(bad.message), std::string::npos) << bad.args << ": " << run.err;
    EXPECT_TRUE(run.out.empty()) << bad.args << ": " << run.out;
  }
  ::setenv("TEACHSIM_RECOGNIZE_RENDER_SEED", "seven", 1);
  const CommandRun run = Teachsim("bench recognize --quick --no-peer");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.err.find("TEACHSIM_RECOGNIZE_RENDER_SEED: 'seven'"), std::string::npos) << run.err;
  ::unsetenv("TEACHSIM_RECOGNIZE_RENDER_SEED");
}

}  // namespace
}  // namespace teachsim::worksite
