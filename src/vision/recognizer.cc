// The recognizer (issue 7; paper §4.1-4.3, §7.1): hypotheses from the model-view index (Beis & Lowe;
// model_index.cc) and, in parallel, from image corners of blocks resting on a support plane
// (support_hypotheses.cc), Lowe's pose fit, verification; the model editor's rules are in model_editor.cc.
#include "teachsim/vision/recognizer.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <set>
#include <unordered_map>

#include "model_editor.h"
#include "model_index.h"
#include "sampling.h"
#include "teachsim/base/json.h"
#include "teachsim/vision/evaluate.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

using internal::ApplyModelEditorRules;
using internal::BoxWorldVertices;
using internal::FixedPart;
using internal::FixedWorld;
using internal::HiddenByAny;
using internal::Hides;
using internal::Hypothesis;
using internal::IndexHypotheses;
using internal::InitialPose;
using internal::kOccluderMarginM;
using internal::LowestZ;
using internal::MakeOccluder;
using internal::Occluder;
using internal::PartPenetration;
using internal::ReadFixedWorld;
using internal::SampleGrey;

// ---------------------------------------------------------------- options and models

Status RecognizerOptions::Validate() const {
  auto positive = [](const char* name, double v) -> Status {
    if (!(v > 0) || !std::isfinite(v)) {
      return Status::InvalidInput(std::string("RecognizerOptions::") + name + " = " + json::FormatNumber(v) +
                                  " must be > 0");
    }
    return Status::Ok();
  };
  auto fraction = [](const char* name, double v) -> Status {
    if (!(v >= 0 && v <= 1)) {
      return Status::InvalidInput(std::string("RecognizerOptions::") + name + " = " + json::FormatNumber(v) +
                                  " must be in [0, 1]");
    }
    return Status::Ok();
  };
  // An integer limit that may be 0; `zero` says what 0 means, if anything.
  auto non_negative = [](const char* name, int v, const char* zero = "") -> Status {
    if (v < 0) {
      return Status::InvalidInput(std::string("RecognizerOptions::") + name + " = " + std::to_string(v) +
                                  " must be >= 0" + zero);
    }
    return Status::Ok();
  };
  TEACHSIM_RETURN_IF_ERROR(positive("canny_low", canny_low));
  TEACHSIM_RETURN_IF_ERROR(positive("canny_high", canny_high));
  if (canny_high < canny_low) {
    return Status::InvalidInput("RecognizerOptions::canny_high = " + json::FormatNumber(canny_high) +
                                " must be >= canny_low = " + json::FormatNumber(canny_low));
  }
  TEACHSIM_RETURN_IF_ERROR(positive("min_segment_length_px", min_segment_length_px));
  TEACHSIM_RETURN_IF_ERROR(positive("split_tolerance_px", split_tolerance_px));
  TEACHSIM_RETURN_IF_ERROR(positive("junction_gap_px", junction_gap_px));
  TEACHSIM_RETURN_IF_ERROR(positive("view_sphere_samples", view_sphere_samples));
  if (view_distances_m.empty()) return Status::InvalidInput("RecognizerOptions::view_distances_m must not be empty");
  for (double d : view_distances_m) TEACHSIM_RETURN_IF_ERROR(positive("view_distances_m[]", d));
  TEACHSIM_RETURN_IF_ERROR(positive("neighbours", neighbours));
  if (!(index_search_eps >= 0)) {
    return Status::InvalidInput("RecognizerOptions::index_search_eps = " +
                                json::FormatNumber(index_search_eps) + " must be >= 0 (0: exact)");
  }
  TEACHSIM_RETURN_IF_ERROR(positive("max_index_queries", max_index_queries));
  TEACHSIM_RETURN_IF_ERROR(positive("max_hypotheses", max_hypotheses));
  TEACHSIM_RETURN_IF_ERROR(positive("max_support_hypotheses", max_support_hypotheses));
  TEACHSIM_RETURN_IF_ERROR(fraction("support_min_score", support_min_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("support_corner_ridge_share", support_corner_ridge_share));
  TEACHSIM_RETURN_IF_ERROR(positive("support_corner_ridge_grey", support_corner_ridge_grey));
  TEACHSIM_RETURN_IF_ERROR(non_negative("support_contour_reserve", support_contour_reserve));
  TEACHSIM_RETURN_IF_ERROR(
      non_negative("support_corner_ridge_min_corners", support_corner_ridge_min_corners));
  TEACHSIM_RETURN_IF_ERROR(non_negative("conflict_balance_margin", conflict_balance_margin, " (0: off)"));
  TEACHSIM_RETURN_IF_ERROR(non_negative("conflict_own_lead", conflict_own_lead, " (0: off)"));
  TEACHSIM_RETURN_IF_ERROR(non_negative("min_own_balance", min_own_balance, " (0: off)"));
  TEACHSIM_RETURN_IF_ERROR(fraction("conflict_rank_share", conflict_rank_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("conflict_in_image_lead", conflict_in_image_lead));
  TEACHSIM_RETURN_IF_ERROR(fraction("conflict_tie_rank_share", conflict_tie_rank_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("conflict_rms_ratio", conflict_rms_ratio));
  TEACHSIM_RETURN_IF_ERROR(fraction("conflict_score_lead", conflict_score_lead));
  TEACHSIM_RETURN_IF_ERROR(fraction("conflict_bare_table_share", conflict_bare_table_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("max_bare_table_share", max_bare_table_share));
  TEACHSIM_RETURN_IF_ERROR(non_negative("max_alternative_fits", max_alternative_fits, " (0: none)"));
  if (!(support_tight_fit_shift_px >= 0) || !std::isfinite(support_tight_fit_shift_px)) {
    return Status::InvalidInput(
        "RecognizerOptions::support_tight_fit_shift_px = " + json::FormatNumber(support_tight_fit_shift_px) +
        " must be >= 0 (0: no second fit)");
  }
  TEACHSIM_RETURN_IF_ERROR(positive("alternatives_per_model", alternatives_per_model));
  TEACHSIM_RETURN_IF_ERROR(positive("support_perpendicular_tol_deg", support_perpendicular_tol_deg));
  TEACHSIM_RETURN_IF_ERROR(positive("support_vertical_tol_deg", support_vertical_tol_deg));
  TEACHSIM_RETURN_IF_ERROR(positive("max_iterations", max_iterations));
  if (!(huber_px >= 0)) return Status::InvalidInput("RecognizerOptions::huber_px must be >= 0 (0: plain least squares)");
  TEACHSIM_RETURN_IF_ERROR(positive("match_distance_px", match_distance_px));
  TEACHSIM_RETURN_IF_ERROR(positive("match_angle_deg", match_angle_deg));
  TEACHSIM_RETURN_IF_ERROR(fraction("min_matched_edge_fraction", min_matched_edge_fraction));
  TEACHSIM_RETURN_IF_ERROR(fraction("matched_share_min_in_image", matched_share_min_in_image));
  TEACHSIM_RETURN_IF_ERROR(fraction("occlusion_min_hidden_share", occlusion_min_hidden_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("occlusion_min_shown_share", occlusion_min_shown_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("occlusion_min_evidence_score", occlusion_min_evidence_score));
  TEACHSIM_RETURN_IF_ERROR(positive("contour_min_length_px", contour_min_length_px));
  if (!(contour_min_step_grey >= 0))
    return Status::InvalidInput("RecognizerOptions::contour_min_step_grey must be >= 0");
  TEACHSIM_RETURN_IF_ERROR(fraction("contour_max_hidden_coverage", contour_max_hidden_coverage));
  TEACHSIM_RETURN_IF_ERROR(fraction("contour_min_shown_share", contour_min_shown_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("contour_low_shown_share", contour_low_shown_share));
  TEACHSIM_RETURN_IF_ERROR(fraction("contour_low_shown_score", contour_low_shown_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("contour_bare_max_coverage", contour_bare_max_coverage));
  TEACHSIM_RETURN_IF_ERROR(fraction("contour_bare_min_evidence_score", contour_bare_min_evidence_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("matched_share_rescue_score", matched_share_rescue_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("min_score", min_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("min_coverage", min_coverage));
  if (!(min_edge_contrast >= 0)) return Status::InvalidInput("RecognizerOptions::min_edge_contrast must be >= 0");
  TEACHSIM_RETURN_IF_ERROR(fraction("min_step_share", min_step_share));
  if (!(step_offset_px > 0 && step_offset_px <= 20)) {
    return Status::InvalidInput("RecognizerOptions::step_offset_px must be in (0, 20]");
  }
  if (!(min_step_grey >= 0)) return Status::InvalidInput("RecognizerOptions::min_step_grey must be >= 0");
  TEACHSIM_RETURN_IF_ERROR(positive("max_reprojection_rms_px", max_reprojection_rms_px));
  if (!(ladder_search_m >= 0 && ladder_search_m <= 0.1)) {
    return Status::InvalidInput(
        "RecognizerOptions::ladder_search_m must be in [0, 0.1] (0: the ladder check off)");
  }
  if (ladder_search_m > 0 && !(ladder_step_m >= 0.2e-3 && ladder_step_m <= ladder_search_m)) {
    return Status::InvalidInput("RecognizerOptions::ladder_step_m must be in [0.0002, ladder_search_m]");
  }
  if (!(ladder_margin >= 0)) return Status::InvalidInput("RecognizerOptions::ladder_margin must be >= 0");
  TEACHSIM_RETURN_IF_ERROR(fraction("ladder_score_gain", ladder_score_gain));
  TEACHSIM_RETURN_IF_ERROR(fraction("ladder_max_coverage", ladder_max_coverage));
  TEACHSIM_RETURN_IF_ERROR(positive("refit_max_rms_px", refit_max_rms_px));
  TEACHSIM_RETURN_IF_ERROR(fraction("refit_min_coverage", refit_min_coverage));
  TEACHSIM_RETURN_IF_ERROR(fraction("refit_accept_score", refit_accept_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("refit_min_in_image", refit_min_in_image));
  TEACHSIM_RETURN_IF_ERROR(fraction("min_evidence_score", min_evidence_score));
  TEACHSIM_RETURN_IF_ERROR(fraction("accept_evidence_score", accept_evidence_score));
  if (accept_evidence_score < min_evidence_score) {
    return Status::InvalidInput(
        "RecognizerOptions::accept_evidence_score = " + json::FormatNumber(accept_evidence_score) +
        " must be >= min_evidence_score = " + json::FormatNumber(min_evidence_score));
  }
  TEACHSIM_RETURN_IF_ERROR(positive("work_area_radius_m", work_area_radius_m));
  TEACHSIM_RETURN_IF_ERROR(positive("support_tolerance_m", support_tolerance_m));
  if (!(support_centre_slack_m >= 0)) {
    return Status::InvalidInput("RecognizerOptions::support_centre_slack_m = " +
                                json::FormatNumber(support_centre_slack_m) + " must be >= 0");
  }
  if (!(below_table_tolerance_m >= 0)) return Status::InvalidInput("RecognizerOptions::below_table_tolerance_m must be >= 0");
  if (!(table_snap_distance_m >= 0)) return Status::InvalidInput("RecognizerOptions::table_snap_distance_m must be >= 0");
  if (!(table_snap_max_tilt_deg >= 0 && table_snap_max_tilt_deg < 45)) {
    return Status::InvalidInput("RecognizerOptions::table_snap_max_tilt_deg = " +
                                json::FormatNumber(table_snap_max_tilt_deg) + " must be in [0, 45)");
  }
  return Status::Ok();
}

namespace {

Status AddModel(ModelLibrary* library, const std::string& name, const Eigen::Vector3d& size, const std::string& where) {
  for (const Model& m : library->models) {
    if (m.name != name) continue;
    if ((m.box_size_m - size).norm() > 1e-9) {
      return Status::InvalidInput(where + ": model \"" + name + "\" is given twice with different sizes");
    }
    return Status::Ok();
  }
  library->models.push_back({name, size});
  return Status::Ok();
}

}  // namespace

Result<ModelLibrary> LoadModels(const std::string& path) {
  TEACHSIM_ASSIGN_OR_RETURN(json::Json document, json::ReadFile(path));
  ModelLibrary library;
  if (document.is_object() && document.contains("models")) {
    return json::Decode<ModelLibrary>(document, path, [&](const json::Reader& root) {
      root.RejectUnknownKeys({"models"});
      const json::Reader models = root.At("models");
      if (models.Size() == 0) throw json::ParseError(models.where() + ": must hold at least one model");
      for (std::size_t i = 0; i < models.Size(); ++i) {
        const json::Reader m = models.Index(i);
        m.RejectUnknownKeys({"name", "shape"});
        const std::string name = m.At("name").NonEmptyString();
        const scene::ShapeSpec spec = scene::ReadShapeSpec(m.At("shape"));
        if (spec.kind != scene::ShapeSpec::Kind::kBox) {
          throw json::ParseError(m.At("shape").where() + ": the recognizer's models are boxes ({\"box\": [sx, sy, sz]})");
        }
        Status s = AddModel(&library, name, spec.box_size, m.where());
        if (!s.ok()) throw json::ParseError(s.message());
      }
      return library;
    });
  }
  // A scene: its movable box-shaped objects.
  auto scene_result = scene::ParseScene(document, path);
  if (!scene_result.ok()) return scene_result.status();
  for (size_t i = 0; i < scene_result->objects.size(); ++i) {
    const scene::SceneObject& o = scene_result->objects[i];
    if (o.fixed || o.shape_spec.kind != scene::ShapeSpec::Kind::kBox) continue;
    TEACHSIM_RETURN_IF_ERROR(AddModel(&library, o.model.empty() ? o.name : o.model, o.shape_spec.box_size,
                                      path + ": objects[" + std::to_string(i) + "]"));
  }
  if (library.models.empty()) {
    return Status::InvalidInput(path + ": objects: the scene has no movable box-shaped object to use as a model");
  }
  return library;
}

// ---------------------------------------------------------------- symmetry

double SymmetricRotationAngle(const Model& model, const geometry::Pose3& a, const geometry::Pose3& b) {
  // The support-plane stage's thinning compares each placement with up to 80 kept ones, and PlaceSet
  // calls this too: building the group on every call (and an atan2 per element, now one) took 5 % of
  // a recognition (perf, render seed 9). A library has a few sizes: a short list per thread,
  // searched in order, begun again past 64 sizes.
  struct SizeGroup {
    Eigen::Vector3d size;
    std::vector<Eigen::Quaterniond> symmetries;
  };
  thread_local std::vector<SizeGroup> groups;
  const Eigen::Vector3d& size = model.box_size_m;
  const SizeGroup* group = nullptr;
  for (const SizeGroup& g : groups) {
    if (g.size == size) {
      group = &g;
      break;
    }
  }
  if (group == nullptr) {
    if (groups.size() >= 64) groups.clear();
    groups.push_back({size, BoxSymmetries(size, 1e-6 * size.maxCoeff())});
    group = &groups.back();
  }
  return SymmetricRotationError(b.rotation, a.rotation, group->symmetries);
}

size_t Recognizer::index_size() const { return index_ ? index_->size() : 0; }

Result<Recognizer> Recognizer::Create(const ModelLibrary& models, const RecognizerOptions& options,
                                      const std::string& cache_dir) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  if (models.models.empty()) return Status::InvalidInput("model library: no models");
  if (models.models.size() > 65535) return Status::InvalidInput("model library: more than 65535 models");
  for (const Model& m : models.models) {
    if (!(m.box_size_m.array() > 0).all() || !m.box_size_m.allFinite()) {
      return Status::InvalidInput("model library: model \"" + m.name + "\": box sides must be finite and > 0");
    }
  }
  Recognizer r;
  r.models_ = models;
  r.options_ = options;
  TEACHSIM_ASSIGN_OR_RETURN(r.index_,
                            internal::LoadOrBuildIndex(models, options, cache_dir, &r.loaded_from_cache_));
  return r;
}

// ---------------------------------------------------------------- recognition

namespace {

// A pose whose RMS is within the limit only over each predicted edge's closest segments must have
// this much of its outline matched by lines, this much edge support along its whole outline, and no
// more image edges running on past its corners.
constexpr double kTrimmedMinMatchedFraction = 0.5;
constexpr double kTrimmedMinCoverage = 0.65;
constexpr int kTrimmedMaxContinuedEnds = 1;
// Occlusion consistency: a recognition that would hide this many samples (2.5 px apart) of an accepted
// recognition's predicted edges where the image shows an edge is not there.
constexpr int kMaxHiddenSupportedSamples = 12;
// Part of a larger straight-edged thing: image edges run on past this many of the pose's edge ends
// (over most of the edge's length) while its outline's support (coverage) is under this.
constexpr int kPartMinContinuedEnds = 2;
constexpr double kPartMaxCoverage = 0.62;
// The selection's pairwise test (RecognizerOptions::conflict_balance_margin): the rival a candidate
// replaces predicts no more than this balance of its own outline (OwnOutlineBalance). Chosen on the
// renders of seeds 7-19: the 4 replacements whose rival's own balance was -2 to 3 each put the
// right model in a wrong one's place; of those above (8 to 131) 6 did the reverse and 4 did not.
constexpr int kRivalMaxOwnBalance = 3;
using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

// The grey-level step across a predicted edge: the smoothed image offset_px to either side of `c`
// along the unit `normal`, their difference's size.
double GreyStepAcross(const EdgeMap& edge_map, const Eigen::Vector2d& c, const Eigen::Vector2d& normal,
                      double offset_px) {
  return std::abs(SampleGrey(edge_map.smoothed, c + offset_px * normal) -
                  SampleGrey(edge_map.smoothed, c - offset_px * normal));
}
// A predicted edge is informative where the image shows this step across it at kContrastOffsetPx to
// either side (RecognizerOptions::min_edge_contrast): a lit face against the lit table shows none.
constexpr double kContrastOffsetPx = 2.5;
// Samples every kOutlineSpacingPx along each visible predicted edge of a box in the image (the ends
// left out: corners blur and shadows meet there): visit(point_in_camera, pixel, normal, edge) with the
// unit normal to the projected edge and the box edge's index. Only the part of an edge in the
// camera's view is sampled (Camera::SegmentInView): a pose with a corner next to the camera plane
// (some fits and their rejected poses end so) once took 3.7 s in the occlusion pass, sampling an edge
// that projected millions of pixels long, and the lens model folds far-off points into the picture.
constexpr double kOutlineSpacingPx = 2.5;
template <typename Visit>
void ForEachOutlineSample(const Eigen::Vector3d& box_size_m, const geometry::Pose3& camera_T_object, const Camera& camera,
                          Visit&& visit) {
  constexpr double kEndShare = 0.08;  // of each edge's length, left out at both ends
  const uint16_t visible = VisibleBoxEdges(box_size_m, camera_T_object.Inverse().translation);
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector3d p = camera_T_object * BoxVertex(box_size_m, kBoxEdges[e][0]);
    const Eigen::Vector3d q = camera_T_object * BoxVertex(box_size_m, kBoxEdges[e][1]);
    const auto in_view = camera.SegmentInView(p, q);
    if (!in_view) continue;
    // The samples' span along the edge: all of it but the ends, or the part of that in view.
    double first = kEndShare, span = 1 - 2 * kEndShare;
    const bool whole = in_view->first == 0 && in_view->second == 1;
    if (!whole) {
      first = std::max(first, in_view->first);
      span = std::min(1 - kEndShare, in_view->second) - first;
      if (!(span > 0)) continue;
    }
    const auto pp = camera.ProjectFromCamera(whole ? p : p + in_view->first * (q - p));
    const auto pq = camera.ProjectFromCamera(whole ? q : p + in_view->second * (q - p));
    if (!pp || !pq) continue;
    const int n = std::max(4, static_cast<int>(((*pq - *pp).norm()) / kOutlineSpacingPx));
    for (int i = 0; i < n; ++i) {
      const double t = first + span * (i + 0.5) / n;
      const Eigen::Vector3d point = p + t * (q - p);
      const auto c = camera.ProjectFromCamera(point);
      const auto c2 = camera.ProjectFromCamera(p + (t + 0.01) * (q - p));
      if (!c || !c2 || !camera.InImage(*c)) continue;
      const Eigen::Vector2d along = (*c2 - *c).normalized();
      visit(point, *c, Eigen::Vector2d(-along.y(), along.x()), e);
    }
  }
}

// The step rule (RecognizerOptions::min_step_share): the supported outline is mostly a step in grey
// level between two surfaces, not a thin line.
bool StepRule(const PoseEvidence& e, const RecognizerOptions& options) {
  return e.step_supported_px >= options.min_step_share * e.supported_px;
}

// Image edges that run on past the ends of the predicted edges: a block's visible edges end at its
// corners, but a smaller wrong model fitted onto part of a real block (a cube on a bar) or onto the
// straight sides of the dark cylinder ends where the real thing's edges go on. Counts the ends of
// visible predicted edges (40 px long or more) whose collinear continuation beyond the corner, from
// 5 px on over relative_length times the edge's length (20 to 80 px), is supported by Canny edges
// across it at min_share of the samples or more.
int ContinuedEdgeEnds(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                      const EdgeMap& edge_map, double min_share, double relative_length) {
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_object.Inverse().translation);
  constexpr double kStartPx = 5, kSpacingPx = 2, kMinEdgePx = 40, kMinRunPx = 20, kMaxRunPx = 80;
  int continued = 0;
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    for (int end = 0; end < 2; ++end) {
      const Eigen::Vector3d v = camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[e][end]);
      const Eigen::Vector3d w = camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[e][1 - end]);
      const auto pv = camera.ProjectFromCamera(v), pin = camera.ProjectFromCamera(v + 0.05 * (w - v));
      const auto pw = camera.ProjectFromCamera(w);
      if (!pv || !pin || !pw) continue;
      const double edge_px = (*pw - *pv).norm();
      if (edge_px < kMinEdgePx) continue;
      const double run_px = std::clamp(relative_length * edge_px, kMinRunPx, kMaxRunPx);
      const Eigen::Vector2d out = (*pv - *pin).normalized();
      const Eigen::Vector2d normal(-out.y(), out.x());
      int samples = 0, supported = 0;
      for (double d = kStartPx; d <= kStartPx + run_px; d += kSpacingPx) {
        const Eigen::Vector2d c = *pv + d * out;
        if (!camera.InImage(c)) continue;
        ++samples;
        supported += EdgeAcross(edge_map, c, normal) ? 1 : 0;
      }
      if (samples >= 6 && supported >= min_share * samples) ++continued;
    }
  }
  return continued;
}

// The matches that lie on their predicted edge: per edge, the segments no farther from it than its
// closest segment plus kSpreadPx. A shadow or grain line running beside a real edge (3-6 px off,
// within the match distance) is then left out of the RMS when the edge's own line was found.
std::vector<LineMatch> ClosestMatchesPerEdge(const Model& model, const Eigen::Matrix3d& K,
                                             const geometry::Pose3& camera_T_object,
                                             const std::vector<LineMatch>& matches) {
  constexpr double kSpreadPx = 1.0;
  std::array<double, 12> closest;
  closest.fill(1e300);
  std::vector<double> offset(matches.size());
  for (size_t i = 0; i < matches.size(); ++i) {
    const LineMatch& m = matches[i];
    const Eigen::Vector3d p = K * (camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[m.edge][0]));
    const Eigen::Vector3d q = K * (camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[m.edge][1]));
    const Eigen::Vector2d a = p.head<2>() / p.z(), b = q.head<2>() / q.z();
    const Eigen::Vector2d dir = (b - a).normalized(), n(-dir.y(), dir.x());
    offset[i] = 0.5 * (std::abs(n.dot(m.a - a)) + std::abs(n.dot(m.b - a)));
    closest[static_cast<size_t>(m.edge)] = std::min(closest[static_cast<size_t>(m.edge)], offset[i]);
  }
  std::vector<LineMatch> out;
  for (size_t i = 0; i < matches.size(); ++i) {
    if (offset[i] <= closest[static_cast<size_t>(matches[i].edge)] + kSpreadPx) out.push_back(matches[i]);
  }
  return out;
}

// Occlusion consistency: the samples of `behind`'s predicted edges that show an image edge with a
// step in grey level across it (as the step rule asks of supported outline) but that `front`, were it
// there, would hide (the ray from the camera to the edge point passes through front's box, shrunk by
// kHideMarginM so that edges on front's own outline and edges touching it do not count). A pose that
// would hide edges the image shows is wrong. A thin line without a step is not counted: it is the
// grain on front's own faces more often than a hidden edge showing through (the benchmark's renders,
// seeds 7-31: four blocks were lost so to a true block in front of them; in the one looked at closely,
// seed 18 image 30, the upright bar's grain ran along the hidden edge of the cube behind it).
int HiddenSupportedSamples(const Model& behind_model, const geometry::Pose3& camera_T_behind,
                           const Model& front_model, const geometry::Pose3& camera_T_front,
                           const Camera& camera, const EdgeMap& edge_map, const RecognizerOptions& options) {
  constexpr double kHideMarginM = 0.004;
  const std::optional<Occluder> front = MakeOccluder(front_model, camera_T_front, kHideMarginM);
  if (!front) return 0;
  int hidden = 0;
  ForEachOutlineSample(
      behind_model.box_size_m, camera_T_behind, camera,
      [&](const Eigen::Vector3d& point, const Eigen::Vector2d& c, const Eigen::Vector2d& normal, int) {
        if (Hides(*front, point) && EdgeAcross(edge_map, c, normal) &&
            GreyStepAcross(edge_map, c, normal, options.step_offset_px) >= options.min_step_grey) {
          ++hidden;
        }
      });
  return hidden;
}

// What hides part of a pose's outline in the occlusion pass: accepted recognitions' boxes, or an
// occluding contour.
struct Hiding {
  const std::vector<Occluder>* boxes = nullptr;
  const ContourOccluder* contour = nullptr;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();  // for the contour (pin-hole, undistorted px)
  bool operator()(const Eigen::Vector3d& point_in_camera) const {
    if (boxes != nullptr && HiddenByAny(*boxes, point_in_camera)) return true;
    return contour != nullptr && point_in_camera.z() > 1e-6 &&
           contour->Hides((K * point_in_camera).hnormalized());
  }
};

// Of a pose's outline samples inside the image: the share hidden, and the share of the hidden ones
// with an edge across (where something in front hides the outline, the image shows little of it).
struct HiddenOutline {
  double share = 0, coverage = 0;
};
// A pose's outline samples (ForEachOutlineSample), kept to be judged against several ways of hiding
// it, each sample's edge support found on first use.
struct OutlineSamples {
  struct Sample {
    Eigen::Vector3d point;  // in the camera frame
    Eigen::Vector2d pixel, normal;
    int8_t edge = -1;  // EdgeAcross: -1 not yet asked, else 0 or 1
  };
  std::vector<Sample> samples;
  OutlineSamples(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object) {
    ForEachOutlineSample(
        model.box_size_m, camera_T_object, camera,
        [&](const Eigen::Vector3d& point, const Eigen::Vector2d& c, const Eigen::Vector2d& normal, int) {
          samples.push_back({point, c, normal});
        });
  }
};
HiddenOutline HiddenOutlineShare(OutlineSamples* outline, const Hiding& hiding, const EdgeMap& edge_map) {
  int hidden = 0, supported = 0;
  const int total = static_cast<int>(outline->samples.size());
  for (OutlineSamples::Sample& s : outline->samples) {
    if (!hiding(s.point)) continue;
    ++hidden;
    if (s.edge < 0) s.edge = EdgeAcross(edge_map, s.pixel, s.normal) ? 1 : 0;
    supported += s.edge;
  }
  HiddenOutline out;
  if (total > 0) out.share = static_cast<double>(hidden) / total;
  if (hidden > 0) out.coverage = static_cast<double>(supported) / hidden;
  return out;
}

// The evidence for a pose (what verification decides on): matched lines and their residuals, and
// edge support sample by sample along the visible predicted edges (distorted image): a sample is
// supported by a Canny edge within 2 px across the edge whose gradient is across the edge. Where the
// image shows no contrast across the predicted edge (a lit face against the lit table) no edge can be
// expected: such samples are uninformative and left out of support_fraction (not of coverage). The
// free_* fields leave out the samples that run along the fixed world's edges. With occluders, the
// samples they hide are left out altogether (the occlusion pass, RecognizerOptions::occlusion_reverify).
PoseEvidence ComputeEvidence(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                             const LineDetection& detection, const FixedEdgeMap* fixed,
                             const RecognizerOptions& options, const EdgeMatchSet& set,
                             const Hiding* hiding = nullptr) {
  const Eigen::Matrix3d K = camera.K();
  PoseEvidence out;
  out.matched_fraction = set.matched_fraction;
  out.matches = static_cast<int>(set.matches.size());
  if (!set.matches.empty()) {
    out.rms_px = LineResidualRmsPx(model.box_size_m, K, camera_T_object, set.matches);
    out.rms_closest_px = LineResidualRmsPx(model.box_size_m, K, camera_T_object,
                                           ClosestMatchesPerEdge(model, K, camera_T_object, set.matches));
  }
  struct PerEdge {
    int samples = 0, free = 0, supported = 0, plus = 0, minus = 0;
    double length_px = 0;
  };
  std::array<PerEdge, 12> per_edge{};
  int samples = 0, on_fixed = 0, supported = 0, informative = 0, free_supported = 0, free_informative = 0;
  int step_supported = 0;
  ForEachOutlineSample(
      model.box_size_m, camera_T_object, camera,
      [&](const Eigen::Vector3d& point, const Eigen::Vector2d& c, const Eigen::Vector2d& normal, int e) {
        if (hiding != nullptr && (*hiding)(point)) return;
        PerEdge& pe = per_edge[static_cast<size_t>(e)];
        ++samples;
        ++pe.samples;
        const std::optional<EdgePixel> edge = EdgePixelAcross(detection.edge_map, c, normal, 2);
        const int sign = edge ? EdgeSign(*edge, normal) : 0;
        if (edge &&
            GreyStepAcross(detection.edge_map, c, normal, options.step_offset_px) >= options.min_step_grey) {
          ++step_supported;
        }
        const bool contrast = sign != 0 || GreyStepAcross(detection.edge_map, c, normal, kContrastOffsetPx) >=
                                               options.min_edge_contrast;
        supported += sign != 0 ? 1 : 0;
        informative += contrast ? 1 : 0;
        if (fixed != nullptr && OnFixedEdge(*fixed, c, normal)) {
          ++on_fixed;
          return;
        }
        ++pe.free;
        if (sign != 0) {
          ++pe.supported;
          (sign > 0 ? pe.plus : pe.minus) += 1;
          ++free_supported;
        }
        free_informative += contrast ? 1 : 0;
      });
  out.support_fraction = informative > 0 ? static_cast<double>(supported) / informative : 0;
  out.coverage = samples > 0 ? static_cast<double>(supported) / samples : 0;
  out.supported_px = supported * kOutlineSpacingPx;
  out.step_supported_px = step_supported * kOutlineSpacingPx;
  out.fixed_share = samples > 0 ? static_cast<double>(on_fixed) / samples : 0;
  out.free_support_fraction =
      free_informative > 0 ? static_cast<double>(free_supported) / free_informative : 0;
  out.free_coverage = samples > 0 ? static_cast<double>(free_supported) / samples : 0;
  out.free_supported_px = free_supported * kOutlineSpacingPx;
  int majority = 0, signed_total = 0;
  for (const PerEdge& pe : per_edge) {
    majority += std::max(pe.plus, pe.minus);
    signed_total += pe.plus + pe.minus;
    if (pe.samples * kOutlineSpacingPx < 20) continue;
    out.edges_visible += 1;
    if (pe.free > 0 && 2 * pe.supported >= pe.free) out.edges_supported += 1;
  }
  out.polarity = signed_total > 0 ? static_cast<double>(majority) / signed_total : 0;
  out.continued_ends = ContinuedEdgeEnds(model, camera, camera_T_object, detection.edge_map, 0.8, 0);
  out.long_continued_ends = ContinuedEdgeEnds(model, camera, camera_T_object, detection.edge_map, 0.7, 0.8);
  return out;
}

struct Candidate {
  int trace_index = -1;  // into RecognitionTrace::fitted
  int model = 0;
  geometry::Pose3 camera_T_object;
  FitResult fit;
  EdgeMatchSet matches;
  PoseEvidence evidence;
  double rms_px = 0;
  double rank_score =
      0;  // the evidence score the selection ranks by (of a refitted pose: with its lines' RMS)
};

// Whether a pose rests on the table: its lowest point within distance_m of the table top and one of
// its faces within tilt_deg of level (the model editor's tolerances: table_snap_distance_m and
// table_snap_max_tilt_deg).
bool RestsOnTable(const Model& model, const geometry::Pose3& world_T_object, double table_top_z,
                  double distance_m, double tilt_deg) {
  const Eigen::Matrix3d rotation = world_T_object.RotationMatrix();
  const double up = rotation.row(2).cwiseAbs().maxCoeff();  // cosine of the most vertical axis' tilt
  return std::abs(LowestZ(model, world_T_object) - table_top_z) <= distance_m &&
         up >= std::cos(tilt_deg * M_PI / 180);
}

}  // namespace

// NetSupportPx (recognition_stages.h), the ranking of the non-maximum suppression: supported length less the
// unsupported length of the predicted outline, so that of two poses explaining the same image edges the one
// that predicts less outline where the image shows nothing (an upright slab over a cube and the table) comes
// first. By supported length times support fraction, the benchmark's demo (cornering, seed 7) lost the cube
// to such a slab. Only outline where the grey level steps across counts as supported length: a slab laid onto
// a bar with one edge along a grain line of the bar's top otherwise outranked the bar (its longer outline is
// as well supported, by the line).
double NetSupportPx(const PoseEvidence& e) {
  return e.step_supported_px * (2 - 1 / std::max(e.coverage, 1e-3));
}

bool ContinuesPastHiddenEnd(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                            const ContourOccluder& occluder, const EdgeMap& edge_map,
                            const RecognizerOptions& options) {
  constexpr double kRunPx = 20;
  const Eigen::Matrix3d K = camera.K();
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_object.Inverse().translation);
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector3d p = camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[e][0]);
    const Eigen::Vector3d q = camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[e][1]);
    if (!(p.z() > 1e-3) || !(q.z() > 1e-3)) continue;
    const bool p_hidden = occluder.Hides((K * p).hnormalized()),
               q_hidden = occluder.Hides((K * q).hnormalized());
    if (p_hidden == q_hidden) continue;
    const Eigen::Vector3d from = p_hidden ? p : q,
                          step = p_hidden ? Eigen::Vector3d(p - q) : Eigen::Vector3d(q - p);
    const auto a = camera.ProjectFromCamera(from), b = camera.ProjectFromCamera(from + step);
    if (!a || !b) continue;
    const int n = static_cast<int>((*b - *a).norm() / kOutlineSpacingPx);
    int run = 0;
    for (int i = 1; i <= n; ++i) {
      const double t = static_cast<double>(i) / n;
      const auto c = camera.ProjectFromCamera(from + t * step),
                 c2 = camera.ProjectFromCamera(from + (t + 0.01) * step);
      if (!c || !c2 || !camera.InImage(*c)) {
        run = 0;
        continue;
      }
      const Eigen::Vector2d along = (*c2 - *c).normalized(), normal(-along.y(), along.x());
      const bool supported =
          EdgeAcross(edge_map, *c, normal) &&
          GreyStepAcross(edge_map, *c, normal, options.step_offset_px) >= options.min_step_grey;
      run = supported ? run + 1 : 0;
      if (run * kOutlineSpacingPx >= kRunPx) return true;
    }
  }
  return false;
}

