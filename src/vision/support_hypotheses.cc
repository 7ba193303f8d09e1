// Support-plane hypotheses: a second source of pose hypotheses beside the model-view index (paper
// §7.1, "several groupings in parallel"). A block at rest stands on one of its faces on a horizontal
// support (the table, a fixed object's top; the model editor rests objects there, §4.3), so its
// pose has 3 DOF per resting face. An image corner (two segments meeting at an L) whose corner point
// lies on the block's bottom or top plane fixes them: the corner back-projects onto that plane,
// each arm is a horizontal edge (its direction on the plane gives the yaw) or the vertical edge
// (pointing along the image of the world's vertical), and the model's edge lengths and the arms'
// directions leave a few poses per corner, which edge support ranks before any fit.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

// Sample points along the visible predicted edges of a box (projected with the lens, straight
// between the projected vertices, or the ends of an edge's part in view), every spacing_px, the
// edges' ends left out, those inside the image. With K, each sample's pin-hole (undistorted) pixel
// too, at the same share along the edge. False when a vertex is behind or next to the camera.
struct OutlineSample {
  Eigen::Vector2d at, normal, pinhole;
};
bool SampleOutline(const Eigen::Vector3d& size_m, const Camera& camera,
                   const geometry::Pose3& camera_T_object, double spacing_px, const Eigen::Matrix3d* K,
                   std::vector<OutlineSample>* samples) {
  samples->clear();
  const uint16_t visible = VisibleBoxEdges(size_m, camera_T_object.Inverse().translation);
  Eigen::Vector3d vertex[8];
  Eigen::Vector2d px[8];
  for (int i = 0; i < 8; ++i) {
    vertex[i] = camera_T_object * BoxVertex(size_m, i);
    const auto p = camera.ProjectFromCamera(vertex[i], 0.05);
    if (!p) return false;
    px[i] = *p;
  }
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const int i0 = kBoxEdges[static_cast<size_t>(e)][0], i1 = kBoxEdges[static_cast<size_t>(e)][1];
    Eigen::Vector2d a = px[i0], b = px[i1];
    Eigen::Vector3d a3 = vertex[i0], b3 = vertex[i1];
    // An edge leaving the camera's view is sampled between its ends in view (Camera::SegmentInView:
    // beyond, the lens model folds far-off points into the picture).
    const auto in_view = camera.SegmentInView(vertex[i0], vertex[i1]);
    if (!in_view) continue;
    if (in_view->first != 0 || in_view->second != 1) {
      a3 = vertex[i0] + in_view->first * (vertex[i1] - vertex[i0]);
      b3 = vertex[i0] + in_view->second * (vertex[i1] - vertex[i0]);
      const auto pa = camera.ProjectFromCamera(a3);
      const auto pb = camera.ProjectFromCamera(b3);
      if (!pa || !pb) continue;
      a = *pa;
      b = *pb;
    }
    const double length = (b - a).norm();
    if (length < 3) continue;
    const Eigen::Vector2d along = (b - a) / length, normal(-along.y(), along.x());
    Eigen::Vector2d pa = Eigen::Vector2d::Zero(), pb = Eigen::Vector2d::Zero();
    if (K != nullptr) pa = (*K * a3).hnormalized(), pb = (*K * b3).hnormalized();
    const int n = std::max(2, static_cast<int>(length / spacing_px));
    for (int i = 0; i < n; ++i) {
      const double u = 0.08 + 0.84 * (i + 0.5) / n;
      const Eigen::Vector2d c = a + u * (b - a);
      if (camera.InImage(c)) samples->push_back({c, normal, pa + u * (pb - pa)});
    }
  }
  return true;
}

// Edge support before any fit: of the sample points (SampleOutline), those with a Canny edge pixel
// within 2 px across whose gradient is across the edge. 0 as soon as `min_score` cannot be reached
// any more (most poses are wrong; the exact score of those is never used).
double QuickSupport(const Eigen::Vector3d& size_m, const Camera& camera,
                    const geometry::Pose3& camera_T_object, const EdgeMap& edge_map, double spacing_px,
                    double min_score) {
  thread_local std::vector<OutlineSample> samples;
  if (!SampleOutline(size_m, camera, camera_T_object, spacing_px, nullptr, &samples)) return 0;
  const int count = static_cast<int>(samples.size());
  if (count < 8) return 0;
  const int needed = static_cast<int>(std::ceil(min_score * count - 1e-9));
  // First the cheap answers: the samples with no edge pixel near (a look at the dilated edges) are
  // unsupported, and a pose whose other samples are too few is done with before any search
  // along a normal (most poses are wrong). Then the search, at the samples that may have support.
  thread_local std::vector<int> maybe;
  maybe.clear();
  for (int i = 0, blank = 0; i < count; ++i) {
    if (!NoEdgeNear(edge_map, samples[static_cast<size_t>(i)].at)) {
      maybe.push_back(i);
    } else if (count - ++blank < needed) {
      return 0;
    }
  }
  int supported = 0;
  for (size_t k = 0; k < maybe.size(); ++k) {
    if (supported + static_cast<int>(maybe.size() - k) < needed) return 0;
    const OutlineSample& sample = samples[static_cast<size_t>(maybe[k])];
    if (EdgeAcross(edge_map, sample.at, sample.normal)) ++supported;
  }
  return static_cast<double>(supported) / count;
}

