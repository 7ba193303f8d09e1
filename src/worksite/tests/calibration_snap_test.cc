// Extrinsic calibration end to end on rendered work-site images (issue 6: the camera position
// within 2 mm from 6 known points with 0.5 px noise on the clicks). The clicks are the true
// projections of the frame's and the table's corners plus noise; vision::SnapCorrespondences moves
// them to the corner in the image (guided by a first pose from the clicks and the corners' 3-D
// edges), vision::CalibrateExtrinsics solves the pose weighted by each point's sigma, and
// vision::FitPoseToEdges fits that pose to the points' model edges along their whole visible length
// (`--snap --edge-fit`). The test lives here, not in vision, because the images come from the
// worksite renderer (worksite depends on vision).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <optional>
#include <random>

#include "calibration_features.h"
#include "fixtures.h"
#include "teachsim/vision/calibration.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {
namespace {

using testing::Feature;
using testing::RecommendedFeatures;

// The scene's camera moved by up to `shift_m` and turned by up to `turn_rad` about a random axis
// through the frame's centre's line of sight (so the work site stays in view).
vision::Camera Perturbed(const vision::Camera& camera, std::mt19937& rng, double shift_m, double turn_rad) {
  std::uniform_real_distribution<double> unit(-1, 1);
  const Eigen::Vector3d shift(unit(rng) * shift_m, unit(rng) * shift_m, unit(rng) * shift_m);
  const Eigen::Vector3d axis = Eigen::Vector3d(unit(rng), unit(rng), unit(rng)).normalized();
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(unit(rng) * turn_rad, axis));
  geometry::Pose3 pose = camera.world_T_camera();
  pose.translation += shift;
  pose.rotation = (turn * pose.rotation).normalized();
  return camera.WithPose(pose);
}

// A feature is usable when it projects at least a snap window inside the image and nothing but its
// own object, the table or the background shows within that window (no block in front of it).
bool Usable(const RenderResult& render, const std::vector<RenderObject>& objects,
            const vision::Camera& camera, const Feature& f, double window_px) {
  auto pixel = camera.Project(f.p_in_world);
  if (!pixel) return false;
  if (pixel->x() < window_px + 2 || pixel->y() < window_px + 2 ||
      pixel->x() > camera.width() - window_px - 3 || pixel->y() > camera.height() - window_px - 3) {
    return false;
  }
  const int r = static_cast<int>(window_px);
  const int u0 = static_cast<int>(std::lround(pixel->x())), v0 = static_cast<int>(std::lround(pixel->y()));
  for (int v = v0 - r; v <= v0 + r; ++v) {
    for (int u = u0 - r; u <= u0 + r; ++u) {
      const int label = render.labels.at<std::int16_t>(v, u);
      if (label < 0) continue;
      const std::string& name = objects[static_cast<std::size_t>(label)].name;
      if (name != f.object && name != "table") return false;
    }
  }
  return true;
}

struct Summary {
  std::vector<double> snap_error_px;  // per snapped point, |snapped - truth|
  std::map<std::string, std::vector<double>> snap_error_by_feature_px;
  std::vector<double> sigma_ratio;        // per snapped point, |snapped - truth| / (sqrt 2 sigma)
  std::vector<double> position_error_mm;  // per trial
  std::vector<double> stations, station_rms_px;  // per trial, with the edge fit
  int points = 0, unsnapped = 0;
};

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

double ShareBelow(const std::vector<double>& v, double limit) {
  return static_cast<double>(std::count_if(v.begin(), v.end(), [&](double x) { return x < limit; })) /
         static_cast<double>(v.size());
}

