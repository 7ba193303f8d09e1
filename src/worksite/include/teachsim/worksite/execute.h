// Running a robot program on the MuJoCo work site (issue 5, item 6; `teachsim execute`): the
// task controller at 100 Hz over the simulated arm's 1 kHz servos, as fast as the machine allows,
// in a world that may differ from the operator's scene by a model error. The result carries the
// controller's execution report plus what only the simulator knows: the workpiece's true final
// pose against the program's intent. Report format: docs/formats/report.md.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/robot/controller.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/worksite/mujoco_world.h"

namespace teachsim::worksite {

// The controller as the work site runs it: the robot module's defaults, with the monitor
// assuming friction up to 0.5 at every contact (the world draws its block friction from 0.1-0.5).
robot::ControllerOptions WorksiteControllerOptions();

// Where an execution stands, after each controller cycle (ExecuteOptions::on_tick).
enum class ExecutionState {
  kRunning,    // the program runs
  kStopping,   // a stop was requested: the arm decelerates (ControllerOptions::stop_time_s)
  kStopped,    // it came to rest and holds (the program did not finish)
  kSucceeded,  // every command reached, every contact verified
  kFailed,     // a command failed, was refused or aborted, or the time ran out
};
const char* ExecutionStateName(ExecutionState state);  // "running", "stopping", ...

struct ExecuteTick {
  double t_s = 0;                 // simulated, since the program started
  std::size_t command = 0;        // the command running now (or the last one run)
  std::size_t command_count = 0;  // in the program
  std::string command_type;       // "grasp", "move", "contact_move", ...
  robot::CommandStatus command_status = robot::CommandStatus::kPending;
  ExecutionState state = ExecutionState::kRunning;
  double force_n = 0;  // magnitude of the force on the tool as the controller read it this cycle
  // The simulated world as of this cycle (RenderObjects() for camera frames, ground truth).
  // Valid during the call only; never give it to the controller.
  const MujocoWorld* world = nullptr;
};

struct ExecuteOptions {
  robot::ControllerOptions controller = WorksiteControllerOptions();
  MujocoWorldOptions world;
  std::optional<ModelError> model_error;  // none: the world is the operator's scene
  double max_time_s = 600;                // simulated; a program still running then has failed
  double report_sample_period_s = 0.05;   // force history in the report, downsampled
  // Hooks for a service driving the execution (all optional, called on Execute's thread):
  // after every controller cycle (100 Hz simulated), including the last one (state final);
  std::function<void(const ExecuteTick&)> on_tick;
  // checked every cycle: true asks for a controlled stop (decelerate, hold within 0.1 s
  // simulated; the result is `stopped`);
  std::function<bool()> stop_requested;
  // called every cycle with the simulated time since the program started, before the physics
  // advances: a caller that wants real time sleeps here until its wall clock reaches t_s.
  std::function<void(double t_s)> pace;
  [[nodiscard]] Status Validate() const;
};

struct ExecuteResult {
  robot::ExecutionReport report;  // the controller's (per command status, contacts, forces)
  bool success = false;
  bool stopped = false;  // ended by ExecuteOptions::stop_requested (then success is false)
  std::string message;
  double block_friction = 0;  // of the simulated world
  // The program's intent: the last move / contact move target while holding, composed with the grasp.
  bool has_intent = false;
  geometry::Pose3 intended_world_T_workpiece, final_world_T_workpiece;
  double workpiece_position_error_m = 0, workpiece_angle_error_rad = 0;
  double simulated_s = 0, wall_s = 0;
  long physics_steps = 0;
  std::vector<double> cycle_us;  // the controller's Cycle() wall time, per cycle
  double real_time_factor() const { return wall_s > 0 ? simulated_s / wall_s : 0; }
};

// The intent of a program: where the workpiece should end (see ExecuteResult); false if the
// program never moves while holding it.
bool IntendedWorkpiecePose(const robot::Program& program, geometry::Pose3* world_T_workpiece);

// Errors (InvalidInput, exit status 2): a scene without a robot or without the program's
// workpiece, an invalid program, a program refused by the safety checks before any motion.
// `progress` receives one line per finished command.
[[nodiscard]] Result<ExecuteResult> Execute(const scene::Scene& operator_scene,
                                            const robot::RobotModel& model, const robot::Program& program,
                                            const ExecuteOptions& options,
                                            const std::function<void(const std::string&)>& progress = {});

json::Json ExecuteResultToJson(const ExecuteResult& result, const ExecuteOptions& options);

}  // namespace teachsim::worksite