FixedEdgeMap ProjectFixedEdges(const scene::Scene* fixed_world, const Camera& camera, int max_16bit_pieces) {
  FixedEdgeMap out;
  if (fixed_world == nullptr) return out;
  // Each piece's direction as the float a direction image would hold, one entry per distinct
  // direction. The image of entries is made at the first piece drawn, 16-bit; should there be more
  // than max_16bit_pieces entries (no scene of ours comes near: the puzzle scene draws 720 pieces),
  // it becomes 32-bit, with the same entries.
  std::unordered_map<float, int> entry_of;
  auto entry = [&](float angle) -> int {
    const auto [it, added] = entry_of.emplace(angle, static_cast<int>(out.direction.size()) + 1);
    if (added) {
      out.direction.push_back({std::cos(angle), std::sin(angle)});
      if (out.piece.empty()) out.piece = cv::Mat::zeros(camera.height(), camera.width(), CV_16U);
      if (out.piece.depth() == CV_16U && it->second > std::min(max_16bit_pieces, 65535)) {
        out.piece.convertTo(out.piece, CV_32S);
      }
    }
    return it->second;
  };
  const geometry::Pose3& world_T_camera = camera.world_T_camera();
  const geometry::Pose3 camera_T_world = world_T_camera.Inverse();
  constexpr double kStepPx = 6, kHalfWidthPx = 2, kMarginPx = 50;
  constexpr int kMaxSteps = 400;
  for (const scene::SceneObject& o : fixed_world->objects) {
    if (!o.fixed) continue;
    for (const geometry::ShapePart& part : o.shape.parts()) {
      const geometry::Pose3 camera_T_part = camera_T_world * o.world_T_object * part.shape_T_part;
      const Eigen::Vector3d eye_in_part = camera_T_part.Inverse().translation;
      const auto& vertices = part.convex->vertices();
      const auto& faces = part.convex->faces();
      for (const geometry::Edge& e : part.convex->edges()) {
        const Eigen::Vector3d& a = vertices[static_cast<size_t>(e.v0)];
        const Eigen::Vector3d& b = vertices[static_cast<size_t>(e.v1)];
        // Shown when a face beside it faces the camera (the fixed parts hiding each other is ignored:
        // a hidden edge then only makes a few samples uninformative).
        auto facing = [&](int f) {
          const geometry::Face& face = faces[static_cast<size_t>(f)];
          return face.normal.dot(eye_in_part) > face.offset;
        };
        if (!facing(e.f0) && !facing(e.f1)) continue;
        const Eigen::Vector3d pa = camera_T_part * a, pb = camera_T_part * b;
        auto project = [&](double t) -> std::optional<Eigen::Vector2d> {
          auto q = camera.ProjectFromCamera(pa + (pb - pa) * t);
          if (q && (q->x() < -kMarginPx || q->y() < -kMarginPx || q->x() > camera.width() + kMarginPx ||
                    q->y() > camera.height() + kMarginPx)) {
            q.reset();
          }
          return q;
        };
        // The part of the edge in view, from a coarse pass (an edge that passes near the camera plane,
        // the table's, projects to thousands of pixels, mostly outside), then steps of about kStepPx.
        constexpr int kCoarse = 64;
        int first = kCoarse + 1, last = -1;
        double length_px = 0;
        std::optional<Eigen::Vector2d> before;
        for (int i = 0; i <= kCoarse; ++i) {
          const auto q = project(static_cast<double>(i) / kCoarse);
          if (!q) continue;
          first = std::min(first, i), last = std::max(last, i);
          if (before) length_px += (*q - *before).norm();
          before = q;
        }
        if (last < 0) continue;
        const double t0 = std::max(0, first - 1) / static_cast<double>(kCoarse);
        const double t1 = std::min(kCoarse, last + 1) / static_cast<double>(kCoarse);
        const int n = std::clamp(static_cast<int>(length_px / kStepPx) + 1, 1, kMaxSteps);
        std::optional<Eigen::Vector2d> prev;
        for (int i = 0; i <= n; ++i) {
          const auto q = project(t0 + (t1 - t0) * (static_cast<double>(i) / n));
          if (q && prev && (*q - *prev).norm() > 1e-6) {
            double angle = std::atan2((*q - *prev).y(), (*q - *prev).x());
            if (angle < 0) angle += M_PI;
            if (angle >= M_PI) angle -= M_PI;
            const int piece = entry(static_cast<float>(angle));  // makes or widens out.piece first
            cv::line(out.piece, cv::Point2d(prev->x(), prev->y()), cv::Point2d(q->x(), q->y()),
                     cv::Scalar(piece), static_cast<int>(2 * kHalfWidthPx + 1), cv::LINE_8);
          }
          prev = q;
        }
      }
    }
  }
  return out;
}

