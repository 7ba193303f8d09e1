#include "teachsim/robot/safety.h"

#include <cmath>
#include <cstdio>
#include <type_traits>
#include <variant>

namespace teachsim::robot {

namespace {

std::string Mm(const Eigen::Vector3d& p) {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "(%.1f, %.1f, %.1f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return buffer;
}

Status Refuse(const std::string& what, const std::string& problem) {
  return Status::InvalidInput("refused: " + what + ": " + problem);
}

Status CheckWidth(const RobotModel& model, const std::string& what, const char* field, double width_m) {
  if (width_m < model.gripper.min_width_m || width_m > model.gripper.max_width_m) {
    char buffer[160];
    std::snprintf(buffer, sizeof buffer, "%s = %.1f mm is outside the gripper's range [%.1f, %.1f] mm", field,
                  width_m * 1e3, model.gripper.min_width_m * 1e3, model.gripper.max_width_m * 1e3);
    return Refuse(what, buffer);
  }
  return Status::Ok();
}

}  // namespace

Status SafetyOptions::Validate() const {
  if (workspace.IsEmpty()) return Status::InvalidInput("SafetyOptions::workspace is empty");
  const std::pair<const char*, double> fields[] = {{"max_tool_speed_mps", max_tool_speed_mps},
                                                   {"max_contact_speed_mps", max_contact_speed_mps},
                                                   {"path_step_m", path_step_m},
                                                   {"path_step_rad", path_step_rad},
                                                   {"joint_speed_fraction", joint_speed_fraction}};
  for (const auto& [name, value] : fields) {
    if (!(std::isfinite(value) && value > 0)) {
      return Status::InvalidInput(std::string("SafetyOptions::") + name + " = " + json::FormatNumber(value) +
                                  " must be > 0");
    }
  }
  return Status::Ok();
}

Status CheckLine(const RobotModel& model, const geometry::Pose3& world_T_base,
                 const geometry::Pose3& world_T_start, const geometry::Pose3& world_T_goal,
                 const Joints& start_joints, const MotionLimits& limits, const SafetyOptions& options,
                 const std::string& what, Joints* end_joints) {
  char buffer[320];
  if (!world_T_goal.IsValid()) return Refuse(what, "the target pose is not a valid rigid transform");
  if (!(limits.speed_mps <= options.max_tool_speed_mps)) {
    std::snprintf(buffer, sizeof buffer,
                  "speed %.1f mm/s exceeds the speed limit %.1f mm/s (ISO 10218-1 reduced speed)",
                  limits.speed_mps * 1e3, options.max_tool_speed_mps * 1e3);
    return Refuse(what, buffer);
  }
  const Eigen::Vector3d& goal = world_T_goal.translation;
  if ((goal.array() < options.workspace.min.array()).any() ||
      (goal.array() > options.workspace.max.array()).any()) {
    return Refuse(what, "target " + Mm(goal) + " is outside the workspace " + Mm(options.workspace.min) +
                            " to " + Mm(options.workspace.max));
  }
  const geometry::Pose3 base_T_world = world_T_base.Inverse();
  // The target itself first: its error is the clearest ("out of reach" rather than a limit on the way).
  if (Result<IkSolution> at_goal = NearestToolIk(model, base_T_world * world_T_goal, start_joints);
      !at_goal.ok()) {
    return Refuse(what, "target: " + at_goal.status().message());
  }
  const CartesianLine line(world_T_start, world_T_goal, limits);
  const int steps =
      std::max(1, static_cast<int>(std::ceil(std::max(line.length_m() / options.path_step_m,
                                                      line.angle_rad() / options.path_step_rad))));
  // The fastest the line may be taken (cruise), per step: a lower bound on the time between samples.
  const double step_time_s =
      std::max(line.length_m() / limits.speed_mps, line.angle_rad() / limits.angular_speed_rad_s) / steps;
  Joints q = start_joints;
  const Joints max_speed = model.MaxSpeeds() * options.joint_speed_fraction;
  for (int k = 1; k <= steps; ++k) {
    const double s = static_cast<double>(k) / steps;
    const geometry::Pose3 world_T_tool = geometry::Interpolate(world_T_start, world_T_goal, s);
    Result<IkSolution> ik = NearestToolIk(model, base_T_world * world_T_tool, q);
    if (!ik.ok()) {
      std::snprintf(buffer, sizeof buffer, "at %.0f%% of the line to %s: ", s * 100, Mm(goal).c_str());
      return Refuse(what, buffer + ik.status().message());
    }
    if (step_time_s > 0) {
      for (int i = 0; i < kNumJoints; ++i) {
        const double rate = std::abs(ik->q[i] - q[i]) / step_time_s;
        if (rate > max_speed[i]) {
          std::snprintf(
              buffer, sizeof buffer,
              "at %.0f%% of the line to %s %s would need %.2f rad/s, above its %.2f rad/s (%s); lower the "
              "speed or change the path",
              s * 100, Mm(goal).c_str(), model.joints[i].name.c_str(), rate, max_speed[i],
              DetectSingularities(model, ik->q, {0.05, 0.05, 0.02}).Describe().c_str());
          return Refuse(what, buffer);
        }
      }
    }
    q = ik->q;
  }
  if (end_joints != nullptr) *end_joints = q;
  return Status::Ok();
}

Status CheckProgram(const RobotModel& model, const geometry::Pose3& world_T_base, const Program& program,
                    const Joints& current, const MotionLimits& limits, const SafetyOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  TEACHSIM_RETURN_IF_ERROR(program.Validate());
  if (!model.WithinLimits(current, 1e-6))
    return Refuse("start", "the current joints are beyond the joint limits");
  Joints q = current;
  geometry::Pose3 pose = world_T_base * ToolPose(model, current);
  auto line = [&](const geometry::Pose3& goal, double speed, const std::string& what) -> Status {
    MotionLimits l = limits;
    l.speed_mps = speed;
    TEACHSIM_RETURN_IF_ERROR(CheckLine(model, world_T_base, pose, goal, q, l, options, what, &q));
    pose = goal;
    return Status::Ok();
  };
  for (std::size_t i = 0; i < program.commands.size(); ++i) {
    const Command& command = program.commands[i];
    const std::string what = "commands[" + std::to_string(i) + "] (" + CommandType(command) + ")";
    if (const auto* g = std::get_if<GraspCommand>(&command)) {
      TEACHSIM_RETURN_IF_ERROR(CheckWidth(model, what, "open_width_m", g->open_width_m));
      TEACHSIM_RETURN_IF_ERROR(CheckWidth(model, what, "width_m", g->width_m));
      TEACHSIM_RETURN_IF_ERROR(line(g->ApproachPose(), g->approach_speed_mps, what + " approach"));
      TEACHSIM_RETURN_IF_ERROR(line(g->world_T_tool, g->speed_mps, what + " descent"));
    } else if (const auto* m = std::get_if<MoveCommand>(&command)) {
      TEACHSIM_RETURN_IF_ERROR(line(m->world_T_tool, m->speed_mps, what));
    } else if (const auto* c = std::get_if<ContactMoveCommand>(&command)) {
      if (c->speed_mps > options.max_contact_speed_mps) {
        char buffer[160];
        std::snprintf(buffer, sizeof buffer, "speed %.1f mm/s exceeds the contact-move limit %.1f mm/s",
                      c->speed_mps * 1e3, options.max_contact_speed_mps * 1e3);
        return Refuse(what, buffer);
      }
      const Eigen::Vector3d& nominal = c->world_T_tool.translation;
      if ((nominal.array() < options.workspace.min.array()).any() ||
          (nominal.array() > options.workspace.max.array()).any()) {
        return Refuse(what, "target " + Mm(nominal) + " is outside the workspace");
      }
      TEACHSIM_RETURN_IF_ERROR(line(c->BiasedTarget(), c->speed_mps, what));
    } else if (const auto* r = std::get_if<ReleaseCommand>(&command)) {
      TEACHSIM_RETURN_IF_ERROR(CheckWidth(model, what, "width_m", r->width_m));
    } else if (const auto* t = std::get_if<RetreatCommand>(&command)) {
      geometry::Pose3 up = pose;
      up.translation.z() += t->distance_m;
      TEACHSIM_RETURN_IF_ERROR(line(up, t->speed_mps, what));
    }
  }
  return Status::Ok();
}

}  // namespace teachsim::robot
