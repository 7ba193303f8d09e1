// teachsim execute: runs a robot program on the MuJoCo work site (issue 5; docs/formats/report.md).
//   teachsim execute --scene FILE --program PROGRAM.json [--model-error-mm X] [--model-error-deg Y]
//                    [--seed N] [--report REPORT.json] [--mjcf MODEL.xml]
//                    [--frames DIR [--frame-period S] [--camera NAME]]
// Exit status: 0 the task succeeded, 1 it failed, 2 bad input (unreadable files, a scene without
// the workpiece or robot, a program refused by the safety checks before any motion).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <variant>

#include "commands.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/camera.h"
#include "teachsim/worksite/render.h"
#include "teachsim/worksite/execute.h"

namespace teachsim::app {

namespace {

struct ExecuteArgs {
  std::string scene, program, report, mjcf;
  std::string frames, camera = "main";
  double frame_period_s = 0.5;
  double error_mm = 0, error_deg = 0;
  std::uint64_t seed = 1;
  double friction_bound = -1;  // < 0: the controller's default
  bool no_clip = false;
  double contact_speed_mps = 0;  // > 0: every contact move at this speed (ablation)
};

int RunExecute(const ExecuteArgs& a) {
  auto scene = scene::LoadScene(a.scene);
  if (!scene.ok()) return ReportError(scene.status());
  if (!scene->robot) return ReportError(Status::InvalidInput(a.scene + ": the scene places no robot"));
  auto program = robot::LoadProgram(a.program);
  if (!program.ok()) return ReportError(program.status());
  if (a.contact_speed_mps > 0) {
    for (robot::Command& c : program->commands) {
      if (auto* move = std::get_if<robot::ContactMoveCommand>(&c)) move->speed_mps = a.contact_speed_mps;
    }
  }
  auto model = robot::LoadRobotModel(DataPath("robots/" + scene->robot->model + ".json"));
  if (!model.ok()) return ReportError(model.status());

  worksite::ExecuteOptions options;
  if (a.friction_bound >= 0) options.controller.monitor.friction_bound = a.friction_bound;
  options.controller.admittance.clip_velocity = !a.no_clip;
  if (Status s = options.Validate(); !s.ok()) return ReportError(s);
  if (a.error_mm != 0 || a.error_deg != 0 || a.seed != 1) {
    worksite::ModelError error;
    error.position_m = a.error_mm * 1e-3;
    error.angle_rad = a.error_deg * M_PI / 180;
    error.seed = a.seed;
    if (Status s = error.Validate(); !s.ok()) return ReportError(s);
    options.model_error = error;
  }
  if (!a.mjcf.empty()) {
    auto mjcf = worksite::BuildMjcf(*scene, *model, options.world);
    if (!mjcf.ok()) return ReportError(mjcf.status());
    if (Status s = json::WriteFileAtomic(a.mjcf, *mjcf); !s.ok()) return ReportError(s);
  }
  // Camera frames of the executing world, robot included (issue 6), every frame_period_s simulated.
  std::optional<worksite::Renderer> renderer;
  json::Json frame_list = json::Json::array();
  Status frame_status = Status::Ok();
  if (!a.frames.empty()) {
    if (!(a.frame_period_s > 0)) {
      return ReportError(Status::InvalidInput("--frame-period " + json::FormatNumber(a.frame_period_s) +
                                              ": must be > 0 s"));
    }
    const int c = scene->FindCamera(a.camera);
    if (c < 0) return ReportError(Status::NotFound(a.scene + ": cameras: no camera named '" + a.camera + "'"));
    auto camera = vision::Camera::FromSpec(scene->cameras[static_cast<std::size_t>(c)]);
    if (!camera.ok()) return ReportError(camera.status());
    auto created = worksite::Renderer::Create(*camera, {});
    if (!created.ok()) return ReportError(created.status());
    renderer = std::move(created).value();
    std::error_code ec;
    std::filesystem::create_directories(a.frames, ec);
    if (ec) return ReportError(Status::IoError(a.frames + ": cannot create folder: " + ec.message()));
    double next_frame_s = 0;
    options.on_tick = [&, next_frame_s](const worksite::ExecuteTick& tick) mutable {
      const bool last = tick.state != worksite::ExecutionState::kRunning &&
                        tick.state != worksite::ExecutionState::kStopping;
      if ((tick.t_s + 1e-9 < next_frame_s && !last) || !frame_status.ok()) return;
      next_frame_s += a.frame_period_s;
      const std::size_t index = frame_list.size();
      char name[64];
      std::snprintf(name, sizeof name, "frame_%05zu.png", index);
      const worksite::RenderResult image = renderer->Render(tick.world->RenderObjects(), index + 1);
      frame_status = worksite::WritePng((std::filesystem::path(a.frames) / name).string(), image.image);
      frame_list.push_back({{"image", name},
                            {"t_s", tick.t_s},
                            {"command", tick.command},
                            {"command_type", tick.command_type},
                            {"state", worksite::ExecutionStateName(tick.state)}});
    };
  }
  std::printf(
      "executing %s (%zu commands) on the MuJoCo work site, model error %.1f mm / %.1f deg, seed %llu\n",
      a.program.c_str(), program->commands.size(), a.error_mm, a.error_deg,
      static_cast<unsigned long long>(a.seed));
  auto result = worksite::Execute(*scene, *model, *program, options, [](const std::string& line) {
    std::printf("  %s\n", line.c_str());
    std::fflush(stdout);
  });
  if (!result.ok()) return ReportError(result.status().WithPrefix(a.program));
  if (!frame_status.ok()) return ReportError(frame_status);
  if (renderer) {
    const std::string list = (std::filesystem::path(a.frames) / "frames.json").string();
    if (Status s = json::WriteJsonFile(list, {{"camera", a.camera}, {"frames", frame_list}}); !s.ok()) {
      return ReportError(s);
    }
    std::printf("%zu camera frames -> %s\n", frame_list.size(), list.c_str());
  }
  std::printf("block friction %.2f; %.1f s simulated in %.2f s (%.0fx real time)\n", result->block_friction,
              result->simulated_s, result->wall_s, result->real_time_factor());
  if (result->has_intent) {
    std::printf("workpiece: %.2f mm / %.2f deg from the program's intent\n",
                result->workpiece_position_error_m * 1e3, result->workpiece_angle_error_rad * 180 / M_PI);
  }
  std::printf("%s: %s (peak force %.1f N)\n", result->success ? "SUCCESS" : "FAILED", result->message.c_str(),
              result->report.peak_force_n);
  if (!a.report.empty()) {
    if (Status s = json::WriteJsonFile(a.report, worksite::ExecuteResultToJson(*result, options)); !s.ok()) {
      return ReportError(s);
    }
    std::printf("report -> %s\n", a.report.c_str());
  }
  return result->success ? 0 : 1;
}

}  // namespace

void AddExecuteCommand(CLI::App& app, Runner* run) {
  auto a = std::make_shared<ExecuteArgs>();
  CLI::App* sub =
      app.add_subcommand("execute", "run a robot program on the MuJoCo work site, faster than real time");
  sub->add_option("--scene", a->scene, "the operator's scene (JSON) placing the robot")->required();
  sub->add_option("--program", a->program, "robot program (JSON, docs/formats/program.md)")->required();
  sub->add_option("--model-error-mm", a->error_mm, "move each movable object by up to this much (mm)");
  sub->add_option("--model-error-deg", a->error_deg, "turn each movable object by up to this much (deg)");
  sub->add_option("--seed", a->seed, "seed of the model error and of the block friction (0.1-0.5)");
  sub->add_option("--report", a->report, "write the execution report here (docs/formats/report.md)");
  sub->add_option("--mjcf", a->mjcf, "write the generated MuJoCo model (operator's scene) here");
  sub->add_option(
      "--friction-bound", a->friction_bound,
      "monitor: friction coefficient allowed for at the other contacts (default 0: the plain check)");
  sub->add_flag("--no-clip", a->no_clip, "ablation: no velocity clipping of the admittance output");
  sub->add_option("--contact-speed", a->contact_speed_mps,
                  "ablation: run every contact move at this speed (m/s; the approach speed into contact; the "
                  "safety limit is 0.05)")
      ->check(CLI::Range(0.0001, 0.05));
  sub->add_option("--frames", a->frames,
                  "write camera images of the executing world (robot included) to this folder, with frames.json");
  sub->add_option("--frame-period", a->frame_period_s, "simulated seconds between frames")->capture_default_str();
  sub->add_option("--camera", a->camera, "scene camera for --frames")->capture_default_str();
  sub->callback([a, run] { *run = [a] { return RunExecute(*a); }; });
}

}  // namespace teachsim::app
