#include "teachsim/geometry/toi.h"

#include <gtest/gtest.h>

#include "tests/random_poses.h"

namespace teachsim::geometry {
namespace {

// A 0.2 mm plate crossed by a 45 mm cube at 1 m/s in one 0.1 s step (100 mm): conservative
// advancement stops before it, at the target distance, from any direction.
TEST(TimeOfImpact, ThinPlateIsNeverTunnelled) {
  const ConvexPolyhedron plate = ConvexPolyhedron::Box({0.2, 0.2, 0.0002}).value();
  const ConvexPolyhedron cube = ConvexPolyhedron::Box({0.045, 0.045, 0.045}).value();
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const ToiOptions options{.target_distance_m = 1e-4, .tolerance_m = 1e-6};
  for (int i = 0; i < 200; ++i) {
    Eigen::Vector3d dir = testing::RandomUnit(rng);
    dir.z() = -std::max(0.3, std::abs(dir.z()));  // downward, through the plate
    dir.normalize();
    Eigen::Quaterniond q0 = testing::RandomRotation(rng);
    Eigen::Quaterniond q1 = q0 * Eigen::Quaterniond(Eigen::AngleAxisd(u(rng) * 0.5, testing::RandomUnit(rng)));
    Eigen::Vector3d mid(u(rng) * 0.03, u(rng) * 0.03, 0.0);
    Pose3 start(q0, mid - 0.05 * dir / std::abs(dir.z()) * 1.0);
    start.translation.z() = 0.05;
    Pose3 end(q1, start.translation + dir * (0.1 / std::abs(dir.z())));
    ToiResult r = TimeOfImpact(cube, start, end, plate, Pose3::Identity(), options);
    ASSERT_TRUE(r.hit) << i;
    EXPECT_GE(r.distance, options.target_distance_m - 1e-12);
    EXPECT_LE(r.distance, options.target_distance_m + options.tolerance_m + 1e-12);
    // Sampled densely, the motion up to r.t never comes closer than the target.
    for (int k = 0; k <= 200; ++k) {
      double t = r.t * k / 200.0;
      double d = DistanceBruteForce(cube, Interpolate(start, end, t), plate, Pose3::Identity());
      ASSERT_GE(d, options.target_distance_m - 1e-9) << "sample " << i << " t " << t;
    }
  }
}

TEST(TimeOfImpact, MissesWhenThePathIsClear) {
  const ConvexPolyhedron cube = ConvexPolyhedron::Box({0.045, 0.045, 0.045}).value();
  ToiResult r = TimeOfImpact(cube, Pose3::Translation({0, 0, 0.1}), Pose3::Translation({0.2, 0, 0.1}), cube,
                             Pose3::Identity(), ToiOptions{.target_distance_m = 1e-4});
  EXPECT_FALSE(r.hit);
  EXPECT_EQ(r.t, 1.0);
  EXPECT_NEAR(r.distance, DistanceBruteForce(cube, Pose3::Translation({0.2, 0, 0.1}), cube, Pose3::Identity()), 1e-9);
}

TEST(TimeOfImpact, ReportsAStartBelowTarget) {
  const ConvexPolyhedron cube = ConvexPolyhedron::Box({0.045, 0.045, 0.045}).value();
  ToiResult r = TimeOfImpact(cube, Pose3::Translation({0, 0, 0.04505}), Pose3::Translation({0, 0, 0.1}), cube,
                             Pose3::Identity(), ToiOptions{.target_distance_m = 1e-4});
  EXPECT_TRUE(r.hit);
  EXPECT_TRUE(r.started_below);
  EXPECT_EQ(r.t, 0.0);
}

// Shapes: a frame made of parts, a block rotating while it moves.
TEST(TimeOfImpact, ShapesStopAtTheFirstPartHitWhileRotating) {
  auto wall = std::make_shared<const ConvexPolyhedron>(ConvexPolyhedron::Box({0.02, 0.2, 0.06}).value());
  Shape frame({{wall, Pose3::Translation({0.1, 0, 0.03})}, {wall, Pose3::Translation({-0.1, 0, 0.03})}});
  Shape cube = Shape::Single(ConvexPolyhedron::Box({0.045, 0.045, 0.045}).value());
  Pose3 start = Pose3::Translation({0.0, 0.0, 0.03});
  Pose3 end = Pose3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 0.8, {0.2, 0.0, 0.03});
  ToiOptions options{.target_distance_m = 1e-4, .tolerance_m = 1e-6};
  ToiResult r = TimeOfImpact(cube, start, end, frame, Pose3::Identity(), options);
  ASSERT_TRUE(r.hit);
  DistanceResult d = ShapeDistance(cube, Interpolate(start, end, r.t), frame, Pose3::Identity());
  EXPECT_NEAR(d.distance, r.distance, 1e-9);
  EXPECT_GE(d.distance, 1e-4 - 1e-12);
  EXPECT_LE(d.distance, 1e-4 + 1e-6 + 1e-12);
  for (int k = 0; k < 100; ++k) {
    double t = r.t * k / 100.0;
    EXPECT_GE(ShapeDistance(cube, Interpolate(start, end, t), frame, Pose3::Identity()).distance, 1e-4 - 1e-12);
  }
}

}  // namespace
}  // namespace teachsim::geometry
