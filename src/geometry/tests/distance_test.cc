#include "teachsim/geometry/distance.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <map>

#include "tests/random_poses.h"

namespace teachsim::geometry {
namespace {

using testing::MakeMotion;
using testing::MakePoses;
using testing::PoseSet;

ConvexPolyhedron Box(double x, double y, double z) { return ConvexPolyhedron::Box({x, y, z}).value(); }

// Poses per set in the two 10^5-pose tests. The sanitizer build (about 17 times slower here) checks
// the same code on a sixth of them; the release build checks the count.
bool SanitizerBuild() { return std::getenv("TEACHSIM_SANITIZER_BUILD") != nullptr; }
int PosesPerSet() { return SanitizerBuild() ? 3000 : 17000; }
int PosesInAll() { return SanitizerBuild() ? 15000 : 100000; }

struct Stats {
  double max_over = 0.0;   // reported - oracle, > 0 means over-estimate
  double max_under = 0.0;  // oracle - reported
  int count = 0;
  int exhaustive = 0;  // queries GJK handed to the exhaustive pass
};

Stats Check(const ConvexPolyhedron& a, const ConvexPolyhedron& b, const std::vector<testing::PosePair>& poses,
            bool warm) {
  Stats s;
  DistanceCache cache;
  for (const auto& p : poses) {
    DistanceResult d = Distance(a, p.a, b, p.b, warm ? &cache : nullptr);
    double oracle = DistanceBruteForce(a, p.a, b, p.b);
    EXPECT_FALSE(d.intersecting);
    s.exhaustive += d.exhaustive ? 1 : 0;
    s.max_over = std::max(s.max_over, d.distance - oracle);
    s.max_under = std::max(s.max_under, oracle - d.distance);
    // The witness points lie on the surfaces and are as far apart as the upper bound says.
    EXPECT_NEAR((d.point_b - d.point_a).norm(), d.upper_bound, 1e-12);
    EXPECT_LE(d.distance, d.upper_bound + 1e-15);
    ++s.count;
  }
  return s;
}

// The property: never over-estimate, error <= 1e-9 m against the exhaustive oracle, over
// >= 10^5 poses including near-parallel (tilt <= 0.5 deg) and exactly parallel faces, gaps 1 um..50 mm.
TEST(Distance, BoxBoxMatchesOracleOnRandomNearParallelAndParallelPoses) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  const ConvexPolyhedron bar = Box(0.09, 0.045, 0.045);
  int total = 0;
  for (PoseSet set : {PoseSet::kRandom, PoseSet::kNearParallel, PoseSet::kParallel}) {
    for (int pair = 0; pair < 2; ++pair) {
      const ConvexPolyhedron& b = pair == 0 ? cube : bar;
      auto poses = MakePoses(cube, b, set, PosesPerSet(), 1000 + static_cast<int>(set) * 10 + pair);
      Stats s = Check(cube, b, poses, /*warm=*/false);
      std::printf("set %d pair %d: %d poses, max over-estimate %.3g m, max under-estimate %.3g m, %d exhaustive\n",
                  static_cast<int>(set), pair, s.count, s.max_over, s.max_under, s.exhaustive);
      EXPECT_LE(s.exhaustive, s.count / 1000) << "the fallback must stay rare";
      EXPECT_LE(s.max_over, 1e-9) << "set " << static_cast<int>(set);
      EXPECT_LE(s.max_under, 1e-9) << "set " << static_cast<int>(set);
      total += s.count;
    }
  }
  EXPECT_GE(total, PosesInAll());
}

// How far `point` (world) is from the feature it is reported on.
double OffFeature(const ConvexPolyhedron& p, const Pose3& world_T_p, const Feature& f, const Eigen::Vector3d& point) {
  const Eigen::Vector3d local = world_T_p.Inverse() * point;
  switch (f.type) {
    case Feature::Type::kVertex:
      return (local - p.vertices()[f.index]).norm();
    case Feature::Type::kEdge: {
      const Edge& e = p.edges()[f.index];
      return SegmentSegmentDistance(local, local, p.vertices()[e.v0], p.vertices()[e.v1]);
    }
    case Feature::Type::kFace:
      return std::abs(p.faces()[f.index].normal.dot(local) - p.faces()[f.index].offset);
  }
  return 0.0;
}

// Warm queries, as the simulator makes them: each starts from the cache of the same pair one step
// (0.1 mm, 0.05 deg) earlier. Most are answered by closest-feature tracking (no GJK iteration);
// all must match the oracle as the cold ones do, and report points on their features.
TEST(Distance, WarmQueriesMatchOracleAfterASmallStep) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  const ConvexPolyhedron bar = Box(0.09, 0.045, 0.045);
  std::mt19937_64 rng(99);
  int total = 0;
  for (PoseSet set : {PoseSet::kRandom, PoseSet::kNearParallel, PoseSet::kParallel}) {
    for (int pair = 0; pair < 2; ++pair) {
      const ConvexPolyhedron& b = pair == 0 ? cube : bar;
      const auto poses = MakePoses(cube, b, set, PosesPerSet(), 3000 + static_cast<int>(set) * 10 + pair);
      double max_over = 0.0, max_under = 0.0, max_off = 0.0;
      int tracked = 0;
      for (const auto& p : poses) {
        const Pose3 before = Integrate(
            p.b, Twist{testing::RandomUnit(rng) * 1e-4, testing::RandomUnit(rng) * (0.05 * M_PI / 180.0)}, 1.0);
        DistanceCache cache;
        Distance(cube, p.a, b, before, &cache);
        const DistanceResult d = Distance(cube, p.a, b, p.b, &cache);
        const double oracle = DistanceBruteForce(cube, p.a, b, p.b);
        ASSERT_FALSE(d.intersecting);
        max_over = std::max(max_over, d.distance - oracle);
        max_under = std::max(max_under, oracle - d.distance);
        EXPECT_NEAR((d.point_b - d.point_a).norm(), d.upper_bound, 1e-12);
        max_off = std::max({max_off, OffFeature(cube, p.a, d.feature_a, d.point_a),
                            OffFeature(b, p.b, d.feature_b, d.point_b)});
        tracked += d.iterations == 0 ? 1 : 0;
        ++total;
      }
      std::printf("warm set %d pair %d: max over-estimate %.3g m, max under-estimate %.3g m, %d of %zu by "
                  "feature tracking, points off their features by <= %.3g m\n",
                  static_cast<int>(set), pair, max_over, max_under, tracked, poses.size(), max_off);
      EXPECT_LE(max_over, 1e-9);
      EXPECT_LE(max_under, 1e-9);
      EXPECT_LE(max_off, 1e-9);
      EXPECT_GT(tracked, static_cast<int>(poses.size()) / 2) << "feature tracking answers most warm queries";
    }
  }
  EXPECT_GE(total, PosesInAll());
}

