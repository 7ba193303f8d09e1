// teachsim plan --scene FILE --path PATH.json --out PROGRAM.json [--listing] [--paths-prefix P]
#include <cmath>
#include <memory>
#include <optional>

#include "commands.h"
#include "plan_report.h"
#include "teachsim/plan/planner.h"

namespace teachsim::app {

void PrintPlanMetrics(const plan::PlanMetrics& m) {
  std::printf("  path length         %.1f mm -> %.1f mm (%+.0f %%)\n", m.length_before_m * 1e3, m.length_after_m * 1e3,
              m.length_before_m > 0 ? 100.0 * (m.length_after_m / m.length_before_m - 1.0) : 0.0);
  std::printf("  nodes               %d demonstrated, %d in the band, %d knots\n", m.nodes_before, m.nodes_deformed, m.knots);
  std::printf("  commands            %d (%d motions)\n", m.commands, m.motion_commands);
  auto mm = [](double v) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.1f mm", v * 1e3);
    return std::isfinite(v) ? std::string(text) : std::string("no obstacle near");
  };
  std::printf("  clearance           %s demonstrated -> %s programmed (to unwanted obstacles, away from contacts)\n",
              mm(m.min_clearance_before_m).c_str(), mm(m.min_clearance_after_m).c_str());
  std::printf("  required contacts   %s (%d nodes)\n", m.required_contacts_kept ? "kept" : "NOT KEPT", m.required_nodes);
  std::printf("  deformation         %d iterations (%s), %.1f ms; simplification %.1f ms; total %.1f ms\n",
              m.iterations, m.band_converged ? "settled" : "budget used up, not settled", m.deform_ms, m.simplify_ms,
              m.total_ms);
  if (m.robot_checked) {
    std::printf("  grasp               turned %.0f deg about the tool axis; gripper %.1f mm from the scene; "
                "|sin theta5| >= %.2f, elbow >= %.2f, shoulder >= %.0f mm\n",
                m.grasp_yaw_deg, m.min_gripper_clearance_m * 1e3, m.min_wrist_measure, m.min_elbow_measure,
                m.min_shoulder_m * 1e3);
  } else {
    std::printf("  grasp               unchecked (no robot)\n");
  }
}

Status WritePlanOutputs(const plan::PlanResult& result, const std::string& program_file, const std::string& prefix) {
  TEACHSIM_RETURN_IF_ERROR(robot::SaveProgram(result.program, program_file));
  if (!prefix.empty()) {
    TEACHSIM_RETURN_IF_ERROR(sim::SavePath(result.initial, prefix + "initial.path.json"));
    TEACHSIM_RETURN_IF_ERROR(sim::SavePath(result.deformed, prefix + "deformed.path.json"));
    TEACHSIM_RETURN_IF_ERROR(sim::SavePath(result.simplified, prefix + "simplified.path.json"));
  }
  return Status::Ok();
}

namespace {

int RunPlan(const std::string& scene_path, const std::string& path_file, const std::string& out, bool listing,
            const std::string& prefix) {
  auto scene = scene::LoadScene(scene_path);
  if (!scene.ok()) return ReportError(scene.status());
  auto path = sim::LoadPath(path_file);
  if (!path.ok()) return ReportError(path.status());
  // The arm the scene places: the grasp is chosen and checked with it (reach, limits,
  // singularities, the gripper against the scene).
  std::optional<robot::RobotModel> model;
  if (scene->robot) {
    auto loaded = robot::LoadRobotModel(DataPath("robots/" + scene->robot->model + ".json"));
    if (!loaded.ok()) return ReportError(loaded.status());
    model = std::move(loaded).value();
  }
  auto result = plan::GenerateProgram(*scene, *path, {}, model ? &*model : nullptr);
  if (!result.ok()) return ReportError(result.status().WithPrefix(path_file));
  if (Status s = WritePlanOutputs(*result, out, prefix); !s.ok()) return ReportError(s);
  std::printf("program for '%s' -> %s\n", result->program.workpiece.c_str(), out.c_str());
  PrintPlanMetrics(result->metrics);
  if (listing) std::printf("%s", robot::ProgramListing(result->program).c_str());
  return result->metrics.required_contacts_kept ? 0 : 1;
}

}  // namespace

void AddPlanCommand(CLI::App& app, Runner* run) {
  struct Options {
    std::string scene, path, out, prefix;
    bool listing = false;
  };
  auto o = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("plan", "deform and simplify a workpiece path and write the robot program");
  sub->add_option("--scene", o->scene, "scene file")->required();
  sub->add_option("--path", o->path, "workpiece path (from teachsim simulate)")->required();
  sub->add_option("--out", o->out, "robot program to write (docs/formats/program.md)")->required();
  sub->add_flag("--listing", o->listing, "print the program, one line per command");
  sub->add_option("--paths-prefix", o->prefix, "also write PREFIXinitial/deformed/simplified.path.json");
  sub->callback([o, run] { *run = [o] { return RunPlan(o->scene, o->path, o->out, o->listing, o->prefix); }; });
}

}  // namespace teachsim::app
