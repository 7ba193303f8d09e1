#pragma once
// Private to the vision module: the model editor's rules (issue 7, item 6; paper §4.3) and the world
// geometry they share with verification and the selection: the fixed world (the table's top, the
// other fixed objects' convex parts), boxes' vertices, their penetration of fixed parts, and
// accepted recognitions as occluders of what lies behind them.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "teachsim/geometry/pose.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision::internal {

// A fixed object's convex part in the world, for the separating-axis test.
struct FixedPart {
  std::string name;
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3d> normals, edge_dirs;
};

// The fixed world: the table top's height and the other fixed objects' convex parts.
struct FixedWorld {
  double table_top_z = 0;
  std::vector<FixedPart> parts;
};

// The fixed objects of `fixed_world` (none when it is null); the table is the object named "table".
FixedWorld ReadFixedWorld(const scene::Scene* fixed_world);

// A box's eight vertices in the world, and the lowest one's height (z, m).
std::vector<Eigen::Vector3d> BoxWorldVertices(const Model& model, const geometry::Pose3& world_T_object);
double LowestZ(const Model& model, const geometry::Pose3& world_T_object);

// How deep a box at a pose reaches into a fixed part, and the smallest move out (separating axes:
// the part's face normals, the box's axes and their cross products with the part's edges; with
// horizontal_only the move is in x and y only).
Penetration PartPenetration(const Model& model, const geometry::Pose3& world_T_object, const FixedPart& part,
                            bool horizontal_only);

// An accepted recognition as an occluder of others (the occlusion pass, the editor's polish): its box
// shrunk by this much, so that edges on its own outline and edges touching it are not hidden.
inline constexpr double kOccluderMarginM = 0.001;

// A box that hides what lies behind it, shrunk by a margin so that edges on its own outline and
// edges touching it are not hidden.
struct Occluder {
  geometry::Pose3 box_T_camera;
  Eigen::Vector3d half;  // half the shrunk box's size, m
};

// Nothing when the margin leaves no box.
inline std::optional<Occluder> MakeOccluder(const Model& model, const geometry::Pose3& camera_T_box,
                                            double margin_m) {
  const Eigen::Vector3d half = 0.5 * model.box_size_m - Eigen::Vector3d::Constant(margin_m);
  if ((half.array() <= 0).any()) return std::nullopt;
  return Occluder{camera_T_box.Inverse(), half};
}

// Whether the segment from the camera to a point (camera frame) passes through the occluder's box
// (slab test, in the box's frame). Inline, with HiddenByAny: verification and the occlusion pass ask
// it for every outline sample.
inline bool Hides(const Occluder& o, const Eigen::Vector3d& point_in_camera) {
  const Eigen::Vector3d& origin = o.box_T_camera.translation;
  const Eigen::Vector3d d = o.box_T_camera * point_in_camera - origin;
  double t0 = 0, t1 = 1;
  for (int a = 0; a < 3 && t0 <= t1; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (std::abs(origin[a]) > o.half[a]) return false;
      continue;
    }
    double ta = (-o.half[a] - origin[a]) / d[a], tb = (o.half[a] - origin[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 <= t1;
}

inline bool HiddenByAny(const std::vector<Occluder>& occluders, const Eigen::Vector3d& point_in_camera) {
  for (const Occluder& o : occluders) {
    if (Hides(o, point_in_camera)) return true;
  }
  return false;
}

// 6. The model editor's rules (paper §4.3), each adjustment reported in the recognition's
// adjustments: a recognition near the table is levelled and rested on it along the camera ray, then
// fitted again there to the image's edge points (and, with RecognizerOptions::ladder_search_m, moved
// along a side where its outline shows more edges); interpenetrating recognitions are separated by
// the smallest moves, and pushed out of fixed objects.
void ApplyModelEditorRules(const ModelLibrary& models, const Camera& camera, const LineDetection& detection,
                           const FixedWorld& fixed, const RecognizerOptions& options,
                           std::vector<Recognition>* objects_io);

}  // namespace teachsim::vision::internal