bool OnFixedEdge(const FixedEdgeMap& fixed, const Eigen::Vector2d& pixel, const Eigen::Vector2d& normal) {
  const int x = static_cast<int>(std::lround(pixel.x())), y = static_cast<int>(std::lround(pixel.y()));
  if (fixed.piece.empty() || x < 0 || y < 0 || x >= fixed.piece.cols || y >= fixed.piece.rows) return false;
  const int piece =
      fixed.piece.depth() == CV_16U ? fixed.piece.at<uint16_t>(y, x) : fixed.piece.at<int32_t>(y, x);
  if (piece == 0) return false;
  const auto [cos_a, sin_a] = fixed.direction[static_cast<size_t>(piece - 1)];
  // The fixed edge's direction against the predicted edge's (the normal turned by 90 deg).
  return std::abs(cos_a * normal.y() - sin_a * normal.x()) >= std::cos(15 * M_PI / 180);
}

int OwnOutlineBalance(const Model& model, const geometry::Pose3& camera_T_object,
                      const std::vector<std::pair<const Model*, geometry::Pose3>>& others,
                      const Camera& camera, const EdgeMap& edge_map, const FixedEdgeMap& fixed,
                      const RecognizerOptions& options) {
  constexpr double kSharedPx = 3, kSharedCos = 0.966;  // 15 deg
  struct Segment {
    Eigen::Vector2d p, dir;
    double length;
  };
  std::vector<Segment> b_edges;
  for (const auto& [b_model, camera_T_b] : others) {
    const uint16_t visible = VisibleBoxEdges(b_model->box_size_m, camera_T_b.Inverse().translation);
    for (int e = 0; e < 12; ++e) {
      if (!(visible >> e & 1)) continue;
      const auto p = camera.ProjectFromCamera(camera_T_b * BoxVertex(b_model->box_size_m, kBoxEdges[e][0]));
      const auto q = camera.ProjectFromCamera(camera_T_b * BoxVertex(b_model->box_size_m, kBoxEdges[e][1]));
      if (!p || !q || (*q - *p).norm() < 1e-6) continue;
      b_edges.push_back({*p, (*q - *p).normalized(), (*q - *p).norm()});
    }
  }
  int balance = 0;
  ForEachOutlineSample(
      model.box_size_m, camera_T_object, camera,
      [&](const Eigen::Vector3d&, const Eigen::Vector2d& c, const Eigen::Vector2d& normal, int) {
        for (const Segment& s : b_edges) {
          const Eigen::Vector2d d = c - s.p;
          const double t = d.dot(s.dir);
          if (t < -kSharedPx || t > s.length + kSharedPx) continue;
          if (std::abs(s.dir.x() * d.y() - s.dir.y() * d.x()) <= kSharedPx &&
              std::abs(s.dir.dot(normal)) <= std::sqrt(1 - kSharedCos * kSharedCos)) {
            return;
          }
        }
        if (OnFixedEdge(fixed, c, normal)) return;
        if (EdgePixelAcross(edge_map, c, normal, 2) &&
            GreyStepAcross(edge_map, c, normal, options.step_offset_px) >= options.min_step_grey) {
          ++balance;
        } else if (GreyStepAcross(edge_map, c, normal, kContrastOffsetPx) >= options.min_edge_contrast) {
          --balance;
        }
      });
  return balance;
}

