#include "teachsim/sim/lcp.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

namespace teachsim::sim {
namespace {

Vector6 Gains() {
  Vector6 d;
  d << 0.1, 0.1, 0.1, 49.0, 49.0, 49.0;
  return d;
}

Eigen::Matrix<double, 6, 1> Wrench(const Eigen::Vector3d& n, const Eigen::Vector3d& r) {
  Eigen::Matrix<double, 6, 1> w;
  w << n, r.cross(n);
  return w;
}

// Random contact sets on a 45 mm cube: points on its faces with inward normals (the obstacle
// pushes the cube), often several on one face (rank-deficient), random applied wrenches.
LcpProblem RandomProblem(std::mt19937_64& rng, int n, bool with_bilateral) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> face(0, 5);
  LcpProblem p;
  p.jt.resize(6, n);
  p.d_diag = Gains();
  for (int i = 0; i < n; ++i) {
    const int f = face(rng) % (i < 3 ? 6 : 3);  // later points crowd onto three faces
    const int axis = f % 3;
    const double sign = f < 3 ? 1.0 : -1.0;
    Eigen::Vector3d r(u(rng), u(rng), u(rng));
    r *= 0.0225;
    r[axis] = sign * 0.0225;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    normal[axis] = -sign;  // pushes the cube inward
    p.jt.col(i) = Wrench(normal, r);
    p.bilateral.push_back(with_bilateral && i % 4 == 0);
  }
  p.applied << 3 * u(rng), 3 * u(rng), 3 * u(rng), 0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng);
  return p;
}

// The issue: on random contact sets the result satisfies the complementarity conditions to 1e-9
// and matches brute-force enumeration of active sets (n <= 10). The velocity is unique even when
// the forces are not (more than six points).
TEST(ContactLcp, MatchesBruteForceOnRandomContactSets) {
  std::mt19937_64 rng(17);
  int rank_deficient = 0;
  for (int trial = 0; trial < 600; ++trial) {
    const int n = 1 + trial % 10;
    LcpProblem p = RandomProblem(rng, n, trial % 3 == 0);
    LcpSolution s = SolveContactLcp(p);
    ASSERT_TRUE(s.converged);
    EXPECT_LE(ComplementarityError(p, s), 1e-9) << "trial " << trial;
    LcpSolution ref;
    ASSERT_TRUE(SolveContactLcpBruteForce(p, 1e-9, &ref)) << "trial " << trial;
    EXPECT_LE((s.velocity - ref.velocity).norm(), 1e-9 * std::max(1.0, ref.velocity.norm())) << "trial " << trial;
    Eigen::FullPivLU<Eigen::MatrixXd> lu(p.jt);
    if (lu.rank() < n) ++rank_deficient;
  }
  EXPECT_GT(rank_deficient, 100);
}

TEST(ContactLcp, BlockPushedIntoTableAndWallSlidesWithoutApproaching) {
  // A cube resting on the table (4 corners) and against a wall at -x (4 corners): 8 contacts, rank 5.
  LcpProblem p;
  p.d_diag = Gains();
  p.jt.resize(6, 8);
  int c = 0;
  for (double sx : {-1.0, 1.0}) {
    for (double sy : {-1.0, 1.0}) p.jt.col(c++) = Wrench({0, 0, 1}, Eigen::Vector3d(sx, sy, -1) * 0.0225);
  }
  for (double sy : {-1.0, 1.0}) {
    for (double sz : {-1.0, 1.0}) p.jt.col(c++) = Wrench({1, 0, 0}, Eigen::Vector3d(-1, sy, sz) * 0.0225);
  }
  p.applied << -2.0, 1.0, -1.0, 0, 0, 0;  // into the wall and the table, and along +y
  LcpSolution s = SolveContactLcp(p);
  EXPECT_LE(ComplementarityError(p, s), 1e-12);
  EXPECT_NEAR(s.velocity(0), 0.0, 1e-12);
  EXPECT_NEAR(s.velocity(2), 0.0, 1e-12);
  EXPECT_NEAR(s.velocity(1), 0.1, 1e-12);  // slides along y at d_t * 1 N
  EXPECT_LT(s.velocity.tail<3>().norm(), 1e-10);
  EXPECT_NEAR(s.force.segment(0, 4).sum(), 1.0, 1e-9);
  EXPECT_NEAR(s.force.segment(4, 4).sum(), 2.0, 1e-9);
}

TEST(ContactLcp, PullingAwayGivesZeroForceAndBilateralHolds) {
  LcpProblem p;
  p.d_diag = Gains();
  p.jt.resize(6, 1);
  p.jt.col(0) = Wrench({0, 0, 1}, {0, 0, -0.0225});
  p.applied << 0, 0, 1.0, 0, 0, 0;  // lifting off
  LcpSolution s = SolveContactLcp(p);
  EXPECT_EQ(s.force(0), 0.0);
  EXPECT_NEAR(s.velocity(2), 0.1, 1e-15);
  p.bilateral = {true};  // captured: the contact holds, pulling back
  s = SolveContactLcp(p);
  EXPECT_NEAR(s.force(0), -1.0, 1e-12);
  EXPECT_NEAR(s.normal_velocity(0), 0.0, 1e-12);
}

}  // namespace
}  // namespace teachsim::sim
