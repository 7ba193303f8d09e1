// Item 4 of issue 7: Lowe's iterative least-squares fit of a 3D model to image lines (Lowe, PAMI
// 1991; paper §4.1): the perpendicular distances of each image segment's endpoints to the
// projection of its model edge, minimised over the 6 pose parameters by Gauss-Newton (Levenberg
// damped), with Huber weights against wrong matches. And the separating-axis penetration test the
// verification and the model editor use.
#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <limits>

#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

geometry::Pose3 Perturb(const geometry::Pose3& pose, const Vector6d& delta) {
  const Eigen::Vector3d w = delta.tail<3>();
  const double angle = w.norm();
  const Eigen::Quaterniond dq =
      angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle)) : Eigen::Quaterniond::Identity();
  return {(dq * pose.rotation).normalized(), pose.translation + delta.head<3>()};
}

// Residuals (px) of every match at a pose: two per match, endpoint a then b.
void Residuals(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K_inv_t, const geometry::Pose3& camera_T_object,
               const std::vector<LineMatch>& matches, Eigen::VectorXd* r) {
  r->resize(static_cast<Eigen::Index>(2 * matches.size()));
  for (size_t i = 0; i < matches.size(); ++i) {
    const LineMatch& m = matches[i];
    const Eigen::Vector3d p1 = camera_T_object * BoxVertex(size_m, kBoxEdges[static_cast<size_t>(m.edge)][0]);
    const Eigen::Vector3d p2 = camera_T_object * BoxVertex(size_m, kBoxEdges[static_cast<size_t>(m.edge)][1]);
    // The interpretation plane's normal, mapped to the pixel line through the edge's projection.
    const Eigen::Vector3d l = K_inv_t * p1.cross(p2);
    const double norm = std::max(std::sqrt(l.x() * l.x() + l.y() * l.y()), 1e-300);
    (*r)(static_cast<Eigen::Index>(2 * i)) = (l.x() * m.a.x() + l.y() * m.a.y() + l.z()) / norm;
    (*r)(static_cast<Eigen::Index>(2 * i + 1)) = (l.x() * m.b.x() + l.y() * m.b.y() + l.z()) / norm;
  }
}

double HuberWeight(double r, double k) { return k <= 0 || std::abs(r) <= k ? 1.0 : k / std::abs(r); }

}  // namespace

