#include "teachsim/vision/evaluate.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <tuple>

#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

// The table's top is z = 0; its extent covers any work area the benchmark uses.
constexpr double kTableSideM = 1.2, kTableThicknessM = 0.04;

// The pose fields of an entry that holds other fields too.
geometry::Pose3 ReadEmbeddedPose(const json::Reader& r) {
  const json::Json pose{{"position", r.At("position").raw()}, {"quaternion_wxyz", r.At("quaternion_wxyz").raw()}};
  try {
    return geometry::ReadPose(json::Reader(pose));
  } catch (const json::ParseError& e) {
    r.Fail(e.what());
  }
}

TruthObject ReadTruthObject(const json::Reader& o, const std::map<std::string, Eigen::Vector3d>& sizes) {
  o.RejectUnknownKeys({"name", "model", "dims", "position", "quaternion_wxyz", "visible_fraction",
                       "visible_pixels"});
  TruthObject t;
  t.name = o.At("name").NonEmptyString();
  t.model = o.At("model").NonEmptyString();
  const auto size = sizes.find(t.model);
  if (size == sizes.end()) o.At("model").Fail("model \"" + t.model + "\" is not in \"models\"");
  if (auto dims = o.Find("dims")) {
    const Eigen::Vector3d d = dims->Vector3();
    if ((d - size->second).cwiseAbs().maxCoeff() > 1e-9) {
      dims->Fail("must equal the model's sizes [" + json::FormatNumber(size->second.x()) + ", " +
                 json::FormatNumber(size->second.y()) + ", " + json::FormatNumber(size->second.z()) + "]");
    }
  }
  t.world_T_object = ReadEmbeddedPose(o);
  t.visible_fraction = o.At("visible_fraction").NumberInRange(0.0, 1.0);
  t.visible_pixels = static_cast<int>(o.At("visible_pixels").IntegerInRange(0, 1LL << 30));
  return t;
}

FrameTruth ReadFrame(const json::Reader& f) {
  f.RejectUnknownKeys({"position", "quaternion_wxyz", "inner", "wall", "height"});
  FrameTruth frame;
  frame.world_T_frame = ReadEmbeddedPose(f);
  const json::Reader inner = f.At("inner");
  inner.ExpectSize(2);
  frame.inner_m = Eigen::Vector2d(inner.Index(0).NumberGreaterThan(0.0), inner.Index(1).NumberGreaterThan(0.0));
  frame.wall_m = f.At("wall").NumberGreaterThan(0.0);
  frame.height_m = f.At("height").NumberGreaterThan(0.0);
  return frame;
}

TruthSet ReadTruthSet(const json::Reader& r, const std::filesystem::path& folder) {
  r.RejectUnknownKeys({"units", "world", "models", "frame_model", "cases"});
  TruthSet set;
  const json::Reader models = r.At("models");
  if (!models.IsObject()) models.Fail("must be an object {model: [x, y, z]}");
  for (const std::string& name : models.Keys()) {
    const json::Reader size = models.At(name);
    const Eigen::Vector3d s = size.Vector3();
    if (s.minCoeff() <= 0) size.Fail("box sides must be > 0");
    set.model_sizes_m[name] = s;
  }
  const json::Reader cases = r.At("cases");
  for (std::size_t i = 0; i < cases.Size(); ++i) {
    const json::Reader c = cases.Index(i);
    c.RejectUnknownKeys({"image", "camera", "frame", "objects", "noise_sigma"});
    TruthCase tc;
    const std::filesystem::path image = c.At("image").NonEmptyString();
    tc.image = (image.is_absolute() ? image : folder / image).string();
    tc.camera = scene::ReadCamera(c.At("camera"));
    if (auto frame = c.Find("frame")) tc.frame = ReadFrame(*frame);
    const json::Reader objects = c.At("objects");
    for (std::size_t j = 0; j < objects.Size(); ++j) {
      tc.objects.push_back(ReadTruthObject(objects.Index(j), set.model_sizes_m));
    }
    set.cases.push_back(std::move(tc));
  }
  return set;
}

// Nearest-rank quantile of sorted values.
double Quantile(const std::vector<double>& sorted, double q) {
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size())));
  return sorted[std::clamp<std::size_t>(rank, 1, sorted.size()) - 1];
}