namespace {

// The recognitions dropped one at a time, the worst first, each judged against the others still
// kept: `badness(recognition, others)`, or nothing where it is fine. Positions in the order dropped;
// on a tie the first.
template <typename Badness>
std::vector<size_t> DroppedWorstFirst(
    const std::vector<std::pair<const Model*, geometry::Pose3>>& recognitions, Badness badness) {
  std::vector<size_t> dropped;
  std::vector<size_t> kept(recognitions.size());
  for (size_t k = 0; k < kept.size(); ++k) kept[k] = k;
  std::vector<std::pair<const Model*, geometry::Pose3>> others;
  while (!kept.empty()) {
    std::optional<double> worst;
    size_t worst_at = 0;
    for (size_t k = 0; k < kept.size(); ++k) {
      others.clear();
      for (size_t j : kept) {
        if (j != kept[k]) others.push_back(recognitions[j]);
      }
      const std::optional<double> bad = badness(recognitions[kept[k]], others);
      if (bad && (!worst || *bad > *worst)) worst = bad, worst_at = k;
    }
    if (!worst) break;
    dropped.push_back(kept[worst_at]);
    kept.erase(kept.begin() + static_cast<std::ptrdiff_t>(worst_at));
  }
  return dropped;
}

}  // namespace

std::vector<size_t> ExplainedAway(const std::vector<std::pair<const Model*, geometry::Pose3>>& recognitions,
                                  const Camera& camera, const EdgeMap& edge_map, const FixedEdgeMap& fixed,
                                  const RecognizerOptions& options) {
  if (options.min_own_balance <= 0) return {};
  return DroppedWorstFirst(
      recognitions, [&](const auto& recognition, const auto& others) -> std::optional<double> {
        const auto& [model, camera_T_object] = recognition;
        const int balance =
            OwnOutlineBalance(*model, camera_T_object, others, camera, edge_map, fixed, options);
        if (balance >= options.min_own_balance) return std::nullopt;
        return -balance;  // the weakest first
      });
}

// At least this many points (2 px apart) of bare table make a claim bare: a sliver along another
// recognition's image is not one.
constexpr int kMinBarePoints = 10;

int TableGrey(const EdgeMap& edge_map) {
  const cv::Mat& grey = edge_map.smoothed;
  std::array<int, 256> histogram{};
  int total = 0;
  for (int y = 0; y < grey.rows; y += 2) {
    const uint8_t* row = grey.ptr<uint8_t>(y);
    for (int x = 0; x < grey.cols; x += 2) ++histogram[row[x]], ++total;
  }
  for (int v = 0, below = 0; v < 256; ++v) {
    below += histogram[static_cast<size_t>(v)];
    if (2 * below >= total) return v;
  }
  return 0;
}

namespace {

// A box's image as the pin-hole camera sees it: the convex hull of its corners' projections
// (BoxImage's, every other corner to the left of each side), each side's unit inward normal (worked
// out once: the samplers ask every side of several hulls at every point), and its bounding box.
struct BoxImageHull {
  std::vector<Eigen::Vector2d> corners, inward;  // inward[i]: the side from corners[i] to the next
  Eigen::Vector2d lo, hi;
  // How far `q` lies inside (> 0) or outside (< 0): exact inside; outside, at most the distance.
  double Depth(const Eigen::Vector2d& q) const {
    double depth = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < corners.size(); ++i) depth = std::min(depth, inward[i].dot(q - corners[i]));
    return depth;
  }
  // Whether `q` lies at least margin_px inside.
  bool HoldsDeep(const Eigen::Vector2d& q, double margin_px) const {
    if ((q.array() < lo.array() + margin_px).any() || (q.array() > hi.array() - margin_px).any())
      return false;
    return Depth(q) >= margin_px;
  }
  // Whether `q` lies less than margin_px outside (or inside).
  bool Reaches(const Eigen::Vector2d& q, double margin_px) const {
    if ((q.array() < lo.array() - margin_px).any() || (q.array() > hi.array() + margin_px).any())
      return false;
    return Depth(q) > -margin_px;
  }
};
std::optional<BoxImageHull> ImageHullOf(const Model& model, const geometry::Pose3& camera_T_object,
                                        const Eigen::Matrix3d& K) {
  std::array<Eigen::Vector2d, 8> px;
  for (int v = 0; v < 8; ++v) {
    const Eigen::Vector3d p = camera_T_object * BoxVertex(model.box_size_m, v);
    if (!(p.z() > 1e-3)) return std::nullopt;
    px[static_cast<size_t>(v)] = (K * p).hnormalized();
  }
  const BoxImage image(px, 0);  // its hull: every other corner to the left of each side (Cross2 >= 0)
  if (image.hull_size < 3) return std::nullopt;
  BoxImageHull out;
  for (int i = 0; i < image.hull_size; ++i) out.corners.push_back(px[static_cast<size_t>(image.hull[i])]);
  for (size_t i = 0; i < out.corners.size(); ++i) {
    const Eigen::Vector2d e = out.corners[(i + 1) % out.corners.size()] - out.corners[i];
    if (!(e.norm() > 1e-9)) return std::nullopt;
    out.inward.push_back(Eigen::Vector2d(-e.y(), e.x()) / e.norm());  // Cross2(e, d) / |e| = inward . d
  }
  out.lo = out.hi = out.corners.front();
  for (const Eigen::Vector2d& q : out.corners) out.lo = out.lo.cwiseMin(q), out.hi = out.hi.cwiseMax(q);
  return out;
}

}  // namespace

ClaimedAlone BareTableBeyond(const Model& model, const geometry::Pose3& camera_T_object,
                             const std::vector<std::pair<const Model*, geometry::Pose3>>& others,
                             const Camera& camera, const EdgeMap& edge_map, int table_grey) {
  constexpr double kStepPx = 2, kMarginPx = 4;
  constexpr int kGreyTolerance = 15;
  ClaimedAlone out;
  const Eigen::Matrix3d K = camera.K();
  const std::optional<BoxImageHull> own = ImageHullOf(model, camera_T_object, K);
  if (!own) return out;
  std::vector<BoxImageHull> elsewhere;
  for (const auto& [m, pose] : others) {
    std::optional<BoxImageHull> hull = ImageHullOf(*m, pose, K);
    if (!hull) return out;  // one reaches behind the camera: what the pose claims alone is not known
    elsewhere.push_back(std::move(*hull));
  }
  const cv::Mat& grey = edge_map.smoothed;
  for (double y = own->lo.y() + kMarginPx; y <= own->hi.y() - kMarginPx; y += kStepPx) {
    for (double x = own->lo.x() + kMarginPx; x <= own->hi.x() - kMarginPx; x += kStepPx) {
      const Eigen::Vector2d q(x, y);
      if (!own->HoldsDeep(q, kMarginPx)) continue;
      bool claimed = false;
      for (const BoxImageHull& o : elsewhere) claimed = claimed || o.Reaches(q, kMarginPx);
      if (claimed) continue;
      const Eigen::Vector2d at = camera.DistortPixel(q);
      const int px = NearestPixel(at.x(), grey.cols), py = NearestPixel(at.y(), grey.rows);
      if (px < 0 || py < 0) continue;
      ++out.samples;
      // No edge pixel near (NoEdgeNear at the pixel already found; without EdgeMap::near, none is bare).
      if (edge_map.near.data != nullptr && !NearEdge(edge_map, px, py) &&
          std::abs(grey.ptr<uint8_t>(py)[px] - table_grey) <= kGreyTolerance) {
        ++out.bare;
      }
    }
  }
  return out;
}

std::vector<size_t> StandingOnBareTable(
    const std::vector<std::pair<const Model*, geometry::Pose3>>& recognitions, const Camera& camera,
    const EdgeMap& edge_map, int table_grey, double share) {
  if (share <= 0) return {};
  return DroppedWorstFirst(
      recognitions, [&](const auto& recognition, const auto& others) -> std::optional<double> {
        const auto& [model, camera_T_object] = recognition;
        const ClaimedAlone alone =
            BareTableBeyond(*model, camera_T_object, others, camera, edge_map, table_grey);
        if (alone.bare < kMinBarePoints) return std::nullopt;
        const double bare_share = static_cast<double>(alone.bare) / alone.samples;
        if (bare_share < share) return std::nullopt;
        return bare_share;  // the barest first
      });
}

namespace {

// The pairwise decision on the two outlines alone (ReplacesRival before the bare table is weighed).
bool ReplacesOnOutline(const PairwiseSide& candidate, const PairwiseSide& rival,
                       const RecognizerOptions& options) {
  const int margin = options.conflict_balance_margin;
  if (margin <= 0) return false;
  if (candidate.own >= margin) {
    if (rival.own <= kRivalMaxOwnBalance) return true;
    if (options.conflict_rms_ratio > 0 && candidate.model != rival.model &&
        candidate.rms_px <= options.conflict_rms_ratio * rival.rms_px &&
        candidate.score >= rival.score + options.conflict_score_lead) {
      return true;
    }
    const double share = candidate.holds_other && options.conflict_within_rank_share > 0
                             ? std::min(options.conflict_rank_share, options.conflict_within_rank_share)
                             : options.conflict_rank_share;
    return options.conflict_own_lead > 0 && candidate.own - rival.own >= options.conflict_own_lead &&
           candidate.rank >= share * rival.rank;
  }
  // Neither own outline shows: the one more inside the image, at a close rank.
  return options.conflict_in_image_lead > 0 && std::abs(candidate.own) < margin &&
         std::abs(rival.own) < margin &&
         candidate.in_image >= rival.in_image + options.conflict_in_image_lead &&
         candidate.rank >= options.conflict_tie_rank_share * rival.rank;
}

}  // namespace

bool ReplacesRival(const PairwiseSide& candidate, const PairwiseSide& rival,
                   const RecognizerOptions& options) {
  const bool on_outline = ReplacesOnOutline(candidate, rival, options);
  const double share = options.conflict_bare_table_share;
  if (share <= 0) return on_outline;
  auto bare = [&](const ClaimedAlone& a) { return a.bare >= kMinBarePoints && a.bare >= share * a.samples; };
  if (on_outline) return !bare(candidate.alone);
  return bare(rival.alone) && candidate.alone.bare <= share / 3 * candidate.alone.samples;
}

bool WithinBox(const Model& outer, const geometry::Pose3& camera_T_outer, const Model& inner,
               const geometry::Pose3& camera_T_inner) {
  constexpr double kWithinMarginM = 0.005;
  const geometry::Pose3 outer_T_inner = camera_T_outer.Inverse() * camera_T_inner;
  const Eigen::Vector3d half = 0.5 * outer.box_size_m + Eigen::Vector3d::Constant(kWithinMarginM);
  for (int v = 0; v < 8; ++v) {
    const Eigen::Vector3d p = outer_T_inner * BoxVertex(inner.box_size_m, v);
    if ((p.cwiseAbs().array() > half.array()).any()) return false;
  }
  return true;
}

PoseEvidence EvaluatePose(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                          const LineDetection& detection, const RecognizerOptions& options,
                          const FixedEdgeMap* fixed) {
  const EdgeMatchSet set = MatchEdges(model, camera.K(), camera_T_object, detection.lines, options.match_distance_px,
                                      options.match_angle_deg * M_PI / 180);
  return ComputeEvidence(model, camera, camera_T_object, detection, fixed, options, set);
}

PoseEvidence EvaluateOutline(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                             const LineDetection& detection, const RecognizerOptions& options) {
  return ComputeEvidence(model, camera, camera_T_object, detection, nullptr, options, EdgeMatchSet{});
}

double EvidenceScore(const PoseEvidence& e) {
  // tools/fit_evidence_weights.py on the benchmark's renders, seeds 7 and 8 (4863 fitted hypotheses,
  // 386 of them true; true ones weighted 5x, L2 penalty 1). The residuals are capped at 4 px: beyond
  // that a pose is as wrong as it gets, and a stray far line should not outweigh the rest.
  constexpr double kIntercept = -2.2347;
  const double edges_supported_fraction = e.edges_supported / std::max(e.edges_visible, 1.0);
  const double z = kIntercept + 6.8563 * e.matched_fraction - 4.0041 * e.support_fraction +
                   2.9860 * e.coverage - 0.9108 * std::min(e.rms_px, 4.0) -
                   1.2449 * std::min(e.rms_closest_px, 4.0) - 0.8988 * e.continued_ends +
                   0.5762 * e.long_continued_ends - 3.7774 * e.fixed_share -
                   3.7323 * e.free_support_fraction + 5.8348 * e.free_coverage + 1.1887 * e.polarity -
                   0.4480 * edges_supported_fraction - 0.4147 * e.edges_visible + 1.2771 * e.edges_supported;
  return 1 / (1 + std::exp(-z));
}

geometry::Aabb ExtentOf(const std::vector<Eigen::Vector3d>& points) {
  TEACHSIM_CHECK(!points.empty());
  geometry::Aabb e;
  for (const Eigen::Vector3d& p : points) e.Extend(p);
  return e;
}

bool RestsOn(const geometry::Aabb& object, const geometry::Aabb& below, double z_tolerance_m) {
  const bool overlap_xy = object.min.x() < below.max.x() && object.max.x() > below.min.x() &&
                          object.min.y() < below.max.y() && object.max.y() > below.min.y();
  return overlap_xy && std::abs(object.min.z() - below.max.z()) <= z_tolerance_m;
}

bool StandsOnSupports(const geometry::Aabb& object, const std::vector<geometry::Aabb>& supports,
                      double z_tolerance_m, double centre_slack_m) {
  Eigen::Vector2d contact_min = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d contact_max = -contact_min;
  bool rests = false;
  for (const geometry::Aabb& below : supports) {
    if (!RestsOn(object, below, z_tolerance_m)) continue;
    rests = true;
    contact_min = contact_min.cwiseMin(object.min.head<2>().cwiseMax(below.min.head<2>()));
    contact_max = contact_max.cwiseMax(object.max.head<2>().cwiseMin(below.max.head<2>()));
  }
  if (!rests) return false;
  const Eigen::Vector2d centre = object.Center().head<2>();
  return (centre.array() >= contact_min.array() - centre_slack_m).all() &&
         (centre.array() <= contact_max.array() + centre_slack_m).all();
}

