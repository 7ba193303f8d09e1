#include "teachsim/robot/friction.h"

#include <Eigen/Geometry>
#include <cmath>
#include <functional>
#include <limits>

namespace teachsim::robot {

namespace {

// lambda . n + mu |P lambda|: the largest value lambda . (N n + t) can take per unit N within
// the cone, i.e. the support function of the cone's unit slice.
double ConeSupport(const Eigen::Vector3d& u, const Eigen::Vector3d& n, double mu) {
  const double along = u.dot(n);
  return along + mu * (u - along * n).norm();
}

// Maximizes score(u) over unit directions: a Fibonacci sphere, then a shrinking ring search
// around the best. score returns -inf where u is not admissible.
Eigen::Vector3d Search(const std::function<double(const Eigen::Vector3d&)>& score, double* best_score) {
  constexpr int kSphere = 3000;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  Eigen::Vector3d best = Eigen::Vector3d::UnitZ();
  double best_value = -INFINITY;
  for (int k = 0; k < kSphere; ++k) {
    const double z = 1.0 - 2.0 * (k + 0.5) / kSphere, r = std::sqrt(1 - z * z), a = golden * k;
    const Eigen::Vector3d u(r * std::cos(a), r * std::sin(a), z);
    const double v = score(u);
    if (v > best_value) {
      best_value = v;
      best = u;
    }
  }
  if (std::isfinite(best_value)) {
    for (double radius = 0.05; radius > 1e-6; radius *= 0.6) {
      const Eigen::Vector3d e1 = best.unitOrthogonal(), e2 = best.cross(e1);
      const Eigen::Vector3d center = best;
      for (int k = 0; k < 16; ++k) {
        const double a = 2 * M_PI * k / 16;
        const Eigen::Vector3d u = (center + radius * (std::cos(a) * e1 + std::sin(a) * e2)).normalized();
        const double v = score(u);
        if (v > best_value) {
          best_value = v;
          best = u;
        }
      }
    }
  }
  *best_score = best_value;
  return best;
}

}  // namespace

NormalForceBound MinNormalForce(const Eigen::Vector3d& force, const Eigen::Matrix3Xd& normals, double mu,
                                long i) {
  NormalForceBound out;
  const long m = normals.cols();
  if (m == 0 || i < 0 || i >= m) return out;
  // Consistency: the distance from the force to the sum of the cones, max u . f over unit u in
  // the polar cone (every cone's support <= 0).
  double outside = 0;
  const Eigen::Vector3d polar = Search(
      [&](const Eigen::Vector3d& u) -> double {
        for (long j = 0; j < m; ++j) {
          if (ConeSupport(u, normals.col(j), mu) > 0) return -std::numeric_limits<double>::infinity();
        }
        return u.dot(force);
      },
      &outside);
  out.outside_n = std::max(0.0, std::isfinite(outside) ? outside : 0.0);
  // Moreau: the force is its projection on the cones' sum plus outside_n along `polar`; the
  // bound is for the projection (what the contacts can explain).
  const Eigen::Vector3d explained = force - out.outside_n * polar;
  // The certificate: lambda = u / support_i(u), with the other cones' supports <= 0.
  double bound = 0;
  Search(
      [&](const Eigen::Vector3d& u) -> double {
        for (long j = 0; j < m; ++j) {
          if (j != i && ConeSupport(u, normals.col(j), mu) > 0) return -std::numeric_limits<double>::infinity();
        }
        const double s = ConeSupport(u, normals.col(i), mu);
        const double f = u.dot(explained);
        if (s <= 0 || f <= 0) return -std::numeric_limits<double>::infinity();
        return f / s;
      },
      &bound);
  out.min_n = std::isfinite(bound) ? std::max(0.0, bound) : 0.0;
  return out;
}

}  // namespace teachsim::robot