json::Json StatsToJson(const Stats& s) {
  auto number = [](double v) { return std::isfinite(v) ? json::Json(v) : json::Json(nullptr); };
  return {{"count", s.count},
          {"mean", number(s.mean)},
          {"median", number(s.median)},
          {"p90", number(s.p90)},
          {"max", number(s.max)}};
}

}  // namespace

std::vector<Eigen::Quaterniond> BoxSymmetries(const Eigen::Vector3d& size_m, double tolerance_m) {
  std::vector<Eigen::Quaterniond> group;
  std::array<int, 3> perm = {0, 1, 2};
  do {
    for (int signs = 0; signs < 8; ++signs) {
      // Column j of the matrix maps object axis j onto axis perm[j] with a sign.
      Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
      bool keeps_sizes = true;
      for (int j = 0; j < 3; ++j) {
        m(perm[static_cast<std::size_t>(j)], j) = (signs >> j & 1) != 0 ? -1.0 : 1.0;
        keeps_sizes = keeps_sizes && std::abs(size_m[j] - size_m[perm[static_cast<std::size_t>(j)]]) <= tolerance_m;
      }
      if (!keeps_sizes || m.determinant() < 0) continue;
      group.emplace_back(m);
    }
  } while (std::next_permutation(perm.begin(), perm.end()));
  // The identity permutation with no sign flips is generated first.
  TEACHSIM_CHECK(group.front().isApprox(Eigen::Quaterniond::Identity()));
  return group;
}

double SymmetricRotationError(const Eigen::Quaterniond& world_R_truth, const Eigen::Quaterniond& world_R_estimate,
                              const std::vector<Eigen::Quaterniond>& symmetries) {
  // The smallest angle is the unit quaternion's with the largest |w|; then angle = 2 atan2(|v|, |w|),
  // exact near 0 and near pi (acos of w is not).
  const Eigen::Quaterniond estimate_R_truth = world_R_estimate.conjugate() * world_R_truth;
  Eigen::Quaterniond best(0, 1, 0, 0);  // pi
  double best_w = -1;
  for (const Eigen::Quaterniond& s : symmetries) {
    const Eigen::Quaterniond d = (estimate_R_truth * s).normalized();
    if (std::abs(d.w()) > best_w) {
      best_w = std::abs(d.w());
      best = d;
    }
  }
  return 2.0 * std::atan2(best.vec().norm(), std::abs(best.w()));
}

double SymmetricProjectionRms(const Camera& camera, const Eigen::Vector3d& size_m,
                              const geometry::Pose3& world_T_truth, const geometry::Pose3& world_T_estimate,
                              const std::vector<Eigen::Quaterniond>& symmetries) {
  std::array<Eigen::Vector2d, 8> estimate_px;
  for (int i = 0; i < 8; ++i) {
    const auto p = camera.Project(world_T_estimate * BoxVertex(size_m, i));
    if (!p) return kNaN;
    estimate_px[static_cast<std::size_t>(i)] = *p;
  }
  double best = kNaN;
  for (const Eigen::Quaterniond& s : symmetries) {
    // The truth's pose under symmetry s: its corner s * c stands where the estimate's corner c does.
    double sum = 0;
    for (int i = 0; i < 8; ++i) {
      const auto p = camera.Project(world_T_truth * (s * BoxVertex(size_m, i)));
      if (!p) return kNaN;
      sum += (*p - estimate_px[static_cast<std::size_t>(i)]).squaredNorm();
    }
    const double rms = std::sqrt(sum / 8);
    if (!(rms >= best)) best = rms;
  }
  return best;
}

PositionError SplitPositionError(const Eigen::Vector3d& truth_in_world, const Eigen::Vector3d& estimate_in_world,
                                 const Eigen::Vector3d& camera_centre_in_world) {
  const Eigen::Vector3d sight = (truth_in_world - camera_centre_in_world).normalized();
  const Eigen::Vector3d e = estimate_in_world - truth_in_world;
  const double along = e.dot(sight);
  return {(e - along * sight).norm(), std::abs(along)};
}

Result<TruthSet> LoadTruthSet(const std::string& path) {
  TEACHSIM_ASSIGN_OR_RETURN(const json::Json document, json::ReadFile(path));
  const std::filesystem::path folder = std::filesystem::absolute(path).parent_path();
  return json::Decode<TruthSet>(document, path, [&](const json::Reader& r) { return ReadTruthSet(r, folder); });
}

