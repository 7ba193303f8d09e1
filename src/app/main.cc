// teachsim: program a robot for contact tasks by demonstrating them on a virtual copy of the
// work site (DESIGN.md).
#include <malloc.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "commands.h"

namespace teachsim::app {

int ReportError(const Status& status) {
  std::fprintf(stderr, "teachsim: error: %s\n", status.message().c_str());
  return status.ExitCode();
}

std::string DataPath(const std::string& relative) {
  if (const char* home = std::getenv("TEACHSIM_HOME"); home != nullptr && *home != '\0') {
    return (std::filesystem::path(home) / relative).string();
  }
  return (std::filesystem::path(TEACHSIM_SOURCE_DIR) / relative).string();
}

}  // namespace teachsim::app

int main(int argc, char** argv) {
  using namespace teachsim::app;
  // glibc serves blocks of 128 kB and more with fresh mmap()s and gives the heap's free top back
  // to the system: a process whose first images are recognized before anything larger has been
  // freed page-faults every image's buffers anew (the dev set measured first in `bench recognize
  // --no-peer`: line detection 35 ms per image against 9 ms once warm; docs/benchmarks.md, session
  // 37). Blocks below 32 MB come from the heap, which keeps up to 128 MB free. The first images
  // still page-fault the heap as it grows: `bench recognize` runs each method twice, untimed,
  // before it times any (session 49).
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 128 << 20);
  CLI::App app{"teachsim " TEACHSIM_VERSION
               ": program contact tasks by demonstration on a reality-based virtual environment",
               "teachsim"};
  app.require_subcommand(1);
  app.set_version_flag("--version", TEACHSIM_VERSION);
  Runner run;
  AddSceneCommand(app, &run);
  AddSimulateCommand(app, &run);
  AddDemoCommand(app, &run);
  AddPlanCommand(app, &run);
  AddRenderCommand(app, &run);
  AddCalibrateCommand(app, &run);
  AddRobotCommand(app, &run);
  AddExecuteCommand(app, &run);
  AddRecognizeCommand(app, &run);
  AddUpCommand(app, &run);
  AddBenchCommand(app, &run);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;  // bad input (DESIGN.md)
  }
  if (!run) return 2;
  return run();
}