namespace {

// Levenberg-damped Gauss-Newton with Huber weights over N pose parameters; perturb(pose, delta)
// applies a parameter step. Shared by the 6-DOF fit and the 3-DOF fit on a support plane.
template <int N, typename Perturbation>
FitResult FitLm(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object_initial,
                const std::vector<LineMatch>& matches, int max_iterations, double huber_px, Perturbation perturb) {
  using VectorNd = Eigen::Matrix<double, N, 1>;
  using MatrixNd = Eigen::Matrix<double, N, N>;
  FitResult out;
  out.camera_T_object = camera_T_object_initial;
  out.covariance_camera.setZero();
  if (matches.empty()) return out;
  const Eigen::Matrix3d K_inv_t = K.inverse().transpose();
  const Eigen::Index m = static_cast<Eigen::Index>(2 * matches.size());
  Eigen::VectorXd r(m), rp(m), rm(m), w(m);
  Eigen::Matrix<double, Eigen::Dynamic, N> J(m, N);

  auto cost = [&](const Eigen::VectorXd& res) {
    double c = 0;
    for (Eigen::Index i = 0; i < res.size(); ++i) {
      const double a = std::abs(res(i));
      c += huber_px > 0 && a > huber_px ? huber_px * (2 * a - huber_px) : a * a;
    }
    return c;
  };
  auto jacobian = [&](const geometry::Pose3& pose) {
    // Central differences: 2N evaluations of a handful of residuals, cheaper to write than to
    // get wrong analytically, and exact enough that the fit converges to 1e-9.
    constexpr double kStep = 1e-7;
    for (int k = 0; k < N; ++k) {
      VectorNd d = VectorNd::Zero();
      d(k) = kStep;
      Residuals(size_m, K_inv_t, perturb(pose, d), matches, &rp);
      d(k) = -kStep;
      Residuals(size_m, K_inv_t, perturb(pose, d), matches, &rm);
      J.col(k) = (rp - rm) / (2 * kStep);
    }
  };

  geometry::Pose3 pose = camera_T_object_initial;
  Residuals(size_m, K_inv_t, pose, matches, &r);
  double current = cost(r);
  double lambda = 1e-6;
  for (int it = 0; it < max_iterations; ++it) {
    out.iterations = it + 1;
    jacobian(pose);
    for (Eigen::Index i = 0; i < m; ++i) w(i) = HuberWeight(r(i), huber_px);
    const MatrixNd H = J.transpose() * w.asDiagonal() * J;
    const VectorNd g = J.transpose() * (w.asDiagonal() * r);
    bool improved = false;
    const double before = current;
    VectorNd step = VectorNd::Zero();
    for (int tries = 0; tries < 8 && !improved; ++tries) {
      MatrixNd A = H;
      A.diagonal() += lambda * (H.diagonal().array() + 1e-12).matrix();
      step = -A.ldlt().solve(g);
      if (!step.allFinite()) break;
      const geometry::Pose3 trial = perturb(pose, step);
      if (trial.translation.z() <= 1e-4) {  // behind the camera: damp harder
        lambda *= 10;
        continue;
      }
      Residuals(size_m, K_inv_t, trial, matches, &rp);
      const double c = cost(rp);
      if (c <= current) {
        pose = trial;
        r = rp;
        current = c;
        improved = true;
        lambda = std::max(lambda * 0.1, 1e-9);
      } else {
        lambda *= 10;
      }
    }
    // Done when nothing improves, the step vanishes, or the cost no longer falls (noisy lines:
    // the last iterations of a plateau move the pose by nanometres).
    if (!improved || step.norm() < 1e-11 || before - current <= 1e-10 * before) {
      out.converged = true;
      break;
    }
  }
  out.camera_T_object = pose;
  out.rms_px = std::sqrt(r.squaredNorm() / static_cast<double>(m));
  return out;
}

}  // namespace

FitResult FitPoseToLines(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K,
                         const geometry::Pose3& camera_T_object_initial, const std::vector<LineMatch>& matches,
                         int max_iterations, double huber_px) {
  FitResult out = FitLm<6>(size_m, K, camera_T_object_initial, matches, max_iterations, huber_px, Perturb);
  if (matches.empty()) return out;
  // Covariance: the inverse of the weighted normal matrix, scaled by the residual variance.
  const Eigen::Matrix3d K_inv_t = K.inverse().transpose();
  const Eigen::Index m = static_cast<Eigen::Index>(2 * matches.size());
  Eigen::VectorXd r(m), rp(m), rm(m);
  Eigen::Matrix<double, Eigen::Dynamic, 6> J(m, 6);
  Residuals(size_m, K_inv_t, out.camera_T_object, matches, &r);
  for (int k = 0; k < 6; ++k) {
    Vector6d d = Vector6d::Zero();
    d(k) = 1e-7;
    Residuals(size_m, K_inv_t, Perturb(out.camera_T_object, d), matches, &rp);
    d(k) = -1e-7;
    Residuals(size_m, K_inv_t, Perturb(out.camera_T_object, d), matches, &rm);
    J.col(k) = (rp - rm) / 2e-7;
  }
  Eigen::VectorXd w(m);
  for (Eigen::Index i = 0; i < m; ++i) w(i) = HuberWeight(r(i), huber_px);
  const Matrix6d H = J.transpose() * w.asDiagonal() * J;
  double weighted = 0;
  for (Eigen::Index i = 0; i < m; ++i) weighted += w(i) * r(i) * r(i);
  const double dof = std::max<double>(1.0, static_cast<double>(m) - 6.0);
  // Floor at (0.1 px)^2: a noise-free fit would claim a zero covariance.
  const double sigma2 = std::max(weighted / dof, 0.01);
  Eigen::FullPivLU<Matrix6d> lu(H);
  out.covariance_camera = lu.isInvertible() ? Matrix6d(sigma2 * lu.inverse())
                                            : Matrix6d(Matrix6d::Identity() * std::numeric_limits<double>::infinity());
  return out;
}