scene::Scene FixedWorldScene(const std::optional<FrameTruth>& frame) {
  scene::Scene world;
  world.objects.push_back(scene::BoxObject(
      "table", true, Eigen::Vector3d(kTableSideM, kTableSideM, kTableThicknessM),
      geometry::Pose3::Translation(Eigen::Vector3d(0, 0, -kTableThicknessM / 2))));
  if (frame.has_value()) {
    const double w = frame->wall_m, h = frame->height_m, ix = frame->inner_m.x(), iy = frame->inner_m.y();
    scene::SceneObject object;
    object.name = "frame";
    object.fixed = true;
    object.shape_spec.kind = scene::ShapeSpec::Kind::kParts;
    auto wall = [&](const Eigen::Vector3d& size, const Eigen::Vector3d& centre) {
      scene::ShapeSpec::Part part;
      part.shape.kind = scene::ShapeSpec::Kind::kBox;
      part.shape.box_size = size;
      part.pose = geometry::Pose3::Translation(centre);
      object.shape_spec.parts.push_back(part);
    };
    // Long walls along x over the whole outer length, short walls along y between them.
    wall({ix + 2 * w, w, h}, {0, (iy + w) / 2, h / 2});
    wall({ix + 2 * w, w, h}, {0, -(iy + w) / 2, h / 2});
    wall({w, iy, h}, {(ix + w) / 2, 0, h / 2});
    wall({w, iy, h}, {-(ix + w) / 2, 0, h / 2});
    auto shape = scene::BuildShape(object.shape_spec);
    TEACHSIM_CHECK_MSG(shape.ok(), "frame walls must have positive sizes");
    object.shape = std::move(shape).value();
    object.world_T_object = frame->world_T_frame;
    world.objects.push_back(std::move(object));
  }
  return world;
}

Status MatchOptions::Validate() const {
  auto positive = [](double v, const char* name) {
    return std::isfinite(v) && v > 0 ? Status::Ok()
                                     : Status::InvalidInput(std::string("MatchOptions::") + name + " = " +
                                                            json::FormatNumber(v) + " must be > 0");
  };
  TEACHSIM_RETURN_IF_ERROR(positive(max_across_m, "max_across_m"));
  TEACHSIM_RETURN_IF_ERROR(positive(max_along_m, "max_along_m"));
  TEACHSIM_RETURN_IF_ERROR(positive(max_rotation_rad, "max_rotation_rad"));
  if (!(min_visible_fraction >= 0 && min_visible_fraction < 1)) {
    return Status::InvalidInput("MatchOptions::min_visible_fraction = " + json::FormatNumber(min_visible_fraction) +
                                " must be in [0, 1)");
  }
  return Status::Ok();
}

Result<ImageEvaluation> EvaluateImage(const std::vector<TruthObject>& truth,
                                      const std::vector<Detection>& detections,
                                      const std::map<std::string, Eigen::Vector3d>& model_sizes_m,
                                      const Eigen::Vector3d& camera_centre_in_world,
                                      const MatchOptions& options, const Camera* camera) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  std::vector<std::vector<Eigen::Quaterniond>> symmetries;
  for (const TruthObject& t : truth) {
    const auto size = model_sizes_m.find(t.model);
    if (size == model_sizes_m.end()) {
      return Status::InvalidInput("truth object \"" + t.name + "\": model \"" + t.model + "\" has no box size");
    }
    symmetries.push_back(BoxSymmetries(size->second));
  }
  ImageEvaluation out;
  std::vector<int> outcome_of(truth.size(), -1);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (truth[i].visible_fraction < options.min_visible_fraction || truth[i].visible_pixels <= 0) continue;
    outcome_of[i] = static_cast<int>(out.objects.size());
    ObjectOutcome o;
    o.truth = static_cast<int>(i);
    o.visible_fraction = truth[i].visible_fraction;
    out.objects.push_back(o);
  }
  std::vector<int> order(detections.size());
  for (std::size_t d = 0; d < order.size(); ++d) order[d] = static_cast<int>(d);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return detections[static_cast<std::size_t>(a)].score > detections[static_cast<std::size_t>(b)].score;
  });
  out.detection_truth.assign(detections.size(), -1);
  std::vector<bool> taken(truth.size(), false);
  for (int d : order) {
    const Detection& det = detections[static_cast<std::size_t>(d)];
    int best = -1;
    double best_cost = 0, best_rotation = 0;
    PositionError best_error;
    for (std::size_t i = 0; i < truth.size(); ++i) {
      if (taken[i] || truth[i].model != det.model) continue;
      const double rotation = SymmetricRotationError(truth[i].world_T_object.rotation, det.world_T_object.rotation,
                                                     symmetries[i]);
      const PositionError e = SplitPositionError(truth[i].world_T_object.translation,
                                                 det.world_T_object.translation, camera_centre_in_world);
      if (rotation > options.max_rotation_rad || e.across_m > options.max_across_m || e.along_m > options.max_along_m) {
        continue;
      }
      const double cost =
          rotation / options.max_rotation_rad + e.across_m / options.max_across_m + e.along_m / options.max_along_m;
      if (best < 0 || cost < best_cost) {
        best = static_cast<int>(i);
        best_cost = cost;
        best_rotation = rotation;
        best_error = e;
      }
    }
    if (best < 0) {
      ++out.false_positives;
      continue;
    }
    taken[static_cast<std::size_t>(best)] = true;
    const int outcome = outcome_of[static_cast<std::size_t>(best)];
    if (outcome < 0) {
      out.detection_truth[static_cast<std::size_t>(d)] = -2;
      continue;
    }
    out.detection_truth[static_cast<std::size_t>(d)] = best;
    ObjectOutcome& o = out.objects[static_cast<std::size_t>(outcome)];
    o.detection = d;
    o.rotation_error_rad = best_rotation;
    o.position_error = best_error;
    o.reprojection_rms_px = det.reprojection_rms_px;
    if (camera != nullptr) {
      o.truth_projection_rms_px =
          SymmetricProjectionRms(*camera, model_sizes_m.at(truth[static_cast<std::size_t>(best)].model),
                                 truth[static_cast<std::size_t>(best)].world_T_object, det.world_T_object,
                                 symmetries[static_cast<std::size_t>(best)]);
    }
  }
  return out;
}

