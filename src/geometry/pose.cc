#include "teachsim/geometry/pose.h"

#include <cmath>

namespace teachsim::geometry {

Pose3 Pose3::FromAxisAngle(const Eigen::Vector3d& axis, double angle_rad, const Eigen::Vector3d& t) {
  return {Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, axis.normalized())), t};
}

Eigen::Isometry3d Pose3::ToIsometry() const {
  Eigen::Isometry3d iso = Eigen::Isometry3d::Identity();
  iso.linear() = rotation.toRotationMatrix();
  iso.translation() = translation;
  return iso;
}

bool Pose3::IsValid() const {
  return translation.allFinite() && rotation.coeffs().allFinite() &&
         std::abs(rotation.squaredNorm() - 1.0) < 1e-6;
}

Pose3 Integrate(const Pose3& world_T_body, const Twist& twist, double dt_s) {
  Eigen::Vector3d rotation_vector = twist.angular * dt_s;
  double angle = rotation_vector.norm();
  Eigen::Quaterniond delta = Eigen::Quaterniond::Identity();
  if (angle > 0.0) delta = Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation_vector / angle));
  return {(delta * world_T_body.rotation).normalized(), world_T_body.translation + twist.linear * dt_s};
}

Pose3 Interpolate(const Pose3& a, const Pose3& b, double t) {
  return {a.rotation.slerp(t, b.rotation).normalized(), a.translation + t * (b.translation - a.translation)};
}

double TranslationDistance(const Pose3& a, const Pose3& b) { return (a.translation - b.translation).norm(); }

double RotationAngle(const Pose3& a, const Pose3& b) {
  return a.rotation.angularDistance(b.rotation);
}

Pose3 ReadPose(const json::Reader& reader) {
  reader.RejectUnknownKeys({"position", "quaternion_wxyz"});
  Eigen::Vector3d position = reader.At("position").Vector3();
  json::Reader q = reader.At("quaternion_wxyz");
  q.ExpectSize(4);
  Eigen::Quaterniond rotation(q.Index(0).Number(), q.Index(1).Number(), q.Index(2).Number(),
                              q.Index(3).Number());
  double norm = rotation.norm();
  if (std::abs(norm - 1.0) > 1e-3) {
    q.Fail("must be a unit quaternion [w, x, y, z], got norm " + json::FormatNumber(norm));
  }
  // Renormalise only what needs it, so that load -> save -> load is bit-identical.
  if (std::abs(norm - 1.0) > 1e-12) rotation.normalize();
  return {rotation, position};
}

json::Json WritePose(const Pose3& pose) {
  const Eigen::Quaterniond& q = pose.rotation;
  return {{"position", {pose.translation.x(), pose.translation.y(), pose.translation.z()}},
          {"quaternion_wxyz", {q.w(), q.x(), q.y(), q.z()}}};
}

}  // namespace teachsim::geometry
