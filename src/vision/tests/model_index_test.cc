// The model-view index's kd-trees (model_index.cc): built side by side, one per group kind, each is
// the tree that building it alone gives.
#include "model_index.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
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

}  // namespace
}  // namespace teachsim::vision
