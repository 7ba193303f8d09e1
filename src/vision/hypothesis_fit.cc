// Fitting one hypothesis (issue 7 item 4): matching image lines to a pose's predicted edges and
// the rounds of Lowe's least-squares fit from a hypothesis' initial pose, predicting the other
// visible edges and matching them from loose to tight (Lowe 1991; paper §4.1).
#include <cmath>

#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

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
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector2d a = px[kBoxEdges[e][0]], b = px[kBoxEdges[e][1]];
    const double len = (b - a).norm();
    if (len < 3) continue;
    const Eigen::Vector2d dir = (b - a) / len;
    edges.push_back({e, a, dir, {-dir.y(), dir.x()}, len});
    out.visible_length_px += len;
  }
  const double cos_max = std::cos(max_angle_rad);
  for (size_t s = 0; s < lines.size(); ++s) {
    const ImageLine& l = lines[s];
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

HypothesisFit FitSupportHypothesis(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world,
                                   const geometry::Pose3& initial, const std::vector<ImageLine>& lines,
                                   const RecognizerOptions& options) {
  HypothesisFit out;
  const double match_angle = options.match_angle_deg * M_PI / 180;
  FitResult& fit = out.fit;
  bool& failed = out.failed;
  fit.camera_T_object = initial;
  for (const double loose : {2.0, 1.5, 1.0}) {
    const EdgeMatchSet set = MatchEdges(model, K, fit.camera_T_object, lines, loose * options.match_distance_px,
                                        loose * match_angle);
    if (set.matches.size() < 3) {
      failed = true;
      break;
    }
    fit = FitPoseOnPlane(model.box_size_m, K, camera_T_world, fit.camera_T_object, set.matches,
                         options.max_iterations, options.huber_px);
    out.rounds.push_back(fit.camera_T_object);
  }
  if (!failed && options.support_refine_6dof) {
    const EdgeMatchSet on_plane = MatchEdges(model, K, fit.camera_T_object, lines, options.match_distance_px, match_angle);
    const FitResult free = FitPoseToLines(model.box_size_m, K, fit.camera_T_object, on_plane.matches,
                                          options.max_iterations, options.huber_px);
    const EdgeMatchSet refined = MatchEdges(model, K, free.camera_T_object, lines, options.match_distance_px, match_angle);
    if (refined.matches.size() >= 3 && refined.matched_fraction >= on_plane.matched_fraction) {
      const double rms_free = FitPoseToLines(model.box_size_m, K, free.camera_T_object, refined.matches, 0, 0).rms_px;
      const double rms_plane = FitPoseToLines(model.box_size_m, K, fit.camera_T_object, on_plane.matches, 0, 0).rms_px;
      if (rms_free <= rms_plane) {
        fit = free;
        out.rounds.push_back(fit.camera_T_object);
      }
    }
  }
  return out;
}

HypothesisFit FitIndexHypothesis(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& initial,
                                 const std::vector<LineMatch>& seed_matches, const std::vector<ImageLine>& lines,
                                 const RecognizerOptions& options) {
  HypothesisFit out;
  const double match_angle = options.match_angle_deg * M_PI / 180;
  FitResult& fit = out.fit;
  bool& failed = out.failed;
  fit = FitPoseToLines(model.box_size_m, K, initial, seed_matches, 8, options.huber_px);
  out.rounds.push_back(fit.camera_T_object);
  for (int round = 0; round < 3; ++round) {
    const double loose = round == 0 ? 3.0 : round == 1 ? 1.5 : 1.0;
    const EdgeMatchSet set =
        MatchEdges(model, K, fit.camera_T_object, lines, loose * options.match_distance_px, loose * match_angle);
    if (set.matches.size() < 3 || fit.camera_T_object.translation.z() <= 0.05) {
      failed = true;
      break;
    }
    fit = FitPoseToLines(model.box_size_m, K, fit.camera_T_object, set.matches, options.max_iterations,
                         options.huber_px);
    out.rounds.push_back(fit.camera_T_object);
  }
  return out;
}

}  // namespace teachsim::vision
