#include "teachsim/robot/controller.h"

#include <cmath>
#include <cstdio>
#include <algorithm>
#include <variant>

namespace teachsim::robot {

namespace {

Status Positive(const char* owner, const char* name, double value) {
  if (!(std::isfinite(value) && value > 0)) {
    return Status::InvalidInput(std::string(owner) + "::" + name + " = " + json::FormatNumber(value) +
                                " must be > 0");
  }
  return Status::Ok();
}

std::string Format(const char* format, double a, double b = 0, double c = 0) {
  char buffer[200];
  std::snprintf(buffer, sizeof buffer, format, a, b, c);
  return buffer;
}

}  // namespace

const char* CommandStatusName(CommandStatus status) {
  switch (status) {
    case CommandStatus::kPending:
      return "pending";
    case CommandStatus::kRunning:
      return "running";
    case CommandStatus::kReached:
      return "reached";
    case CommandStatus::kNotReached:
      return "not_reached";
    case CommandStatus::kAborted:
      return "aborted";
    case CommandStatus::kRefused:
      return "refused";
    case CommandStatus::kSkipped:
      return "skipped";
    case CommandStatus::kStopped:
      return "stopped";
  }
  return "?";
}

Status MonitorOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(Positive("MonitorOptions", "force_limit_n", force_limit_n));
  TEACHSIM_RETURN_IF_ERROR(Positive("MonitorOptions", "settle_time_s", settle_time_s));
  TEACHSIM_RETURN_IF_ERROR(Positive("MonitorOptions", "verify_window_s", verify_window_s));
  if (verify_window_s > settle_time_s) {
    return Status::InvalidInput("MonitorOptions::verify_window_s must not exceed settle_time_s");
  }
  if (!(probe_depth_scale > 0 && probe_depth_scale <= 4)) {
    return Status::InvalidInput("MonitorOptions::probe_depth_scale = " + json::FormatNumber(probe_depth_scale) +
                                " must be in (0, 4]");
  }
  if (!(unexplained_force_n >= 0)) {
    return Status::InvalidInput("MonitorOptions::unexplained_force_n = " + json::FormatNumber(unexplained_force_n) +
                                " must be >= 0");
  }
  if (!(friction_bound >= 0 && friction_bound < 1)) {
    return Status::InvalidInput("MonitorOptions::friction_bound = " + json::FormatNumber(friction_bound) +
                                " must be in [0, 1)");
  }
  return Status::Ok();
}

Status ControllerOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(Positive("ControllerOptions", "cycle_s", cycle_s));
  TEACHSIM_RETURN_IF_ERROR(limits.Validate());
  TEACHSIM_RETURN_IF_ERROR(safety.Validate());
  TEACHSIM_RETURN_IF_ERROR(admittance.Validate());
  TEACHSIM_RETURN_IF_ERROR(monitor.Validate());
  TEACHSIM_RETURN_IF_ERROR(Positive("ControllerOptions", "reach_tolerance_m", reach_tolerance_m));
  TEACHSIM_RETURN_IF_ERROR(Positive("ControllerOptions", "reach_tolerance_rad", reach_tolerance_rad));
  TEACHSIM_RETURN_IF_ERROR(Positive("ControllerOptions", "reach_timeout_s", reach_timeout_s));
  TEACHSIM_RETURN_IF_ERROR(
      Positive("ControllerOptions", "contact_reach_tolerance_m", contact_reach_tolerance_m));
  TEACHSIM_RETURN_IF_ERROR(Positive("ControllerOptions", "gripper_timeout_s", gripper_timeout_s));
  TEACHSIM_RETURN_IF_ERROR(Positive("ControllerOptions", "gripper_tolerance_m", gripper_tolerance_m));
  if (!(grip_squeeze_m >= 0)) return Status::InvalidInput("ControllerOptions::grip_squeeze_m must be >= 0");
  if (!(stop_time_s > 0 && stop_time_s <= 0.1)) {
    return Status::InvalidInput("ControllerOptions::stop_time_s = " + json::FormatNumber(stop_time_s) +
                                " must be in (0, 0.1]");
  }
  return Status::Ok();
}

