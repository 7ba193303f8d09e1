#include "teachsim/sim/dragger.h"

#include <cmath>

namespace teachsim::sim {

namespace {
std::optional<Eigen::Vector3d> RayPlane(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                        const Eigen::Vector3d& normal, const Eigen::Vector3d& on_plane) {
  const double denom = normal.dot(direction);
  if (std::abs(denom) < 1e-9 * direction.norm()) return std::nullopt;
  const double t = normal.dot(on_plane - origin) / denom;
  if (!(t > 0.0)) return std::nullopt;
  return origin + t * direction;
}
}  // namespace

Status DraggerOptions::Validate() const {
  for (auto [field, value] : {std::pair{"stiffness_n_per_m", stiffness_n_per_m}, {"max_force_n", max_force_n},
                              {"torque_stiffness_nm_per_rad", torque_stiffness_nm_per_rad},
                              {"max_torque_nm", max_torque_nm}}) {
    if (!(std::isfinite(value) && value > 0.0)) {
      return Status::InvalidInput(std::string("DraggerOptions::") + field + " = " + json::FormatNumber(value) +
                                  " must be > 0");
    }
  }
  return Status::Ok();
}

Dragger::Dragger(const geometry::Pose3& world_T_workpiece, const Eigen::Vector3d& half_extents_m,
                 const DraggerOptions& options)
    : world_T_dragger_(world_T_workpiece), half_extents_(half_extents_m), options_(options) {}

bool Dragger::Pick(int face, const Eigen::Vector3d& ray_origin, const Eigen::Vector3d& ray_direction) {
  if (face < 0 || face > 5) return false;
  const int axis = face / 2;
  const double sign = face % 2 ? 1.0 : -1.0;
  Eigen::Vector3d normal_local = Eigen::Vector3d::Zero();
  normal_local[axis] = sign;
  const Eigen::Vector3d normal = world_T_dragger_.Rotate(normal_local);
  const Eigen::Vector3d on_face = world_T_dragger_ * (normal_local * half_extents_[axis]);
  auto hit = RayPlane(ray_origin, ray_direction, normal, on_face);
  if (!hit) return false;
  picked_ = Picked{normal, *hit, world_T_dragger_.translation};
  return true;
}

bool Dragger::DragTo(const Eigen::Vector3d& ray_origin, const Eigen::Vector3d& ray_direction) {
  if (!picked_) return false;
  auto hit = RayPlane(ray_origin, ray_direction, picked_->plane_normal, picked_->hit0);
  if (!hit) return false;
  // The displacement stays in the face's plane by construction.
  world_T_dragger_.translation = picked_->position0 + (*hit - picked_->hit0);
  return true;
}

void Dragger::SetPose(const geometry::Pose3& world_T_dragger, bool rotate) {
  world_T_dragger_ = world_T_dragger;
  rotate_ = rotate;
}

void Dragger::Rotate(const Eigen::Vector3d& axis_world, double angle_rad) {
  world_T_dragger_.rotation =
      (Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, axis_world.normalized())) * world_T_dragger_.rotation).normalized();
  rotate_ = true;
}

StepInput Dragger::Force(const geometry::Pose3& world_T_workpiece) const {
  StepInput input;
  Eigen::Vector3d f = options_.stiffness_n_per_m * (world_T_dragger_.translation - world_T_workpiece.translation);
  if (f.norm() > options_.max_force_n) f *= options_.max_force_n / f.norm();
  input.force_n = f;
  if (rotate_) {
    const Eigen::AngleAxisd delta(world_T_dragger_.rotation * world_T_workpiece.rotation.conjugate());
    Eigen::Vector3d tau = options_.torque_stiffness_nm_per_rad * delta.angle() * delta.axis();
    if (tau.norm() > options_.max_torque_nm) tau *= options_.max_torque_nm / tau.norm();
    input.torque_nm = tau;
  }
  return input;
}

}  // namespace teachsim::sim