double VisibleOutlineInImage(const Model& model, const Camera& camera,
                             const geometry::Pose3& camera_T_object) {
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_object.Inverse().translation);
  const Eigen::Matrix3d K = camera.K();
  int inside = 0, total = 0;
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector3d a =
        camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[static_cast<size_t>(e)][0]);
    const Eigen::Vector3d b =
        camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[static_cast<size_t>(e)][1]);
    if (a.z() <= 0.05 || b.z() <= 0.05) return 0;
    const int n = std::max(1, static_cast<int>(((K * a).hnormalized() - (K * b).hnormalized()).norm() / 2));
    // Outside the camera's view a point is not in the image, wherever the lens model would put it.
    const auto in_view = camera.SegmentInView(a, b);
    for (int i = 0; i < n; ++i) {
      const double t = (i + 0.5) / n;
      if (!in_view || t < in_view->first || t > in_view->second) {
        ++total;
        continue;
      }
      const auto px = camera.ProjectFromCamera(a + t * (b - a));
      inside += px && camera.InImage(*px) ? 1 : 0;
      ++total;
    }
  }
  return total > 0 ? static_cast<double>(inside) / total : 0;
}

void MatchedWithinImage(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                        EdgeMatchSet& matched, double min_inside) {
  if (matched.visible_length_px <= 0) return;
  bool all_inside = true;  // every corner 2 px or more inside: the whole outline is in the image
  for (int i = 0; i < 8 && all_inside; ++i) {
    const auto px = camera.ProjectFromCamera(camera_T_object * BoxVertex(model.box_size_m, i));
    all_inside =
        px && px->x() >= 2 && px->y() >= 2 && px->x() <= camera.width() - 2 && px->y() <= camera.height() - 2;
  }
  if (all_inside) return;
  const double inside = VisibleOutlineInImage(model, camera, camera_T_object);
  if (inside <= 0 || inside >= 1 || inside < min_inside) return;
  const double covered = matched.matched_fraction * matched.visible_length_px;
  matched.visible_length_px *= inside;
  matched.matched_fraction = std::min(1.0, covered / matched.visible_length_px);
}

std::optional<PolishResult> RefitOnEdgePoints(const Model& model, const Camera& camera,
                                              const geometry::Pose3& camera_T_object, const EdgeMap& edge_map,
                                              double table_top_z, const RecognizerOptions& options) {
  // The polish moves the outline by at most 2 px: a pose far from resting on the table will not
  // come to rest there, and is not polished at all (twice the editor's tolerances).
  if (!RestsOnTable(model, camera.world_T_camera() * camera_T_object, table_top_z,
                    2 * options.table_snap_distance_m, 2 * options.table_snap_max_tilt_deg)) {
    return std::nullopt;
  }
  const PolishResult polished = PolishPose(model, camera, camera_T_object, edge_map, false);
  if (!polished.ok || polished.rms_px > options.refit_max_rms_px ||
      VisibleOutlineInImage(model, camera, polished.fit.camera_T_object) < options.refit_min_in_image ||
      !RestsOnTable(model, camera.world_T_camera() * polished.fit.camera_T_object, table_top_z,
                    options.table_snap_distance_m, options.table_snap_max_tilt_deg)) {
    return std::nullopt;
  }
  return polished;
}

const char* LossStageName(LossStage stage) {
  switch (stage) {
    case LossStage::kSegments: return "segments";
    case LossStage::kGroups: return "groups";
    case LossStage::kHypotheses: return "hypotheses";
    case LossStage::kFit: return "fit";
    case LossStage::kVerification: return "verification";
    case LossStage::kSelection: return "selection";
    case LossStage::kAccepted: return "accepted";
  }
  return "?";
}

const char* SecondLookName(RecognitionTrace::SecondLook::Verdict verdict) {
  using Verdict = RecognitionTrace::SecondLook::Verdict;
  static_assert(static_cast<int>(Verdict::kPassed) + 1 == kSecondLookVerdicts, "a verdict without its count");
  switch (verdict) {
    case Verdict::kNone:
      return "none";
    case Verdict::kOverlaps:
      return "overlaps";
    case Verdict::kImplausible:
      return "implausible";
    case Verdict::kNothingHides:
      return "nothing hides";
    case Verdict::kRules:
      return "rules";
    case Verdict::kScore:
      return "score";
    case Verdict::kVetoed:
      return "vetoed";
    case Verdict::kPassed:
      return "passed";
  }
  return "?";
}

StageLoss ClassifyLoss(const Model& model, int model_index, const Camera& camera, const geometry::Pose3& camera_T_truth,
                       const LineDetection& detection, const std::vector<Group>& groups,
                       const RecognitionTrace& trace) {
  StageLoss out;
  const Eigen::Matrix3d K = camera.K();
  constexpr double kNearPx = 3, kNearAngle = 5 * M_PI / 180;
  const EdgeMatchSet set = MatchEdges(model, K, camera_T_truth, detection.lines, kNearPx, kNearAngle);
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_truth.Inverse().translation);
  std::set<int> edges;
  for (const LineMatch& m : set.matches) edges.insert(m.edge);
  for (int e = 0; e < 12; ++e) out.visible_edges += visible >> e & 1;
  out.edges_with_lines = static_cast<int>(edges.size());
  if (out.edges_with_lines < 3) return out;
  out.stage = LossStage::kGroups;
  const std::set<int> own(set.segments.begin(), set.segments.end());
  bool grouped = false;
  for (const Group& g : groups) {
    bool all = true;
    for (int s = 0; s < GroupSegments(g.kind); ++s) all = all && own.count(g.segments[static_cast<size_t>(s)]) > 0;
    grouped = grouped || all;
  }
  out.stage = LossStage::kHypotheses;
  // Distance between two poses as the mean distance of each projected vertex to the nearest
  // projected vertex of the other (invariant to the box's symmetries), px.
  Eigen::Vector2d truth_px[8];
  double extent = 0;
  for (int i = 0; i < 8; ++i) {
    truth_px[i] = (K * (camera_T_truth * BoxVertex(model.box_size_m, i))).hnormalized();
    for (int j = 0; j < i; ++j) extent = std::max(extent, (truth_px[i] - truth_px[j]).norm());
  }
  auto distance = [&](const geometry::Pose3& pose) {
    double sum = 0;
    Eigen::Vector2d px[8];
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d p = pose * BoxVertex(model.box_size_m, i);
      if (p.z() <= 1e-3) return 1e9;
      px[i] = (K * p).hnormalized();
    }
    for (int i = 0; i < 8; ++i) {
      double best = 1e9;
      for (int j = 0; j < 8; ++j) best = std::min(best, (truth_px[i] - px[j]).norm());
      sum += best;
    }
    return sum / 8;
  };
  out.extent_px = extent;
  const double start_px = std::max(8.0, 0.25 * extent);
  constexpr double kConvergedPx = 3;
  bool started = false, converged = false, candidate = false;
  for (const RecognitionTrace::Fitted& f : trace.fitted) {
    if (f.model != model_index) continue;
    const double end_px = distance(f.camera_T_object);
    out.best_end_px = std::min(out.best_end_px, end_px);
    const double start = distance(f.initial_camera_T_object);
    if (start < out.best_start_px) {
      out.best_start_px = start;
      out.best_start_rounds_px.clear();
      for (const geometry::Pose3& r : f.rounds) out.best_start_rounds_px.push_back(distance(r));
    }
    const bool near_end = end_px < kConvergedPx;
    if (near_end && f.accepted) {
      out.stage = LossStage::kAccepted;
      return out;
    }
    started = started || distance(f.initial_camera_T_object) < start_px;
    if (near_end) {
      converged = true;
      if (f.outcome == RecognitionTrace::Outcome::kCandidate) {
        candidate = true;
      } else if (!candidate) {
        out.verification = std::max(out.verification, f.outcome);
        if (f.second_look.NearerThan(out.second_look)) out.second_look = f.second_look;
      }
    }
  }
  if (candidate) out.stage = LossStage::kSelection;
  else if (converged) out.stage = LossStage::kVerification;
  else if (started) out.stage = LossStage::kFit;
  // No group of its own edges, and no hypothesis (of the index or of a support plane's corner)
  // started near it: lost for want of a group.
  else if (!grouped) out.stage = LossStage::kGroups;
  return out;
}

namespace {

// The planes a block can rest on: the table and the fixed objects' flat tops above it.
std::vector<SupportPlane> SupportPlanes(const FixedWorld& fixed, const RecognizerOptions& options) {
  SupportPlane table;
  table.z_m = fixed.table_top_z;
  table.min_xy = Eigen::Vector2d::Constant(-options.work_area_radius_m);
  table.max_xy = Eigen::Vector2d::Constant(options.work_area_radius_m);
  std::vector<SupportPlane> planes = {table};
  for (const FixedPart& part : fixed.parts) {
    // A horizontal top face.
    bool flat_top = false;
    for (const Eigen::Vector3d& n : part.normals) flat_top = flat_top || n.z() > std::cos(1e-3);
    if (!flat_top || part.vertices.empty()) continue;
    SupportPlane top;
    top.z_m = -1e9;
    top.min_xy = Eigen::Vector2d::Constant(1e9);
    top.max_xy = Eigen::Vector2d::Constant(-1e9);
    for (const Eigen::Vector3d& v : part.vertices) {
      top.z_m = std::max(top.z_m, v.z());
      top.min_xy = top.min_xy.cwiseMin(v.head<2>());
      top.max_xy = top.max_xy.cwiseMax(v.head<2>());
    }
    if (top.z_m > fixed.table_top_z + 1e-3) planes.push_back(top);
  }
  return planes;
}

// The rules after the matched share: the RMS of all matched segments against the final pose, or,
// when only the segments closest to each predicted edge are within the limit (a shadow or grain
// line runs beside an edge), stronger evidence: support along most of the predicted outline and no image
// edges running on past its corners (a wrong, smaller model fitted onto part of a real block);
// edge support; not part of a larger straight-edged thing (a cube fitted onto a bar, an upright
// block onto the dark cylinder: image edges run on past two or more of its corners for most of
// the edge's length while little of its own outline is supported). Then the step rule and the
// evidence score (below). The verdict: kCandidate or why not.
RecognitionTrace::Outcome Judge(const PoseEvidence& e, const RecognizerOptions& options, double* rms_px) {
  using Outcome = RecognitionTrace::Outcome;
  const bool trimmed_rms = e.rms_px > options.max_reprojection_rms_px;
  *rms_px = trimmed_rms ? std::min(e.rms_px, e.rms_closest_px) : e.rms_px;
  Outcome rule = Outcome::kCandidate;
  if (*rms_px > options.max_reprojection_rms_px) {
    rule = Outcome::kReprojection;
  } else if (e.support_fraction < options.min_score || e.coverage < options.min_coverage ||
             (trimmed_rms &&
              (e.matched_fraction < kTrimmedMinMatchedFraction || e.coverage < kTrimmedMinCoverage ||
               e.continued_ends > kTrimmedMaxContinuedEnds)) ||
             (e.long_continued_ends >= kPartMinContinuedEnds && e.coverage < kPartMaxCoverage)) {
    rule = Outcome::kSupport;
  }
  // Outline along thin lines: where most of the supported outline is a thin line (wood grain
  // inside a face, a scratch) and not a step in grey level between two surfaces, the pose is a
  // wrong model laid onto a block's texture, whatever the rest of its evidence.
  if (!StepRule(e, options)) return Outcome::kSupport;
  // The evidence score over all of it (EvidenceScore): required of a pose that passes the rules,
  // and enough on its own when it is high.
  const double score = EvidenceScore(e);
  if (rule == Outcome::kCandidate) return score < options.min_evidence_score ? Outcome::kEvidence : rule;
  return score < options.accept_evidence_score ? rule : Outcome::kCandidate;
}

using Outcome = RecognitionTrace::Outcome;

// Poses verification turned down for want of evidence, judged again after the selection where
// accepted recognitions hide part of them (RecognizerOptions::occlusion_reverify).
struct Rejected {
  int model = 0;
  FitResult fit;
  int trace_index = -1;
};

// Steps 4-5b of one image's recognition: the hypotheses' fits and their verification, the selection
// and the occlusion pass. They share what has been fitted (no initial pose twice), the image lines
// the candidates claim, the candidates and the poses verification turned down.
class RecognitionPass {
 public:
  RecognitionPass(const ModelLibrary& models, const RecognizerOptions& options, const Camera& camera,
                  const LineDetection& detection, const FixedWorld& fixed, const FixedEdgeMap& fixed_edges,
                  RecognitionTrace* trace)
      : models_(models),
        options_(options),
        camera_(camera),
        K_(camera.K()),
        detection_(detection),
        lines_(detection.lines),
        fixed_(fixed),
        fixed_edges_(fixed_edges),
        trace_(trace),
        claims_(detection.lines.size()),
        match_angle_(options.match_angle_deg * M_PI / 180) {
    for (const FixedPart& part : fixed.parts) fixed_extents_.push_back(ExtentOf(part.vertices));
  }

  // 4. Support-plane hypotheses (ranked by edge support): fitted on their plane first (x, y, yaw),
  // where a predicted edge that picks up a shadow or grain line cannot tilt the block; then,
  // optionally, in 6 DOF, kept when it matches more of the outline without a larger residual.
  void FitSupportHypotheses(const std::vector<ImageCorner>& corners,
                            const std::vector<SupportHypothesis>& hypotheses);
  // 4. The index's most probable hypotheses, at most max_hypotheses fitted.
  void FitIndexHypotheses(const RecognizerIndex& index, const std::vector<Group>& groups,
                          const std::vector<Hypothesis>& hypotheses);
  // 4. Other models at each candidate's place (the candidates of the passes above only): where the
  // block's own model was lost at its hypotheses or fit, a wrong model fitted onto it would otherwise
  // stand unopposed in the selection.
  void FitAlternatives();
  // 5. consistency and non-maximum suppression: the best explained outline first, weighed by the
  // evidence score (where a slab and a bar compete for one block, the longer outline alone favoured
  // the slab: seeds 7-15 of the benchmark's renders 1559 -> 1562 found, 38 -> 34 false); a candidate
  // that deeply interpenetrates an accepted one or claims the same image edges is the same object or
  // a wrong one. Returns the accepted candidates' indices.
  // contours: the occluding contours (a shorter rival ending at one inside a longer candidate's image;
  // conflict_within_rank_share), or none.
  std::vector<size_t> Select(const std::vector<ImageLine>* contours);
  // Whether `inner`'s pose ends at an occluding contour inside `outer`'s image (EndsAtContourInside);
  // false where either lies partly behind the camera.
  bool EndsAtContour(const Model& inner, const geometry::Pose3& camera_T_inner, const Model& outer,
                     const geometry::Pose3& camera_T_outer, const std::vector<ImageLine>& contours) const;
  // 5b. Blocks partly hidden by recognized ones (RecognizerOptions::occlusion_reverify): each pose
  // verification turned down is judged again without the outline the accepted recognitions hide and
  // without the image lines they claim (their edges end where a hidden block's do not). Those that
  // pass, best ranked first, join the accepted ones unless they conflict with one. Then, as much, the
  // outline that occluding contours hide (RecognizerOptions::occlusion_contours): `contours`, or
  // found here when null.
  void ReverifyOccluded(std::vector<size_t>* accepted_io, const std::vector<ImageLine>* contours);