void Print(const char* label, const Summary& s) {
  std::printf("%-34s trials %4zu  ", label, s.position_error_mm.size());
  if (!s.snap_error_px
           .empty()) {  // rows without snapping (or whose snaps are not measured) say nothing of it
    std::printf("snap error px median %.3f p95 %.3f (unsnapped %d of %d)  ", Quantile(s.snap_error_px, 0.5),
                Quantile(s.snap_error_px, 0.95), s.unsnapped, s.points);
  }
  std::printf("position error mm median %.2f p95 %.2f max %.2f  within 2 mm %.1f %%\n",
              Quantile(s.position_error_mm, 0.5), Quantile(s.position_error_mm, 0.95),
              Quantile(s.position_error_mm, 1.0), 100 * ShareBelow(s.position_error_mm, 2.0));
  for (const auto& [name, errors] : s.snap_error_by_feature_px) {
    std::printf("    %-20s snapped %3zu  error px median %.3f p95 %.3f max %.3f\n", name.c_str(),
                errors.size(), Quantile(errors, 0.5), Quantile(errors, 0.95), Quantile(errors, 1.0));
  }
  if (!s.stations.empty()) {
    std::printf("    edge stations used per trial median %.0f min %.0f, their RMS px median %.3f p95 %.3f\n",
                Quantile(s.stations, 0.5), Quantile(s.stations, 0.0), Quantile(s.station_rms_px, 0.5),
                Quantile(s.station_rms_px, 0.95));
  }
  if (!s.sigma_ratio.empty()) {
    std::printf("    error / (sqrt 2 sigma) median %.2f p95 %.2f\n", Quantile(s.sigma_ratio, 0.5),
                Quantile(s.sigma_ratio, 0.95));
  }
}

enum class Clicks { kGaussianHalfPixel, kWholePixelTwoOff };
enum class Snap { kNone, kEdgeLines, kCornerSubPix };

// One image's trials: each trial clicks every usable feature (truth + noise), snaps, solves.
void RunTrials(const cv::Mat& image, const vision::Camera& truth, const std::vector<Feature>& features,
               Clicks clicks, Snap snap, int trials, std::mt19937& rng, Summary& summary,
               Summary* edge_fit = nullptr) {
  std::normal_distribution<double> gaussian(0, 0.5);
  // The operator's click accuracy, as `--click-sigma` tells it: points the snapping keeps as clicked
  // are weighted by it. Whole-pixel clicks up to 2 px off: uniform over 4 px, sigma 4 / sqrt 12.
  const double click_sigma_px = clicks == Clicks::kGaussianHalfPixel ? 0.5 : 4 / std::sqrt(12.0);
  std::uniform_real_distribution<double> two(-2, 2);
  vision::SnapOptions options;
  if (snap == Snap::kCornerSubPix) options.method = vision::SnapMethod::kCornerSubPix;
  for (int trial = 0; trial < trials; ++trial) {
    std::vector<vision::PointCorrespondence> points;
    std::vector<Eigen::Vector2d> true_pixels;
    for (const Feature& f : features) {
      const Eigen::Vector2d pixel = *truth.Project(f.p_in_world);
      Eigen::Vector2d click;
      if (clicks == Clicks::kGaussianHalfPixel) {
        click = pixel + Eigen::Vector2d(gaussian(rng), gaussian(rng));
      } else {
        click = (pixel + Eigen::Vector2d(two(rng), two(rng))).array().round();
      }
      points.push_back({f.name, click, f.p_in_world, 0, f.edges_in_world});
      true_pixels.push_back(pixel);
    }
    if (snap != Snap::kNone) {
      // The camera the snapping sees is the calibrated one (intrinsics and distortion); its pose is
      // not used.
      const vision::Camera intrinsics_only = truth.WithPose(geometry::Pose3::Identity());
      const std::vector<vision::SnapResult> snapped =
          vision::SnapCorrespondences(image, intrinsics_only, points, options, click_sigma_px);
      for (std::size_t i = 0; i < snapped.size(); ++i) {
        ++summary.points;
        if (snapped[i].snapped) {
          const double error = (snapped[i].pixel - true_pixels[i]).norm();
          summary.snap_error_px.push_back(error);
          summary.snap_error_by_feature_px[points[i].name].push_back(error);
          if (snapped[i].sigma_px > 0)
            summary.sigma_ratio.push_back(error / (std::sqrt(2.0) * snapped[i].sigma_px));
        } else {
          ++summary.unsnapped;
        }
      }
    }
    vision::ExtrinsicsOptions eo;
    eo.click_sigma_px = click_sigma_px;
    auto result = vision::CalibrateExtrinsics(truth, points, eo);
    ASSERT_TRUE(result.ok()) << result.status().message();
    summary.position_error_mm.push_back(
        (result->world_T_camera.translation - truth.world_T_camera().translation).norm() * 1e3);
    if (edge_fit != nullptr) {
      // From that pose, fitted to the model's edges along their whole visible length (--edge-fit).
      const vision::Camera posed = truth.WithPose(result->world_T_camera);
      auto fitted = vision::FitPoseToEdges(image, posed, points, vision::EdgeFitOptions{}, click_sigma_px);
      ASSERT_TRUE(fitted.ok()) << fitted.status().message();
      edge_fit->points += static_cast<int>(points.size());
      edge_fit->stations.push_back(fitted->stations_used);
      edge_fit->station_rms_px.push_back(fitted->station_rms_px);
      edge_fit->position_error_mm.push_back(
          (fitted->extrinsics.world_T_camera.translation - truth.world_T_camera().translation).norm() * 1e3);
    }
  }
}

