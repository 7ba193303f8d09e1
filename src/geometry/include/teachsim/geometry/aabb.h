// Axis-aligned bounding boxes in the world frame.
#pragma once

#include <Eigen/Core>
#include <limits>

namespace teachsim::geometry {

struct Aabb {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d max = Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity());

  bool IsEmpty() const { return (min.array() > max.array()).any(); }
  void Extend(const Eigen::Vector3d& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  void Extend(const Aabb& other) {
    min = min.cwiseMin(other.min);
    max = max.cwiseMax(other.max);
  }
  Aabb Inflated(double margin) const {
    return {min - Eigen::Vector3d::Constant(margin), max + Eigen::Vector3d::Constant(margin)};
  }
  bool Overlaps(const Aabb& o) const {
    return (min.array() <= o.max.array()).all() && (o.min.array() <= max.array()).all();
  }
  // Lower bound on the distance between anything inside the two boxes.
  double Distance(const Aabb& o) const {
    Eigen::Vector3d gap = (o.min - max).cwiseMax(min - o.max).cwiseMax(0.0);
    return gap.norm();
  }
  Eigen::Vector3d Center() const { return 0.5 * (min + max); }
  Eigen::Vector3d Size() const { return max - min; }
};

}  // namespace teachsim::geometry