// A placement short of the support threshold, scored again with the outline on one side of an
// occluding contour across its image left out (RecognizerOptions::occlusion_contours): the support
// of the samples in view (every 3 px), over the contours and sides where at least
// RecognizerOptions::LeastContourShownShare() of the samples are in view, at least
// occlusion_min_hidden_share hidden and at most contour_max_hidden_coverage of the hidden ones supported. -1
// when none reaches support_min_score; else the best side's support times its share in view.
double OccludedPlacementSupport(const Eigen::Vector3d& size_m, const Camera& camera, const Eigen::Matrix3d& K,
                                const geometry::Pose3& camera_T_object, const EdgeMap& edge_map,
                                const std::vector<ImageLine>& contours, const RecognizerOptions& options) {
  std::array<Eigen::Vector2d, 8> px;
  for (int v = 0; v < 8; ++v) {
    const Eigen::Vector3d p = camera_T_object * BoxVertex(size_m, v);
    if (!(p.z() > 0.05)) return -1;
    px[static_cast<size_t>(v)] = (K * p).hnormalized();
  }
  const uint16_t visible = VisibleBoxEdges(size_m, camera_T_object.Inverse().translation);
  thread_local std::vector<ContourOccluder> occlusions;
  // Flanks that end inside the box's image only with support_pole_ends (RecognizerOptions).
  ContourOcclusions(contours, BoxImage(px, visible), &occlusions,
                    {.ends_inside = options.contour_pole_ends && options.support_pole_ends,
                     // measured: no block changed (RecognizerOptions::contour_across_beside)
                     .across_beside = false,
                     // measured: render seeds 7-38, 2 fewer blocks half hidden and 1 more false
                     // detection (docs/benchmarks.md, session 53); the pole's top only in the
                     // occlusion pass (RecognizerOptions::contour_pole_tops)
                     .pole_tops = false,
                     .sides_bounded = options.contour_sides_bounded});
  if (occlusions.empty()) return -1;
  thread_local std::vector<OutlineSample> samples;
  thread_local std::vector<uint8_t> support_state;
  thread_local std::vector<uint8_t> hides;
  thread_local std::vector<double> pinhole_x, pinhole_y;
  // The best side's support in view (and its share in view) at a sample spacing; -1: none passes.
  // A sample's support is looked for only when a side needs it, and a side is left as soon as its
  // hidden samples show too much support, or its samples in view can no longer reach min_score or
  // the best side so far (the bound below is the score with every sample left supported: division
  // and multiplication round monotonically, so it fails only where the whole count would).
  auto best_side = [&](double spacing_px, double min_score, double* shown_share) {
    if (!SampleOutline(size_m, camera, camera_T_object, spacing_px, &K, &samples) || samples.size() < 8)
      return -1.0;
    // Each sample's support: 0 or 1, or kUnknown until looked for; none where the dilated edges
    // show no edge pixel near (NoEdgeNear: EdgeAcross would find none).
    constexpr uint8_t kUnknown = 2;
    const int count = static_cast<int>(samples.size());
    support_state.resize(samples.size());
    for (size_t i = 0; i < samples.size(); ++i)
      support_state[i] = NoEdgeNear(edge_map, samples[i].at) ? 0 : kUnknown;
    hides.resize(samples.size());
    pinhole_x.resize(samples.size());
    pinhole_y.resize(samples.size());
    for (size_t i = 0; i < samples.size(); ++i)
      pinhole_x[i] = samples[i].pinhole.x(), pinhole_y[i] = samples[i].pinhole.y();
    auto support_at = [&](size_t i) {
      if (support_state[i] == kUnknown)
        support_state[i] = EdgeAcross(edge_map, samples[i].at, samples[i].normal);
      return static_cast<int>(support_state[i]);
    };
    double best = -1;
    for (const ContourOccluder& occluder : occlusions) {
      const int hidden = occluder.HidesEach(pinhole_x.data(), pinhole_y.data(), count, hides.data());
      int shown_maybe = 0;  // shown samples that may be supported
      for (size_t i = 0; i < samples.size(); ++i)
        shown_maybe += static_cast<int>(hides[i] == 0) & static_cast<int>(support_state[i] != 0);
      const int shown = count - hidden;
      if (hidden < options.occlusion_min_hidden_share * count ||
          shown < options.LeastContourShownShare() * count)
        continue;
      auto passes = [&](int shown_supported) {
        const double score = static_cast<double>(shown_supported) / shown;
        return score >= min_score && score * shown / count > best * *shown_share;
      };
      if (!passes(shown_maybe)) continue;
      int hidden_supported = 0;
      for (size_t i = 0;
           i < samples.size() && hidden_supported <= options.contour_max_hidden_coverage * hidden; ++i)
        if (hides[i] && support_state[i] != 0) hidden_supported += support_at(i);
      if (hidden_supported > options.contour_max_hidden_coverage * hidden) continue;
      // The bound drops only where a sample turns out unsupported.
      int shown_supported = 0, left = shown_maybe;
      bool short_of_it = false;
      for (size_t i = 0; i < samples.size() && left > 0 && !short_of_it; ++i) {
        if (hides[i] || support_state[i] == 0) continue;
        --left;
        if (support_at(i) != 0) {
          ++shown_supported;
        } else {
          short_of_it = !passes(shown_supported + left);
        }
      }
      if (short_of_it || !passes(shown_supported)) continue;
      best = static_cast<double>(shown_supported) / shown;
      *shown_share = static_cast<double>(shown) / count;
    }
    return best;
  };
  // Coarse samples first (as PlacementSupport), then every 3 px. Ranked as the whole outline would
  // be were the hidden part unsupported: below the placements in full view that support as well.
  double shown_share = 0;
  if (best_side(12, options.support_min_score - 0.1, &shown_share) < 0) return -1;
  shown_share = 0;
  const double best = best_side(3, options.support_min_score, &shown_share);
  return best < 0 ? -1 : best * shown_share;
}

