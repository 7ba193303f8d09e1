// The dragger fixture (paper §5, Figures 7-8), independent of any UI: a box around the workpiece
// with the gripper's pose. Picking a box face and dragging moves the dragger in that face's plane
// (the mouse ray intersected with the plane); the displacement between dragger and workpiece is
// the virtual force f_a = k_a dx (saturated). Rotation handles add a torque, beyond the paper, for
// re-orienting.
#pragma once

#include <optional>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/sim/simulator.h"

namespace teachsim::sim {

struct DraggerOptions {
  double stiffness_n_per_m = 100.0;         // k_a: 10 mm of lag pulls with 1 N
  double max_force_n = 4.0;                 // with d_t = 0.1 m/s/N: the paper's 400 mm/s
  double torque_stiffness_nm_per_rad = 0.02;
  double max_torque_nm = 0.02;
  [[nodiscard]] Status Validate() const;
};

class Dragger {
 public:
  // The dragger box starts on the workpiece (its frame), sized half_extents_m (the box's half sides).
  Dragger(const geometry::Pose3& world_T_workpiece, const Eigen::Vector3d& half_extents_m,
          const DraggerOptions& options = {});

  const geometry::Pose3& world_T_dragger() const { return world_T_dragger_; }
  const Eigen::Vector3d& half_extents() const { return half_extents_; }

  // Face 0..5 is -x, +x, -y, +y, -z, +z of the dragger box. Picking intersects the ray with the
  // box face; false if the ray misses that face's plane (parallel or behind the origin).
  bool Pick(int face, const Eigen::Vector3d& ray_origin, const Eigen::Vector3d& ray_direction);
  // Moves the dragger in the picked face's plane to where the ray meets it; false when nothing is
  // picked or the ray is parallel to the plane.
  bool DragTo(const Eigen::Vector3d& ray_origin, const Eigen::Vector3d& ray_direction);
  void Release() { picked_.reset(); }

  // Scripted input: the dragger's pose directly. `rotate` says whether its orientation pulls.
  void SetPose(const geometry::Pose3& world_T_dragger, bool rotate);
  void Rotate(const Eigen::Vector3d& axis_world, double angle_rad);

  // The virtual force and torque on the workpiece at its current pose.
  StepInput Force(const geometry::Pose3& world_T_workpiece) const;

 private:
  struct Picked {
    Eigen::Vector3d plane_normal;  // world
    Eigen::Vector3d hit0;          // world, where the pick ray met the plane
    Eigen::Vector3d position0;     // dragger position at the pick
  };
  geometry::Pose3 world_T_dragger_;
  Eigen::Vector3d half_extents_;
  DraggerOptions options_;
  std::optional<Picked> picked_;
  bool rotate_ = false;
};

}  // namespace teachsim::sim
