#include <unistd.h>
// The generated cornering program (teachsim demo: task simulator + program generator) executed on
// the MuJoCo work site: it succeeds with no model error, verifies the contacts it asked for, and
// survives 3 mm / 2 deg model error with block friction 0.1-0.5 over a set of seeds; bad input is
// refused before any motion; and `teachsim execute` writes the report.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <variant>

#include "teachsim/worksite/execute.h"

namespace teachsim::worksite {
namespace {

const std::string kScene = std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json";

int Teachsim(const std::string& args, std::string* out = nullptr) {
  // ctest runs every test as its own process, in parallel: the capture file is per process.
  const std::string capture = ::testing::TempDir() + "/exec_out_" + std::to_string(::getpid()) + ".txt";
  const std::string command = std::string(TEACHSIM_BINARY) + " " + args + " > " + capture + " 2>&1";
  const int raw = std::system(command.c_str());
  if (out) {
    std::ifstream f(capture);
    std::stringstream s;
    s << f.rdbuf();
    *out = s.str();
  }
  return WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

class ExecuteCornering : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    folder_ = ::testing::TempDir() + "/execute_cornering_" + std::to_string(::getpid());  // per process
    std::filesystem::remove_all(folder_);
    std::string out;
    // The program generator's output for the paper's Figure 1 demonstration.
    ASSERT_EQ(Teachsim("demo cornering --scene " + kScene + " --out " + folder_, &out), 0) << out;
    program_file_ = folder_ + "/cornering.program.json";
  }
  void SetUp() override {
    auto scene = scene::LoadScene(kScene);
    ASSERT_TRUE(scene.ok());
    scene_ = *scene;
    auto model = robot::LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.json");
    ASSERT_TRUE(model.ok());
    model_ = *model;
    auto program = robot::LoadProgram(program_file_);
    ASSERT_TRUE(program.ok()) << program.status().message();
    program_ = *program;
  }
  static std::string folder_, program_file_;
  scene::Scene scene_;
  robot::RobotModel model_;
  robot::Program program_;
};
std::string ExecuteCornering::folder_, ExecuteCornering::program_file_;

TEST_F(ExecuteCornering, SucceedsWithoutModelErrorAndVerifiesTheProgramsContacts) {
  ExecuteOptions options;
  auto result = Execute(scene_, model_, program_, options);
  ASSERT_TRUE(result.ok()) << result.status().message();
  EXPECT_TRUE(result->success) << result->message;
  EXPECT_LT(result->report.peak_force_n, options.controller.monitor.force_limit_n);
  ASSERT_TRUE(result->has_intent);
  std::printf(
      "no model error: %.2f mm / %.2f deg from the intent, peak %.1f N, %.1f s simulated, %.0fx real time\n",
      result->workpiece_position_error_m * 1e3, result->workpiece_angle_error_rad * 180 / M_PI,
      result->report.peak_force_n, result->simulated_s, result->real_time_factor());
  EXPECT_LT(result->workpiece_position_error_m, 2e-3);
  EXPECT_LT(result->workpiece_angle_error_rad, 2 * M_PI / 180);
  // The report's verified contacts are exactly those the program asked for.
  const json::Json doc = ExecuteResultToJson(*result, options);
  EXPECT_TRUE(doc["success"].get<bool>());
  EXPECT_TRUE(doc["contacts_verified"].get<bool>());
  ASSERT_EQ(doc["commands"].size(), program_.commands.size());
  int contact_moves = 0;
  for (std::size_t i = 0; i < program_.commands.size(); ++i) {
    const json::Json& c = doc["commands"][i];
    EXPECT_EQ(c["status"], "reached") << i;
    EXPECT_FALSE(c["forces"]["t_s"].empty()) << i;
    const auto* contact = std::get_if<robot::ContactMoveCommand>(&program_.commands[i]);
    if (!contact) {
      EXPECT_TRUE(c["contacts"].empty()) << i;
      continue;
    }
    ++contact_moves;
    ASSERT_EQ(c["contacts"].size(), static_cast<std::size_t>(contact->normals.cols())) << i;
    for (long n = 0; n < contact->normals.cols(); ++n) {
      const json::Json& k = c["contacts"][static_cast<std::size_t>(n)];
      EXPECT_TRUE(k["verified"].get<bool>());
      Eigen::Vector3d normal(k["normal"][0].get<double>(), k["normal"][1].get<double>(),
                             k["normal"][2].get<double>());
      EXPECT_LT((normal - contact->normals.col(n)).norm(), 1e-12);
      EXPECT_GE(k["force_n"].get<double>(), contact->force_thresholds_n[static_cast<std::size_t>(n)]);
    }
  }
  EXPECT_GE(contact_moves, 1);
}

// Issue 5: >= 95 % success with 3 mm / 2 deg model error and block friction 0.1-0.5, peak force
// below 50 N. Here as many seeds as fit in ~15 s; the 200-seed figure: `teachsim bench worksite`.
TEST_F(ExecuteCornering, SurvivesThreeMillimetreTwoDegreeModelError) {
  ExecuteOptions options;
  options.model_error = ModelError{};
  options.model_error->position_m = 0.003;
  options.model_error->angle_rad = 2 * M_PI / 180;
  const int seeds = 20;
  int successes = 0;
  double worst_peak = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    options.model_error->seed = static_cast<std::uint64_t>(seed);
    auto result = Execute(scene_, model_, program_, options);
    ASSERT_TRUE(result.ok()) << result.status().message();
    if (result->success) ++successes;
    if (!result->success)
      std::printf("seed %d (friction %.2f): %s\n", seed, result->block_friction, result->message.c_str());
    worst_peak = std::max(worst_peak, result->report.peak_force_n);
  }
  std::printf("3 mm / 2 deg model error: %d / %d succeeded, worst peak force %.1f N\n", successes, seeds,
              worst_peak);
  EXPECT_GE(successes, 19);
  EXPECT_LT(worst_peak, 50.0);
}