  // RecognizerOptions::max_bare_table_share: drops the accepted recognitions that stand on bare
  // table, one at a time, the barest first, each judged against the others still accepted.
  std::vector<size_t> WithoutBareClaims(std::vector<size_t> accepted);

  const std::vector<Candidate>& candidates() const { return candidates_; }

 private:
  int table_grey_ = -1;  // TableGrey, worked out when first needed (TableGreyOnce)
  int TableGreyOnce();
  // The accepted candidates' models and poses, in order.
  std::vector<std::pair<const Model*, geometry::Pose3>> ModelsAndPoses(
      const std::vector<size_t>& accepted) const;
  // `accepted` without the positions `dropped`, and without what rested on them (SupportedSubset).
  std::vector<size_t> KeptWithout(const std::vector<size_t>& accepted,
                                  const std::vector<size_t>& dropped) const;
  // Whether an initial pose like this one (1 cm, 8 degrees up to the model's symmetry) was fitted;
  // remembers it.
  bool AlreadyTried(int model_index, const geometry::Pose3& initial);
  // The trace's entry for a fit from `initial` (none when no trace was asked for).
  RecognitionTrace::Fitted* StartTrace(int model_index, int kind, const geometry::Pose3& initial);
  // The matched share's rule on what the image can show (RecognizerOptions::matched_share_in_image);
  // the evidence keeps the share of the whole visible edges, the feature its score was fitted on.
  bool EnoughMatched(const Model& model, const EdgeMatchSet& matched,
                     const geometry::Pose3& camera_T_object) const;
  // Culling (§7.1): outside the work site, under the table, inside a fixed object.
  bool Implausible(const Model& model, const geometry::Pose3& camera_T_object) const;
  // How a fitted pose is judged: on its whole outline, or only as partly hidden (a placement scored
  // behind an occluding contour: a block in full view has its own hypotheses).
  enum class Judged { kWhole, kOnlyHidden };
  // Verification and culling of a fitted pose: a candidate when it passes; turned down for want of
  // evidence (at once when judged only hidden), kept for ReverifyOccluded.
  void Verify(int model_index, FitResult fit, RecognitionTrace::Fitted* traced, Judged judged);
  // A hypothesis' fit: its rounds and final pose into its trace entry; verified unless it failed.
  void VerifyFitted(int model_index, const HypothesisFit& fitted, RecognitionTrace::Fitted* traced,
                    Judged judged);
  // A hypothesis of a block resting on a plane (support-plane or alternative; `kind` for the trace):
  // fitted on the plane (FitSupportHypothesis), then verified.
  void FitOnSupport(int model_index, int kind, const geometry::Pose3& initial, Judged judged);
  // Culling what floats (§7.1: poses that cannot be real): each recognition rests on the table, or
  // stands on fixed objects' tops or other recognitions' tops (StandsOnSupports: its centre over where
  // it touches them; checked until nothing changes). Applied to all candidates before the non-maximum
  // suppression too, so that a floating wrong candidate cannot suppress the right one and then be
  // culled itself. Returns the members of `set` (candidate indices) that are supported.
  std::vector<size_t> SupportedSubset(const std::vector<size_t>& set) const;
  // Drops, weakest first, the accepted recognitions that the others explain away
  // (RecognizerOptions::min_own_balance).
  std::vector<size_t> WithoutExplainedAway(std::vector<size_t> accepted) const;
  // Two poses that interpenetrate this deeply are the same object or one of them is wrong.
  bool Interpenetrate(int model_c, const geometry::Pose3& camera_T_c, const Candidate& a) const;
  // A candidate conflicts with an accepted one when they interpenetrate, share a third of its
  // matched lines, or it hides outline of the accepted one where the image shows a step
  // (HiddenSupportedSamples).
  bool Conflicting(const Candidate& c, const Candidate& a) const;

