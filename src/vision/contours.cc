// Occluding contours: long straight image lines taken for the outline of something in front of a
// block that the model library does not hold (an arm, a hand, a tool; the benchmark's dark
// cylinder). Where one runs across a pose's image, the outline on one side of it may be hidden
// (RecognizerOptions::occlusion_contours): the support-plane source scores such placements on the
// side in view, and the occlusion pass judges turned-down poses so.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

float SmoothedGrey(const cv::Mat& m, const Eigen::Vector2d& p) {
  const int x = std::clamp(static_cast<int>(std::lround(p.x())), 0, m.cols - 1);
  const int y = std::clamp(static_cast<int>(std::lround(p.y())), 0, m.rows - 1);
  return m.at<uint8_t>(y, x);
}

}  // namespace

std::vector<ImageLine> OccludingContours(const LineDetection& detection, const Camera& camera,
                                         const RecognizerOptions& options) {
  return OccludingContours(detection, JoinCollinearLines(detection.lines), camera, options);
}

std::vector<ImageLine> OccludingContours(const LineDetection& detection, const JoinedLines& joined,
                                         const Camera& camera, const RecognizerOptions& options) {
  constexpr int kProbes = 9;
  constexpr double kOffsetPx = 4.5;
  TEACHSIM_CHECK(joined.representative.size() == detection.lines.size() &&
                 joined.extent.size() == detection.lines.size());
  const Eigen::Matrix3d K_inv = camera.K().inverse();
  std::vector<ImageLine> out;
  for (size_t l = 0; l < detection.lines.size(); ++l) {
    if (joined.representative[l] != static_cast<int>(l)) continue;
    const ImageLine& line = joined.extent[l];
    const double length = line.Length();
    if (length < options.contour_min_length_px) continue;
    // The grey-level step across it (the smoothed, distorted image), its median over the probes.
    const Eigen::Vector2d along = (line.b - line.a) / length, normal(-along.y(), along.x());
    std::array<float, kProbes> steps{};
    for (int k = 0; k < kProbes; ++k) {
      const Eigen::Vector2d c = line.a + (k + 0.5) / kProbes * (line.b - line.a);
      float grey[2] = {0, 0};
      for (int side = 0; side < 2; ++side) {
        const Eigen::Vector2d u = c + (side == 0 ? kOffsetPx : -kOffsetPx) * normal;
        const auto px = camera.ProjectFromCamera(K_inv * Eigen::Vector3d(u.x(), u.y(), 1));
        grey[side] = px ? SmoothedGrey(detection.edge_map.smoothed, *px) : 0;
      }
      steps[static_cast<size_t>(k)] = grey[0] - grey[1];
    }
    std::array<float, kProbes> signed_steps = steps;
    for (float& step : steps) step = std::abs(step);
    std::nth_element(steps.begin(), steps.begin() + kProbes / 2, steps.end());
    if (steps[kProbes / 2] < options.contour_min_step_grey) continue;
    // Oriented with the darker side towards (-d.y, d.x), d = b - a: turned round where the median
    // signed step says otherwise.
    std::nth_element(signed_steps.begin(), signed_steps.begin() + kProbes / 2, signed_steps.end());
    out.push_back(signed_steps[kProbes / 2] <= 0 ? line : ImageLine{line.b, line.a});
  }
  return out;
}

BoxImage::BoxImage(const std::array<Eigen::Vector2d, 8>& vertices_px, uint16_t visible)
    : px(vertices_px), visible_edges(visible) {
  // The vertices' convex hull by gift wrapping (8 points), counter-clockwise in a y-up sense: every
  // other vertex to the left of each hull edge.
  int start = 0;
  for (int i = 1; i < 8; ++i) {
    if (px[i].x() < px[start].x() || (px[i].x() == px[start].x() && px[i].y() < px[start].y())) start = i;
  }
  int current = start;
  do {
    hull[hull_size++] = current;
    int next = (current + 1) % 8;
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector2d a = px[next] - px[current], b = px[i] - px[current];
      const double cross = a.x() * b.y() - a.y() * b.x();
      if (cross < 0 || (cross == 0 && b.squaredNorm() > a.squaredNorm())) next = i;
    }
    current = next;
  } while (current != start && hull_size < 8);
}

