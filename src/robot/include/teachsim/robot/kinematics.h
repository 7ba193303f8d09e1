// Kinematics of the Puma-type arm: forward kinematics, closed-form inverse kinematics (all eight
// solutions: shoulder right/left, elbow up/down, wrist flip; Craig §4.7 restated geometrically),
// the geometric Jacobian and singularity detection. All poses here are in the robot's base frame;
// nothing allocates (these run inside the 100 Hz control cycle).
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/robot/robot_model.h"

namespace teachsim::robot {

using Jacobian = Eigen::Matrix<double, 6, kNumJoints>;  // rows: linear (m/rad), angular (rad/rad)

// base_T_link for the DH frames 0..6 (0 = base, 6 = flange).
std::array<geometry::Pose3, kNumJoints + 1> LinkFrames(const RobotModel& model, const Joints& q);
geometry::Pose3 FlangePose(const RobotModel& model, const Joints& q);  // base_T_flange
geometry::Pose3 ToolPose(const RobotModel& model, const Joints& q);    // base_T_tool

// Geometric Jacobian of the tool frame's origin, in the base frame: [v; w] = J qdot.
Jacobian ToolJacobian(const RobotModel& model, const Joints& q);

// The three Puma branch choices.
struct IkBranch {
  bool shoulder_right = true;  // wrist centre in front of the shoulder (left: reached over the top)
  bool elbow_up = true;        // elbow above the shoulder–wrist line
  bool wrist_flip = false;     // theta5 < 0
  std::string Name() const;    // "right/up/noflip"
};

enum class IkStatus {
  kOk,
  kInvalidPose,   // not finite or not a rotation
  kOutOfReach,    // the wrist centre is farther from the shoulder than the arm reaches
  kInsideReach,   // nearer than the folded arm allows (or inside the shoulder offset's cylinder)
  kBeyondLimits,  // solutions exist but none within the joint limits
};
const char* IkStatusName(IkStatus status);

struct Singularities {
  // |sin theta5|: the wrist axes 4 and 6 align at 0.
  double wrist_measure = 1;
  // |sin| of the forearm's angle to the upper arm's line: 0 when stretched out or folded.
  double elbow_measure = 1;
  // distance of the wrist centre from joint 1's axis, beyond the shoulder offset (m).
  double shoulder_measure_m = 1;
  bool wrist = false, elbow = false, shoulder = false;
  bool any() const { return wrist || elbow || shoulder; }
  std::string Describe() const;  // "regular" or "wrist singular (|sin theta5| = 0.0003), ..."
};

struct SingularityOptions {
  double wrist_tolerance = 1e-3;  // |sin theta5|
  double elbow_tolerance = 1e-3;  // |sin| of the elbow angle
  double shoulder_tolerance_m = 1e-3;
};

struct IkSolution {
  Joints q = Joints::Zero();  // each joint in (-pi, pi], or the equivalent within its limits
  IkBranch branch;
  bool within_limits = false;
  Singularities singularities;
};

struct IkSolutions {
  IkStatus status = IkStatus::kOk;
  std::array<IkSolution, 8> solutions;  // the first `count` are valid
  int count = 0;
};

// All closed-form solutions reaching base_T_flange. Where a singularity leaves a joint free, that
// joint (theta1 at the shoulder, theta4 at the wrist) keeps its value in `hint` so that solutions
// stay continuous along a path. Solutions that coincide at a singularity are still listed (count 8).
IkSolutions SolveFlangeIk(const RobotModel& model, const geometry::Pose3& base_T_flange, const Joints& hint,
                          const SingularityOptions& options = {});
IkSolutions SolveToolIk(const RobotModel& model, const geometry::Pose3& base_T_tool, const Joints& hint,
                        const SingularityOptions& options = {});

// The solution within the joint limits nearest `current` (each joint taken modulo 2 pi to the
// equivalent nearest current within its limits; distance weighted by 1 / max speed, i.e. the time
// to get there). Errors name the pose and why it cannot be reached.
[[nodiscard]] Result<IkSolution> NearestToolIk(const RobotModel& model, const geometry::Pose3& base_T_tool,
                                               const Joints& current, const SingularityOptions& options = {});

Singularities DetectSingularities(const RobotModel& model, const Joints& q,
                                  const SingularityOptions& options = {});

// Wraps to (-pi, pi].
double WrapAngle(double angle_rad);

}  // namespace teachsim::robot
