// teachsim bench recognize [--json] [--quick] [--render-seeds N|A-B] [--no-peer]: recognition of
// blocks (issue 7) on the dev set (../shared/data/vision-dev: POV-Ray images with exact truth) and on
// our own renders with controlled occlusion (a dark cylinder between the camera and a block), per
// method on the same images: teachsim's recognizer (after the model editor's rules, and its raw
// fitted pose), and the peer, OpenCV's LINE-MOD (raw template poses, and refined by the recognizer's
// own least-squares fit of model edges to image lines). Figures per data set: recall per
// visible-fraction bin and of the unoccluded blocks (vision::kUnoccludedFraction), false positives
// per image, position error across / along the line of sight, symmetry-aware rotation error,
// reprojection RMS (the fit's residual, as each method reports it), the pose's projection error
// against the truth (vision::SymmetricProjectionRms: every method's, LINE-MOD's raw poses too) and
// time per image (thread CPU time, one OpenCV thread); and, since each method's medians are over the
// blocks it found, each peer's pose figures beside teachsim's on the blocks both found
// (vision::PairedBuilder; "paired_with_teachsim" in the JSON); and on the renders, each method's
// recall apart from the blocks that a shorter model would show alike (vision::ShorterModelsInView: a
// bar whose far end the cylinder hides or the image border cuts off shows as a cube at its near end;
// "recall_identifiable", "explained_by_shorter_model_per_bin" and
// "teachsim_false_positives_as_shorter_model" in the JSON). --render-seeds: the
// renders of each seed (60 scenes; default 7), several pooled into one data set; --no-peer: teachsim
// alone (LINE-MOD's templates not even made).
// Environment: TEACHSIM_HOME (repository), TEACHSIM_SHARED (../shared), TEACHSIM_CACHE_DIR
// (templates and index; default: bench-cache beside the executable, in the build folder);
// TEACHSIM_RECOGNIZE_DUMP=DIR draws the images with a miss or a false detection, with the detected
// segments and Canny edges (see DumpCase; with TEACHSIM_RECOGNIZE_DUMP_ALL=1 every image);
// TEACHSIM_RECOGNIZE_DEBUG=1 prints every LINE-MOD match beside the truth (and, for the recognizer,
// each image's stage counts and times, each object it found with its errors — each found block
// drawn over 2 px off its truth also with its raw pose's error, the editor's adjustments and the
// evidence at the raw, edited and true poses —, each object it missed with the stage that lost it and
// the evidence at the true pose, and each false detection); TEACHSIM_RECOGNIZE_NO_PEER=1 leaves LINE-MOD
// out (as --no-peer); TEACHSIM_RECOGNIZE_RENDER_SEED=N or A-B is the default of --render-seeds;
// TEACHSIM_RECOGNIZE_FEATURES=FILE appends the evidence of every fitted hypothesis with its truth
// label (see AppendFeatures; tools/fit_evidence_weights.py fits the evidence score to it);
// TEACHSIM_RECOGNIZE_ABLATION runs the recognizer with options changed, several separated by
// commas (see ApplyAblation: no-support, plane-only, no-polish, no-refit, rules-only, index-N, support-N,
// contourreserve-N (placements behind a contour kept past support-N),
// contrast-X, score-X, evidence-X, accept-X, below-MM, canny-X (both thresholds times X), cannylow-X,
// cannyhigh-X, eps-X, neighbours-N, queries-N, matched-X, supportmin-X, cornerridge-X (0: the thin-line
// corner filter off), cornerridgegrey-GREY, cornerridgecorners-N, seglen-PX, junction-PX,
// stepshare-X (0: the step rule off), stepgrey-X, stepoffset-PX, alternatives-N (0: no other models
// fitted at the candidates' places), ladder-MM (the model editor's ladder check's reach, mm; 0: off),
// laddermargin-X, ladderscore-X, laddercoverage-X, permodel-N (places per model among them), skip-any-claim
// (a corner's support hypotheses skipped once a candidate of any model matched its segments),
// matched-whole-edges (the matched share of the whole visible edges, the parts outside the image
// included) and matchedinimage-X (the share of the outline inside the image from which the matched
// share is of that part only), no-rescue and rescue-X (poses short of the matched share turned down
// unjudged; the evidence score that accepts them), no-occlusion (no second judgement of poses that
// accepted recognitions partly hide), hiddenmin-X, shownmin-X and hiddenscore-X (its limits), no-contours
// (no occluding contours: vision::RecognizerOptions::occlusion_contours), no-pole-ends (no strips
// between flanks that end inside a pose's image: contour_pole_ends; no-pole-tops: such strips end
// with their flanks, contour_pole_tops; no-support-pole-ends: not in the support-plane source,
// support_pole_ends), no-across-beside (no strips between a contour across
// a pose's image and one beside it: contour_across_beside), no-sides-bounded (a contour across hides
// its side past another across beyond it too: contour_sides_bounded), contourlen-PX, contourstep-GREY,
// contourcover-X and contourshown-X (their limits), barescore-X and barecover-X (the lower evidence score
// behind a contour where the hidden outline shows no edge, and how bare it must be; barescore-1: off),
// contourlowshown-X and contourlowscore-X (more than
// half hidden behind a contour: the share in view and the evidence score it needs; contourlowshown-0.5:
// off), refitrms-PX,
// refitcoverage-X, refitscore-X, refitinimage-X (the edge-point refit's limits; no-refit switches it off),
// balance-N (the non-maximum suppression's pairwise margin; 0: off), ownlead-N and rankshare-X (its second
// way to replace a rival; ownlead-0: off; withinshare-X: its rank share where the rival lies within the
// candidate and ends at an occluding contour inside its image, 0: off), inimagelead-X and tieshare-X (its
// third way, where neither own outline shows; inimagelead-0: off), centreslack-MM (how far beyond its
// supports' tops an off-table recognition's centre may lie). For teachsim, every scored object is put down to
// the stage that lost it (vision::ClassifyLoss), per visible-fraction bin. TEACHSIM_RECOGNIZE_RENDER_GAMMA=G
// renders the scenes as a camera of that gamma writes them (scene::CameraSpec::gamma; default 1, linear), and
// the recognizer is told it.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "linemod_peer.h"
#include "teachsim/base/bench_registry.h"
#include "teachsim/vision/evaluate.h"
#include "teachsim/vision/overlay.h"
#include "teachsim/vision/recognition_stages.h"
#include "teachsim/vision/recognizer.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {
namespace {

constexpr double kPi = 3.14159265358979323846;

double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

std::string EnvOr(const char* name, const std::string& fallback) {
  const char* value = std::getenv(name);
  return value != nullptr && *value != '\0' ? value : fallback;
}

std::string CacheDir() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return EnvOr("TEACHSIM_CACHE_DIR", ec ? std::string() : (exe.parent_path() / "bench-cache").string());
}

struct Case {
  std::string name;
  cv::Mat image;  // 8-bit monochrome, as the camera saw it
  scene::CameraSpec camera;
  std::optional<vision::FrameTruth> frame;
  std::vector<vision::TruthObject> truth;
  // Per truth object, the shorter models that would show in the image as it does
  // (vision::ShorterModelsInView); empty where none does, and for the dev set (its truth has no
  // pixels in view).
  std::vector<std::vector<std::string>> shorter_in_view;
};

struct DataSet {
  std::string name, description;
  std::vector<Case> cases;
};

// An error on one case, named on stderr; returns exit_status: 2 for a camera Camera::FromSpec
// refuses (the loaders check the same fields; this names the case should they ever part), 1 where
// the evaluation of what was found fails.
int ReportCaseError(const Case& c, const Status& status, int exit_status) {
  std::fprintf(stderr, "teachsim: error: %s: %s\n", c.name.c_str(), status.message().c_str());
  return exit_status;
}

Result<DataSet> LoadDevSet(const vision::TruthSet& truth, std::size_t max_cases) {
  DataSet set{"dev", "../shared/data/vision-dev: POV-Ray, 640x480, distortion, soft shadows, wood, noise", {}};
  for (const vision::TruthCase& c : truth.cases) {
    if (set.cases.size() >= max_cases) break;
    Case out;
    out.name = std::filesystem::path(c.image).filename().string();
    out.image = cv::imread(c.image, cv::IMREAD_GRAYSCALE);
    if (out.image.empty()) return Status::IoError(c.image + ": cannot read the image");
    out.camera = c.camera;
    out.camera.gamma = vision::kDevSetGamma;
    out.frame = c.frame;
    out.truth = c.objects;
    set.cases.push_back(std::move(out));
  }
  return set;
}

// --- Our own renders -------------------------------------------------------------------------------

RenderObject BoxRenderObject(const std::string& name, const std::string& model, const Eigen::Vector3d& size,
                             const geometry::Pose3& world_T_object, std::uint32_t seed) {
  auto box = geometry::ConvexPolyhedron::Box(size);
  TEACHSIM_CHECK(box.ok());
  RenderObject o;
  o.name = name;
  o.model = model;
  o.parts.push_back({std::make_shared<const geometry::ConvexPolyhedron>(std::move(*box)), {}});
  o.world_T_object = world_T_object;
  o.texture_seed = seed;
  return o;
}

// A dark vertical cylinder (24-sided prism) standing on the table.
RenderObject Occluder(const Eigen::Vector2d& xy, double radius_m, double height_m) {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 24; ++i) {
    const double a = 2 * kPi * i / 24;
    for (double z : {0.0, height_m}) points.emplace_back(radius_m * std::cos(a), radius_m * std::sin(a), z);
  }
  auto hull = geometry::ConvexPolyhedron::Hull(points);
  TEACHSIM_CHECK(hull.ok());
  RenderObject o;
  o.name = "occluder";
  o.model = "occluder";
  o.parts.push_back({std::make_shared<const geometry::ConvexPolyhedron>(std::move(*hull)), {}});
  o.world_T_object = geometry::Pose3::Translation({xy.x(), xy.y(), 0});
  o.material = Material::kFlat;
  o.albedo = 0.12;
  return o;
}

// The distance from p to an axis-aligned rectangle (zero inside).
double DistanceToRect(const Eigen::Vector2d& p, const Eigen::Vector2d& centre, const Eigen::Vector2d& half) {
  const Eigen::Vector2d d = ((p - centre).cwiseAbs() - half).cwiseMax(0.0);
  return d.norm();
}

// Random scenes in the work area: table, the dev set's frame at a random pose near the origin, one
// to six blocks of the library resting on a random face with a random yaw, not touching each other
// or the frame; in three images of four a dark cylinder (120-250 mm tall) stands close in front of
// one block, at a random sideways offset, so the visible fractions spread over all three bins. Cameras look
// at the work area from 0.45-0.75 m, 35-70 deg above the table, with varying focal length and radial
// distortion. Seeded: the same count gives the same images. The rendered set's description; `seeds` says
// which scenes ("seed 7", "seeds 7-31, 60 each").
std::string RenderedDescription(const std::string& seeds) {
  return "teachsim renderer, 640x480, random scenes (" + seeds + "), distortion, dark cylinder occluder";
}

