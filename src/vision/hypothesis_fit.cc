// Fitting one hypothesis (issue 7 item 4): matching image lines to a pose's predicted edges and
// the rounds of Lowe's least-squares fit from a hypothesis' initial pose, predicting the other
// visible edges and matching them from loose to tight (Lowe 1991; paper §4.1).
//
// Robustly: a round fits only the lines that lie on their predicted edge (a shadow, a grain line or
// the neighbouring block's edge running beside it within the match distance is left out), the last
// round with Tukey's biweight (no pull from a residual beyond kTukeyPx), and the hypothesis ends at
// the round's pose that puts the most image line length within kExplainedPx of its predicted edges
// (a later round that drifted off the block does not replace a better earlier one). The first
// round matches within 3 match distances for either source (support-plane starts 15 px and 10 deg
// off did not converge within 2). Benchmark
// (bench recognize, >= 0.7 visible, blocks lost because no fit converged onto them): renders seed 7
// 25 -> 7, seed 8 9 -> 7, dev set 3 -> 2. Loose first rounds can also take a half-hidden block's
// hidden edges for lines beside them and leave the block: a support hypothesis can be fitted tightly
// as well (`tight`), for the recognizer to verify both.
#include <algorithm>
#include <cmath>
#include <limits>

#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

// A round's matches: a line whose offset from its predicted edge exceeds the edge's closest line's
// by more than this is beside the edge, not on it (a split edge's pieces lie within it).
constexpr double kOnEdgeSpreadPx = 1.5;
// Tukey's biweight scale of the last round (and the 6-DOF refinement), px.
constexpr double kTukeyPx = 2;
// A pose's explained line length counts the lines within this of their predicted edges, px.
constexpr double kExplainedPx = 2;

void ProjectEdge(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object, int edge,
                 Eigen::Vector2d* a, Eigen::Vector2d* b) {
  const Eigen::Vector3d p = K * (camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[static_cast<size_t>(edge)][0]));
  const Eigen::Vector3d q = K * (camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[static_cast<size_t>(edge)][1]));
  *a = p.head<2>() / std::max(p.z(), 1e-9);
  *b = q.head<2>() / std::max(q.z(), 1e-9);
}

}  // namespace

// Matches image lines to the predicted visible edges of a box at a pose (undistorted px).
EdgeMatchSet MatchEdges(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                        const std::vector<ImageLine>& lines, double max_distance_px, double max_angle_rad) {
  EdgeMatchSet out;
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_object.Inverse().translation);
  Eigen::Vector2d px[8];
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d p = K * (camera_T_object * BoxVertex(model.box_size_m, i));
    px[i] = p.head<2>() / std::max(p.z(), 1e-9);
  }
  struct EdgeGeom {
    int e;
    Eigen::Vector2d a, dir, n;
    double length;
    double covered = 0;
  };
  std::vector<EdgeGeom> edges;
  // The edges' bounding box (for passing over far lines, below).
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector2d a = px[kBoxEdges[e][0]], b = px[kBoxEdges[e][1]];
    const double len = (b - a).norm();
    if (len < 3) continue;
    const Eigen::Vector2d dir = (b - a) / len;
    edges.push_back({e, a, dir, {-dir.y(), dir.x()}, len});
    out.visible_length_px += len;
    lo = lo.cwiseMin(a).cwiseMin(b);
    hi = hi.cwiseMax(a).cwiseMax(b);
  }
  if (edges.empty()) return out;
  // A line that matches an edge lies within max_distance_px of it along at least half its own length,
  // so it reaches into the edges' bounding box grown by that distance (and a pixel more, against
  // rounding): every other line is passed over without testing it against each edge. Most of an
  // image's lines are far from any one pose (the recognizer's fits call this for every round).
  lo.array() -= max_distance_px + 1;
  hi.array() += max_distance_px + 1;
  const double cos_max = std::cos(max_angle_rad);
  for (size_t s = 0; s < lines.size(); ++s) {
    const ImageLine& l = lines[s];
    if (std::max(l.a.x(), l.b.x()) < lo.x() || std::min(l.a.x(), l.b.x()) > hi.x() ||
        std::max(l.a.y(), l.b.y()) < lo.y() || std::min(l.a.y(), l.b.y()) > hi.y()) {
      continue;
    }
    const double len = l.Length();
    const Eigen::Vector2d ldir = (l.b - l.a) / len;
    int best = -1;
    double best_d = 1e300, best_overlap = 0;
    for (size_t k = 0; k < edges.size(); ++k) {
      const EdgeGeom& g = edges[k];
      if (std::abs(ldir.dot(g.dir)) < cos_max) continue;
      const double da = std::abs(g.n.dot(l.a - g.a)), db = std::abs(g.n.dot(l.b - g.a));
      if (da > max_distance_px || db > max_distance_px) continue;
      const double ta = g.dir.dot(l.a - g.a), tb = g.dir.dot(l.b - g.a);
      const double overlap = std::min(std::max(ta, tb), g.length) - std::max(std::min(ta, tb), 0.0);
      if (overlap < 0.5 * len) continue;
      if (da + db < best_d) best = static_cast<int>(k), best_d = da + db, best_overlap = overlap;
    }
    if (best < 0) continue;
    edges[static_cast<size_t>(best)].covered += best_overlap;
    out.matches.push_back({edges[static_cast<size_t>(best)].e, l.a, l.b});
    out.segments.push_back(static_cast<int>(s));
  }
  double covered = 0;
  for (const EdgeGeom& g : edges) covered += std::min(g.covered, g.length);
  out.matched_fraction = out.visible_length_px > 0 ? covered / out.visible_length_px : 0;
  return out;
}