// A placement's edge support as the support hypotheses score it: coarse samples first (most poses
// are wrong and show it anywhere along their outline; the coarse threshold was 0.2 under the fine
// one: at 0.05 under it, the same blocks are found on the renders of seeds 7-9 and the support-plane
// stage takes 12 ms per image instead of 19), then every 3 px. Below options.support_min_score: -1.
double PlacementSupport(const Eigen::Vector3d& size_m, const Camera& camera,
                        const geometry::Pose3& camera_T_object, const EdgeMap& edge_map,
                        const RecognizerOptions& options) {
  const double coarse_min = options.support_min_score - 0.05;
  if (QuickSupport(size_m, camera, camera_T_object, edge_map, 12, coarse_min) < coarse_min) return -1;
  const double score = QuickSupport(size_m, camera, camera_T_object, edge_map, 3, options.support_min_score);
  return score >= options.support_min_score ? score : -1;
}

// Equal poses of a box up to its symmetries (SymmetricRotationAngle: the signs of its axes, and
// quarter turns about an axis whose other two sides are equal), for thinning: a corner of a block
// with a square face gives each pose twice, with the two equal axes swapped.
bool SamePlace(const Model& model, const SupportHypothesis& a, const SupportHypothesis& b, double distance_m) {
  if (a.model != b.model || (a.world_T_object.translation - b.world_T_object.translation).norm() > distance_m) {
    return false;
  }
  return SymmetricRotationAngle(model, a.world_T_object, b.world_T_object) < 10 * M_PI / 180;
}

// JoinCollinearLines: the pieces of one edge are this close to one line and this far apart at most.
constexpr double kCollinearPx = 1.5, kCollinearDeg = 3, kJoinGapPx = 40;

// Best first, for stable sorts (equal scores keep the order they were tried in).
bool HigherScore(const SupportHypothesis& a, const SupportHypothesis& b) { return a.score > b.score; }

}  // namespace

JoinedLines JoinCollinearLines(const std::vector<ImageLine>& lines) {
  const int n = static_cast<int>(lines.size());
  std::vector<int> parent(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) parent[static_cast<size_t>(i)] = i;
  auto find = [&](int i) {
    while (parent[static_cast<size_t>(i)] != i) i = parent[static_cast<size_t>(i)] = parent[static_cast<size_t>(parent[static_cast<size_t>(i)])];
    return i;
  };
  const double cos_tol = std::cos(kCollinearDeg * M_PI / 180);
  // Only lines within kCollinearDeg of each other's direction join: the lines go into buckets of
  // their direction (mod 180 deg) wider than that, and each is tested against those of its own
  // bucket and the two beside it, not against every other line (the pairs tried are those of a loop
  // over all pairs that can pass, in the same order). Lines without a direction (shorter than 1e-9
  // px, or not finite) join none.
  constexpr int kBuckets = 45;  // 4 deg each
  static_assert(180.0 / kBuckets > kCollinearDeg);
  std::vector<int> bucket(static_cast<size_t>(n), -1);
  std::vector<std::vector<int>> in_bucket(kBuckets);
  for (int i = 0; i < n; ++i) {
    const ImageLine& l = lines[static_cast<size_t>(i)];
    if (!(l.Length() >= 1e-9) || !l.a.allFinite() || !l.b.allFinite()) continue;
    double angle = std::atan2(l.b.y() - l.a.y(), l.b.x() - l.a.x());  // (-pi, pi]
    if (angle < 0) angle += M_PI;
    const int b = std::min(kBuckets - 1, static_cast<int>(angle / M_PI * kBuckets));
    bucket[static_cast<size_t>(i)] = b;
    in_bucket[static_cast<size_t>(b)].push_back(i);
  }
  std::vector<int> candidates;
  for (int i = 0; i < n; ++i) {
    if (bucket[static_cast<size_t>(i)] < 0) continue;
    const ImageLine& li = lines[static_cast<size_t>(i)];
    const double length_i = li.Length();
    const Eigen::Vector2d di = (li.b - li.a) / length_i;
    candidates.clear();
    for (int step = -1; step <= 1; ++step) {
      for (const int j :
           in_bucket[static_cast<size_t>((bucket[static_cast<size_t>(i)] + step + kBuckets) % kBuckets)]) {
        if (j > i) candidates.push_back(j);
      }
    }
    std::sort(candidates.begin(), candidates.end());
    for (const int j : candidates) {
      const ImageLine& lj = lines[static_cast<size_t>(j)];
      const double length_j = lj.Length();
      if (std::abs(di.dot((lj.b - lj.a) / length_j)) < cos_tol) continue;
      // Each on the other's line (the longer one's line is the better reference).
      const ImageLine& longer = length_i >= length_j ? li : lj;
      const ImageLine& shorter = length_i >= length_j ? lj : li;
      const Eigen::Vector2d dl = (longer.b - longer.a).normalized(), nl(-dl.y(), dl.x());
      if (std::abs(nl.dot(shorter.a - longer.a)) > kCollinearPx || std::abs(nl.dot(shorter.b - longer.a)) > kCollinearPx) continue;
      // The gap between them along the line (negative: they overlap).
      const double ta = di.dot(lj.a - li.a), tb = di.dot(lj.b - li.a);
      const double gap = std::max(std::min(ta, tb) - length_i, -std::max(ta, tb));
      if (gap > kJoinGapPx) continue;
      parent[static_cast<size_t>(find(j))] = find(i);
    }
  }
  JoinedLines out;
  out.representative.assign(static_cast<size_t>(n), -1);
  out.extent = lines;
  std::vector<std::vector<int>> members(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) members[static_cast<size_t>(find(i))].push_back(i);
  for (const std::vector<int>& m : members) {
    if (m.empty()) continue;
    int longest = m[0];
    for (int i : m) {
      if (lines[static_cast<size_t>(i)].Length() > lines[static_cast<size_t>(longest)].Length()) longest = i;
    }
    const ImageLine& l = lines[static_cast<size_t>(longest)];
    const Eigen::Vector2d d = (l.b - l.a).normalized();
    double lo = 0, hi = l.Length();
    for (int i : m) {
      for (const Eigen::Vector2d& p : {lines[static_cast<size_t>(i)].a, lines[static_cast<size_t>(i)].b}) {
        lo = std::min(lo, d.dot(p - l.a));
        hi = std::max(hi, d.dot(p - l.a));
      }
    }
    for (int i : m) out.representative[static_cast<size_t>(i)] = longest;
    out.extent[static_cast<size_t>(longest)] = {l.a + lo * d, l.a + hi * d};
  }
  return out;
}

