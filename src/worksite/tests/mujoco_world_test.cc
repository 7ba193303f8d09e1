// The MuJoCo work site's world: the generated MJCF loads, a wooden block rests on the table
// without sinking or jitter, the arm matches our kinematics, the wrist sensor reads the contact
// force in the tool frame, a guarded move stops on the table, and the model error keeps resting
// objects resting.
#include "teachsim/worksite/mujoco_world.h"

#include <gtest/gtest.h>

#include <cmath>

#include "teachsim/robot/controller.h"
#include "teachsim/robot/kinematics.h"
#include "tests/fixtures.h"

namespace teachsim::worksite {
namespace {

using Eigen::Vector3d;

using testing::Arm;
using testing::Puzzle;

TEST(MujocoWorld, BlocksRestOnTheTableWithoutSinkingOrJitter) {
  const scene::Scene scene = Puzzle();
  MujocoWorldOptions options;
  options.settle_s = 0;
  auto world = MujocoWorld::Create(scene, Arm(), options);
  ASSERT_TRUE(world.ok()) << world.status().message();
  (*world)->Advance(0.5);
  std::vector<geometry::Pose3> before;
  for (const char* name : {"cube", "bar", "tall", "plate", "slab"})
    before.push_back((*world)->ObjectPose(name));
  (*world)->Advance(2.0);
  int k = 0;
  for (const char* name : {"cube", "bar", "tall", "plate", "slab"}) {
    const int index = scene.FindObject(name);
    const scene::SceneObject& o = scene.objects[static_cast<std::size_t>(index)];
    const geometry::Pose3 now = (*world)->ObjectPose(name);
    // Resting on the table: the bottom at z = 0 (the scene put it 0.25 mm above), within 0.3 mm.
    const double half_height = o.shape_spec.box_size.z() / 2;
    EXPECT_NEAR(now.translation.z(), half_height, 3e-4) << name;
    // No drift or jitter over 2 s at rest.
    EXPECT_LT(geometry::TranslationDistance(now, before[static_cast<std::size_t>(k)]), 2e-5) << name;
    EXPECT_LT(geometry::RotationAngle(now, before[static_cast<std::size_t>(k)]), 1e-3) << name;
    EXPECT_LT((now.translation - o.world_T_object.translation).head<2>().norm(), 1e-4) << name;
    ++k;
  }
  // The cube's weight is carried by the table: a 45 mm wooden cube, about 55 g.
  const Vector3d support = (*world)->ContactForceOn("cube");
  EXPECT_NEAR(support.z(), 600 * std::pow(0.045, 3) * 9.81, 0.02);
}

TEST(MujocoWorld, ArmFollowsOurKinematicsAndTheSensorIsTheWristOnly) {
  const scene::Scene scene = Puzzle();
  const robot::RobotModel arm = Arm();
  robot::Joints q;
  q << 0.3, 0.2, -0.4, 0.5, 1.2, -0.3;
  MujocoWorldOptions options;
  options.settle_s = 0.5;
  auto world = MujocoWorld::Create(scene, arm, options, &q);
  ASSERT_TRUE(world.ok()) << world.status().message();
  const robot::Joints measured = (*world)->ReadJoints();
  EXPECT_LT((measured - q).cwiseAbs().maxCoeff(), 2e-3);  // the servos hold against the links' weight
  const geometry::Pose3 ours = scene.robot->world_T_base * robot::ToolPose(arm, measured);
  const geometry::Pose3 theirs = (*world)->TrueToolPose();
  EXPECT_LT(geometry::TranslationDistance(ours, theirs), 1e-9);
  EXPECT_LT(geometry::RotationAngle(ours, theirs), 1e-9);
  // In free space, at rest, the sensor reads the gripper's weight only (straight down, world).
  const robot::Wrench w = (*world)->ReadWristWrench();
  const Vector3d f_world = theirs.Rotate(w.force_n);
  EXPECT_LT(f_world.head<2>().norm(), 0.05);
  EXPECT_NEAR(f_world.z(), -(0.4 + 2 * 0.03) * 9.81, 0.05);
  const robot::GripperState g = (*world)->ReadGripper();
  EXPECT_FALSE(g.moving);
  EXPECT_NEAR(g.width_m, 0.9 * arm.gripper.max_width_m, 1e-4);
}

TEST(MujocoWorld, GripperClosesToTheCommandedWidth) {
  auto world = MujocoWorld::Create(Puzzle(), Arm(), {});
  ASSERT_TRUE(world.ok());
  (*world)->CommandGripper(0.03);
  (*world)->Advance(0.05);
  EXPECT_TRUE((*world)->ReadGripper().moving);
  (*world)->Advance(1.0);
  EXPECT_FALSE((*world)->ReadGripper().moving);
  EXPECT_NEAR((*world)->ReadGripper().width_m, 0.03, 1e-3);
}

// Issue 5: a guarded move down onto the table stops with the force below the limit and within 1 mm
// of first contact (first contact: the simulator's ground truth, never shown to the controller).
TEST(MujocoWorld, GuardedMoveOntoTheTableStopsWithinOneMillimetreOfFirstContact) {
  const scene::Scene scene = Puzzle();
  const robot::RobotModel arm = Arm();
  auto created = MujocoWorld::Create(scene, arm, {});
  ASSERT_TRUE(created.ok());
  MujocoWorld& world = **created;
  robot::ControllerOptions options;
  options.safety.workspace.min.z() = -0.02;  // the plan goes into the table: the guard must stop it
  robot::TaskController controller(arm, scene.robot->world_T_base, options);
  // Above a free spot of the table, tool pointing down, planned 10 mm into the table.
  const Eigen::Quaterniond down(Eigen::AngleAxisd(M_PI, Vector3d::UnitX()));
  robot::MotionRequest approach;
  approach.world_T_tool = geometry::Pose3(down, Vector3d(0.0, -0.2, 0.05));
  approach.speed_mps = 0.1;
  ASSERT_TRUE(controller.StartMotion(approach, world, 0).ok());
  double t = 0;
  while (controller.Cycle(world, t)) {
    world.Advance(options.cycle_s);
    t += options.cycle_s;
  }
  ASSERT_TRUE(controller.report().success) << controller.report().message;
  robot::MotionRequest descend;
  descend.world_T_tool = geometry::Pose3(down, Vector3d(0.0, -0.2, -0.01));
  descend.speed_mps = 0.02;
  descend.guard = robot::GuardSpec{Vector3d::UnitZ(), 5.0};
  ASSERT_TRUE(controller.StartMotion(descend, world, t).ok());
  double first_contact_z = NAN;
  while (true) {
    const bool running = controller.Cycle(world, t);
    if (!running) break;
    for (int k = 0; k < 10; ++k) {
      world.Advance(0.001);
      if (std::isnan(first_contact_z) && (world.ContactForceOn("finger_left").norm() > 0 ||
                                          world.ContactForceOn("finger_right").norm() > 0)) {
        first_contact_z = world.TrueToolPose().translation.z();
      }
    }
    t += options.cycle_s;
    ASSERT_LT(t, 20);
  }
  world.Advance(0.5);  // the servos settle on the held setpoint
  const robot::CommandReport& rep = controller.report().commands[0];
  EXPECT_EQ(rep.status, robot::CommandStatus::kReached) << rep.message;
  EXPECT_TRUE(rep.guard_triggered) << rep.message;
  ASSERT_FALSE(std::isnan(first_contact_z));
  const double z = world.TrueToolPose().translation.z();
  std::printf("guarded stop: first contact at z = %.2f mm, stopped at %.2f mm; peak %.1f N, now %.1f N\n",
              first_contact_z * 1e3, z * 1e3, rep.peak_force_n, world.ContactForceOn("table").norm());
  EXPECT_NEAR(first_contact_z, 0.0, 5e-4);  // the fingertips are the tool origin
  EXPECT_LT(std::abs(z - first_contact_z), 1e-3);
  EXPECT_LT(rep.peak_force_n, options.monitor.force_limit_n);
  EXPECT_LT(world.ContactForceOn("table").norm(), options.monitor.force_limit_n);
}

TEST(MujocoWorld, ModelErrorMovesRestingObjectsInThePlaneOnly) {
  const scene::Scene scene = Puzzle();
  ModelError error;
  error.position_m = 0.003;
  error.angle_rad = 2 * M_PI / 180;
  double min_friction = 1, max_friction = 0;
  double largest_move = 0;
  for (std::uint64_t seed = 1; seed <= 50; ++seed) {
    error.seed = seed;
    const PerturbedWorld w = PerturbScene(scene, error);
    min_friction = std::min(min_friction, w.block_friction);
    max_friction = std::max(max_friction, w.block_friction);
    for (std::size_t i = 0; i < scene.objects.size(); ++i) {
      const geometry::Pose3& a = scene.objects[i].world_T_object;
      const geometry::Pose3& b = w.scene.objects[i].world_T_object;
      if (scene.objects[i].fixed) {
        EXPECT_EQ(a.translation, b.translation);
        continue;
      }
      EXPECT_DOUBLE_EQ(a.translation.z(), b.translation.z());  // still on the table
      EXPECT_LE(geometry::TranslationDistance(a, b), error.position_m + 1e-12);
      EXPECT_LE(geometry::RotationAngle(a, b), error.angle_rad + 1e-9);
      EXPECT_NEAR((b.rotation * Vector3d::UnitZ()).z(), 1.0, 1e-9);  // upright
      largest_move = std::max(largest_move, geometry::TranslationDistance(a, b));
    }
  }
  EXPECT_GT(largest_move, 0.0025);  // the error is used, not ignored
  EXPECT_GE(min_friction, 0.1);
  EXPECT_LE(max_friction, 0.5);
  EXPECT_LT(min_friction, 0.2);
  EXPECT_GT(max_friction, 0.4);
  // Deterministic per seed.
  error.seed = 7;
  EXPECT_EQ(PerturbScene(scene, error).scene.objects[2].world_T_object.translation,
            PerturbScene(scene, error).scene.objects[2].world_T_object.translation);
}

TEST(MujocoWorld, SceneWithoutRobotIsRejected) {
  scene::Scene scene = Puzzle();
  scene.robot.reset();
  auto world = MujocoWorld::Create(scene, Arm(), {});
  ASSERT_FALSE(world.ok());
  EXPECT_NE(world.status().message().find("robot"), std::string::npos);
}

}  // namespace
}  // namespace teachsim::worksite