namespace {

// Whether a contour's line leaves the box's image wholly on one side.
bool ClearOfBoxImage(const ImageLine& contour, const BoxImage& box) {
  const Eigen::Vector2d d = contour.b - contour.a, normal(-d.y(), d.x());
  bool left = false, right = false;
  for (int i = 0; i < box.hull_size; ++i) {
    const double side = normal.dot(box.px[static_cast<size_t>(box.hull[i])] - contour.a);
    left = left || side > 0, right = right || side < 0;
  }
  return !(left && right);
}

}  // namespace

ContourPassage PassageThroughBoxImage(const ImageLine& contour, const BoxImage& box) {
  constexpr double kBeyondPx = 4, kMinInsidePx = 10, kOwnEdgePx = 3, kOwnEdgeOverhangPx = 40;
  const double length = contour.Length();
  if (!(length > kBeyondPx + kMinInsidePx) || box.hull_size < 3) return ContourPassage::kNone;
  const Eigen::Vector2d along = (contour.b - contour.a) / length, normal(-along.y(), along.x());
  // Quick refusal: the box's image lies wholly on one side of the line.
  if (ClearOfBoxImage(contour, box)) return ContourPassage::kNone;
  // Where the line enters and leaves the hull (Cyrus-Beck; inward is to the left of each edge).
  double t_in = -std::numeric_limits<double>::infinity(), t_out = -t_in;
  for (int i = 0; i < box.hull_size; ++i) {
    const Eigen::Vector2d& p = box.px[static_cast<size_t>(box.hull[i])];
    const Eigen::Vector2d e = box.px[static_cast<size_t>(box.hull[(i + 1) % box.hull_size])] - p;
    const Eigen::Vector2d inward(-e.y(), e.x());
    const double num = inward.dot(contour.a - p), den = inward.dot(along);
    if (std::abs(den) < 1e-12) {
      if (num < 0) return ContourPassage::kNone;
    } else if (den > 0) {
      t_in = std::max(t_in, -num / den);
    } else {
      t_out = std::min(t_out, -num / den);
    }
  }
  // The part of the contour inside the hull, and whether each end lies beyond it.
  const double inside = std::min(t_out, length) - std::max(t_in, 0.0);
  const bool a_beyond = t_in >= kBeyondPx, b_beyond = t_out <= length - kBeyondPx;
  if (!(inside >= kMinInsidePx) || (!a_beyond && !b_beyond)) return ContourPassage::kNone;
  // None of the box's own visible edges: a line along one of them is that edge (a block's outline
  // against the table looks like a contour), unless it reaches kOwnEdgeOverhangPx or more past the
  // box's image, both ends together. A block's edge ends at its corners; such a line is the flank of
  // something in front that happens to run along one of its edges (an upright edge beside the
  // benchmark's upright cylinder). Session 71, render seeds 7-71: 2 / 10 / 7 more blocks found (>= 0.7
  // / 0.4-0.7 / < 0.4 visible), 1 more false detection (docs/benchmarks.md).
  const double overhang = std::max(t_in, 0.0) + std::max(length - t_out, 0.0);
  if (overhang < kOwnEdgeOverhangPx) {
    for (int e = 0; e < 12; ++e) {
      if (!(box.visible_edges >> e & 1)) continue;
      if (std::abs(normal.dot(box.px[kBoxEdges[e][0]] - contour.a)) < kOwnEdgePx &&
          std::abs(normal.dot(box.px[kBoxEdges[e][1]] - contour.a)) < kOwnEdgePx) {
        return ContourPassage::kNone;
      }
    }
  }
  if (a_beyond && b_beyond) return ContourPassage::kAcross;
  return a_beyond ? ContourPassage::kIntoAtB : ContourPassage::kIntoAtA;
}