Result<std::vector<int>> FalsePositiveHosts(const std::vector<TruthObject>& truth,
                                            const std::vector<Detection>& detections,
                                            const std::map<std::string, Eigen::Vector3d>& model_sizes_m,
                                            const ImageEvaluation& evaluation, double margin_m) {
  if (evaluation.detection_truth.size() != detections.size()) {
    return Status::InvalidInput("the evaluation has " + std::to_string(evaluation.detection_truth.size()) +
                                " detections, not " + std::to_string(detections.size()));
  }
  auto size_of = [&](const std::string& model) -> const Eigen::Vector3d* {
    const auto it = model_sizes_m.find(model);
    return it == model_sizes_m.end() ? nullptr : &it->second;
  };
  // Whether `point` lies in the box of `size` at `world_T_box`, grown by margin_m on every side.
  auto inside = [&](const Eigen::Vector3d& point, const geometry::Pose3& world_T_box,
                    const Eigen::Vector3d& size) {
    const Eigen::Vector3d local = world_T_box.Inverse() * point;
    return (local.cwiseAbs().array() <= 0.5 * size.array() + margin_m).all();
  };
  std::vector<int> hosts(detections.size(), -1);
  for (std::size_t d = 0; d < detections.size(); ++d) {
    if (evaluation.detection_truth[d] != -1) continue;
    const Detection& det = detections[d];
    const Eigen::Vector3d* det_size = size_of(det.model);
    if (det_size == nullptr) {
      return Status::InvalidInput("detection " + std::to_string(d) + ": model \"" + det.model +
                                  "\" has no box size");
    }
    double nearest = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < truth.size(); ++i) {
      const Eigen::Vector3d* truth_size = size_of(truth[i].model);
      if (truth_size == nullptr) {
        return Status::InvalidInput("truth object \"" + truth[i].name + "\": model \"" + truth[i].model +
                                    "\" has no box size");
      }
      const Eigen::Vector3d& t = truth[i].world_T_object.translation;
      const Eigen::Vector3d& c = det.world_T_object.translation;
      if (!inside(c, truth[i].world_T_object, *truth_size) && !inside(t, det.world_T_object, *det_size))
        continue;
      const double distance = (t - c).norm();
      if (distance < nearest) {
        nearest = distance;
        hosts[d] = static_cast<int>(i);
      }
    }
  }
  return hosts;
}