std::vector<ImageCorner> FindHiddenCorners(const JoinedLines& joined, const std::vector<ImageLine>& contours,
                                           const std::vector<ImageCorner>& corners,
                                           const RecognizerOptions& options) {
  TEACHSIM_CHECK(joined.extent.size() == joined.representative.size());
  const double reach_px = options.hidden_corner_reach_px, max_gap_px = options.hidden_corner_max_gap_px;
  constexpr double kMinSinAngle = 0.34;  // 20 deg
  // The joined edges with an end at a contour that they run into (at 15 deg or more to it): the
  // edge's line, continued past that end, crosses the contour within reach_px of the end.
  struct EndAtContour {
    int line = 0;
    Eigen::Vector2d at, far, direction;  // the end, the other end, unit from far to at
  };
  std::vector<EndAtContour> ends;
  for (size_t l = 0; l < joined.extent.size(); ++l) {
    if (joined.representative[l] != static_cast<int>(l)) continue;
    const ImageLine& line = joined.extent[l];
    const double length = line.Length();
    if (!(length >= 8)) continue;
    for (int end = 0; end < 2; ++end) {
      const Eigen::Vector2d at = LineEnd(line, end), far = LineEnd(line, 1 - end);
      const Eigen::Vector2d d = (at - far) / length;
      for (const ImageLine& contour : contours) {
        const double contour_length = contour.Length();
        if (!(contour_length >= 1e-9)) continue;
        const Eigen::Vector2d c = (contour.b - contour.a) / contour_length, n(-c.y(), c.x());
        const double across = n.dot(d);
        if (std::abs(across) < 0.26) continue;  // within 15 deg of the contour: not into it
        // Where the edge's line meets the contour's, along the edge from its end (px).
        const double t = -n.dot(at - contour.a) / across;
        if (t < -reach_px || t > reach_px) continue;
        const double s = c.dot(at + t * d - contour.a);
        if (s < -reach_px || s > contour_length + reach_px) continue;
        ends.push_back({static_cast<int>(l), at, far, d});
        break;
      }
    }
  }
  std::vector<ImageCorner> out;
  for (size_t x = 0; x < ends.size(); ++x) {
    for (size_t y = x + 1; y < ends.size(); ++y) {
      const EndAtContour& p = ends[x];
      const EndAtContour& q = ends[y];
      if (p.line == q.line) continue;
      const double cross = Cross2(p.direction, q.direction);
      if (std::abs(cross) < kMinSinAngle) continue;
      // p.at + u p.direction = q.at + v q.direction, both beyond the ends.
      const Eigen::Vector2d w = q.at - p.at;
      const double u = Cross2(w, q.direction) / cross;
      const double v = Cross2(w, p.direction) / cross;
      if (u <= reach_px || v <= reach_px || u > max_gap_px || v > max_gap_px) continue;
      bool known = false;
      for (const ImageCorner& c : corners) {
        known = known || (c.segments[0] == p.line && c.segments[1] == q.line) ||
                (c.segments[0] == q.line && c.segments[1] == p.line);
      }
      if (known) continue;
      ImageCorner corner;
      corner.point = p.at + u * p.direction;
      corner.arm_end = {p.far, q.far};
      corner.segments = {p.line, q.line};
      out.push_back(corner);
    }
  }
  return out;
}

std::vector<ImageCorner> FindCorners(const std::vector<ImageLine>& lines, const RecognizerOptions& options) {
  return FindCorners(JoinCollinearLines(lines), options);
}

std::vector<ImageCorner> FindCorners(const JoinedLines& joined, const RecognizerOptions& options) {
  TEACHSIM_CHECK(joined.extent.size() == joined.representative.size());
  const size_t count = joined.representative.size();
  std::vector<char> representative(count);
  for (size_t i = 0; i < count; ++i) representative[i] = joined.representative[i] == static_cast<int>(i);
  std::vector<ImageCorner> corners;
  for (const LineJunction& j : FindJunctions(joined.extent, options.junction_gap_px, representative)) {
    ImageCorner c;
    c.point = j.point;
    c.arm_end = {LineEnd(joined.extent[static_cast<size_t>(j.first)], 1 - j.first_end),
                 LineEnd(joined.extent[static_cast<size_t>(j.second)], 1 - j.second_end)};
    c.segments = {j.first, j.second};
    corners.push_back(c);
  }
  return corners;
}

