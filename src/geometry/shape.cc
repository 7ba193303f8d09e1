#include "teachsim/geometry/shape.h"

#include <algorithm>
#include <limits>

namespace teachsim::geometry {

Shape::Shape(std::vector<ShapePart> parts) : parts_(std::move(parts)) {
  for (const ShapePart& part : parts_) {
    bounding_radius_ = std::max(bounding_radius_,
                                part.shape_T_part.translation.norm() + part.convex->bounding_radius());
  }
}

Shape Shape::Single(ConvexPolyhedron convex) {
  return Shape({ShapePart{std::make_shared<const ConvexPolyhedron>(std::move(convex)), Pose3::Identity()}});
}

Aabb Shape::WorldBounds(const Pose3& world_T_shape) const {
  Aabb box;
  for (const ShapePart& part : parts_) box.Extend(part.convex->WorldBounds(world_T_shape * part.shape_T_part));
  return box;
}

double Shape::min_thickness() const {
  double thinnest = std::numeric_limits<double>::infinity();
  for (const ShapePart& part : parts_) thinnest = std::min(thinnest, part.convex->min_thickness());
  return thinnest;
}

}  // namespace teachsim::geometry