bool CrossesBoxImage(const ImageLine& contour, const BoxImage& box) {
  return PassageThroughBoxImage(contour, box) == ContourPassage::kAcross;
}

namespace {

ContourOccluder::Side SideOf(const ImageLine& contour, const Eigen::Vector2d& toward) {
  ContourOccluder::Side side;
  side.a = contour.a;
  side.length = contour.Length();
  side.along = (contour.b - contour.a) / side.length;
  side.toward_hidden = Eigen::Vector2d(-side.along.y(), side.along.x());
  if (side.toward_hidden.dot(toward) < 0) side.toward_hidden = -side.toward_hidden;
  return side;
}

// The strip between two contours that do not meet where they are.
ContourOccluder Strip(const ImageLine& p, const ImageLine& q) {
  ContourOccluder o;
  o.sides[0] = SideOf(p, 0.5 * (q.a + q.b) - p.a);
  o.sides[1] = SideOf(q, 0.5 * (p.a + p.b) - q.a);
  o.count = 2;
  return o;
}

// A pole's top: a strip `width_px` wide between flanks that end inside a box's image goes on past their
// ends by half its width (the flanks of a round pole end where its top's ellipse is widest; the ellipse
// reaches at most its radius beyond). The strip so lengthened is a rectangle: it hides the ellipse's corners
// too. Each side with a non-zero `inward` (the direction in which the strip's end lies along it: for a flank
// that ends inside, the direction it runs in there; for a flank beside the box paired with one that ends
// inside, that one's) is lengthened at its end that way; a side with zero is left as it is.
void ExtendOverPoleTop(ContourOccluder* o, const std::array<Eigen::Vector2d, 2>& inward, double width_px) {
  const double by_px = 0.5 * width_px;
  for (int k = 0; k < 2; ++k) {
    ContourOccluder::Side& side = o->sides[static_cast<size_t>(k)];
    const Eigen::Vector2d& in = inward[static_cast<size_t>(k)];
    if (in == Eigen::Vector2d::Zero()) continue;
    if (in.dot(side.along) < 0) side.a -= by_px * side.along;
    side.length += by_px;
  }
}

// Whether two flanks end alike in the direction `inward` (unit): their far ends that way no farther
// apart along it than the flanks are apart (the two sides of a pole end where its top begins).
bool EndsAlike(const ImageLine& p, const ImageLine& q, const Eigen::Vector2d& inward) {
  const double p_end = std::max(inward.dot(p.a), inward.dot(p.b));
  const double q_end = std::max(inward.dot(q.a), inward.dot(q.b));
  const Eigen::Vector2d across(-inward.y(), inward.x());
  const double apart = std::abs(across.dot(0.5 * (q.a + q.b) - 0.5 * (p.a + p.b)));
  return std::abs(p_end - q_end) <= apart;
}

// Whether the strip between two flanks is on the same side of the step at both (darker than
// beyond both, or lighter than beyond both: one thing in front), by OccludingContours' orientation.
bool SameBetween(const ImageLine& p, const ImageLine& q) {
  auto dark_toward = [](const ImageLine& l, const Eigen::Vector2d& point) {
    const Eigen::Vector2d d = l.b - l.a;
    return Eigen::Vector2d(-d.y(), d.x()).dot(point - l.a) > 0;
  };
  return dark_toward(p, 0.5 * (q.a + q.b)) == dark_toward(q, 0.5 * (p.a + p.b));
}

}  // namespace