Eigen::Vector2d UpImageDirection(const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world, const Eigen::Vector2d& px) {
  // d/dt of the projection of P + t up at t = 0, times depth: (K up)_xy - px (K up)_z.
  const Eigen::Vector3d up = K * camera_T_world.Rotate(Eigen::Vector3d::UnitZ());
  const Eigen::Vector2d d = up.head<2>() - px * up.z();
  const double norm = d.norm();
  return norm > 1e-12 ? Eigen::Vector2d(d / norm) : Eigen::Vector2d(0, -1);
}

int VerticalArm(const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world, const Eigen::Vector2d& corner_px,
                const Eigen::Vector2d& arm_end_px, double tolerance_rad) {
  const Eigen::Vector2d up = UpImageDirection(K, camera_T_world, corner_px);
  const Eigen::Vector2d arm = arm_end_px - corner_px;
  const double length = arm.norm();
  if (length < 1e-9) return 0;
  const double cos_angle = up.dot(arm) / length;
  if (std::abs(cos_angle) < std::cos(tolerance_rad)) return 0;
  return cos_angle > 0 ? 1 : -1;
}

bool PlaceSet::Insert(int model, const geometry::Pose3& pose) {
  const Eigen::Vector3d& t = pose.translation;
  std::vector<Eigen::Quaterniond>& rotations =
      places_[{model, std::llround(t.x() * 1e6), std::llround(t.y() * 1e6), std::llround(t.z() * 1e6)}];
  for (const Eigen::Quaterniond& q : rotations) {
    if (SymmetricRotationAngle(models_.models[static_cast<size_t>(model)], geometry::Pose3(q, t), pose) <
        1e-6) {
      return false;
    }
  }
  rotations.push_back(pose.rotation);
  return true;
}

size_t PlaceSet::PlaceHash::operator()(const Place& p) const {
  size_t h = std::hash<long long>()(p.x);
  for (long long v : {p.y, p.z, static_cast<long long>(p.model)})
    h = h * 1000003u ^ std::hash<long long>()(v);
  return h;
}

namespace {

// The resting faces of each model: the up axis and its two horizontal axes, without repeats (a box
// with two equal sides has two resting faces that look alike).
struct Resting {
  int model, up, a, b;
};
std::vector<Resting> RestingFaces(const ModelLibrary& models) {
  std::vector<Resting> resting;
  for (size_t m = 0; m < models.models.size(); ++m) {
    const Eigen::Vector3d& s = models.models[m].box_size_m;
    for (int up = 0; up < 3; ++up) {
      const int a = (up + 1) % 3, b = (up + 2) % 3;
      bool repeat = false;
      for (int prev = 0; prev < up; ++prev) {
        const int pa = (prev + 1) % 3, pb = (prev + 2) % 3;
        const double tol = 1e-6 * s.maxCoeff();
        repeat = repeat || (std::abs(s[prev] - s[up]) < tol &&
                            ((std::abs(s[pa] - s[a]) < tol && std::abs(s[pb] - s[b]) < tol) ||
                             (std::abs(s[pa] - s[b]) < tol && std::abs(s[pb] - s[a]) < tol)));
      }
      if (!repeat) resting.push_back({static_cast<int>(m), up, a, b});
    }
  }
  return resting;
}

// The support planes' geometry as the camera sees it: where a pixel's ray meets a horizontal plane,
// and how far from an image corner a box of the library can reach.
class PlaneView {
 public:
  PlaneView(const ModelLibrary& models, const Camera& camera, const std::vector<SupportPlane>& planes)
      : K_(camera.K()),
        K_inv_(K_.inverse()),
        camera_T_world_(camera.camera_T_world()),
        centre_(camera.world_T_camera().translation),
        world_R_camera_(camera.world_T_camera().RotationMatrix()) {
    for (const Model& m : models.models)
      largest_diagonal_m_ = std::max(largest_diagonal_m_, m.box_size_m.norm());
    for (const SupportPlane& plane : planes)
      highest_m_ = std::max(highest_m_, plane.z_m + largest_diagonal_m_);
  }
  // Where the ray through an undistorted pixel meets the plane z = z_m (in front of the camera).
  std::optional<Eigen::Vector3d> OnPlane(const Eigen::Vector2d& px, double z_m) const {
    const Eigen::Vector3d d = world_R_camera_ * (K_inv_ * Eigen::Vector3d(px.x(), px.y(), 1));
    if (std::abs(d.z()) < 1e-9) return std::nullopt;
    const double t = (z_m - centre_.z()) / d.z();
    if (!(t > 0.05)) return std::nullopt;
    return centre_ + t * d;
  }
  // How far from `px` (undistorted) the image of the largest box that can have a vertex there reaches:
  // its diagonal, at the depth of the highest plane a vertex can lie on, projected by the pin-hole
  // model.
  double ReachPx(const Eigen::Vector2d& px) const {
    const std::optional<Eigen::Vector3d> nearest = OnPlane(px, highest_m_);
    return nearest ? K_(0, 0) * largest_diagonal_m_ / (camera_T_world_ * *nearest).z()
                   : std::numeric_limits<double>::infinity();
  }

