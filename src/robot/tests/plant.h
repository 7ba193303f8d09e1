// A small simulated plant for the controller tests: a kinematic arm whose joints follow their
// setpoints through 1 kHz first-order servos, a sphere around the tool origin (the fingertips, or
// the block they hold) meeting stiff planes modelled as springs with stick–slip friction, a
// parallel gripper that stops on a block between its jaws, and the block's weight once held.
#pragma once

#include <cmath>
#include <optional>
#include <vector>

#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/robot_io.h"

namespace teachsim::robot::testing {

struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, pointing to the free side
  double offset_m = 0;                                // free where normal . p >= offset
  double stiffness_n_per_m = 5e4;
  double friction = 0;  // Coulomb coefficient
  // state: where the tangential spring is anchored (stick), valid while in contact
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();
  bool touching = false;
};

class Plant : public RobotIo {
 public:
  Plant(const RobotModel& model, const geometry::Pose3& world_T_base, const Joints& q0)
      : model_(model), world_T_base_(world_T_base), q_(q0), setpoint_(q0) {
    UpdateForce();
  }

  std::vector<Plane> planes;
  double contact_radius_m = 0.0225;
  double servo_time_constant_s = 0.005;
  double gripper_speed_mps = 0.1;
  std::optional<Eigen::Vector3d> block;  // centre of a block to grasp, world
  double block_width_m = 0.045;
  double block_weight_n = 0.9;  // a 45 mm wooden cube: about 90 g

  Joints ReadJoints() override { return q_; }
  Wrench ReadWristWrench() override {
    Wrench w;
    w.force_n = Tool().rotation.conjugate() * force_;
    return w;
  }
  GripperState ReadGripper() override { return {width_, moving_}; }
  void CommandJoints(const Joints& q) override {
    setpoint_ = q;
    ++joint_commands_;
  }
  void CommandGripper(double width_m) override { gripper_target_ = width_m; }

  void Advance(double dt_s) {
    const int steps = std::max(1, static_cast<int>(std::lround(dt_s / 1e-3)));
    const double h = dt_s / steps;
    const double alpha = 1 - std::exp(-h / servo_time_constant_s);
    for (int k = 0; k < steps; ++k) {
      q_ += (setpoint_ - q_) * alpha;
      StepGripper(h);
      UpdateForce();
    }
  }

  geometry::Pose3 Tool() const { return world_T_base_ * ToolPose(model_, q_); }
  const Eigen::Vector3d& force() const { return force_; }  // on the tool, world, with the payload
  bool holding() const { return holding_; }
  int joint_commands() const { return joint_commands_; }

 private:
  void StepGripper(double h) {
    double stop = gripper_target_;
    const Eigen::Vector3d p = Tool().translation;
    if (block && !holding_ && (p - *block).head<2>().norm() < 0.005 && std::abs(p.z() - block->z()) < 0.01 &&
        width_ >= block_width_m && gripper_target_ < block_width_m) {
      stop = block_width_m;  // the jaws close on the block
    }
    if (holding_ && gripper_target_ < block_width_m) stop = block_width_m;
    const double step = gripper_speed_mps * h;
    const double before = width_;
    width_ += std::clamp(stop - width_, -step, step);
    moving_ = std::abs(width_ - before) > 1e-12;
    if (!holding_ && block && std::abs(width_ - block_width_m) < 1e-9 && stop == block_width_m)
      holding_ = true;
    if (holding_ && width_ > block_width_m + 1e-3) {
      holding_ = false;
      block = p;  // left where it was released
    }
  }

  void UpdateForce() {
    const Eigen::Vector3d p = Tool().translation;
    force_ = Eigen::Vector3d::Zero();
    for (Plane& plane : planes) {
      const double depth = plane.offset_m + contact_radius_m - plane.normal.dot(p);
      if (depth <= 0) {
        plane.touching = false;
        continue;
      }
      const double normal_force = plane.stiffness_n_per_m * depth;
      force_ += normal_force * plane.normal;
      if (plane.friction > 0) {
        if (!plane.touching) plane.anchor = p;
        Eigen::Vector3d slip = p - plane.anchor;
        slip -= plane.normal * plane.normal.dot(slip);
        Eigen::Vector3d tangential = -plane.stiffness_n_per_m * slip;
        const double limit = plane.friction * normal_force;
        if (tangential.norm() > limit) {  // sliding: drag the anchor along
          tangential *= limit / tangential.norm();
          plane.anchor = p + tangential / plane.stiffness_n_per_m;
        }
        force_ += tangential;
      }
      plane.touching = true;
    }
    if (holding_) force_.z() -= block_weight_n;
  }

  const RobotModel& model_;
  geometry::Pose3 world_T_base_;
  Joints q_, setpoint_;
  Eigen::Vector3d force_ = Eigen::Vector3d::Zero();
  double width_ = 0.03, gripper_target_ = 0.03;
  bool moving_ = false, holding_ = false;
  int joint_commands_ = 0;
};

}  // namespace teachsim::robot::testing
