// A shape is a union of convex parts, each placed in the shape's frame (a frame is four or more
// boxes). Nested part lists are flattened when the shape is built.
#pragma once

#include <memory>
#include <vector>

#include "teachsim/geometry/aabb.h"
#include "teachsim/geometry/convex.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::geometry {

struct ShapePart {
  std::shared_ptr<const ConvexPolyhedron> convex;
  Pose3 shape_T_part;
};

class Shape {
 public:
  Shape() = default;
  explicit Shape(std::vector<ShapePart> parts);
  static Shape Single(ConvexPolyhedron convex);

  const std::vector<ShapePart>& parts() const { return parts_; }
  bool empty() const { return parts_.empty(); }
  Aabb WorldBounds(const Pose3& world_T_shape) const;
  double bounding_radius() const { return bounding_radius_; }  // about the shape origin
  double min_thickness() const;                                // thinnest part

 private:
  std::vector<ShapePart> parts_;
  double bounding_radius_ = 0.0;
};

}  // namespace teachsim::geometry
