// Drag scripts: a demonstration without a person (`teachsim simulate`, the demos, the tests).
// The script names the workpiece, capture objects switched on and off at given times, and
// dragger poses at given times; the dragger moves linearly between them and the run ends after
// the last one, once the workpiece settles. Format: docs/formats.md ("Drag script").
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "teachsim/sim/dragger.h"
#include "teachsim/sim/path.h"
#include "teachsim/sim/simulator.h"

namespace teachsim::sim {

struct CaptureInterval {
  std::string object;
  double from_s = 0.0;
  double to_s = 1e300;
};

struct Keyframe {
  double time_s = 0.0;
  Eigen::Vector3d position;                       // the dragger's origin, world
  std::optional<Eigen::Quaterniond> orientation;  // if given, the dragger's orientation pulls too
};

struct DragScript {
  std::string workpiece;
  std::vector<CaptureInterval> capture;
  std::vector<Keyframe> keyframes;  // sorted by time
  double settle_s = 2.0;            // at most this long after the last keyframe
  std::optional<geometry::Pose3> start_pose;  // overrides the scene's pose of the workpiece
};

json::Json ScriptToJson(const DragScript& script);
[[nodiscard]] Result<DragScript> ParseScript(const json::Json& document, const std::string& name);
[[nodiscard]] Result<DragScript> LoadScript(const std::string& file);

struct RunSummary {
  long steps = 0;
  double simulated_s = 0.0;
  double wall_s = 0.0;
  double min_distance_m = 0.0;
  double queries_per_step = 0.0;
  long sticking_events = 0;
  long sticking_resolved = 0;
  std::vector<PathContact> final_contacts;
  geometry::Pose3 final_pose;
  std::vector<double> step_us;  // wall time of each Step() call, for the benchmark
};

// Runs the script in simulated time, as fast as the machine allows. `progress` (optional) is
// called every step with the simulated time and the script's end time.
[[nodiscard]] Result<WorkpiecePath> RunScript(const SimWorld& world, const DragScript& script,
                                              const DraggerOptions& dragger, RunSummary* summary,
                                              const std::function<void(double, double)>& progress = {});

// Groups of contacts by object, e.g. "table(4) frame(4)".
std::string DescribeContacts(const std::vector<PathContact>& contacts);

}  // namespace teachsim::sim