Result<DataSet> MakeRenderedSet(const vision::TruthSet& library, int count, std::uint64_t seed,
                                double gamma) {
  DataSet set{"rendered", RenderedDescription("seed " + std::to_string(seed)), {}};
  std::vector<std::string> models;
  for (const auto& [name, size] : library.model_sizes_m) models.push_back(name);
  vision::FrameTruth frame_shape = library.cases.empty() ? vision::FrameTruth{} : *library.cases.front().frame;
  for (int index = 0; index < count; ++index) {
    std::mt19937_64 rng(seed * 1000003ull + static_cast<std::uint64_t>(index));
    std::uniform_real_distribution<double> u01(0, 1);
    auto uniform = [&](double a, double b) { return a + (b - a) * u01(rng); };
    // Camera.
    scene::CameraSpec camera;
    camera.name = "bench";
    camera.fx = uniform(720, 800);
    camera.fy = camera.fx * uniform(0.997, 1.003);
    camera.k1 = uniform(-0.25, 0.05);
    camera.k2 = uniform(0.0, 0.02);
    camera.gamma = gamma;
    const Eigen::Vector3d target(uniform(-0.06, 0.06), uniform(-0.06, 0.06), 0);
    const double distance = uniform(0.45, 0.75), elevation = uniform(35, 70) * kPi / 180, azimuth = uniform(0, 2 * kPi);
    const Eigen::Vector3d eye =
        target + distance * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                            std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
    const Eigen::Vector3d z = (target - eye).normalized();
    const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d world_R_camera;
    world_R_camera << x, z.cross(x), z;
    camera.world_T_camera = geometry::Pose3(Eigen::Quaterniond(world_R_camera), eye);
    TEACHSIM_ASSIGN_OR_RETURN(const vision::Camera cam, vision::Camera::FromSpec(camera));

    // Frame and table.
    vision::FrameTruth frame = frame_shape;
    const double frame_yaw = uniform(-0.3, 0.3);
    frame.world_T_frame = geometry::Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(frame_yaw, Eigen::Vector3d::UnitZ())),
                                          {uniform(-0.03, 0.03), uniform(-0.03, 0.03), 0});
    std::vector<RenderObject> objects = ObjectsFromScene(vision::FixedWorldScene(frame));
    const std::size_t first_block = objects.size();
    const geometry::Pose3 frame_T_world = frame.world_T_frame.Inverse();
    const Eigen::Vector2d inner_half = frame.inner_m / 2, outer_half = inner_half + Eigen::Vector2d::Constant(frame.wall_m);
    // Clearance of a disc from the walls: inside the opening or outside the outer rectangle.
    auto clear_of_frame = [&](const Eigen::Vector2d& p_world, double radius) {
      const Eigen::Vector3d p = frame_T_world * Eigen::Vector3d(p_world.x(), p_world.y(), 0);
      const Eigen::Vector2d q = p.head<2>().cwiseAbs();
      const bool inside = (q - inner_half).maxCoeff() < -radius;
      return inside || DistanceToRect(p.head<2>(), Eigen::Vector2d::Zero(), outer_half) > radius;
    };

    // Blocks.
    std::vector<std::pair<Eigen::Vector2d, double>> discs;  // footprints: centre, radius
    const int blocks = 1 + static_cast<int>(u01(rng) * 6);
    for (int b = 0, tries = 0; b < blocks && tries < 200; ++tries) {
      const std::string& model = models[static_cast<std::size_t>(u01(rng) * static_cast<double>(models.size())) % models.size()];
      const Eigen::Vector3d size = library.model_sizes_m.at(model);
      const int up = static_cast<int>(u01(rng) * 3) % 3;  // the object axis pointing up
      Eigen::Quaterniond rest = Eigen::Quaterniond::Identity();
      if (up == 0) rest = Eigen::AngleAxisd(-kPi / 2, Eigen::Vector3d::UnitY());
      if (up == 1) rest = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitX());
      const Eigen::Quaterniond rotation = Eigen::AngleAxisd(uniform(0, 2 * kPi), Eigen::Vector3d::UnitZ()) * rest;
      const double radius = 0.5 * std::hypot(size[(up + 1) % 3], size[(up + 2) % 3]);
      const Eigen::Vector2d xy(target.x() + uniform(-0.2, 0.2), target.y() + uniform(-0.16, 0.16));
      bool free = clear_of_frame(xy, radius + 0.003);
      for (const auto& [c, r] : discs) free = free && (c - xy).norm() > r + radius + 0.005;
      const geometry::Pose3 pose(rotation, {xy.x(), xy.y(), size[up] / 2});
      auto centre = cam.Project(pose.translation);
      free = free && centre.has_value() && centre->x() > 30 && centre->x() < camera.width - 30 &&
             centre->y() > 30 && centre->y() < camera.height - 30;
      if (!free) continue;
      discs.emplace_back(xy, radius);
      objects.push_back(BoxRenderObject(model + "_" + std::to_string(b), model, size, pose,
                                        static_cast<std::uint32_t>(rng())));
      ++b;
    }
    // Occluder: between the camera and one block, seen sideways by a random share of both widths.
    if (objects.size() > first_block && index % 4 != 3) {
      const std::size_t victim = first_block + static_cast<std::size_t>(u01(rng) * static_cast<double>(objects.size() - first_block)) % (objects.size() - first_block);
      const Eigen::Vector2d block_xy = objects[victim].world_T_object.translation.head<2>();
      const double block_r = discs[victim - first_block].second;
      const Eigen::Vector2d toward = (eye.head<2>() - block_xy).normalized();
      const Eigen::Vector2d side(-toward.y(), toward.x());
      for (int tries = 0; tries < 30; ++tries) {
        const double r = uniform(0.012, 0.025);
        const Eigen::Vector2d xy = block_xy + toward * uniform(block_r + r + 0.005, block_r + r + 0.05) +
                                   side * uniform(-0.9, 0.9) * (block_r + r);
        bool free = clear_of_frame(xy, r + 0.002);
        for (const auto& [c, rr] : discs) free = free && (c - xy).norm() > rr + r + 0.003;
        if (!free) continue;
        objects.push_back(Occluder(xy, r, uniform(0.12, 0.25)));
        break;
      }
    }

    TEACHSIM_ASSIGN_OR_RETURN(const Renderer renderer, Renderer::Create(cam, RenderOptions{}));
    const RenderResult rendered = renderer.Render(objects, static_cast<std::uint64_t>(index) + seed);
    Case out;
    out.name = "render_" + std::to_string(index);
    out.image = rendered.image;
    out.camera = camera;
    out.frame = frame;
    // The outline of each block's pixels answers as all of them would, at a fraction of the cost.
    const std::vector<std::vector<Eigen::Vector2d>> in_view = OutlinePixelsInView(rendered);
    for (std::size_t i = first_block; i < rendered.objects.size(); ++i) {
      const ObjectTruth& t = rendered.objects[i];
      if (t.model == "occluder") continue;
      out.truth.push_back({t.name, t.model, t.world_T_object, t.visible_fraction, t.visible_pixels});
      TEACHSIM_ASSIGN_OR_RETURN(
          std::vector<std::string> shorter,
          vision::ShorterModelsInView(library.model_sizes_m, t.model, t.world_T_object, cam, in_view[i]));
      out.shorter_in_view.push_back(std::move(shorter));
    }
    set.cases.push_back(std::move(out));
  }
  return set;
}

// --- The peer's pose, refined by the recognizer's least-squares fit ----------------------------------

// Matches the visible model edges predicted from camera_T_object to image lines (near and nearly
// parallel, overlapping), then Lowe's fit (vision::FitPoseToLines); a few rounds with shrinking
// match distance. nullopt when too few edges match.
std::optional<vision::FitResult> RefineWithFit(const Eigen::Vector3d& size, const Eigen::Matrix3d& K,
                                               const geometry::Pose3& camera_T_object,
                                               const std::vector<vision::ImageLine>& lines) {
  geometry::Pose3 pose = camera_T_object;
  std::optional<vision::FitResult> fit;
  for (double distance_px : {20.0, 8.0, 3.0}) {
    const Eigen::Vector3d eye_in_object = pose.Inverse().translation;
    const std::uint16_t visible = vision::VisibleBoxEdges(size, eye_in_object);
    std::vector<vision::LineMatch> matches;
    std::vector<int> edges_matched;
    for (int e = 0; e < 12; ++e) {
      if ((visible >> e & 1) == 0) continue;
      const Eigen::Vector3d pa = pose * vision::BoxVertex(size, vision::kBoxEdges[static_cast<std::size_t>(e)][0]);
      const Eigen::Vector3d pb = pose * vision::BoxVertex(size, vision::kBoxEdges[static_cast<std::size_t>(e)][1]);
      if (pa.z() <= 0.01 || pb.z() <= 0.01) continue;
      const Eigen::Vector2d a = (K * pa).hnormalized(), b = (K * pb).hnormalized();
      const Eigen::Vector2d dir = (b - a).normalized();
      const Eigen::Vector2d normal(-dir.y(), dir.x());
      const double length = (b - a).norm();
      bool any = false;
      for (const vision::ImageLine& line : lines) {
        const Eigen::Vector2d ld = (line.b - line.a).normalized();
        if (std::abs(ld.dot(dir)) < std::cos(8 * kPi / 180)) continue;
        if (std::abs((line.a - a).dot(normal)) > distance_px || std::abs((line.b - a).dot(normal)) > distance_px) continue;
        const double s0 = (line.a - a).dot(dir), s1 = (line.b - a).dot(dir);
        if (std::max(s0, s1) < 0 || std::min(s0, s1) > length) continue;
        matches.push_back({e, line.a, line.b});
        any = true;
      }
      if (any) edges_matched.push_back(e);
    }
    if (edges_matched.size() < 3) return fit;
    vision::FitResult next = vision::FitPoseToLines(size, K, pose, matches, 10, 1.5);
    if (!next.camera_T_object.IsValid() || next.camera_T_object.translation.z() <= 0) return fit;
    pose = next.camera_T_object;
    fit = next;
  }
  return fit;
}