Result<std::vector<std::string>> ShorterModelsInView(
    const std::map<std::string, Eigen::Vector3d>& model_sizes_m, const std::string& model,
    const geometry::Pose3& world_T_object, const Camera& camera,
    const std::vector<Eigen::Vector2d>& visible_px, double margin_px) {
  const auto it = model_sizes_m.find(model);
  if (it == model_sizes_m.end()) return Status::InvalidInput("model \"" + model + "\" has no box size");
  const Eigen::Vector3d& size = it->second;
  // The shorter models of the block's cross-section: cut along the block's axis k, the other two
  // sides match two of the model's, whose third side (its length there) is shorter. Models whose
  // sides match so in two ways have equal lengths both ways: each is taken once.
  constexpr double kSameM = 1e-6;
  struct Candidate {
    double length;
    std::string name;
    int axis;
  };
  std::vector<Candidate> candidates;
  for (const auto& [name, other] : model_sizes_m) {
    for (int k = 0; k < 3; ++k) {
      const double a1 = size[(k + 1) % 3], a2 = size[(k + 2) % 3];
      bool taken = false;
      for (int m = 0; m < 3 && !taken; ++m) {
        const double b1 = other[(m + 1) % 3], b2 = other[(m + 2) % 3], length = other[m];
        const bool same_section = (std::abs(a1 - b1) <= kSameM && std::abs(a2 - b2) <= kSameM) ||
                                  (std::abs(a1 - b2) <= kSameM && std::abs(a2 - b1) <= kSameM);
        if (same_section && length < size[k] - kSameM) {
          candidates.push_back({length, name, k});
          taken = true;
        }
      }
    }
  }
  std::vector<std::string> out;
  if (candidates.empty() || visible_px.empty()) return out;
  // The pixels in view, lens distortion removed (a pixel the lens model cannot undo is left out).
  std::vector<cv::Point2f> pinhole;
  pinhole.reserve(visible_px.size());
  for (const Eigen::Vector2d& p : visible_px) {
    if (const std::optional<Eigen::Vector2d> u = camera.UndistortPixel(p)) {
      pinhole.emplace_back(static_cast<float>(u->x()), static_cast<float>(u->y()));
    }
  }
  if (pinhole.empty()) return out;
  const Eigen::Matrix3d K = camera.K();
  const geometry::Pose3 camera_T_object = camera.camera_T_world() * world_T_object;
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return std::tie(a.length, a.name) < std::tie(b.length, b.name);
  });
  for (const Candidate& c : candidates) {
    if (!out.empty() && out.back() == c.name) continue;  // explained along another axis already
    for (const double end : {-1.0, 1.0}) {
      // The shorter box, in the block's frame: flush with the end at `end` * size[axis] / 2.
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      centre[c.axis] = end * 0.5 * (size[c.axis] - c.length);
      Eigen::Vector3d half = 0.5 * size;
      half[c.axis] = 0.5 * c.length;
      std::vector<cv::Point2f> corners;
      for (int v = 0; v < 8; ++v) {
        const Eigen::Vector3d local =
            centre + Eigen::Vector3d((v & 1) ? half.x() : -half.x(), (v & 2) ? half.y() : -half.y(),
                                     (v & 4) ? half.z() : -half.z());
        const Eigen::Vector3d p = camera_T_object * local;
        if (!(p.z() > 1e-6)) return std::vector<std::string>{};
        const Eigen::Vector2d px = (K * p).hnormalized();
        corners.emplace_back(static_cast<float>(px.x()), static_cast<float>(px.y()));
      }
      std::vector<cv::Point2f> hull;
      cv::convexHull(corners, hull);
      // Signed distance: positive inside, negative outside.
      const bool all_inside = std::all_of(pinhole.begin(), pinhole.end(), [&](const cv::Point2f& p) {
        return cv::pointPolygonTest(hull, p, true) >= -margin_px;
      });
      if (all_inside) {
        out.push_back(c.name);
        break;
      }
    }
  }
  return out;
}

Stats Summarize(std::vector<double> values) {
  values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return !std::isfinite(v); }),
               values.end());
  Stats s;
  s.count = static_cast<int>(values.size());
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  double sum = 0;
  for (double v : values) sum += v;
  s.mean = sum / static_cast<double>(values.size());
  s.median = values.size() % 2 == 1 ? values[values.size() / 2]
                                    : 0.5 * (values[values.size() / 2 - 1] + values[values.size() / 2]);
  s.p90 = Quantile(values, 0.9);
  s.max = values.back();
  return s;
}

VisibilityBin BinOf(double visible_fraction) {
  if (visible_fraction >= 0.7) return VisibilityBin::kHigh;
  if (visible_fraction >= 0.4) return VisibilityBin::kMedium;
  return VisibilityBin::kLow;
}

