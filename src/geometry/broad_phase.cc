#include "teachsim/geometry/broad_phase.h"

#include <algorithm>

namespace teachsim::geometry {

int BroadPhase::Add(const Aabb& box) {
  boxes_.push_back(box);
  order_.push_back(static_cast<int>(boxes_.size()) - 1);
  dirty_ = true;
  return static_cast<int>(boxes_.size()) - 1;
}

void BroadPhase::Update(int id, const Aabb& box) {
  boxes_[static_cast<std::size_t>(id)] = box;
  dirty_ = true;
}

void BroadPhase::Sort() {
  if (!dirty_) return;
  // Sweep along the axis with the largest spread of box centres.
  Aabb centres;
  for (const Aabb& b : boxes_) centres.Extend(b.Center());
  int axis = 0;
  if (!boxes_.empty()) centres.Size().maxCoeff(&axis);
  if (axis != axis_) {
    axis_ = axis;
    std::sort(order_.begin(), order_.end(), [&](int a, int b) { return boxes_[a].min[axis_] < boxes_[b].min[axis_]; });
  } else {
    // Insertion sort: nearly sorted after small motions.
    for (std::size_t i = 1; i < order_.size(); ++i) {
      int id = order_[i];
      double key = boxes_[id].min[axis_];
      std::size_t j = i;
      while (j > 0 && boxes_[order_[j - 1]].min[axis_] > key) {
        order_[j] = order_[j - 1];
        --j;
      }
      order_[j] = id;
    }
  }
  dirty_ = false;
}

void BroadPhase::Query(const Aabb& box, std::vector<int>* out) {
  Sort();
  out->clear();
  for (int id : order_) {
    if (boxes_[id].min[axis_] > box.max[axis_]) break;
    if (boxes_[id].Overlaps(box)) out->push_back(id);
  }
  std::sort(out->begin(), out->end());
}

void BroadPhase::Pairs(std::vector<std::pair<int, int>>* out) {
  Sort();
  out->clear();
  for (std::size_t i = 0; i < order_.size(); ++i) {
    const Aabb& a = boxes_[order_[i]];
    for (std::size_t j = i + 1; j < order_.size(); ++j) {
      const Aabb& b = boxes_[order_[j]];
      if (b.min[axis_] > a.max[axis_]) break;
      if (a.Overlaps(b)) out->emplace_back(std::minmax(order_[i], order_[j]));
    }
  }
  std::sort(out->begin(), out->end());
}

}  // namespace teachsim::geometry
