#include <gtest/gtest.h>

#include <set>

#include "teachsim/geometry/broad_phase.h"
#include "teachsim/geometry/convex.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/geometry/shape.h"
#include "tests/random_poses.h"

namespace teachsim::geometry {
namespace {

TEST(Convex, BoxHasSixQuadsTwelveEdgesAndOutwardNormals) {
  auto box = ConvexPolyhedron::Box({0.09, 0.045, 0.03}).value();
  EXPECT_EQ(box.vertices().size(), 8u);
  EXPECT_EQ(box.faces().size(), 6u);
  EXPECT_EQ(box.edges().size(), 12u);
  for (const Face& f : box.faces()) {
    ASSERT_EQ(f.vertices.size(), 4u);
    // Counter-clockwise seen from outside: the loop's normal agrees with the face normal.
    Eigen::Vector3d a = box.vertices()[f.vertices[0]], b = box.vertices()[f.vertices[1]], c = box.vertices()[f.vertices[2]];
    EXPECT_GT((b - a).cross(c - b).dot(f.normal), 0.0);
    for (int v : f.vertices) EXPECT_NEAR(f.normal.dot(box.vertices()[v]), f.offset, 1e-15);
  }
  for (const Edge& e : box.edges()) EXPECT_NE(e.f0, e.f1);
  EXPECT_NEAR(box.Volume(), 0.09 * 0.045 * 0.03, 1e-15);
  EXPECT_NEAR(box.min_thickness(), 0.03, 1e-15);
  EXPECT_FALSE(ConvexPolyhedron::Box({0.1, -0.02, 0.1}).ok());
}

TEST(Convex, HullMergesCoplanarFacetsAndDropsInteriorPoints) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 8; ++i) points.emplace_back((i & 1) ? 0.02 : -0.02, (i & 2) ? 0.03 : -0.03, (i & 4) ? 0.01 : -0.01);
  points.emplace_back(0.0, 0.0, 0.0);     // interior
  points.emplace_back(0.0, 0.0, 0.01);    // inside the top face
  points.emplace_back(0.02, 0.0, 0.0);    // inside a side face
  auto hull = ConvexPolyhedron::Hull(points).value();
  EXPECT_EQ(hull.vertices().size(), 8u);
  EXPECT_EQ(hull.faces().size(), 6u);
  EXPECT_NEAR(hull.Volume(), 0.04 * 0.06 * 0.02, 1e-15);
}

TEST(Convex, HullOfRandomPointsIsClosedAndContainsThemAll) {
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    auto points = testing::RandomConvexPoints(rng, 40, 0.03);
    auto hull = ConvexPolyhedron::Hull(points).value();
    const int v = static_cast<int>(hull.vertices().size()), e = static_cast<int>(hull.edges().size()),
              f = static_cast<int>(hull.faces().size());
    EXPECT_EQ(v - e + f, 2);  // Euler
    for (const Eigen::Vector3d& p : points) {
      for (const Face& face : hull.faces()) EXPECT_LE(face.normal.dot(p) - face.offset, 1e-10);
    }
    // Support agrees between scan and hill climb.
    for (int k = 0; k < 50; ++k) {
      Eigen::Vector3d d = testing::RandomUnit(rng);
      int scan = hull.Support(d), climb = hull.Support(d, k % v);
      EXPECT_NEAR(hull.vertices()[scan].dot(d), hull.vertices()[climb].dot(d), 1e-15);
    }
  }
}

TEST(Convex, HullRejectsDegenerateInput) {
  EXPECT_FALSE(ConvexPolyhedron::Hull({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}).ok());
  EXPECT_FALSE(ConvexPolyhedron::Hull({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}).ok());  // coplanar
  EXPECT_FALSE(ConvexPolyhedron::Hull({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, NAN}}).ok());
}

TEST(Pose, ComposesInvertsAndInterpolates) {
  std::mt19937_64 rng(2);
  for (int i = 0; i < 100; ++i) {
    Pose3 a(testing::RandomRotation(rng), testing::RandomUnit(rng));
    Pose3 b(testing::RandomRotation(rng), testing::RandomUnit(rng));
    Eigen::Vector3d p = testing::RandomUnit(rng);
    EXPECT_LT(((a * b) * p - a * (b * p)).norm(), 1e-14);
    EXPECT_LT((a.Inverse() * (a * p) - p).norm(), 1e-14);
    EXPECT_LT(TranslationDistance(Interpolate(a, b, 0.0), a) + RotationAngle(Interpolate(a, b, 1.0), b), 1e-12);
    EXPECT_NEAR(RotationAngle(a, Interpolate(a, b, 0.5)), 0.5 * RotationAngle(a, b), 1e-9);
  }
}

TEST(Pose, JsonRoundTripAndErrors) {
  Pose3 pose = Pose3::FromAxisAngle({1, 2, 3}, 0.7, {0.1, -0.2, 0.3});
  Pose3 back = ReadPose(json::Reader(WritePose(pose)));
  EXPECT_LT(TranslationDistance(pose, back) + RotationAngle(pose, back), 1e-15);
  json::Json bad = {{"position", {0, 0, 0}}, {"quaternion_wxyz", {0, 0, 0, 2}}};
  try {
    ReadPose(json::Reader(bad, "pose"));
    FAIL() << "expected a ParseError";
  } catch (const json::ParseError& e) {
    EXPECT_STREQ(e.what(), "pose.quaternion_wxyz: must be a unit quaternion [w, x, y, z], got norm 2");
  }
}

TEST(BroadPhase, PairsAndQueriesMatchBruteForceAcrossUpdates) {
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-0.5, 0.5), s(0.01, 0.08);
  BroadPhase bp;
  std::vector<Aabb> boxes;
  for (int i = 0; i < 100; ++i) {
    Eigen::Vector3d c(u(rng), u(rng), 0.2 * u(rng)), h(s(rng), s(rng), s(rng));
    boxes.push_back({c - h, c + h});
    bp.Add(boxes.back());
  }
  for (int round = 0; round < 20; ++round) {
    std::vector<std::pair<int, int>> pairs, expected;
    bp.Pairs(&pairs);
    for (int i = 0; i < 100; ++i) {
      for (int j = i + 1; j < 100; ++j) {
        if (boxes[i].Overlaps(boxes[j])) expected.emplace_back(i, j);
      }
    }
    ASSERT_EQ(pairs, expected) << "round " << round;
    std::vector<int> hits, expected_hits;
    Aabb probe{Eigen::Vector3d(-0.1, -0.1, -0.1), Eigen::Vector3d(0.1, 0.1, 0.1)};
    bp.Query(probe, &hits);
    for (int i = 0; i < 100; ++i) {
      if (boxes[i].Overlaps(probe)) expected_hits.push_back(i);
    }
    ASSERT_EQ(hits, expected_hits);
    for (int i = 0; i < 100; ++i) {  // small motions
      Eigen::Vector3d d(0.02 * u(rng), 0.02 * u(rng), 0.0);
      boxes[i] = {boxes[i].min + d, boxes[i].max + d};
      bp.Update(i, boxes[i]);
    }
  }
}

}  // namespace
}  // namespace teachsim::geometry