// TEACHSIM_RECOGNIZE_DUMP=DIR: each image with a missed block or a false detection (every image with
// TEACHSIM_RECOGNIZE_DUMP_ALL=1), as DIR/NAME.png (a render's NAME holds its seed's folder:
// DIR/seed8/render_13.png)
// with the detected segments (yellow), the truth's visible edges (green), found recognitions (blue)
// and false ones (red), its Canny edges as DIR/NAME.edges.png, and each missed block close up
// (below).
void DumpCase(const std::string& dir, const Case& c, const vision::Camera& camera,
              const std::map<std::string, Eigen::Vector3d>& sizes, const vision::LineDetection& detection,
              const std::vector<vision::Recognition>& objects, const vision::ImageEvaluation& evaluation,
              const std::vector<vision::ImageCorner>& corners) {
  bool interesting = evaluation.false_positives > 0 || std::getenv("TEACHSIM_RECOGNIZE_DUMP_ALL") != nullptr;
  for (const vision::ObjectOutcome& o : evaluation.objects) interesting = interesting || o.detection < 0;
  if (!interesting) return;
  cv::Mat out;
  cv::cvtColor(c.image, out, cv::COLOR_GRAY2BGR);
  // A box's visible edges into `image`, through the lens; `at` maps an image pixel to image's.
  const auto identity = [](const Eigen::Vector2d& p) { return cv::Point2d(p.x(), p.y()); };
  auto draw_into = [&](cv::Mat& image, const auto& at, const std::string& model,
                       const geometry::Pose3& world_T_object, const cv::Scalar& colour) {
    for (const std::vector<Eigen::Vector2d>& line :
         vision::BoxOutlineInImage(sizes.at(model), camera, camera.camera_T_world() * world_T_object)) {
      for (std::size_t k = 1; k < line.size(); ++k)
        cv::line(image, at(line[k - 1]), at(line[k]), colour, 1, cv::LINE_AA);
    }
  };
  auto draw = [&](const std::string& model, const geometry::Pose3& world_T_object, const cv::Scalar& colour) {
    draw_into(out, identity, model, world_T_object, colour);
  };
  for (const vision::TruthObject& t : c.truth) draw(t.model, t.world_T_object, cv::Scalar(0, 200, 0));
  for (std::size_t d = 0; d < objects.size(); ++d) {
    const bool fp = evaluation.detection_truth[d] == -1;
    draw(objects[d].model, objects[d].world_T_object, fp ? cv::Scalar(0, 0, 255) : cv::Scalar(255, 128, 0));
    auto p = camera.Project(objects[d].world_T_object.translation);
    if (p && fp)
      cv::putText(out, objects[d].model, cv::Point2d(p->x(), p->y()), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                  cv::Scalar(0, 0, 255));
  }
  // The detected segments (undistorted pixels) through the lens, in yellow over the outlines.
  const Eigen::Matrix3d K_inverse = camera.K().inverse();
  auto to_image = [&](const Eigen::Vector2d& undistorted) {
    const Eigen::Vector2d px = camera.NormalizedToPixel((K_inverse * undistorted.homogeneous()).hnormalized());
    return cv::Point2d(px.x(), px.y());
  };
  for (const vision::ImageLine& l : detection.lines) {
    cv::line(out, to_image(l.a), to_image(l.b), cv::Scalar(0, 220, 255), 1, cv::LINE_AA);
  }
  const std::string stem = dir + "/" + (c.name.size() > 4 && c.name.substr(c.name.size() - 4) == ".png"
                                             ? c.name.substr(0, c.name.size() - 4)
                                             : c.name);
  // A render's name holds its seed's folder ("seed8/render_13"): made here.
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(stem).parent_path(), ec);
  if (ec) {
    std::fprintf(stderr, "teachsim: warning: cannot create the dump folder for %s: %s\n", stem.c_str(),
                 ec.message().c_str());
    return;
  }
  cv::imwrite(stem + ".png", out);
  cv::imwrite(stem + ".edges.png", detection.edge_map.edges > 0);  // both kinds of edge pixel, 255
  // Each missed block close up (3x, nearest neighbour): the segments, the support-plane source's
  // corners with their arms (magenta) and the truth's visible edges, as DIR/NAME.MODEL.png.
  constexpr int kZoom = 3;
  for (const vision::ObjectOutcome& o : evaluation.objects) {
    if (o.detection >= 0 || o.truth < 0) continue;
    const vision::TruthObject& t = c.truth[static_cast<std::size_t>(o.truth)];
    const auto centre = camera.Project(t.world_T_object.translation);
    if (!centre) continue;
    const double depth_m = std::max(0.05, (camera.camera_T_world() * t.world_T_object.translation).z());
    const int half = static_cast<int>(0.7 * sizes.at(t.model).norm() * camera.intrinsics().fx / depth_m) + 10;
    const cv::Rect roi = cv::Rect(static_cast<int>(centre->x()) - half, static_cast<int>(centre->y()) - half,
                                  2 * half, 2 * half) &
                         cv::Rect(0, 0, out.cols, out.rows);
    if (roi.width < 8 || roi.height < 8) continue;
    cv::Mat grey, close;
    cv::cvtColor(c.image(roi), grey, cv::COLOR_GRAY2BGR);
    cv::resize(grey, close, cv::Size(), kZoom, kZoom, cv::INTER_NEAREST);
    auto close_up = [&](const Eigen::Vector2d& p) {
      return cv::Point2d((p.x() - roi.x + 0.5) * kZoom - 0.5, (p.y() - roi.y + 0.5) * kZoom - 0.5);
    };
    auto zoomed = [&](const Eigen::Vector2d& undistorted) {
      const cv::Point2d p = to_image(undistorted);
      return close_up(Eigen::Vector2d(p.x, p.y));
    };
    draw_into(close, close_up, t.model, t.world_T_object, cv::Scalar(0, 200, 0));
    for (const vision::ImageLine& l : detection.lines) {
      cv::line(close, zoomed(l.a), zoomed(l.b), cv::Scalar(0, 220, 255), 1, cv::LINE_AA);
    }
    for (const vision::ImageCorner& k : corners) {
      for (const Eigen::Vector2d& arm : k.arm_end)
        cv::line(close, zoomed(k.point), zoomed(arm), cv::Scalar(255, 0, 255), 1);
      cv::circle(close, zoomed(k.point), 4, cv::Scalar(255, 0, 255), 1);
    }
    cv::imwrite(stem + "." + t.model + ".png", close);
  }
}

const char* OutcomeName(vision::RecognitionTrace::Outcome outcome) {
  using Outcome = vision::RecognitionTrace::Outcome;
  switch (outcome) {
    case Outcome::kFitFailed:
      return "fit_failed";
    case Outcome::kMatchedFraction:
      return "matched_fraction";
    case Outcome::kReprojection:
      return "reprojection";
    case Outcome::kSupport:
      return "support";
    case Outcome::kEvidence:
      return "evidence";
    case Outcome::kImplausible:
      return "implausible";
    case Outcome::kCandidate:
      return "candidate";
  }
  return "?";
}

// TEACHSIM_RECOGNIZE_FEATURES=FILE: appends one row per fitted hypothesis (not failed) with the
// evidence at its fitted pose (vision::EvaluatePose) and whether it lies on a true block of its
// model (mean distance of the projected vertices to the truth's nearest ones < 3 px): the data for
// choosing the verification rule.
void AppendFeatures(const std::string& path, const std::string& set_name, const Case& c,
                    const vision::Camera& camera, const vision::ModelLibrary& library,
                    const vision::LineDetection& detection, const vision::FixedEdgeMap& fixed,
                    const vision::RecognizerOptions& options, const vision::RecognitionTrace& trace) {
  std::FILE* f = std::fopen(path.c_str(), "a");
  if (f == nullptr) return;
  const Eigen::Matrix3d K = camera.K();
  auto vertices_px = [&](const Eigen::Vector3d& size, const geometry::Pose3& camera_T_object,
                         std::array<Eigen::Vector2d, 8>* px) {
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d p = camera_T_object * vision::BoxVertex(size, i);
      if (p.z() <= 1e-3) return false;
      (*px)[static_cast<std::size_t>(i)] = (K * p).hnormalized();
    }
    return true;
  };
  for (const vision::RecognitionTrace::Fitted& fitted : trace.fitted) {
    if (fitted.outcome == vision::RecognitionTrace::Outcome::kFitFailed) continue;
    const vision::Model& model = library.models[static_cast<std::size_t>(fitted.model)];
    std::array<Eigen::Vector2d, 8> px;
    if (!vertices_px(model.box_size_m, fitted.camera_T_object, &px)) continue;
    double best = 1e9, visible = 0;
    for (const vision::TruthObject& t : c.truth) {
      if (t.model != model.name) continue;
      std::array<Eigen::Vector2d, 8> tp;
      if (!vertices_px(model.box_size_m, camera.camera_T_world() * t.world_T_object, &tp)) continue;
      double sum = 0;
      for (const Eigen::Vector2d& q : tp) {
        double nearest = 1e9;
        for (const Eigen::Vector2d& p : px) nearest = std::min(nearest, (p - q).norm());
        sum += nearest;
      }
      if (sum / 8 < best) best = sum / 8, visible = t.visible_fraction;
    }
    const vision::PoseEvidence e =
        vision::EvaluatePose(model, camera, fitted.camera_T_object, detection, options, &fixed);
    const Eigen::Vector2d centre = (K * fitted.camera_T_object.translation).hnormalized();
    std::fprintf(
        f,
        "%s\t%s\t%s\t%d\t%s\t%d\t%.2f\t%.3f\t%.4f\t%.4f\t%.4f\t%.1f\t%.3f\t%.3f\t%d\t%d\t%d\t%.4f\t%.4f\t%.4f"
        "\t%.1f\t%.4f\t%.0f\t%.0f\t%.4f\t%.1f\t%.1f\t%.1f\n",
        set_name.c_str(), c.name.c_str(), model.name.c_str(), fitted.group_kind, OutcomeName(fitted.outcome),
        fitted.accepted ? 1 : 0, best, visible, e.matched_fraction, e.support_fraction, e.coverage,
        e.supported_px, e.rms_px, e.rms_closest_px, e.matches, e.continued_ends, e.long_continued_ends,
        e.fixed_share, e.free_support_fraction, e.free_coverage, e.free_supported_px, e.polarity,
        e.edges_supported, e.edges_visible, vision::EvidenceScore(e), e.step_supported_px, centre.x(),
        centre.y());
  }
  std::fclose(f);
}