 private:
  Eigen::Matrix3d K_, K_inv_;
  geometry::Pose3 camera_T_world_;
  Eigen::Vector3d centre_;
  Eigen::Matrix3d world_R_camera_;
  double largest_diagonal_m_ = 0, highest_m_ = -std::numeric_limits<double>::infinity();
};

// Every placement the corners give: each model on each of its resting faces and each plane, with the corner
// on its bottom or top plane, filtered by the arms' perpendicularity on the plane and their lengths against
// the model's edges, inside the work area and in front of the camera. A placement that two corners (or two
// arms of one) give is visited once (PlaceSet): it is not scored again. visit(h, camera_T_object) receives
// each as a SupportHypothesis whose model, pose, corner and plane are set and whose score is still 0,
// with its pose in the camera frame (computed here for the in-front test: not again by the visitor).
template <typename Visit>
void ForEachPlacement(const ModelLibrary& models, const Camera& camera, const LineDetection& detection,
                      const std::vector<ImageCorner>& corners, const std::vector<SupportPlane>& planes,
                      const RecognizerOptions& options, const PlaneView& view, Visit&& visit) {
  const Eigen::Matrix3d K = camera.K();
  const geometry::Pose3& camera_T_world = camera.camera_T_world();
  const double sin_perpendicular = std::sin(options.support_perpendicular_tol_deg * M_PI / 180);
  const double vertical_tol = options.support_vertical_tol_deg * M_PI / 180;
  constexpr double kLengthSlack = 1.1, kLengthSlackM = 0.004;  // an arm may be this much longer than its edge
  constexpr double kRegionMarginM = 0.01;
  auto project = [&](const Eigen::Vector3d& p_in_world) -> Eigen::Vector2d {
    return (K * (camera_T_world * p_in_world)).hnormalized();
  };
  const std::vector<Resting> resting = RestingFaces(models);
  PlaceSet seen(models);
  // The box with its corner at `corner`, its axis i along u_i (unit, horizontal), j along u_j and
  // the up axis rising (bottom corner) or falling (top corner) from the corner.
  auto emit = [&](const Resting& r, int i, int j, const Eigen::Vector3d& corner, const Eigen::Vector3d& u_i,
                  const Eigen::Vector3d& u_j, bool bottom, int corner_index, int plane_index) {
    const Eigen::Vector3d& s = models.models[static_cast<size_t>(r.model)].box_size_m;
    const Eigen::Vector3d vertical = Eigen::Vector3d::UnitZ() * (bottom ? 1.0 : -1.0);
    Eigen::Matrix3d rotation;
    rotation.col(i) = u_i;
    rotation.col(j) = u_j;
    rotation.col(r.up) = Eigen::Vector3d::UnitZ();
    // The box is symmetric under reflection in its mid-planes: a left-handed frame is the same box
    // with one axis reversed.
    if (rotation.determinant() < 0) rotation.col(r.up) = -rotation.col(r.up);
    const Eigen::Vector3d middle = corner + 0.5 * (s[i] * u_i + s[j] * u_j + s[r.up] * vertical);
    if (middle.head<2>().norm() > options.work_area_radius_m) return;
    SupportHypothesis h;
    h.model = r.model;
    h.world_T_object = geometry::Pose3(Eigen::Quaterniond(rotation).normalized(), middle);
    const geometry::Pose3 camera_T_object = camera_T_world * h.world_T_object;
    if (!(camera_T_object.translation.z() > 0.05) || !seen.Insert(r.model, h.world_T_object)) return;
    h.corner = corner_index;
    h.plane = plane_index;
    visit(h, camera_T_object);
  };

  // In a cluttered image, corners with a thin-line arm propose nothing (RecognizerOptions::
  // support_corner_ridge_share).
  const bool skip_thin_arms = options.support_corner_ridge_share > 0 &&
                              static_cast<int>(corners.size()) >= options.support_corner_ridge_min_corners;
  for (size_t c = 0; c < corners.size(); ++c) {
    const ImageCorner& corner = corners[c];
    if (skip_thin_arms) {
      bool ridge = false;
      for (int k = 0; k < 2 && !ridge; ++k) {
        ridge = LineRidgeShareAtLeast(ImageLine{corner.point, corner.arm_end[static_cast<size_t>(k)]}, camera,
                                      detection.edge_map, options.support_corner_ridge_grey,
                                      options.support_corner_ridge_share);
      }
      if (ridge) continue;
    }
    int vertical[2];
    for (int k = 0; k < 2; ++k)
      vertical[k] =
          VerticalArm(K, camera_T_world, corner.point, corner.arm_end[static_cast<size_t>(k)], vertical_tol);
    for (size_t p = 0; p < planes.size(); ++p) {
      const SupportPlane& plane = planes[p];
      for (const Resting& r : resting) {
        const Eigen::Vector3d& s = models.models[static_cast<size_t>(r.model)].box_size_m;
        for (int level = 0; level < 2; ++level) {
          const bool bottom = level == 0;
          const double z = plane.z_m + (bottom ? 0.0 : s[r.up]);
          const std::optional<Eigen::Vector3d> at = view.OnPlane(corner.point, z);
          if (!at) continue;
          const Eigen::Vector3d P = *at;
          if ((P.head<2>() - plane.min_xy).minCoeff() < -kRegionMarginM ||
              (plane.max_xy - P.head<2>()).minCoeff() < -kRegionMarginM) {
            continue;
          }
          // Each arm as a horizontal edge on this plane: its direction and length there.
          std::optional<Eigen::Vector3d> u[2];
          double length[2] = {0, 0};
          for (int k = 0; k < 2; ++k) {
            const auto q = view.OnPlane(corner.arm_end[static_cast<size_t>(k)], z);
            if (!q) continue;
            Eigen::Vector3d d = *q - P;
            d.z() = 0;
            length[k] = d.norm();
            if (length[k] > 1e-3) u[k] = d / length[k];
          }
          auto fits = [&](int axis, double l) { return l <= kLengthSlack * s[axis] + kLengthSlackM; };
          // Two horizontal arms: perpendicular on the plane.
          if (u[0] && u[1] && std::abs(u[0]->dot(*u[1])) <= sin_perpendicular) {
            // Share the misfit between the arms: the yaw halfway.
            const double side = u[0]->cross(*u[1]).z() >= 0 ? 1.0 : -1.0;
            const Eigen::Vector3d u1_turned = Eigen::AngleAxisd(-side * M_PI / 2, Eigen::Vector3d::UnitZ()) * *u[1];
            const Eigen::Vector3d first = (*u[0] + u1_turned).normalized();
            const Eigen::Vector3d second = Eigen::AngleAxisd(side * M_PI / 2, Eigen::Vector3d::UnitZ()) * first;
            for (int swap = 0; swap < 2; ++swap) {
              const int i = swap ? r.b : r.a, j = swap ? r.a : r.b;
              if (fits(i, length[0]) && fits(j, length[1])) {
                emit(r, i, j, P, first, second, bottom, static_cast<int>(c), static_cast<int>(p));
              }
            }
          }
          // One vertical arm (up from a bottom corner, down from a top corner) and one horizontal.
          for (int v = 0; v < 2; ++v) {
            const int hz = 1 - v;
            if (vertical[v] != (bottom ? 1 : -1) || !u[hz]) continue;
            const Eigen::Vector3d Q = P + Eigen::Vector3d::UnitZ() * (bottom ? s[r.up] : -s[r.up]);
            const double edge_px = (project(Q) - corner.point).norm();
            const double arm_px = (corner.arm_end[static_cast<size_t>(v)] - corner.point).norm();
            if (arm_px > kLengthSlack * edge_px + 3) continue;
            const Eigen::Vector3d across = Eigen::Vector3d::UnitZ().cross(*u[hz]);
            for (int swap = 0; swap < 2; ++swap) {
              const int i = swap ? r.b : r.a, j = swap ? r.a : r.b;
              if (!fits(i, length[hz])) continue;
              for (double sign : {1.0, -1.0}) {
                emit(r, i, j, P, *u[hz], sign * across, bottom, static_cast<int>(c), static_cast<int>(p));
              }
            }
          }
        }
      }
    }
  }
}

// Appends to `kept`, best first, the hypotheses of `ranked` (sorted best first) not at the place of
// one kept (SamePlace within a quarter of the model's smallest side), until it holds `limit`.
void KeepBestPerPlace(const ModelLibrary& models, const std::vector<SupportHypothesis>& ranked, size_t limit,
                      std::vector<SupportHypothesis>* kept) {
  for (const SupportHypothesis& h : ranked) {
    if (kept->size() >= limit) break;
    const Model& model = models.models[static_cast<size_t>(h.model)];
    const double near_m = 0.25 * model.box_size_m.minCoeff();
    bool repeat = false;
    for (const SupportHypothesis& k : *kept) repeat = repeat || SamePlace(model, h, k, near_m);
    if (!repeat) kept->push_back(h);
  }
}

}  // namespace

