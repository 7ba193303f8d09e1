// Safety checks before any motion (issue 5, item 7): a command whose path leaves the workspace,
// passes beyond reach or the joint limits, needs joint speeds the arm does not have (near a
// singularity), or asks for more than the speed limit is refused with a clear error.
#pragma once

#include <string>

#include "teachsim/base/status.h"
#include "teachsim/geometry/aabb.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/robot/trajectory.h"

namespace teachsim::robot {

struct SafetyOptions {
  // Where the tool's origin may go, world frame (the work site sets it from its scene).
  geometry::Aabb workspace{Eigen::Vector3d(-0.3, -0.3, 0.0), Eigen::Vector3d(0.3, 0.3, 0.4)};
  double max_tool_speed_mps = 0.25;     // ISO 10218-1 reduced speed
  double max_contact_speed_mps = 0.05;  // contact moves go slower (paper §6.2)
  double path_step_m = 0.002;           // path sampling for the joint-space checks
  double path_step_rad = 0.01;
  double joint_speed_fraction = 1.0;  // of each joint's max speed that a path may ask for
  [[nodiscard]] Status Validate() const;
};

// Checks one straight line from `start` (reached with joints `start_joints`) to `goal` at the peak
// tool speed `speed_mps` (angular speed per `limits`); on success *end_joints holds the joints at
// the goal. `what` names the command in messages ("commands[2] (move)").
[[nodiscard]] Status CheckLine(const RobotModel& model, const geometry::Pose3& world_T_base,
                               const geometry::Pose3& world_T_start, const geometry::Pose3& world_T_goal,
                               const Joints& start_joints, const MotionLimits& limits,
                               const SafetyOptions& options, const std::string& what, Joints* end_joints);

// Checks every motion and gripper width of a program, starting from `current` joints. Errors are
// InvalidInput "refused: commands[3] (contact_move): ...".
[[nodiscard]] Status CheckProgram(const RobotModel& model, const geometry::Pose3& world_T_base,
                                  const Program& program, const Joints& current, const MotionLimits& limits,
                                  const SafetyOptions& options);

}  // namespace teachsim::robot
