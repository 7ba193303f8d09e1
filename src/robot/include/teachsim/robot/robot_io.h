// What the task controller sees of a robot: only what a real one offers (issue 5): joint
// positions, the wrist force/torque sensor, the gripper; and what it commands: joint position
// setpoints (for the 1 kHz joint servos) and the gripper. Backends: the MuJoCo work site, the
// tests' kinematic plant, one day a real arm.
#pragma once

#include <Eigen/Core>

#include "teachsim/robot/robot_model.h"

namespace teachsim::robot {

struct Wrench {
  // Exerted by the environment on the tool (through the fingers and whatever they hold), in the
  // tool frame, about the tool frame's origin.
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();
};

struct GripperState {
  double width_m = 0;   // between the finger pads
  bool moving = false;  // still closing or opening (false once stopped by an object)
};

class RobotIo {
 public:
  virtual ~RobotIo() = default;
  virtual Joints ReadJoints() = 0;
  virtual Wrench ReadWristWrench() = 0;
  virtual GripperState ReadGripper() = 0;
  virtual void CommandJoints(const Joints& setpoint_rad) = 0;
  virtual void CommandGripper(double width_m) = 0;
};

}  // namespace teachsim::robot
