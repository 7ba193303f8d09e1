#include "teachsim/geometry/toi.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace teachsim::geometry {

namespace {

// Conservative advancement for one convex part that rides on a moving frame: the part sits at
// frame_T_part in a frame that moves from `start` to `end`. `radius` bounds |frame_T_part * v|
// over the part's vertices: the distance from the moving origin that sets the rotational speed.
//
// Bound: the distance result certifies a plane with normal n that separates the part from the
// obstacle by `d`. A point of the part approaches that plane no faster than n.dp + theta*radius
// per unit t, so the distance cannot drop below target before t + (d - target)/bound.
ToiResult Advance(const ConvexPolyhedron& part, const Pose3& frame_T_part, const Pose3& start, const Pose3& end,
                  double radius, const ConvexPolyhedron& obstacle, const Pose3& world_T_obstacle,
                  const ToiOptions& options, DistanceCache* cache) {
  const Eigen::Vector3d dp = end.translation - start.translation;
  const double theta = start.rotation.angularDistance(end.rotation);
  ToiResult result;
  double t = 0.0;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const Pose3 pose = Interpolate(start, end, t) * frame_T_part;
    const DistanceResult dr = Distance(part, pose, obstacle, world_T_obstacle, cache);
    result.iterations = iteration + 1;
    result.distance = dr.distance;
    result.t = t;
    const double gap = dr.distance - options.target_distance_m;
    if (dr.intersecting || gap < 0.0) {
      result.hit = true;
      result.started_below = iteration == 0;
      return result;
    }
    if (gap <= options.tolerance_m) {
      result.hit = true;
      return result;
    }
    const double bound = std::max(0.0, dr.normal.dot(dp)) + theta * radius;
    if (bound <= 0.0) break;  // moving away from the separating plane for the whole motion
    t += gap / bound;
    if (t >= 1.0) break;
  }
  if (result.iterations >= options.max_iterations && result.t < 1.0) {
    // Not converged within the budget: stopping here is safe (distance >= target at result.t).
    result.hit = true;
    return result;
  }
  const Pose3 pose = end * frame_T_part;
  const DistanceResult dr = Distance(part, pose, obstacle, world_T_obstacle, cache);
  result.t = 1.0;
  result.distance = dr.distance;
  result.hit = false;
  return result;
}

double PartRadius(const ShapePart& part) {
  double r = 0.0;
  for (const Eigen::Vector3d& v : part.convex->vertices()) r = std::max(r, (part.shape_T_part * v).norm());
  return r;
}

}  // namespace

ToiResult TimeOfImpact(const ConvexPolyhedron& moving, const Pose3& start, const Pose3& end,
                       const ConvexPolyhedron& obstacle, const Pose3& world_T_obstacle, const ToiOptions& options,
                       DistanceCache* cache) {
  return Advance(moving, Pose3::Identity(), start, end, moving.bounding_radius(), obstacle, world_T_obstacle,
                 options, cache);
}

ToiResult TimeOfImpact(const Shape& moving, const Pose3& start, const Pose3& end, const Shape& obstacle,
                       const Pose3& world_T_obstacle, const ToiOptions& options) {
  ToiResult earliest;
  earliest.t = 1.0;
  earliest.distance = std::numeric_limits<double>::infinity();
  const double theta = start.rotation.angularDistance(end.rotation);
  for (const ShapePart& mp : moving.parts()) {
    const double radius = PartRadius(mp);
    Aabb swept = mp.convex->WorldBounds(start * mp.shape_T_part);
    swept.Extend(mp.convex->WorldBounds(end * mp.shape_T_part));
    swept = swept.Inflated(theta * radius + options.target_distance_m + options.tolerance_m);
    for (const ShapePart& op : obstacle.parts()) {
      const Pose3 world_T_part = world_T_obstacle * op.shape_T_part;
      if (!swept.Overlaps(op.convex->WorldBounds(world_T_part))) continue;
      ToiResult r = Advance(*mp.convex, mp.shape_T_part, start, end, radius, *op.convex, world_T_part, options,
                            nullptr);
      earliest.iterations += r.iterations;
      if (r.hit && (!earliest.hit || r.t < earliest.t)) {
        earliest.hit = true;
        earliest.t = r.t;
        earliest.distance = r.distance;
        earliest.started_below = r.started_below;
      } else if (!earliest.hit) {
        earliest.distance = std::min(earliest.distance, r.distance);
      }
    }
  }
  return earliest;
}

DistanceResult ShapeDistance(const Shape& a, const Pose3& world_T_a, const Shape& b, const Pose3& world_T_b,
                             double max_distance, int* part_a, int* part_b) {
  DistanceResult best;
  best.distance = std::numeric_limits<double>::infinity();
  best.upper_bound = best.distance;
  for (std::size_t i = 0; i < a.parts().size(); ++i) {
    const ShapePart& pa = a.parts()[i];
    const Pose3 ta = world_T_a * pa.shape_T_part;
    const Aabb box_a = pa.convex->WorldBounds(ta);
    for (std::size_t j = 0; j < b.parts().size(); ++j) {
      const ShapePart& pb = b.parts()[j];
      const Pose3 tb = world_T_b * pb.shape_T_part;
      const double box_gap = box_a.Distance(pb.convex->WorldBounds(tb));
      if (box_gap > max_distance || box_gap >= best.distance) continue;
      DistanceResult r = Distance(*pa.convex, ta, *pb.convex, tb);
      if (r.distance < best.distance || (r.intersecting && !best.intersecting)) {
        best = r;
        if (part_a != nullptr) *part_a = static_cast<int>(i);
        if (part_b != nullptr) *part_b = static_cast<int>(j);
      }
    }
  }
  return best;
}

}  // namespace teachsim::geometry