std::vector<LineMatch> OnEdgeMatches(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                                     const std::vector<LineMatch>& matches, double spread_px) {
  std::array<double, 12> closest;
  closest.fill(1e300);
  std::vector<double> offset(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) {
    const LineMatch& m = matches[i];
    Eigen::Vector2d a, b;
    ProjectEdge(model, K, camera_T_object, m.edge, &a, &b);
    const Eigen::Vector2d dir = (b - a).normalized(), n(-dir.y(), dir.x());
    offset[i] = 0.5 * (std::abs(n.dot(m.a - a)) + std::abs(n.dot(m.b - a)));
    closest[static_cast<size_t>(m.edge)] = std::min(closest[static_cast<size_t>(m.edge)], offset[i]);
  }
  std::vector<LineMatch> out;
  for (size_t i = 0; i < matches.size(); ++i) {
    if (offset[i] <= closest[static_cast<size_t>(matches[i].edge)] + spread_px) out.push_back(matches[i]);
  }
  return out;
}

double ExplainedLengthPx(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                         const std::vector<ImageLine>& lines, double max_distance_px, double max_angle_rad) {
  const EdgeMatchSet set = MatchEdges(model, K, camera_T_object, lines, max_distance_px, max_angle_rad);
  return set.matched_fraction * set.visible_length_px;
}

HypothesisFit FitSupportHypothesis(const Model& model, const Eigen::Matrix3d& K,
                                   const geometry::Pose3& camera_T_world, const geometry::Pose3& initial,
                                   const std::vector<ImageLine>& lines, const RecognizerOptions& options,
                                   bool tight) {
  HypothesisFit out;
  const double match_angle = options.match_angle_deg * M_PI / 180;
  const RobustLoss huber{RobustLoss::Kind::kHuber, options.huber_px}, tukey{RobustLoss::Kind::kTukey, kTukeyPx};
  auto explained = [&](const geometry::Pose3& pose) {
    return ExplainedLengthPx(model, K, pose, lines, kExplainedPx, match_angle);
  };
  FitResult& fit = out.fit;
  fit.camera_T_object = initial;
  // The rounds' fits leave out the covariance: it is made once, for the pose kept, from that
  // round's matches and loss (PoseCovariance: the same figures as the fit would give).
  FitResult best;  // the round with the most explained length; none: the initial pose
  std::vector<LineMatch> best_matches;
  RobustLoss best_loss = huber;
  double best_explained = explained(initial);
  bool improved = false;
  static constexpr double kLoose[3] = {3.0, 1.5, 1.0}, kTight[3] = {1.0, 1.0, 1.0};
  const double* loose = tight ? kTight : kLoose;
  std::vector<LineMatch> first_matches;
  for (int round = 0; round < 3; ++round) {
    const EdgeMatchSet set = MatchEdges(model, K, fit.camera_T_object, lines, loose[round] * options.match_distance_px,
                                        loose[round] * match_angle);
    if (set.matches.size() < 3) {
      out.failed = true;
      return out;
    }
    std::vector<LineMatch> matches =
        OnEdgeMatches(model, K, fit.camera_T_object, set.matches, kOnEdgeSpreadPx);
    if (round == 0) first_matches = matches;
    const RobustLoss& loss = round == 2 ? tukey : huber;
    fit = FitPoseOnPlane(model.box_size_m, K, camera_T_world, fit.camera_T_object, matches,
                         options.max_iterations, loss, false);
    out.rounds.push_back(fit.camera_T_object);
    const double e = explained(fit.camera_T_object);
    if (e >= best_explained) {  // ties: the later, tighter round
      best_explained = e, best = fit, improved = true;
      best_matches = std::move(matches), best_loss = loss;
    }
  }
  // No round explained more than the start: the start, with its covariance.
  if (improved) {
    fit = best;
    fit.covariance_camera = PoseCovariance(model.box_size_m, K, fit.camera_T_object, best_matches, best_loss);
  } else {
    fit = FitPoseOnPlane(model.box_size_m, K, camera_T_world, initial, first_matches, 0, huber);
  }
  if (options.support_refine_6dof) {
    const EdgeMatchSet on_plane = MatchEdges(model, K, fit.camera_T_object, lines, options.match_distance_px, match_angle);
    const std::vector<LineMatch> free_matches =
        OnEdgeMatches(model, K, fit.camera_T_object, on_plane.matches, kOnEdgeSpreadPx);
    const FitResult free = FitPoseToLines(model.box_size_m, K, fit.camera_T_object, free_matches,
                                          options.max_iterations, tukey, false);
    const EdgeMatchSet refined = MatchEdges(model, K, free.camera_T_object, lines, options.match_distance_px, match_angle);
    if (refined.matches.size() >= 3 && refined.matched_fraction >= on_plane.matched_fraction &&
        explained(free.camera_T_object) >= best_explained) {
      const double rms_free = LineResidualRmsPx(model.box_size_m, K, free.camera_T_object, refined.matches);
      const double rms_plane = LineResidualRmsPx(model.box_size_m, K, fit.camera_T_object, on_plane.matches);
      if (rms_free <= rms_plane) {
        fit = free;
        fit.covariance_camera =
            PoseCovariance(model.box_size_m, K, free.camera_T_object, free_matches, tukey);
        out.rounds.push_back(fit.camera_T_object);
      }
    }
  }
  return out;
}

