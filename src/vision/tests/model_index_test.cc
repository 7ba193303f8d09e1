// The model-view index (model_index.cc): its kd-trees, built side by side, one per group kind, each
// the tree that building it alone gives; a damaged cache file is rebuilt, not trusted.
#include "model_index.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace teachsim::vision {
namespace {

// For random queries near the index's own vectors, each kind's tree in the index finds the same
// neighbours at the same distances, approximate search included, as a tree built on this thread
// from the same vectors.
TEST(ModelIndexTest, EachKindsTreeSearchesAsOneBuiltAlone) {
  const ModelLibrary library{
      {{"cube45", Eigen::Vector3d(0.045, 0.045, 0.045)}, {"bar90", Eigen::Vector3d(0.09, 0.045, 0.045)}}};
  RecognizerOptions options;
  options.view_sphere_samples = 400;
  bool from_cache = true;
  auto index = internal::LoadOrBuildIndex(library, options, "", &from_cache);
  ASSERT_TRUE(index.ok()) << index.status().message();
  EXPECT_FALSE(from_cache);
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0, 0.05f);
  for (int k = 0; k < kGroupKinds; ++k) {
    const cv::Mat& vectors = (*index)->vectors[k];
    ASSERT_GT(vectors.rows, 100) << "kind " << k;
    ASSERT_NE((*index)->trees[k], nullptr) << "kind " << k;
    const KindTree alone(vectors);
    std::uniform_int_distribution<int> row(0, vectors.rows - 1);
    constexpr size_t kNeighbours = 10;
    for (int q = 0; q < 300; ++q) {
      std::vector<float> query(static_cast<size_t>(vectors.cols));
      const float* v = vectors.ptr<float>(row(rng));
      for (size_t d = 0; d < query.size(); ++d) query[d] = v[d] + noise(rng);
      for (const float eps : {0.0f, 1.0f}) {
        const nanoflann::SearchParams search(0, eps);
        std::vector<uint32_t> found[2] = {std::vector<uint32_t>(kNeighbours),
                                          std::vector<uint32_t>(kNeighbours)};
        std::vector<float> d2[2] = {std::vector<float>(kNeighbours), std::vector<float>(kNeighbours)};
        const KdTree* trees[2] = {&(*index)->trees[k]->tree, &alone.tree};
        for (int t = 0; t < 2; ++t) {
          nanoflann::KNNResultSet<float, uint32_t> result(kNeighbours);
          result.init(found[t].data(), d2[t].data());
          trees[t]->findNeighbors(result, query.data(), search);
          ASSERT_EQ(result.size(), kNeighbours);
        }
        ASSERT_EQ(found[0], found[1]) << "kind " << k << ", query " << q << ", eps " << eps;
        ASSERT_EQ(d2[0], d2[1]) << "kind " << k << ", query " << q << ", eps " << eps;
      }
    }
  }
}

// A cache file with the right key whose contents were damaged (an entry naming a model the library
// does not have, a view past the index's, a vertex past a box's eight, two vertices that no box edge
// joins, a NaN in an index vector) is not loaded: the index is built again, and the rebuilt file then
// loads.
TEST(ModelIndexTest, ADamagedCacheFileIsRebuiltNotTrusted) {
  const ModelLibrary library{
      {{"cube45", Eigen::Vector3d(0.045, 0.045, 0.045)}, {"bar90", Eigen::Vector3d(0.09, 0.045, 0.045)}}};
  RecognizerOptions options;
  options.view_sphere_samples = 400;
  const std::string dir = ::testing::TempDir() + "/teachsim-index-damage-test";
  std::filesystem::remove_all(dir);
  bool from_cache = true;
  auto built = internal::LoadOrBuildIndex(library, options, dir, &from_cache);
  ASSERT_TRUE(built.ok()) << built.status().message();
  ASSERT_FALSE(from_cache);
  std::string path;
  for (const auto& file : std::filesystem::directory_iterator(dir)) path = file.path().string();
  ASSERT_FALSE(path.empty());
  std::string original;
  {
    std::ifstream in(path, std::ios::binary);
    original.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // The layout (SaveIndex): magic, key, view count, the views (7 doubles each), then per kind the
  // entry count, the entries, the vectors.
  uint64_t views = 0;
  std::memcpy(&views, original.data() + 16, sizeof(views));
  const size_t entries = 24 + views * 7 * sizeof(double) + sizeof(uint64_t);  // kind 0's first entry
  uint64_t count = 0;
  std::memcpy(&count, original.data() + entries - sizeof(uint64_t), sizeof(count));
  ASSERT_EQ(count, (*built)->entries[0].size());
  const size_t vectors = entries + count * sizeof(IndexEntry);  // kind 0's first vector
  const size_t model = entries + offsetof(IndexEntry, model), view = entries + offsetof(IndexEntry, view),
               vertex = entries + offsetof(IndexEntry, vertices) + 2;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const uint16_t two = 2, far_view = static_cast<uint16_t>(views);
  const uint8_t ninth = 8;
  // The first entry's second vertex made its first: its first segment is then no edge of the box.
  const char first_vertex = original[entries + offsetof(IndexEntry, vertices)];
  const std::vector<std::pair<size_t, std::string>> damages = {
      {model, std::string(reinterpret_cast<const char*>(&two), sizeof(two))},
      {view, std::string(reinterpret_cast<const char*>(&far_view), sizeof(far_view))},
      {vertex, std::string(reinterpret_cast<const char*>(&ninth), sizeof(ninth))},
      {entries + offsetof(IndexEntry, vertices) + 1, std::string(1, first_vertex)},
      {vectors + sizeof(float), std::string(reinterpret_cast<const char*>(&nan), sizeof(nan))}};
  for (const auto& [at, bytes] : damages) {
    std::string damaged = original;
    damaged.replace(at, bytes.size(), bytes);
    {
      std::ofstream out(path, std::ios::binary | std::ios::trunc);
      out.write(damaged.data(), static_cast<std::streamsize>(damaged.size()));
    }
    auto again = internal::LoadOrBuildIndex(library, options, dir, &from_cache);
    ASSERT_TRUE(again.ok()) << again.status().message();
    EXPECT_FALSE(from_cache) << "damage at byte " << at << " was not noticed";
    EXPECT_EQ((*again)->size(), (*built)->size());
    auto reloaded = internal::LoadOrBuildIndex(library, options, dir, &from_cache);
    ASSERT_TRUE(reloaded.ok());
    EXPECT_TRUE(from_cache) << "the rebuilt file did not load";
  }
}

}  // namespace
}  // namespace teachsim::vision