TaskController::TaskController(const RobotModel& model, const geometry::Pose3& world_T_base,
                               const ControllerOptions& options)
    : model_(model), world_T_base_(world_T_base), base_T_world_(world_T_base.Inverse()), options_(options) {
  TEACHSIM_CHECK_MSG(options.Validate().ok(), options.Validate().message().c_str());
  TEACHSIM_CHECK(model.Validate().ok());
}

geometry::Pose3 TaskController::MeasuredTool(const Joints& q) const {
  return world_T_base_ * ToolPose(model_, q);
}

Status TaskController::Start(const Program& program, RobotIo& io, double t_s) {
  TEACHSIM_CHECK(!running_);
  const Joints q = io.ReadJoints();
  TEACHSIM_RETURN_IF_ERROR(CheckProgram(model_, world_T_base_, program, q, options_.limits, options_.safety));

  std::vector<Phase> phases;
  std::vector<std::string> names;
  std::vector<double> durations(program.commands.size(), 0.0);
  geometry::Pose3 pose = MeasuredTool(q);  // the planned chain, for the history's capacity
  auto planned = [&](std::size_t i, const geometry::Pose3& goal, double speed) {
    MotionLimits l = options_.limits;
    l.speed_mps = speed;
    durations[i] += CartesianLine(pose, goal, l).duration_s();
    pose = goal;
  };
  for (std::size_t i = 0; i < program.commands.size(); ++i) {
    const Command& command = program.commands[i];
    names.emplace_back(CommandType(command));
    Phase motion;
    motion.command = i;
    Phase gripper = motion;
    gripper.kind = Phase::Kind::kGripper;
    if (const auto* g = std::get_if<GraspCommand>(&command)) {
      Phase open = gripper;
      open.width_m = g->open_width_m;
      phases.push_back(open);
      Phase approach = motion;
      approach.goal = approach.nominal = g->ApproachPose();
      approach.speed_mps = g->approach_speed_mps;
      approach.tare_at_end = true;  // empty gripper, at rest, in free space
      phases.push_back(approach);
      planned(i, approach.goal, approach.speed_mps);
      Phase descend = motion;
      descend.goal = descend.nominal = g->world_T_tool;
      descend.speed_mps = g->speed_mps;
      descend.guard = GuardSpec{Eigen::Vector3d::UnitZ(), g->contact_force_n};
      phases.push_back(descend);
      planned(i, descend.goal, descend.speed_mps);
      Phase close = gripper;
      close.width_m = std::max(model_.gripper.min_width_m, g->width_m - options_.grip_squeeze_m);
      close.expect_width_m = g->width_m;
      phases.push_back(close);
    } else if (const auto* m = std::get_if<MoveCommand>(&command)) {
      motion.goal = motion.nominal = m->world_T_tool;
      motion.speed_mps = m->speed_mps;
      motion.tare_at_end = true;  // free space, at rest: what the sensor reads now is the payload
      phases.push_back(motion);
      planned(i, motion.goal, motion.speed_mps);
    } else if (const auto* c = std::get_if<ContactMoveCommand>(&command)) {
      motion.goal = c->BiasedTarget();
      motion.nominal = c->world_T_tool;
      motion.speed_mps = c->speed_mps;
      motion.impedance = ImpedanceSpec{c->stiffness_n_per_m, c->damping_n_s_per_m, c->bias_m, c->normals,
                                       c->force_thresholds_n};
      phases.push_back(motion);
      planned(i, motion.goal, motion.speed_mps);
    } else if (const auto* r = std::get_if<ReleaseCommand>(&command)) {
      gripper.width_m = r->width_m;
      phases.push_back(gripper);
    } else if (const auto* t = std::get_if<RetreatCommand>(&command)) {
      motion.rise_m = t->distance_m;
      motion.speed_mps = t->speed_mps;
      motion.tare_at_end = true;
      phases.push_back(motion);
      geometry::Pose3 up = pose;
      up.translation.z() += t->distance_m;
      planned(i, up, t->speed_mps);
    }
    phases.back().last_of_command = true;
  }
  return Load(std::move(phases), std::move(names), io, t_s, durations);
}

