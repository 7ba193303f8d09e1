// The hooks a work-site service drives an execution with (ExecuteOptions::on_tick, stop_requested,
// pace) and the camera's view of the executing world (MujocoWorld::RenderObjects): a tick per
// controller cycle with the command and state, a requested stop that brings the arm to rest
// within 0.1 s simulated and still holds the block, and renders in which the arm hides part of
// the block below it.
#include <gtest/gtest.h>

#include <cmath>

#include "teachsim/robot/kinematics.h"
#include "teachsim/vision/camera.h"
#include "teachsim/worksite/execute.h"
#include "teachsim/worksite/render.h"
#include "tests/fixtures.h"

namespace teachsim::worksite {
namespace {

using Eigen::Vector3d;

using testing::Arm;
using testing::Puzzle;

// Grasp the cube from above (jaws along its y axis, fingertips 12 mm below its top), lift it and
// carry it 12 cm across the table at 0.1 m/s.
robot::Program CarryCube(const scene::Scene& scene) {
  const scene::SceneObject& cube = scene.objects[static_cast<std::size_t>(scene.FindObject("cube"))];
  robot::Program program;
  program.workpiece = "cube";
  program.workpiece_T_tool = geometry::Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Vector3d::UnitX())),
                                             Vector3d(0, 0, cube.shape_spec.box_size.z() / 2 - 0.012));
  robot::GraspCommand grasp;
  grasp.world_T_tool = cube.world_T_object * program.workpiece_T_tool;
  grasp.width_m = cube.shape_spec.box_size.y();
  grasp.open_width_m = grasp.width_m + 0.015;
  program.commands.push_back(grasp);
  geometry::Pose3 up = grasp.world_T_tool;
  up.translation.z() += 0.05;
  program.commands.push_back(robot::MoveCommand{up, 0.1});
  geometry::Pose3 across = up;
  across.translation.x() -= 0.12;
  program.commands.push_back(robot::MoveCommand{across, 0.1});
  program.commands.push_back(robot::ReleaseCommand{grasp.open_width_m});
  return program;
}

TEST(ExecuteHooks, TicksEveryCycleAndStopsWithinAHundredMillisecondsHoldingTheBlock) {
  const scene::Scene scene = Puzzle();
  const robot::Program program = CarryCube(scene);
  ExecuteOptions options;
  // Ask for the stop in the middle of the carry, at full speed.
  double stop_at_s = -1;
  options.stop_requested = [&] { return stop_at_s >= 0; };
  std::vector<ExecuteTick> ticks;
  std::vector<geometry::Pose3> tools, cubes;
  options.on_tick = [&](const ExecuteTick& tick) {
    ticks.push_back(tick);
    tools.push_back(tick.world->TrueToolPose());
    cubes.push_back(tick.world->ObjectPose("cube"));
    // Half way through the carry (its 0.24 s ramps, 1.2 s total).
    if (stop_at_s < 0 && tick.command == 2 && tick.command_status == robot::CommandStatus::kRunning &&
        tools.size() > 60 && std::abs(tools.back().translation.x() - tools[tools.size() - 2].translation.x()) > 8e-4) {
      stop_at_s = tick.t_s;
    }
  };
  std::vector<double> paced;
  options.pace = [&](double t_s) { paced.push_back(t_s); };
  auto result = Execute(scene, Arm(), program, options);
  ASSERT_TRUE(result.ok()) << result.status().message();
  ASSERT_GE(stop_at_s, 0) << "the carry never reached full speed";
  EXPECT_FALSE(result->success);
  EXPECT_TRUE(result->stopped) << result->message;
  EXPECT_EQ(result->report.commands[2].status, robot::CommandStatus::kStopped);
  EXPECT_EQ(result->report.commands[3].status, robot::CommandStatus::kSkipped);
  EXPECT_NE(result->message.find("stopped"), std::string::npos) << result->message;
  const json::Json doc = ExecuteResultToJson(*result, options);
  EXPECT_TRUE(doc["stopped"].get<bool>());
  EXPECT_EQ(doc["commands"][2]["status"], "stopped");

  // One tick per controller cycle, 10 ms apart, each paced before the physics advanced.
  ASSERT_GE(ticks.size(), 100u);
  for (std::size_t i = 1; i < ticks.size(); ++i) {
    EXPECT_NEAR(ticks[i].t_s - ticks[i - 1].t_s, 0.01, 1e-9);
    EXPECT_EQ(ticks[i].command_count, program.commands.size());
    EXPECT_GE(ticks[i].command, ticks[i - 1].command);
  }
  EXPECT_EQ(paced.size(), ticks.size() - 1);
  EXPECT_EQ(ticks.front().state, ExecutionState::kRunning);
  EXPECT_EQ(ticks.back().state, ExecutionState::kStopped);
  EXPECT_EQ(ticks.back().command, 2u);
  EXPECT_EQ(ticks.back().command_type, "move");
  bool saw_stopping = false;
  for (const ExecuteTick& t : ticks) saw_stopping = saw_stopping || t.state == ExecutionState::kStopping;
  EXPECT_TRUE(saw_stopping);

  // The tool (ground truth) at rest within 0.1 s of the request (the request is seen on the cycle
  // after the tick that asked): under 1 mm/s over the last cycle; the block still held, lifted.
  std::size_t at = 0;
  while (ticks[at].t_s < stop_at_s - 1e-9) ++at;
  ASSERT_GE(at, 1u);
  const double speed_before = (tools[at].translation - tools[at - 1].translation).norm() / 0.01;
  const std::size_t n = ticks.size();
  const double speed_after = (tools[n - 1].translation - tools[n - 2].translation).norm() / 0.01;
  const double travel = (tools[n - 1].translation - tools[at].translation).norm();
  std::printf("stop: %.0f mm/s at the request, at rest (%.2f mm/s) %.2f s later, %.1f mm further\n",
              speed_before * 1e3, speed_after * 1e3, ticks.back().t_s - stop_at_s, travel * 1e3);
  EXPECT_GT(speed_before, 0.05);
  EXPECT_LE(ticks.back().t_s - stop_at_s, 0.1 + 0.01 + 1e-9);
  EXPECT_LT(speed_after, 3e-3);  // from 80-100 mm/s: the servos' last creep after 0.1 s
  EXPECT_LT(travel, 0.015);
  EXPECT_GT(cubes.back().translation.z(), 0.04);  // lifted 5 cm: still held
}