// A cache carried across unrelated poses (a stale or foreign start) still gives the exact answer:
// the tracked features are certified, never trusted.
TEST(Distance, StaleCachesStillMatchOracle) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  const ConvexPolyhedron bar = Box(0.09, 0.045, 0.045);
  for (PoseSet set : {PoseSet::kRandom, PoseSet::kNearParallel, PoseSet::kParallel}) {
    Stats s = Check(cube, bar, MakePoses(cube, bar, set, 5000, 4000 + static_cast<int>(set)), /*warm=*/true);
    EXPECT_LE(s.max_over, 1e-9) << "set " << static_cast<int>(set);
    EXPECT_LE(s.max_under, 1e-9) << "set " << static_cast<int>(set);
  }
}

TEST(Distance, ConvexConvexMatchesOracle) {
  std::mt19937_64 rng(7);
  int total = 0;
  for (int shape = 0; shape < 40; ++shape) {
    std::uniform_int_distribution<int> count(8, 40);
    auto a = ConvexPolyhedron::Hull(testing::RandomConvexPoints(rng, count(rng), 0.03)).value();
    auto b = ConvexPolyhedron::Hull(testing::RandomConvexPoints(rng, count(rng), 0.03)).value();
    auto poses = MakePoses(a, b, PoseSet::kRandom, 100, 2000 + shape);
    Stats s = Check(a, b, poses, false);
    EXPECT_LE(s.max_over, 1e-9);
    EXPECT_LE(s.max_under, 1e-9);
    total += s.count;
  }
  EXPECT_EQ(total, 4000);
}

