#pragma once
// Private to the vision module: the model-view index of the recognizer (issue 7, item 3; Beis &
// Lowe): views sampled over the view sphere, their groups' index vectors in one kd-tree per group
// kind (nanoflann, approximate search), cached on disk per model library; the hypotheses it gives
// an image's groups and the initial pose of each.

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <nanoflann.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

struct IndexEntry {
  uint16_t model = 0;
  uint16_t view = 0;
  uint8_t vertices[5] = {0, 0, 0, 0, 0};  // the group's points as box vertex ids (see Group)
};

// The box edge (index into kBoxEdges) that segment s of an entry of `kind` lies on: a fork's runs
// from its first vertex, a chain's from one vertex to the next. -1 where those two vertices are not
// the ends of one edge (only in a damaged cache file).
int EntrySegmentEdge(const IndexEntry& entry, GroupKind kind, int s);

// One group kind's index vectors (the rows of a CV_32F matrix) as nanoflann reads them.
struct IndexRows {
  cv::Mat rows;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(rows.rows); }
  float kdtree_get_pt(size_t i, size_t d) const { return rows.ptr<float>(static_cast<int>(i))[d]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, IndexRows>, IndexRows,
                                                   -1, uint32_t>;
// A kd-tree over one kind's vectors (the tree keeps a reference to its rows: neither moves).
struct KindTree {
  explicit KindTree(const cv::Mat& vectors)
      : data{vectors}, tree(vectors.cols, data, nanoflann::KDTreeSingleIndexAdaptorParams(kLeafSize)) {
    tree.buildIndex();
  }
  KindTree(const KindTree&) = delete;
  KindTree& operator=(const KindTree&) = delete;
  static constexpr size_t kLeafSize = 10;
  IndexRows data;
  KdTree tree;
};

struct RecognizerIndex {
  std::vector<geometry::Pose3> views;  // camera_T_object of each view
  std::vector<IndexEntry> entries[kGroupKinds];
  cv::Mat vectors[kGroupKinds];  // CV_32F, one row per entry
  std::shared_ptr<const KindTree> trees[kGroupKinds];
  size_t size() const {
    size_t n = 0;
    for (const auto& e : entries) n += e.size();
    return n;
  }
};

namespace internal {

// The index for `library` and the options' view sampling: read from `cache_dir` when a file there was
// built for the same models and sampling and holds together (counts the file can fill, entries
// naming the library's models, the index's views and box vertices joined by box edges; unit view
// rotations, finite numbers), else built (and written there atomically,
// unless `cache_dir` is empty); its kd-trees built. *loaded_from_cache says which.
Result<std::shared_ptr<RecognizerIndex>> LoadOrBuildIndex(const ModelLibrary& library,
                                                          const RecognizerOptions& options,
                                                          const std::string& cache_dir,
                                                          bool* loaded_from_cache);

// A hypothesis: an image group (index into the groups) matched with an index entry of its kind.
struct Hypothesis {
  double probability = 0;
  int group = 0;
  int kind = 0;
  int entry = 0;
};

// 3. indexing: the k nearest model-view vectors of each group; their votes give p(model | group)
// (Beis & Lowe). The hypotheses, most probable first.
std::vector<Hypothesis> IndexHypotheses(const RecognizerIndex& index, const std::vector<Group>& groups,
                                        const std::vector<ImageLine>& lines,
                                        const RecognizerOptions& options);

// The initial pose of a hypothesis: the model view's pose turned and scaled by the 2D similarity
// that maps the view's group onto the image group (weak perspective), then re-aimed at the group.
geometry::Pose3 InitialPose(const RecognizerIndex& index, const Model& model, const IndexEntry& entry,
                            const Group& group, const Eigen::Matrix3d& K);

}  // namespace internal

}  // namespace teachsim::vision
