// The calibration features the docs recommend (docs/formats/camera.md), with their 3-D edges, for
// the work-site tests that calibrate from rendered images (calibration_snap_test, cli_test).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "teachsim/geometry/aabb.h"
#include "teachsim/scene/scene.h"

namespace teachsim::worksite::testing {

// The six features docs/formats/camera.md recommends: the table's -x -y top corner, three outer top
// corners of the frame's walls and the two inner top corners on the other diagonal.
struct Feature {
  std::string name;
  std::string object;  // whose corner it is
  Eigen::Vector3d p_in_world;
  std::vector<Eigen::Vector3d> edges_in_world;  // the straight edges leaving the corner (direction x length)
};

inline std::vector<Feature> RecommendedFeatures(const scene::Scene& scene) {
  const scene::SceneObject& table = scene.objects.at(static_cast<std::size_t>(scene.FindObject("table")));
  const scene::SceneObject& frame = scene.objects.at(static_cast<std::size_t>(scene.FindObject("frame")));
  geometry::Aabb walls;
  double wall = 1e9;
  for (const geometry::ShapePart& part : frame.shape.parts()) {
    const geometry::Aabb b = part.convex->WorldBounds(frame.world_T_object * part.shape_T_part);
    if (std::abs(b.min.z()) < 1e-6) {
      walls.Extend(b);
      wall = std::min(wall, (b.max - b.min).minCoeff());
    }
  }
  const geometry::Aabb t = table.shape.WorldBounds(table.world_T_object);
  const Eigen::Vector3d lo = walls.min, hi = walls.max;
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d size = hi - lo, table_size = t.max - t.min;
  const double inner_x = size.x() - 2 * wall, inner_y = size.y() - 2 * wall;
  return {
      {"table corner -x-y",
       "table",
       {t.min.x(), t.min.y(), t.max.z()},
       {x * table_size.x(), y * table_size.y(), -z * table_size.z()}},
      {"outer top +x-y", "frame", {hi.x(), lo.y(), hi.z()}, {-x * size.x(), y * size.y(), -z * size.z()}},
      {"outer top -x+y", "frame", {lo.x(), hi.y(), hi.z()}, {x * size.x(), -y * size.y(), -z * size.z()}},
      {"outer top +x+y", "frame", {hi.x(), hi.y(), hi.z()}, {-x * size.x(), -y * size.y(), -z * size.z()}},
      {"inner top +x-y",
       "frame",
       {hi.x() - wall, lo.y() + wall, hi.z()},
       {-x * inner_x, y * inner_y, -z * size.z()}},
      {"inner top -x+y",
       "frame",
       {lo.x() + wall, hi.y() - wall, hi.z()},
       {x * inner_x, -y * inner_y, -z * size.z()}}};
}

}  // namespace teachsim::worksite::testing