double MeanVertexShiftPx(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& a,
                         const geometry::Pose3& b) {
  double sum = 0;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d v = BoxVertex(model.box_size_m, i);
    const Eigen::Vector3d p = K * (a * v), q = K * (b * v);
    sum += (p.head<2>() / std::max(p.z(), 1e-9) - q.head<2>() / std::max(q.z(), 1e-9)).norm();
  }
  return sum / 8;
}

HypothesisFit FitIndexHypothesis(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& initial,
                                 const std::vector<LineMatch>& seed_matches, const std::vector<ImageLine>& lines,
                                 const RecognizerOptions& options) {
  HypothesisFit out;
  const double match_angle = options.match_angle_deg * M_PI / 180;
  const RobustLoss huber{RobustLoss::Kind::kHuber, options.huber_px}, tukey{RobustLoss::Kind::kTukey, kTukeyPx};
  auto explained = [&](const geometry::Pose3& pose) {
    return ExplainedLengthPx(model, K, pose, lines, kExplainedPx, match_angle);
  };
  FitResult& fit = out.fit;
  // As for the support hypotheses: the covariance once, for the round kept.
  fit = FitPoseToLines(model.box_size_m, K, initial, seed_matches, 8, huber, false);
  out.rounds.push_back(fit.camera_T_object);
  FitResult best = fit;
  std::vector<LineMatch> best_matches = seed_matches;
  RobustLoss best_loss = huber;
  double best_explained = explained(fit.camera_T_object);
  const double loose[3] = {3.0, 1.5, 1.0};
  for (int round = 0; round < 3; ++round) {
    const EdgeMatchSet set = MatchEdges(model, K, fit.camera_T_object, lines, loose[round] * options.match_distance_px,
                                        loose[round] * match_angle);
    if (set.matches.size() < 3 || fit.camera_T_object.translation.z() <= 0.05) {
      out.failed = true;
      return out;
    }
    // The first round starts from the group's own correspondences, up to 20 px off: the closest
    // line beside a predicted edge need not be its own yet, so all matches count (Huber).
    std::vector<LineMatch> matches =
        round == 0 ? set.matches : OnEdgeMatches(model, K, fit.camera_T_object, set.matches, kOnEdgeSpreadPx);
    const RobustLoss& loss = round == 2 ? tukey : huber;
    fit = FitPoseToLines(model.box_size_m, K, fit.camera_T_object, matches, options.max_iterations, loss,
                         false);
    out.rounds.push_back(fit.camera_T_object);
    const double e = explained(fit.camera_T_object);
    if (e >= best_explained) {  // ties: the later, tighter round
      best_explained = e, best = fit;
      best_matches = std::move(matches), best_loss = loss;
    }
  }
  fit = best;
  fit.covariance_camera = PoseCovariance(model.box_size_m, K, fit.camera_T_object, best_matches, best_loss);
  return out;
}

}  // namespace teachsim::vision
