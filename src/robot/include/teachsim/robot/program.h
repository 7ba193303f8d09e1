// The robot program (docs/formats/program.md): what the program generator writes and the work
// site's task controller runs (paper §6.2). Every pose is of the gripper's tool frame in the world.
#pragma once

#include <Eigen/Core>
#include <string>
#include <variant>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::robot {

// Guarded grasp: open, move (free, at `approach_speed_mps`) to the approach pose
// `approach_height_m` above `world_T_tool`, descend straight down (world -z) at `speed_mps` until the force
// pushing the tool up exceeds `contact_force_n` or the planned grasp pose is reached, then close to
// `width_m`.
struct GraspCommand {
  geometry::Pose3 world_T_tool;
  double approach_height_m = 0.05;
  double approach_speed_mps = 0.1;
  double speed_mps = 0.02;
  double contact_force_n = 5.0;
  double open_width_m = 0.07;
  double width_m = 0.045;  // the block's width across the jaws
  geometry::Pose3 ApproachPose() const;
};

// Free motion: a straight Cartesian line, position-controlled; any force is unexpected.
struct MoveCommand {
  geometry::Pose3 world_T_tool;
  double speed_mps = 0.1;
};

// Compliant motion into a contact state (paper §6.2): straight line to world_T_tool + bias_m at a
// lowered speed under a low, uniform spring–damper impedance; verified when the force along each
// contact normal exceeds its threshold.
struct ContactMoveCommand {
  geometry::Pose3 world_T_tool;                      // the nominal target (the contact state as demonstrated)
  Eigen::Matrix3Xd normals;                          // N: world, unit, from the obstacle toward the workpiece
  std::vector<double> force_thresholds_n;            // one per normal
  Eigen::Vector3d bias_m = Eigen::Vector3d::Zero();  // delta_p, solving d 1 = -N^T delta_p
  double stiffness_n_per_m = 300;
  double damping_n_s_per_m = 1000;
  double speed_mps = 0.01;
  geometry::Pose3 BiasedTarget() const;
};

struct ReleaseCommand {
  double width_m = 0.07;  // open to
};

// Straight up (world +z) by distance_m, free.
struct RetreatCommand {
  double distance_m = 0.05;
  double speed_mps = 0.05;
};

using Command = std::variant<GraspCommand, MoveCommand, ContactMoveCommand, ReleaseCommand, RetreatCommand>;
const char* CommandType(const Command& command);  // "grasp", "move", ...

struct Program {
  std::string workpiece;             // the scene object the program moves
  geometry::Pose3 workpiece_T_tool;  // the grasp
  std::vector<Command> commands;
  [[nodiscard]] Status Validate() const;  // the checks of ParseProgram, for programs built in code
};

// Errors name the file and the JSON path ("p.json: commands[2].normals[1]: must be a unit vector").
[[nodiscard]] Result<Program> LoadProgram(const std::string& path);
[[nodiscard]] Result<Program> ParseProgram(const json::Json& document, const std::string& name);
json::Json ProgramToJson(const Program& program);
// The same program gives a byte-identical file (sorted keys, shortest exact numbers).
std::string ProgramToText(const Program& program);
[[nodiscard]] Status SaveProgram(const Program& program, const std::string& path);

// One line per command, for people ("2 contact_move to (12.0, -3.5, 45.0) mm, 2 contacts ...").
std::string ProgramListing(const Program& program);

// The least-norm bias delta_p with d 1 = -N^T delta_p (paper §6.2): the target moves d into every
// contact. Fails (InvalidInput) when no exact solution exists (opposing or otherwise incompatible
// normals: the paper's tight-fit case) or when its norm exceeds max_norm_m.
[[nodiscard]] Result<Eigen::Vector3d> ContactBias(const Eigen::Matrix3Xd& normals, double depth_m,
                                                  double max_norm_m);

}  // namespace teachsim::robot