Status TaskController::StartMotion(const MotionRequest& request, RobotIo& io, double t_s) {
  TEACHSIM_CHECK(!running_);
  if (!request.world_T_tool.IsValid()) return Status::InvalidInput("motion: the target is not a valid pose");
  if (!(request.speed_mps > 0)) return Status::InvalidInput("motion: speed_mps must be > 0");
  Phase motion;
  motion.goal = motion.nominal = request.world_T_tool;
  motion.speed_mps = request.speed_mps;
  motion.last_of_command = true;
  if (request.guard) {
    if (std::abs(request.guard->direction.norm() - 1) > 1e-6 || !(request.guard->force_n > 0)) {
      return Status::InvalidInput("motion: the guard needs a unit direction and a force > 0");
    }
    motion.guard = request.guard;
  }
  if (request.impedance) {
    const ImpedanceSpec& imp = request.impedance.value();
    if (!(imp.stiffness_n_per_m > 0 && imp.damping_n_s_per_m > 0) || !imp.bias_m.allFinite() ||
        static_cast<std::size_t>(imp.normals.cols()) != imp.force_thresholds_n.size()) {
      return Status::InvalidInput(
          "motion: impedance needs K > 0, B > 0, a finite bias, one threshold per normal");
    }
    motion.impedance = imp;
    motion.goal.translation += imp.bias_m;
  }
  Joints q = io.ReadJoints();
  MotionLimits l = options_.limits;
  l.speed_mps = request.speed_mps;
  TEACHSIM_RETURN_IF_ERROR(CheckLine(model_, world_T_base_, MeasuredTool(q), motion.goal, q, l,
                                     options_.safety, request.name, nullptr));
  std::vector<double> durations = {CartesianLine(MeasuredTool(q), motion.goal, l).duration_s()};
  return Load({motion}, {request.name}, io, t_s, durations);
}

Status TaskController::Load(std::vector<Phase> phases, std::vector<std::string> names, RobotIo& io,
                            double t_s, const std::vector<double>& durations_s) {
  phases_ = std::move(phases);
  report_ = ExecutionReport{};
  report_.commands.resize(names.size());
  std::size_t max_normals = 0;
  std::vector<int> phase_count(names.size(), 0);
  for (const Phase& p : phases_) {
    ++phase_count[p.command];
    if (p.impedance) {
      max_normals = std::max(max_normals, static_cast<std::size_t>(p.impedance->normals.cols()));
      report_.commands[p.command].contacts.reserve(static_cast<std::size_t>(p.impedance->normals.cols()));
    }
  }
  const double slack_s =
      std::max({options_.monitor.settle_time_s, options_.reach_timeout_s, options_.gripper_timeout_s});
  names_.clear();
  for (std::size_t i = 0; i < names.size(); ++i) {
    names_.push_back("commands[" + std::to_string(i) + "] (" + names[i] + ")");
    report_.commands[i].type = names[i];
    if (options_.monitor.record_forces) {
      double seconds = durations_s[i] + phase_count[i] * (slack_s + 2 * options_.cycle_s);
      report_.commands[i].forces.reserve(static_cast<std::size_t>(seconds / options_.cycle_s) + 16);
    }
  }
  (void)max_normals;
  window_force_.setZero();
  window_samples_ = 0;
  probe_stage_ = ProbeStage::kNone;
  const Joints q = io.ReadJoints();
  setpoint_ = q;
  last_step_.setZero();
  stop_requested_ = false;
  stop_cycles_left_ = -1;
  payload_n_ = MeasuredTool(q).Rotate(io.ReadWristWrench().force_n);  // tare (at rest, touching nothing)
  phase_ = 0;
  phase_started_ = false;
  running_ = true;
  (void)t_s;
  return Status::Ok();
}

