// The generated around-the-corner program (paper Figure 2 / Figure 12 bottom: task simulator with
// the demonstration script → program generator with the robot → work site) executed in the MuJoCo
// world: it reaches every command and verifies every contact with no model error and with 1 mm /
// 1 deg. The operator's model is the scene file itself (recognizing the plate is the vision
// module's part of `teachsim demo`).
#include <gtest/gtest.h>

#include <cmath>
#include <variant>

#include "fixtures.h"
#include "teachsim/plan/planner.h"
#include "teachsim/sim/demos.h"
#include "teachsim/worksite/execute.h"

namespace teachsim::worksite {
namespace {

void ExpectEveryCommandReachedAndVerified(const robot::Program& program, const ExecuteResult& result, const char* what) {
  ASSERT_EQ(result.report.commands.size(), program.commands.size()) << what;
  for (std::size_t i = 0; i < program.commands.size(); ++i) {
    const robot::CommandReport& c = result.report.commands[i];
    EXPECT_EQ(c.status, robot::CommandStatus::kReached) << what << ": commands[" << i << "] " << c.message;
    EXPECT_TRUE(c.contacts_verified) << what << ": commands[" << i << "]";
    if (const auto* contact = std::get_if<robot::ContactMoveCommand>(&program.commands[i])) {
      EXPECT_EQ(c.contacts.size(), static_cast<std::size_t>(contact->normals.cols())) << what << ": commands[" << i << "]";
    }
  }
}

TEST(ExecuteAroundCorner, GeneratedProgramSucceedsWithoutAndWithOneMillimetreOneDegreeModelError) {
  const scene::Scene scene = testing::Puzzle();
  const robot::RobotModel arm = testing::Arm();
  const sim::SimWorld sim_world = sim::SimWorld::Build(scene, {}).value();
  auto script = sim::AroundCornerScript(scene);
  ASSERT_TRUE(script.ok()) << script.status().message();
  auto path = sim::RunScript(sim_world, *script, {}, nullptr);
  ASSERT_TRUE(path.ok()) << path.status().message();
  auto plan = plan::GenerateProgram(scene, *path, {}, &arm);
  ASSERT_TRUE(plan.ok()) << plan.status().message();
  const robot::Program& program = plan->program;
  int contact_moves = 0;
  for (const robot::Command& c : program.commands) contact_moves += std::holds_alternative<robot::ContactMoveCommand>(c);
  std::printf("program: %zu commands, %d contact moves, grasp turned %.0f deg\n", program.commands.size(), contact_moves,
              plan->metrics.grasp_yaw_deg);
  EXPECT_GE(contact_moves, 10);

  ExecuteOptions options;
  auto exact = Execute(scene, arm, program, options);
  ASSERT_TRUE(exact.ok()) << exact.status().message();
  std::printf("no model error: %s; %.2f mm / %.2f deg from the intent, peak %.1f N, %.1f s simulated, %.1f s wall\n",
              exact->success ? "succeeded" : exact->message.c_str(), exact->workpiece_position_error_m * 1e3,
              exact->workpiece_angle_error_rad * 180 / M_PI, exact->report.peak_force_n, exact->simulated_s,
              exact->wall_s);
  EXPECT_TRUE(exact->success) << exact->message;
  ExpectEveryCommandReachedAndVerified(program, *exact, "no model error");
  EXPECT_LT(exact->report.peak_force_n, options.controller.monitor.force_limit_n);
  // The last contact move presses d = 5 mm into the south wall and the table; along the wall the
  // plate may stop short of the demonstrated end by up to about d as well.
  EXPECT_LT(exact->workpiece_position_error_m, 5e-3);
  EXPECT_LT(exact->workpiece_angle_error_rad, 2 * M_PI / 180);

  options.model_error = ModelError{};
  options.model_error->position_m = 0.001;
  options.model_error->angle_rad = M_PI / 180;
  options.model_error->seed = 1;
  auto perturbed = Execute(scene, arm, program, options);
  ASSERT_TRUE(perturbed.ok()) << perturbed.status().message();
  std::printf("1 mm / 1 deg, seed 1 (friction %.2f): %s; peak %.1f N, %.1f s wall\n", perturbed->block_friction,
              perturbed->success ? "succeeded" : perturbed->message.c_str(), perturbed->report.peak_force_n,
              perturbed->wall_s);
  EXPECT_TRUE(perturbed->success) << perturbed->message;
  ExpectEveryCommandReachedAndVerified(program, *perturbed, "1 mm / 1 deg");
  EXPECT_LT(perturbed->report.peak_force_n, options.controller.monitor.force_limit_n);
}

}  // namespace
}  // namespace teachsim::worksite
