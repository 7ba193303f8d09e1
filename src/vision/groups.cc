// Item 2 of issue 7 (paper §4.1, §7.1): perceptual groups of connected segments and their index
// vectors; and the box model's geometry the other stages share.
#include <algorithm>
#include <cmath>
#include <limits>

#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

Eigen::Vector3d BoxVertex(const Eigen::Vector3d& size_m, int i) {
  return {(i & 1 ? 0.5 : -0.5) * size_m.x(), (i & 2 ? 0.5 : -0.5) * size_m.y(), (i & 4 ? 0.5 : -0.5) * size_m.z()};
}

namespace {

// Which faces look at the camera: bit f for face f (-x, +x, -y, +y, -z, +z).
int FrontFaces(const Eigen::Vector3d& size_m, const Eigen::Vector3d& c) {
  int mask = 0;
  for (int axis = 0; axis < 3; ++axis) {
    if (c[axis] < -0.5 * size_m[axis]) mask |= 1 << (2 * axis);
    if (c[axis] > 0.5 * size_m[axis]) mask |= 1 << (2 * axis + 1);
  }
  return mask;
}

// The two faces beside edge e.
std::array<int, 2> EdgeFaces(int e) {
  const int axis = e / 4;  // the edge runs along this axis
  const int v = kBoxEdges[e][0];
  std::array<int, 2> faces{};
  int n = 0;
  for (int other = 0; other < 3; ++other) {
    if (other == axis) continue;
    faces[n++] = 2 * other + ((v >> other) & 1);
  }
  return faces;
}

}  // namespace

uint16_t VisibleBoxEdges(const Eigen::Vector3d& size_m, const Eigen::Vector3d& camera_in_object) {
  const int front = FrontFaces(size_m, camera_in_object);
  uint16_t mask = 0;
  for (int e = 0; e < 12; ++e) {
    const auto f = EdgeFaces(e);
    if ((front >> f[0] & 1) || (front >> f[1] & 1)) mask |= static_cast<uint16_t>(1 << e);
  }
  return mask;
}

uint16_t OutlineBoxEdges(const Eigen::Vector3d& size_m, const Eigen::Vector3d& camera_in_object) {
  const int front = FrontFaces(size_m, camera_in_object);
  uint16_t mask = 0;
  for (int e = 0; e < 12; ++e) {
    const auto f = EdgeFaces(e);
    if ((front >> f[0] & 1) != (front >> f[1] & 1)) mask |= static_cast<uint16_t>(1 << e);
  }
  return mask;
}

int GroupSegments(GroupKind kind) { return kind == GroupKind::kChain4 ? 4 : 3; }
int GroupDimension(GroupKind kind) { return kind == GroupKind::kChain4 ? 6 : 4; }

// Length ratios are less reliable than angles (occlusion and junction placement shorten
// segments), so they count half.
constexpr double kRatioWeight = 0.5;

std::vector<float> IndexVector(const Group& group) {
  std::vector<float> v;
  if (group.kind == GroupKind::kFork3) {
    Eigen::Vector2d u[3];
    for (int k = 0; k < 3; ++k) u[k] = group.points[k + 1] - group.points[0];
    for (int k = 0; k < 2; ++k) {
      double a = std::atan2(Cross2(u[k], u[k + 1]), u[k].dot(u[k + 1]));
      if (a < 0) a += 2 * M_PI;
      v.push_back(static_cast<float>(a));
    }
    for (int k = 1; k < 3; ++k) {
      v.push_back(static_cast<float>(kRatioWeight * std::log(u[k].norm() / std::max(u[0].norm(), 1e-9))));
    }
    return v;
  }
  const int n = GroupSegments(group.kind);
  Eigen::Vector2d d[4];
  for (int k = 0; k < n; ++k) d[k] = group.points[k + 1] - group.points[k];
  for (int k = 1; k < n; ++k) v.push_back(static_cast<float>(std::atan2(Cross2(d[k - 1], d[k]), d[k - 1].dot(d[k]))));
  for (int k = 1; k < n; ++k) {
    v.push_back(static_cast<float>(kRatioWeight * std::log(std::max(d[k].norm(), 1e-9) / std::max(d[k - 1].norm(), 1e-9))));
  }
  return v;
}

