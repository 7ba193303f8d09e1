#include "teachsim/robot/robot_model.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <sstream>

namespace teachsim::robot {

namespace {

constexpr double kHalfPi = std::numbers::pi / 2;
constexpr double kStructureTolerance = 1e-9;

std::string Path(int joint, const char* field) { return "joints[" + std::to_string(joint) + "]." + field; }

// Craig's PUMA 560 pattern (§3.7, §4.7): alpha = (0, -90, 0, -90, 90, -90) degrees, a0 = a1 = a4 = a5
// = 0 and d5 = 0, so that the last three axes meet at the wrist centre.
Status CheckStructure(const RobotModel& m) {
  static constexpr double kAlpha[kNumJoints] = {0, -kHalfPi, 0, -kHalfPi, kHalfPi, -kHalfPi};
  for (int i = 0; i < kNumJoints; ++i) {
    if (std::abs(m.joints[i].alpha_rad - kAlpha[i]) > kStructureTolerance) {
      return Status::InvalidInput(Path(i, "alpha_rad") + ": must be " + json::FormatNumber(kAlpha[i]) +
                                  " (the Puma-type structure the closed-form IK needs), got " +
                                  json::FormatNumber(m.joints[i].alpha_rad));
    }
  }
  const struct {
    int joint;
    const char* field;
    double value;
  } zeros[] = {{0, "a_m", m.joints[0].a_m},
               {1, "a_m", m.joints[1].a_m},
               {4, "a_m", m.joints[4].a_m},
               {5, "a_m", m.joints[5].a_m},
               {4, "d_m", m.joints[4].d_m}};
  for (const auto& z : zeros) {
    if (std::abs(z.value) > kStructureTolerance) {
      return Status::InvalidInput(Path(z.joint, z.field) + ": must be 0 (the wrist axes must meet), got " +
                                  json::FormatNumber(z.value));
    }
  }
  if (!(m.upper_arm_m() > 0)) {
    return Status::InvalidInput(Path(2, "a_m") + ": the upper arm a2 must be > 0, got " +
                                json::FormatNumber(m.upper_arm_m()));
  }
  if (!(std::hypot(m.elbow_offset_m(), m.forearm_m()) > 0)) {
    return Status::InvalidInput(Path(3, "d_m") + ": the forearm (a3, d4) must have a length > 0");
  }
  return Status::Ok();
}

}  // namespace

std::vector<GripperBox> GripperBoxes(const GripperSpec& g, double width_m) {
  const Eigen::Vector3d& f = g.finger_size_m;
  std::vector<GripperBox> boxes;
  boxes.push_back({"palm", g.palm_size_m, geometry::Pose3::Translation(Eigen::Vector3d(0, 0, -f.z() - g.palm_size_m.z() / 2))});
  for (double side : {1.0, -1.0}) {
    boxes.push_back({side > 0 ? "finger_left" : "finger_right", f,
                     geometry::Pose3::Translation(Eigen::Vector3d(0, side * (width_m / 2 + f.y() / 2), -f.z() / 2))});
  }
  return boxes;
}

Joints RobotModel::LowerLimits() const {
  Joints v;
  for (int i = 0; i < kNumJoints; ++i) v[i] = joints[i].lower_rad;
  return v;
}

Joints RobotModel::UpperLimits() const {
  Joints v;
  for (int i = 0; i < kNumJoints; ++i) v[i] = joints[i].upper_rad;
  return v;
}

Joints RobotModel::MaxSpeeds() const {
  Joints v;
  for (int i = 0; i < kNumJoints; ++i) v[i] = joints[i].max_speed_rad_s;
  return v;
}

bool RobotModel::WithinLimits(const Joints& q, double tolerance_rad) const {
  for (int i = 0; i < kNumJoints; ++i) {
    if (!(q[i] >= joints[i].lower_rad - tolerance_rad && q[i] <= joints[i].upper_rad + tolerance_rad)) {
      return false;
    }
  }
  return true;
}

Status RobotModel::Validate() const {
  if (name.empty()) return Status::InvalidInput("name: must not be empty");
  for (int i = 0; i < kNumJoints; ++i) {
    const DhJoint& j = joints[i];
    for (double v :
         {j.alpha_rad, j.a_m, j.d_m, j.theta_offset_rad, j.lower_rad, j.upper_rad, j.max_speed_rad_s}) {
      if (!std::isfinite(v)) return Status::InvalidInput(Path(i, "") + ": all numbers must be finite");
    }
    if (!(j.lower_rad < j.upper_rad)) {
      return Status::InvalidInput(Path(i, "upper_rad") + ": must be > lower_rad " +
                                  json::FormatNumber(j.lower_rad) + ", got " +
                                  json::FormatNumber(j.upper_rad));
    }
    if (j.lower_rad < -2 * std::numbers::pi || j.upper_rad > 2 * std::numbers::pi) {
      return Status::InvalidInput(Path(i, "lower_rad") + ": limits must lie within [-2 pi, 2 pi]");
    }
    if (!(j.max_speed_rad_s > 0)) {
      return Status::InvalidInput(Path(i, "max_speed_rad_s") + ": must be > 0, got " +
                                  json::FormatNumber(j.max_speed_rad_s));
    }
  }
  TEACHSIM_RETURN_IF_ERROR(CheckStructure(*this));
  if (!flange_T_tool.IsValid()) return Status::InvalidInput("flange_T_tool: must be a finite pose");
  if (!(gripper.min_width_m >= 0 && gripper.min_width_m < gripper.max_width_m)) {
    return Status::InvalidInput("gripper: need 0 <= min_width_m < max_width_m, got " +
                                json::FormatNumber(gripper.min_width_m) + " and " +
                                json::FormatNumber(gripper.max_width_m));
  }
  for (int k = 0; k < 3; ++k) {
    if (!(std::isfinite(gripper.finger_size_m[k]) && gripper.finger_size_m[k] > 0)) {
      return Status::InvalidInput("gripper.finger_size_m[" + std::to_string(k) + "]: must be > 0, got " +
                                  json::FormatNumber(gripper.finger_size_m[k]));
    }
    if (!(std::isfinite(gripper.palm_size_m[k]) && gripper.palm_size_m[k] > 0)) {
      return Status::InvalidInput("gripper.palm_size_m[" + std::to_string(k) + "]: must be > 0, got " +
                                  json::FormatNumber(gripper.palm_size_m[k]));
    }
  }
  if (!(gripper.pad_length_m > 0 && gripper.pad_length_m <= gripper.finger_size_m.z())) {
    return Status::InvalidInput("gripper.pad_length_m: must be in (0, finger_size_m[2] = " +
                                json::FormatNumber(gripper.finger_size_m.z()) + "], got " +
                                json::FormatNumber(gripper.pad_length_m));
  }
  // Fingers and palm hang between the tool origin and the flange.
  if (gripper.finger_size_m.z() + gripper.palm_size_m.z() > flange_T_tool.translation.norm() + 1e-9) {
    return Status::InvalidInput("gripper.palm_size_m[2]: palm (" + json::FormatNumber(gripper.palm_size_m.z()) +
                                " m) and fingers (" + json::FormatNumber(gripper.finger_size_m.z()) +
                                " m) reach beyond the flange, " + json::FormatNumber(flange_T_tool.translation.norm()) +
                                " m from the tool origin");
  }
  if (!WithinLimits(ready_rad)) return Status::InvalidInput("ready_rad: must lie within the joint limits");
  return Status::Ok();
}

Result<RobotModel> ParseRobotModel(const json::Json& document, const std::string& name) {
  auto parsed = json::Decode<RobotModel>(document, name, [](const json::Reader& r) {
    r.RejectUnknownKeys({"format", "name", "description", "dh_convention", "joints", "flange_T_tool",
                         "gripper", "ready_rad"});
    if (r.At("format").String() != "teachsim-robot") r.At("format").Fail("must be \"teachsim-robot\"");
    if (r.At("dh_convention").String() != "modified") {
      r.At("dh_convention").Fail("must be \"modified\" (Craig's convention, docs/formats/robot.md)");
    }
    RobotModel m;
    m.name = r.At("name").NonEmptyString();
    if (auto d = r.Find("description")) (void)d->String();
    json::Reader joints = r.At("joints");
    joints.ExpectSize(kNumJoints);
    for (int i = 0; i < kNumJoints; ++i) {
      json::Reader j = joints.Index(i);
      j.RejectUnknownKeys({"name", "alpha_rad", "a_m", "d_m", "theta_offset_rad", "lower_rad", "upper_rad",
                           "max_speed_rad_s"});
      DhJoint& out = m.joints[i];
      out.name = j.At("name").NonEmptyString();
      out.alpha_rad = j.At("alpha_rad").Number();
      out.a_m = j.At("a_m").Number();
      out.d_m = j.At("d_m").Number();
      out.theta_offset_rad = j.At("theta_offset_rad").NumberInRange(-std::numbers::pi, std::numbers::pi);
      out.lower_rad = j.At("lower_rad").NumberInRange(-2 * std::numbers::pi, 2 * std::numbers::pi);
      out.upper_rad = j.At("upper_rad").NumberInRange(-2 * std::numbers::pi, 2 * std::numbers::pi);
      if (!(out.lower_rad < out.upper_rad)) j.At("upper_rad").Fail("must be > lower_rad");
      out.max_speed_rad_s = j.At("max_speed_rad_s").NumberGreaterThan(0);
    }
    m.flange_T_tool = geometry::ReadPose(r.At("flange_T_tool"));
    json::Reader g = r.At("gripper");
    g.RejectUnknownKeys({"min_width_m", "max_width_m", "finger_size_m", "pad_length_m", "palm_size_m"});
    m.gripper.min_width_m = g.At("min_width_m").NumberAtLeast(0);
    m.gripper.max_width_m = g.At("max_width_m").NumberGreaterThan(m.gripper.min_width_m);
    auto positive_size = [](const json::Reader& v) {
      const Eigen::Vector3d size = v.Vector3();
      for (int k = 0; k < 3; ++k) {
        if (!(size[k] > 0)) v.Index(static_cast<std::size_t>(k)).Fail("must be > 0");
      }
      return size;
    };
    m.gripper.finger_size_m = positive_size(g.At("finger_size_m"));
    m.gripper.palm_size_m = positive_size(g.At("palm_size_m"));
    m.gripper.pad_length_m = g.At("pad_length_m").NumberInRange(1e-6, m.gripper.finger_size_m.z());
    json::Reader ready = r.At("ready_rad");
    ready.ExpectSize(kNumJoints);
    for (int i = 0; i < kNumJoints; ++i) m.ready_rad[i] = ready.Index(i).Number();
    return m;
  });
  if (!parsed.ok()) return parsed.status();
  if (Status s = parsed->Validate(); !s.ok()) return s.WithPrefix(name);
  return parsed;
}

Result<RobotModel> LoadRobotModel(const std::string& path) {
  TEACHSIM_ASSIGN_OR_RETURN(json::Json document, json::ReadFile(path));
  return ParseRobotModel(document, path);
}

json::Json RobotModelToJson(const RobotModel& m) {
  json::Json joints = json::Json::array();
  for (const DhJoint& j : m.joints) {
    joints.push_back({{"name", j.name},
                      {"alpha_rad", j.alpha_rad},
                      {"a_m", j.a_m},
                      {"d_m", j.d_m},
                      {"theta_offset_rad", j.theta_offset_rad},
                      {"lower_rad", j.lower_rad},
                      {"upper_rad", j.upper_rad},
                      {"max_speed_rad_s", j.max_speed_rad_s}});
  }
  json::Json ready = json::Json::array();
  for (int i = 0; i < kNumJoints; ++i) ready.push_back(m.ready_rad[i]);
  return {{"format", "teachsim-robot"},
          {"name", m.name},
          {"dh_convention", "modified"},
          {"joints", joints},
          {"flange_T_tool", geometry::WritePose(m.flange_T_tool)},
          {"gripper",
           {{"min_width_m", m.gripper.min_width_m},
            {"max_width_m", m.gripper.max_width_m},
            {"finger_size_m", {m.gripper.finger_size_m.x(), m.gripper.finger_size_m.y(), m.gripper.finger_size_m.z()}},
            {"pad_length_m", m.gripper.pad_length_m},
            {"palm_size_m", {m.gripper.palm_size_m.x(), m.gripper.palm_size_m.y(), m.gripper.palm_size_m.z()}}}},
          {"ready_rad", ready}};
}

namespace {

// The shortest text that reads back as the same double.
std::string Num(double v) {
  if (std::abs(v) < 1e-12) v = 0;  // cos(pi/2) is 6e-17 in doubles; and no "-0"
  char buffer[40];
  auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, v);
  TEACHSIM_CHECK(ec == std::errc());
  return std::string(buffer, end);
}

// URDF rpy (fixed axes: R = Rz(yaw) Ry(pitch) Rx(roll)) of a rotation, exact at gimbal lock.
Eigen::Vector3d RollPitchYaw(const Eigen::Matrix3d& R) {
  double pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  if (std::abs(R(2, 0)) < 1 - 1e-12)
    return {std::atan2(R(2, 1), R(2, 2)), pitch, std::atan2(R(1, 0), R(0, 0))};
  // cos(pitch) = 0: only roll - yaw (or roll + yaw) is defined; take yaw = 0.
  return {std::atan2(-R(1, 2), R(1, 1)), R(2, 0) < 0 ? std::numbers::pi / 2 : -std::numbers::pi / 2, 0.0};
}

std::string Origin(const Eigen::Vector3d& xyz, const Eigen::Matrix3d& R) {
  Eigen::Vector3d rpy = RollPitchYaw(R);
  return "<origin xyz=\"" + Num(xyz.x()) + " " + Num(xyz.y()) + " " + Num(xyz.z()) + "\" rpy=\"" +
         Num(rpy.x()) + " " + Num(rpy.y()) + " " + Num(rpy.z()) + "\"/>";
}

}  // namespace

