// Random pose sets shared by the geometry tests and the distance benchmark: random box-box,
// near-parallel box-box, exactly parallel box-box, convex-convex, small-motion sequences. Gaps are
// set by moving B along the oracle's normal until the oracle distance matches the target.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "teachsim/geometry/convex.h"
#include "teachsim/geometry/distance.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::geometry::testing {

inline Eigen::Quaterniond RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized();
}

inline Eigen::Vector3d RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized();
}

// A gap log-uniform in [1 um, 50 mm].
inline double RandomGap(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(std::log(1e-6), std::log(50e-3));
  return std::exp(u(rng));
}

// Moves b along the separating direction until the brute-force distance is `gap` (a few Newton steps).
inline Pose3 PlaceAtGap(const ConvexPolyhedron& a, const Pose3& pa, const ConvexPolyhedron& b, Pose3 pb, double gap) {
  for (int i = 0; i < 6; ++i) {
    DistanceResult d = Distance(a, pa, b, pb);
    double oracle = DistanceBruteForce(a, pa, b, pb);
    if (d.intersecting || !std::isfinite(oracle)) {
      pb.translation += 0.05 * (pb.translation - pa.translation).normalized();
      continue;
    }
    if (std::abs(oracle - gap) < 1e-3 * gap) break;
    pb.translation += (gap - oracle) * d.normal;
  }
  return pb;
}

inline std::vector<Eigen::Vector3d> RandomConvexPoints(std::mt19937_64& rng, int count, double radius) {
  std::vector<Eigen::Vector3d> points;
  std::uniform_real_distribution<double> scale(0.6, 1.0);
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d u = RandomUnit(rng);
    points.push_back(radius * scale(rng) * Eigen::Vector3d(u.x(), 0.7 * u.y(), 0.5 * u.z()));
  }
  return points;
}

struct PosePair {
  Pose3 a, b;
};

enum class PoseSet { kRandom, kNearParallel, kParallel };

// Pairs of poses for two polyhedra. Random: any orientations. Near-parallel: B is A's face-to-face
// neighbour tilted by at most 0.5 degrees about a random axis. Parallel: B differs from A by a
// rotation about A's face normal and an offset in the face plane.
inline std::vector<PosePair> MakePoses(const ConvexPolyhedron& a, const ConvexPolyhedron& b, PoseSet set, int count,
                                       std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<PosePair> out;
  out.reserve(static_cast<std::size_t>(count));
  const double reach = a.bounding_radius() + b.bounding_radius();
  while (static_cast<int>(out.size()) < count) {
    Pose3 pa(RandomRotation(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)) * 0.1);
    Pose3 pb;
    if (set == PoseSet::kRandom) {
      pb = Pose3(RandomRotation(rng), pa.translation + RandomUnit(rng) * reach * 1.2);
    } else {
      // Stack B on top of A's +z face (both boxes share the frame up to the perturbation).
      const double tilt = set == PoseSet::kNearParallel ? u(rng) * 0.5 * M_PI / 180.0 : 0.0;
      Eigen::Quaterniond turn(Eigen::AngleAxisd(set == PoseSet::kParallel ? u(rng) * M_PI : u(rng) * 0.05,
                                                Eigen::Vector3d::UnitZ()));
      Eigen::Vector3d axis = RandomUnit(rng);
      Eigen::Quaterniond tilt_q(Eigen::AngleAxisd(tilt, axis));
      const double ha = a.local_bounds().max.z(), hb = -b.local_bounds().min.z();
      Eigen::Vector3d offset(u(rng) * 0.6 * a.local_bounds().max.x(), u(rng) * 0.6 * a.local_bounds().max.y(),
                             ha + hb + 0.01);
      pb = pa * Pose3(tilt_q * turn, offset);
    }
    pb = PlaceAtGap(a, pa, b, pb, RandomGap(rng));
    if (Distance(a, pa, b, pb).intersecting) continue;
    out.push_back({pa, pb});
  }
  return out;
}

// A sequence of poses of B moving a little (0.1 mm, 0.05 deg per step) near A: the warm-start case.
inline std::vector<PosePair> MakeMotion(const ConvexPolyhedron& a, const ConvexPolyhedron& b, int count,
                                        std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Pose3 pa = Pose3::Identity();
  Pose3 pb(RandomRotation(rng), RandomUnit(rng) * (a.bounding_radius() + b.bounding_radius()));
  pb = PlaceAtGap(a, pa, b, pb, 2e-3);
  std::vector<PosePair> out;
  Eigen::Vector3d drift = RandomUnit(rng) * 1e-4;
  Eigen::Vector3d spin = RandomUnit(rng);
  for (int i = 0; i < count; ++i) {
    Pose3 next = Integrate(pb, Twist{drift, spin * (0.05 * M_PI / 180.0)}, 1.0);
    DistanceResult d = Distance(a, pa, b, next);
    if (d.intersecting || d.distance < 1e-4 || d.distance > 5e-2) {
      drift = RandomUnit(rng) * 1e-4;  // turn away from contact or from drifting off
      if (d.intersecting || d.distance < 1e-4) drift = d.normal * 1e-4 + RandomUnit(rng) * 3e-5;
      else drift = -d.normal * 1e-4 + RandomUnit(rng) * 3e-5;
      continue;
    }
    pb = next;
    out.push_back({pa, pb});
  }
  return out;
}

}  // namespace teachsim::geometry::testing
