// The commands of the `teachsim` program (DESIGN.md, "Command line"). Each Add*Command() adds its
// subcommand to `app`; when that subcommand is chosen, its callback stores in *run the function
// that does the work and returns the exit status (0 done, 1 task failed, 2 bad input).
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <string>

#include "teachsim/base/status.h"

namespace teachsim::app {

using Runner = std::function<int()>;

void AddBenchCommand(CLI::App& app, Runner* run);
void AddSceneCommand(CLI::App& app, Runner* run);
void AddSimulateCommand(CLI::App& app, Runner* run);
void AddDemoCommand(CLI::App& app, Runner* run);
void AddPlanCommand(CLI::App& app, Runner* run);
void AddRenderCommand(CLI::App& app, Runner* run);
void AddCalibrateCommand(CLI::App& app, Runner* run);
void AddRobotCommand(CLI::App& app, Runner* run);
void AddExecuteCommand(CLI::App& app, Runner* run);
void AddRecognizeCommand(CLI::App& app, Runner* run);
void AddUpCommand(CLI::App& app, Runner* run);  // up, worksite, operator

// Prints "teachsim: error: MESSAGE" to stderr and returns the status's exit code.
int ReportError(const Status& status);

// Where the project's data lives (scenes/, robots/): $TEACHSIM_HOME, else the source tree.
std::string DataPath(const std::string& relative);

}  // namespace teachsim::app
