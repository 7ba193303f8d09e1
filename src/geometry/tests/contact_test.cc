#include "teachsim/geometry/contact.h"

#include <gtest/gtest.h>

#include "tests/random_poses.h"

namespace teachsim::geometry {
namespace {

constexpr double kThreshold = 0.5e-3;  // the paper's contact distance

ConvexPolyhedron Cube() { return ConvexPolyhedron::Box({0.045, 0.045, 0.045}).value(); }
ConvexPolyhedron Slab() { return ConvexPolyhedron::Box({0.2, 0.2, 0.02}).value(); }

ContactSet Contacts(const ConvexPolyhedron& a, const Pose3& pa, const ConvexPolyhedron& b, const Pose3& pb) {
  return ComputeContacts(a, pa, b, pb, Distance(a, pa, b, pb), kThreshold);
}

// A: a slab (table top at z = 0.01); B: the cube above it.
TEST(Contacts, FaceOnFaceGivesTheFourCornersWithACommonNormal) {
  const Pose3 cube_pose = Pose3::FromAxisAngle(Eigen::Vector3d::UnitZ(), 0.3, {0.01, -0.02, 0.01 + 0.0225 + 2e-4});
  ContactSet set = Contacts(Slab(), Pose3::Identity(), Cube(), cube_pose);
  EXPECT_EQ(set.kind, ContactKind::kFaceFace);
  ASSERT_EQ(set.points.size(), 4u);
  for (const ContactPoint& p : set.points) {
    EXPECT_NEAR(p.normal.z(), 1.0, 1e-12);  // from A (slab) toward B (cube)
    EXPECT_NEAR(p.distance, 2e-4, 1e-12);
    EXPECT_NEAR(p.point_a.z(), 0.01, 1e-12);
    EXPECT_NEAR(p.point_b.z(), 0.01 + 2e-4, 1e-12);
  }
}

TEST(Contacts, EdgeOnFaceGivesTwoPoints) {
  // The cube rolled 45 degrees about x rests on one edge.
  const double half_diagonal = 0.045 * std::sqrt(2.0) / 2.0;
  const Pose3 cube_pose = Pose3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI / 4, {0.0, 0.0, 0.01 + half_diagonal + 1e-4});
  ContactSet set = Contacts(Slab(), Pose3::Identity(), Cube(), cube_pose);
  EXPECT_EQ(set.kind, ContactKind::kEdgeFace);
  ASSERT_EQ(set.points.size(), 2u);
  EXPECT_NEAR(std::abs(set.points[0].point_b.x() - set.points[1].point_b.x()), 0.045, 1e-9);
  for (const ContactPoint& p : set.points) EXPECT_NEAR(p.distance, 1e-4, 1e-12);
}

TEST(Contacts, VertexOnFaceGivesOnePoint) {
  Eigen::Quaterniond corner_down = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d(-1, -1, -1).normalized(),
                                                                      -Eigen::Vector3d::UnitZ());
  const double half_diagonal = 0.045 * std::sqrt(3.0) / 2.0;
  ContactSet set = Contacts(Slab(), Pose3::Identity(), Cube(), Pose3(corner_down, {0, 0, 0.01 + half_diagonal + 3e-4}));
  EXPECT_EQ(set.kind, ContactKind::kVertexFace);
  ASSERT_EQ(set.points.size(), 1u);
  EXPECT_NEAR(set.points[0].distance, 3e-4, 1e-12);
}

TEST(Contacts, CrossedEdgesGiveOneEdgeEdgePoint) {
  // Two cubes, each rolled 45 degrees so that an edge points at the other, the edges crossed.
  const double half_diagonal = 0.045 * std::sqrt(2.0) / 2.0;
  const Pose3 lower = Pose3::FromAxisAngle(Eigen::Vector3d::UnitX(), M_PI / 4);
  const Pose3 upper = Pose3::FromAxisAngle(Eigen::Vector3d::UnitY(), M_PI / 4, {0, 0, 2 * half_diagonal + 2e-4});
  ContactSet set = Contacts(Cube(), lower, Cube(), upper);
  EXPECT_EQ(set.kind, ContactKind::kEdgeEdge);
  ASSERT_EQ(set.points.size(), 1u);
  EXPECT_NEAR(set.points[0].distance, 2e-4, 1e-12);
  EXPECT_NEAR(std::abs(set.points[0].normal.z()), 1.0, 1e-9);
}

