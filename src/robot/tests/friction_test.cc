// The monitor's friction-aware bound on a contact's normal force (friction.h): exact for a single
// contact, never above the true normal force of any contact forces within the friction cones that
// produce the measurement, tight on a case solved by hand, and it flags forces no contact explains.
#include "teachsim/robot/friction.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace teachsim::robot {
namespace {

using Eigen::Vector3d;

Eigen::Matrix3Xd Normals(std::initializer_list<Vector3d> list) {
  Eigen::Matrix3Xd n(3, static_cast<Eigen::Index>(list.size()));
  long i = 0;
  for (const Vector3d& v : list) n.col(i++) = v.normalized();
  return n;
}

TEST(Friction, SingleContactReadsItsNormalForceExactly) {
  const Eigen::Matrix3Xd n = Normals({Vector3d::UnitZ()});
  // 2 N down with 0.6 N of friction (inside the 0.5 cone): the normal force is 2 N whatever the friction.
  const NormalForceBound b = MinNormalForce(Vector3d(0.6, 0, 2.0), n, 0.5, 0);
  EXPECT_NEAR(b.min_n, 2.0, 1e-6);
  EXPECT_LE(b.min_n, 2.0 + 1e-12);
  EXPECT_LT(b.outside_n, 1e-9);
  // 1.5 N sideways on 1 N normal: outside the 0.5 cone by the distance to its surface.
  const NormalForceBound out = MinNormalForce(Vector3d(1.5, 0, 1.0), n, 0.5, 0);
  const double expected = (1.5 - 0.5 * 1.0) / std::sqrt(1 + 0.25);  // distance to the cone's side
  EXPECT_NEAR(out.outside_n, expected, 1e-4);
}

TEST(Friction, TableAndWallMatchTheBoundSolvedByHand) {
  // Wall (+x) and table (+z), 1.5 N along each, mu = 0.5. The smallest wall force: the table's
  // friction pushes +x with mu N_z, the wall's friction pushes the table harder:
  // N_x = (f_x - mu f_z) / (1 + mu^2) = 0.6 N.
  const Eigen::Matrix3Xd n = Normals({Vector3d::UnitX(), Vector3d::UnitZ()});
  const NormalForceBound b = MinNormalForce(Vector3d(1.5, 0, 1.5), n, 0.5, 0);
  EXPECT_NEAR(b.min_n, 0.6, 2e-3);
  EXPECT_LE(b.min_n, 0.6 + 1e-9);
  // mu = 0: the plain component.
  EXPECT_NEAR(MinNormalForce(Vector3d(1.5, 0, 1.5), n, 0.0, 0).min_n, 1.5, 1e-4);
  // A force along y is friction only; with mu = 0 it is explained by nothing.
  EXPECT_NEAR(MinNormalForce(Vector3d(1.5, 0.4, 1.5), n, 0.0, 0).outside_n, 0.4, 1e-4);
  EXPECT_LT(MinNormalForce(Vector3d(1.5, 0.4, 1.5), n, 0.5, 0).outside_n, 1e-9);
}

TEST(Friction, ACornerPressedEquallyCannotBeCertifiedWithHighFriction) {
  // Three orthogonal contacts each pressed with 1.5 N: with mu = 0.5 the other two contacts'
  // friction can account for most of the force along each normal (the reason the monitor probes
  // the contacts one at a time); pressed alone, with the others light, it certifies.
  const Eigen::Matrix3Xd n = Normals({Vector3d::UnitX(), Vector3d::UnitY(), Vector3d::UnitZ()});
  const NormalForceBound equal = MinNormalForce(Vector3d(1.5, 1.5, 1.5), n, 0.5, 0);
  EXPECT_LT(equal.min_n, 0.6);
  const NormalForceBound alone = MinNormalForce(Vector3d(1.5, 0.2, 0.2), n, 0.5, 0);
  EXPECT_GT(alone.min_n, 0.8);  // above the programs' 0.6 N threshold
  EXPECT_LE(alone.min_n, 1.5);
}

// Soundness: random contact forces inside the cones (2-3 contacts, random normals spanning a
// half-space, mu up to 0.6); the bound never exceeds the normal force that produced the sum.
TEST(Friction, NeverAboveTheTrueNormalForce) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1, 1), pos(0, 1);
  int tight = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int m = 2 + trial % 2;
    Eigen::Matrix3Xd n(3, m);
    for (int j = 0; j < m; ++j) n.col(j) = (Vector3d(u(rng), u(rng), u(rng)) + Vector3d(0, 0, 1.2)).normalized();
    const double mu = 0.6 * pos(rng);
    Vector3d f = Vector3d::Zero();
    std::vector<double> normal_force(static_cast<std::size_t>(m));
    for (int j = 0; j < m; ++j) {
      normal_force[static_cast<std::size_t>(j)] = 3 * pos(rng);
      Vector3d t(u(rng), u(rng), u(rng));
      t -= t.dot(n.col(j)) * n.col(j);
      if (t.norm() > 0) t *= mu * normal_force[static_cast<std::size_t>(j)] * pos(rng) / t.norm();
      f += normal_force[static_cast<std::size_t>(j)] * n.col(j) + t;
    }
    for (int i = 0; i < m; ++i) {
      const NormalForceBound b = MinNormalForce(f, n, mu, i);
      EXPECT_LT(b.outside_n, 1e-6) << trial;
      EXPECT_LE(b.min_n, normal_force[static_cast<std::size_t>(i)] + 1e-9) << trial << " contact " << i;
      if (b.min_n > 0.5 * normal_force[static_cast<std::size_t>(i)]) ++tight;
    }
  }
  EXPECT_GT(tight, 100);  // and it is not vacuous
}

}  // namespace
}  // namespace teachsim::robot
