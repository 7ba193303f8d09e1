// Time of impact by conservative advancement (Mirtich 1996): a body moving from pose `start` to
// pose `end` (Interpolate(): linear origin, slerp rotation) first comes within `target_distance`
// of a fixed obstacle at the returned t. Each advance is bounded by the body's largest possible
// approach speed, so no thickness is ever tunnelled through.
#pragma once

#include "teachsim/geometry/convex.h"
#include "teachsim/geometry/distance.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/geometry/shape.h"

namespace teachsim::geometry {

struct ToiOptions {
  double target_distance_m = 0.0;   // stop when the distance drops to this
  double tolerance_m = 1e-6;        // the result's distance lies in [target, target + tolerance]
  int max_iterations = 200;
};

struct ToiResult {
  bool hit = false;        // the distance reaches target within t in [0, 1]
  double t = 1.0;          // first time it does (1 when !hit)
  double distance = 0.0;   // distance at t (certified lower bound)
  int iterations = 0;
  bool started_below = false;  // the distance at t = 0 was already below target
};

ToiResult TimeOfImpact(const ConvexPolyhedron& moving, const Pose3& start, const Pose3& end,
                       const ConvexPolyhedron& obstacle, const Pose3& world_T_obstacle,
                       const ToiOptions& options, DistanceCache* cache = nullptr);

// The same for unions of convex parts: the earliest impact over all part pairs.
ToiResult TimeOfImpact(const Shape& moving, const Pose3& start, const Pose3& end, const Shape& obstacle,
                       const Pose3& world_T_obstacle, const ToiOptions& options);

// Smallest distance between two shapes (over part pairs, AABB-culled beyond `max_distance`);
// returns +inf when every pair is farther than max_distance.
DistanceResult ShapeDistance(const Shape& a, const Pose3& world_T_a, const Shape& b, const Pose3& world_T_b,
                             double max_distance = 1e300, int* part_a = nullptr, int* part_b = nullptr);

}  // namespace teachsim::geometry