// TEACHSIM_RECOGNIZE_ABLATION: the recognizer with one option changed. "no-support" (the index
// alone), "plane-only" (support hypotheses fitted on their plane without the 6-DOF refinement),
// "rules-only" (verification without the evidence score), or NAME-VALUE: index-N (at most N index
// hypotheses), support-N (at most N support hypotheses), contourreserve-N (placements behind an
// occluding contour kept past that cap), contrast-X (min_edge_contrast), score-X
// (min_score), evidence-X (min_evidence_score), accept-X (accept_evidence_score), below-MM (culling
// depth under the table, mm). What is wrong with the value, or nothing.
std::optional<std::string> ApplyAblation(const std::string& a, vision::RecognizerOptions* o) {
  if (a == "no-support") return o->support_hypotheses = false, std::nullopt;
  if (a == "plane-only") return o->support_refine_6dof = false, std::nullopt;
  if (a == "no-polish") return o->polish_pose = false, std::nullopt;
  if (a == "no-refit") return o->edge_point_refit = false, std::nullopt;
  if (a == "skip-any-claim") return o->skip_corners_claimed_by_any_model = true, std::nullopt;
  if (a == "matched-whole-edges") return o->matched_share_in_image = false, std::nullopt;
  if (a == "no-occlusion") return o->occlusion_reverify = false, std::nullopt;
  if (a == "no-contours") return o->occlusion_contours = false, std::nullopt;
  if (a == "no-pole-ends") return o->contour_pole_ends = false, std::nullopt;
  if (a == "no-pole-tops") return o->contour_pole_tops = false, std::nullopt;
  if (a == "no-across-beside") return o->contour_across_beside = false, std::nullopt;
  if (a == "no-sides-bounded") return o->contour_sides_bounded = false, std::nullopt;
  if (a == "no-support-pole-ends") return o->support_pole_ends = false, std::nullopt;
  if (a == "no-hidden-corners") return o->support_hidden_corners = false, std::nullopt;
  if (a == "no-rescue") return o->matched_share_rescue = false, std::nullopt;
  if (a == "rules-only") return o->min_evidence_score = 0, o->accept_evidence_score = 1, std::nullopt;
  // NAME-VALUE at the first dash (no NAME below holds one), so that a negative VALUE ("tightfit--1")
  // reaches Validate and its message.
  const std::size_t dash = a.find('-');
  const std::string name = dash == std::string::npos ? a : a.substr(0, dash);
  const std::string text = dash == std::string::npos ? "" : a.substr(dash + 1);
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  const bool number = !text.empty() && end == text.c_str() + text.size() && std::isfinite(value);
  const std::map<std::string, std::function<void(double)>> setters = {
      {"index", [o](double v) { o->max_hypotheses = static_cast<int>(v); }},
      {"support", [o](double v) { o->max_support_hypotheses = static_cast<int>(v); }},
      {"contourreserve", [o](double v) { o->support_contour_reserve = static_cast<int>(v); }},
      {"contrast", [o](double v) { o->min_edge_contrast = v; }},
      {"score", [o](double v) { o->min_score = v; }},
      {"evidence", [o](double v) { o->min_evidence_score = v; }},
      {"accept", [o](double v) { o->accept_evidence_score = v; }},
      {"below", [o](double v) { o->below_table_tolerance_m = v * 1e-3; }},
      {"canny", [o](double v) { o->canny_low *= v, o->canny_high *= v; }},
      {"matched", [o](double v) { o->min_matched_edge_fraction = v; }},
      {"queries", [o](double v) { o->max_index_queries = static_cast<int>(v); }},
      {"seglen", [o](double v) { o->min_segment_length_px = v; }},
      {"junction", [o](double v) { o->junction_gap_px = v; }},
      {"hcreach", [o](double v) { o->hidden_corner_reach_px = v; }},
      {"hcgap", [o](double v) { o->hidden_corner_max_gap_px = v; }},
      {"supportmin", [o](double v) { o->support_min_score = v; }},
      {"cornerridge", [o](double v) { o->support_corner_ridge_share = v; }},
      {"cornerridgegrey", [o](double v) { o->support_corner_ridge_grey = v; }},
      {"cornerridgecorners", [o](double v) { o->support_corner_ridge_min_corners = static_cast<int>(v); }},
      {"eps", [o](double v) { o->index_search_eps = v; }},
      {"neighbours", [o](double v) { o->neighbours = static_cast<int>(v); }},
      {"cannylow", [o](double v) { o->canny_low *= v; }},
      {"cannyhigh", [o](double v) { o->canny_high *= v; }},
      {"stepshare", [o](double v) { o->min_step_share = v; }},
      {"stepgrey", [o](double v) { o->min_step_grey = v; }},
      {"stepoffset", [o](double v) { o->step_offset_px = v; }},
      {"alternatives", [o](double v) { o->max_alternative_fits = static_cast<int>(v); }},
      {"permodel", [o](double v) { o->alternatives_per_model = static_cast<int>(v); }},
      {"matchedinimage", [o](double v) { o->matched_share_min_in_image = v; }},
      {"hiddenmin", [o](double v) { o->occlusion_min_hidden_share = v; }},
      {"shownmin", [o](double v) { o->occlusion_min_shown_share = v; }},
      {"hiddenscore", [o](double v) { o->occlusion_min_evidence_score = v; }},
      {"contourlen", [o](double v) { o->contour_min_length_px = v; }},
      {"contourcover", [o](double v) { o->contour_max_hidden_coverage = v; }},
      {"barescore", [o](double v) { o->contour_bare_min_evidence_score = v; }},
      {"barecover", [o](double v) { o->contour_bare_max_coverage = v; }},
      {"contourstep", [o](double v) { o->contour_min_step_grey = v; }},
      {"contourshown", [o](double v) { o->contour_min_shown_share = v; }},
      {"contourlowshown", [o](double v) { o->contour_low_shown_share = v; }},
      {"contourlowscore", [o](double v) { o->contour_low_shown_score = v; }},
      {"rescue", [o](double v) { o->matched_share_rescue_score = v; }},
      {"ladder", [o](double v) { o->ladder_search_m = v / 1000; }},
      {"laddermargin", [o](double v) { o->ladder_margin = v; }},
      {"ladderscore", [o](double v) { o->ladder_score_gain = v; }},
      {"laddercoverage", [o](double v) { o->ladder_max_coverage = v; }},

      {"refitrms", [o](double v) { o->refit_max_rms_px = v; }},
      {"refitcoverage", [o](double v) { o->refit_min_coverage = v; }},
      {"refitscore", [o](double v) { o->refit_accept_score = v; }},
      {"refitinimage", [o](double v) { o->refit_min_in_image = v; }},
      {"balance", [o](double v) { o->conflict_balance_margin = static_cast<int>(v); }},
      {"ownlead", [o](double v) { o->conflict_own_lead = static_cast<int>(v); }},
      {"rankshare", [o](double v) { o->conflict_rank_share = v; }},
      {"withinshare", [o](double v) { o->conflict_within_rank_share = v; }},
      {"inimagelead", [o](double v) { o->conflict_in_image_lead = v; }},
      {"tieshare", [o](double v) { o->conflict_tie_rank_share = v; }},
      {"ownbalance", [o](double v) { o->min_own_balance = static_cast<int>(v); }},
      {"centreslack", [o](double v) { o->support_centre_slack_m = v / 1000; }},
      {"tightfit", [o](double v) { o->support_tight_fit_shift_px = v; }},
      {"rmsratio", [o](double v) { o->conflict_rms_ratio = v; }},
      {"scorelead", [o](double v) { o->conflict_score_lead = v; }},
      {"baretable", [o](double v) { o->conflict_bare_table_share = v; }},
      {"barealone", [o](double v) { o->max_bare_table_share = v; }},
  };
  const auto setter = setters.find(name);
  if (setter == setters.end()) {
    return "unknown ablation (no-support, plane-only, no-polish, no-refit, skip-any-claim, "
           "matched-whole-edges, no-occlusion, no-contours, no-pole-ends, no-pole-tops, no-across-beside, "
           "no-sides-bounded, no-support-pole-ends, no-rescue, "
           "rescue-X, "
           "rules-only, index-N, "
           "support-N, contourreserve-N, "
           "contrast-X, "
           "score-X, evidence-X, accept-X, below-MM, canny-X, cannylow-X, cannyhigh-X, eps-X, "
           "neighbours-N, queries-N, matched-X, supportmin-X, cornerridge-X, cornerridgegrey-GREY, "
           "cornerridgecorners-N, seglen-PX, junction-PX, stepshare-X, "
           "stepgrey-X, stepoffset-PX, alternatives-N, permodel-N, matchedinimage-X, refitrms-PX, "
           "refitcoverage-X, refitscore-X, contourlen-PX, contourcover-X, barescore-X, barecover-X, "
           "contourstep-GREY, "
           "contourshown-X, "
           "contourlowshown-X, contourlowscore-X, ladder-MM, laddermargin-X, ladderscore-X, "
           "laddercoverage-X, "
           "refitinimage-X, "
           "balance-N, ownlead-N, rankshare-X, withinshare-X, inimagelead-X, tieshare-X, ownbalance-N, "
           "centreslack-MM, tightfit-PX, rmsratio-X, scorelead-X, baretable-X, barealone-X)";
  }
  if (!number) return "'" + text + "' after '" + name + "-' is not a number";
  setter->second(value);
  if (Status s = o->Validate(); !s.ok()) return s.message();
  return std::nullopt;
}

// --- Arguments ---------------------------------------------------------------------------------------

// `bench recognize`'s own arguments (after the common --json and --quick).
struct RecognizeArgs {
  // The render seeds, inclusive. 7 is the set the recognizer's thresholds were chosen on; 8 and up are
  // held out to check that they generalise.
  std::uint64_t first_seed = 7, last_seed = 7;
  bool no_peer = false;
};

// --render-seeds N or A-B (default TEACHSIM_RECOGNIZE_RENDER_SEED, else 7) and --no-peer (or
// TEACHSIM_RECOGNIZE_NO_PEER); anything else is an error that names it.
Result<RecognizeArgs> ParseRecognizeArgs(const std::vector<std::string>& extra) {
  TEACHSIM_ASSIGN_OR_RETURN(const BenchOptions given,
                            ParseBenchOptions("recognize", extra, {"--render-seeds"}, {"--no-peer"}));
  RecognizeArgs out;
  out.no_peer = given.flags.count("--no-peer") > 0 || std::getenv("TEACHSIM_RECOGNIZE_NO_PEER") != nullptr;
  const auto flag = given.values.find("--render-seeds");
  const std::string what = flag != given.values.end() ? "--render-seeds" : "TEACHSIM_RECOGNIZE_RENDER_SEED";
  const std::string seeds =
      flag != given.values.end() ? flag->second : EnvOr("TEACHSIM_RECOGNIZE_RENDER_SEED", "7");
  constexpr long long kMaxSeed = 1000000000;
  auto seed = [&](const std::string& text) -> Result<long long> {
    Result<long long> value = ParseBenchCount(what, text, 0, kMaxSeed);
    if (value.ok()) return value;
    return Status::InvalidInput(what + ": '" + seeds +
                                "' is not a seed N or a range A-B (whole numbers from 0 to " +
                                std::to_string(kMaxSeed) + ")");
  };
  const std::size_t dash = seeds.find('-');
  TEACHSIM_ASSIGN_OR_RETURN(const long long first, seed(seeds.substr(0, dash)));
  TEACHSIM_ASSIGN_OR_RETURN(const long long last,
                            seed(dash == std::string::npos ? seeds : seeds.substr(dash + 1)));
  if (last < first) return Status::InvalidInput(what + ": '" + seeds + "' ends before it starts");
  out.first_seed = static_cast<std::uint64_t>(first);
  out.last_seed = static_cast<std::uint64_t>(last);
  return out;
}

// --- Methods and the run -----------------------------------------------------------------------------

const char* const kMethods[] = {"teachsim", "teachsim_raw_pose", "linemod", "linemod_fit"};
constexpr int kMethodCount = 4;
constexpr int kFirstPeer = 2;  // the methods from here on are the peer's
// A block lost at verification counts as cut by the image border when this share of its visible
// outline or more lies outside the image (SecondLook::outside_image; the share the occlusion pass
// asks hidden, RecognizerOptions::occlusion_min_hidden_share).
constexpr double kBorderCutShare = 0.1;

