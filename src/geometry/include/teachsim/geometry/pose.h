// Rigid transforms in SE(3) and twists. `a_T_b` maps b-coordinates to a-coordinates (DESIGN.md).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"

namespace teachsim::geometry {

struct Pose3 {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // unit
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();         // m

  Pose3() = default;
  Pose3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) : rotation(q), translation(t) {}

  static Pose3 Identity() { return {}; }
  static Pose3 Translation(const Eigen::Vector3d& t) { return {Eigen::Quaterniond::Identity(), t}; }
  static Pose3 FromAxisAngle(const Eigen::Vector3d& axis, double angle_rad,
                             const Eigen::Vector3d& t = Eigen::Vector3d::Zero());

  // a_T_c = a_T_b * b_T_c
  Pose3 operator*(const Pose3& b_T_c) const {
    return {rotation * b_T_c.rotation, rotation * b_T_c.translation + translation};
  }
  // p_in_a = a_T_b * p_in_b
  Eigen::Vector3d operator*(const Eigen::Vector3d& p_in_b) const { return rotation * p_in_b + translation; }
  Eigen::Vector3d Rotate(const Eigen::Vector3d& v_in_b) const { return rotation * v_in_b; }
  Pose3 Inverse() const {
    Eigen::Quaterniond inv = rotation.conjugate();
    return {inv, -(inv * translation)};
  }
  Eigen::Matrix3d RotationMatrix() const { return rotation.toRotationMatrix(); }
  Eigen::Isometry3d ToIsometry() const;

  bool IsValid() const;  // finite and unit quaternion within 1e-6
};

// Spatial velocity: linear velocity of the body origin and angular velocity, both in the world frame.
struct Twist {
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();   // m/s
  Eigen::Vector3d angular = Eigen::Vector3d::Zero();  // rad/s
};

// The body's pose after moving with `twist` for `dt_s`: origin translates linearly, the body
// rotates about its origin by angular*dt (world frame). This is the motion the simulator takes
// within one step and the one time-of-impact assumes (Interpolate() between the end poses).
Pose3 Integrate(const Pose3& world_T_body, const Twist& twist, double dt_s);

// The motion between two poses, t in [0, 1]: linear in the origin, slerp in the rotation (a
// constant angular velocity about a fixed world axis through the moving origin).
Pose3 Interpolate(const Pose3& a, const Pose3& b, double t);

// Distance measures between poses.
double TranslationDistance(const Pose3& a, const Pose3& b);
double RotationAngle(const Pose3& a, const Pose3& b);  // rad, in [0, pi]

// JSON: {"position": [x, y, z], "quaternion_wxyz": [w, x, y, z]}. The quaternion must be unit
// within 1e-3 (it is normalised), which catches a reordered xyzw.
Pose3 ReadPose(const json::Reader& reader);
json::Json WritePose(const Pose3& pose);

}  // namespace teachsim::geometry
