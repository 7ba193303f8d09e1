// teachsim calibrate: the camera's intrinsics from chessboard images, and its pose from image points
// of known world position (paper §4.2). Both write a camera entry of the scene format, atomically.
//
// clang-format off
//   teachsim calibrate intrinsics --images DIR --board COLSxROWS --square METRES --out CAMERA.json [--name NAME]
//   teachsim calibrate extrinsics --camera CAMERA.json --image IMG.png --points POINTS.json --out CAMERA.json
//                                 [--max-rms PX] [--click-sigma PX] [--snap] [--snap-method lines|cornersubpix]
//                                 [--snap-window PX] [--snap-max-offset PX] [--snap-drop SIGMAS]
//                                 [--edge-fit] [--edge-rounds N]
// clang-format on
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <memory>
#include <opencv2/imgcodecs.hpp>

#include "commands.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/calibration.h"

namespace teachsim::app {

namespace {

struct IntrinsicsArgs {
  std::string images, board, out, name = "camera";
  double square_m = 0;
  double gamma = 1.0;  // the camera's response, written into the file (not measured)
  int min_views = 5;
  bool fix_tangential = false;
};

struct ExtrinsicsArgs {
  std::string camera, image, points, out;
  double max_rms_px = 2.0;
  double click_sigma_px = 0.5;
  // Off by default: it needs the image to show the corners' edges unobstructed. On rendered
  // work-site images, with clicks 0.5 px off, it puts the camera within 2 mm in 88 % of trials
  // against 47 % unsnapped (docs/formats/calibration.md has the figures); with --edge-fit, 100 %.
  bool snap = false;
  double drop_beyond_sigmas = 4;
  std::string snap_method = "lines";
  double snap_window_px = 12;
  double snap_max_offset_px = 4;
  // The pose fitted to the points' model edges along their whole visible length (Lowe-style), from
  // the PnP pose. With --snap, on the same renders: 100 % of trials within 2 mm (max 1.5 mm).
  bool edge_fit = false;
  int edge_rounds = vision::EdgeFitOptions{}.rounds;
};

int RunIntrinsics(const IntrinsicsArgs& a) {
  auto board = vision::ParseBoardSize(a.board, a.square_m);
  if (!board.ok()) return ReportError(board.status().WithPrefix("--board/--square"));
  vision::IntrinsicsOptions options;
  options.min_views = a.min_views;
  options.fix_tangential = a.fix_tangential;
  auto calibration = vision::CalibrateIntrinsicsFromFolder(a.images, *board, options);
  if (!calibration.ok()) return ReportError(calibration.status());
  for (const vision::SkippedImage& s : calibration->skipped) {
    std::fprintf(stderr, "teachsim: warning: skipped %s: %s\n", s.path.c_str(), s.reason.c_str());
  }
  const vision::IntrinsicsResult& r = calibration->result;
  vision::Camera camera(r.intrinsics, r.distortion, geometry::Pose3::Identity(), r.width, r.height);
  camera.set_gamma(a.gamma);
  if (Status s = json::WriteJsonFile(a.out, scene::WriteCamera(camera.ToSpec(a.name))); !s.ok()) {
    return ReportError(s);
  }
  std::printf("%s: %zu views used, %zu skipped; reprojection RMS %.3f px\n", a.out.c_str(),
              calibration->used.size(), calibration->skipped.size(), r.rms_px);
  std::printf("  fx %.2f  fy %.2f  cx %.2f  cy %.2f  k1 %.4f  k2 %.4f  p1 %.5f  p2 %.5f  k3 %.4f\n",
              r.intrinsics.fx, r.intrinsics.fy, r.intrinsics.cx, r.intrinsics.cy, r.distortion.k1,
              r.distortion.k2, r.distortion.p1, r.distortion.p2, r.distortion.k3);
  std::printf("  the pose is the identity: run `teachsim calibrate extrinsics` next\n");
  return 0;
}

int RunExtrinsics(const ExtrinsicsArgs& a) {
  auto spec = scene::LoadCamera(a.camera);
  if (!spec.ok()) return ReportError(spec.status());
  auto camera = vision::Camera::FromSpec(*spec);
  if (!camera.ok()) return ReportError(camera.status().WithPrefix(a.camera));
  // The image the points were picked on: it must exist and match the camera's size.
  const cv::Mat image = cv::imread(a.image, cv::IMREAD_UNCHANGED);
  if (image.empty())
    return ReportError(Status::NotFound(a.image + ": cannot read the image (missing or not an image)"));
  if (image.cols != camera->width() || image.rows != camera->height()) {
    return ReportError(Status::InvalidInput(a.image + ": image is " + std::to_string(image.cols) + "x" +
                                            std::to_string(image.rows) + " but camera " + a.camera + " is " +
                                            std::to_string(camera->width()) + "x" +
                                            std::to_string(camera->height())));
  }
  auto points = vision::LoadPointCorrespondences(a.points);
  if (!points.ok()) return ReportError(points.status());
  for (std::size_t i = 0; i < points->size(); ++i) {
    if (!camera->InImage((*points)[i].pixel)) {
      return ReportError(Status::InvalidInput(a.points + ": points[" + std::to_string(i) + "].pixel: (" +
                                              json::FormatNumber((*points)[i].pixel.x()) + ", " +
                                              json::FormatNumber((*points)[i].pixel.y()) +
                                              ") lies outside the " + std::to_string(camera->width()) + "x" +
                                              std::to_string(camera->height()) + " image"));
    }
  }
  if (a.snap) {
    vision::SnapOptions snap;
    snap.method =
        a.snap_method == "cornersubpix" ? vision::SnapMethod::kCornerSubPix : vision::SnapMethod::kEdgeLines;
    snap.window_px = a.snap_window_px;
    snap.max_offset_px = a.snap_max_offset_px;
    if (Status s = snap.Validate(); !s.ok())
      return ReportError(s.WithPrefix("--snap-window/--snap-max-offset"));
    const cv::Mat gray = cv::imread(a.image, cv::IMREAD_GRAYSCALE);
    std::vector<vision::PointCorrespondence> snapped_points = *points;
    const std::vector<vision::SnapResult> snapped =
        vision::SnapCorrespondences(gray, *camera, snapped_points, snap, a.click_sigma_px);
    int kept = 0;
    double sum2 = 0;
    std::printf(
        "snapping the clicks to the image's corners (%s%s):\n", a.snap_method.c_str(),
        snap.method == vision::SnapMethod::kEdgeLines ? ", guided by a first pose from the clicks" : "");
    for (std::size_t i = 0; i < snapped.size(); ++i) {
      const vision::SnapResult& r = snapped[i];
      const Eigen::Vector2d& click = (*points)[i].pixel;
      if (r.snapped) {
        sum2 += r.offset_px * r.offset_px;
        std::printf("  %-20s (%.2f, %.2f) -> (%.2f, %.2f)  moved %.2f px  sigma %.2f px  %d edges\n",
                    (*points)[i].name.c_str(), click.x(), click.y(), r.pixel.x(), r.pixel.y(), r.offset_px,
                    r.sigma_px, r.edges);
      } else {
        ++kept;
        std::printf("  %-20s (%.2f, %.2f) kept as clicked, sigma %.2f px: %s\n", (*points)[i].name.c_str(),
                    click.x(), click.y(), a.click_sigma_px, r.reason.c_str());
        std::fprintf(stderr, "teachsim: warning: %s at (%.2f, %.2f) not snapped, kept as clicked: %s\n",
                     (*points)[i].name.c_str(), click.x(), click.y(), r.reason.c_str());
      }
    }
    const int moved = static_cast<int>(snapped.size()) - kept;
    std::printf("  %d of %zu points snapped, RMS snap offset %.2f px\n", moved, snapped.size(),
                moved > 0 ? std::sqrt(sum2 / moved) : 0.0);
    *points = std::move(snapped_points);
  }
  vision::ExtrinsicsOptions options;
  options.click_sigma_px = a.click_sigma_px;
  // Snapped points carry their own sigma; one far beyond it (a wrong edge) is dropped.
  if (a.snap) options.drop_beyond_sigmas = a.drop_beyond_sigmas;
  if (Status s = options.Validate(); !s.ok()) return ReportError(s.WithPrefix("--click-sigma/--snap-drop"));
  auto result = vision::CalibrateExtrinsics(*camera, *points, options);
  if (!result.ok()) return ReportError(result.status().WithPrefix(a.points));
  if (a.edge_fit) {
    vision::EdgeFitOptions edge_options;
    edge_options.rounds = a.edge_rounds;
    if (Status s = edge_options.Validate(); !s.ok()) return ReportError(s.WithPrefix("--edge-rounds"));
    const Eigen::Vector3d& first = result->world_T_camera.translation;
    std::printf(
        "fitting the pose to the points' model edges (from the PnP pose, camera at (%.1f, %.1f, %.1f) mm):\n",
        first.x() * 1e3, first.y() * 1e3, first.z() * 1e3);
    const cv::Mat gray = cv::imread(a.image, cv::IMREAD_GRAYSCALE);
    const vision::Camera posed = camera->WithPose(result->world_T_camera);
    auto fitted = vision::FitPoseToEdges(gray, posed, *points, edge_options, a.click_sigma_px,
                                         [](const std::string& line) { std::printf("  %s\n", line.c_str()); });
    if (!fitted.ok()) return ReportError(fitted.status().WithPrefix(a.points + ": --edge-fit"));
    std::printf("  %-40s %8s %6s %5s %8s %10s\n", "edge", "stations", "fitted", "used", "RMS px", "offset px");
    int edges_used = 0;
    for (const vision::EdgeReport& e : fitted->edges) {
      if (e.used > 0) ++edges_used;
      if (e.used > 0) {
        std::printf("  %-40s %8d %6d %5d %8.3f %+10.3f\n", e.name.c_str(), e.stations, e.fitted, e.used, e.rms_px,
                    e.offset_px);
      } else {
        std::printf("  %-40s %8d %6d %5d %8s\n", e.name.c_str(), e.stations, e.fitted, e.used, "-");
      }
    }
    std::printf("  %d stations on %d of %zu edges used, RMS %.3f px from the projected edges\n",
                fitted->stations_used, edges_used, fitted->edges.size(), fitted->station_rms_px);
    if (edges_used == 0) {
      std::fprintf(stderr, "teachsim: warning: --edge-fit found no model edge in the image; the pose rests on the points\n");
    }
    result = std::move(fitted->extrinsics);
  }
  const Eigen::Vector3d& p = result->world_T_camera.translation;
  std::printf("camera at (%.1f, %.1f, %.1f) mm; reprojection RMS %.3f px over %zu points\n", p.x() * 1e3,
              p.y() * 1e3, p.z() * 1e3, result->rms_px, points->size());
  // The Cramer-Rao bound at the solution: what clicks of this accuracy allow with these points.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> axes(result->position_covariance_m2);
  const Eigen::Vector3d axis_sigma_mm = axes.eigenvalues().cwiseMax(0).cwiseSqrt() * 1e3;
  if (a.edge_fit) {
    std::printf(
        "  predicted position uncertainty %.2f mm RMS (%.2f / %.2f / %.2f mm along its principal axes) "
        "from the edge stations and the points\n",
        result->position_sigma_m * 1e3, axis_sigma_mm(2), axis_sigma_mm(1), axis_sigma_mm(0));
  } else {
    std::printf(
        "  predicted position uncertainty %.2f mm RMS (%.2f / %.2f / %.2f mm along its principal axes) "
        "for %.2f px click noise\n",
        result->position_sigma_m * 1e3, axis_sigma_mm(2), axis_sigma_mm(1), axis_sigma_mm(0), a.click_sigma_px);
  }
  for (std::size_t i = 0; i < points->size(); ++i) {
    const bool dropped = i < result->dropped.size() && result->dropped[i];
    std::printf("  %-20s %.3f px%s\n", (*points)[i].name.c_str(), result->residuals_px[i],
                dropped ? "  (dropped: far beyond its sigma)" : "");
    if (dropped) {
      std::fprintf(stderr, "teachsim: warning: %s dropped from the pose: residual %.2f px\n",
                   (*points)[i].name.c_str(), result->residuals_px[i]);
    }
  }
  if (result->rms_px > a.max_rms_px) {
    return ReportError(Status::Failed(a.points + ": reprojection RMS " + json::FormatNumber(result->rms_px) +
                                      " px exceeds --max-rms " + json::FormatNumber(a.max_rms_px) +
                                      " px (a mislabelled or misplaced point?); " + a.out + " not written"));
  }
  scene::CameraSpec out = *spec;
  out.world_T_camera = result->world_T_camera;
  if (Status s = json::WriteJsonFile(a.out, scene::WriteCamera(out)); !s.ok()) return ReportError(s);
  std::printf("%s: written\n", a.out.c_str());
  return 0;
}

}  // namespace

void AddCalibrateCommand(CLI::App& app, Runner* run) {
  CLI::App* sub = app.add_subcommand("calibrate", "calibrate the camera: intrinsics, then extrinsics");
  sub->require_subcommand(1);

  auto in = std::make_shared<IntrinsicsArgs>();
  CLI::App* intr =
      sub->add_subcommand("intrinsics", "focal lengths, principal point, distortion from chessboard images");
  intr->add_option("--images", in->images, "folder of chessboard images")->required();
  intr->add_option("--board", in->board, "COLSxROWS inner corners, e.g. 9x6")->required();
  intr->add_option("--square", in->square_m, "square size, m")->required();
  intr->add_option("--out", in->out, "camera file to write (a scene camera entry)")->required();
  intr->add_option("--name", in->name, "camera name in the file")->capture_default_str();
  intr->add_option("--min-views", in->min_views, "fewer usable views is an error")->capture_default_str();
  intr->add_flag("--zero-tangential", in->fix_tangential, "fix p1 = p2 = 0");
  intr->add_option(
          "--gamma", in->gamma,
          "the camera's response, written into the file: 1 linear, about 2.2 for most cameras' 8-bit "
          "(sRGB) images; not measured (docs/formats/camera.md)")
      ->check(CLI::Range(vision::Camera::kMinGamma, vision::Camera::kMaxGamma))
      ->capture_default_str();
  intr->callback([in, run] { *run = [in] { return RunIntrinsics(*in); }; });

  auto ex = std::make_shared<ExtrinsicsArgs>();
  CLI::App* extr =
      sub->add_subcommand("extrinsics", "the camera's pose from image points of known world position");
  extr->add_option("--camera", ex->camera, "camera file with the intrinsics")->required();
  extr->add_option("--image", ex->image, "the image the points were picked on")->required();
  extr->add_option("--points", ex->points, "POINTS.json: pixel positions with world points")->required();
  extr->add_option("--out", ex->out, "camera file to write (may be --camera)")->required();
  extr->add_option("--max-rms", ex->max_rms_px, "fail above this reprojection RMS, px")
      ->capture_default_str();
  extr->add_option("--click-sigma", ex->click_sigma_px,
                   "assumed click noise per coordinate, px (the predicted uncertainty; with --snap or "
                   "--edge-fit also the weight of the points that were not snapped)")
      ->capture_default_str();
  extr->add_flag("--snap,!--no-snap", ex->snap,
                 "move each click to the corner in the image where the edges near it meet (default off)");
  extr->add_option("--snap-method", ex->snap_method,
                   "lines (edge lines intersected) or cornersubpix (OpenCV)")
      ->check(CLI::IsMember({"lines", "cornersubpix"}))
      ->capture_default_str();
  extr->add_option("--snap-window", ex->snap_window_px, "edges within this radius of the click, px")
      ->capture_default_str();
  extr->add_option("--snap-max-offset", ex->snap_max_offset_px, "a snap farther than this is refused, px")
      ->capture_default_str();
  extr->add_option("--snap-drop", ex->drop_beyond_sigmas,
                   "with --snap: leave out a point whose residual exceeds this many of its sigmas (0: none)")
      ->capture_default_str();
  extr->add_flag("--edge-fit,!--no-edge-fit", ex->edge_fit,
                 "then fit the pose to the points' model edges (\"edges\" in POINTS.json) along their whole "
                 "visible length (default off; best with --snap)");
  extr->add_option("--edge-rounds", ex->edge_rounds, "with --edge-fit: predict -> measure -> fit this many times")
      ->capture_default_str();
  extr->footer(
      "Points: click at least 6 features of known position spread over the image and not all on one\n"
      "plane. In the default scene: the table corner in the image, three outer top corners of the\n"
      "frame's walls (not the one next to the table corner) and the two inner top corners on the\n"
      "other diagonal: 2.2 mm RMS at 0.5 px click noise (docs/formats/camera.md). Every extra\n"
      "feature helps; sub-pixel clicks help most (the error scales with the click noise). Give each\n"
      "point its \"edges\" and use --snap --edge-fit: the pose is then fitted to the edges' whole\n"
      "length (within 2 mm in 98 % of trials on rendered images, docs/formats/calibration.md).\n");
  extr->callback([ex, run] { *run = [ex] { return RunExtrinsics(*ex); }; });
}

}  // namespace teachsim::app
