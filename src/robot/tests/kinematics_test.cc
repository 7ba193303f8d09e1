#include "teachsim/robot/kinematics.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <numbers>
#include <random>

#include "teachsim/robot/robot_model.h"

namespace teachsim::robot {
namespace {

using geometry::Pose3;
constexpr double kPi = std::numbers::pi;

RobotModel Arm() {
  auto model = LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.json");
  TEACHSIM_CHECK_MSG(model.ok(), model.status().message().c_str());
  return *model;
}

Joints RandomJoints(const RobotModel& m, std::mt19937_64& rng) {
  Joints q;
  for (int i = 0; i < kNumJoints; ++i) {
    q[i] = std::uniform_real_distribution<double>(m.joints[i].lower_rad, m.joints[i].upper_rad)(rng);
  }
  return q;
}

double PoseError(const Pose3& a, const Pose3& b) {
  return std::max(geometry::TranslationDistance(a, b), geometry::RotationAngle(a, b));
}

double JointDistance(const Joints& a, const Joints& b) {
  double d = 0;
  for (int i = 0; i < kNumJoints; ++i) d = std::max(d, std::abs(WrapAngle(a[i] - b[i])));
  return d;
}

TEST(Kinematics, ZeroPoseMatchesTheTable) {
  RobotModel m = Arm();
  // q = 0: upper arm up (d1 + a2 high), forearm along x (d4 + d6), tool along the forearm.
  Pose3 flange = FlangePose(m, Joints::Zero());
  EXPECT_NEAR((flange.translation - Eigen::Vector3d(0.330 + 0.076, 0, 0.330 + 0.305)).norm(), 0, 1e-12);
  EXPECT_NEAR((flange.Rotate(Eigen::Vector3d::UnitZ()) - Eigen::Vector3d::UnitX()).norm(), 0, 1e-12);
  // The ready pose points the tool straight down.
  Pose3 ready = ToolPose(m, m.ready_rad);
  EXPECT_NEAR((ready.Rotate(Eigen::Vector3d::UnitZ()) - Eigen::Vector3d(0, 0, -1)).norm(), 0, 1e-12);
  EXPECT_NEAR((ready.translation - Eigen::Vector3d(0.330, 0, 0.635 - 0.076 - 0.13)).norm(), 0, 1e-12);
}

// The brief's main property: 1e5 random reachable poses (FK of random joints within the limits);
// every analytic solution reproduces the pose to 1e-9, there are eight, and the joints we started
// from are among them.
TEST(Kinematics, IkFkRoundTripOnRandomPoses) {
  RobotModel m = Arm();
  std::mt19937_64 rng(12345);
  constexpr int kSamples = 100000;
  int eight = 0, found_original = 0, regular = 0;
  double worst = 0;
  auto start = std::chrono::steady_clock::now();
  for (int n = 0; n < kSamples; ++n) {
    Joints q = RandomJoints(m, rng);
    Pose3 target = ToolPose(m, q);
    IkSolutions all = SolveToolIk(m, target, q);
    ASSERT_EQ(all.status, IkStatus::kOk) << "sample " << n;
    if (all.count == 8) ++eight;
    bool has_original = false;
    for (int s = 0; s < all.count; ++s) {
      double error = PoseError(ToolPose(m, all.solutions[s].q), target);
      worst = std::max(worst, error);
      ASSERT_LT(error, 1e-9) << "sample " << n << " branch " << all.solutions[s].branch.Name();
      if (JointDistance(all.solutions[s].q, q) < 1e-6) has_original = true;
    }
    bool singular = DetectSingularities(m, q).any();
    if (!singular) {
      ++regular;
      found_original += has_original;
    }
  }
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("round trip: %d poses, worst error %.3g, %d regular, %.2f s\n", kSamples, worst, regular,
              seconds);
  EXPECT_EQ(eight, kSamples);
  EXPECT_EQ(found_original, regular);
  EXPECT_GT(regular, kSamples * 99 / 100);
}

// Away from singularities the eight solutions are distinct and carry the eight branch labels.
TEST(Kinematics, EightDistinctSolutionsWithAllBranches) {
  RobotModel m = Arm();
  std::mt19937_64 rng(7);
  int checked = 0;
  for (int n = 0; n < 2000; ++n) {
    Joints q = RandomJoints(m, rng);
    if (DetectSingularities(m, q, {0.05, 0.05, 0.05}).any()) continue;
    IkSolutions all = SolveToolIk(m, ToolPose(m, q), q);
    ASSERT_EQ(all.count, 8);
    int labels = 0;
    for (int a = 0; a < 8; ++a) {
      const IkBranch& b = all.solutions[a].branch;
      labels |= 1 << (b.shoulder_right * 4 + b.elbow_up * 2 + b.wrist_flip);
      for (int b2 = a + 1; b2 < 8; ++b2) {
        EXPECT_GT(JointDistance(all.solutions[a].q, all.solutions[b2].q), 1e-3);
      }
    }
    EXPECT_EQ(labels, 0xff) << "every branch once";
    ++checked;
  }
  EXPECT_GT(checked, 1000);
}

TEST(Kinematics, ElbowUpIsGeometric) {
  RobotModel m = Arm();
  // Forearm bent down from a raised upper arm: the elbow is above the shoulder–wrist line.
  Joints q;
  q << 0.3, 0.4, 0.6, 0.2, -1.0, 0.1;
  IkSolutions all = SolveToolIk(m, ToolPose(m, q), q);
  for (int s = 0; s < all.count; ++s) {
    if (JointDistance(all.solutions[s].q, q) < 1e-9) {
      EXPECT_TRUE(all.solutions[s].branch.elbow_up);
      EXPECT_TRUE(all.solutions[s].branch.shoulder_right);
    }
  }
}

TEST(Kinematics, NearestSolutionIsTheCurrentBranchAndRespectsLimits) {
  RobotModel m = Arm();
  std::mt19937_64 rng(99);
  for (int n = 0; n < 5000; ++n) {
    Joints q = RandomJoints(m, rng);
    if (DetectSingularities(m, q, {0.05, 0.05, 0.05}).any()) continue;
    // From a start a little away from q, the nearest solution is q itself.
    Joints start = q + Joints::Constant(0.01);
    Result<IkSolution> nearest = NearestToolIk(m, ToolPose(m, q), start);
    ASSERT_TRUE(nearest.ok()) << nearest.status().message();
    EXPECT_LT((nearest->q - q).cwiseAbs().maxCoeff(), 1e-7);
    EXPECT_TRUE(m.WithinLimits(nearest->q));
  }
}

TEST(Kinematics, UnreachablePosesAreRefusedWithAClearStatus) {
  RobotModel m = Arm();
  Joints hint = m.ready_rad;
  Pose3 down(Eigen::Quaterniond(0, 1, 0, 0), Eigen::Vector3d(0.9, 0, 0.3));  // tool pointing down
  IkSolutions far = SolveToolIk(m, down, hint);
  EXPECT_EQ(far.status, IkStatus::kOutOfReach);
  EXPECT_EQ(far.count, 0);
  Result<IkSolution> r = NearestToolIk(m, down, hint);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("out of reach"), std::string::npos) << r.status().message();
  EXPECT_NE(r.status().message().find("(900.0, 0.0, 300.0) mm"), std::string::npos) << r.status().message();

