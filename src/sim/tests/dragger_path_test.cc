#include <gtest/gtest.h>

#include "teachsim/sim/dragger.h"
#include "teachsim/sim/path.h"
#include "teachsim/sim/script.h"

namespace teachsim::sim {
namespace {

// Dragging on the top face (+z) moves the dragger in the horizontal plane through that face,
// wherever the camera ray comes from; the force follows the displacement and saturates.
TEST(Dragger, TopFaceDragStaysInItsPlaneAndPullsWithSaturation) {
  const geometry::Pose3 block = geometry::Pose3::Translation({0.0, 0.0, 0.0225});
  Dragger dragger(block, Eigen::Vector3d::Constant(0.0325));
  const Eigen::Vector3d eye(0.3, 0.2, 0.4);
  ASSERT_TRUE(dragger.Pick(5, eye, Eigen::Vector3d(0.0, 0.0, 0.055) - eye));
  ASSERT_TRUE(dragger.DragTo(eye, Eigen::Vector3d(0.01, 0.005, 0.055) - eye));
  EXPECT_NEAR(dragger.world_T_dragger().translation.z(), 0.0225, 1e-12);
  EXPECT_NEAR(dragger.world_T_dragger().translation.x(), 0.01, 1e-12);
  EXPECT_NEAR(dragger.world_T_dragger().translation.y(), 0.005, 1e-12);
  StepInput f = dragger.Force(block);
  EXPECT_NEAR(f.force_n.x(), 1.0, 1e-9);  // 100 N/m * 10 mm
  EXPECT_NEAR(f.force_n.y(), 0.5, 1e-9);
  EXPECT_NEAR(f.force_n.z(), 0.0, 1e-9);
  EXPECT_EQ(f.torque_nm.norm(), 0.0);  // no rotation handle used
  ASSERT_TRUE(dragger.DragTo(eye, Eigen::Vector3d(0.2, 0.0, 0.055) - eye));
  EXPECT_NEAR(dragger.Force(block).force_n.norm(), 4.0, 1e-9);  // saturated
  // A ray parallel to the plane cannot drag.
  EXPECT_FALSE(dragger.DragTo(Eigen::Vector3d(0, 0, 0.055), Eigen::Vector3d(1, 0, 0)));
  dragger.Release();
  EXPECT_FALSE(dragger.DragTo(eye, Eigen::Vector3d(0, 0, 0.055) - eye));
}

TEST(Dragger, SideFaceDragMovesVertically) {
  const geometry::Pose3 block = geometry::Pose3::Translation({0.0, 0.0, 0.0225});
  Dragger dragger(block, Eigen::Vector3d::Constant(0.0325));
  const Eigen::Vector3d eye(0.5, 0.0, 0.03);
  ASSERT_TRUE(dragger.Pick(1, eye, Eigen::Vector3d(0.0325, 0.0, 0.03) - eye));  // +x face
  ASSERT_TRUE(dragger.DragTo(eye, Eigen::Vector3d(0.0325, 0.01, 0.05) - eye));
  EXPECT_NEAR(dragger.world_T_dragger().translation.x(), 0.0, 1e-12);
  EXPECT_NEAR(dragger.world_T_dragger().translation.z(), 0.0225 + 0.02, 1e-12);
}

TEST(Dragger, RotationHandleGivesATorqueAboutTheAxis) {
  const geometry::Pose3 block = geometry::Pose3::Translation({0.0, 0.0, 0.0225});
  Dragger dragger(block, Eigen::Vector3d::Constant(0.0325));
  dragger.Rotate(Eigen::Vector3d::UnitZ(), 0.5);
  StepInput f = dragger.Force(block);
  EXPECT_GT(f.torque_nm.z(), 0.0);
  EXPECT_NEAR(f.torque_nm.x(), 0.0, 1e-12);
  EXPECT_LE(f.torque_nm.norm(), 0.02 + 1e-12);
}

TEST(Path, RoundTripAndErrors) {
  WorkpiecePath path;
  path.workpiece = "cube";
  path.capture_objects = {"frame"};
  PathNode node;
  node.time_s = 0.05;
  node.world_T_workpiece = geometry::Pose3::FromAxisAngle({0, 0, 1}, 0.3, {0.01, 0.02, 0.0225});
  node.contacts.push_back({"table", {0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}, 2.5e-4, false});
  path.nodes.push_back(node);
  const json::Json doc = PathToJson(path);
  auto back = ParsePath(doc, "p.json");
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(PathToJson(*back).dump(), doc.dump());

  json::Json bad = doc;
  bad["nodes"][0]["contacts"][0]["normal"] = {0.0, 0.0, 2.0};
  EXPECT_EQ(ParsePath(bad, "p.json").status().message(), "p.json: nodes[0].contacts[0].normal: must be a unit vector, got norm 2");
  bad = doc;
  bad["nodes"] = json::Json::array();
  EXPECT_EQ(ParsePath(bad, "p.json").status().message(), "p.json: nodes: must have at least one node");
  bad = doc;
  bad["format"] = "teachsim.path/9";
  EXPECT_EQ(ParsePath(bad, "p.json").status().message(),
            "p.json: format: unsupported format 'teachsim.path/9' (expected teachsim.path/1)");
}

TEST(Script, ParsesAndRejectsWhatItCannotRun) {
  auto ok = json::ParseText(R"({"workpiece": "cube", "capture": [{"object": "frame", "from_s": 1, "to_s": 2}],
      "keyframes": [{"time_s": 0, "position": [0, 0, 0.02]}, {"time_s": 1, "position": [0.1, 0, 0.02],
      "quaternion_wxyz": [1, 0, 0, 0]}]})", "s.json");
  ASSERT_TRUE(ok.ok());
  auto script = ParseScript(*ok, "s.json");
  ASSERT_TRUE(script.ok()) << script.status().message();
  EXPECT_EQ(script->capture[0].to_s, 2.0);
  EXPECT_TRUE(script->keyframes[1].orientation.has_value());
  EXPECT_EQ(ParseScript(ScriptToJson(*script), "s.json").ok(), true);

  auto decreasing = json::ParseText(R"({"workpiece": "cube", "keyframes": [{"time_s": 1, "position": [0, 0, 0]},
      {"time_s": 0.5, "position": [0, 0, 0]}]})", "s.json");
  EXPECT_EQ(ParseScript(*decreasing, "s.json").status().message(),
            "s.json: keyframes[1].time_s: must increase (previous keyframe at 1)");
  auto capture = json::ParseText(R"({"workpiece": "cube", "capture": [{"object": "frame", "from_s": 2, "to_s": 1}],
      "keyframes": [{"time_s": 0, "position": [0, 0, 0]}]})", "s.json");
  EXPECT_EQ(ParseScript(*capture, "s.json").status().message(), "s.json: capture[0].to_s: must be >= 2, got 1");
  auto none = json::ParseText(R"({"workpiece": "cube", "keyframes": []})", "s.json");
  EXPECT_EQ(ParseScript(*none, "s.json").status().message(), "s.json: keyframes: must have at least one keyframe");
}

}  // namespace
}  // namespace teachsim::sim
