// Broad phase: sweep and prune over world AABBs along the axis of largest spread, kept sorted by
// insertion sort between updates (objects move a little each step, so the sort is nearly free).
#pragma once

#include <utility>
#include <vector>

#include "teachsim/geometry/aabb.h"

namespace teachsim::geometry {

class BroadPhase {
 public:
  // Adds a proxy and returns its id (ids are dense: 0, 1, 2, ...).
  int Add(const Aabb& box);
  void Update(int id, const Aabb& box);
  int size() const { return static_cast<int>(boxes_.size()); }
  const Aabb& box(int id) const { return boxes_[static_cast<std::size_t>(id)]; }

  // Ids whose boxes overlap `box`, ascending. Appends to *out after clearing it.
  void Query(const Aabb& box, std::vector<int>* out);
  // All overlapping pairs (i < j), sorted.
  void Pairs(std::vector<std::pair<int, int>>* out);

 private:
  void Sort();
  std::vector<Aabb> boxes_;
  std::vector<int> order_;  // ids sorted by box min along axis_
  int axis_ = 0;
  bool dirty_ = true;
};

}  // namespace teachsim::geometry
