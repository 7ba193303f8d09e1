// teachsim render: the simulated camera's image of a scene (worksite renderer), or chessboard
// views for calibration.
//
//   teachsim render --scene FILE [--camera NAME] --out IMG.png [--truth TRUTH.json] [--seed N]
//   teachsim render --chessboard 9x6 --square 0.03 (--scene FILE [--camera NAME] | --camera-file CAMERA.json)
//                   (--board-pose X,Y,Z,RX,RY,RZ --out IMG.png | --views N --out DIR) [--seed N]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>

#include "commands.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/calibration.h"
#include "teachsim/worksite/chessboard.h"
#include "teachsim/worksite/render.h"

namespace teachsim::app {

namespace {

struct RenderArgs {
  std::string scene_path, camera_name = "main", camera_file, out, truth;
  std::uint64_t seed = 1;
  int supersample = 2;
  double noise_sigma = -1, blur_sigma_px = -1;
  bool high_contrast = false;
  std::string chessboard, board_pose;
  double square_m = 0.03;
  int views = 0;
};

Result<scene::CameraSpec> ChooseCamera(const RenderArgs& a, const scene::Scene* scene) {
  if (!a.camera_file.empty()) return scene::LoadCamera(a.camera_file);
  if (scene == nullptr) return Status::InvalidInput("render: give --scene FILE or --camera-file CAMERA.json");
  const int i = scene->FindCamera(a.camera_name);
  if (i < 0) {
    std::string names;
    for (const scene::CameraSpec& c : scene->cameras) names += (names.empty() ? "" : ", ") + c.name;
    return Status::NotFound(a.scene_path + ": cameras: no camera named '" + a.camera_name +
                            "' (the scene has " + (names.empty() ? std::string("none") : names) + ")");
  }
  return scene->cameras[static_cast<std::size_t>(i)];
}

Result<geometry::Pose3> ParseBoardPose(const std::string& text) {
  std::vector<double> v;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    try {
      std::size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size()) v.push_back(NAN);
    } catch (const std::exception&) {
      v.push_back(NAN);
    }
  }
  if (v.size() != 6 || !std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); })) {
    return Status::InvalidInput(
        "--board-pose: expected X,Y,Z,RX,RY,RZ (camera_T_board: metres, rotation vector in "
        "rad), got '" +
        text + "'");
  }
  const Eigen::Vector3d r(v[3], v[4], v[5]);
  const double angle = r.norm();
  const Eigen::Quaterniond q =
      angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, r / angle)) : Eigen::Quaterniond::Identity();
  return geometry::Pose3(q, Eigen::Vector3d(v[0], v[1], v[2]));
}