int ContourOccluder::HidesEach(const double* x, const double* y, int n, uint8_t* hides) const {
  if (count <= 0) {
    std::fill(hides, hides + n, uint8_t{0});
    return 0;
  }
  const Side s0 = sides[0];
  const Side s1 = sides[count >= 2 ? 1 : 0];
  int hidden = 0;
  for (int i = 0; i < n; ++i) {
    const int h = static_cast<int>(s0.HidesAt(x[i], y[i])) & static_cast<int>(s1.HidesAt(x[i], y[i]));
    hides[i] = static_cast<uint8_t>(h);
    hidden += h;
  }
  return hidden;
}

void ContourOcclusions(const std::vector<ImageLine>& contours, const BoxImage& box,
                       std::vector<ContourOccluder>* occlusions, ContourPairing pairing) {
  std::vector<ContourOccluder>& out = *occlusions;
  out.clear();
  struct Passing {
    const ImageLine* line;
    ContourPassage passage;
  };
  thread_local std::vector<Passing> passing;
  thread_local std::vector<ContourPassage> passage_of;  // of each contour
  passing.clear();
  passage_of.resize(contours.size());
  for (size_t k = 0; k < contours.size(); ++k) {
    const ContourPassage passage = passage_of[k] = PassageThroughBoxImage(contours[k], box);
    if (passage == ContourPassage::kAcross || (pairing.ends_inside && passage != ContourPassage::kNone))
      passing.push_back({&contours[k], passage});
  }
  // The end of a contour that lies inside the box's image, as the direction in which it runs there
  // (from the end beyond); zero for one across it.
  auto inward = [](const Passing& p) -> Eigen::Vector2d {
    const Eigen::Vector2d d = (p.line->b - p.line->a).normalized();
    switch (p.passage) {
      case ContourPassage::kIntoAtB:
        return d;
      case ContourPassage::kIntoAtA:
        return -d;
      default:
        return Eigen::Vector2d::Zero();
    }
  };
  // The strips between two that pass through (kept to go after the sides), and, with
  // pairing.sides_bounded, the sides of each contour across that hold another across with which it
  // makes a strip (bit 0: the side its normal (-d.y, d.x) points to; bit 1: the other): the far
  // flank of a pole, past which the outline is in view.
  const double min_cos = std::cos(30 * M_PI / 180);
  thread_local std::vector<ContourOccluder> strips;
  thread_local std::vector<uint8_t> bounded_sides;
  strips.clear();
  bounded_sides.assign(passing.size(), 0);
  for (size_t i = 0; i < passing.size(); ++i) {
    for (size_t j = i + 1; j < passing.size(); ++j) {
      const ImageLine& p = *passing[i].line;
      const ImageLine& q = *passing[j].line;
      const Eigen::Vector2d dp = (p.b - p.a).normalized(), dq = (q.b - q.a).normalized();
      if (std::abs(dp.dot(dq)) < min_cos) continue;
      // Two that end inside: both from the same side (the two flanks of a thing whose end is in
      // front of the box). One that ends inside may pair with one across.
      const Eigen::Vector2d ip = inward(passing[i]), iq = inward(passing[j]);
      if (ip.dot(iq) < 0) continue;
      if ((ip != Eigen::Vector2d::Zero() || iq != Eigen::Vector2d::Zero()) &&
          (!EndsAlike(p, q, ip != Eigen::Vector2d::Zero() ? ip : iq) || !SameBetween(p, q))) {
        continue;
      }
      // Each wholly on one side of the other (they do not meet where they are).
      const Eigen::Vector2d np(-dp.y(), dp.x()), nq(-dq.y(), dq.x());
      const double qa = np.dot(q.a - p.a), qb = np.dot(q.b - p.a);
      const double pa = nq.dot(p.a - q.a), pb = nq.dot(p.b - q.a);
      if (qa * qb <= 0 || pa * pb <= 0) continue;
      strips.push_back(Strip(p, q));
      // The strip's width: the mean distance of q's ends from p's line (two across: no side grows).
      if (pairing.pole_tops) ExtendOverPoleTop(&strips.back(), {ip, iq}, 0.5 * (std::abs(qa) + std::abs(qb)));
      if (passing[i].passage == ContourPassage::kAcross && passing[j].passage == ContourPassage::kAcross) {
        bounded_sides[i] |= qa > 0 ? 1 : 2;
        bounded_sides[j] |= pa > 0 ? 1 : 2;
      }
    }
  }
  // Either side of each across (first), then those strips.
  for (size_t i = 0; i < passing.size(); ++i) {
    const Passing& p = passing[i];
    if (p.passage != ContourPassage::kAcross) continue;
    const Eigen::Vector2d d = p.line->b - p.line->a, normal(-d.y(), d.x());
    for (int side = 0; side < 2; ++side) {
      if (pairing.sides_bounded && (bounded_sides[i] >> side & 1)) continue;
      ContourOccluder o;
      o.sides[0] = SideOf(*p.line, (side == 0 ? 1.0 : -1.0) * normal);
      o.count = 1;
      out.push_back(o);
    }
  }
  out.insert(out.end(), strips.begin(), strips.end());
  // One that ends inside with a flank beside the box's image (the pole's other side passes the box
  // by): the strip between them, when they are no farther apart than the box's image is wide and end
  // alike. One across with a flank beside (pairing.across_beside): the strip at any distance, the
  // flank's line clear of the box's image (wholly to one side of it).
  for (const Passing& into : passing) {
    const bool across = into.passage == ContourPassage::kAcross;
    if (across && !pairing.across_beside) continue;
    const ImageLine& p = *into.line;
    const Eigen::Vector2d dp = (p.b - p.a).normalized(), np(-dp.y(), dp.x());
    double width = 0;  // of the box's image across p (for one that ends inside)
    if (!across) {
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (int k = 0; k < box.hull_size; ++k) {
        const double d = np.dot(box.px[static_cast<size_t>(box.hull[k])] - p.a);
        lo = std::min(lo, d), hi = std::max(hi, d);
      }
      width = hi - lo;
    }
    for (size_t k = 0; k < contours.size(); ++k) {
      if (passage_of[k] != ContourPassage::kNone) continue;  // passes through the box's image
      const ImageLine& q = contours[k];
      const Eigen::Vector2d dq = (q.b - q.a).normalized(), nq(-dq.y(), dq.x());
      if (std::abs(dp.dot(dq)) < min_cos) continue;
      const double qa = np.dot(q.a - p.a), qb = np.dot(q.b - p.a);
      const double pa = nq.dot(p.a - q.a), pb = nq.dot(p.b - q.a);
      if (qa * qb <= 0 || pa * pb <= 0 || !SameBetween(p, q)) continue;
      if (across ? !ClearOfBoxImage(q, box)
                 : (std::max(std::abs(qa), std::abs(qb)) > width || !EndsAlike(p, q, inward(into)))) {
        continue;
      }
      out.push_back(Strip(p, q));
      if (pairing.pole_tops && !across) {
        const Eigen::Vector2d in = inward(into);
        ExtendOverPoleTop(&out.back(), {in, in}, 0.5 * (std::abs(qa) + std::abs(qb)));
      }
    }
  }
}