const char* BinName(VisibilityBin bin) {
  switch (bin) {
    case VisibilityBin::kHigh:
      return ">=0.7";
    case VisibilityBin::kMedium:
      return "0.4-0.7";
    case VisibilityBin::kLow:
      return "<0.4";
  }
  return "?";
}

double Summary::Recall(VisibilityBin bin) const {
  const int i = static_cast<int>(bin);
  return objects[i] > 0 ? static_cast<double>(found[i]) / objects[i] : kNaN;
}

double Summary::RecallUnoccluded() const {
  return unoccluded_objects > 0 ? static_cast<double>(unoccluded_found) / unoccluded_objects : kNaN;
}

double Summary::FalsePositivesPerImage() const {
  return images > 0 ? static_cast<double>(false_positives) / images : kNaN;
}

void PoseSamples::Add(const ObjectOutcome& o) {
  rotation_deg_.push_back(o.rotation_error_rad * kRadToDeg);
  across_mm_.push_back(o.position_error.across_m * 1e3);
  along_mm_.push_back(o.position_error.along_m * 1e3);
  rms_px_.push_back(o.reprojection_rms_px);
  truth_projection_px_.push_back(o.truth_projection_rms_px);
}

PoseFigures PoseSamples::Build() const {
  return {Summarize(rotation_deg_), Summarize(across_mm_), Summarize(along_mm_), Summarize(rms_px_),
          Summarize(truth_projection_px_)};
}

void SummaryBuilder::Add(const ImageEvaluation& evaluation, const ImageTime& time) {
  ++counts_.images;
  counts_.false_positives += evaluation.false_positives;
  time_ms_.push_back(time.total_ms);
  counts_.over_time_goal += time.total_ms > kTimeGoalMs ? 1 : 0;
  for (const auto& [stage, ms] : time.stage_ms) stage_ms_[stage].push_back(ms);
  if (!counts_.slowest || time.total_ms > counts_.slowest->total_ms) counts_.slowest = time;
  for (const ObjectOutcome& o : evaluation.objects) {
    const int bin = static_cast<int>(BinOf(o.visible_fraction));
    const bool unoccluded = o.visible_fraction >= kUnoccludedFraction;
    ++counts_.objects[bin];
    counts_.unoccluded_objects += unoccluded ? 1 : 0;
    if (o.detection < 0) continue;
    ++counts_.found[bin];
    counts_.unoccluded_found += unoccluded ? 1 : 0;
    poses_.Add(o);
    if (o.rotation_error_rad <= goals_.rotation_rad && o.position_error.across_m <= goals_.across_m &&
        o.position_error.along_m <= goals_.along_m) {
      ++counts_.within_goals;
    }
  }
}

Summary SummaryBuilder::Build() const {
  Summary s = counts_;
  s.poses = poses_.Build();
  s.time_ms = Summarize(time_ms_);
  for (const auto& [stage, values] : stage_ms_) s.stage_time_ms[stage] = Summarize(values);
  return s;
}

json::Json RecallToJson(int objects, int found) {
  return {{"objects", objects},
          {"found", found},
          {"recall", objects > 0 ? json::Json(static_cast<double>(found) / objects) : json::Json(nullptr)}};
}

namespace {
// A set of pose figures under the names both summaries give them in JSON.
json::Json PoseFiguresToJson(const PoseFigures& f) {
  return {{"rotation_error_deg", StatsToJson(f.rotation_deg)},
          {"position_error_across_mm", StatsToJson(f.across_mm)},
          {"position_error_along_mm", StatsToJson(f.along_mm)},
          {"reprojection_rms_px", StatsToJson(f.reprojection_rms_px)},
          {"truth_projection_rms_px", StatsToJson(f.truth_projection_rms_px)}};
}
}  // namespace