TEST(Contacts, NothingBeyondTheThreshold) {
  ContactSet set = Contacts(Slab(), Pose3::Identity(), Cube(), Pose3::Translation({0, 0, 0.01 + 0.0225 + 6e-4}));
  EXPECT_EQ(set.kind, ContactKind::kNone);
  EXPECT_TRUE(set.points.empty());
}

// Near-parallel (tilt <= 0.5 deg) and exactly parallel faces within the threshold give face
// contacts (edge-face or face-face), never a spurious edge-edge one; every point is within the threshold.
TEST(Contacts, ParallelAndNearParallelFacesNeverGiveEdgeEdge) {
  const ConvexPolyhedron cube = Cube();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int face_face = 0;
  for (int i = 0; i < 2000; ++i) {
    const double tilt = (i % 2 == 0) ? 0.0 : u(rng) * 0.5 * M_PI / 180.0;
    Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::AngleAxisd(tilt, testing::RandomUnit(rng))) *
                           Eigen::Quaterniond(Eigen::AngleAxisd(u(rng) * M_PI, Eigen::Vector3d::UnitZ()));
    // Lateral offsets up to 10 mm: the facing squares (22.5 mm half-width) always overlap.
    Pose3 pb(q, {u(rng) * 0.01, u(rng) * 0.01, 0.045 + 0.3e-3});
    pb = testing::PlaceAtGap(cube, Pose3::Identity(), cube, pb, 1e-4 + 0.3e-3 * (u(rng) + 1.0) / 2.0);
    ContactSet set = Contacts(cube, Pose3::Identity(), cube, pb);
    ASSERT_NE(set.kind, ContactKind::kEdgeEdge) << "sample " << i;
    ASSERT_FALSE(set.points.empty());
    if (set.kind == ContactKind::kFaceFace) ++face_face;
    for (const ContactPoint& p : set.points) {
      EXPECT_LE(p.distance, kThreshold);
      EXPECT_GT(p.normal.z(), 0.999);
    }
  }
  EXPECT_GT(face_face, 1500);
}

// Every contact point's distance matches the real gap between its two points, which lie on the
// surfaces: the point on B is at least the exact distance from A.
TEST(Contacts, PointsAreConsistentWithTheExactDistanceOnRandomPoses) {
  const ConvexPolyhedron cube = Cube();
  const ConvexPolyhedron bar = ConvexPolyhedron::Box({0.09, 0.045, 0.045}).value();
  std::mt19937_64 rng(5);
  int with_contacts = 0;
  for (int i = 0; i < 3000; ++i) {
    Pose3 pa(testing::RandomRotation(rng), Eigen::Vector3d::Zero());
    Pose3 pb(testing::RandomRotation(rng), testing::RandomUnit(rng) * 0.08);
    pb = testing::PlaceAtGap(cube, pa, bar, pb, 0.45e-3 * (i % 10 + 1) / 10.0);
    DistanceResult d = Distance(cube, pa, bar, pb);
    if (d.intersecting) continue;
    ContactSet set = ComputeContacts(cube, pa, bar, pb, d, kThreshold);
    ASSERT_FALSE(set.points.empty());
    ++with_contacts;
    for (const ContactPoint& p : set.points) {
      EXPECT_NEAR(p.distance, (p.point_b - p.point_a).dot(p.normal), 1e-12);
      EXPECT_GE(p.distance, d.distance - kFaceAxisSlack - 1e-12);
      EXPECT_LE(p.distance, kThreshold + 1e-12);
      EXPECT_NEAR(p.normal.norm(), 1.0, 1e-12);
    }
  }
  EXPECT_GT(with_contacts, 2900);
}

}  // namespace
}  // namespace teachsim::geometry