bool EndsAtContourInside(const BoxImage& inner, const BoxImage& outer,
                         const std::vector<ImageLine>& contours) {
  constexpr double kMinEdgePx = 10, kAlongPx = 2.5, kBehindPx = 25, kInsidePx = 2, kPastPx = 10,
                   kPastShare = 1.0 / 3;
  auto inside_outer = [&](const Eigen::Vector2d& p) {
    for (int h = 0; h < outer.hull_size; ++h) {
      const Eigen::Vector2d& a = outer.px[static_cast<size_t>(outer.hull[h])];
      const Eigen::Vector2d& b = outer.px[static_cast<size_t>(outer.hull[(h + 1) % outer.hull_size])];
      const Eigen::Vector2d e = b - a, q = p - a;
      const double length = e.norm();
      if (!(length > 0) || (e.x() * q.y() - e.y() * q.x()) < kInsidePx * length) return false;
    }
    return outer.hull_size >= 3;
  };
  if (inner.hull_size < 3) return false;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (int h = 0; h < inner.hull_size; ++h) centre += inner.px[static_cast<size_t>(inner.hull[h])];
  centre /= inner.hull_size;
  for (int h = 0; h < inner.hull_size; ++h) {
    const Eigen::Vector2d& a = inner.px[static_cast<size_t>(inner.hull[h])];
    const Eigen::Vector2d& b = inner.px[static_cast<size_t>(inner.hull[(h + 1) % inner.hull_size])];
    const double length = (b - a).norm();
    if (!(length >= kMinEdgePx) || !inside_outer(0.5 * (a + b))) continue;
    const double past = std::max(kPastPx, kPastShare * length);
    for (const ImageLine& c : contours) {
      const Eigen::Vector2d d = c.b - c.a;
      const double contour_length = d.norm();
      if (!(contour_length > 0)) continue;
      const Eigen::Vector2d dc = d / contour_length, darker(-dc.y(), dc.x());
      // Both ends of the edge along the contour or behind it, at most kBehindPx.
      const double da = darker.dot(a - c.a), db = darker.dot(b - c.a);
      if (da < -kAlongPx || db < -kAlongPx || da > kBehindPx || db > kBehindPx) continue;
      if (darker.dot(centre - 0.5 * (a + b)) > 0) continue;  // darker towards the block: not in front
      const double ta = dc.dot(a - c.a), tb = dc.dot(b - c.a);
      if (std::min(ta, tb) >= past && contour_length - std::max(ta, tb) >= past) return true;
    }
  }
  return false;
}

