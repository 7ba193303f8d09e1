#include "teachsim/worksite/execute.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <variant>

namespace teachsim::worksite {

robot::ControllerOptions WorksiteControllerOptions() {
  robot::ControllerOptions options;
  options.monitor.friction_bound = 0.5;  // the block friction is drawn from 0.1-0.5
  return options;
}

const char* ExecutionStateName(ExecutionState state) {
  switch (state) {
    case ExecutionState::kRunning:
      return "running";
    case ExecutionState::kStopping:
      return "stopping";
    case ExecutionState::kStopped:
      return "stopped";
    case ExecutionState::kSucceeded:
      return "succeeded";
    case ExecutionState::kFailed:
      return "failed";
  }
  return "?";
}

Status ExecuteOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(controller.Validate());
  TEACHSIM_RETURN_IF_ERROR(world.Validate());
  if (model_error) TEACHSIM_RETURN_IF_ERROR(model_error->Validate());
  if (!(max_time_s > 0)) return Status::InvalidInput("ExecuteOptions::max_time_s must be > 0");
  if (!(report_sample_period_s >= 0)) {
    return Status::InvalidInput("ExecuteOptions::report_sample_period_s must be >= 0");
  }
  return Status::Ok();
}

bool IntendedWorkpiecePose(const robot::Program& program, geometry::Pose3* world_T_workpiece) {
  bool holding = false, found = false;
  const geometry::Pose3 tool_T_workpiece = program.workpiece_T_tool.Inverse();
  for (const robot::Command& command : program.commands) {
    if (std::holds_alternative<robot::GraspCommand>(command)) holding = true;
    if (std::holds_alternative<robot::ReleaseCommand>(command)) holding = false;
    if (!holding) continue;
    const geometry::Pose3* target = nullptr;
    if (const auto* m = std::get_if<robot::MoveCommand>(&command)) target = &m->world_T_tool;
    if (const auto* c = std::get_if<robot::ContactMoveCommand>(&command)) target = &c->world_T_tool;
    if (target) {
      *world_T_workpiece = *target * tool_T_workpiece;
      found = true;
    }
  }
  return found;
}

Result<ExecuteResult> Execute(const scene::Scene& operator_scene, const robot::RobotModel& model,
                              const robot::Program& program, const ExecuteOptions& options,
                              const std::function<void(const std::string&)>& progress) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  TEACHSIM_RETURN_IF_ERROR(program.Validate());
  if (!operator_scene.robot) return Status::InvalidInput("the scene places no robot (its \"robot\" entry)");
  const int workpiece = operator_scene.FindObject(program.workpiece);
  if (workpiece < 0) {
    return Status::InvalidInput("the scene has no object \"" + program.workpiece +
                                "\", the program's workpiece");
  }
  if (operator_scene.objects[static_cast<std::size_t>(workpiece)].fixed) {
    return Status::InvalidInput("the program's workpiece \"" + program.workpiece +
                                "\" is fixed in the scene");
  }

  ExecuteResult result;
  scene::Scene world_scene = operator_scene;
  MujocoWorldOptions world_options = options.world;
  if (options.model_error) {
    PerturbedWorld perturbed = PerturbScene(operator_scene, *options.model_error);
    world_scene = std::move(perturbed.scene);
    world_options.block_friction = perturbed.block_friction;
  }
  result.block_friction = world_options.block_friction;
  auto world = MujocoWorld::Create(world_scene, model, world_options);
  if (!world.ok()) return world.status();
  MujocoWorld& io = **world;

  // The controller works in the operator's frame: the robot's placement is known exactly (it is
  // calibrated), only the objects carry the model error.
  robot::TaskController controller(model, operator_scene.robot->world_T_base, options.controller);
  const double t0 = io.time_s();
  if (Status started = controller.Start(program, io, 0.0); !started.ok()) return started;

  using Clock = std::chrono::steady_clock;
  const auto wall0 = Clock::now();
  const double cycle_s = options.controller.cycle_s;
  std::size_t reported = 0;
  auto report_progress = [&](bool final) {
    const robot::ExecutionReport& r = controller.report();
    while (reported < r.commands.size()) {
      const robot::CommandReport& c = r.commands[reported];
      const bool done =
          c.status != robot::CommandStatus::kPending && c.status != robot::CommandStatus::kRunning;
      if (!done && !final) break;
      if (progress) {
        char line[512];
        std::snprintf(line, sizeof line, "commands[%zu] %-12s %-11s t=%6.2f s  peak %5.1f N%s%s", reported,
                      c.type.c_str(), robot::CommandStatusName(c.status), c.end_s, c.peak_force_n,
                      c.message.empty() ? "" : "  ", c.message.c_str());
        progress(line);
      }
      ++reported;
    }
  };
  double t_s = 0;
  result.cycle_us.reserve(static_cast<std::size_t>(120.0 / cycle_s));
  ExecuteTick tick;
  tick.command_count = program.commands.size();
  tick.world = &io;
  while (true) {
    if (options.stop_requested && !controller.stopping() && options.stop_requested()) controller.RequestStop();
    const auto c0 = Clock::now();
    const bool running = controller.Cycle(io, t_s);
    result.cycle_us.push_back(std::chrono::duration<double, std::micro>(Clock::now() - c0).count());
    report_progress(false);
    const bool timed_out = running && t_s > options.max_time_s;
    if (options.on_tick) {
      const robot::ExecutionReport& r = controller.report();
      tick.t_s = t_s;
      tick.command = controller.current_command();
      tick.command_type = r.commands[tick.command].type;
      tick.command_status = r.commands[tick.command].status;
      tick.force_n = controller.last_force_n().norm();
      if (running && !timed_out) {
        tick.state = controller.stopping() ? ExecutionState::kStopping : ExecutionState::kRunning;
      } else if (r.stopped) {
        tick.state = ExecutionState::kStopped;
      } else {
        tick.state = r.success ? ExecutionState::kSucceeded : ExecutionState::kFailed;
      }
      options.on_tick(tick);
    }
    if (!running || timed_out) break;
    if (options.pace) options.pace(t_s);
    io.Advance(cycle_s);
    t_s += cycle_s;
  }
  result.wall_s = std::chrono::duration<double>(Clock::now() - wall0).count();
  result.simulated_s = io.time_s() - t0;
  result.physics_steps = io.steps();
  result.report = controller.report();
  report_progress(true);
  if (!result.report.finished) {
    result.report.success = false;
    result.report.message =
        "the program did not finish within " + json::FormatNumber(options.max_time_s) + " s";
  }
  result.success = result.report.success;
  result.stopped = result.report.stopped;
  result.message = result.report.message;
  result.final_world_T_workpiece = io.ObjectPose(program.workpiece);
  result.has_intent = IntendedWorkpiecePose(program, &result.intended_world_T_workpiece);
  if (result.has_intent) {
    result.workpiece_position_error_m =
        geometry::TranslationDistance(result.final_world_T_workpiece, result.intended_world_T_workpiece);
    result.workpiece_angle_error_rad =
        geometry::RotationAngle(result.final_world_T_workpiece, result.intended_world_T_workpiece);
  }
  return result;
}