int RunRender(const RenderArgs& a) {
  std::optional<scene::Scene> scene;
  if (!a.scene_path.empty()) {
    auto loaded = scene::LoadScene(a.scene_path);
    if (!loaded.ok()) return ReportError(loaded.status());
    scene = std::move(*loaded);
  }
  auto spec = ChooseCamera(a, scene ? &*scene : nullptr);
  if (!spec.ok()) return ReportError(spec.status());
  auto camera = vision::Camera::FromSpec(*spec);
  if (!camera.ok()) return ReportError(camera.status());

  worksite::RenderOptions options =
      a.high_contrast ? worksite::RenderOptions::HighContrast() : worksite::RenderOptions{};
  options.supersample = a.supersample;
  if (a.noise_sigma >= 0) options.noise_sigma = a.noise_sigma;
  if (a.blur_sigma_px >= 0) options.blur_sigma_px = a.blur_sigma_px;
  const auto t0 = std::chrono::steady_clock::now();
  auto renderer = worksite::Renderer::Create(*camera, options);
  if (!renderer.ok()) return ReportError(renderer.status());
  const auto t1 = std::chrono::steady_clock::now();
  auto ms = [](auto d) { return std::chrono::duration<double, std::milli>(d).count(); };

  if (!a.chessboard.empty()) {
    auto board = vision::ParseBoardSize(a.chessboard, a.square_m);
    if (!board.ok()) return ReportError(board.status());
    if (a.views > 0) {
      std::error_code ec;
      std::filesystem::create_directories(a.out, ec);
      if (ec) return ReportError(Status::IoError(a.out + ": cannot create the folder: " + ec.message()));
      const auto poses = worksite::SampleBoardPoses(*camera, *board, a.views, a.seed);
      if (static_cast<int>(poses.size()) < a.views) {
        return ReportError(Status::InvalidInput("--views: only " + std::to_string(poses.size()) + " of " +
                                                std::to_string(a.views) +
                                                " board poses fit the image; use a smaller --square"));
      }
      json::Json list = json::Json::array();
      for (std::size_t i = 0; i < poses.size(); ++i) {
        char name[32];
        std::snprintf(name, sizeof(name), "view_%02zu.png", i);
        const std::string path = (std::filesystem::path(a.out) / name).string();
        auto result = worksite::RenderChessboard(*renderer, *board, poses[i], a.seed + i);
        if (Status s = worksite::WritePng(path, result.image); !s.ok()) return ReportError(s);
        list.push_back({{"image", name}, {"camera_T_board", geometry::WritePose(poses[i])}});
      }
      json::Json truth{{"camera", scene::WriteCamera(*spec)},
                       {"board", {{"cols", board->cols}, {"rows", board->rows}, {"square", board->square_m}}},
                       {"views", list}};
      if (Status s = json::WriteJsonFile((std::filesystem::path(a.out) / "views.json").string(), truth);
          !s.ok()) {
        return ReportError(s);
      }
      std::printf("%s: %zu chessboard views (%dx%d inner corners, %.4f m squares), poses in views.json\n",
                  a.out.c_str(), poses.size(), board->cols, board->rows, board->square_m);
      return 0;
    }
    if (a.board_pose.empty())
      return ReportError(Status::InvalidInput("--chessboard needs --board-pose or --views"));
    auto pose = ParseBoardPose(a.board_pose);
    if (!pose.ok()) return ReportError(pose.status());
    auto result = worksite::RenderChessboard(*renderer, *board, *pose, a.seed);
    if (Status s = worksite::WritePng(a.out, result.image); !s.ok()) return ReportError(s);
    std::printf("%s: chessboard view\n", a.out.c_str());
    return 0;
  }

  if (!scene) return ReportError(Status::InvalidInput("render: --scene FILE is required (or --chessboard)"));
  const auto objects = worksite::ObjectsFromScene(*scene);
  const auto t2 = std::chrono::steady_clock::now();
  const worksite::RenderResult result = renderer->Render(objects, a.seed);
  const auto t3 = std::chrono::steady_clock::now();
  if (Status s = worksite::WritePng(a.out, result.image); !s.ok()) return ReportError(s);
  if (!a.truth.empty()) {
    if (Status s = json::WriteJsonFile(a.truth, worksite::TruthToJson(result, *spec, a.seed)); !s.ok()) {
      return ReportError(s);
    }
  }
  std::printf("%s: %dx%d, camera '%s', seed %llu; set-up %.0f ms, image %.0f ms (supersample %d)\n",
              a.out.c_str(), camera->width(), camera->height(), spec->name.c_str(),
              static_cast<unsigned long long>(a.seed), ms(t1 - t0), ms(t3 - t2), options.supersample);
  for (const worksite::ObjectTruth& o : result.objects) {
    std::printf("  %-12s visible %6d px  fraction %.3f\n", o.name.c_str(), o.visible_pixels,
                o.visible_fraction);
  }
  return 0;
}

}  // namespace

void AddRenderCommand(CLI::App& app, Runner* run) {
  auto a = std::make_shared<RenderArgs>();
  CLI::App* sub =
      app.add_subcommand("render", "render the simulated camera's image of a scene, or chessboard views");
  sub->add_option("--scene", a->scene_path, "scene file (JSON, docs/formats.md)");
  sub->add_option("--camera", a->camera_name, "camera of the scene to render from")->capture_default_str();
  sub->add_option("--camera-file", a->camera_file,
                  "camera file (a scene camera entry) instead of --scene's camera");
  sub->add_option("--out", a->out, "output PNG (with --views: output folder)")->required();
  sub->add_option("--truth", a->truth, "also write the truth file (JSON, docs/formats/render.md)");
  sub->add_option("--seed", a->seed, "noise seed: the same seed gives the same image")->capture_default_str();
  sub->add_option("--supersample", a->supersample, "samples per pixel along each axis (anti-aliasing)")
      ->capture_default_str()
      ->check(CLI::Range(1, 8));
  sub->add_option("--noise", a->noise_sigma, "sensor noise sigma, gray levels (default 3)");
  sub->add_option("--blur", a->blur_sigma_px, "blur sigma, px (default 0.85)");
  sub->add_flag("--high-contrast", a->high_contrast, "flat shading, no texture, shadow, blur or noise");
  sub->add_option("--chessboard", a->chessboard, "render a chessboard of COLSxROWS inner corners instead");
  sub->add_option("--square", a->square_m, "chessboard square size, m")->capture_default_str();
  sub->add_option("--board-pose", a->board_pose, "chessboard pose camera_T_board: X,Y,Z,RX,RY,RZ (m, rad)");
  sub->add_option("--views", a->views, "render N random chessboard views into the --out folder");
  sub->callback([a, run] { *run = [a] { return RunRender(*a); }; });
}

}  // namespace teachsim::app