  const ModelLibrary& models_;
  const RecognizerOptions& options_;
  const Camera& camera_;
  const Eigen::Matrix3d K_;
  const LineDetection& detection_;
  const std::vector<ImageLine>& lines_;
  const FixedWorld& fixed_;
  const FixedEdgeMap& fixed_edges_;
  RecognitionTrace* trace_;
  std::vector<geometry::Aabb> fixed_extents_;  // of each fixed part
  SegmentClaims claims_;
  const double match_angle_;                            // rad
  std::vector<std::pair<int, geometry::Pose3>> tried_;  // initial poses already fitted
  std::vector<Candidate> candidates_;
  std::vector<double> rank_;  // of each candidate in the selection
  std::vector<Rejected> rejected_;
};

bool RecognitionPass::AlreadyTried(int model_index, const geometry::Pose3& initial) {
  const Model& model = models_.models[static_cast<size_t>(model_index)];
  for (const auto& [m, pose] : tried_) {
    if (m == model_index && (pose.translation - initial.translation).norm() < 0.01 &&
        SymmetricRotationAngle(model, pose, initial) < 8 * M_PI / 180) {
      return true;
    }
  }
  tried_.push_back({model_index, initial});
  return false;
}

RecognitionTrace::Fitted* RecognitionPass::StartTrace(int model_index, int kind,
                                                      const geometry::Pose3& initial) {
  if (trace_ == nullptr) return nullptr;
  trace_->fitted.push_back({model_index, kind, initial, initial, {}, Outcome::kFitFailed, false});
  return &trace_->fitted.back();
}

bool RecognitionPass::EnoughMatched(const Model& model, const EdgeMatchSet& matched,
                                    const geometry::Pose3& camera_T_object) const {
  EdgeMatchSet in_image;  // the two figures the rule needs, not the matches themselves
  in_image.matched_fraction = matched.matched_fraction;
  in_image.visible_length_px = matched.visible_length_px;
  if (options_.matched_share_in_image) {
    MatchedWithinImage(model, camera_, camera_T_object, in_image, options_.matched_share_min_in_image);
  }
  return in_image.matched_fraction >= options_.min_matched_edge_fraction;
}

bool RecognitionPass::Implausible(const Model& model, const geometry::Pose3& camera_T_object) const {
  const geometry::Pose3 world_T_object = camera_.world_T_camera() * camera_T_object;
  if (world_T_object.translation.head<2>().norm() > options_.work_area_radius_m) return true;
  if (LowestZ(model, world_T_object) < fixed_.table_top_z - options_.below_table_tolerance_m) return true;
  for (const FixedPart& part : fixed_.parts) {
    if (PartPenetration(model, world_T_object, part, false).depth_m >
        std::max(0.005, 0.2 * model.box_size_m.minCoeff())) {
      return true;
    }
  }
  return false;
}

void RecognitionPass::Verify(int model_index, FitResult fit, RecognitionTrace::Fitted* traced,
                             Judged judged) {
  const Model& model = models_.models[static_cast<size_t>(model_index)];
  auto reject = [&](Outcome outcome) {
    if (traced != nullptr) traced->outcome = outcome;
    if (options_.occlusion_reverify && outcome != Outcome::kImplausible && outcome != Outcome::kCandidate) {
      rejected_.push_back(
          {model_index, fit, traced != nullptr ? static_cast<int>(trace_->fitted.size()) - 1 : -1});
    }
  };
  if (judged == Judged::kOnlyHidden) return reject(Outcome::kSupport);
  EdgeMatchSet set =
      MatchEdges(model, K_, fit.camera_T_object, lines_, options_.match_distance_px, match_angle_);
  // Short of the matched share, a pose is judged on its evidence only with the rescue on
  // (RecognizerOptions::matched_share_rescue_score); whatever turns it down, it stays a
  // matched-share rejection.
  const bool enough_matched = EnoughMatched(model, set, fit.camera_T_object);
  if (!enough_matched && !options_.matched_share_rescue) return reject(Outcome::kMatchedFraction);
  if (Implausible(model, fit.camera_T_object)) {
    return reject(enough_matched ? Outcome::kImplausible : Outcome::kMatchedFraction);
  }
  PoseEvidence evidence =
      ComputeEvidence(model, camera_, fit.camera_T_object, detection_, &fixed_edges_, options_, set);
  Outcome outcome = Judge(evidence, options_, &fit.rms_px);
  if (!enough_matched &&
      (outcome != Outcome::kCandidate || EvidenceScore(evidence) < options_.matched_share_rescue_score)) {
    return reject(Outcome::kMatchedFraction);
  }
  double rank_score = -1;  // set by the refit
  // A second chance, the edge-point refit (RecognizerOptions::edge_point_refit), for a pose whose
  // matched lines are off its predicted edges: often a grain line or a shadow beside an edge was
  // matched with it. The image's own edge points along the outline have no such neighbours. A pose
  // that fits them closely while resting on the table is judged again on them, its RMS theirs, and
  // accepted only with a strong evidence score. Refitted only when it could reach that score at all
  // (its score with no residual) and its outline is supported well enough otherwise. The step rule
  // is judged on the refitted pose only: on the line fit's pose, a pixel or two off the edges, its
  // samples can straddle the step (render seeds 7-31: 4 more blocks found, no more false).
  if (outcome != Outcome::kCandidate && options_.edge_point_refit &&
      evidence.rms_px > options_.max_reprojection_rms_px &&
      evidence.coverage >= options_.refit_min_coverage && evidence.support_fraction >= options_.min_score) {
    PoseEvidence best = evidence;
    best.rms_px = best.rms_closest_px = 0;
    const std::optional<PolishResult> polished =
        EvidenceScore(best) >= options_.refit_accept_score
            ? RefitOnEdgePoints(model, camera_, fit.camera_T_object, detection_.edge_map, fixed_.table_top_z,
                                options_)
            : std::nullopt;
    if (polished && !Implausible(model, polished->fit.camera_T_object)) {
      EdgeMatchSet refit_set = MatchEdges(model, K_, polished->fit.camera_T_object, lines_,
                                          options_.match_distance_px, match_angle_);
      PoseEvidence refit_evidence = ComputeEvidence(model, camera_, polished->fit.camera_T_object, detection_,
                                                    &fixed_edges_, options_, refit_set);
      const double lines_score = EvidenceScore(refit_evidence);
      refit_evidence.rms_px = refit_evidence.rms_closest_px = polished->rms_px;
      double rms_px = 0;
      if (EnoughMatched(model, refit_set, polished->fit.camera_T_object) &&
          Judge(refit_evidence, options_, &rms_px) == Outcome::kCandidate &&
          EvidenceScore(refit_evidence) >= options_.refit_accept_score) {
        fit = polished->fit;
        fit.rms_px = rms_px;
        set = std::move(refit_set);
        evidence = refit_evidence;
        rank_score = lines_score;
        outcome = Outcome::kCandidate;
        if (traced != nullptr) traced->camera_T_object = fit.camera_T_object;
      }
    }
  }
  if (outcome != Outcome::kCandidate) return reject(outcome);
  if (traced != nullptr) traced->outcome = Outcome::kCandidate;
  Candidate c;
  c.trace_index = traced != nullptr ? static_cast<int>(trace_->fitted.size()) - 1 : -1;
  c.model = model_index;
  c.camera_T_object = fit.camera_T_object;
  c.fit = fit;
  c.matches = set;
  c.evidence = evidence;
  c.rms_px = fit.rms_px;
  c.rank_score = rank_score >= 0 ? rank_score : EvidenceScore(evidence);
  for (int seg : set.segments) claims_.Claim(seg, model_index);
  candidates_.push_back(std::move(c));
}

void RecognitionPass::VerifyFitted(int model_index, const HypothesisFit& fitted,
                                   RecognitionTrace::Fitted* traced, Judged judged) {
  if (traced != nullptr) {
    traced->rounds.insert(traced->rounds.end(), fitted.rounds.begin(), fitted.rounds.end());
    traced->camera_T_object = fitted.fit.camera_T_object;
  }
  if (!fitted.failed) Verify(model_index, fitted.fit, traced, judged);
}

void RecognitionPass::FitOnSupport(int model_index, int kind, const geometry::Pose3& initial, Judged judged) {
  RecognitionTrace::Fitted* traced = StartTrace(model_index, kind, initial);
  const Model& model = models_.models[static_cast<size_t>(model_index)];
  // Where the fit drifted off its start (a half-hidden block's hidden edges matched to lines beside
  // them), the start fitted again matching tightly, and verified too when it ends elsewhere.
  const HypothesisFit loose =
      FitSupportHypothesis(model, K_, camera_.camera_T_world(), initial, lines_, options_);
  VerifyFitted(model_index, loose, traced, judged);
  if (options_.support_tight_fit_shift_px <= 0 ||
      MeanVertexShiftPx(model, K_, initial, loose.fit.camera_T_object) <=
          options_.support_tight_fit_shift_px) {
    return;
  }
  const HypothesisFit tight =
      FitSupportHypothesis(model, K_, camera_.camera_T_world(), initial, lines_, options_, true);
  constexpr double kSamePosePx = 1.5;  // a tight fit this close to the loose one adds nothing
  if (tight.failed || (!loose.failed && MeanVertexShiftPx(model, K_, loose.fit.camera_T_object,
                                                          tight.fit.camera_T_object) <= kSamePosePx)) {
    return;
  }
  VerifyFitted(model_index, tight, StartTrace(model_index, kind, initial), judged);
}

void RecognitionPass::FitSupportHypotheses(const std::vector<ImageCorner>& corners,
                                           const std::vector<SupportHypothesis>& hypotheses) {
  const geometry::Pose3& camera_T_world = camera_.camera_T_world();
  for (const SupportHypothesis& h : hypotheses) {
    const ImageCorner& corner = corners[static_cast<size_t>(h.corner)];
    if (claims_.BothClaimed(
            corner.segments[0], corner.segments[1],
            options_.skip_corners_claimed_by_any_model ? SegmentClaims::kAnyModel : h.model)) {
      continue;
    }
    const geometry::Pose3 initial = camera_T_world * h.world_T_object;
    if (AlreadyTried(h.model, initial)) continue;
    FitOnSupport(h.model, kSupportKind, initial, h.behind_contour ? Judged::kOnlyHidden : Judged::kWhole);
  }
}

void RecognitionPass::FitIndexHypotheses(const RecognizerIndex& index, const std::vector<Group>& groups,
                                         const std::vector<Hypothesis>& hypotheses) {
  int fits = 0;
  for (const Hypothesis& h : hypotheses) {
    if (fits >= options_.max_hypotheses) break;
    const Group& group = groups[static_cast<size_t>(h.group)];
    const IndexEntry& entry = index.entries[h.kind][static_cast<size_t>(h.entry)];
    const Model& model = models_.models[entry.model];
    const int nseg = GroupSegments(group.kind);
    bool all_claimed = true;
    for (int s = 0; s < nseg; ++s) {
      all_claimed =
          all_claimed && claims_.Claimed(group.segments[static_cast<size_t>(s)], SegmentClaims::kAnyModel);
    }
    if (all_claimed) continue;
    const geometry::Pose3 initial = InitialPose(index, model, entry, group, K_);
    if (!(initial.translation.z() > 0.05) || !initial.translation.allFinite()) continue;
    if (AlreadyTried(entry.model, initial)) continue;
    ++fits;
    RecognitionTrace::Fitted* traced = StartTrace(entry.model, h.kind, initial);

    // The hypothesis' own correspondences first, then predicted edges' matches (Lowe 1991).
    std::vector<LineMatch> matches;
    for (int s = 0; s < nseg; ++s) {
      const int edge = EntrySegmentEdge(entry, group.kind, s);
      TEACHSIM_CHECK(edge >= 0);  // a loaded index holds together (LoadOrBuildIndex)
      const ImageLine& l = lines_[static_cast<size_t>(group.segments[static_cast<size_t>(s)])];
      matches.push_back({edge, l.a, l.b});
    }
    VerifyFitted(entry.model, FitIndexHypothesis(model, K_, initial, matches, lines_, options_), traced,
                 Judged::kWhole);
  }
}

void RecognitionPass::FitAlternatives() {
  for (size_t c = 0, first_pass = candidates_.size(); c < first_pass && options_.max_alternative_fits > 0;
       ++c) {
    const int candidate_model = candidates_[c].model;
    const geometry::Pose3 world_T_candidate = camera_.world_T_camera() * candidates_[c].camera_T_object;
    int fitted = 0;
    for (const SupportHypothesis& h :
         AlternativeHypotheses(models_, camera_, detection_, candidate_model, world_T_candidate, options_)) {
      if (fitted >= options_.max_alternative_fits) break;
      const geometry::Pose3 initial = camera_.camera_T_world() * h.world_T_object;
      if (AlreadyTried(h.model, initial)) continue;
      ++fitted;
      FitOnSupport(h.model, kAlternativeKind, initial, Judged::kWhole);
    }
  }
}

std::vector<size_t> RecognitionPass::SupportedSubset(const std::vector<size_t>& set) const {
  std::vector<geometry::Aabb> extents;
  for (size_t i : set) {
    const Candidate& c = candidates_[i];
    extents.push_back(ExtentOf(BoxWorldVertices(models_.models[static_cast<size_t>(c.model)],
                                                camera_.world_T_camera() * c.camera_T_object)));
  }
  std::vector<bool> supported(set.size(), false);
  std::vector<geometry::Aabb> supports;
  for (bool changed = true; changed;) {
    changed = false;
    for (size_t k = 0; k < set.size(); ++k) {
      if (supported[k]) continue;
      bool ok = std::abs(extents[k].min.z() - fixed_.table_top_z) <= options_.support_tolerance_m;
      if (!ok) {
        supports = fixed_extents_;
        for (size_t j = 0; j < set.size(); ++j) {
          if (supported[j] && j != k) supports.push_back(extents[j]);
        }
        ok = StandsOnSupports(extents[k], supports, options_.support_tolerance_m,
                              options_.support_centre_slack_m);
      }
      if (ok) supported[k] = changed = true;
    }
  }
  std::vector<size_t> kept;
  for (size_t k = 0; k < set.size(); ++k) {
    if (supported[k]) kept.push_back(set[k]);
  }
  return kept;
}

bool RecognitionPass::Interpenetrate(int model_c, const geometry::Pose3& camera_T_c,
                                     const Candidate& a) const {
  const Model& mc = models_.models[static_cast<size_t>(model_c)];
  const Model& ma = models_.models[static_cast<size_t>(a.model)];
  const Penetration pen =
      BoxBoxPenetration(mc.box_size_m, camera_.world_T_camera() * camera_T_c, ma.box_size_m,
                        camera_.world_T_camera() * a.camera_T_object, false);
  return pen.depth_m > 0.25 * std::min(mc.box_size_m.minCoeff(), ma.box_size_m.minCoeff());
}

bool RecognitionPass::Conflicting(const Candidate& c, const Candidate& a) const {
  const Model& mc = models_.models[static_cast<size_t>(c.model)];
  const Model& ma = models_.models[static_cast<size_t>(a.model)];
  if (Interpenetrate(c.model, c.camera_T_object, a)) return true;
  std::set<int> sa(a.matches.segments.begin(), a.matches.segments.end());
  int shared = 0;
  for (int s : c.matches.segments) shared += sa.count(s) ? 1 : 0;
  if (shared * 3 > static_cast<int>(c.matches.segments.size())) return true;
  return HiddenSupportedSamples(ma, a.camera_T_object, mc, c.camera_T_object, camera_, detection_.edge_map,
                                options_) >= kMaxHiddenSupportedSamples;
}

bool RecognitionPass::EndsAtContour(const Model& inner, const geometry::Pose3& camera_T_inner,
                                    const Model& outer, const geometry::Pose3& camera_T_outer,
                                    const std::vector<ImageLine>& contours) const {
  auto image = [&](const Model& model, const geometry::Pose3& pose) -> std::optional<BoxImage> {
    std::array<Eigen::Vector2d, 8> px;
    for (int v = 0; v < 8; ++v) {
      const Eigen::Vector3d p = pose * BoxVertex(model.box_size_m, v);
      if (!(p.z() > 1e-3)) return std::nullopt;
      px[static_cast<size_t>(v)] = (K_ * p).hnormalized();
    }
    return BoxImage(px, VisibleBoxEdges(model.box_size_m, pose.Inverse().translation));
  };
  const std::optional<BoxImage> in = image(inner, camera_T_inner), out = image(outer, camera_T_outer);
  return in && out && EndsAtContourInside(*in, *out, contours);
}

std::vector<size_t> RecognitionPass::Select(const std::vector<ImageLine>* contours) {
  std::vector<size_t> order(candidates_.size());
  rank_.assign(candidates_.size(), 0);
  for (size_t i = 0; i < order.size(); ++i) {
    order[i] = i;
    rank_[i] = NetSupportPx(candidates_[i].evidence) * candidates_[i].rank_score;
  }
  order = SupportedSubset(order);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return rank_[a] > rank_[b]; });
  std::vector<size_t> accepted;
  for (size_t i : order) {
    const Candidate& c = candidates_[i];
    std::vector<size_t> conflicts;  // positions in accepted
    for (size_t k = 0; k < accepted.size() && conflicts.size() < 2; ++k) {
      if (Conflicting(c, candidates_[accepted[k]])) conflicts.push_back(k);
    }
    if (conflicts.empty()) {
      accepted.push_back(i);
      continue;
    }
    // One rival at the same place: the candidate replaces it when what it predicts alone is in the
    // image and what the rival predicts alone is not (OwnOutlineBalance): a wrong model that
    // outranked the right one by the outline both share (a slab over a bar, a cube on a bar's end).
    if (conflicts.size() == 1 && options_.conflict_balance_margin > 0) {
      const Candidate& a = candidates_[accepted[conflicts[0]]];
      const Model& mc = models_.models[static_cast<size_t>(c.model)];
      const Model& ma = models_.models[static_cast<size_t>(a.model)];
      // What else is accepted explains its own edges: those count for neither. The first of the
      // others is the one compared with: the rival for the candidate, then the candidate for it.
      std::vector<std::pair<const Model*, geometry::Pose3>> others = {{&ma, a.camera_T_object}};
      for (size_t k = 0; k < accepted.size(); ++k) {
        if (k == conflicts[0]) continue;
        const Candidate& o = candidates_[accepted[k]];
        others.push_back({&models_.models[static_cast<size_t>(o.model)], o.camera_T_object});
      }
      PairwiseSide own{.own = OwnOutlineBalance(mc, c.camera_T_object, others, camera_, detection_.edge_map,
                                                fixed_edges_, options_),
                       .rank = rank_[i],
                       .in_image = VisibleOutlineInImage(mc, camera_, c.camera_T_object),
                       .holds_other = options_.conflict_within_rank_share > 0 && contours != nullptr &&
                                      WithinBox(mc, c.camera_T_object, ma, a.camera_T_object) &&
                                      EndsAtContour(ma, a.camera_T_object, mc, c.camera_T_object, *contours),
                       .rms_px = c.rms_px,
                       .score = c.rank_score,
                       .model = c.model};
      others.front() = {&mc, c.camera_T_object};
      PairwiseSide rival{.own = OwnOutlineBalance(ma, a.camera_T_object, others, camera_, detection_.edge_map,
                                                  fixed_edges_, options_),
                         .rank = rank_[accepted[conflicts[0]]],
                         .in_image = VisibleOutlineInImage(ma, camera_, a.camera_T_object),
                         .rms_px = a.rms_px,
                         .score = a.rank_score,
                         .model = a.model};
      if (options_.conflict_bare_table_share > 0) {
        // What each claims alone, the other accepted recognitions' images left out of both.
        const int table_grey = TableGreyOnce();
        rival.alone =
            BareTableBeyond(ma, a.camera_T_object, others, camera_, detection_.edge_map, table_grey);
        others.front() = {&ma, a.camera_T_object};
        own.alone = BareTableBeyond(mc, c.camera_T_object, others, camera_, detection_.edge_map, table_grey);
      }
      if (ReplacesRival(own, rival, options_)) accepted[conflicts[0]] = i;
    }
  }
  return WithoutExplainedAway(SupportedSubset(accepted));
}

std::vector<std::pair<const Model*, geometry::Pose3>> RecognitionPass::ModelsAndPoses(
    const std::vector<size_t>& accepted) const {
  std::vector<std::pair<const Model*, geometry::Pose3>> recognitions;
  for (size_t i : accepted) {
    const Candidate& c = candidates_[i];
    recognitions.push_back({&models_.models[static_cast<size_t>(c.model)], c.camera_T_object});
  }
  return recognitions;
}

std::vector<size_t> RecognitionPass::KeptWithout(const std::vector<size_t>& accepted,
                                                 const std::vector<size_t>& dropped) const {
  if (dropped.empty()) return accepted;
  std::vector<size_t> kept;
  for (size_t k = 0; k < accepted.size(); ++k) {
    if (std::find(dropped.begin(), dropped.end(), k) == dropped.end()) kept.push_back(accepted[k]);
  }
  return SupportedSubset(kept);  // what rested on a dropped one no longer stands
}

int RecognitionPass::TableGreyOnce() {
  if (table_grey_ < 0) table_grey_ = TableGrey(detection_.edge_map);
  return table_grey_;
}

std::vector<size_t> RecognitionPass::WithoutExplainedAway(std::vector<size_t> accepted) const {
  if (options_.min_own_balance <= 0 || accepted.empty()) return accepted;
  return KeptWithout(accepted, ExplainedAway(ModelsAndPoses(accepted), camera_, detection_.edge_map,
                                             fixed_edges_, options_));
}

std::vector<size_t> RecognitionPass::WithoutBareClaims(std::vector<size_t> accepted) {
  if (options_.max_bare_table_share <= 0 || accepted.empty()) return accepted;
  return KeptWithout(accepted, StandingOnBareTable(ModelsAndPoses(accepted), camera_, detection_.edge_map,
                                                   TableGreyOnce(), options_.max_bare_table_share));
}