FitResult FitPoseOnPlane(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world,
                         const geometry::Pose3& camera_T_object_initial, const std::vector<LineMatch>& matches,
                         int max_iterations, double huber_px) {
  // Parameters: a translation along world x, y and a turn about the world's vertical through the
  // object's centre; the height and the tilt stay as the support gave them.
  const geometry::Pose3 world_T_camera = camera_T_world.Inverse();
  auto perturb = [&](const geometry::Pose3& camera_T_object, const Eigen::Vector3d& d) {
    geometry::Pose3 world_T_object = world_T_camera * camera_T_object;
    world_T_object.rotation = (Eigen::Quaterniond(Eigen::AngleAxisd(d.z(), Eigen::Vector3d::UnitZ())) *
                               world_T_object.rotation).normalized();
    world_T_object.translation += Eigen::Vector3d(d.x(), d.y(), 0);
    return camera_T_world * world_T_object;
  };
  FitResult out = FitLm<3>(size_m, K, camera_T_object_initial, matches, max_iterations, huber_px, perturb);
  if (matches.empty()) return out;
  // The covariance of the full pose at the constrained optimum (what the recognition reports).
  out.covariance_camera = FitPoseToLines(size_m, K, out.camera_T_object, matches, 0, huber_px).covariance_camera;
  return out;
}

Penetration VertexSetPenetration(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                                 const std::vector<Eigen::Vector3d>& axes) {
  Penetration best;
  best.depth_m = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& axis : axes) {
    if (axis.squaredNorm() < 1e-12) continue;
    const Eigen::Vector3d d = axis.normalized();
    double amin = 1e300, amax = -1e300, bmin = 1e300, bmax = -1e300;
    for (const auto& p : a) amin = std::min(amin, d.dot(p)), amax = std::max(amax, d.dot(p));
    for (const auto& p : b) bmin = std::min(bmin, d.dot(p)), bmax = std::max(bmax, d.dot(p));
    // Move a along +d by (bmax - amin), or along -d by (amax - bmin).
    const double plus = bmax - amin, minus = amax - bmin;
    if (plus <= 0 || minus <= 0) return {0.0, d};  // a separating axis
    if (plus < best.depth_m) best = {plus, d};
    if (minus < best.depth_m) best = {minus, -d};
  }
  if (!std::isfinite(best.depth_m)) best.depth_m = 0;
  return best;
}

Penetration BoxBoxPenetration(const Eigen::Vector3d& size_a, const geometry::Pose3& world_T_a,
                              const Eigen::Vector3d& size_b, const geometry::Pose3& world_T_b,
                              bool horizontal_only) {
  std::vector<Eigen::Vector3d> va, vb, axes;
  for (int i = 0; i < 8; ++i) {
    va.push_back(world_T_a * BoxVertex(size_a, i));
    vb.push_back(world_T_b * BoxVertex(size_b, i));
  }
  const Eigen::Matrix3d ra = world_T_a.RotationMatrix(), rb = world_T_b.RotationMatrix();
  for (int i = 0; i < 3; ++i) {
    axes.push_back(ra.col(i));
    axes.push_back(rb.col(i));
    for (int j = 0; j < 3; ++j) axes.push_back(ra.col(i).cross(rb.col(j)));
  }
  if (horizontal_only) {
    for (Eigen::Vector3d& axis : axes) axis.z() = 0;
  }
  return VertexSetPenetration(va, vb, axes);
}

}  // namespace teachsim::vision