Status TaskController::BeginPhase(double t_s) {
  Phase& ph = phases_[phase_];
  CommandReport& rep = report_.commands[ph.command];
  if (rep.status == CommandStatus::kPending) {
    rep.status = CommandStatus::kRunning;
    rep.start_s = t_s;
  }
  phase_started_ = true;
  phase_t0_ = t_s;
  if (ph.kind == Phase::Kind::kMotion) {
    // Start from the pose last commanded, so that the setpoint never jumps.
    const geometry::Pose3 start = MeasuredTool(setpoint_);
    if (ph.rise_m > 0) {
      ph.goal = start;
      ph.goal.translation.z() += ph.rise_m;
      ph.nominal = ph.goal;
    }
    MotionLimits l = options_.limits;
    l.speed_mps = ph.speed_mps;
    TEACHSIM_RETURN_IF_ERROR(CheckLine(model_, world_T_base_, start, ph.goal, setpoint_, l, options_.safety,
                                       names_[ph.command], nullptr));
    line_ = CartesianLine(start, ph.goal, l);
    admittance_ = AdmittanceState{};
    window_force_.setZero();
    window_samples_ = 0;
    probe_stage_ = ProbeStage::kNone;
    probe_queue_.clear();
    probe_queue_.reserve(static_cast<std::size_t>(ph.impedance ? ph.impedance->normals.cols() : 0));
  }
  return Status::Ok();
}

void TaskController::EndProgram(RobotIo& io, const Joints& hold, CommandStatus status,
                                const std::string& message, double t_s) {
  setpoint_ = hold;
  last_step_.setZero();
  io.CommandJoints(hold);  // hold there
  const Joints& q = hold;
  CommandReport& rep = report_.commands[phases_[phase_].command];
  rep.status = status;
  rep.message = message;
  rep.end_s = t_s;
  rep.position_error_m = phases_[phase_].kind == Phase::Kind::kMotion
                             ? geometry::TranslationDistance(MeasuredTool(q), phases_[phase_].nominal)
                             : 0.0;
  for (std::size_t i = phases_[phase_].command + 1; i < report_.commands.size(); ++i) {
    report_.commands[i].status = CommandStatus::kSkipped;
  }
  report_.finished = true;
  report_.success = false;
  report_.stopped = status == CommandStatus::kStopped;
  report_.message = "commands[" + std::to_string(phases_[phase_].command) + "] (" + rep.type + ") " +
                    CommandStatusName(status) + ": " + message;
  running_ = false;
}

void TaskController::RequestStop() {
  if (running_) stop_requested_ = true;
}

// One cycle of a controlled stop: the setpoint keeps moving by its last step, shrinking linearly
// to zero over stop_time_s (uniform deceleration); then it holds until the measured joints are at
// rest (or 0.1 s after the request), and the program ends there.
bool TaskController::StopCycle(RobotIo& io, const Joints& q, double t_s) {
  const int n = std::max(1, static_cast<int>(std::lround(options_.stop_time_s / options_.cycle_s)));
  if (stop_cycles_left_ < 0) {
    stop_cycles_left_ = n;
    stop_step_ = last_step_;
    stop_t0_ = t_s;
    stop_last_q_ = q;
  }
  if (stop_cycles_left_ > 0) {
    --stop_cycles_left_;
    setpoint_ += stop_step_ * (static_cast<double>(stop_cycles_left_) / (n + 1));
  }
  io.CommandJoints(setpoint_);
  // At rest: no joint moved more than 2e-5 rad in the last cycle (< 1 mm/s at the tool here).
  const bool at_rest = (q - stop_last_q_).cwiseAbs().maxCoeff() < 2e-5;
  stop_last_q_ = q;
  const double elapsed = t_s - stop_t0_;
  if (stop_cycles_left_ > 0 || (!at_rest && elapsed + 1e-9 < 0.1 - options_.cycle_s)) return true;
  EndProgram(io, setpoint_, CommandStatus::kStopped,
             at_rest ? Format("stopped on request, at rest after %.2f s", elapsed + options_.cycle_s)
                     : Format("stopped on request, still settling after %.2f s", elapsed + options_.cycle_s),
             t_s);
  return false;
}

