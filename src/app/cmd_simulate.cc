// teachsim simulate --scene FILE --script DRAGS.json --out PATH.json
// teachsim demo [cornering|around-corner|all] [--out DIR] [--seed N]
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "plan_report.h"
#include "teachsim/sim/demos.h"
#include "teachsim/sim/script.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/worksite/execute.h"

namespace teachsim::app {

namespace {

void PrintSummary(const std::string& title, const sim::RunSummary& s) {
  std::printf("%s\n", title.c_str());
  std::printf("  steps               %ld (%.2f s simulated in %.3f s: %.0fx real time)\n", s.steps, s.simulated_s,
              s.wall_s, s.wall_s > 0 ? s.simulated_s / s.wall_s : 0.0);
  std::printf("  final contacts      %s\n", sim::DescribeContacts(s.final_contacts).c_str());
  const Eigen::Vector3d& p = s.final_pose.translation;
  std::printf("  final position      (%.2f, %.2f, %.2f) mm\n", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  std::printf("  minimum distance    %.4f mm (over the continuous motion)\n", s.min_distance_m * 1e3);
  std::printf("  distance queries    %.1f per step\n", s.queries_per_step);
  std::printf("  sticking events     %ld (%ld blocked steps resolved by re-projection)\n", s.sticking_events,
              s.sticking_resolved);
}

// A progress line on a terminal, nothing when output is redirected.
std::function<void(double, double)> ProgressLine(const std::string& label) {
  if (!isatty(fileno(stdout))) return {};
  return [label](double t, double end) {
    std::printf("\r  %s: %5.1f / %.1f s simulated", label.c_str(), t, end);
    if (t >= end - 1e-9) std::printf("\n");
    std::fflush(stdout);
  };
}

int RunSimulate(const std::string& scene_path, const std::string& script_path, const std::string& out) {
  auto scene = scene::LoadScene(scene_path);
  if (!scene.ok()) return ReportError(scene.status());
  auto script = sim::LoadScript(script_path);
  if (!script.ok()) return ReportError(script.status());
  auto world = sim::SimWorld::Build(std::move(scene).value(), {});
  if (!world.ok()) return ReportError(world.status());
  sim::RunSummary summary;
  auto path = sim::RunScript(*world, *script, {}, &summary, ProgressLine("simulate"));
  if (!path.ok()) return ReportError(path.status().WithPrefix(script_path));
  if (Status saved = sim::SavePath(*path, out); !saved.ok()) return ReportError(saved);
  PrintSummary("simulated '" + script->workpiece + "': " + std::to_string(path->nodes.size()) + " nodes -> " + out,
               summary);
  return 0;
}

int RunDemo(const std::string& which, const std::string& scene_path, const std::string& out_dir, std::uint64_t seed) {
  if (which != "cornering" && which != "around-corner" && which != "all") {
    return ReportError(Status::InvalidInput("demo: unknown demonstration '" + which +
                                            "' (cornering, around-corner or all)"));
  }
  auto scene = scene::LoadScene(scene_path);
  if (!scene.ok()) return ReportError(scene.status());
  auto world = sim::SimWorld::Build(scene.value(), {});
  if (!world.ok()) return ReportError(world.status());
  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) return ReportError(Status::IoError(out_dir + ": cannot create folder: " + ec.message()));
  int failures = 0;
  for (const std::string name : {"cornering", "around-corner"}) {
    if (which != "all" && which != name) continue;
    sim::CorneringVariation variation;
    if (seed != 0) variation = sim::RandomCornering(seed);
    auto script = name == "cornering" ? sim::CorneringScript(*scene, variation) : sim::AroundCornerScript(*scene);
    if (!script.ok()) return ReportError(script.status().WithPrefix(scene_path));
    sim::RunSummary summary;
    auto path = sim::RunScript(*world, *script, {}, &summary, ProgressLine(name));
    if (!path.ok()) return ReportError(path.status());
    const std::string file = (std::filesystem::path(out_dir) / (name + ".path.json")).string();
    if (Status saved = sim::SavePath(*path, file); !saved.ok()) return ReportError(saved);
    const std::string script_file = (std::filesystem::path(out_dir) / (name + ".drags.json")).string();
    if (Status saved = json::WriteJsonFile(script_file, sim::ScriptToJson(*script)); !saved.ok()) {
      return ReportError(saved);
    }
    PrintSummary("demo " + name + ": " + std::to_string(path->nodes.size()) + " nodes -> " + file, summary);
    if (summary.sticking_events > 0) ++failures;
    // Program generation (paper §6).
    auto planned = plan::GenerateProgram(*scene, *path);
    if (!planned.ok()) {
      std::printf("  planning failed: %s\n", planned.status().message().c_str());
      ++failures;
      continue;
    }
    const std::string program_file = (std::filesystem::path(out_dir) / (name + ".program.json")).string();
    const std::string prefix = (std::filesystem::path(out_dir) / (name + ".")).string();
    if (Status s = WritePlanOutputs(*planned, program_file, prefix); !s.ok()) return ReportError(s);
    std::printf("  program             -> %s\n", program_file.c_str());
    PrintPlanMetrics(planned->metrics);
    std::printf("%s", robot::ProgramListing(planned->program).c_str());
    if (!planned->metrics.required_contacts_kept) ++failures;
    // Execution on the (MuJoCo-simulated) work site, with the monitor verifying the contacts.
    if (!scene->robot) return ReportError(Status::InvalidInput(scene_path + ": robot: missing (the demo executes on it)"));
    auto model = robot::LoadRobotModel(DataPath("robots/" + scene->robot->model + ".json"));
    if (!model.ok()) return ReportError(model.status());
    worksite::ExecuteOptions execute_options;
    auto executed = worksite::Execute(*scene, *model, planned->program, execute_options);
    if (!executed.ok()) {
      std::printf("  execution refused: %s\n", executed.status().message().c_str());
      ++failures;
      continue;
    }
    const std::string report_file = (std::filesystem::path(out_dir) / (name + ".report.json")).string();
    if (Status s = json::WriteJsonFile(report_file, worksite::ExecuteResultToJson(*executed, execute_options)); !s.ok()) {
      return ReportError(s);
    }
    std::printf("  execution           %s: %s (%.1f s simulated, %.0fx real time; workpiece %.2f mm / %.2f deg from "
                "the intent) -> %s\n",
                executed->success ? "SUCCESS" : "FAILED", executed->message.c_str(), executed->simulated_s,
                executed->real_time_factor(), executed->workpiece_position_error_m * 1e3,
                executed->workpiece_angle_error_rad * 180.0 / M_PI, report_file.c_str());
    if (!executed->success) ++failures;
  }
  return failures > 0 ? 1 : 0;
}

}  // namespace

void AddSimulateCommand(CLI::App& app, Runner* run) {
  struct Options {
    std::string scene, script, out;
  };
  auto o = std::make_shared<Options>();
  CLI::App* sub = app.add_subcommand("simulate", "run a drag script through the task simulator; write the workpiece path");
  sub->add_option("--scene", o->scene, "scene file (docs/formats.md)")->required();
  sub->add_option("--script", o->script, "drag script (docs/formats.md)")->required();
  sub->add_option("--out", o->out, "workpiece path to write")->required();
  sub->callback([o, run] { *run = [o] { return RunSimulate(o->scene, o->script, o->out); }; });
}

void AddDemoCommand(CLI::App& app, Runner* run) {
  struct Options {
    std::string which = "all";
    std::string scene;
    std::string out = "demo-out";
    std::uint64_t seed = 0;
  };
  auto o = std::make_shared<Options>();
  o->scene = DataPath("scenes/puzzle.json");
  CLI::App* sub = app.add_subcommand("demo", "the paper's demonstrations: cornering (Figure 1), around-corner (Figure 2)");
  sub->add_option("which", o->which, "cornering, around-corner or all")->capture_default_str();
  sub->add_option("--scene", o->scene, "scene (default: scenes/puzzle.json)")->capture_default_str();
  sub->add_option("--out", o->out, "folder for the paths and scripts")->capture_default_str();
  sub->add_option("--seed", o->seed, "vary the cornering start (0: the scene's start)")->capture_default_str();
  sub->callback([o, run] { *run = [o] { return RunDemo(o->which, o->scene, o->out, o->seed); }; });
}

}  // namespace teachsim::app