struct Measurement {
  int images = 0;
  Summary gauss_none, gauss_lines, gauss_subpix, whole_none, whole_lines, whole_subpix;
  bool edge_fit = false;
  Summary gauss_edges, whole_edges;  // snapped, then the pose fitted to the model's edges (edge_fit)
  // With a gamma (`gamma_told_or_not`): the same Gaussian clicks on the same images, snapped and
  // edge-fitted by a calibration told the camera is linear.
  Summary untold_lines, untold_edges;
};

// Cameras: the scene's camera and perturbed copies (up to 4 cm and 4 degrees), two renders each
// (sensor noise and the wood's grain differ), 20 trials per render and click model: Gaussian
// clicks of sigma 0.5 px, and whole-pixel clicks up to 2 px off (before rounding). With edge_fit,
// the snapped trials go on to the edge fit too (~6 s more). With `gamma_told_or_not`, the cameras
// write their images encoded with that gamma (Camera::gamma), and only the Gaussian clicks are run,
// snapped and edge-fitted, once by a calibration told the gamma and once by one told the camera is
// linear (gauss_* and untold_*), on the same images.
Measurement Measure(bool edge_fit, std::optional<double> gamma_told_or_not = std::nullopt) {
  Measurement m;
  m.edge_fit = edge_fit;
  const scene::Scene scene = testing::Puzzle();
  auto main_camera =
      vision::Camera::FromSpec(scene.cameras.at(static_cast<std::size_t>(scene.FindCamera("main"))));
  TEACHSIM_CHECK(main_camera.ok());
  const std::vector<Feature> all_features = RecommendedFeatures(scene);
  const std::vector<RenderObject> base_objects = ObjectsFromScene(scene);
  // TEACHSIM_CALIBRATION_SNAP_SEED picks other cameras, grain and noise (a held-out check of
  // figures measured on the default set; the tests' bars are stated for the default).
  std::uint32_t set = 2026;
  if (const char* env = std::getenv("TEACHSIM_CALIBRATION_SNAP_SEED")) set = static_cast<std::uint32_t>(std::stoul(env));
  const std::uint32_t other = set - 2026;
  std::mt19937 rng(set);
  // The sanitizer build (about 6 times slower here) runs the same code on fewer trials per image.
  const int cameras = 6, renders_per_camera = 2,
            trials = std::getenv("TEACHSIM_SANITIZER_BUILD") != nullptr ? 6 : 20;
  for (int c = 0; c < cameras; ++c) {
    vision::Camera camera = c == 0 ? *main_camera : Perturbed(*main_camera, rng, 0.04, 0.07);
    if (gamma_told_or_not) camera.set_gamma(*gamma_told_or_not);
    vision::Camera untold = camera;
    untold.set_gamma(1.0);
    auto renderer = Renderer::Create(camera, RenderOptions{});
    TEACHSIM_CHECK(renderer.ok());
    for (int r = 0; r < renders_per_camera; ++r) {
      std::vector<RenderObject> objects = base_objects;
      for (RenderObject& o : objects) o.texture_seed += 7919u * (static_cast<std::uint32_t>(r) + 2 * other);
      const RenderResult render = renderer->Render(objects, 100 + 100 * other + static_cast<std::uint64_t>(10 * c + r));
      std::vector<Feature> features;
      for (const Feature& f : all_features) {
        if (Usable(render, objects, camera, f, 12)) features.push_back(f);
      }
      if (features.size() < 6) continue;  // a block in front of a corner: not this camera
      ++m.images;
      const std::uint32_t seed = static_cast<std::uint32_t>(1000 * c + r);
      std::mt19937 a(seed), b(seed), d(seed);  // the same clicks for each method
      if (gamma_told_or_not) {
        std::mt19937 u(seed);
        RunTrials(render.image, camera, features, Clicks::kGaussianHalfPixel, Snap::kEdgeLines, trials, b,
                  m.gauss_lines, &m.gauss_edges);
        RunTrials(render.image, untold, features, Clicks::kGaussianHalfPixel, Snap::kEdgeLines, trials, u,
                  m.untold_lines, &m.untold_edges);
        continue;
      }
      RunTrials(render.image, camera, features, Clicks::kGaussianHalfPixel, Snap::kNone, trials, a,
                m.gauss_none);
      RunTrials(render.image, camera, features, Clicks::kGaussianHalfPixel, Snap::kEdgeLines, trials, b,
                m.gauss_lines, edge_fit ? &m.gauss_edges : nullptr);
      RunTrials(render.image, camera, features, Clicks::kGaussianHalfPixel, Snap::kCornerSubPix, trials, d,
                m.gauss_subpix);
      if (edge_fit) {  // per image: the edge fit's errors of this image's trials
        const std::vector<double> errors(m.gauss_edges.position_error_mm.end() - trials,
                                         m.gauss_edges.position_error_mm.end());
        std::printf("camera %d render %d: snap + edge fit, sigma 0.5 px: error mm median %.2f max %.2f\n", c, r,
                    Quantile(errors, 0.5), Quantile(errors, 1.0));
      }
      std::mt19937 e(seed + 1), f(seed + 1), g(seed + 1);
      RunTrials(render.image, camera, features, Clicks::kWholePixelTwoOff, Snap::kNone, trials, e,
                m.whole_none);
      RunTrials(render.image, camera, features, Clicks::kWholePixelTwoOff, Snap::kEdgeLines, trials, f,
                m.whole_lines, edge_fit ? &m.whole_edges : nullptr);
      RunTrials(render.image, camera, features, Clicks::kWholePixelTwoOff, Snap::kCornerSubPix, trials, g,
                m.whole_subpix);
    }
  }
  std::printf("%d images of %d cameras (set %u, gamma %g)\n", m.images, cameras, set,
              gamma_told_or_not.value_or(1.0));
  if (gamma_told_or_not) return m;  // the test prints its two rows
  Print("sigma 0.5 px, no snap", m.gauss_none);
  Print("sigma 0.5 px, snap edge lines", m.gauss_lines);
  if (edge_fit) Print("sigma 0.5 px, snap + edge fit", m.gauss_edges);
  Print("sigma 0.5 px, snap cornerSubPix", m.gauss_subpix);
  Print("whole px +-2, no snap", m.whole_none);
  Print("whole px +-2, snap edge lines", m.whole_lines);
  if (edge_fit) Print("whole px +-2, snap + edge fit", m.whole_edges);
  Print("whole px +-2, snap cornerSubPix", m.whole_subpix);
  return m;
}

