// The arm's table (robots/*.json, docs/formats/robot.md): modified Denavit–Hartenberg parameters
// (Craig's convention), joint limits and speeds, the gripper's tool frame and opening range.
// A RobotModel is const once loaded (STYLE.md: model apart from state).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::robot {

inline constexpr int kNumJoints = 6;
using Joints = Eigen::Matrix<double, kNumJoints, 1>;  // rad, in the robot's joint convention

// Row i of Craig's modified DH table: link frame i relative to frame i-1 is
//   RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(theta_i) TransZ(d_i),  theta_i = q_i + theta_offset_i.
struct DhJoint {
  std::string name;
  double alpha_rad = 0;         // alpha_{i-1}
  double a_m = 0;               // a_{i-1}
  double d_m = 0;               // d_i
  double theta_offset_rad = 0;  // theta_i at q_i = 0
  double lower_rad = 0, upper_rad = 0;
  double max_speed_rad_s = 0;
};

// The parallel-jaw gripper's opening range and its geometry (boxes, in the tool frame: z out of
// the gripper, y the closing direction). The MuJoCo work site builds its gripper from these and the
// program generator checks them against the scene along every program (the palm catching a wall
// after a corner was what made the first around-the-corner program fail on the work site).
struct GripperSpec {
  double min_width_m = 0;  // parallel jaws: distance between the finger pads
  double max_width_m = 0;
  // Each finger: depth (x) x thickness (y) x length (z); its inner face at y = +-width / 2, its tip
  // at the tool origin, reaching back toward the flange.
  Eigen::Vector3d finger_size_m = Eigen::Vector3d(0.016, 0.008, 0.025);
  // The finger's lower pad_length_m is its rubber pad (soft, high friction); above it, bare finger.
  double pad_length_m = 0.025;
  // The palm: centred on the tool z axis, its underside on the fingers' tops (z = -finger length),
  // reaching toward the flange.
  Eigen::Vector3d palm_size_m = Eigen::Vector3d(0.03, 0.104, 0.105);
};

// One box of the gripper, placed in the tool frame.
struct GripperBox {
  std::string name;  // "palm", "finger_left" (+y), "finger_right" (-y)
  Eigen::Vector3d size_m;
  geometry::Pose3 tool_T_box;
};
// The palm and both fingers (pads included) with the jaws `width_m` apart.
std::vector<GripperBox> GripperBoxes(const GripperSpec& gripper, double width_m);

struct RobotModel {
  std::string name;
  std::array<DhJoint, kNumJoints> joints;
  // The tool frame (gripper): origin midway between the finger pads, z out of the gripper (the
  // approach direction), y the closing direction. DH frame 6 is the flange.
  geometry::Pose3 flange_T_tool;
  GripperSpec gripper;
  Joints ready_rad = Joints::Zero();  // a comfortable start: tool pointing down above the work area

  Joints LowerLimits() const;
  Joints UpperLimits() const;
  Joints MaxSpeeds() const;
  bool WithinLimits(const Joints& q, double tolerance_rad = 0) const;

  // Named lengths of the Puma-type geometry (Craig §4.7), read from the table.
  double base_height_m() const { return joints[0].d_m; }                      // d1
  double shoulder_offset_m() const { return joints[1].d_m + joints[2].d_m; }  // d2 + d3
  double upper_arm_m() const { return joints[2].a_m; }                        // a2
  double elbow_offset_m() const { return joints[3].a_m; }                     // a3
  double forearm_m() const { return joints[3].d_m; }                          // d4
  double flange_m() const { return joints[5].d_m; }                           // d6

  // The checks a loaded table must pass (the closed-form IK needs the Puma structure).
  [[nodiscard]] Status Validate() const;
};

// Loading: errors name the file and the JSON path ("robots/x.json: joints[2].lower_rad: ...").
[[nodiscard]] Result<RobotModel> LoadRobotModel(const std::string& path);
[[nodiscard]] Result<RobotModel> ParseRobotModel(const json::Json& document, const std::string& name);
json::Json RobotModelToJson(const RobotModel& model);

// The URDF of the same arm (base_link, link_1..link_6 = DH frames, flange = link_6, tool), numbers
// written as the shortest text that reads back exactly, so its FK agrees with ours to rounding.
std::string RobotModelToUrdf(const RobotModel& model);

}  // namespace teachsim::robot
