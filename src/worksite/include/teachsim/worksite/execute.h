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

// The controller as the work site runs it: the robot module's defaults except the monitor's
// friction allowance, which is 0 (the paper's plain check, §6.2). With the allowance at 0.5 a
// corner (three orthogonal contacts, each pressed with K d) can never verify: the allowance along
// each normal, 0.5 (K d + K d), equals the force itself (measured: 1.0-1.3 N read, 1.4-1.6 N allowed).
robot::ControllerOptions WorksiteControllerOptions();

struct ExecuteOptions {
  robot::ControllerOptions controller = WorksiteControllerOptions();
  MujocoWorldOptions world;
  std::optional<ModelError> model_error;  // none: the world is the operator's scene
  double max_time_s = 600;                // simulated; a program still running then has failed
  double report_sample_period_s = 0.05;   // force history in the report, downsampled
  [[nodiscard]] Status Validate() const;
};

struct ExecuteResult {
  robot::ExecutionReport report;  // the controller's (per command status, contacts, forces)
  bool success = false;
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