  // Wrist centre beside the shoulder, nearer than the folded arm allows (|a2 - d4| = 25 mm).
  Pose3 inside = Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.0, 0.0, 0.33 + 0.01 + 0.076 - 0.0));
  inside = inside * m.flange_T_tool;  // flange z up, wrist centre at (0, 0, 0.34)
  IkSolutions in = SolveToolIk(m, inside, hint);
  EXPECT_EQ(in.status, IkStatus::kInsideReach);

  // Reachable only by going through the floor: below the base, joint 2 would pass its limits.
  Pose3 below(Eigen::Quaterniond(0, 1, 0, 0), Eigen::Vector3d(0.05, 0.0, -0.45));
  IkSolutions low = SolveToolIk(m, below, hint);
  EXPECT_EQ(low.status, IkStatus::kBeyondLimits);
  Result<IkSolution> lr = NearestToolIk(m, below, hint);
  ASSERT_FALSE(lr.ok());
  EXPECT_NE(lr.status().message().find("beyond the joint limits"), std::string::npos)
      << lr.status().message();

  Pose3 nan(Eigen::Quaterniond::Identity(), Eigen::Vector3d(std::nan(""), 0, 0));
  EXPECT_EQ(SolveToolIk(m, nan, hint).status, IkStatus::kInvalidPose);
}

