// teachsim demo [cornering|around-corner|all] [--out DIR] [--seed N] [--scene FILE] [--cache DIR]
// The paper's demonstrations end to end (issue 9): camera image, recognition, demonstration,
// program, execution on the MuJoCo work site, verification; the report in DIR (report.html,
// demo_summary.json, figures). Exit 0 when every demonstration verifies, 1 when one fails (the
// failing stage is named), 2 on bad input.
#include <cstdlib>
#include <filesystem>
#include <memory>

#include "commands.h"
#include "demo_pipeline.h"

namespace teachsim::app {

std::string DefaultRecognizerCache() {
  if (const char* dir = std::getenv("TEACHSIM_CACHE"); dir != nullptr && *dir != '\0') {
    return (std::filesystem::path(dir) / "recognizer").string();
  }
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    return (std::filesystem::path(home) / ".cache" / "teachsim" / "recognizer").string();
  }
  return "";
}

int RunDemoCommand(const DemoOptions& options) {
  auto result = RunDemoPipeline(options);
  if (!result.ok()) return ReportError(result.status());
  if (Status s = WriteDemoReport(*result); !s.ok()) return ReportError(s);
  const std::string report = (std::filesystem::path(options.out_dir) / "report.html").string();
  for (const DemoRun& run : result->runs) {
    if (run.success) {
      std::printf("demo %-14s SUCCESS: every command reached, every contact verified\n", run.name.c_str());
    } else {
      std::printf("demo %-14s FAILED at stage %d/%d (%s): %s\n", run.name.c_str(), run.failed_stage, kDemoStages,
                  kDemoStageNames[run.failed_stage - 1], run.message.c_str());
    }
  }
  std::printf("report: %s (%.1f s)\n", report.c_str(), result->total_s);
  return result->success() ? 0 : 1;
}

void AddDemoCommand(CLI::App& app, Runner* run) {
  auto o = std::make_shared<DemoOptions>();
  o->scene_path = DataPath("scenes/puzzle.json");
  o->cache_dir = DefaultRecognizerCache();
  CLI::App* sub = app.add_subcommand(
      "demo", "the paper's demonstrations end to end, camera image to verified execution, with a report");
  sub->add_option("which", o->which, "cornering (Figure 1), around-corner (Figure 2) or all")->capture_default_str();
  sub->add_option("--scene", o->scene_path, "the operator's scene: fixed world, camera, robot, model library")
      ->capture_default_str();
  sub->add_option("--out", o->out_dir, "folder for report.html, demo_summary.json, figures and files")
      ->capture_default_str();
  sub->add_option("--seed", o->seed, "perturbs the blocks and the camera of the work site's world (0: none)")
      ->capture_default_str();
  sub->add_option("--cache", o->cache_dir, "the recognizer's model-view index cache (\"\": none)")
      ->capture_default_str();
  sub->callback([o, run] { *run = [o] { return RunDemoCommand(*o); }; });
}

}  // namespace teachsim::app
