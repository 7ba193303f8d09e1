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
#include "teachsim/robot/friction.h"
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
  // Coulomb friction assumed at every contact, at most (wood on wood; the work site draws its
  // block friction from 0.1-0.5). Friction at the other contacts reads along a contact's normal
  // (a block slid into a corner reads the table's friction along the wall's normal), so a
  // contact is verified when the SMALLEST normal force consistent with the measured force and
  // friction up to this (MinNormalForce, friction.h) reaches the threshold. 0: the paper's plain
  // check of the force along each normal.
  double friction_bound = 0.5;
  // A force that no contact of the program explains (its distance from the friction cones' sum)
  // above this means something else touches: not verified, and no probing.
  double unexplained_force_n = 0.5;
  // When several contacts cannot all be certified in place, press each doubtful one alone (the
  // bias along the others removed), settle and judge it again; then return to the biased target.
  bool probe = true;
  // The probe presses its contact this many times the program's bias depth: the other contacts,
  // relieved, still carry what the model error presses into them, and their friction is then a
  // smaller share of the probed force.
  double probe_depth_scale = 2.0;
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
  // A requested stop (RequestStop) brings the setpoint to rest over this long (at most 0.1 s),
  // decelerating uniformly from its last speed, then holds it.
  double stop_time_s = 0.05;
  [[nodiscard]] Status Validate() const;
};

enum class CommandStatus { kPending, kRunning, kReached, kNotReached, kAborted, kRefused, kSkipped, kStopped };
const char* CommandStatusName(CommandStatus status);

struct ContactCheck {
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double threshold_n = 0;
  double force_n = 0;               // mean force along the normal over the verification window
  double min_normal_n = 0;          // the normal force certified despite friction (friction.h)
  double friction_allowance_n = 0;  // force_n - min_normal_n: what friction may account for
  double unexplained_n = 0;         // force explained by no contact of the program
  bool probed = false;              // judged while pressed alone (MonitorOptions::probe)
  bool verified = false;            // min_normal_n >= threshold_n, unexplained_n within bounds
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
  bool stopped = false;  // ended by RequestStop (a controlled stop, not a failure of the task)
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

  // Controlled stop, e.g. an operator's request: from the next cycle on the setpoint decelerates
  // to rest within ControllerOptions::stop_time_s and holds there (the gripper keeps its
  // command, so a held block stays held); once the measured joints are at rest (at most 0.1 s
  // after the request) the command running ends `stopped`, the rest are skipped. No effect when
  // not running.
  void RequestStop();
  bool stopping() const { return stop_requested_; }

  bool running() const { return running_; }
  // The command running now (or the last one run); 0 before Start.
  std::size_t current_command() const { return phases_.empty() ? 0 : phases_[std::min(phase_, phases_.size() - 1)].command; }
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
  void EndProgram(RobotIo& io, const Joints& hold, CommandStatus status, const std::string& message, double t_s);
  bool StopCycle(RobotIo& io, const Joints& q, double t_s);
  ContactCheck CheckContact(const ImpedanceSpec& imp, long n, const Eigen::Vector3d& mean_force, bool probed) const;
  std::string DescribeCheck(const ContactCheck& check) const;
  void BeginProbe(const Phase& ph, long n, double t_s);
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
  Joints last_step_ = Joints::Zero();  // setpoint change of the last cycle (the stop decelerates it)
  bool stop_requested_ = false;
  int stop_cycles_left_ = -1;  // -1: the stop ramp has not begun
  Joints stop_step_ = Joints::Zero();
  Joints stop_last_q_ = Joints::Zero();
  double stop_t0_ = 0;
  AdmittanceState admittance_;
  Eigen::Vector3d window_force_ = Eigen::Vector3d::Zero();  // sum of the force over the verify window
  int window_samples_ = 0;
  enum class ProbeStage { kNone, kProbe, kRestore } probe_stage_ = ProbeStage::kNone;
  std::vector<long> probe_queue_;  // contacts to press alone, in order
  std::size_t probe_next_ = 0;
  Eigen::Vector3d payload_n_ = Eigen::Vector3d::Zero();  // tare: what the sensor reads at rest, world
  Eigen::Vector3d last_force_ = Eigen::Vector3d::Zero();
  bool running_ = false;
  ExecutionReport report_;
};

}  // namespace teachsim::robot