TEST(ExecuteHooks, WithoutAStopRequestTheLastTickSaysSucceeded) {
  const scene::Scene scene = Puzzle();
  ExecuteOptions options;
  ExecutionState last = ExecutionState::kRunning;
  int ticks = 0;
  options.on_tick = [&](const ExecuteTick& tick) {
    last = tick.state;
    ++ticks;
  };
  options.stop_requested = [] { return false; };
  auto result = Execute(scene, Arm(), CarryCube(scene), options);
  ASSERT_TRUE(result.ok()) << result.status().message();
  EXPECT_TRUE(result->success) << result->message;
  EXPECT_FALSE(result->stopped);
  EXPECT_EQ(last, ExecutionState::kSucceeded);
  EXPECT_EQ(static_cast<std::size_t>(ticks), result->cycle_us.size());
}

// Issue 6 ("later: of the MuJoCo world, robot included"): the arm above a block hides part of it
// in the camera's image.
TEST(MujocoWorldRender, TheArmAboveABlockHidesPartOfIt) {
  const scene::Scene scene = Puzzle();
  const robot::RobotModel arm = Arm();
  const scene::SceneObject& cube = scene.objects[static_cast<std::size_t>(scene.FindObject("cube"))];
  // The tool 15 mm above the cube's top, pointing down.
  const geometry::Pose3 world_T_tool(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Vector3d::UnitX())),
                                     cube.world_T_object.translation + Vector3d(0, 0, 0.0375));
  auto ik = robot::NearestToolIk(arm, scene.robot->world_T_base.Inverse() * world_T_tool, arm.ready_rad);
  ASSERT_TRUE(ik.ok()) << ik.status().message();
  auto camera = vision::Camera::FromSpec(scene.cameras.front());
  ASSERT_TRUE(camera.ok());
  auto renderer = Renderer::Create(*camera, RenderOptions::HighContrast());
  ASSERT_TRUE(renderer.ok());

  auto cube_truth = [&](const robot::Joints& q, std::vector<RenderObject>* objects) {
    auto world = MujocoWorld::Create(scene, arm, {}, &q);
    TEACHSIM_CHECK(world.ok());
    *objects = (*world)->RenderObjects();
    const RenderResult r = renderer->Render(*objects, 1);
    for (const ObjectTruth& t : r.objects) {
      if (t.name == "cube") return t;
    }
    return ObjectTruth{};
  };
  std::vector<RenderObject> above, ready;
  const ObjectTruth hidden = cube_truth(ik->q, &above);
  const ObjectTruth clear = cube_truth(arm.ready_rad, &ready);
  std::printf("cube visible: %.3f with the gripper above it, %.3f with the arm at its ready pose\n",
              hidden.visible_fraction, clear.visible_fraction);
  // Every scene object, then the robot's bodies that have geometry (base, links, gripper, fingers).
  ASSERT_GE(above.size(), scene.objects.size() + 6);  // links of zero length have no geometry
  for (std::size_t i = 0; i < scene.objects.size(); ++i) EXPECT_EQ(above[i].name, scene.objects[i].name);
  int robot_objects = 0;
  bool fingers = false;
  for (const RenderObject& o : above) {
    robot_objects += o.name.rfind("robot_", 0) == 0 ? 1 : 0;
    fingers = fingers || o.name == "robot_finger_left";
  }
  EXPECT_EQ(static_cast<std::size_t>(robot_objects), above.size() - scene.objects.size());
  EXPECT_TRUE(fingers);
  EXPECT_GT(clear.visible_fraction, 0.97);
  EXPECT_LT(hidden.visible_fraction, 0.9);
  EXPECT_GT(hidden.visible_pixels, 0);
  // The cube's pose is the simulated one (resting on the table).
  const RenderObject& cube_object = above[static_cast<std::size_t>(scene.FindObject("cube"))];
  EXPECT_LT(geometry::TranslationDistance(cube_object.world_T_object, cube.world_T_object), 1e-3);
}

}  // namespace
}  // namespace teachsim::worksite