std::vector<SupportHypothesis> SupportHypotheses(const ModelLibrary& models, const Camera& camera,
                                                 const LineDetection& detection,
                                                 const std::vector<ImageCorner>& corners,
                                                 const std::vector<SupportPlane>& planes,
                                                 const RecognizerOptions& options,
                                                 const std::vector<ImageLine>& contours) {
  const Eigen::Matrix3d K = camera.K();
  const geometry::Pose3& camera_T_world = camera.camera_T_world();
  const PlaneView view(models, camera, planes);

  // The occluding contours near each corner: within the image of the largest box that can have its
  // vertex there. Also worked out for the corners that ForEachPlacement skips for a thin-line arm:
  // those give no placement, so their lists are never read.
  std::vector<std::vector<ImageLine>> near_by_corner(corners.size());
  if (!contours.empty()) {
    for (size_t c = 0; c < corners.size(); ++c) {
      const Eigen::Vector2d& at = corners[c].point;
      const double reach_px = view.ReachPx(at);
      for (const ImageLine& line : contours) {
        const Eigen::Vector2d d = line.b - line.a;
        const double t = std::clamp(d.dot(at - line.a) / d.squaredNorm(), 0.0, 1.0);
        if ((line.a + t * d - at).norm() <= reach_px) near_by_corner[c].push_back(line);
      }
    }
  }
  // Placements short of the support threshold with a contour near their corner: scored behind it
  // (OccludedPlacementSupport) only where the placements in full view leave room, and ranked after
  // them. Against scoring them as they came, mixed in by score (session 36), one block more is
  // found in 3900 images and the support-plane stage takes 0.6-1.5 ms less in four of five
  // alternating runs (docs/benchmarks.md, session 37).
  std::vector<SupportHypothesis> short_near_contour;
  std::vector<SupportHypothesis> all;
  ForEachPlacement(models, camera, detection, corners, planes, options, view,
                   [&](SupportHypothesis h, const geometry::Pose3& camera_T_object) {
                     const Eigen::Vector3d& s = models.models[static_cast<size_t>(h.model)].box_size_m;
                     h.score = PlacementSupport(s, camera, camera_T_object, detection.edge_map, options);
                     if (h.score >= 0) {
                       all.push_back(h);
                     } else if (!near_by_corner[static_cast<size_t>(h.corner)].empty()) {
                       short_near_contour.push_back(h);
                     }
                   });

  // The best few per model and place.
  std::stable_sort(all.begin(), all.end(), HigherScore);
  std::vector<SupportHypothesis> kept;
  KeepBestPerPlace(models, all, static_cast<size_t>(options.max_support_hypotheses), &kept);
  // Those behind a contour take the room left under the cap, or options.support_contour_reserve
  // places if that is more (past the cap).
  const size_t behind_limit = std::max(static_cast<size_t>(options.max_support_hypotheses),
                                       kept.size() + static_cast<size_t>(options.support_contour_reserve));
  if (kept.size() < behind_limit) {
    std::vector<SupportHypothesis> behind;
    for (SupportHypothesis h : short_near_contour) {
      const Eigen::Vector3d& s = models.models[static_cast<size_t>(h.model)].box_size_m;
      const geometry::Pose3 camera_T_object = camera_T_world * h.world_T_object;
      h.score = OccludedPlacementSupport(s, camera, K, camera_T_object, detection.edge_map,
                                         near_by_corner[static_cast<size_t>(h.corner)], options);
      h.behind_contour = true;
      if (h.score >= 0) behind.push_back(h);
    }
    std::stable_sort(behind.begin(), behind.end(), HigherScore);
    KeepBestPerPlace(models, behind, behind_limit, &kept);
  }
  return kept;
}

