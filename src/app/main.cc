// teachsim: program a robot for contact tasks by demonstrating them on a virtual copy of the
// work site (DESIGN.md).
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
