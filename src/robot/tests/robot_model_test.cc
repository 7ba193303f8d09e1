#include "teachsim/robot/robot_model.h"

#include <gtest/gtest.h>
#include <urdf_parser/urdf_parser.h>

#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>

#include "teachsim/robot/kinematics.h"

namespace teachsim::robot {
namespace {

const std::string kTable = std::string(TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.json";
const std::string kUrdf = std::string(TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.urdf";

json::Json TableJson() {
  auto doc = json::ReadFile(kTable);
  TEACHSIM_CHECK(doc.ok());
  return *doc;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(RobotModel, LoadsTheCrsA465Table) {
  Result<RobotModel> m = LoadRobotModel(kTable);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_EQ(m->name, "crs_a465");
  EXPECT_DOUBLE_EQ(m->base_height_m(), 0.330);
  EXPECT_DOUBLE_EQ(m->upper_arm_m(), 0.305);
  EXPECT_DOUBLE_EQ(m->forearm_m(), 0.330);
  EXPECT_DOUBLE_EQ(m->flange_m(), 0.076);
  EXPECT_DOUBLE_EQ(m->shoulder_offset_m(), 0.0);
  EXPECT_DOUBLE_EQ(m->elbow_offset_m(), 0.0);
  EXPECT_GT(m->flange_T_tool.translation.z(), 0.05);  // the gripper reaches beyond the flange
  EXPECT_LT(m->gripper.min_width_m, 0.045);           // closes on a 45 mm block
  EXPECT_GT(m->gripper.max_width_m, 0.060);           // opens wider than a 60 mm block
  // The gripper's boxes: the palm's underside 25 mm above the fingertips (the tool origin), the
  // fingers' inner faces at +-width / 2, everything between the tool origin and the flange.
  const std::vector<GripperBox> boxes = GripperBoxes(m->gripper, 0.06);
  ASSERT_EQ(boxes.size(), 3u);
  EXPECT_EQ(boxes[0].name, "palm");
  EXPECT_NEAR(boxes[0].tool_T_box.translation.z() + boxes[0].size_m.z() / 2, -0.025, 1e-12);
  EXPECT_NEAR(boxes[0].tool_T_box.translation.z() - boxes[0].size_m.z() / 2, -0.13, 1e-12);
  EXPECT_NEAR(boxes[1].tool_T_box.translation.y() - boxes[1].size_m.y() / 2, 0.03, 1e-12);
  EXPECT_NEAR(boxes[2].tool_T_box.translation.y() + boxes[2].size_m.y() / 2, -0.03, 1e-12);
  EXPECT_NEAR(boxes[1].tool_T_box.translation.z() + boxes[1].size_m.z() / 2, 0.0, 1e-12);
  for (const DhJoint& j : m->joints) {
    EXPECT_LT(j.lower_rad, 0);
    EXPECT_GT(j.upper_rad, 0);
    EXPECT_GT(j.max_speed_rad_s, 1.0);
  }
  // Round trip through JSON.
  Result<RobotModel> again = ParseRobotModel(RobotModelToJson(*m), "again");
  ASSERT_TRUE(again.ok()) << again.status().message();
  EXPECT_EQ(RobotModelToJson(*again).dump(), RobotModelToJson(*m).dump());
}

struct BadCase {
  const char* json_pointer;
  json::Json value;
  const char* expected;  // substring of the message after the file name
};

TEST(RobotModel, ValidationErrorsNameFileAndJsonPath) {
  const BadCase cases[] = {
      {"/joints/2/lower_rad", 2.5, "joints[2].upper_rad: must be > lower_rad"},
      {"/joints/1/alpha_rad", 1.5707963267948966, "joints[1].alpha_rad: must be -1.5708"},
      {"/joints/4/d_m", 0.01, "joints[4].d_m: must be 0"},
      {"/joints/3/max_speed_rad_s", 0.0, "joints[3].max_speed_rad_s: must be > 0"},
      {"/joints/0/a_m", "zero", "joints[0].a_m: must be a number, got string"},
      {"/gripper/max_width_m", -0.01, "gripper.max_width_m: must be > 0"},
      {"/gripper/finger_size_m/1", 0.0, "gripper.finger_size_m[1]: must be > 0"},
      {"/gripper/palm_size_m", json::Json::array({0.03, 0.1}), "gripper.palm_size_m: must have 3 elements"},
      {"/gripper/pad_length_m", 0.03, "gripper.pad_length_m: must be"},
      {"/gripper/palm_size_m/2", 0.2, "gripper.palm_size_m[2]: palm (0.2 m) and fingers (0.025 m) reach beyond the flange"},
      {"/gripper/pads", 1.0, "gripper: unknown field 'pads'"},
      {"/flange_T_tool/quaternion_wxyz", json::Json::array({0, 0, 0, 2}),
       "flange_T_tool.quaternion_wxyz: must be a unit"},
      {"/ready_rad/1", 3.0, "ready_rad: must lie within the joint limits"},
      {"/dh_convention", "standard", "dh_convention: must be \"modified\""},
      {"/joints/5/speed", 1.0, "joints[5]: unknown field 'speed'"},
  };
  for (const BadCase& c : cases) {
    json::Json doc = TableJson();
    doc[json::Json::json_pointer(c.json_pointer)] = c.value;
    Result<RobotModel> m = ParseRobotModel(doc, "robots/bad.json");
    ASSERT_FALSE(m.ok()) << c.json_pointer;
    EXPECT_EQ(m.status().code(), StatusCode::kInvalidInput);
    EXPECT_EQ(m.status().message().rfind("robots/bad.json: ", 0), 0u) << m.status().message();
    EXPECT_NE(m.status().message().find(c.expected), std::string::npos)
        << "got: " << m.status().message() << "\nexpected: " << c.expected;
  }
  json::Json doc = TableJson();
  doc["joints"].erase(5);
  Result<RobotModel> m = ParseRobotModel(doc, "robots/bad.json");
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.status().message().find("joints: must have 6 elements, got 5"), std::string::npos);
  EXPECT_FALSE(LoadRobotModel("/nonexistent/robot.json").ok());
}

// robots/crs_a465.urdf is generated from the table; set TEACHSIM_UPDATE_GOLDEN=1 to rewrite it.
TEST(RobotModel, UrdfFileIsGeneratedFromTheTable) {
  Result<RobotModel> m = LoadRobotModel(kTable);
  ASSERT_TRUE(m.ok());
  std::string urdf = RobotModelToUrdf(*m);
  if (const char* update = std::getenv("TEACHSIM_UPDATE_GOLDEN"); update != nullptr && *update == '1') {
    ASSERT_TRUE(json::WriteFileAtomic(kUrdf, urdf).ok());
  }
  EXPECT_EQ(ReadText(kUrdf), urdf) << "robots/crs_a465.urdf is stale: rerun with TEACHSIM_UPDATE_GOLDEN=1";
}

geometry::Pose3 FromUrdf(const urdf::Pose& p) {
  double w, x, y, z;
  p.rotation.getQuaternion(x, y, z, w);
  return {Eigen::Quaterniond(w, x, y, z).normalized(),
          Eigen::Vector3d(p.position.x, p.position.y, p.position.z)};
}

// Debian's liburdfdom parses the file; chaining its joint origins and axes gives our FK.
TEST(RobotModel, UrdfForwardKinematicsMatchesOurs) {
  Result<RobotModel> m = LoadRobotModel(kTable);
  ASSERT_TRUE(m.ok());
  urdf::ModelInterfaceSharedPtr model = urdf::parseURDFFile(kUrdf);
  ASSERT_TRUE(model != nullptr);
  EXPECT_EQ(model->getName(), "crs_a465");
  std::vector<urdf::JointConstSharedPtr> chain;
  for (std::string link = "tool"; link != "base_link";) {
    urdf::LinkConstSharedPtr l = model->getLink(link);
    ASSERT_TRUE(l != nullptr && l->parent_joint != nullptr) << link;
    chain.insert(chain.begin(), l->parent_joint);
    link = l->parent_joint->parent_link_name;
  }
  ASSERT_EQ(chain.size(), 7u);
  for (int i = 0; i < kNumJoints; ++i) {
    EXPECT_EQ(chain[i]->type, urdf::Joint::REVOLUTE);
    EXPECT_EQ(chain[i]->name, m->joints[i].name);
    EXPECT_DOUBLE_EQ(chain[i]->limits->lower, m->joints[i].lower_rad);
    EXPECT_DOUBLE_EQ(chain[i]->limits->upper, m->joints[i].upper_rad);
    EXPECT_DOUBLE_EQ(chain[i]->limits->velocity, m->joints[i].max_speed_rad_s);
  }
  EXPECT_EQ(chain[6]->type, urdf::Joint::FIXED);

  std::mt19937_64 rng(5);
  double worst = 0;
  for (int n = 0; n < 1000; ++n) {
    Joints q;
    for (int i = 0; i < kNumJoints; ++i) {
      q[i] = std::uniform_real_distribution<double>(m->joints[i].lower_rad, m->joints[i].upper_rad)(rng);
    }
    auto frames = LinkFrames(*m, q);
    geometry::Pose3 T;
    for (int i = 0; i < 7; ++i) {
      T = T * FromUrdf(chain[i]->parent_to_joint_origin_transform);
      if (i < kNumJoints) {
        const urdf::Vector3& a = chain[i]->axis;
        T = T * geometry::Pose3::FromAxisAngle(Eigen::Vector3d(a.x, a.y, a.z), q[i]);
        double error = std::max(geometry::TranslationDistance(T, frames[i + 1]),
                                geometry::RotationAngle(T, frames[i + 1]));
        worst = std::max(worst, error);
      }
    }
    geometry::Pose3 tool = ToolPose(*m, q);
    worst = std::max({worst, geometry::TranslationDistance(T, tool), geometry::RotationAngle(T, tool)});
  }
  EXPECT_LT(worst, 1e-9);
}

}  // namespace
}  // namespace teachsim::robot