bool AmbiguousExtent(const ModelLibrary& models, int model_index, const geometry::Pose3& camera_T_object,
                     const ContourOccluder& occluder, const Eigen::Matrix3d& K) {
  const Eigen::Vector3d& s = models.models[static_cast<size_t>(model_index)].box_size_m;
  auto hidden = [&](const Eigen::Vector3d& in_object) {
    const Eigen::Vector3d p = camera_T_object * in_object;
    return p.z() > 1e-3 && occluder.Hides((K * p).hnormalized());
  };
  // The four corners of the face across axis k at `at` along it.
  auto face_hidden = [&](int k, double at) {
    const int i = (k + 1) % 3, j = (k + 2) % 3;
    for (int c = 0; c < 4; ++c) {
      Eigen::Vector3d v;
      v[k] = at;
      v[i] = (c & 1 ? 0.5 : -0.5) * s[i];
      v[j] = (c & 2 ? 0.5 : -0.5) * s[j];
      if (!hidden(v)) return false;
    }
    return true;
  };
  constexpr double kSameM = 0.002;
  for (int k = 0; k < 3; ++k) {
    const int i = (k + 1) % 3, j = (k + 2) % 3;
    for (double sign : {1.0, -1.0}) {
      if (!face_hidden(k, sign * 0.5 * s[k])) continue;
      for (size_t m = 0; m < models.models.size(); ++m) {
        if (static_cast<int>(m) == model_index) continue;
        const Eigen::Vector3d& t = models.models[m].box_size_m;
        for (int kk = 0; kk < 3; ++kk) {
          const double a = t[(kk + 1) % 3], b = t[(kk + 2) % 3];
          const bool same_sides = (std::abs(a - s[i]) < kSameM && std::abs(b - s[j]) < kSameM) ||
                                  (std::abs(a - s[j]) < kSameM && std::abs(b - s[i]) < kSameM);
          if (!same_sides || std::abs(t[kk] - s[k]) < kSameM) continue;
          // Laid from the end in view (at -sign s_k / 2): its far end face.
          if (face_hidden(k, -sign * 0.5 * s[k] + sign * t[kk])) return true;
        }
      }
    }
  }
  return false;
}

}  // namespace teachsim::vision