struct DataSetResult {
  vision::SummaryBuilder builders[kMethodCount];
  // Each peer (linemod, linemod_fit) against teachsim on the blocks both found; [0] and [1] unused.
  vision::PairedBuilder paired[kMethodCount];
  int errors[kMethodCount] = {0, 0, 0, 0};
  int bins[3] = {0, 0, 0};
  int losses[3][vision::kLossStages] = {};  // teachsim: per bin, objects by the stage that lost them
  int losses_found[3][vision::kLossStages] = {};  // ... of them those the evaluation counts as found
  // teachsim: per bin, the objects missed at verification by the occlusion pass's second look
  int second_looks[3][vision::kSecondLookVerdicts] = {};
  // ... of them those cut by the image border (kBorderCutShare of the outline or more outside it)
  int second_looks_at_border[3][vision::kSecondLookVerdicts] = {};
  // teachsim's false positives by where they stand (vision::FalsePositiveHosts): at a missed block, by
  // the stage that lost it; at a found block; at a block too little visible to be scored; at none.
  int false_at_missed[vision::kLossStages] = {};
  int false_at_found = 0, false_at_unscored = 0, false_elsewhere = 0;
  // Scored objects per bin whose view a shorter model explains (Case::shorter_in_view), and per
  // method those of them found and those of the rest (the identifiable) found.
  int explained[3] = {0, 0, 0};
  int explained_found[kMethodCount][3] = {};
  int identifiable_found[kMethodCount][3] = {};
  // teachsim's false detections that are a shorter model explaining the block they stand at.
  int false_as_shorter = 0;
};

// Whether truth object i of `c` is one whose view a shorter model explains; with `model`, whether
// that model is one of them.
bool ExplainedByShorter(const Case& c, std::size_t i, const std::string* model = nullptr) {
  if (i >= c.shorter_in_view.size() || c.shorter_in_view[i].empty()) return false;
  return model == nullptr || std::find(c.shorter_in_view[i].begin(), c.shorter_in_view[i].end(), *model) !=
                                 c.shorter_in_view[i].end();
}

vision::Detection FromRecognition(const vision::Recognition& r, bool raw) {
  return {r.model, raw ? r.raw_world_T_object : r.world_T_object, r.score, r.reprojection_rms_px};
}