void TaskController::FinishPhase(RobotIo& io, const Joints& q, const Wrench& wrench,
                                 const GripperState& gripper, double t_s) {
  const Phase& ph = phases_[phase_];
  CommandReport& rep = report_.commands[ph.command];
  const geometry::Pose3 tool = MeasuredTool(q);
  if (ph.tare_at_end) payload_n_ = tool.Rotate(wrench.force_n);
  if (ph.last_of_command) {
    rep.status = CommandStatus::kReached;
    rep.end_s = t_s;
    rep.gripper_width_m = gripper.width_m;
    if (ph.kind == Phase::Kind::kMotion)
      rep.position_error_m = geometry::TranslationDistance(tool, ph.nominal);
    if (!rep.contacts_verified && options_.monitor.stop_on_unverified) {
      report_.finished = true;
      report_.success = false;
      report_.message = "commands[" + std::to_string(ph.command) + "] (" + rep.type + "): " + rep.message;
      for (std::size_t i = ph.command + 1; i < report_.commands.size(); ++i) {
        report_.commands[i].status = CommandStatus::kSkipped;
      }
      running_ = false;
      return;
    }
  }
  ++phase_;
  phase_started_ = false;
  if (phase_ == phases_.size()) {
    report_.finished = true;
    report_.success = true;
    for (const CommandReport& c : report_.commands) {
      report_.success = report_.success && c.status == CommandStatus::kReached && c.contacts_verified;
    }
    report_.message = report_.success ? "done: every command reached, every contact verified"
                                      : "done, but a contact was not verified";
    running_ = false;
  }
  (void)io;
}

ContactCheck TaskController::CheckContact(const ImpedanceSpec& imp, long n, const Eigen::Vector3d& mean_force,
                                         bool probed) const {
  ContactCheck check;
  check.normal = imp.normals.col(n);
  check.threshold_n = imp.force_thresholds_n[static_cast<std::size_t>(n)];
  check.force_n = mean_force.dot(check.normal);
  const NormalForceBound bound = MinNormalForce(mean_force, imp.normals, options_.monitor.friction_bound, n);
  check.min_normal_n = bound.min_n;
  check.friction_allowance_n = std::max(0.0, check.force_n - bound.min_n);
  check.unexplained_n = bound.outside_n;
  check.probed = probed;
  check.verified =
      check.min_normal_n >= check.threshold_n && check.unexplained_n <= options_.monitor.unexplained_force_n;
  return check;
}

std::string TaskController::DescribeCheck(const ContactCheck& c) const {
  std::string text = Format("%.2f N along (%.2f, %.2f, ", c.force_n, c.normal.x(), c.normal.y()) +
                     Format("%.2f), at least %.2f N certified with friction", c.normal.z(), c.min_normal_n) +
                     Format(" %.2f, needed %.2f N", options_.monitor.friction_bound, c.threshold_n);
  if (c.unexplained_n > options_.monitor.unexplained_force_n) {
    text += Format(" (%.2f N of the force is explained by no contact of the program)", c.unexplained_n);
  }
  if (c.probed) text += " (probed alone)";
  return text;
}

// Presses contact n alone: the target is the nominal one moved d into contact n only (the other
// contacts at their nominal surfaces), d being the program's bias depth along n.
void TaskController::BeginProbe(const Phase& ph, long n, double t_s) {
  const ImpedanceSpec& imp = ph.impedance.value();
  const double depth = -imp.normals.col(n).dot(imp.bias_m) * options_.monitor.probe_depth_scale;
  Eigen::VectorXd depths = Eigen::VectorXd::Zero(imp.normals.cols());
  depths[n] = depth;
  const Eigen::Matrix3Xd& N = imp.normals;
  const Eigen::MatrixXd gram = N.transpose() * N;
  const Eigen::Vector3d delta = -N * gram.ldlt().solve(depths);
  geometry::Pose3 goal = ph.nominal;
  goal.translation += delta;
  MotionLimits l = options_.limits;
  l.speed_mps = ph.speed_mps;
  line_ = CartesianLine(line_.goal(), goal, l);
  phase_t0_ = t_s;
  window_force_.setZero();
  window_samples_ = 0;
  probe_stage_ = ProbeStage::kProbe;
}