namespace {

struct Junction {
  int segment = 0, end = 0;  // the other segment and which of its ends (0: a, 1: b)
  Eigen::Vector2d point;     // where the two lines meet, px
};

}  // namespace

std::vector<LineJunction> FindJunctions(const std::vector<ImageLine>& lines, double junction_gap_px,
                                        const std::vector<char>& considered) {
  const int n = static_cast<int>(lines.size());
  const double min_sin = std::sin(15.0 * M_PI / 180);
  std::vector<char> part(static_cast<size_t>(n));  // the lines that take part
  for (int i = 0; i < n; ++i) {
    const ImageLine& l = lines[static_cast<size_t>(i)];
    part[static_cast<size_t>(i)] =
        (considered.empty() || considered[static_cast<size_t>(i)] != 0) && l.a.allFinite() && l.b.allFinite();
  }
  auto take_part = [&](int i) { return part[static_cast<size_t>(i)] != 0; };
  std::vector<Eigen::Vector2d> dir(static_cast<size_t>(n));
  std::vector<double> length(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    dir[static_cast<size_t>(i)] =
        (lines[static_cast<size_t>(i)].b - lines[static_cast<size_t>(i)].a).normalized();
    length[static_cast<size_t>(i)] = lines[static_cast<size_t>(i)].Length();
  }
  // Two ends meet only within twice the gap, and the gap of lines i and j is at most
  // max(junction_gap_px, a quarter of line i): the lines with an end that near one of line i's are
  // found in a grid of the ends (cells of twice the junction gap), not by testing every pair (an
  // image of 800 lines has 320,000 pairs and a few hundred junctions).
  const double cell = 2 * std::max(junction_gap_px, 1.0);
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (int i = 0; i < n; ++i) {
    if (!take_part(i)) continue;
    lo = lo.cwiseMin(lines[static_cast<size_t>(i)].a).cwiseMin(lines[static_cast<size_t>(i)].b);
    hi = hi.cwiseMax(lines[static_cast<size_t>(i)].a).cwiseMax(lines[static_cast<size_t>(i)].b);
  }
  std::vector<LineJunction> out;
  if (!(lo.x() <= hi.x())) return out;
  // At most 1001 cells a side, and not many more cells than ends: a far-flung end makes the cells
  // larger, never the grid. Cell indices are clamped to the grid (a huge or infinite reach, or
  // cells made infinite by ends ~1e308 apart, falls into the border or the one cell).
  int ends = 0;
  for (int i = 0; i < n; ++i) ends += take_part(i) ? 2 : 0;
  const Eigen::Vector2d extent = hi - lo;
  const double cell_px =
      std::max({cell, extent.maxCoeff() / 1000, std::sqrt(extent.x() * extent.y() / (4.0 * ends))});
  auto clamped = [](double c, int cells) {
    return !(c > 0) ? 0 : c >= cells - 1 ? cells - 1 : static_cast<int>(c);
  };
  const int nx = clamped(std::floor(extent.x() / cell_px), 1001) + 1;
  const int ny = clamped(std::floor(extent.y() / cell_px), 1001) + 1;
  auto cell_of = [&](double v, double origin, int cells) {
    return clamped(std::floor((v - origin) / cell_px), cells);
  };
  // The ends in each cell (line indices), compressed rows.
  std::vector<int> first(static_cast<size_t>(nx) * ny + 1, 0);
  std::vector<int> members;
  auto cell_index = [&](const Eigen::Vector2d& p) {
    return static_cast<size_t>(cell_of(p.y(), lo.y(), ny)) * nx +
           static_cast<size_t>(cell_of(p.x(), lo.x(), nx));
  };
  for (int i = 0; i < n; ++i) {
    if (!take_part(i)) continue;
    for (int e = 0; e < 2; ++e) ++first[cell_index(LineEnd(lines[static_cast<size_t>(i)], e)) + 1];
  }
  for (size_t c = 1; c < first.size(); ++c) first[c] += first[c - 1];
  members.resize(static_cast<size_t>(first.back()));
  {
    std::vector<int> fill(first.begin(), first.end() - 1);
    for (int i = 0; i < n; ++i) {
      if (!take_part(i)) continue;
      for (int e = 0; e < 2; ++e)
        members[static_cast<size_t>(fill[cell_index(LineEnd(lines[static_cast<size_t>(i)], e))]++)] = i;
    }
  }

  std::vector<int> near;
  for (int i = 0; i < n; ++i) {
    if (!take_part(i)) continue;
    const Eigen::Vector2d di = dir[static_cast<size_t>(i)];
    // The lines j > i with an end within 2 max(junction gap, quarter of line i) of one of i's ends
    // (a pixel more, against rounding), ascending: the pairs in the order of a loop over all.
    const double reach = 2 * std::max(junction_gap_px, 0.25 * length[static_cast<size_t>(i)]) + 1;
    near.clear();
    for (int ei = 0; ei < 2; ++ei) {
      const Eigen::Vector2d p = LineEnd(lines[static_cast<size_t>(i)], ei);
      const int x0 = cell_of(p.x() - reach, lo.x(), nx), x1 = cell_of(p.x() + reach, lo.x(), nx);
      const int y0 = cell_of(p.y() - reach, lo.y(), ny), y1 = cell_of(p.y() + reach, lo.y(), ny);
      for (int y = y0; y <= y1; ++y) {
        const size_t row = static_cast<size_t>(y) * nx;
        for (int k = first[row + static_cast<size_t>(x0)]; k < first[row + static_cast<size_t>(x1) + 1];
             ++k) {
          if (members[static_cast<size_t>(k)] > i) near.push_back(members[static_cast<size_t>(k)]);
        }
      }
    }
    std::sort(near.begin(), near.end());
    near.erase(std::unique(near.begin(), near.end()), near.end());
    for (const int j : near) {
      const Eigen::Vector2d dj = dir[static_cast<size_t>(j)];
      const double s = Cross2(di, dj);
      if (std::abs(s) < min_sin) continue;
      const double gap = std::max(
          junction_gap_px, 0.25 * std::min(length[static_cast<size_t>(i)], length[static_cast<size_t>(j)]));
      for (int ei = 0; ei < 2; ++ei) {
        const Eigen::Vector2d p = LineEnd(lines[static_cast<size_t>(i)], ei);
        for (int ej = 0; ej < 2; ++ej) {
          const Eigen::Vector2d q = LineEnd(lines[static_cast<size_t>(j)], ej);
          if ((p - q).squaredNorm() > 4 * gap * gap) continue;
          // Intersection of the two lines: p + t di = q + u dj.
          const double t = Cross2(q - p, dj) / s;
          const Eigen::Vector2d x = p + t * di;
          if ((x - p).norm() > gap || (x - q).norm() > gap) continue;
          out.push_back({i, ei, j, ej, x});
        }
      }
    }
  }
  return out;
}