// Measured once per process and shared by the tests below (ctest runs each test in a process of its
// own: the snapping tests skip the edge fit, ~11 s; with it ~17 s in Release). The edge fit's test
// comes first so that one run of the whole binary measures once.
const Measurement& Measured(bool edge_fit) {
  static std::optional<Measurement> m;
  if (!m || (edge_fit && !m->edge_fit)) m = Measure(edge_fit);
  return *m;
}

// Issue 6's bar: the camera position within 2 mm in >= 95 % of the trials with 6 points clicked at
// 0.5 px, met by `--snap --edge-fit`: the snapped points' pose fitted to the points' model edges along
// their whole visible length (~173 stations per trial over ~10 edges, Tukey weights, each edge's
// offset free within 1.5 x its stations' spread, two rounds of predict -> measure -> fit). Measured:
// 100 % (max 1.5 mm) for sigma 0.5 px clicks and 100 % (max 1.9 mm) for whole-pixel clicks up to 2 px
// off; snapping alone reaches 88 % and 82 %. Six other sets (TEACHSIM_CALIBRATION_SNAP_SEED 2027-2032):
// 92-100 % per set, 98 % over all (docs/formats/calibration.md).
TEST(CalibrationSnapTest, SnappedClicksAndEdgeFitPutTheCameraWithinTwoMillimetres) {
  const Measurement& m = Measured(/*edge_fit=*/true);
  ASSERT_GE(m.images, 5);
  ASSERT_EQ(m.gauss_edges.position_error_mm.size(), m.gauss_lines.position_error_mm.size());
  EXPECT_GE(ShareBelow(m.gauss_edges.position_error_mm, 2.0), 0.95);
  EXPECT_GE(ShareBelow(m.whole_edges.position_error_mm, 2.0), 0.95);
  // Better than the snapped points alone, in the bulk and in the tail.
  EXPECT_LT(Quantile(m.gauss_edges.position_error_mm, 0.5), Quantile(m.gauss_lines.position_error_mm, 0.5));
  EXPECT_LT(Quantile(m.gauss_edges.position_error_mm, 0.95), 0.7 * Quantile(m.gauss_lines.position_error_mm, 0.95));
  // The walls' and the table's edges carry it: many stations, fitted to a fraction of a pixel.
  EXPECT_GT(Quantile(m.gauss_edges.stations, 0.0), 60);
  EXPECT_LT(Quantile(m.gauss_edges.station_rms_px, 0.95), 0.6);
}