std::string RobotModelToUrdf(const RobotModel& m) {
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n"
      << "<!-- generated from robots/" << m.name
      << ".json by robot::RobotModelToUrdf (src/robot); do not edit by hand.\n"
      << "     link_i is the modified-DH frame i (Craig); link_6 is the flange; tool is the gripper's tool "
         "frame.\n"
      << "     URDF joint angles are the robot's joint angles q (the DH theta offsets are in the origins).\n"
      << "     Kinematics only: no inertias or geometry; effort=\"0\" because the table has no torque "
         "limits\n"
      << "     (the arm is position-controlled). -->\n"
      << "<robot name=\"" << m.name << "\">\n"
      << "  <link name=\"base_link\"/>\n";
  for (int i = 0; i < kNumJoints; ++i) {
    const DhJoint& j = m.joints[i];
    // RotX(alpha) TransX(a) RotZ(offset + q) TransZ(d) = [RotX(alpha) TransX(a) TransZ(d) RotZ(offset)]
    // RotZ(q).
    Eigen::Matrix3d Rx = Eigen::AngleAxisd(j.alpha_rad, Eigen::Vector3d::UnitX()).toRotationMatrix();
    Eigen::Vector3d xyz = Eigen::Vector3d(j.a_m, 0, 0) + Rx * Eigen::Vector3d(0, 0, j.d_m);
    Eigen::Matrix3d R =
        Rx * Eigen::AngleAxisd(j.theta_offset_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    std::string parent = i == 0 ? "base_link" : "link_" + std::to_string(i);
    out << "  <link name=\"link_" << i + 1 << "\"/>\n"
        << "  <joint name=\"" << j.name << "\" type=\"revolute\">\n"
        << "    <parent link=\"" << parent << "\"/>\n"
        << "    <child link=\"link_" << i + 1 << "\"/>\n"
        << "    " << Origin(xyz, R) << "\n"
        << "    <axis xyz=\"0 0 1\"/>\n"
        << "    <limit lower=\"" << Num(j.lower_rad) << "\" upper=\"" << Num(j.upper_rad) << "\" velocity=\""
        << Num(j.max_speed_rad_s) << "\" effort=\"0\"/>\n"
        << "  </joint>\n";
  }
  out << "  <link name=\"tool\"/>\n"
      << "  <joint name=\"tool_joint\" type=\"fixed\">\n"
      << "    <parent link=\"link_6\"/>\n"
      << "    <child link=\"tool\"/>\n"
      << "    " << Origin(m.flange_T_tool.translation, m.flange_T_tool.RotationMatrix()) << "\n"
      << "  </joint>\n"
      << "</robot>\n";
  return out.str();
}

}  // namespace teachsim::robot
