// teachsim simulate --scene FILE --script DRAGS.json --out PATH.json
#include <unistd.h>

#include <memory>

#include "commands.h"
#include "teachsim/sim/script.h"

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

}  // namespace teachsim::app