std::vector<SupportHypothesis> AlternativeHypotheses(const ModelLibrary& models, const Camera& camera,
                                                     const LineDetection& detection, int model_index,
                                                     const geometry::Pose3& world_T_object,
                                                     const RecognizerOptions& options) {
  std::vector<SupportHypothesis> out;
  const Eigen::Vector3d& size = models.models[static_cast<size_t>(model_index)].box_size_m;
  const Eigen::Matrix3d R = world_T_object.RotationMatrix();
  // At rest: one axis within the editor's tilt of the vertical.
  int up = -1;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(R.col(k).z()) > std::cos(options.table_snap_max_tilt_deg * M_PI / 180)) up = k;
  }
  if (up < 0) return out;
  const int i = (up + 1) % 3, j = (up + 2) % 3;
  // Its horizontal edge directions, levelled and made perpendicular (the pose may tilt a little).
  Eigen::Vector3d h[2] = {Eigen::Vector3d(R(0, i), R(1, i), 0).normalized(), Eigen::Vector3d(R(0, j), R(1, j), 0)};
  h[1] = (h[1] - h[1].dot(h[0]) * h[0]).normalized();
  const double half[2] = {0.5 * size[i], 0.5 * size[j]};
  const Eigen::Vector3d bottom_centre =
      world_T_object.translation - Eigen::Vector3d::UnitZ() * 0.5 * size[up];
  const geometry::Pose3& camera_T_world = camera.camera_T_world();
  PlaceSet scored(models);
  for (size_t m = 0; m < models.models.size(); ++m) {
    const Eigen::Vector3d& s = models.models[m].box_size_m;
    std::vector<SupportHypothesis> placements;  // of this model, in the order tried
    for (int corner = 0; corner < 4; ++corner) {
      const double sign[2] = {corner & 1 ? 1.0 : -1.0, corner & 2 ? 1.0 : -1.0};
      const Eigen::Vector3d anchor = bottom_centre + sign[0] * half[0] * h[0] + sign[1] * half[1] * h[1];
      for (int b_up = 0; b_up < 3; ++b_up) {
        for (int swap = 0; swap < 2; ++swap) {
          const int a0 = swap ? (b_up + 2) % 3 : (b_up + 1) % 3, a1 = swap ? (b_up + 1) % 3 : (b_up + 2) % 3;
          // The box from the anchor inwards along both horizontal axes, up from the plane.
          const Eigen::Vector3d centre = anchor - sign[0] * 0.5 * s[a0] * h[0] -
                                         sign[1] * 0.5 * s[a1] * h[1] +
                                         Eigen::Vector3d::UnitZ() * 0.5 * s[b_up];
          Eigen::Matrix3d rotation;
          rotation.col(a0) = h[0];
          rotation.col(a1) = h[1];
          rotation.col(b_up) = Eigen::Vector3d::UnitZ();
          if (rotation.determinant() < 0) rotation.col(b_up) = -rotation.col(b_up);
          // The recognized pose itself (same model, same extent) is no alternative.
          if (static_cast<int>(m) == model_index &&
              (centre - (bottom_centre + Eigen::Vector3d::UnitZ() * 0.5 * size[up])).norm() < 1e-3 &&
              std::abs(s[a0] - size[i]) < 1e-6 && std::abs(s[a1] - size[j]) < 1e-6) {
            continue;
          }
          const geometry::Pose3 pose(Eigen::Quaterniond(rotation).normalized(), centre);
          const geometry::Pose3 camera_T_object = camera_T_world * pose;
          if (!(camera_T_object.translation.z() > 0.05) || !scored.Insert(static_cast<int>(m), pose))
            continue;
          const double score = PlacementSupport(s, camera, camera_T_object, detection.edge_map, options);
          if (score < 0) continue;
          SupportHypothesis placement;
          placement.model = static_cast<int>(m);
          placement.world_T_object = pose;
          placement.score = score;
          placements.push_back(placement);
        }
      }
    }
    // The best few distinct placements of this model (equal scores: the first tried).
    std::stable_sort(placements.begin(), placements.end(),
                     HigherScore);
    const double near_m = 0.25 * s.minCoeff();
    const size_t first = out.size();
    for (const SupportHypothesis& placement : placements) {
      if (static_cast<int>(out.size() - first) >= options.alternatives_per_model) break;
      bool repeat = false;
      for (size_t k = first; k < out.size(); ++k) {
        repeat = repeat || SamePlace(models.models[m], placement, out[k], near_m);
      }
      if (!repeat) out.push_back(placement);
    }
  }
  std::stable_sort(out.begin(), out.end(),
                   HigherScore);
  return out;
}

}  // namespace teachsim::vision