json::Json ExecuteResultToJson(const ExecuteResult& result, const ExecuteOptions& options) {
  json::Json doc = robot::ExecutionReportToJson(result.report, false);
  // The force history, downsampled to report_sample_period_s.
  for (std::size_t i = 0; i < result.report.commands.size(); ++i) {
    json::Json t = json::Json::array(), f = json::Json::array();
    double next = -1e300;
    for (const robot::ForceSample& s : result.report.commands[i].forces) {
      if (s.t_s + 1e-9 < next) continue;
      next = s.t_s + options.report_sample_period_s;
      t.push_back(s.t_s);
      f.push_back({s.force_n.x(), s.force_n.y(), s.force_n.z()});
    }
    doc["commands"][i]["forces"] = {{"t_s", t}, {"force_n", f}};
  }
  doc["format"] = "teachsim-execution-report";
  doc["success"] = result.success;
  doc["stopped"] = result.stopped;
  doc["message"] = result.message;
  bool all_contacts = true;
  for (const robot::CommandReport& c : result.report.commands)
    all_contacts = all_contacts && c.contacts_verified;
  doc["contacts_verified"] = all_contacts;
  doc["peak_force_n"] = result.report.peak_force_n;
  json::Json world = {
      {"block_friction", result.block_friction},
      {"model_error_mm", options.model_error ? options.model_error->position_m * 1e3 : 0.0},
      {"model_error_deg", options.model_error ? options.model_error->angle_rad * 180 / M_PI : 0.0}};
  if (options.model_error) world["seed"] = options.model_error->seed;
  doc["world"] = world;
  json::Json wp = {{"final", geometry::WritePose(result.final_world_T_workpiece)}};
  if (result.has_intent) {
    wp["intended"] = geometry::WritePose(result.intended_world_T_workpiece);
    wp["position_error_m"] = result.workpiece_position_error_m;
    wp["angle_error_deg"] = result.workpiece_angle_error_rad * 180 / M_PI;
  }
  doc["workpiece"] = wp;
  doc["timing"] = {{"simulated_s", result.simulated_s},
                   {"wall_s", result.wall_s},
                   {"real_time_factor", result.real_time_factor()},
                   {"physics_steps", result.physics_steps}};
  return doc;
}

}  // namespace teachsim::worksite