bool TaskController::Cycle(RobotIo& io, double t_s) {
  if (!running_) return false;
  const Joints q = io.ReadJoints();
  const Wrench wrench = io.ReadWristWrench();
  const GripperState gripper = io.ReadGripper();
  const geometry::Pose3 tool = MeasuredTool(q);
  const Eigen::Vector3d force = tool.Rotate(wrench.force_n) - payload_n_;
  last_force_ = force;
  Phase& ph = phases_[phase_];
  CommandReport& rep = report_.commands[ph.command];

  if (!phase_started_) {
    if (Status begun = BeginPhase(t_s); !begun.ok()) {
      EndProgram(io, q, CommandStatus::kRefused, begun.message(), t_s);
      return false;
    }
    if (ph.kind == Phase::Kind::kGripper) io.CommandGripper(ph.width_m);
  }

  // The monitor: force history, peak, and the safety limit.
  const double force_norm = force.norm();
  rep.peak_force_n = std::max(rep.peak_force_n, force_norm);
  report_.peak_force_n = std::max(report_.peak_force_n, force_norm);
  if (options_.monitor.record_forces) rep.forces.push_back({t_s, force});
  if (force_norm > options_.monitor.force_limit_n) {
    EndProgram(io, q, CommandStatus::kAborted,
               Format("force %.1f N exceeds the limit %.1f N", force_norm, options_.monitor.force_limit_n),
               t_s);
    return false;
  }

  if (stop_requested_) return StopCycle(io, q, t_s);

  const double elapsed = t_s - phase_t0_;
  if (ph.kind == Phase::Kind::kGripper) {
    last_step_.setZero();
    io.CommandJoints(setpoint_);
    const bool stopped = !gripper.moving && elapsed >= 2 * options_.cycle_s;
    if (!stopped && elapsed < options_.gripper_timeout_s) return true;
    if (!stopped) {
      EndProgram(io, q, CommandStatus::kNotReached,
                 Format("the gripper still moves after %.1f s (at %.1f mm)", elapsed, gripper.width_m * 1e3),
                 t_s);
      return false;
    }
    if (ph.expect_width_m >= 0) {
      if (std::abs(gripper.width_m - ph.expect_width_m) > options_.gripper_tolerance_m) {
        EndProgram(io, q, CommandStatus::kNotReached,
                   Format("the jaws stopped at %.1f mm, not at the block's %.1f mm: no block between them",
                          gripper.width_m * 1e3, ph.expect_width_m * 1e3),
                   t_s);
        return false;
      }
      rep.message = Format("grasped at %.1f mm", gripper.width_m * 1e3);
    } else if (std::abs(gripper.width_m - ph.width_m) > options_.gripper_tolerance_m) {
      EndProgram(
          io, q, CommandStatus::kNotReached,
          Format("the jaws stopped at %.1f mm, commanded %.1f mm", gripper.width_m * 1e3, ph.width_m * 1e3),
          t_s);
      return false;
    }
    FinishPhase(io, q, wrench, gripper, t_s);
    return running_;
  }

  // Motion: command the next setpoint of the line (one cycle ahead of now).
  const double along = elapsed + options_.cycle_s;
  if (ph.guard && force.dot(ph.guard->direction) >= ph.guard->force_n) {
    setpoint_ = q;  // stop where the contact was felt
    last_step_.setZero();
    io.CommandJoints(q);
    rep.guard_triggered = true;
    rep.message =
        Format("stopped on contact: %.1f N along the guard direction", force.dot(ph.guard->direction));
    FinishPhase(io, q, wrench, gripper, t_s);
    return running_;
  }
  geometry::Pose3 target = line_.At(along).pose;
  if (ph.impedance) {
    // Clip to the command's speed (paper §6.2), the speed the robot is asked to move at.
    AdmittanceStep(ph.impedance->stiffness_n_per_m, ph.impedance->damping_n_s_per_m, options_.admittance,
                   force, ph.speed_mps, options_.cycle_s, &admittance_);
    target.translation += admittance_.offset_m;
  }
  Result<IkSolution> ik = NearestToolIk(model_, base_T_world_ * target, setpoint_);
  if (!ik.ok()) {
    EndProgram(io, q, CommandStatus::kAborted, "setpoint unreachable: " + ik.status().message(), t_s);
    return false;
  }
  const Joints max_step = model_.MaxSpeeds() * options_.cycle_s;
  for (int i = 0; i < kNumJoints; ++i) {
    if (std::abs(ik->q[i] - setpoint_[i]) > max_step[i]) {
      EndProgram(
          io, q, CommandStatus::kAborted,
          model_.joints[i].name +
              Format(" would move at %.2f rad/s, above its %.2f rad/s (",
                     std::abs(ik->q[i] - setpoint_[i]) / options_.cycle_s, model_.joints[i].max_speed_rad_s) +
              DetectSingularities(model_, ik->q, {0.05, 0.05, 0.02}).Describe() + ")",
          t_s);
      return false;
    }
  }
  last_step_ = ik->q - setpoint_;
  setpoint_ = ik->q;
  io.CommandJoints(setpoint_);
  if (along < line_.duration_s()) return true;

  const double after = along - line_.duration_s();
  if (ph.impedance) {
    const ImpedanceSpec& imp = ph.impedance.value();
    const long k = imp.normals.cols();
    if (probe_stage_ == ProbeStage::kRestore) {  // back to the biased target after probing
      FinishPhase(io, q, wrench, gripper, t_s);
      return running_;
    }
    if (after >= options_.monitor.settle_time_s - options_.monitor.verify_window_s) {
      window_force_ += force;
      ++window_samples_;
    }
    if (after < options_.monitor.settle_time_s) return true;
    const Eigen::Vector3d mean_force = window_force_ / std::max(window_samples_, 1);
    if (probe_stage_ == ProbeStage::kProbe) {
      // This probe's verdict replaces the in-place one of its contact; then the next probe.
      const long n = probe_queue_[probe_next_ - 1];
      rep.contacts[static_cast<std::size_t>(n)] = CheckContact(imp, n, mean_force, true);
      if (probe_next_ < probe_queue_.size()) {
        BeginProbe(ph, probe_queue_[probe_next_++], t_s);
        return true;
      }
      rep.contacts_verified = true;
      std::string unverified;
      for (const ContactCheck& c : rep.contacts) {
        rep.contacts_verified = rep.contacts_verified && c.verified;
        if (!c.verified) unverified += (unverified.empty() ? "" : "; ") + DescribeCheck(c);
      }
      rep.message = rep.contacts_verified ? "contacts verified (probed one at a time)"
                                          : "contact not verified: " + unverified;
      // Back to the biased target (every contact pressed), the state the program asked for.
      MotionLimits l = options_.limits;
      l.speed_mps = ph.speed_mps;
      line_ = CartesianLine(line_.goal(), ph.goal, l);
      phase_t0_ = t_s;
      probe_stage_ = ProbeStage::kRestore;
      return true;
    }
    // Verdict in place (paper §6.2): a certified normal force above the threshold on every
    // contact, friction at all of them considered (MonitorOptions::friction_bound).
    rep.contacts.clear();
    rep.contacts_verified = true;
    std::string unverified;
    probe_queue_.clear();
    for (long n = 0; n < k; ++n) {
      ContactCheck check = CheckContact(imp, n, mean_force, false);
      if (!check.verified) {
        unverified += (unverified.empty() ? "" : "; ") + DescribeCheck(check);
        if (check.unexplained_n <= options_.monitor.unexplained_force_n) probe_queue_.push_back(n);
      }
      rep.contacts_verified = rep.contacts_verified && check.verified;
      rep.contacts.push_back(check);
    }
    const double error = geometry::TranslationDistance(tool, ph.nominal);
    if (error > options_.contact_reach_tolerance_m) {
      EndProgram(io, q, CommandStatus::kNotReached,
                 Format("the tool stopped %.1f mm from the target (tolerance %.1f mm)", error * 1e3,
                        options_.contact_reach_tolerance_m * 1e3),
                 t_s);
      return false;
    }
    // Friction makes several simultaneous contacts ambiguous (a corner with mu = 0.5 can read
    // the same with one wall untouched): press the doubtful ones one at a time, the others
    // relieved, so that little friction can hide behind them.
    if (!rep.contacts_verified && options_.monitor.probe && k >= 2 &&
        probe_queue_.size() == static_cast<std::size_t>(std::count_if(rep.contacts.begin(), rep.contacts.end(),
                                                                   [](const ContactCheck& c) { return !c.verified; }))) {
      probe_next_ = 0;
      BeginProbe(ph, probe_queue_[probe_next_++], t_s);
      return true;
    }
    rep.message = rep.contacts_verified ? "contacts verified" : "contact not verified: " + unverified;
    FinishPhase(io, q, wrench, gripper, t_s);
    return running_;
  }

  const double error_m = geometry::TranslationDistance(tool, line_.goal());
  const double error_rad = geometry::RotationAngle(tool, line_.goal());
  if (error_m <= options_.reach_tolerance_m && error_rad <= options_.reach_tolerance_rad) {
    if (ph.guard) rep.message = "planned depth reached without contact";
    FinishPhase(io, q, wrench, gripper, t_s);
    return running_;
  }
  if (after >= options_.reach_timeout_s) {
    EndProgram(
        io, q, CommandStatus::kNotReached,
        Format("the tool stopped %.1f mm / %.1f deg from the target", error_m * 1e3, error_rad * 180 / M_PI),
        t_s);
    return false;
  }
  return true;
}