json::Json SummaryToJson(const Summary& s) {
  json::Json recall = json::Json::object();
  for (VisibilityBin bin : {VisibilityBin::kHigh, VisibilityBin::kMedium, VisibilityBin::kLow}) {
    const int i = static_cast<int>(bin);
    recall[BinName(bin)] = RecallToJson(s.objects[i], s.found[i]);
  }
  const int found = s.found[0] + s.found[1] + s.found[2];
  json::Json unoccluded = RecallToJson(s.unoccluded_objects, s.unoccluded_found);
  unoccluded["min_visible_fraction"] = kUnoccludedFraction;
  json::Json stages = json::Json::object();
  for (const auto& [stage, stats] : s.stage_time_ms) stages[stage] = StatsToJson(stats);
  json::Json slowest = nullptr;
  if (s.slowest) {
    json::Json stage_ms = json::Json::object(), counts = json::Json::object();
    for (const auto& [stage, ms] : s.slowest->stage_ms) stage_ms[stage] = ms;
    for (const auto& [what, n] : s.slowest->counts) counts[what] = n;
    slowest = {
        {"image", s.slowest->image}, {"ms", s.slowest->total_ms}, {"stage_ms", stage_ms}, {"counts", counts}};
  }
  json::Json j = {{"images", s.images},
                  {"recall", recall},
                  {"recall_unoccluded", unoccluded},
                  {"false_positives", s.false_positives},
                  {"false_positives_per_image",
                   s.images > 0 ? json::Json(s.FalsePositivesPerImage()) : json::Json(nullptr)},
                  {"found_within_goals", s.within_goals},
                  {"found_within_goals_fraction",
                   found > 0 ? json::Json(double(s.within_goals) / found) : json::Json(nullptr)},
                  {"time_per_image_ms", StatsToJson(s.time_ms)},
                  {"time_goal_ms", kTimeGoalMs},
                  {"images_over_time_goal", s.over_time_goal},
                  {"stage_time_ms", stages},
                  {"slowest_image", slowest}};
  j.update(PoseFiguresToJson(s.poses));
  return j;
}

Status PairedBuilder::Add(const ImageEvaluation& a, const ImageEvaluation& b) {
  if (a.objects.size() != b.objects.size()) {
    return Status::InvalidInput("PairedBuilder: the evaluations score " + std::to_string(a.objects.size()) +
                                " and " + std::to_string(b.objects.size()) + " truth objects");
  }
  // Every pair checked before any is added: a refused image leaves the figures as they were.
  for (size_t i = 0; i < a.objects.size(); ++i) {
    if (a.objects[i].truth != b.objects[i].truth) {
      return Status::InvalidInput("PairedBuilder: scored object " + std::to_string(i) + " is truth object " +
                                  std::to_string(a.objects[i].truth) + " in one evaluation and " +
                                  std::to_string(b.objects[i].truth) + " in the other");
    }
  }
  for (size_t i = 0; i < a.objects.size(); ++i) {
    const ObjectOutcome &x = a.objects[i], &y = b.objects[i];
    if (x.detection < 0 || y.detection < 0) continue;
    ++counts_.objects;
    a_.Add(x);
    b_.Add(y);
    // Which one is smaller; NaN compares false both ways and counts for neither.
    auto tally = [](double u, double v, int* u_smaller, int* v_smaller) {
      *u_smaller += u < v ? 1 : 0;
      *v_smaller += v < u ? 1 : 0;
    };
    tally(x.rotation_error_rad, y.rotation_error_rad, &counts_.a_smaller_rotation,
          &counts_.b_smaller_rotation);
    tally(x.reprojection_rms_px, y.reprojection_rms_px, &counts_.a_smaller_reprojection,
          &counts_.b_smaller_reprojection);
    tally(x.truth_projection_rms_px, y.truth_projection_rms_px, &counts_.a_smaller_truth_projection,
          &counts_.b_smaller_truth_projection);
  }
  return Status::Ok();
}

PairedSummary PairedBuilder::Build() const {
  PairedSummary s = counts_;
  s.a = a_.Build();
  s.b = b_.Build();
  return s;
}

json::Json PairedSummaryToJson(const PairedSummary& s, const std::string& first, const std::string& second) {
  auto smaller = [](int rotation, int reprojection, int truth_projection) {
    return json::Json{{"rotation_error_deg", rotation},
                      {"reprojection_rms_px", reprojection},
                      {"truth_projection_rms_px", truth_projection}};
  };
  json::Json j = {{"objects", s.objects}};
  j[first] = PoseFiguresToJson(s.a);
  j[second] = PoseFiguresToJson(s.b);
  j[first + "_smaller"] =
      smaller(s.a_smaller_rotation, s.a_smaller_reprojection, s.a_smaller_truth_projection);
  j[second + "_smaller"] =
      smaller(s.b_smaller_rotation, s.b_smaller_reprojection, s.b_smaller_truth_projection);
  return j;
}

}  // namespace teachsim::vision
