// The task controller and execution monitor (paper §3.1, §6.2): runs a robot program at 100 Hz
// over a RobotIo — straight-line Cartesian trajectories, guarded moves, position-based impedance
// control with target bias and clipped output velocity — and monitors it: per command reached or
// not, contacts verified or not from the force along each normal, a force limit that aborts, and
// the force history for the report. Time is passed in (no clock inside): the caller runs one
// Cycle() per period and advances its plant in between. A steady cycle does not allocate (the
// history is reserved at Start); messages are built only when a phase ends.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/robot/admittance.h"
#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_io.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/robot/safety.h"
#include "teachsim/robot/trajectory.h"

namespace teachsim::robot {

struct MonitorOptions {
  double force_limit_n = 50;     // any contact force above this aborts the program (safety)
  double settle_time_s = 0.5;    // contact moves: impedance keeps running this long after the trajectory
  double verify_window_s = 0.1;  // ...and the force along each normal is judged over its last part
  // Friction at the other contacts adds up to mu * (their normal force) * |n_i x n_j| along a normal
  // n_i (a block slid into a corner reads the table's friction along the wall's normal); the
  // monitor subtracts that allowance before comparing with the threshold. 0: the paper's plain check.
  double friction_bound = 0.5;
  bool stop_on_unverified = true;  // an unverified contact ends the program (it failed)
  bool record_forces = true;       // per-command force history in the report
  [[nodiscard]] Status Validate() const;
};

struct ControllerOptions {
  double cycle_s = 0.01;  // 100 Hz trajectory generation (paper §3.1)
  MotionLimits limits;    // accelerations and angular speed; the linear speed comes from each command
  SafetyOptions safety;
  AdmittanceOptions admittance;
  MonitorOptions monitor;
  double reach_tolerance_m = 1e-3;  // a free move is reached when the measured tool is this close
  double reach_tolerance_rad = 0.01;
  double reach_timeout_s = 1.0;             // after the trajectory, time for the servos to arrive
  double contact_reach_tolerance_m = 0.01;  // contact moves: measured tool to the nominal target
  double gripper_timeout_s = 3.0;
  double gripper_tolerance_m = 0.003;  // a grasp holds when the jaws stop this close to the block width
  double grip_squeeze_m = 0.005;       // close this much narrower than the block to squeeze it
  [[nodiscard]] Status Validate() const;
};

enum class CommandStatus { kPending, kRunning, kReached, kNotReached, kAborted, kRefused, kSkipped };
const char* CommandStatusName(CommandStatus status);

struct ContactCheck {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double threshold_n = 0;
  double force_n = 0;               // mean force along the normal over the verification window
  double friction_allowance_n = 0;  // subtracted before the comparison (MonitorOptions::friction_bound)
  bool verified = false;
};

struct ForceSample {
  double t_s = 0;
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // on the tool, world frame, payload removed
};

struct CommandReport {
  std::string type;
  CommandStatus status = CommandStatus::kPending;
  std::string message;
  double start_s = 0, end_s = 0;
  double peak_force_n = 0;
  bool guard_triggered = false;  // a guarded descent stopped on force
  double position_error_m = 0;   // measured tool to the command's (nominal) target at the end
  double gripper_width_m = 0;    // at the end
  std::vector<ContactCheck> contacts;
  bool contacts_verified = true;  // all contacts verified (true when there are none)
  std::vector<ForceSample> forces;
};

struct ExecutionReport {
  bool finished = false;
  bool success = false;  // every command reached and every contact verified
  std::string message;
  double peak_force_n = 0;
  std::vector<CommandReport> commands;
};
json::Json ExecutionReportToJson(const ExecutionReport& report, bool with_forces);

// A single motion outside a program (tests, jogging): a line to a pose, optionally guarded
// (stop when the force along `direction` reaches force_n) and/or compliant.
struct GuardSpec {
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // unit, world
  double force_n = 5;
};
struct ImpedanceSpec {
  double stiffness_n_per_m = 300, damping_n_s_per_m = 1000;
  Eigen::Vector3d bias_m = Eigen::Vector3d::Zero();
  Eigen::Matrix3Xd normals = Eigen::Matrix3Xd(3, 0);  // contacts to verify
  std::vector<double> force_thresholds_n;
};
struct MotionRequest {
  std::string name = "motion";
  geometry::Pose3 world_T_tool;
  double speed_mps = 0.05;
  std::optional<GuardSpec> guard;
  std::optional<ImpedanceSpec> impedance;
};

class TaskController {
 public:
  // model must outlive the controller; options must be valid (TEACHSIM_CHECK).
  TaskController(const RobotModel& model, const geometry::Pose3& world_T_base,
                 const ControllerOptions& options);

  // Checks the whole program (safety, before any motion) from the robot's present joints and
  // starts it. The wrist sensor is tared now: the robot must be at rest and touching nothing.
  [[nodiscard]] Status Start(const Program& program, RobotIo& io, double t_s);
  [[nodiscard]] Status StartMotion(const MotionRequest& request, RobotIo& io, double t_s);

  // One control cycle at time t_s: read, compute, command. Returns true while running.
  bool Cycle(RobotIo& io, double t_s);

  bool running() const { return running_; }
  const ExecutionReport& report() const { return report_; }
  const AdmittanceState& admittance() const { return admittance_; }
  // The force on the tool in the world frame with the payload removed, as of the last cycle.
  const Eigen::Vector3d& last_force_n() const { return last_force_; }

 private:
  struct Phase {
    enum class Kind { kGripper, kMotion } kind = Kind::kMotion;
    std::size_t command = 0;
    bool last_of_command = false;
    // gripper
    double width_m = 0;
    double expect_width_m = -1;  // a grasp: the jaws must stop at this width (the block's), or -1
    // motion
    geometry::Pose3 goal;     // absolute target, world (biased for contact moves)
    double rise_m = 0;        // > 0: relative, straight up from where the tool is (retreat)
    geometry::Pose3 nominal;  // for position_error_m
    double speed_mps = 0.05;
    std::optional<GuardSpec> guard;
    std::optional<ImpedanceSpec> impedance;
    bool tare_at_end = false;
  };

  Status Load(std::vector<Phase> phases, std::vector<std::string> names, RobotIo& io, double t_s,
              const std::vector<double>& durations_s);
  Status BeginPhase(double t_s);
  void FinishPhase(RobotIo& io, const Joints& q, const Wrench& wrench, const GripperState& gripper,
                   double t_s);
  void EndProgram(RobotIo& io, const Joints& q, CommandStatus status, const std::string& message, double t_s);
  geometry::Pose3 MeasuredTool(const Joints& q) const;

  const RobotModel& model_;
  geometry::Pose3 world_T_base_, base_T_world_;
  ControllerOptions options_;

  std::vector<Phase> phases_;
  std::vector<std::string> names_;  // "commands[2] (move)", built before the program runs
  std::size_t phase_ = 0;
  bool phase_started_ = false;
  double phase_t0_ = 0;
  CartesianLine line_;
  Joints setpoint_ = Joints::Zero();
  AdmittanceState admittance_;
  std::vector<double> window_sums_;  // per contact normal: sum of force along it over the window
  int window_samples_ = 0;
  Eigen::Vector3d payload_n_ = Eigen::Vector3d::Zero();  // tare: what the sensor reads at rest, world
  Eigen::Vector3d last_force_ = Eigen::Vector3d::Zero();
  bool running_ = false;
  ExecutionReport report_;
};

}  // namespace teachsim::robot