// Cold box-box queries: the separating axis names a feature pair (a face and the other box's
// extreme vertex, or an edge of each), else each box's extreme vertex is tried against the other
// box's nearest feature; GJK's certificate accepts or refuses the pair. Every kind of accepted
// pair must occur, each matching the oracle with its points on the features it reports.
TEST(Distance, ColdBoxQueriesAreAnsweredByCertifiedFeaturePairs) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  const ConvexPolyhedron bar = Box(0.09, 0.045, 0.045);
  const ConvexPolyhedron plate = Box(0.1, 0.06, 0.015);
  std::map<std::pair<Feature::Type, Feature::Type>, int> by_pair;
  int total = 0, without_gjk = 0;
  for (const ConvexPolyhedron* b : {&cube, &bar, &plate}) {
    std::vector<testing::PosePair> poses = MakePoses(cube, *b, PoseSet::kRandom, 3000, 5000 + total);
    const auto motion = MakeMotion(cube, *b, 1000, 6000 + total);
    poses.insert(poses.end(), motion.begin(), motion.end());
    double max_over = 0.0, max_under = 0.0, max_off = 0.0;
    for (const auto& p : poses) {
      const DistanceResult d = Distance(cube, p.a, *b, p.b);
      const double oracle = DistanceBruteForce(cube, p.a, *b, p.b);
      ASSERT_FALSE(d.intersecting);
      max_over = std::max(max_over, d.distance - oracle);
      max_under = std::max(max_under, oracle - d.distance);
      EXPECT_NEAR((d.point_b - d.point_a).norm(), d.upper_bound, 1e-12);
      max_off = std::max({max_off, OffFeature(cube, p.a, d.feature_a, d.point_a),
                          OffFeature(*b, p.b, d.feature_b, d.point_b)});
      if (d.iterations == 0) {
        ++without_gjk;
        ++by_pair[{d.feature_a.type, d.feature_b.type}];
      }
      ++total;
    }
    EXPECT_LE(max_over, 1e-9);
    EXPECT_LE(max_under, 1e-9);
    EXPECT_LE(max_off, 1e-9);
  }
  std::printf("%d of %d cold box-box queries answered by a certified feature pair without GJK\n", without_gjk,
              total);
  EXPECT_GT(without_gjk, total * 3 / 4);
  using T = Feature::Type;
  for (const auto& pair : {std::pair{T::kFace, T::kVertex}, std::pair{T::kVertex, T::kFace},
                           std::pair{T::kEdge, T::kEdge}, std::pair{T::kVertex, T::kVertex},
                           std::pair{T::kVertex, T::kEdge}, std::pair{T::kEdge, T::kVertex}}) {
    EXPECT_GT(by_pair[pair], 0) << "feature pair " << static_cast<int>(pair.first) << "-"
                                << static_cast<int>(pair.second);
  }
}

// n points on a sphere (a Fibonacci lattice): a hull with exactly n vertices.
std::vector<Eigen::Vector3d> SpherePoints(int n, double radius) {
  std::vector<Eigen::Vector3d> points;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n, r = std::sqrt(1.0 - z * z);
    points.push_back(radius * Eigen::Vector3d(r * std::cos(golden * i), r * std::sin(golden * i), z));
  }
  return points;
}

// Cold hull queries scan a column copy of each hull's vertices, padded to a multiple of four (B's
// placed in A's frame): every vertex count (each remainder mod 4, small and large hulls, a box
// against a hull either way round) gives the oracle's distance and the warm query's answer.
TEST(Distance, ColdHullQueriesMatchOracleForEveryVertexCount) {
  std::mt19937_64 rng(17);
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  int total = 0;
  for (int n : {4, 5, 6, 7, 8, 9, 10, 11, 13, 40, 61, 64}) {
    const ConvexPolyhedron a = ConvexPolyhedron::Hull(SpherePoints(n, 0.02)).value();
    ASSERT_EQ(a.vertices().size(), static_cast<std::size_t>(n));
    const ConvexPolyhedron b =
        ConvexPolyhedron::Hull(testing::RandomConvexPoints(rng, 8 + n % 5, 0.03)).value();
    for (const auto& [first, second] :
         {std::pair{&a, &b}, std::pair{&b, &a}, std::pair{&a, &cube}, std::pair{&cube, &a}}) {
      const auto poses = MakePoses(*first, *second, PoseSet::kRandom, 150, 7000 + total);
      const Stats s = Check(*first, *second, poses, /*warm=*/false);
      EXPECT_LE(s.max_over, 1e-9) << n << " vertices";
      EXPECT_LE(s.max_under, 1e-9) << n << " vertices";
      for (const auto& p : poses) {
        DistanceCache cache;
        const DistanceResult cold = Distance(*first, p.a, *second, p.b, &cache);
        const DistanceResult warm = Distance(*first, p.a, *second, p.b, &cache);  // support by hill climb
        EXPECT_NEAR(cold.distance, warm.distance, 1e-10);
      }
      total += s.count;
    }
  }
  EXPECT_EQ(total, 12 * 4 * 150);
}