TEST(Kinematics, JacobianMatchesFiniteDifferences) {
  RobotModel m = Arm();
  std::mt19937_64 rng(3);
  for (int n = 0; n < 200; ++n) {
    Joints q = RandomJoints(m, rng);
    Jacobian J = ToolJacobian(m, q);
    Pose3 T = ToolPose(m, q);
    for (int i = 0; i < kNumJoints; ++i) {
      constexpr double h = 1e-6;
      Joints qp = q, qm = q;
      qp[i] += h;
      qm[i] -= h;
      Pose3 Tp = ToolPose(m, qp), Tm = ToolPose(m, qm);
      Eigen::Vector3d v = (Tp.translation - Tm.translation) / (2 * h);
      Eigen::AngleAxisd d(Tp.rotation * Tm.rotation.conjugate());
      Eigen::Vector3d w = d.axis() * d.angle() / (2 * h);
      EXPECT_LT((J.block<3, 1>(0, i) - v).norm(), 1e-7);
      EXPECT_LT((J.block<3, 1>(3, i) - w).norm(), 1e-7);
    }
    (void)T;
  }
}

// Each singularity flagged by DetectSingularities makes the Jacobian lose rank; regular poses do not.
TEST(Kinematics, SingularitiesAreDetectedAndLoseJacobianRank) {
  RobotModel m = Arm();
  auto smallest = [&](const Joints& q) {
    Eigen::JacobiSVD<Jacobian> svd(ToolJacobian(m, q));
    return svd.singularValues()(kNumJoints - 1);
  };
  Joints regular;
  regular << 0.2, 0.3, 0.5, 0.4, -1.0, 0.3;
  Singularities s = DetectSingularities(m, regular);
  EXPECT_FALSE(s.any()) << s.Describe();
  EXPECT_EQ(s.Describe(), "regular");
  EXPECT_GT(smallest(regular), 1e-2);

  Joints wrist = regular;
  wrist[4] = 0;  // axes 4 and 6 aligned
  s = DetectSingularities(m, wrist);
  EXPECT_TRUE(s.wrist);
  EXPECT_FALSE(s.elbow);
  EXPECT_NE(s.Describe().find("wrist singular"), std::string::npos);
  EXPECT_LT(smallest(wrist), 1e-9);

  Joints elbow = regular;
  elbow[2] = -kPi / 2;  // forearm in line with the upper arm: stretched out
  s = DetectSingularities(m, elbow);
  EXPECT_TRUE(s.elbow);
  EXPECT_NE(s.Describe().find("elbow singular"), std::string::npos);
  EXPECT_LT(smallest(elbow), 1e-9);

  // Wrist centre on joint 1's axis: upper arm tilted back so that the forearm ends above the base.
  // rho = cos(t2) X - sin(t2) Y with X = a2 - d4 s3, Y = d4 c3 (a3 = 0); choose t3 = 0 and solve.
  Joints shoulder = regular;
  shoulder[2] = 0;
  double theta2 = std::atan2(m.upper_arm_m(), m.forearm_m());  // cos(t2) a2 = sin(t2) d4
  shoulder[1] = theta2 - m.joints[1].theta_offset_rad;
  shoulder[1] = WrapAngle(shoulder[1]);
  s = DetectSingularities(m, shoulder);
  EXPECT_TRUE(s.shoulder) << s.Describe();
  EXPECT_LT(smallest(shoulder), 1e-9);
  // IK there keeps joint 1 where it is (it is free) and still reproduces the pose.
  Pose3 target = ToolPose(m, shoulder);
  Joints hint = shoulder;
  hint[0] = 0.7;
  IkSolutions all = SolveToolIk(m, target, hint);
  ASSERT_GT(all.count, 0);
  for (int i = 0; i < all.count; ++i) EXPECT_LT(PoseError(ToolPose(m, all.solutions[i].q), target), 1e-9);
  EXPECT_NEAR(all.solutions[0].q[0], 0.7, 1e-12);
  EXPECT_TRUE(all.solutions[0].singularities.shoulder);

  // At the wrist singularity, joint 4 keeps the hint's value.
  Pose3 wt = ToolPose(m, wrist);
  Joints whint = wrist;
  whint[3] = -0.9;
  IkSolutions ws = SolveToolIk(m, wt, whint);
  bool kept = false;
  for (int i = 0; i < ws.count; ++i) {
    EXPECT_LT(PoseError(ToolPose(m, ws.solutions[i].q), wt), 1e-9);
    if (std::abs(ws.solutions[i].q[3] + 0.9) < 1e-12) kept = true;
  }
  EXPECT_TRUE(kept);
}

}  // namespace
}  // namespace teachsim::robot