// Issue 5 on MuJoCo (not only on the robot module's own plant): the impedance controller pressing
// the cube into the corner settles without oscillation — the force stays within 20 % of its mean
// from 0.5 s after the trajectory's end (a 1.5 s settle here, no probing, to watch it longer).
TEST_F(ExecuteCornering, ImpedancePressingIntoTheCornerSettlesWithoutOscillation) {
  ExecuteOptions options;
  options.controller.monitor.settle_time_s = 1.5;
  options.controller.monitor.probe = false;
  options.controller.monitor.stop_on_unverified = false;
  auto result = Execute(scene_, model_, program_, options);
  ASSERT_TRUE(result.ok()) << result.status().message();
  int checked = 0;
  for (std::size_t i = 0; i < program_.commands.size(); ++i) {
    if (!std::holds_alternative<robot::ContactMoveCommand>(program_.commands[i])) continue;
    const robot::CommandReport& c = result->report.commands[i];
    ASSERT_EQ(c.status, robot::CommandStatus::kReached) << c.message;
    const double from = c.end_s - 1.5 + 0.5;  // the line ended settle_time_s before end_s
    std::vector<double> magnitudes;
    for (const robot::ForceSample& f : c.forces) {
      if (f.t_s >= from - 1e-9) magnitudes.push_back(f.force_n.norm());
    }
    ASSERT_GE(magnitudes.size(), 90u);
    double mean = 0;
    for (double m : magnitudes) mean += m;
    mean /= static_cast<double>(magnitudes.size());
    double worst = 0;
    for (double m : magnitudes) worst = std::max(worst, std::abs(m - mean));
    std::printf("commands[%zu]: force %.2f N mean, largest deviation %.3f N (%.1f %%) over the last %.1f s\n", i,
                mean, worst, 100 * worst / mean, c.end_s - from);
    EXPECT_GT(mean, 1.0);  // pressing: K d = 1.5 N per contact
    EXPECT_LE(worst, 0.2 * mean);
    ++checked;
  }
  EXPECT_GE(checked, 1);
}

TEST_F(ExecuteCornering, BadInputIsRefusedBeforeAnyMotion) {
  scene::Scene no_cube = scene_;
  no_cube.objects.erase(no_cube.objects.begin() + no_cube.FindObject("cube"));
  auto missing = Execute(no_cube, model_, program_, {});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kInvalidInput);
  EXPECT_NE(missing.status().message().find("cube"), std::string::npos);

  robot::Program unsafe = program_;
  auto& move = std::get<robot::MoveCommand>(unsafe.commands[1]);
  move.world_T_tool.translation.x() = 0.9;  // far outside the workspace
  auto refused = Execute(scene_, model_, unsafe, {});
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidInput);
  EXPECT_NE(refused.status().message().find("refused"), std::string::npos) << refused.status().message();
}

TEST_F(ExecuteCornering, CommandLineWritesTheReportAndExitStatus) {
  const std::string report = folder_ + "/report.json";
  std::string out;
  ASSERT_EQ(
      Teachsim("execute --scene " + kScene + " --program " + program_file_ + " --report " + report, &out), 0)
      << out;
  // One line per command; the contact move's says its contacts were verified.
  const std::size_t contact = out.find("] contact_move ");
  ASSERT_NE(contact, std::string::npos) << out;
  EXPECT_NE(out.find("contacts verified", contact), std::string::npos) << out;
  EXPECT_NE(out.find("SUCCESS"), std::string::npos) << out;
  auto doc = json::ReadFile(report);
  ASSERT_TRUE(doc.ok());
  EXPECT_TRUE((*doc)["success"].get<bool>());
  EXPECT_EQ((*doc)["commands"].size(), program_.commands.size());
  EXPECT_LT((*doc)["workpiece"]["position_error_m"].get<double>(), 2e-3);
  EXPECT_GT((*doc)["timing"]["real_time_factor"].get<double>(), 1.0);

  // Bad input: exit status 2 with a message naming the problem.
  EXPECT_EQ(Teachsim("execute --scene " + kScene + " --program " + folder_ + "/missing.json", &out), 2);
  EXPECT_NE(out.find("missing.json"), std::string::npos) << out;
  robot::Program unsafe = program_;
  std::get<robot::MoveCommand>(unsafe.commands[1]).world_T_tool.translation.x() = 0.9;
  ASSERT_TRUE(robot::SaveProgram(unsafe, folder_ + "/unsafe.json").ok());
  EXPECT_EQ(Teachsim("execute --scene " + kScene + " --program " + folder_ + "/unsafe.json", &out), 2);
  EXPECT_NE(out.find("refused"), std::string::npos) << out;
}

}  // namespace
}  // namespace teachsim::worksite