int Run(const BenchArgs& args) {
  cv::setNumThreads(1);  // one core for both methods
  const Result<RecognizeArgs> parsed = ParseRecognizeArgs(args.extra);
  if (!parsed.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", parsed.status().message().c_str());
    return 2;
  }
  const RecognizeArgs& options = *parsed;
  const int render_sets = static_cast<int>(options.last_seed - options.first_seed + 1);
  const std::string shared = EnvOr("TEACHSIM_SHARED", EnvOr("TEACHSIM_HOME", TEACHSIM_BENCH_SOURCE_DIR) + "/../shared");
  const std::string truth_path = shared + "/data/vision-dev/truth.json";
  auto truth = vision::LoadTruthSet(truth_path);
  if (!truth.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", truth.status().message().c_str());
    return 2;
  }
  const std::string cache_dir = CacheDir();
  vision::ModelLibrary library;
  for (const auto& [name, size] : truth->model_sizes_m) library.models.push_back({name, size});

  // Set-up: the recognizer's index and the peer's templates (cached on disk).
  auto t0 = std::chrono::steady_clock::now();
  vision::RecognizerOptions recognizer_options;
  if (const char* ablation = std::getenv("TEACHSIM_RECOGNIZE_ABLATION"); ablation != nullptr) {
    // Several, separated by commas, apply in order.
    std::string rest = ablation;
    for (std::size_t start = 0;;) {
      const std::size_t comma = rest.find(',', start);
      const std::string one = rest.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      if (const std::optional<std::string> error = ApplyAblation(one, &recognizer_options)) {
        std::fprintf(stderr, "teachsim: error: TEACHSIM_RECOGNIZE_ABLATION=%s: %s: %s\n", ablation, one.c_str(),
                     error->c_str());
        return 2;
      }
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  auto recognizer = vision::Recognizer::Create(library, recognizer_options, cache_dir);
  const double recognizer_setup_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!recognizer.ok()) {
    std::fprintf(stderr, "teachsim: error: recognizer: %s\n", recognizer.status().message().c_str());
    return 1;
  }
  LinemodOptions linemod_options;
  if (args.quick) {
    linemod_options.view_step_deg = 25;
    linemod_options.in_plane_step_deg = 30;
    linemod_options.distances_m = {0.42, 0.55, 0.72, 0.91};
  }
  // Without the peer (--no-peer), its templates are not even made.
  std::optional<LinemodPeer> peer;
  if (!options.no_peer) {
    auto created = LinemodPeer::Create(truth->model_sizes_m, linemod_options, cache_dir);
    if (!created.ok()) {
      std::fprintf(stderr, "teachsim: error: LINE-MOD: %s\n", created.status().message().c_str());
      return 1;
    }
    peer.emplace(std::move(*created));
  }
  const int method_count = options.no_peer ? 2 : kMethodCount;  // teachsim's two first

  const double render_gamma = std::atof(EnvOr("TEACHSIM_RECOGNIZE_RENDER_GAMMA", "1").c_str());
  if (!(render_gamma >= vision::Camera::kMinGamma && render_gamma <= vision::Camera::kMaxGamma)) {
    std::fprintf(stderr, "teachsim: error: TEACHSIM_RECOGNIZE_RENDER_GAMMA must be in [%g, %g]\n",
                 vision::Camera::kMinGamma, vision::Camera::kMaxGamma);
    return 2;
  }
  auto dev = LoadDevSet(*truth, args.quick ? 3 : truth->cases.size());
  if (!dev.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", dev.status().message().c_str());
    return 2;
  }

  // Two data sets: the dev set, and the renders of every seed pooled (made and measured one seed's
  // set at a time, so that many seeds need no more memory than one).
  struct SetInfo {
    std::string name, description;
    int images = 0;
  };
  std::vector<SetInfo> sets = {{dev->name, dev->description, 0}, {"rendered", "", 0}};
  const vision::MatchOptions match;
  std::vector<DataSetResult> results(sets.size());
  double render_s = 0;
  // Measures every method on `cases` into results[s]; 0, or the exit status of an error.
  auto measure = [&](std::size_t s, const std::vector<Case>& cases) -> int {
    DataSetResult& result = results[s];
    sets[s].images += static_cast<int>(cases.size());
    for (const Case& c : cases) {
      for (std::size_t i = 0; i < c.truth.size(); ++i) {
        const vision::TruthObject& t = c.truth[i];
        if (t.visible_fraction >= match.min_visible_fraction && t.visible_pixels > 0) {
          ++result.bins[static_cast<int>(vision::BinOf(t.visible_fraction))];
          if (ExplainedByShorter(c, i))
            ++result.explained[static_cast<int>(vision::BinOf(t.visible_fraction))];
        }
      }
      auto camera = vision::Camera::FromSpec(c.camera);
      if (!camera.ok()) return ReportCaseError(c, camera.status(), 2);
      const scene::Scene fixed_world = vision::FixedWorldScene(c.frame);
      const Eigen::Vector3d eye = c.camera.world_T_camera.translation;
      std::vector<vision::Detection> found[kMethodCount];
      double time_ms[kMethodCount] = {0, 0, 0, 0};
      bool failed[kMethodCount] = {false, false, false, false};

      double cpu = ThreadCpuMs();
      vision::RecognitionTrace trace;
      auto recognized = recognizer->Recognize(c.image, *camera, &fixed_world, &trace);
      time_ms[0] = time_ms[1] = ThreadCpuMs() - cpu;
      // Its time as the summaries take it (both of its methods): the recognizer's own clock per
      // stage, and its counts.
      vision::ImageTime recognized_time{time_ms[0], c.name, {}, {}};
      if (recognized.ok()) {
        for (const vision::Recognition& r : recognized->objects) {
          found[0].push_back(FromRecognition(r, false));
          found[1].push_back(FromRecognition(r, true));
        }
        for (const auto& [stage, ms] : recognized->timing_ms) recognized_time.stage_ms[stage] = ms;
        recognized_time.counts = {{"lines", trace.lines},
                                  {"groups", trace.groups},
                                  {"corners", trace.corners},
                                  {"support_hypotheses", trace.support_hypotheses},
                                  {"fitted", static_cast<int>(trace.fitted.size())}};
      } else {
        failed[0] = failed[1] = true;
      }

      if (recognized.ok() && std::getenv("TEACHSIM_RECOGNIZE_DEBUG") != nullptr) {
        std::fprintf(stderr, "%s: %d lines, %d groups, %d corners, %d support hypotheses, %zu fitted; ms:", c.name.c_str(),
                     trace.lines, trace.groups, trace.corners, trace.support_hypotheses, trace.fitted.size());
        for (const auto& [stage, ms] : recognized->timing_ms)
          std::fprintf(stderr, " %s %.1f", stage.c_str(), ms);
        std::fprintf(stderr, "\n");
      }
      if (recognized.ok()) {  // which stage lost each object (not timed)
        const vision::LineDetection detection =
            vision::DetectLinesAndEdges(c.image, *camera, recognizer->options());
        const std::vector<vision::Group> groups = vision::FindGroups(detection.lines, recognizer->options());
        auto evaluation =
            vision::EvaluateImage(c.truth, found[0], truth->model_sizes_m, eye, match, &*camera);
        if (evaluation.ok() && std::getenv("TEACHSIM_RECOGNIZE_DEBUG") != nullptr) {
          // The tilt of a pose: its most vertical axis against the world's vertical, deg.
          auto tilt_deg = [](const Eigen::Quaterniond& q) {
            return std::acos(std::min(1.0, q.toRotationMatrix().row(2).cwiseAbs().maxCoeff())) * 180 / kPi;
          };
          for (std::size_t d = 0; d < found[0].size(); ++d) {
            if (evaluation->detection_truth[d] != -1) continue;
            const vision::Recognition& r = recognized->objects[d];
            auto p = camera->Project(r.world_T_object.translation);
            double lowest = 1e9;
            for (int v = 0; v < 8; ++v) {
              lowest = std::min(
                  lowest, (r.world_T_object * vision::BoxVertex(truth->model_sizes_m.at(r.model), v)).z());
            }
            std::fprintf(stderr,
                         "%s false %s at (%.0f, %.0f) world (%.1f, %.1f, %.1f) mm, lowest point %.1f mm: "
                         "score %.3f, matched "
                         "%.2f, rms %.2f px\n",
                         c.name.c_str(), r.model.c_str(), p ? p->x() : -1, p ? p->y() : -1,
                         1000 * r.world_T_object.translation.x(), 1000 * r.world_T_object.translation.y(),
                         1000 * r.world_T_object.translation.z(), lowest * 1000, r.score,
                         r.matched_edge_fraction, r.reprojection_rms_px);
            // The nearest true block of the same model, if any: how far off this one is.
            auto away_m = [&](const vision::TruthObject& t) {
              return (t.world_T_object.translation - r.world_T_object.translation).norm();
            };
            const vision::TruthObject* nearest = nullptr;
            for (const vision::TruthObject& t : c.truth) {
              if (t.model == r.model && (nearest == nullptr || away_m(t) < away_m(*nearest))) nearest = &t;
            }
            if (nearest != nullptr) {
              std::fprintf(
                  stderr,
                  "    nearest true %s: %.1f mm away (raw pose %.1f mm), turned %.1f deg (tilt %.2f, truth's "
                  "%.2f)\n",
                  r.model.c_str(), 1000 * away_m(*nearest),
                  1000 * (nearest->world_T_object.translation - r.raw_world_T_object.translation).norm(),
                  vision::SymmetricRotationError(nearest->world_T_object.rotation, r.world_T_object.rotation,
                                                 vision::BoxSymmetries(truth->model_sizes_m.at(r.model))) *
                      180 / kPi,
                  tilt_deg(r.world_T_object.rotation), tilt_deg(nearest->world_T_object.rotation));
            }
            for (const std::string& a : r.adjustments) std::fprintf(stderr, "    editor: %s\n", a.c_str());
          }
          for (const vision::ObjectOutcome& o : evaluation->objects) {
            if (o.detection < 0) continue;
            const vision::TruthObject& t = c.truth[static_cast<std::size_t>(o.truth)];
            const vision::Recognition& r = recognized->objects[static_cast<std::size_t>(o.detection)];
            std::fprintf(
                stderr,
                "%s found %s %.2f: rotation %.2f deg (raw %.2f; tilt %.2f, truth's %.2f), across %.2f mm, "
                "along %.2f "
                "mm, rms %.2f px, score %.3f, matched %.2f, off truth %.2f px\n",
                c.name.c_str(), t.model.c_str(), t.visible_fraction, o.rotation_error_rad * 180 / kPi,
                vision::SymmetricRotationError(t.world_T_object.rotation, r.raw_world_T_object.rotation,
                                               vision::BoxSymmetries(truth->model_sizes_m.at(t.model))) *
                    180 / kPi,
                tilt_deg(r.world_T_object.rotation), tilt_deg(t.world_T_object.rotation),
                o.position_error.across_m * 1000, o.position_error.along_m * 1000, r.reprojection_rms_px,
                r.score, r.matched_edge_fraction, o.truth_projection_rms_px);
            // The editor's ladder check, when it moved the block.
            for (const std::string& a : r.adjustments) {
              if (a.find("along its side") != std::string::npos)
                std::fprintf(stderr, "    ladder: %s\n", a.c_str());
            }
            // A found block drawn well off its truth: its raw pose's figure, what the editor did, and
            // the evidence at the raw, edited and true poses.
            if (o.truth_projection_rms_px > 2) {
              std::fprintf(
                  stderr, "    raw pose off truth %.2f px\n",
                  vision::SymmetricProjectionRms(*camera, truth->model_sizes_m.at(t.model), t.world_T_object,
                                                 r.raw_world_T_object,
                                                 vision::BoxSymmetries(truth->model_sizes_m.at(t.model))));
              for (const std::string& a : r.adjustments) std::fprintf(stderr, "    editor: %s\n", a.c_str());
              const vision::Model& model =
                  *std::find_if(library.models.begin(), library.models.end(),
                                [&](const vision::Model& m) { return m.name == t.model; });
              auto score_at = [&](const geometry::Pose3& world_T_object) {
                const vision::PoseEvidence e =
                    vision::EvaluatePose(model, *camera, camera->camera_T_world() * world_T_object, detection,
                                         recognizer->options());
                std::fprintf(stderr, "score %.3f support %.2f coverage %.2f step %.0f px supported %.0f px",
                             vision::EvidenceScore(e), e.support_fraction, e.coverage, e.step_supported_px,
                             e.supported_px);
              };
              std::fprintf(stderr, "    evidence at the raw pose: ");
              score_at(r.raw_world_T_object);
              std::fprintf(stderr, "; at the edited pose: ");
              score_at(r.world_T_object);
              std::fprintf(stderr, "; at the truth: ");
              score_at(t.world_T_object);
              std::fprintf(stderr, "\n");
            }
          }
        }
        if (const char* features = std::getenv("TEACHSIM_RECOGNIZE_FEATURES"); features != nullptr) {
          AppendFeatures(features, s == 1 ? "render" : "dev", c, *camera, library, detection,
                         vision::ProjectFixedEdges(&fixed_world, *camera), recognizer->options(), trace);
        }
        if (const char* dump_dir = std::getenv("TEACHSIM_RECOGNIZE_DUMP");
            evaluation.ok() && dump_dir != nullptr && *dump_dir != '\0') {
          DumpCase(dump_dir, c, *camera, truth->model_sizes_m, detection, recognized->objects, *evaluation,
                   vision::FindCorners(detection.lines, recognizer->options()));
        }
        // Each truth object's outcome for its false positives: -1 unscored, -2 found, else the stage that
        // lost it.
        std::vector<int> outcome_of(c.truth.size(), -1);
        for (std::size_t i = 0; i < c.truth.size(); ++i) {
          const vision::TruthObject& t = c.truth[i];
          if (t.visible_fraction < match.min_visible_fraction || t.visible_pixels <= 0) continue;
          int model_index = 0;
          while (library.models[static_cast<std::size_t>(model_index)].name != t.model) ++model_index;
          const vision::StageLoss loss = vision::ClassifyLoss(
              library.models[static_cast<std::size_t>(model_index)], model_index, *camera,
              camera->camera_T_world() * t.world_T_object, detection, groups, trace);
          const int bin = static_cast<int>(vision::BinOf(t.visible_fraction));
          ++result.losses[bin][static_cast<int>(loss.stage)];
          bool was_found = false;
          if (evaluation.ok()) {
            for (const vision::ObjectOutcome& o : evaluation->objects) {
              was_found = was_found || (o.truth == static_cast<int>(i) && o.detection >= 0);
            }
          }
          if (was_found) ++result.losses_found[bin][static_cast<int>(loss.stage)];
          outcome_of[i] = was_found ? -2 : static_cast<int>(loss.stage);
          if (!was_found && loss.stage == vision::LossStage::kVerification) {
            const int verdict = static_cast<int>(loss.second_look.verdict);
            ++result.second_looks[bin][verdict];
            if (loss.second_look.outside_image >= kBorderCutShare)
              ++result.second_looks_at_border[bin][verdict];
          }
          if (std::getenv("TEACHSIM_RECOGNIZE_DEBUG") != nullptr && !was_found) {
            auto p = camera->Project(t.world_T_object.translation);
            std::fprintf(stderr,
                         "%s missed %s %.2f at (%.0f, %.0f): %s (%d of %d edges have lines; outcome %d; "
                         "size %.0f px, closest start %.1f px, end %.1f px)\n",
                         c.name.c_str(), t.model.c_str(), t.visible_fraction, p ? p->x() : -1, p ? p->y() : -1,
                         vision::LossStageName(loss.stage), loss.edges_with_lines, loss.visible_edges,
                         static_cast<int>(loss.verification), loss.extent_px, loss.best_start_px, loss.best_end_px);
            for (double d : loss.best_start_rounds_px) std::fprintf(stderr, "    round: %.1f px\n", d);
            if (loss.stage == vision::LossStage::kVerification) {
              // Where the pass judged the part in view: behind what, and its verdict there.
              const vision::RecognitionTrace::SecondLook& look = loss.second_look;
              std::fprintf(stderr, "    occlusion pass: %s", vision::SecondLookName(look.verdict));
              if (look.verdict >= vision::RecognitionTrace::SecondLook::Verdict::kRules) {
                std::fprintf(stderr, " (behind %s, %.0f %% hidden; outcome %d, score %.3f of %.3f asked)",
                             look.behind_contour ? "a contour" : "recognitions", 100 * look.hidden,
                             static_cast<int>(look.outcome), look.score, look.min_score);
              }
              if (look.outside_image > 0)
                std::fprintf(stderr, "; %.0f %% outside the image", 100 * look.outside_image);
              std::fprintf(stderr, "\n");
            }
            const vision::PoseEvidence at_truth =
                vision::EvaluatePose(library.models[static_cast<std::size_t>(model_index)], *camera,
                                     camera->camera_T_world() * t.world_T_object, detection, recognizer->options());
            std::fprintf(stderr, "    at the true pose: matched %.2f, support %.2f, coverage %.2f, rms %.2f px, %d matches\n",
                         at_truth.matched_fraction, at_truth.support_fraction, at_truth.coverage, at_truth.rms_px,
                         at_truth.matches);
          }
        }
        if (evaluation.ok()) {
          auto hosts = vision::FalsePositiveHosts(c.truth, found[0], truth->model_sizes_m, *evaluation);
          if (!hosts.ok()) return ReportCaseError(c, hosts.status(), 1);
          for (std::size_t d = 0; d < hosts->size(); ++d) {
            if (evaluation->detection_truth[d] != -1) continue;
            const int host = (*hosts)[d];
            if (host < 0) {
              ++result.false_elsewhere;
              continue;
            }
            if (ExplainedByShorter(c, static_cast<std::size_t>(host), &found[0][d].model))
              ++result.false_as_shorter;
            const int outcome = outcome_of[static_cast<std::size_t>(host)];
            if (outcome == -1)
              ++result.false_at_unscored;
            else if (outcome == -2)
              ++result.false_at_found;
            else
              ++result.false_at_missed[outcome];
          }
        }
      }

      // The peer (none with --no-peer).
      std::vector<LinemodDetection> matches;
      cpu = ThreadCpuMs();
      if (peer) matches = peer->Detect(c.image, *camera);
      time_ms[2] = ThreadCpuMs() - cpu;
      for (const LinemodDetection& m : matches) found[2].push_back(m.detection);
      if (std::getenv("TEACHSIM_RECOGNIZE_DEBUG") != nullptr) {
        for (const LinemodDetection& m : matches) {
          auto p = camera->Project(m.detection.world_T_object.translation);
          const vision::TruthObject* near = nullptr;
          double best = 1e9;
          for (const vision::TruthObject& t : c.truth) {
            auto q = camera->Project(t.world_T_object.translation);
            if (p && q && (*p - *q).norm() < best) {
              best = (*p - *q).norm();
              near = &t;
            }
          }
          double rot = -1;
          vision::PositionError e;
          if (near != nullptr) {
            rot = vision::SymmetricRotationError(near->world_T_object.rotation, m.detection.world_T_object.rotation,
                                                 vision::BoxSymmetries(truth->model_sizes_m.at(near->model))) * 180 / kPi;
            e = vision::SplitPositionError(near->world_T_object.translation, m.detection.world_T_object.translation, eye);
          }
          std::fprintf(stderr, "%s linemod %s %.2f at (%.0f, %.0f) z %.3f; nearest %s %.0f px, rot %.1f deg, across %.1f along %.1f mm\n",
                       c.name.c_str(), m.detection.model.c_str(), m.detection.score, p ? p->x() : -1, p ? p->y() : -1,
                       m.camera_T_object.translation.z(), near ? near->model.c_str() : "-", best, rot, e.across_m * 1e3,
                       e.along_m * 1e3);
        }
        for (const vision::TruthObject& t : c.truth) {
          auto p = camera->Project(t.world_T_object.translation);
          std::fprintf(stderr, "%s truth %s %.2f at (%.0f, %.0f) depth %.3f m, world (%.1f, %.1f, %.1f) mm\n",
                       c.name.c_str(), t.model.c_str(), t.visible_fraction, p ? p->x() : -1, p ? p->y() : -1,
                       (camera->camera_T_world() * t.world_T_object.translation).z(),
                       1000 * t.world_T_object.translation.x(), 1000 * t.world_T_object.translation.y(),
                       1000 * t.world_T_object.translation.z());
        }
      }
      // The same matches refined by the recognizer's fit: line detection and fitting are added to
      // LINE-MOD's time.
      cpu = ThreadCpuMs();
      const std::vector<vision::ImageLine> lines =
          peer ? vision::DetectLines(c.image, *camera, vision::RecognizerOptions{})
               : std::vector<vision::ImageLine>{};
      for (const LinemodDetection& m : matches) {
        const Eigen::Vector3d size = truth->model_sizes_m.at(m.detection.model);
        auto fit = RefineWithFit(size, camera->K(), m.camera_T_object, lines);
        // Verified as the recognizer verifies a fit: enough edges matched, small residuals.
        if (!fit.has_value() || fit->rms_px > recognizer->options().max_reprojection_rms_px) continue;
        vision::Detection d = m.detection;
        d.world_T_object = camera->world_T_camera() * fit->camera_T_object;
        d.reprojection_rms_px = fit->rms_px;
        found[3].push_back(d);
      }
      time_ms[3] = time_ms[2] + ThreadCpuMs() - cpu;

      std::optional<vision::ImageEvaluation> evaluations[kMethodCount];
      for (int m = 0; m < method_count; ++m) {
        if (failed[m]) {
          ++result.errors[m];
          continue;
        }
        auto evaluation =
            vision::EvaluateImage(c.truth, found[m], truth->model_sizes_m, eye, match, &*camera);
        if (!evaluation.ok()) return ReportCaseError(c, evaluation.status(), 1);
        result.builders[m].Add(*evaluation,
                               m <= 1 ? recognized_time : vision::ImageTime{time_ms[m], c.name, {}, {}});
        for (const vision::ObjectOutcome& o : evaluation->objects) {
          if (o.detection < 0) continue;
          const int bin = static_cast<int>(vision::BinOf(o.visible_fraction));
          if (ExplainedByShorter(c, static_cast<std::size_t>(o.truth)))
            ++result.explained_found[m][bin];
          else
            ++result.identifiable_found[m][bin];
        }
        evaluations[m] = std::move(*evaluation);
      }
      for (int m = kFirstPeer; m < method_count; ++m) {
        if (!evaluations[0] || !evaluations[m]) continue;
        if (const Status paired = result.paired[m].Add(*evaluations[0], *evaluations[m]); !paired.ok()) {
          std::fprintf(stderr, "teachsim: error: %s: %s\n", c.name.c_str(), paired.message().c_str());
          return 1;
        }
      }
    }
    return 0;
  };

  // Untimed runs of teachsim and LINE-MOD on the dev set's first image before any image is timed
  // (LINE-MOD + our fit reuses teachsim's line detector and fit, warmed with it). A process's first
  // recognitions page-fault the memory its heap takes from the system (kept from then on: main.cc's
  // mallopt): on our 2-core VM the line stage of the first image timed took 35-40 ms more, whichever
  // image it was, and after one warm-up run still about 4 ms more (case_000: 9.4-9.6 ms against
  // 5.0-5.6 after two). `teachsim up` pays this once.
  constexpr int kWarmupRuns = 2;
  constexpr const char* kWarmupRunsInWords = "twice";  // for the table
  json::Json warmup = json::Json::object();
  if (!dev->cases.empty()) {
    const Case& first = dev->cases.front();
    auto camera = vision::Camera::FromSpec(first.camera);
    if (!camera.ok()) return ReportCaseError(first, camera.status(), 2);
    const scene::Scene fixed_world = vision::FixedWorldScene(first.frame);
    json::Json teachsim_ms = json::Json::array(), linemod_ms = json::Json::array();
    bool recognized = true;
    for (int run = 0; run < kWarmupRuns; ++run) {
      double cpu = ThreadCpuMs();
      recognized = recognizer->Recognize(first.image, *camera, &fixed_world, nullptr).ok() && recognized;
      teachsim_ms.push_back(ThreadCpuMs() - cpu);
      if (peer) {
        cpu = ThreadCpuMs();
        (void)peer->Detect(first.image, *camera);
        linemod_ms.push_back(ThreadCpuMs() - cpu);
      }
    }
    warmup["image"] = first.name;
    warmup["teachsim_ms"] = teachsim_ms;
    warmup["teachsim_ok"] = recognized;
    if (peer) warmup["linemod_ms"] = linemod_ms;
  }
  if (const int status = measure(0, dev->cases); status != 0) return status;
  const auto started = std::chrono::steady_clock::now();  // of the renders
  const int per_seed = args.quick ? 3 : 60;               // images per render seed
  for (std::uint64_t seed = options.first_seed; seed <= options.last_seed; ++seed) {
    t0 = std::chrono::steady_clock::now();
    auto rendered = MakeRenderedSet(*truth, per_seed, seed, render_gamma);
    render_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!rendered.ok()) {
      std::fprintf(stderr, "teachsim: error: render seed %llu: %s\n", static_cast<unsigned long long>(seed),
                   rendered.status().message().c_str());
      return 1;
    }
    if (render_sets > 1) {
      // The images' names repeat from seed to seed: each is prefixed by its seed.
      for (Case& c : rendered->cases) c.name = "seed" + std::to_string(seed) + "/" + c.name;
    }
    sets[1].description = rendered->description;
    if (const int status = measure(1, rendered->cases); status != 0) return status;
    if (render_sets > 1) {
      const int done = static_cast<int>(seed - options.first_seed + 1);
      const double elapsed_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
      std::fprintf(stderr,
                   "bench recognize: render seed %llu measured (%d of %d, %.0f s, about %.0f s to go)\n",
                   static_cast<unsigned long long>(seed), done, render_sets, elapsed_s,
                   elapsed_s / done * (render_sets - done));
    }
  }
  if (render_sets > 1) {
    sets[1].description =
        RenderedDescription("seeds " + std::to_string(options.first_seed) + "-" +
                            std::to_string(options.last_seed) + ", " + std::to_string(per_seed) + " each");
  }

  // --- Report.
  json::Json data_sets = json::Json::array();
  for (std::size_t s = 0; s < sets.size(); ++s) {
    json::Json methods = json::Json::object();
    for (int m = 0; m < method_count; ++m) {
      json::Json summary = vision::SummaryToJson(results[s].builders[m].Build());
      summary["failed_images"] = results[s].errors[m];
      // A peer's pose figures beside teachsim's on the blocks both found.
      if (m >= kFirstPeer)
        summary["paired_with_teachsim"] =
            vision::PairedSummaryToJson(results[s].paired[m].Build(), "teachsim", "peer");
      // Recall apart from the blocks whose view a shorter model explains, and how many of those
      // were found all the same.
      json::Json identifiable = json::Json::object(), explained_found = json::Json::object();
      for (int b = 0; b < 3; ++b) {
        const char* bin = vision::BinName(static_cast<vision::VisibilityBin>(b));
        identifiable[bin] = vision::RecallToJson(results[s].bins[b] - results[s].explained[b],
                                                 results[s].identifiable_found[m][b]);
        explained_found[bin] = results[s].explained_found[m][b];
      }
      summary["recall_identifiable"] = identifiable;
      summary["found_of_explained_by_shorter"] = explained_found;
      methods[kMethods[m]] = summary;
    }
    json::Json losses = json::Json::object();
    for (int b = 0; b < 3; ++b) {
      json::Json per_stage = json::Json::object();
      for (int k = 0; k < vision::kLossStages; ++k) {
        per_stage[vision::LossStageName(static_cast<vision::LossStage>(k))] = {
            {"objects", results[s].losses[b][k]}, {"found", results[s].losses_found[b][k]}};
      }
      losses[vision::BinName(static_cast<vision::VisibilityBin>(b))] = per_stage;
    }
    // The blocks lost at verification by the occlusion pass's second look (SecondLook::Verdict).
    // And of them, those cut by the image border.
    auto per_bin_and_verdict = [](const int(&counts)[3][vision::kSecondLookVerdicts]) {
      json::Json per_bin = json::Json::object();
      for (int b = 0; b < 3; ++b) {
        json::Json per_verdict = json::Json::object();
        for (int v = 0; v < vision::kSecondLookVerdicts; ++v) {
          per_verdict[vision::SecondLookName(static_cast<vision::RecognitionTrace::SecondLook::Verdict>(v))] =
              counts[b][v];
        }
        per_bin[vision::BinName(static_cast<vision::VisibilityBin>(b))] = per_verdict;
      }
      return per_bin;
    };
    const json::Json second_looks = per_bin_and_verdict(results[s].second_looks);
    const json::Json second_looks_at_border = per_bin_and_verdict(results[s].second_looks_at_border);
    json::Json at_missed = json::Json::object();
    int missed_total = 0;
    for (int k = 0; k < vision::kLossStages; ++k) {
      at_missed[vision::LossStageName(static_cast<vision::LossStage>(k))] = results[s].false_at_missed[k];
      missed_total += results[s].false_at_missed[k];
    }
    at_missed["total"] = missed_total;
    data_sets.push_back(
        {{"name", sets[s].name},
         {"teachsim_losses", losses},
         {"teachsim_verification_losses", second_looks},
         {"teachsim_verification_losses_at_border", second_looks_at_border},
         {"teachsim_false_positives",
          {{"at_missed_block", at_missed},
           {"at_found_block", results[s].false_at_found},
           {"at_unscored_block", results[s].false_at_unscored},
           {"elsewhere", results[s].false_elsewhere}}},
         {"description", sets[s].description},
         {"images", sets[s].images},
         {"scored_objects_per_bin",
          {{">=0.7", results[s].bins[0]}, {"0.4-0.7", results[s].bins[1]}, {"<0.4", results[s].bins[2]}}},
         {"explained_by_shorter_model_per_bin",
          {{">=0.7", results[s].explained[0]},
           {"0.4-0.7", results[s].explained[1]},
           {"<0.4", results[s].explained[2]}}},
         {"teachsim_false_positives_as_shorter_model", results[s].false_as_shorter},
         {"methods", methods}});
  }
  const json::Json document{
      {"benchmark", "recognize"},
      {"quick", args.quick},
      {"render_seeds", {options.first_seed, options.last_seed}},
      {"peer", !options.no_peer},
      {"match_criteria",
       {{"same_model", true},
        {"max_across_mm", match.max_across_m * 1e3},
        {"max_along_mm", match.max_along_m * 1e3},
        {"max_rotation_deg", match.max_rotation_rad * 180 / kPi},
        {"min_visible_fraction", match.min_visible_fraction}}},
      {"time", "thread CPU time per image, one OpenCV thread"},
      {"setup",
       {{"teachsim_index_size", recognizer->index_size()},
        {"teachsim_index_from_cache", recognizer->loaded_from_cache()},
        {"teachsim_setup_s", recognizer_setup_s},
        {"linemod_templates", peer ? json::Json(peer->num_templates()) : json::Json()},
        {"linemod_templates_from_cache", peer ? json::Json(peer->loaded_from_cache()) : json::Json()},
        {"linemod_setup_s", peer ? json::Json(peer->build_s()) : json::Json()},
        {"render_s", render_s},
        {"warmup", warmup},
        {"cache_dir", cache_dir}}},
      {"data_sets", data_sets}};
  if (args.json) {
    std::printf("%s\n", document.dump(2).c_str());
    return 0;
  }
  auto number = [](const json::Json& v, const char* format) {
    char buffer[32];
    if (v.is_null()) return std::string("-");
    std::snprintf(buffer, sizeof(buffer), format, v.get<double>());
    return std::string(buffer);
  };
  if (peer) {
    std::printf(
        "recognition: teachsim vs OpenCV LINE-MOD (%d templates%s), same images; one core (CPU time)\n",
        peer->num_templates(), peer->loaded_from_cache() ? ", from cache" : "");
  } else {
    std::printf("recognition: teachsim (the peer left out: --no-peer); one core (CPU time)\n");
  }
  if (warmup.contains("image")) {
    auto runs = [](const json::Json& ms) {
      std::string out;
      for (const json::Json& v : ms) {
        char buffer[32];
        std::snprintf(buffer, sizeof(buffer), "%s%.1f", out.empty() ? "" : ", ", v.get<double>());
        out += buffer;
      }
      return out + " ms";
    };
    std::printf("warm-up, untimed: %s %s on %s first (teachsim %s%s",
                warmup.contains("linemod_ms") ? "teachsim and LINE-MOD" : "teachsim", kWarmupRunsInWords,
                warmup["image"].get<std::string>().c_str(), runs(warmup["teachsim_ms"]).c_str(),
                warmup["teachsim_ok"].get<bool>() ? "" : ", failed");
    if (warmup.contains("linemod_ms")) std::printf("; LINE-MOD %s", runs(warmup["linemod_ms"]).c_str());
    std::printf("): a process's first runs pay for fresh memory\n");
  }
  std::printf("found = same model, <= %.0f mm across, <= %.0f mm along the line of sight, <= %.0f deg (symmetry-aware)\n",
              match.max_across_m * 1e3, match.max_along_m * 1e3, match.max_rotation_rad * 180 / kPi);
  for (const json::Json& set : data_sets) {
    std::printf("\n%s (%d images; objects per bin >=0.7 / 0.4-0.7 / <0.4: %d / %d / %d)\n",
                set["name"].get<std::string>().c_str(), set["images"].get<int>(),
                set["scored_objects_per_bin"][">=0.7"].get<int>(), set["scored_objects_per_bin"]["0.4-0.7"].get<int>(),
                set["scored_objects_per_bin"]["<0.4"].get<int>());
    std::printf("  %-30s", "");
    for (int m = 0; m < method_count; ++m) std::printf("%20s", kMethods[m]);
    std::printf("\n");
    auto row = [&](const char* label, auto get) {
      std::printf("  %-30s", label);
      for (int m = 0; m < method_count; ++m) std::printf("%20s", get(set["methods"][kMethods[m]]).c_str());
      std::printf("\n");
    };
    const std::string unoccluded_label =
        "recall, unoccluded (>=" + json::FormatNumber(vision::kUnoccludedFraction) + ")";
    row(unoccluded_label.c_str(),
        [&](const json::Json& j) { return number(j["recall_unoccluded"]["recall"], "%.3f"); });
    for (const char* bin : {">=0.7", "0.4-0.7", "<0.4"}) {
      const std::string label = std::string("recall, visible ") + bin;
      row(label.c_str(), [&](const json::Json& j) { return number(j["recall"][bin]["recall"], "%.3f"); });
    }
    // Recall without the blocks that a shorter model would show alike (a bar whose far end the
    // cylinder hides), where there are any.
    const json::Json& explained = set["explained_by_shorter_model_per_bin"];
    if (explained[">=0.7"].get<int>() + explained["0.4-0.7"].get<int>() + explained["<0.4"].get<int>() > 0) {
      for (const char* bin : {">=0.7", "0.4-0.7", "<0.4"}) {
        const std::string label = std::string("  identifiable ") + bin;
        row(label.c_str(),
            [&](const json::Json& j) { return number(j["recall_identifiable"][bin]["recall"], "%.3f"); });
      }
    }
    row("false positives / image", [&](const json::Json& j) { return number(j["false_positives_per_image"], "%.3f"); });
    row("found within pose goals", [&](const json::Json& j) { return number(j["found_within_goals_fraction"], "%.3f"); });
    for (const auto& [key, label] : std::vector<std::pair<const char*, const char*>>{
             {"position_error_across_mm", "across mm (median/p90)"},
             {"position_error_along_mm", "along mm (median/p90)"},
             {"rotation_error_deg", "rotation deg (median/p90)"},
             {"reprojection_rms_px", "reprojection px (median/p90)"},
             {"truth_projection_rms_px", "off truth px (median/p90)"}}) {
      row(label, [&, k = key](const json::Json& j) {
        return number(j[k]["median"], "%.2f") + " / " + number(j[k]["p90"], "%.2f");
      });
    }
    // The slowest image too: the goal is per image, and one pathological pose can cost seconds.
    row("time ms (median/p90/max)", [&](const json::Json& j) {
      const json::Json& t = j["time_per_image_ms"];
      return number(t["median"], "%.1f") + "/" + number(t["p90"], "%.1f") + "/" + number(t["max"], "%.0f");
    });
    const std::string over_label = "images over " + json::FormatNumber(vision::kTimeGoalMs) + " ms";
    row(over_label.c_str(), [&](const json::Json& j) {
      return std::to_string(j["images_over_time_goal"].get<int>()) + " / " +
             std::to_string(j["images"].get<int>());
    });
    // Each method's own medians above are over the blocks it found; on the blocks both found, the
    // pose figures compare like with like.
    for (int m = kFirstPeer; m < method_count; ++m) {
      const json::Json& paired = set["methods"][kMethods[m]]["paired_with_teachsim"];
      std::printf(
          "  on the %d blocks teachsim and %s both found, median teachsim / %s (blocks where each is "
          "smaller):\n",
          paired["objects"].get<int>(), kMethods[m], kMethods[m]);
      for (const auto& [key, label] :
           std::vector<std::pair<const char*, const char*>>{{"rotation_error_deg", "rotation deg"},
                                                            {"reprojection_rms_px", "reprojection px"},
                                                            {"truth_projection_rms_px", "off truth px"}}) {
        std::printf("    %-16s %s / %s (%d / %d)\n", label,
                    number(paired["teachsim"][key]["median"], "%.2f").c_str(),
                    number(paired["peer"][key]["median"], "%.2f").c_str(),
                    paired["teachsim_smaller"][key].get<int>(), paired["peer_smaller"][key].get<int>());
      }
    }
    // Where the recognizer's time goes, on the mean image and on the slowest one.
    const json::Json& ours = set["methods"]["teachsim"];
    if (!ours["stage_time_ms"].empty()) {
      std::printf("  teachsim: mean ms per stage (its own clock):");
      for (const auto& [stage, stats] : ours["stage_time_ms"].items()) {
        std::printf(" %s %s", stage.c_str(), number(stats["mean"], "%.1f").c_str());
      }
      std::printf("\n");
    }
    if (const json::Json& slowest = ours["slowest_image"]; !slowest.is_null()) {
      std::printf("  teachsim: slowest image %s, %.1f ms;", slowest["image"].get<std::string>().c_str(),
                  slowest["ms"].get<double>());
      for (const auto& [what, n] : slowest["counts"].items())
        std::printf(" %s %d", what.c_str(), n.get<int>());
      std::printf(";");
      for (const auto& [stage, ms] : slowest["stage_ms"].items())
        std::printf(" %s %.1f", stage.c_str(), ms.get<double>());
      std::printf("\n");
    }
    std::printf("  teachsim: objects by the stage that lost them (of them found), per bin\n");
    for (const char* bin : {">=0.7", "0.4-0.7", "<0.4"}) {
      std::printf("    %-8s", bin);
      for (const auto& [stage, n] : set["teachsim_losses"][bin].items()) {
        std::printf("  %s %d (%d)", stage.c_str(), n["objects"].get<int>(), n["found"].get<int>());
      }
      std::printf("\n");
    }
    std::printf(
        "  teachsim: objects lost at verification by the occlusion pass's second look (of them cut by the "
        "image border), per bin\n");
    for (const char* bin : {">=0.7", "0.4-0.7", "<0.4"}) {
      std::printf("    %-8s", bin);
      for (const auto& [verdict, n] : set["teachsim_verification_losses"][bin].items()) {
        std::printf("  %s %d (%d)", verdict.c_str(), n.get<int>(),
                    set["teachsim_verification_losses_at_border"][bin][verdict].get<int>());
      }
      std::printf("\n");
    }
    const json::Json& fp = set["teachsim_false_positives"];
    std::printf("  teachsim: false detections at a missed block %d (lost at:",
                fp["at_missed_block"]["total"].get<int>());
    for (const auto& [stage, n] : fp["at_missed_block"].items()) {
      if (stage != "total" && n.get<int>() > 0) std::printf(" %s %d", stage.c_str(), n.get<int>());
    }
    std::printf("), at a found block %d, at an unscored block %d, elsewhere %d\n",
                fp["at_found_block"].get<int>(), fp["at_unscored_block"].get<int>(),
                fp["elsewhere"].get<int>());
    if (explained[">=0.7"].get<int>() + explained["0.4-0.7"].get<int>() + explained["<0.4"].get<int>() > 0) {
      std::printf(
          "  blocks a shorter model would show alike (its far end hidden or outside the image), per bin: %d "
          "/ %d / "
          "%d, of them teachsim found %d / %d / %d; teachsim's false detections that are such a shorter "
          "model: %d\n",
          explained[">=0.7"].get<int>(), explained["0.4-0.7"].get<int>(), explained["<0.4"].get<int>(),
          set["methods"]["teachsim"]["found_of_explained_by_shorter"][">=0.7"].get<int>(),
          set["methods"]["teachsim"]["found_of_explained_by_shorter"]["0.4-0.7"].get<int>(),
          set["methods"]["teachsim"]["found_of_explained_by_shorter"]["<0.4"].get<int>(),
          set["teachsim_false_positives_as_shorter_model"].get<int>());
    }
  }
  return 0;
}

}  // namespace
}  // namespace teachsim::worksite

TEACHSIM_BENCH(
    "recognize",
    "recognition of blocks on the dev set and on renders with occlusion: teachsim vs OpenCV LINE-MOD "
    "([--render-seeds N|A-B] [--no-peer])",
    teachsim::worksite::Run);