TEST(Distance, WarmStartGivesTheColdAnswerInFewerIterations) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  const ConvexPolyhedron bar = Box(0.09, 0.045, 0.045);
  auto motion = MakeMotion(cube, bar, 5000, 11);
  ASSERT_GT(motion.size(), 4000u);
  DistanceCache cache;
  long cold_iterations = 0, warm_iterations = 0;
  for (const auto& p : motion) {
    DistanceResult cold = Distance(cube, p.a, bar, p.b);
    DistanceResult warm = Distance(cube, p.a, bar, p.b, &cache);
    EXPECT_NEAR(cold.distance, warm.distance, 1e-10);
    cold_iterations += cold.iterations;
    warm_iterations += warm.iterations;
  }
  EXPECT_LT(warm_iterations, cold_iterations);
}

TEST(Distance, ReportsClosestFeaturesOfFaceToFaceAndVertexToFace) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  // Parallel faces 1 mm apart: the features on each side include the facing faces or parts of them.
  DistanceResult d = Distance(cube, Pose3::Identity(), cube, Pose3::Translation({0.01, 0.005, 0.046}));
  EXPECT_NEAR(d.distance, 1e-3, 1e-12);
  EXPECT_NEAR(d.normal.z(), 1.0, 1e-12);
  // A corner pointing down onto the top face: B's feature is a vertex, A's a face.
  Eigen::Quaterniond corner_down = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d(-1, -1, -1).normalized(),
                                                                      -Eigen::Vector3d::UnitZ());
  const double half_diagonal = 0.045 * std::sqrt(3.0) / 2.0;
  DistanceResult v = Distance(cube, Pose3::Identity(), cube,
                              Pose3(corner_down, {0.0, 0.0, 0.0225 + half_diagonal + 2e-3}));
  EXPECT_NEAR(v.distance, 2e-3, 1e-12);
  EXPECT_EQ(v.feature_b.type, Feature::Type::kVertex);
  EXPECT_EQ(v.feature_a.type, Feature::Type::kFace);
  EXPECT_NEAR(v.point_a.z(), 0.0225, 1e-12);
}

TEST(Distance, FlagsIntersection) {
  const ConvexPolyhedron cube = Box(0.045, 0.045, 0.045);
  EXPECT_TRUE(Distance(cube, Pose3::Identity(), cube, Pose3::Translation({0.01, 0.02, 0.03})).intersecting);
  EXPECT_FALSE(Distance(cube, Pose3::Identity(), cube, Pose3::Translation({0.0, 0.0, 0.0451})).intersecting);
}

TEST(Distance, SegmentDistanceHandlesParallelAndCrossingSegments) {
  using V = Eigen::Vector3d;
  EXPECT_NEAR(SegmentSegmentDistance(V(0, 0, 0), V(1, 0, 0), V(0.5, 1, 0), V(2, 1, 0)), 1.0, 1e-15);
  EXPECT_NEAR(SegmentSegmentDistance(V(0, 0, 0), V(1, 0, 0), V(0.5, -1, 1), V(0.5, 1, 1)), 1.0, 1e-15);
  EXPECT_NEAR(SegmentSegmentDistance(V(0, 0, 0), V(1, 0, 0), V(2, 0, 0), V(3, 0, 0)), 1.0, 1e-15);
}

}  // namespace
}  // namespace teachsim::geometry