json::Json ExecutionReportToJson(const ExecutionReport& report, bool with_forces) {
  json::Json commands = json::Json::array();
  for (std::size_t i = 0; i < report.commands.size(); ++i) {
    const CommandReport& c = report.commands[i];
    json::Json contacts = json::Json::array();
    for (const ContactCheck& k : c.contacts) {
      contacts.push_back({{"normal", {k.normal.x(), k.normal.y(), k.normal.z()}},
                          {"threshold_n", k.threshold_n},
                          {"force_n", k.force_n},
                          {"friction_allowance_n", k.friction_allowance_n},
                          {"min_normal_n", k.min_normal_n},
                          {"unexplained_n", k.unexplained_n},
                          {"probed", k.probed},
                          {"verified", k.verified}});
    }
    json::Json entry = {{"index", i},
                        {"type", c.type},
                        {"status", CommandStatusName(c.status)},
                        {"message", c.message},
                        {"start_s", c.start_s},
                        {"end_s", c.end_s},
                        {"peak_force_n", c.peak_force_n},
                        {"guard_triggered", c.guard_triggered},
                        {"position_error_m", c.position_error_m},
                        {"gripper_width_m", c.gripper_width_m},
                        {"contacts", contacts},
                        {"contacts_verified", c.contacts_verified}};
    if (with_forces) {
      json::Json t = json::Json::array(), f = json::Json::array();
      for (const ForceSample& s : c.forces) {
        t.push_back(s.t_s);
        f.push_back({s.force_n.x(), s.force_n.y(), s.force_n.z()});
      }
      entry["forces"] = {{"t_s", t}, {"force_n", f}};
    }
    commands.push_back(std::move(entry));
  }
  return {{"finished", report.finished},
          {"success", report.success},
          {"message", report.message},
          {"peak_force_n", report.peak_force_n},
          {"commands", commands}};
}

}  // namespace teachsim::robot
