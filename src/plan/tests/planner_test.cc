#include "teachsim/plan/planner.h"

#include <gtest/gtest.h>

#include <functional>

#include "teachsim/geometry/toi.h"
#include "teachsim/robot/controller.h"
#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/safety.h"
#include "teachsim/sim/demos.h"

namespace teachsim::plan {
namespace {

const std::string kPuzzle = std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json";

struct Demo {
  scene::Scene scene;
  sim::WorkpiecePath path;
};

Demo Demonstrate(const std::function<Result<sim::DragScript>(const scene::Scene&)>& make) {
  Demo d;
  d.scene = scene::LoadScene(kPuzzle).value();
  const sim::SimWorld world = sim::SimWorld::Build(d.scene, {}).value();
  auto script = make(d.scene);
  EXPECT_TRUE(script.ok());
  d.path = sim::RunScript(world, *script, {}, nullptr).value();
  return d;
}

// Every motion between consecutive poses stays collision-free (conservative advancement, 0 m).
void ExpectCollisionFree(const sim::SimWorld& world, int workpiece, const sim::WorkpiecePath& path, const char* what) {
  for (std::size_t i = 1; i < path.nodes.size(); ++i) {
    EXPECT_TRUE(MotionClear(world, workpiece, path.nodes[i - 1].world_T_workpiece, path.nodes[i].world_T_workpiece, 0.0))
        << what << " segment " << i;
  }
}

void ExpectBiasSolves(const robot::Program& program, double depth) {
  for (const robot::Command& c : program.commands) {
    if (const auto* move = std::get_if<robot::ContactMoveCommand>(&c)) {
      const Eigen::VectorXd residual = -move->normals.transpose() * move->bias_m - Eigen::VectorXd::Constant(move->normals.cols(), depth);
      EXPECT_LT(residual.norm(), 1e-9);
    }
  }
}

// Figure 12 top: the cornering program approaches from above and from the open side, clear of
// the lip, in at most six motion commands, and the band stays collision-free and clear of the
// walls and table where it is free to be.
TEST(Planner, CorneringApproachesFromAboveAndTheOpenSideInFewMoves) {
  for (std::uint64_t seed : {0, 4, 9}) {
    Demo d = Demonstrate([&](const scene::Scene& s) {
      return sim::CorneringScript(s, seed == 0 ? sim::CorneringVariation{} : sim::RandomCornering(seed));
    });
    auto result = GenerateProgram(d.scene, d.path);
    ASSERT_TRUE(result.ok()) << result.status().message();
    const PlanMetrics& m = result->metrics;
    EXPECT_LE(m.motion_commands, 6) << "seed " << seed;
    EXPECT_TRUE(m.required_contacts_kept);
    EXPECT_GE(m.min_clearance_after_m, 3e-3) << "seed " << seed;
    sim::SimOptions band_options;
    band_options.settle_force_n = 0;
    const sim::SimWorld world = sim::SimWorld::Build(d.scene, band_options).value();
    const int cube = d.scene.FindObject("cube");
    ExpectCollisionFree(world, cube, result->deformed, "deformed");
    ExpectCollisionFree(world, cube, result->simplified, "simplified");
    // The final approach: down from above, and from the open (north-east) side of the corner.
    const auto& knots = result->simplified.nodes;
    ASSERT_GE(knots.size(), 3u);
    const Eigen::Vector3d end = knots.back().world_T_workpiece.translation;
    const Eigen::Vector3d before = knots[knots.size() - 2].world_T_workpiece.translation;
    EXPECT_GT(before.z(), end.z() + 1e-3) << "seed " << seed;
    EXPECT_GT((before - end).x() + (before - end).y(), 0.0) << "seed " << seed;
    // Nothing in the last motion passes under the lip from the west wall's side: the lip spans
    // x in [-100, -88] mm; the approach starts east of the corner pose.
    EXPECT_GE(before.x(), end.x() - 1e-4);
    // The program ends in a contact move into the corner with three normals.
    const auto* last = std::get_if<robot::ContactMoveCommand>(&result->program.commands[result->program.commands.size() - 3]);
    ASSERT_NE(last, nullptr);
    EXPECT_EQ(last->normals.cols(), 3);
    ExpectBiasSolves(result->program, PlanOptions{}.bias_depth_m);
  }
}

TEST(Planner, WanderingDemonstrationLosesAtLeastThirtyPercent) {
  Demo d = Demonstrate([](const scene::Scene& s) {
    sim::CorneringVariation v;
    v.wander = true;
    return sim::CorneringScript(s, v);
  });
  auto result = GenerateProgram(d.scene, d.path);
  ASSERT_TRUE(result.ok()) << result.status().message();
  const PlanMetrics& m = result->metrics;
  std::printf("wandering: %.1f mm -> %.1f mm (%.0f %% shorter)\n", m.length_before_m * 1e3, m.length_after_m * 1e3,
              100.0 * (1.0 - m.length_after_m / m.length_before_m));
  EXPECT_LE(m.length_after_m, 0.7 * m.length_before_m);
  EXPECT_GE(m.min_clearance_after_m, 3e-3);
}

// Figure 12 bottom: contact with the frame and the table is kept through the captured stretch
// around the corner; the free approach before it is pushed up, away from the table.
TEST(Planner, AroundTheCornerKeepsCapturedContactAndLiftsTheApproach) {
  Demo d = Demonstrate([](const scene::Scene& s) { return sim::AroundCornerScript(s); });
  auto result = GenerateProgram(d.scene, d.path);
  ASSERT_TRUE(result.ok()) << result.status().message();
  EXPECT_TRUE(result->metrics.required_contacts_kept);
  EXPECT_GT(result->metrics.required_nodes, 20);
  const sim::SimWorld world = sim::SimWorld::Build(d.scene, {}).value();
  const int plate = d.scene.FindObject("plate"), frame = d.scene.FindObject("frame"), table = d.scene.FindObject("table");
  // Every contact move targets a pose within eps_o of the frame and the table.
  int contact_moves = 0;
  for (const robot::Command& c : result->program.commands) {
    if (const auto* move = std::get_if<robot::ContactMoveCommand>(&c)) {
      const geometry::Pose3 workpiece = move->world_T_tool * result->program.workpiece_T_tool.Inverse();
      EXPECT_LE(ObjectDistance(world, plate, workpiece, frame), world.options.capture_distance_m);
      EXPECT_LE(ObjectDistance(world, plate, workpiece, table), world.options.capture_distance_m);
      ++contact_moves;
    }
  }
  EXPECT_GE(contact_moves, 3);
  // The approach (before capture) rises well clear of the table.
  double highest = 0.0;
  for (const auto& node : result->deformed.nodes) highest = std::max(highest, node.world_T_workpiece.translation.z());
  EXPECT_GT(highest, d.path.nodes.front().world_T_workpiece.translation.z() + 0.01);
  ExpectCollisionFree(world, plate, result->simplified, "simplified");
  ExpectBiasSolves(result->program, PlanOptions{}.bias_depth_m);
}

// The band settles (paper §6.1: "until the path stabilises") inside the iteration budget on all
// three demonstrations, rather than running out of sweeps while nodes still hop about.
TEST(Planner, BandConvergesWithinTheIterationBudget) {
  const std::vector<std::function<Result<sim::DragScript>(const scene::Scene&)>> scripts = {
      [](const scene::Scene& s) { return sim::CorneringScript(s, {}); },
      [](const scene::Scene& s) {
        sim::CorneringVariation v;
        v.wander = true;
        return sim::CorneringScript(s, v);
      },
      [](const scene::Scene& s) { return sim::AroundCornerScript(s); }};
  for (const auto& script : scripts) {
    Demo d = Demonstrate(script);
    auto result = GenerateProgram(d.scene, d.path);
    ASSERT_TRUE(result.ok()) << result.status().message();
    std::printf("band iterations: %d of %d\n", result->metrics.iterations, PlanOptions{}.max_iterations);
    EXPECT_TRUE(result->metrics.band_converged);
    EXPECT_LE(result->metrics.iterations, PlanOptions{}.max_iterations);
  }
}

TEST(Planner, SamePathGivesAByteIdenticalProgram) {
  Demo d = Demonstrate([](const scene::Scene& s) { return sim::CorneringScript(s, {}); });
  auto a = GenerateProgram(d.scene, d.path);
  auto b = GenerateProgram(d.scene, d.path);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(robot::ProgramToText(a->program), robot::ProgramToText(b->program));
  EXPECT_EQ(sim::PathToJson(a->deformed).dump(), sim::PathToJson(b->deformed).dump());
}

// The paper's tight fit: a block dropped into a slot barely wider than itself touches both sides,
// whose normals oppose; no bias can press into both, and the generator says so.
TEST(Planner, TightFitIsAClearError) {
  scene::Scene scene;
  auto add = [&](const std::string& name, bool fixed, Eigen::Vector3d size, Eigen::Vector3d position) {
    scene.objects.push_back(scene::BoxObject(name, fixed, size, geometry::Pose3::Translation(position)));
  };
  add("table", true, {0.4, 0.4, 0.05}, {0, 0, -0.025});
  add("left", true, {0.02, 0.1, 0.03}, {-0.0225 - 0.0003 - 0.01, 0, 0.015});
  add("right", true, {0.02, 0.1, 0.03}, {0.0225 + 0.0003 + 0.01, 0, 0.015});
  add("block", false, {0.045, 0.045, 0.045}, {0, 0, 0.1});
  sim::WorkpiecePath path;
  path.workpiece = "block";
  sim::PathNode start, end;
  start.world_T_workpiece = geometry::Pose3::Translation({0, 0, 0.1});
  end.world_T_workpiece = geometry::Pose3::Translation({0, 0, 0.02275});
  end.time_s = 1.0;
  end.contacts = {{"table", {0, 0, 0}, {0, 0, 1}, 2.5e-4, false},
                  {"left", {-0.0228, 0, 0.02}, {1, 0, 0}, 3e-4, false},
                  {"right", {0.0228, 0, 0.02}, {-1, 0, 0}, 3e-4, false}};
  path.nodes = {start, end};
  auto result = GenerateProgram(scene, path);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kFailed);
  EXPECT_NE(result.status().message().find("tight fit"), std::string::npos) << result.status().message();
}

robot::RobotModel Arm() { return robot::LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.json").value(); }

// The smallest distance from the gripper's palm and fingers to the scene (the workpiece aside) along
// a program's motions, sampled every 1 mm here, independently of the planner's own sampling.
double GripperClearance(const scene::Scene& scene, const robot::RobotModel& model, const robot::Program& program,
                        std::string* where) {
  double best = 1e300;
  const int workpiece = scene.FindObject(program.workpiece);
  geometry::Pose3 pose = geometry::Pose3::Identity();  // set by the grasp, the first command
  double width = model.gripper.max_width_m;
  auto check = [&](const geometry::Pose3& tool, const std::string& what) {
    for (const robot::GripperBox& b : robot::GripperBoxes(model.gripper, width)) {
      const geometry::Shape shape = geometry::Shape::Single(geometry::ConvexPolyhedron::Box(b.size_m).value());
      for (int o = 0; o < static_cast<int>(scene.objects.size()); ++o) {
        if (o == workpiece) continue;
        const auto d = geometry::ShapeDistance(shape, tool * b.tool_T_box, scene.objects[static_cast<std::size_t>(o)].shape,
                                               scene.objects[static_cast<std::size_t>(o)].world_T_object);
        const double distance = d.intersecting ? 0.0 : d.distance;
        if (distance < best) {
          best = distance;
          *where = b.name + " to " + scene.objects[static_cast<std::size_t>(o)].name + " in " + what;
        }
      }
    }
  };
  auto line = [&](const geometry::Pose3& goal, const std::string& what) {
    const int n = std::max(1, static_cast<int>((goal.translation - pose.translation).norm() / 1e-3));
    for (int k = 1; k <= n; ++k) check(geometry::Interpolate(pose, goal, static_cast<double>(k) / n), what);
    pose = goal;
  };
  for (const robot::Command& c : program.commands) {
    if (const auto* g = std::get_if<robot::GraspCommand>(&c)) {
      width = g->open_width_m;
      pose = g->ApproachPose();
      check(pose, "grasp");
      line(g->world_T_tool, "grasp");
      width = g->width_m;
    } else if (const auto* m = std::get_if<robot::MoveCommand>(&c)) {
      line(m->world_T_tool, "move");
    } else if (const auto* cm = std::get_if<robot::ContactMoveCommand>(&c)) {
      line(cm->world_T_tool, "contact move");
    } else if (const auto* r = std::get_if<robot::ReleaseCommand>(&c)) {
      width = r->width_m;
      check(pose, "release");
    } else if (const auto* t = std::get_if<robot::RetreatCommand>(&c)) {
      geometry::Pose3 up = pose;
      up.translation.z() += t->distance_m;
      line(up, "retreat");
    }
  }
  return best;
}

// With the robot, the programs of both demonstrations keep the gripper (palm, fingers) at least
// the planner's clearance from the scene all along, pass the work site's safety checks, and stay
// away from the singularities; cornering's grasp leaves the post and lip alone.
TEST(Planner, WithTheRobotTheGripperClearsTheSceneOnBothDemoPaths) {
  const robot::RobotModel arm = Arm();
  const std::vector<std::pair<const char*, std::function<Result<sim::DragScript>(const scene::Scene&)>>> demos = {
      {"cornering", [](const scene::Scene& s) { return sim::CorneringScript(s, {}); }},
      {"around-corner", [](const scene::Scene& s) { return sim::AroundCornerScript(s); }}};
  for (const auto& [name, script] : demos) {
    Demo d = Demonstrate(script);
    auto result = GenerateProgram(d.scene, d.path, {}, &arm);
    ASSERT_TRUE(result.ok()) << name << ": " << result.status().message();
    const PlanMetrics& m = result->metrics;
    ASSERT_TRUE(m.robot_checked);
    ASSERT_EQ(result->grasps.size(), 4u);
    for (const GraspReport& g : result->grasps) {
      std::printf("%s: grasp %3.0f deg: %s; gripper %.1f mm (%s); wrist %.3f\n", name, g.yaw_deg,
                  g.feasible ? "feasible" : g.problem.c_str(), g.min_gripper_clearance_m * 1e3, g.closest.c_str(),
                  g.min_wrist_measure);
    }
    std::string where;
    const double clearance = GripperClearance(d.scene, arm, result->program, &where);
    EXPECT_GE(clearance, PlanOptions{}.gripper_clearance_m - 1e-4) << name << ": " << where;
    EXPECT_GE(m.min_wrist_measure, PlanOptions{}.min_wrist_measure) << name;
    const robot::ControllerOptions controller;
    const Status safe = robot::CheckProgram(arm, d.scene.robot->world_T_base, result->program, arm.ready_rad,
                                            controller.limits, controller.safety);
    EXPECT_TRUE(safe.ok()) << name << ": " << safe.message();
    // The grasp turned 90 degrees puts a finger through the cornering post or the palm over a wall:
    // refused, with the place named.
    if (std::string(name) == "cornering") {
      EXPECT_FALSE(result->grasps[1].feasible);
      EXPECT_FALSE(result->grasps[3].feasible);
      EXPECT_NE(result->grasps[3].problem.find("frame"), std::string::npos) << result->grasps[3].problem;
    }
  }
}

// The plate slid around the corner without turning (the first around-the-corner script): after the
// corner, jaws that held it along the east wall would close across the south wall, and jaws turned
// the other way put the palm over the east wall. No grasp can run it; the error says where.
TEST(Planner, AProgramNoGraspCanRunIsRefusedNamingThePlace) {
  const robot::RobotModel arm = Arm();
  Demo d = Demonstrate([](const scene::Scene& s) -> Result<sim::DragScript> {
    sim::DragScript script;
    script.workpiece = "plate";
    script.capture = {{"frame", 1.5, 1e300}, {"table", 1.5, 1e300}};
    const Eigen::Vector3d start = s.objects[static_cast<std::size_t>(s.FindObject("plate"))].world_T_object.translation;
    const double z = start.z();
    script.keyframes = {{0.0, start, std::nullopt},
                        {2.0, Eigen::Vector3d(0.142, -0.05, z), std::nullopt},
                        {5.0, Eigen::Vector3d(0.142, -0.16, z), std::nullopt},
                        {8.0, Eigen::Vector3d(0.08, -0.122, z), std::nullopt},
                        {10.0, Eigen::Vector3d(0.0, -0.122, z), std::nullopt}};
    return script;
  });
  auto result = GenerateProgram(d.scene, d.path, {}, &arm);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kFailed);
  const std::string& message = result.status().message();
  std::printf("%s\n", message.c_str());
  EXPECT_NE(message.find("no grasp of 'plate'"), std::string::npos) << message;
  for (const char* yaw : {"grasp turned 0 deg", "grasp turned 90 deg", "grasp turned 180 deg", "grasp turned 270 deg"}) {
    EXPECT_NE(message.find(yaw), std::string::npos) << message;
  }
  EXPECT_NE(message.find("frame"), std::string::npos) << message;
  EXPECT_NE(message.find("commands["), std::string::npos) << message;
  // Without the robot the same path still gives a program (the old, unchecked behaviour).
  EXPECT_TRUE(GenerateProgram(d.scene, d.path).ok());
}

TEST(Planner, BadInputIsNamed) {
  scene::Scene scene = scene::LoadScene(kPuzzle).value();
  sim::WorkpiecePath path;
  path.workpiece = "unicorn";
  path.nodes.resize(2);
  EXPECT_EQ(GenerateProgram(scene, path).status().message(), "path: workpiece 'unicorn' is not in the scene");
  path.workpiece = "table";
  EXPECT_EQ(GenerateProgram(scene, path).status().message(), "path: workpiece 'table' is a fixed object in the scene");
  PlanOptions o;
  o.tension_n = -1;
  path.workpiece = "cube";
  EXPECT_EQ(GenerateProgram(scene, path, o).status().message(), "PlanOptions::tension_n = -1 must be > 0");
}

}  // namespace
}  // namespace teachsim::plan