void RecognitionPass::ReverifyOccluded(std::vector<size_t>* accepted_io,
                                       const std::vector<ImageLine>* found_contours) {
  std::vector<size_t>& accepted = *accepted_io;
  if (!options_.occlusion_reverify || rejected_.empty()) return;
  // Which occluders can hide part of a pose: those whose boxes' images (pin-hole projections: a
  // ray through both boxes maps to one point in both) overlap and that come nearer the camera.
  struct ImageExtent {
    Eigen::Vector2d lo, hi;
    double near_z = 0, far_z = 0;
    bool valid = false;  // no vertex behind or at the camera
  };
  auto image_extent = [&](const Model& model, const geometry::Pose3& camera_T_object) {
    ImageExtent e;
    e.lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
    e.hi = -e.lo;
    e.near_z = std::numeric_limits<double>::infinity();
    e.far_z = -e.near_z;
    for (int v = 0; v < 8; ++v) {
      const Eigen::Vector3d p = camera_T_object * BoxVertex(model.box_size_m, v);
      if (p.z() <= 1e-3) return e;
      const Eigen::Vector2d px = (K_ * p).hnormalized();
      e.lo = e.lo.cwiseMin(px);
      e.hi = e.hi.cwiseMax(px);
      e.near_z = std::min(e.near_z, p.z());
      e.far_z = std::max(e.far_z, p.z());
    }
    e.valid = true;
    return e;
  };
  std::vector<Occluder> occluders;
  std::vector<ImageExtent> occluder_extents;  // of each occluder
  std::vector<bool> claimed(lines_.size(), false);
  for (size_t i : accepted) {
    const Candidate& a = candidates_[i];
    const Model& model = models_.models[static_cast<size_t>(a.model)];
    if (auto o = MakeOccluder(model, a.camera_T_object, kOccluderMarginM)) {
      occluders.push_back(*o);
      occluder_extents.push_back(image_extent(model, a.camera_T_object));
    }
    for (int seg : a.matches.segments) claimed[static_cast<size_t>(seg)] = true;
  }
  std::vector<ImageLine> free_lines;  // the lines no accepted recognition claims
  std::vector<int> free_index;        // each one's index in `lines`
  for (size_t l = 0; l < lines_.size(); ++l) {
    if (claimed[l]) continue;
    free_lines.push_back(lines_[l]);
    free_index.push_back(static_cast<int>(l));
  }
  const std::vector<ImageLine> contours = !options_.occlusion_contours ? std::vector<ImageLine>{}
                                          : found_contours != nullptr
                                              ? *found_contours
                                              : OccludingContours(detection_, camera_, options_);
  // With a trace: each pose's judgement nearest to passing (RecognitionTrace::SecondLook).
  using Second = RecognitionTrace::SecondLook::Verdict;
  RecognitionTrace::SecondLook judgement;
  auto note = [&](Second verdict, bool behind_contour, double hidden, Outcome outcome, double score,
                  double min_score) {
    if (trace_ == nullptr) return;
    const RecognitionTrace::SecondLook look{verdict, behind_contour, outcome, hidden, score, min_score};
    if (look.NearerThan(judgement)) judgement = look;
  };
  // A pose judged again with `hiding` leaving out part of its outline (`hidden` of its samples in
  // the image): the matched share over the outline in view, without the lines accepted recognitions
  // claim; the rules, and an evidence score of at least `min_score`.
  // `free_matches`: the pose's matches among the free lines, found on the first call for the pose
  // (they do not depend on what hides it).
  auto judge_hidden = [&](const Rejected& r, const Hiding& hiding, double hidden,
                          std::optional<EdgeMatchSet>* free_matches,
                          double min_score) -> std::optional<Candidate> {
    const bool behind_contour = hiding.contour != nullptr;
    const Model& model = models_.models[static_cast<size_t>(r.model)];
    const geometry::Pose3& pose = r.fit.camera_T_object;
    if (!*free_matches) {
      *free_matches = MatchEdges(model, K_, pose, free_lines, options_.match_distance_px, match_angle_);
      for (int& seg : (*free_matches)->segments) seg = free_index[static_cast<size_t>(seg)];
    }
    EdgeMatchSet set = **free_matches;
    // The matched share of the outline in view (the hidden share as the samples inside the image give it).
    const double covered = set.matched_fraction * set.visible_length_px;
    set.visible_length_px *= 1 - hidden;
    set.matched_fraction = set.visible_length_px > 0 ? std::min(1.0, covered / set.visible_length_px) : 0;
    if (!EnoughMatched(model, set, pose)) {
      note(Second::kRules, behind_contour, hidden, Outcome::kMatchedFraction, 0, min_score);
      return std::nullopt;
    }
    const PoseEvidence evidence =
        ComputeEvidence(model, camera_, pose, detection_, &fixed_edges_, options_, set, &hiding);
    double rms_px = 0;
    const Outcome verdict = Judge(evidence, options_, &rms_px);
    const double score = EvidenceScore(evidence);
    if (verdict != Outcome::kCandidate || score < min_score) {
      note(verdict != Outcome::kCandidate ? Second::kRules : Second::kScore, behind_contour, hidden, verdict,
           score, min_score);
      return std::nullopt;
    }
    Candidate c;
    c.trace_index = r.trace_index;
    c.model = r.model;
    c.camera_T_object = pose;
    c.fit = r.fit;
    c.fit.rms_px = rms_px;
    c.matches = std::move(set);
    c.evidence = evidence;
    c.rms_px = rms_px;
    c.rank_score = score;
    return c;
  };
  const double min_shown = options_.LeastContourShownShare();
  std::vector<Occluder> in_front;
  std::vector<size_t> passed;
  for (const Rejected& r : rejected_) {
    const Model& model = models_.models[static_cast<size_t>(r.model)];
    const geometry::Pose3& pose = r.fit.camera_T_object;
    // One that interpenetrates an accepted recognition cannot join them (most turned-down poses
    // are other fits of an accepted block): not judged again.
    bool deep = false;
    for (size_t k = 0; k < accepted.size() && !deep; ++k) {
      deep = Interpenetrate(r.model, pose, candidates_[accepted[k]]);
    }
    judgement = {};
    // The judgement into the trace, where there is one.
    auto trace_it = [&] {
      if (trace_ == nullptr || r.trace_index < 0) return;
      judgement.outside_image = 1 - VisibleOutlineInImage(model, camera_, pose);
      trace_->fitted[static_cast<size_t>(r.trace_index)].second_look = judgement;
    };
    if (deep || Implausible(model, pose)) {
      note(deep ? Second::kOverlaps : Second::kImplausible, false, 0, Outcome::kFitFailed, 0, 0);
      trace_it();
      continue;
    }
    note(Second::kNothingHides, false, 0, Outcome::kFitFailed, 0, 0);
    std::optional<EdgeMatchSet> free_matches;
    const ImageExtent extent = image_extent(model, pose);
    in_front.clear();
    for (size_t k = 0; k < occluders.size(); ++k) {
      const ImageExtent& o = occluder_extents[k];
      if (!extent.valid || !o.valid ||
          (o.near_z < extent.far_z && (o.lo.array() <= extent.hi.array()).all() &&
           (extent.lo.array() <= o.hi.array()).all())) {
        in_front.push_back(occluders[k]);
      }
    }
    std::optional<Candidate> best;
    std::optional<OutlineSamples> outline;  // sampled on first use
    auto hidden_outline = [&](const Hiding& hiding) {
      if (!outline) outline.emplace(model, camera_, pose);
      return HiddenOutlineShare(&*outline, hiding, detection_.edge_map);
    };
    if (!in_front.empty()) {
      Hiding hiding;
      hiding.boxes = &in_front;
      const double hidden = hidden_outline(hiding).share;
      if (hidden >= options_.occlusion_min_hidden_share && 1 - hidden >= options_.occlusion_min_shown_share) {
        best = judge_hidden(r, hiding, hidden, &free_matches, options_.occlusion_min_evidence_score);
        if (best) {
          note(Second::kPassed, false, hidden, Outcome::kCandidate, best->rank_score,
               options_.occlusion_min_evidence_score);
        }
      }
    }
    if (!best && !contours.empty() && extent.valid) {
      std::array<Eigen::Vector2d, 8> px;  // the pose's image (pin-hole)
      for (int v = 0; v < 8; ++v)
        px[static_cast<size_t>(v)] = (K_ * (pose * BoxVertex(model.box_size_m, v))).hnormalized();
      const uint16_t visible = VisibleBoxEdges(model.box_size_m, pose.Inverse().translation);
      std::vector<ContourOccluder> occlusions;
      ContourOcclusions(contours, BoxImage(px, visible), &occlusions,
                        {.ends_inside = options_.contour_pole_ends,
                         .across_beside = options_.contour_across_beside,
                         .pole_tops = options_.contour_pole_tops,
                         .sides_bounded = options_.contour_sides_bounded});
      for (const ContourOccluder& contour : occlusions) {
        Hiding hiding;
        hiding.contour = &contour;
        hiding.K = K_;
        const HiddenOutline hidden = hidden_outline(hiding);
        const double shown = 1 - hidden.share;
        if (hidden.share < options_.occlusion_min_hidden_share || shown < min_shown ||
            hidden.coverage > options_.contour_max_hidden_coverage) {
          continue;
        }
        const double asked = options_.ContourMinEvidenceScore(hidden.coverage);
        std::optional<Candidate> c = judge_hidden(r, hiding, hidden.share, &free_matches, asked);
        // Less than contour_min_shown_share in view: only with the higher evidence score.
        const double score = c ? c->rank_score : 0;
        if (c && shown < options_.contour_min_shown_share &&
            c->rank_score < options_.contour_low_shown_score) {
          c.reset();
          note(Second::kVetoed, true, hidden.share, Outcome::kCandidate, score,
               options_.contour_low_shown_score);
        }
        if (c && (!best || c->rank_score > best->rank_score)) {
          if (!ContinuesPastHiddenEnd(model, camera_, pose, contour, detection_.edge_map, options_) &&
              !AmbiguousExtent(models_, r.model, pose, contour, K_)) {
            best = std::move(c);
            note(Second::kPassed, true, hidden.share, Outcome::kCandidate, score, asked);
          } else {
            note(Second::kVetoed, true, hidden.share, Outcome::kCandidate, score, asked);
          }
        }
      }
    }
    trace_it();
    if (!best) continue;
    passed.push_back(candidates_.size());
    rank_.push_back(NetSupportPx(best->evidence) * best->rank_score);
    candidates_.push_back(std::move(*best));
  }
  std::stable_sort(passed.begin(), passed.end(), [&](size_t a, size_t b) { return rank_[a] > rank_[b]; });
  for (size_t i : passed) {
    bool conflict = false;
    for (size_t k = 0; k < accepted.size() && !conflict; ++k) {
      conflict = Conflicting(candidates_[i], candidates_[accepted[k]]);
    }
    if (conflict) continue;
    std::vector<size_t> with = accepted;
    with.push_back(i);
    if (SupportedSubset(with).size() == with.size()) accepted = std::move(with);
  }
}

}  // namespace

Result<RecognitionResult> Recognizer::Recognize(const cv::Mat& image_gray8, const Camera& camera,
                                                const scene::Scene* fixed_world,
                                                RecognitionTrace* trace) const {
  if (image_gray8.empty() || image_gray8.type() != CV_8UC1) {
    return Status::InvalidInput("Recognize: the image must be 8-bit monochrome (CV_8UC1)");
  }
  if (image_gray8.cols != camera.width() || image_gray8.rows != camera.height()) {
    return Status::InvalidInput("Recognize: the image is " + std::to_string(image_gray8.cols) + "x" +
                                std::to_string(image_gray8.rows) + " but the camera is " +
                                std::to_string(camera.width()) + "x" + std::to_string(camera.height()));
  }
  RecognitionResult result;
  const RecognizerIndex& index = *index_;
  const auto t0 = Clock::now();

  // 1. lines
  const LineDetection detection = DetectLinesAndEdges(image_gray8, camera, options_);
  const std::vector<ImageLine>& lines = detection.lines;
  const auto t1 = Clock::now();

  // 2. groups
  const std::vector<Group> groups = FindGroups(lines, options_);
  const auto t2 = Clock::now();

  // 3. indexing
  const std::vector<Hypothesis> hypotheses = IndexHypotheses(index, groups, lines, options_);
  const auto t3 = Clock::now();
  if (trace != nullptr) {
    trace->lines = static_cast<int>(lines.size());
    trace->groups = static_cast<int>(groups.size());
    trace->hypotheses = static_cast<int>(hypotheses.size());
  }

  // The fixed world: the table top and the other fixed parts.
  const FixedWorld fixed = ReadFixedWorld(fixed_world);
  const FixedEdgeMap fixed_edges = ProjectFixedEdges(fixed_world, camera);

  // 4. pose fitting and verification: the support-plane hypotheses, the index's most probable
  // hypotheses, then other models at each candidate's place.
  RecognitionPass pass(models_, options_, camera, detection, fixed, fixed_edges, trace);
  double support_ms = 0;  // proposing the support-plane hypotheses (their fits count in fit_verify)
  std::vector<ImageLine> contours;  // occluding contours, found with the support-plane hypotheses
  bool contours_found = false;
  if (options_.support_hypotheses) {
    const std::vector<SupportPlane> planes = SupportPlanes(fixed, options_);
    const auto ts = Clock::now();
    // The pieces of each straight edge joined once, for the corners and the occluding contours.
    const JoinedLines joined = JoinCollinearLines(lines);
    std::vector<ImageCorner> corners = FindCorners(joined, options_);
    if (options_.occlusion_reverify && options_.occlusion_contours) {
      contours = OccludingContours(detection, joined, camera, options_);
      contours_found = true;
      if (options_.support_hidden_corners) {
        const std::vector<ImageCorner> hidden = FindHiddenCorners(joined, contours, corners, options_);
        corners.insert(corners.end(), hidden.begin(), hidden.end());
      }
    }
    const std::vector<SupportHypothesis> support_hypotheses =
        SupportHypotheses(models_, camera, detection, corners, planes, options_, contours);
    support_ms = Ms(ts, Clock::now());
    if (trace != nullptr) {
      trace->corners = static_cast<int>(corners.size());
      trace->support_hypotheses = static_cast<int>(support_hypotheses.size());
    }
    pass.FitSupportHypotheses(corners, support_hypotheses);
  }
  pass.FitIndexHypotheses(index, groups, hypotheses);
  pass.FitAlternatives();
  const auto t4 = Clock::now();

  // 5. consistency and non-maximum suppression; 5b. blocks partly hidden by the accepted ones.
  std::vector<size_t> accepted = pass.Select(contours_found ? &contours : nullptr);
  const auto t_occlusion = Clock::now();
  pass.ReverifyOccluded(&accepted, contours_found ? &contours : nullptr);
  accepted = pass.WithoutBareClaims(std::move(accepted));
  const double occlusion_ms = Ms(t_occlusion, Clock::now());

  // 6. the accepted candidates as recognitions in the world frame, then the model editor's rules (§4.3).
  const geometry::Pose3& world_T_camera = camera.world_T_camera();
  for (size_t i : accepted) {
    const Candidate& c = pass.candidates()[i];
    if (trace != nullptr && c.trace_index >= 0) trace->fitted[static_cast<size_t>(c.trace_index)].accepted = true;
    const Model& model = models_.models[static_cast<size_t>(c.model)];
    Recognition r;
    r.model = model.name;
    r.raw_world_T_object = world_T_camera * c.camera_T_object;
    r.world_T_object = r.raw_world_T_object;
    r.score = c.evidence.support_fraction;
    r.matched_edge_fraction = c.matches.matched_fraction;
    r.reprojection_rms_px = c.rms_px;
    Eigen::Matrix<double, 6, 6> b = Eigen::Matrix<double, 6, 6>::Zero();
    b.block<3, 3>(0, 0) = world_T_camera.RotationMatrix();
    b.block<3, 3>(3, 3) = world_T_camera.RotationMatrix();
    r.covariance = b * c.fit.covariance_camera * b.transpose();
    result.objects.push_back(std::move(r));
  }
  ApplyModelEditorRules(models_, camera, detection, fixed, options_, &result.objects);
  const auto t5 = Clock::now();
  result.timing_ms = {{"lines", Ms(t0, t1)},
                      {"groups", Ms(t1, t2)},
                      {"index", Ms(t2, t3)},
                      {"support_hypotheses", support_ms},
                      {"fit_verify", Ms(t3, t4) - support_ms},
                      {"select_edit", Ms(t4, t5) - occlusion_ms},
                      {"occlusion", occlusion_ms},
                      {"total", Ms(t0, t5)}};
  return result;
}

}  // namespace teachsim::vision
