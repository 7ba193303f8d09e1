#include "teachsim/sim/simulator.h"

#include <gtest/gtest.h>

#include <random>

#include "teachsim/sim/demos.h"
#include "teachsim/geometry/toi.h"
#include "teachsim/sim/script.h"

namespace teachsim::sim {
namespace {

const std::string kPuzzle = std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json";

SimWorld PuzzleWorld() {
  auto scene = scene::LoadScene(kPuzzle);
  EXPECT_TRUE(scene.ok()) << scene.status().message();
  return SimWorld::Build(std::move(scene).value(), {}).value();
}

double Yaw(const geometry::Pose3& pose) {
  const Eigen::Vector3d x = pose.rotation * Eigen::Vector3d::UnitX();
  return std::atan2(x.y(), x.x());
}

// Angle from the nearest multiple of 90 degrees (a box's faces parallel to the walls).
double Misalignment(const geometry::Pose3& pose) {
  const double quarter = M_PI / 2;
  double r = std::fmod(std::abs(Yaw(pose)), quarter);
  return std::min(r, quarter - r);
}

// Distance from the workpiece to every obstacle part along the motion between two nodes.
double MinDistanceAlong(const SimWorld& world, int workpiece, const geometry::Pose3& a, const geometry::Pose3& b,
                        int samples) {
  double best = 1e300;
  const scene::SceneObject& wp = world.scene.objects[static_cast<std::size_t>(workpiece)];
  for (int i = 0; i <= samples; ++i) {
    const geometry::Pose3 pose = geometry::Interpolate(a, b, static_cast<double>(i) / samples);
    for (const ObstaclePart& part : world.parts) {
      if (part.object == workpiece) continue;
      for (const geometry::ShapePart& wpp : wp.shape.parts()) {
        const geometry::Pose3 wp_pose = pose * wpp.shape_T_part;
        if (wpp.convex->WorldBounds(wp_pose).Distance(part.bounds) > 0.002) continue;
        const geometry::DistanceResult d = geometry::Distance(*wpp.convex, wp_pose, *part.convex, part.world_T_part);
        best = std::min(best, d.intersecting ? -1.0 : d.distance);
      }
    }
  }
  return best;
}

// Figure 1: from 20 random starts (20 degrees misaligned) the cube ends in the south-west
// corner, in contact with the table and both walls, aligned within 0.5 degrees, every contact
// distance in [eps_b / 2, eps_c].
TEST(Simulator, CorneringFromRandomStartsEndsAlignedInTheCorner) {
  const SimWorld world = PuzzleWorld();
  const SimOptions& o = world.options;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    auto script = CorneringScript(world.scene, RandomCornering(seed));
    ASSERT_TRUE(script.ok());
    RunSummary summary;
    auto path = RunScript(world, *script, {}, &summary);
    ASSERT_TRUE(path.ok()) << path.status().message();
    bool table = false, west = false, south = false;
    for (const PathContact& c : summary.final_contacts) {
      EXPECT_GE(c.distance, 0.5 * o.barrier_distance_m) << "seed " << seed;
      EXPECT_LE(c.distance, o.contact_distance_m) << "seed " << seed;
      if (c.object == "table" && c.normal.z() > 0.999) table = true;
      if (c.object == "frame" && c.normal.x() > 0.999) west = true;
      if (c.object == "frame" && c.normal.y() > 0.999) south = true;
    }
    EXPECT_TRUE(table && west && south) << "seed " << seed << ": " << DescribeContacts(summary.final_contacts);
    EXPECT_LT(Misalignment(summary.final_pose), 0.5 * M_PI / 180) << "seed " << seed;
    EXPECT_EQ(summary.sticking_events, 0);
  }
}

// Figure 2: around the outside corner with capture on the frame and the table: after first
// contact the distance to the frame stays in (0, eps_o] at every node, the plate reaches the far
// side of the corner, and nothing sticks.
TEST(Simulator, AroundTheCornerKeepsCaptureContactWithoutSticking) {
  const SimWorld world = PuzzleWorld();
  auto script = AroundCornerScript(world.scene);
  ASSERT_TRUE(script.ok());
  RunSummary summary;
  auto path = RunScript(world, *script, {}, &summary);
  ASSERT_TRUE(path.ok()) << path.status().message();
  const int frame = world.scene.FindObject("frame");
  const int plate = world.scene.FindObject("plate");
  const auto& frame_shape = world.scene.objects[static_cast<std::size_t>(frame)].shape;
  const auto& plate_shape = world.scene.objects[static_cast<std::size_t>(plate)].shape;
  bool touched = false;
  int captured_nodes = 0;
  for (const PathNode& node : path->nodes) {
    const double d = geometry::ShapeDistance(plate_shape, node.world_T_workpiece, frame_shape, geometry::Pose3::Identity())
                         .distance;
    if (d <= world.options.contact_distance_m) touched = true;
    if (!touched) continue;
    ++captured_nodes;
    EXPECT_GT(d, 0.0) << "t " << node.time_s;
    EXPECT_LE(d, world.options.capture_distance_m + 1e-9) << "t " << node.time_s;
  }
  EXPECT_GT(captured_nodes, 100);
  // The far side: west of the corner (x < 0.05) and against the south wall's outside.
  const Eigen::Vector3d end = summary.final_pose.translation;
  EXPECT_LT(end.x(), 0.05);
  EXPECT_NEAR(end.y(), -0.13, 0.002);
  // The plate pivoted -90 degrees about the corner's edge (so that a gripper can hold it all the
  // way: its jaws stay parallel to the wall it slides along), and it lies flat on the table.
  const Eigen::Matrix3d R = summary.final_pose.RotationMatrix();
  EXPECT_NEAR(std::atan2(R(1, 0), R(0, 0)) * 180 / M_PI, -90.0, 2.0);
  EXPECT_GT(R(2, 2), std::cos(0.5 * M_PI / 180));
  EXPECT_EQ(summary.sticking_events, 0);
}

// 10^4 random scripted drags in the puzzle scene (random directions, speeds up to 400 mm/s,
// random capture choices): the distance never drops below zero over the continuous motion.
TEST(Simulator, RandomDragsNeverPenetrate) {
  const SimWorld world = PuzzleWorld();
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> u(-1.0, 1.0), unit(0.0, 1.0);
  const std::vector<std::string> movable = {"cube", "bar", "tall", "plate", "slab"};
  const std::vector<std::string> capturable = {"table", "frame", "cube", "bar"};
  const int drags = std::getenv("TEACHSIM_SANITIZER_BUILD") ? 2000 : 10000;
  double min_distance = 1e300;
  long steps = 0;
  for (int i = 0; i < drags; ++i) {
    DragScript script;
    script.workpiece = movable[static_cast<std::size_t>(i) % movable.size()];
    const auto& wp = world.scene.objects[static_cast<std::size_t>(world.scene.FindObject(script.workpiece))];
    const Eigen::Vector3d start = wp.world_T_object.translation;
    Eigen::Vector3d direction(u(rng), u(rng), 0.6 * u(rng));
    direction.normalize();
    const double speed = 0.4 * unit(rng);
    const double duration = 0.3;
    // The dragger runs ahead at up to 400 mm/s; the spring saturates at the speed limit.
    script.keyframes = {{0.0, start, std::nullopt}, {duration, start + direction * speed * duration, std::nullopt}};
    script.settle_s = 0.0;
    if (unit(rng) < 0.5) {
      const std::string& c = capturable[static_cast<std::size_t>(rng() % capturable.size())];
      if (c != script.workpiece) script.capture.push_back({c, 0.0, 1e300});
    }
    RunSummary summary;
    auto path = RunScript(world, script, {}, &summary);
    ASSERT_TRUE(path.ok()) << path.status().message();
    const int index = world.scene.FindObject(script.workpiece);
    for (std::size_t n = 1; n < path->nodes.size(); ++n) {
      const double d = MinDistanceAlong(world, index, path->nodes[n - 1].world_T_workpiece,
                                        path->nodes[n].world_T_workpiece, 4);
      ASSERT_GE(d, 0.0) << "drag " << i << " node " << n << " script " << ScriptToJson(script).dump();
      min_distance = std::min(min_distance, d);
    }
    steps += summary.steps;
  }
  std::printf("%d drags, %ld steps, smallest distance %.3g m\n", drags, steps, min_distance);
  EXPECT_GT(min_distance, 0.0);
}

// A 1 mm plate, dragged against at 400 mm/s from 20 directions, is never crossed.
TEST(Simulator, ThinPlateIsNeverTunnelled) {
  scene::Scene scene;
  auto add = [&](const std::string& name, bool fixed, Eigen::Vector3d size, Eigen::Vector3d position) {
    scene.objects.push_back(scene::BoxObject(name, fixed, size, geometry::Pose3::Translation(position)));
  };
  add("table", true, {0.8, 0.6, 0.05}, {0, 0, -0.025});
  add("plate", true, {0.001, 0.58, 0.1}, {0, 0, 0.05});  // a 1 mm wall across the table at x = 0
  add("cube", false, {0.045, 0.045, 0.045}, {-0.05, 0, 0.02275});
  const SimWorld world = SimWorld::Build(scene, {}).value();
  for (int k = 0; k < 20; ++k) {
    const double angle = (-80.0 + 160.0 * k / 19.0) * M_PI / 180;  // toward +x, fanned out
    const Eigen::Vector3d dir(std::cos(angle), std::sin(angle), 0.0);
    DragScript script;
    script.workpiece = "cube";
    const Eigen::Vector3d start(-0.05, 0.0, 0.02275);
    // 400 mm/s for half a second: too short to reach around the wall's ends.
    script.keyframes = {{0.0, start, std::nullopt}, {0.5, start + 0.2 * dir, std::nullopt}};
    script.settle_s = 0.2;
    RunSummary summary;
    auto path = RunScript(world, script, {}, &summary);
    ASSERT_TRUE(path.ok());
    for (std::size_t n = 1; n < path->nodes.size(); ++n) {
      // The cube's centre never passes the plate (x < 0), and no motion between nodes touches it.
      ASSERT_LT(path->nodes[n].world_T_workpiece.translation.x(), 0.0) << "direction " << k << " node " << n;
      ASSERT_GE(MinDistanceAlong(world, 2, path->nodes[n - 1].world_T_workpiece, path->nodes[n].world_T_workpiece, 8), 0.0);
    }
    EXPECT_GT(summary.min_distance_m, 0.0);
  }
}

TEST(Simulator, SameScriptGivesAByteIdenticalPath) {
  const SimWorld world = PuzzleWorld();
  auto script = CorneringScript(world.scene, RandomCornering(3));
  ASSERT_TRUE(script.ok());
  auto a = RunScript(world, *script, {}, nullptr);
  auto b = RunScript(world, *script, {}, nullptr);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(PathToJson(*a).dump(), PathToJson(*b).dump());
}

TEST(Simulator, StartRefusesFixedUnknownAndIntersectingWorkpieces) {
  const SimWorld world = PuzzleWorld();
  EXPECT_EQ(StartDrag(world, "nothing").status().message(), "no object named 'nothing' in the scene");
  EXPECT_EQ(StartDrag(world, "table").status().code(), StatusCode::kInvalidInput);
  scene::Scene scene = world.scene;
  scene.objects[static_cast<std::size_t>(scene.FindObject("cube"))].world_T_object.translation.z() = 0.0;
  const SimWorld sunk = SimWorld::Build(scene, {}).value();
  auto started = StartDrag(sunk, "cube");
  ASSERT_FALSE(started.ok());
  EXPECT_NE(started.status().message().find("touches or intersects 'table'"), std::string::npos);
}

TEST(Simulator, OptionsValidateNamesTheField) {
  SimOptions o;
  o.step_s = -1;
  EXPECT_EQ(o.Validate().message(), "SimOptions::step_s = -1 must be > 0");
  o = SimOptions{};
  o.barrier_distance_m = 1e-3;
  EXPECT_FALSE(o.Validate().ok());
}

}  // namespace
}  // namespace teachsim::sim
