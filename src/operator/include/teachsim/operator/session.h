// Saved sessions of the operator site (issue 8, item 3): the world model (a scene), the
// demonstration (a workpiece path), the generated paths and program, and the last execution
// report, in one JSON file written atomically (docs/formats/session.md). Loading checks every part
// with its own reader, so an error names the file and the JSON path.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/robot/program.h"
#include "teachsim/scene/scene.h"
#include "teachsim/sim/path.h"

namespace teachsim::op {

struct SessionReport {
  std::string program_id;
  bool ok = false;
  json::Json report;  // the work site's report (docs/formats/report.md)
};

struct SessionData {
  scene::Scene scene;                    // the world model as it is now
  std::vector<std::string> recognized;   // objects of `scene` added from recognitions
  std::optional<std::string> workpiece;  // the selected object
  std::vector<std::string> capture;      // capture objects
  std::optional<sim::WorkpiecePath> path;  // the demonstration
  std::optional<sim::WorkpiecePath> deformed, simplified;
  std::optional<robot::Program> program;
  std::string program_id;
  std::optional<SessionReport> report;
};

json::Json SessionToJson(const SessionData& session);
// `name` stands for the file in error messages.
[[nodiscard]] Result<SessionData> ParseSession(const json::Json& document, const std::string& name);
[[nodiscard]] Result<SessionData> LoadSession(const std::string& path);
[[nodiscard]] Status SaveSession(const SessionData& session, const std::string& path);  // atomic

}  // namespace teachsim::op