// What snapping does today: clicks that are whole pixels and up to ~2 px off come out far better
// snapped than as clicked (median camera position error 1.4 vs 4.3 mm), most snapped corners land
// within half a pixel of the truth, and a point that cannot be snapped is reported, not moved.
TEST(CalibrationSnapTest, SnappingImprovesCoarseClicks) {
  const Measurement& m = Measured(/*edge_fit=*/false);
  ASSERT_GE(m.images, 5);
  EXPECT_LT(Quantile(m.whole_lines.position_error_mm, 0.5),
            0.5 * Quantile(m.whole_none.position_error_mm, 0.5));
  EXPECT_GT(ShareBelow(m.whole_lines.position_error_mm, 2.0), 0.6);
  EXPECT_LT(Quantile(m.whole_lines.snap_error_px, 0.5), 0.5);
  EXPECT_GT(m.whole_lines.points - m.whole_lines.unsnapped, m.whole_lines.points / 2);
}

// Clicks of sigma 0.5 px: the model-guided snapping (a first pose from the clicks predicts each
// corner's edges, blurred steps fitted along them, the pose weighted by each snap's sigma) puts the
// camera within 2 mm far more often than the clicks alone (88 % vs 47.5 % of the trials).
TEST(CalibrationSnapTest, SnappingImprovesHalfPixelClicks) {
  const Measurement& m = Measured(/*edge_fit=*/false);
  ASSERT_GE(m.images, 5);
  EXPECT_GT(ShareBelow(m.gauss_lines.position_error_mm, 2.0),
            ShareBelow(m.gauss_none.position_error_mm, 2.0) + 0.2);
  EXPECT_LT(Quantile(m.gauss_lines.position_error_mm, 0.95),
            0.8 * Quantile(m.gauss_none.position_error_mm, 0.95));
  EXPECT_LT(Quantile(m.gauss_lines.snap_error_px, 0.95), 1.2);
}

// A gamma-encoded camera (about 2.2: most cameras' 8-bit images) lifts mid greys, so on its grey
// levels a blurred step's middle sits towards the darker side and the fitted edges move. Told the
// camera's gamma, the snapping and the edge fit work on the light brought back to linear. Measured
// (Release, snap + edge fit, clicks of sigma 0.5 px), not told -> told: set 2026 median 0.96 ->
// 0.72 mm, within 2 mm 100 -> 100 %; held out, set 2027 1.52 -> 0.95 mm, 91.9 -> 99.4 %; set 2028
// 1.19 -> 0.76 mm, 79.6 -> 97.9 %. (A linear camera's images: 0.53 mm on set 2026.)
TEST(CalibrationSnapTest, AGammaCameraIsCalibratedOnItsLinearLight) {
  const Measurement m = Measure(/*edge_fit=*/true, /*gamma_told_or_not=*/2.2);
  Print("gamma 2.2 told: snap + edge fit", m.gauss_edges);
  Print("gamma 2.2 not told: snap + edge fit", m.untold_edges);
  ASSERT_GE(m.images, 5);
  EXPECT_LT(Quantile(m.gauss_edges.position_error_mm, 0.5),
            0.85 * Quantile(m.untold_edges.position_error_mm, 0.5));
  EXPECT_GE(ShareBelow(m.gauss_edges.position_error_mm, 2.0), 0.95);
}

}  // namespace
}  // namespace teachsim::worksite
