// teachsim bench demo [--json] [--quick] [--seeds N] [--out DIR] [--which all|cornering|around-corner]:
// `teachsim demo` over seeds 1..N (default 10; --quick: 2), each seed's full report in DIR/seed-N,
// and the sweep's table (verdict per demonstration, recognition errors, wall time per stage) with
// its figure DIR/sweep.png and DIR/sweep.json (issue 9, "Show": 10 seeds out of 10).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "commands.h"
#include "demo_pipeline.h"
#include "demo_plot.h"
#include "teachsim/base/bench_registry.h"
#include "teachsim/worksite/render.h"

namespace teachsim::app {
namespace {

struct SeedRow {
  std::uint64_t seed = 0;
  bool ok = false;                  // the pipeline ran (no bad input)
  std::vector<std::string> verdicts;  // per demonstration: "ok" or "stage N name"
  bool success = false;
  int recognized = 0, truth = 0;
  double max_position_mm = NAN, max_rotation_deg = NAN;
  double stage_s[kDemoStages] = {};  // summed over the demonstrations
  double total_s = 0;
};

int RunDemoBench(const BenchArgs& args) {
  // Bad arguments stop the sweep before its first seed, named (exit status 2).
  const Result<BenchOptions> given =
      ParseBenchOptions("demo", args.extra, {"--seeds", "--out", "--which"}, {});
  if (!given.ok()) return ReportError(given.status());
  auto value = [&](const char* name, const std::string& fallback) {
    const auto it = given->values.find(name);
    return it != given->values.end() ? it->second : fallback;
  };
  const Result<long long> seeds_given =
      ParseBenchCount("--seeds", value("--seeds", args.quick ? "2" : "10"), 1, 1000);
  if (!seeds_given.ok()) return ReportError(seeds_given.status());
  const int seeds = static_cast<int>(*seeds_given);
  const std::string out = value("--out", "demo-sweep"), which = value("--which", "all");
  if (which != "all" && which != "cornering" && which != "around-corner") {
    return ReportError(
        Status::InvalidInput("--which: '" + which + "' is not all, cornering or around-corner"));
  }
  if (out.empty()) return ReportError(Status::InvalidInput("--out: needs a folder"));
  std::vector<SeedRow> rows;
  std::vector<std::string> names;
  for (int s = 1; s <= seeds; ++s) {
    DemoOptions options;
    options.which = which;
    options.scene_path = DataPath("scenes/puzzle.json");
    options.cache_dir = DefaultRecognizerCache();
    options.seed = static_cast<std::uint64_t>(s);
    options.out_dir = (std::filesystem::path(out) / ("seed-" + std::to_string(s))).string();
    options.progress = false;
    SeedRow row;
    row.seed = options.seed;
    auto result = RunDemoPipeline(options);
    if (!result.ok()) {
      std::fprintf(stderr, "seed %d: %s\n", s, result.status().message().c_str());
      rows.push_back(row);
      continue;
    }
    if (Status w = WriteDemoReport(*result); !w.ok()) return ReportError(w);
    row.ok = true;
    row.success = result->success();
    row.total_s = result->total_s;
    row.truth = static_cast<int>(result->world.truth.size());
    for (const DemoTruthObject& t : result->world.truth) row.recognized += t.recognized ? 1 : 0;
    for (const DemoRecognition& r : result->world.recognitions) {
      if (r.position_error_m < 0) continue;
      row.max_position_mm = std::isnan(row.max_position_mm) ? r.position_error_m * 1e3
                                                            : std::max(row.max_position_mm, r.position_error_m * 1e3);
      const double deg = r.rotation_error_rad * 180 / M_PI;
      row.max_rotation_deg = std::isnan(row.max_rotation_deg) ? deg : std::max(row.max_rotation_deg, deg);
    }
    auto add = [&](const std::vector<StageTime>& times) {
      for (const StageTime& t : times) {
        for (int k = 0; k < kDemoStages; ++k) {
          if (t.name == kDemoStageNames[k]) row.stage_s[k] += t.wall_s;
        }
      }
    };
    add(result->world.times);
    names.clear();
    for (const DemoRun& r : result->runs) {
      add(r.times);
      names.push_back(r.name);
      row.verdicts.push_back(r.success ? "verified"
                                       : "failed at " + std::to_string(r.failed_stage) + " " +
                                             kDemoStageNames[r.failed_stage - 1]);
    }
    rows.push_back(row);
    if (!args.json) {
      std::printf("seed %2d: %s (%.1f s)\n", s, row.success ? "SUCCESS" : "FAILED", row.total_s);
      std::fflush(stdout);
    }
  }

  // The table, the figure, the JSON.
  int successes = 0;
  double sum[kDemoStages] = {}, worst[kDemoStages] = {};
  for (const SeedRow& r : rows) {
    successes += r.success ? 1 : 0;
    for (int k = 0; k < kDemoStages; ++k) sum[k] += r.stage_s[k], worst[k] = std::max(worst[k], r.stage_s[k]);
  }
  json::Json doc;
  doc["benchmark"] = "demo";
  doc["seeds"] = seeds;
  doc["successes"] = successes;
  json::Json seed_rows = json::Json::array();
  for (const SeedRow& r : rows) {
    json::Json stages = json::Json::object();
    for (int k = 0; k < kDemoStages; ++k) stages[kDemoStageNames[k]] = r.stage_s[k];
    seed_rows.push_back({{"seed", r.seed},
                         {"success", r.success},
                         {"verdicts", r.verdicts},
                         {"recognized", r.recognized},
                         {"blocks", r.truth},
                         {"max_position_error_mm", std::isnan(r.max_position_mm) ? json::Json() : json::Json(r.max_position_mm)},
                         {"max_rotation_error_deg", std::isnan(r.max_rotation_deg) ? json::Json() : json::Json(r.max_rotation_deg)},
                         {"stage_wall_s", stages},
                         {"total_s", r.total_s}});
  }
  doc["rows"] = seed_rows;
  json::Json mean = json::Json::object(), max = json::Json::object();
  for (int k = 0; k < kDemoStages; ++k) {
    mean[kDemoStageNames[k]] = sum[k] / std::max<std::size_t>(1, rows.size());
    max[kDemoStageNames[k]] = worst[k];
  }
  doc["stage_wall_s_mean"] = mean;
  doc["stage_wall_s_max"] = max;
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (Status s = json::WriteJsonFile((std::filesystem::path(out) / "sweep.json").string(), doc); !s.ok()) {
    return ReportError(s);
  }
  plot::BarChart times;
  times.title = "wall time per stage and seed (both demonstrations)";
  times.y_label = "s";
  times.value_format = "";
  for (int k = 0; k < kDemoStages; ++k) times.series.push_back(kDemoStageNames[k]);
  times.values.assign(kDemoStages, {});
  plot::BarChart errors;
  errors.title = "largest recognition error per seed";
  errors.series = {"position, mm", "rotation, deg"};
  errors.values.assign(2, {});
  for (const SeedRow& r : rows) {
    const std::string label = std::to_string(r.seed) + (r.success ? "" : " X");
    times.categories.push_back(label);
    errors.categories.push_back(label);
    for (int k = 0; k < kDemoStages; ++k) times.values[static_cast<std::size_t>(k)].push_back(r.stage_s[k]);
    errors.values[0].push_back(r.max_position_mm);
    errors.values[1].push_back(r.max_rotation_deg);
  }
  cv::Mat figure = plot::VConcat({plot::DrawBarChart(times, 1000, 340), plot::DrawBarChart(errors, 1000, 300)});
  plot::PutText(figure, "seeds marked X failed; " + std::to_string(successes) + " of " + std::to_string(seeds) +
                            " seeds verified every demonstration",
                cv::Point(12, figure.rows - 8), 0.45, cv::Scalar(0, 0, 0));
  if (Status s = worksite::WritePng((std::filesystem::path(out) / "sweep.png").string(), figure); !s.ok()) {
    return ReportError(s);
  }
  if (args.json) {
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    std::printf("\nseed  ");
    for (const std::string& n : names) std::printf("%-30s", n.c_str());
    std::printf("blocks   pos mm  rot deg");
    for (int k = 0; k < kDemoStages; ++k) std::printf("  %6.6s", kDemoStageNames[k]);
    std::printf("   total s\n");
    for (const SeedRow& r : rows) {
      std::printf("%4llu  ", static_cast<unsigned long long>(r.seed));
      for (std::size_t i = 0; i < names.size(); ++i) {
        std::printf("%-30s", i < r.verdicts.size() ? r.verdicts[i].c_str() : (r.ok ? "" : "bad input"));
      }
      std::printf("%2d/%-2d  %7.1f  %7.2f", r.recognized, r.truth, r.max_position_mm, r.max_rotation_deg);
      for (int k = 0; k < kDemoStages; ++k) std::printf("  %6.2f", r.stage_s[k]);
      std::printf("   %7.1f\n", r.total_s);
    }
    std::printf("mean  %*s", static_cast<int>(30 * names.size() + 23), "");
    for (int k = 0; k < kDemoStages; ++k) std::printf("  %6.2f", sum[k] / std::max<std::size_t>(1, rows.size()));
    std::printf("\n%d of %d seeds verified every demonstration; reports in %s/seed-N, figure %s/sweep.png\n",
                successes, seeds, out.c_str(), out.c_str());
  }
  return successes == seeds ? 0 : 1;
}

TEACHSIM_BENCH("demo",
               "teachsim demo over seeds: verdicts, recognition errors, time per stage ([--seeds N] [--out "
               "DIR] [--which W])",
               RunDemoBench);

}  // namespace
}  // namespace teachsim::app