std::vector<Group> FindGroups(const std::vector<ImageLine>& lines, const RecognizerOptions& options,
                              int max_groups_per_kind) {
  const int n = static_cast<int>(lines.size());
  // junctions[2 * i + end]: the segment ends meeting segment i's end.
  std::vector<std::vector<Junction>> junctions(static_cast<size_t>(2 * n));
  for (const LineJunction& j : FindJunctions(lines, options.junction_gap_px)) {
    junctions[static_cast<size_t>(2 * j.first + j.first_end)].push_back({j.second, j.second_end, j.point});
    junctions[static_cast<size_t>(2 * j.second + j.second_end)].push_back({j.first, j.first_end, j.point});
  }

  std::vector<Group> groups;
  int counts[kGroupKinds] = {0, 0, 0};
  // Chains: depth-first from each segment in each direction.
  struct Step {
    int segment, entry_end;
    Eigen::Vector2d entry_point;
  };
  std::vector<Step> path;
  auto emit = [&](GroupKind kind) {
    int& count = counts[static_cast<int>(kind)];
    if (count >= max_groups_per_kind) return;
    const int m = static_cast<int>(path.size());
    if (path.front().segment > path.back().segment) return;  // the reversed chain is the same group
    Group g;
    g.kind = kind;
    for (int k = 0; k < m; ++k) {
      g.segments[static_cast<size_t>(k)] = path[static_cast<size_t>(k)].segment;
      g.points[static_cast<size_t>(k)] = path[static_cast<size_t>(k)].entry_point;
    }
    const Step& last = path.back();
    g.points[static_cast<size_t>(m)] = LineEnd(lines[static_cast<size_t>(last.segment)], 1 - last.entry_end);
    groups.push_back(g);
    ++count;
  };
  auto extend = [&](auto&& self) -> void {
    const size_t m = path.size();
    if (m == 3) emit(GroupKind::kChain3);
    if (m == 4) {
      emit(GroupKind::kChain4);
      return;
    }
    const Step& s = path.back();
    for (const Junction& j : junctions[static_cast<size_t>(2 * s.segment + (1 - s.entry_end))]) {
      bool used = false;
      for (const Step& p : path) used = used || p.segment == j.segment;
      if (used) continue;
      path.push_back({j.segment, j.end, j.point});
      self(self);
      path.pop_back();
    }
  };
  for (int i = 0; i < n; ++i) {
    for (int e = 0; e < 2; ++e) {
      path.clear();
      path.push_back({i, e, LineEnd(lines[static_cast<size_t>(i)], e)});
      extend(extend);
    }
  }
  // Forks (Y and arrow junctions): three segment ends meeting pairwise.
  for (int i = 0; i < n; ++i) {
    for (int ei = 0; ei < 2; ++ei) {
      const auto& ji = junctions[static_cast<size_t>(2 * i + ei)];
      for (size_t a = 0; a < ji.size(); ++a) {
        for (size_t b = a + 1; b < ji.size(); ++b) {
          const Junction &x = ji[a], &y = ji[b];
          if (x.segment < i || y.segment < i || x.segment == y.segment) continue;
          const auto& jx = junctions[static_cast<size_t>(2 * x.segment + x.end)];
          const auto it = std::find_if(jx.begin(), jx.end(),
                                       [&](const Junction& z) { return z.segment == y.segment && z.end == y.end; });
          if (it == jx.end()) continue;
          if (counts[static_cast<int>(GroupKind::kFork3)] >= max_groups_per_kind) continue;
          Group g;
          g.kind = GroupKind::kFork3;
          g.points[0] = (x.point + y.point + it->point) / 3.0;
          std::array<std::pair<double, int>, 3> arms;
          const int segs[3] = {i, x.segment, y.segment};
          const int ends[3] = {ei, x.end, y.end};
          Eigen::Vector2d far[3];
          for (int k = 0; k < 3; ++k) {
            far[k] = LineEnd(lines[static_cast<size_t>(segs[k])], 1 - ends[k]);
            const Eigen::Vector2d u = far[k] - g.points[0];
            arms[static_cast<size_t>(k)] = {std::atan2(u.y(), u.x()), k};
          }
          std::sort(arms.begin(), arms.end());
          for (int k = 0; k < 3; ++k) {
            const int src = arms[static_cast<size_t>(k)].second;
            g.segments[static_cast<size_t>(k)] = segs[src];
            g.points[static_cast<size_t>(k + 1)] = far[src];
          }
          groups.push_back(g);
          ++counts[static_cast<int>(GroupKind::kFork3)];
        }
      }
    }
  }
  return groups;
}

}  // namespace teachsim::vision
