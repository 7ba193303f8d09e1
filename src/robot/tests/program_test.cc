#include "teachsim/robot/program.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace teachsim::robot {
namespace {

using Eigen::Vector3d;
using geometry::Pose3;

const Eigen::Quaterniond kDown(0, 1, 0, 0);  // tool z pointing down

// Cornering (paper Figure 12 top): grasp a block, lift, move above the corner, slide into the
// corner of a wall (normal +x) on the table (normal +z), release, retreat.
Program Cornering() {
  Program p;
  p.workpiece = "block_a";
  p.workpiece_T_tool = Pose3(kDown, Vector3d(0, 0, 0.0225));
  GraspCommand g;
  g.world_T_tool = Pose3(kDown, Vector3d(0.05, 0.02, 0.0225));
  p.commands.emplace_back(g);
  p.commands.emplace_back(MoveCommand{Pose3(kDown, Vector3d(0.05, 0.02, 0.10)), 0.1});
  p.commands.emplace_back(MoveCommand{Pose3(kDown, Vector3d(-0.07, 0.02, 0.06)), 0.1});
  ContactMoveCommand c;
  c.world_T_tool = Pose3(kDown, Vector3d(-0.0775, 0.02, 0.0225));
  c.normals.resize(3, 2);
  c.normals.col(0) = Vector3d(1, 0, 0);
  c.normals.col(1) = Vector3d(0, 0, 1);
  c.force_thresholds_n = {1.0, 1.0};
  c.bias_m = ContactBias(c.normals, 0.005, 0.02).value();
  c.speed_mps = 0.01;
  p.commands.emplace_back(c);
  p.commands.emplace_back(ReleaseCommand{0.07});
  p.commands.emplace_back(RetreatCommand{0.05, 0.05});
  return p;
}

TEST(Program, RoundTripsAndSerialisesDeterministically) {
  Program p = Cornering();
  ASSERT_TRUE(p.Validate().ok()) << p.Validate().message();
  std::string text = ProgramToText(p);
  EXPECT_EQ(ProgramToText(Cornering()), text);  // same program, same bytes
  auto doc = json::ParseText(text, "mem");
  ASSERT_TRUE(doc.ok());
  Result<Program> again = ParseProgram(*doc, "mem");
  ASSERT_TRUE(again.ok()) << again.status().message();
  EXPECT_EQ(ProgramToText(*again), text);  // and reading it back changes nothing
  ASSERT_EQ(again->commands.size(), 6u);
  const auto& c = std::get<ContactMoveCommand>(again->commands[3]);
  EXPECT_EQ(c.normals.cols(), 2);
  EXPECT_EQ(c.bias_m, std::get<ContactMoveCommand>(p.commands[3]).bias_m);

  // Through a file, atomically written.
  std::string path = (std::filesystem::temp_directory_path() / "teachsim_program_test.json").string();
  ASSERT_TRUE(SaveProgram(p, path).ok());
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  EXPECT_EQ(s.str(), text);
  Result<Program> loaded = LoadProgram(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status().message();
  std::filesystem::remove(path);
}

TEST(Program, ListingHasOneLinePerCommand) {
  std::string listing = ProgramListing(Cornering());
  int lines = 0;
  for (char ch : listing) lines += ch == '\n';
  EXPECT_EQ(lines, 1 + 6);  // a header and one line per command
  EXPECT_NE(listing.find("  3 contact_move  to (-77.5, 20.0, 22.5) mm"), std::string::npos) << listing;
  EXPECT_NE(listing.find("n (1.000, 0.000, 0.000) >= 1.0 N"), std::string::npos) << listing;
  EXPECT_NE(listing.find("  5 retreat       up 50.0 mm at 50.0 mm/s"), std::string::npos) << listing;
}

struct BadCase {
  const char* pointer;
  json::Json value;
  const char* expected;
};

TEST(Program, ValidationErrorsNameTheJsonPath) {
  const json::Json good = ProgramToJson(Cornering());
  const BadCase cases[] = {
      {"/commands/3/normals/1", json::Json::array({0, 0, 0.9}),
       "commands[3].normals[1]: must be a unit vector"},
      {"/commands/3/force_thresholds_n", json::Json::array({1.0}),
       "commands[3].force_thresholds_n: must hold one threshold per normal: 2 normals, 1 thresholds"},
      {"/commands/3/force_thresholds_n/0", -1.0,
       "commands[3].force_thresholds_n[0]: must be a finite number > 0"},
      {"/commands/3/bias_m", json::Json::array({0.005, 0, -0.005}),
       "commands[3].bias_m: must move the target into every contact"},
      {"/commands/3/normals", json::Json::array(), "commands[3].normals: must hold at least one"},
      {"/commands/3/normals/0", json::Json::array({0, 0, 1}), "commands[3].normals[1]: repeats normals[0]"},
      {"/commands/1/speed_mps", 0.0, "commands[1].speed_mps: must be a finite number > 0, got 0"},
      {"/commands/2/speed_mps", "fast", "commands[2].speed_mps: must be a number, got string"},
      {"/commands/0/open_width_m", 0.04, "commands[0].open_width_m: must exceed width_m"},
      {"/commands/0/world_T_tool/quaternion_wxyz", json::Json::array({1, 0, 0, 0.5}),
       "commands[0].world_T_tool.quaternion_wxyz: must be a unit"},
      {"/commands/4/type", "open", "commands[4].type: unknown command type 'open'"},
      {"/commands/5/speed", 1.0, "commands[5]: unknown field 'speed'"},
      {"/units/length", "mm", "units.length: must be \"m\" (SI)"},
      {"/workpiece", "", "workpiece: must not be empty"},
      {"/version", 2, "version: must be 1"},
      {"/commands/4",
       json::Json{{"type", "grasp"},
                  {"world_T_tool", {{"position", {0, 0, 0.02}}, {"quaternion_wxyz", {0, 1, 0, 0}}}},
                  {"approach_height_m", 0.05},
                  {"approach_speed_mps", 0.1},
                  {"speed_mps", 0.02},
                  {"contact_force_n", 5},
                  {"open_width_m", 0.07},
                  {"width_m", 0.045}},
       "commands[4]: grasp while already holding the workpiece (grasped by commands[0]"},
  };
  for (const BadCase& c : cases) {
    json::Json doc = good;
    doc[json::Json::json_pointer(c.pointer)] = c.value;
    Result<Program> p = ParseProgram(doc, "bad.json");
    ASSERT_FALSE(p.ok()) << c.pointer;
    EXPECT_EQ(p.status().code(), StatusCode::kInvalidInput);
    EXPECT_EQ(p.status().message().rfind("bad.json: ", 0), 0u) << p.status().message();
    EXPECT_NE(p.status().message().find(c.expected), std::string::npos)
        << "got: " << p.status().message() << "\nexpected: " << c.expected;
  }
  // Infinity cannot be written in JSON; in code it is caught by Validate().
  Program p = Cornering();
  std::get<MoveCommand>(p.commands[1]).speed_mps = std::numeric_limits<double>::infinity();
  EXPECT_NE(p.Validate().message().find("commands[1].speed_mps: must be a finite number > 0"),
            std::string::npos);
}

// docs/formats/program.md's example parses, and its listing is what ProgramListing prints.
TEST(Program, DocumentedExampleParses) {
  std::ifstream in(std::string(TEACHSIM_SOURCE_DIR) + "/docs/formats/program.md");
  std::stringstream s;
  s << in.rdbuf();
  const std::string doc = s.str();
  auto block = [&](const std::string& fence, std::size_t from) {
    std::size_t begin = doc.find(fence, from);
    TEACHSIM_CHECK(begin != std::string::npos);
    begin += fence.size();
    std::size_t end = doc.find("```", begin);
    return std::make_pair(doc.substr(begin, end - begin), end + 3);
  };
  auto [example, after] = block("```json\n", 0);
  auto [listing, unused] = block("```\n", after);
  auto parsed = json::ParseText(example, "program.md");
  ASSERT_TRUE(parsed.ok()) << parsed.status().message();
  Result<Program> p = ParseProgram(*parsed, "program.md");
  ASSERT_TRUE(p.ok()) << p.status().message();
  EXPECT_EQ(ProgramListing(*p), listing);
}

Eigen::Matrix3Xd Normals(std::initializer_list<Vector3d> list) {
  Eigen::Matrix3Xd N(3, static_cast<long>(list.size()));
  long i = 0;
  for (const Vector3d& n : list) N.col(i++) = n.normalized();
  return N;
}

// d 1 = -N^T delta_p to 1e-9, and least-norm: delta_p lies in the span of the normals.
TEST(ContactBias, SolvesForOneTwoAndThreeNormals) {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> g;
  const double d = 0.005;
  for (int k = 1; k <= 3; ++k) {
    for (int trial = 0; trial < 200; ++trial) {
      Eigen::Matrix3Xd N(3, k);
      for (int i = 0; i < k; ++i) {
        do {
          N.col(i) = Vector3d(g(rng), g(rng), g(rng)).normalized();
        } while (i > 0 && (N.leftCols(i).transpose() * N.col(i)).cwiseAbs().maxCoeff() > 0.8);
      }
      Result<Vector3d> bias = ContactBias(N, d, 1.0);
      if (k == 3 && !bias.ok()) continue;  // three random normals may be nearly dependent
      ASSERT_TRUE(bias.ok()) << bias.status().message();
      EXPECT_LT((N.transpose() * *bias + Eigen::VectorXd::Constant(k, d)).cwiseAbs().maxCoeff(), 1e-9);
      // Least norm: no component orthogonal to the normals' span.
      Eigen::Matrix3d P = N * (N.transpose() * N).inverse() * N.transpose();
      EXPECT_LT((*bias - P * *bias).norm(), 1e-9);
    }
  }
  // The paper's corner on a table: a wall (+x) and the table (+z): bias (-d, 0, -d).
  Result<Vector3d> corner = ContactBias(Normals({{1, 0, 0}, {0, 0, 1}}), d, 0.02);
  ASSERT_TRUE(corner.ok());
  EXPECT_LT((*corner - Vector3d(-d, 0, -d)).norm(), 1e-12);
  // One normal: straight into it by d.
  Result<Vector3d> one = ContactBias(Normals({{0, 0, 1}}), d, 0.02);
  ASSERT_TRUE(one.ok());
  EXPECT_LT((*one - Vector3d(0, 0, -d)).norm(), 1e-12);
  // A box corner: three orthogonal walls.
  Result<Vector3d> three = ContactBias(Normals({{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}), d, 0.02);
  ASSERT_TRUE(three.ok());
  EXPECT_LT((*three - Vector3d(-d, -d, -d)).norm(), 1e-12);
}

TEST(ContactBias, TightFitsAreRefused) {
  // Opposing normals: a block between two walls (the paper's tight-fit case).
  Result<Vector3d> opposing = ContactBias(Normals({{1, 0, 0}, {-1, 0, 0}}), 0.005, 0.02);
  ASSERT_FALSE(opposing.ok());
  EXPECT_EQ(opposing.status().code(), StatusCode::kInvalidInput);
  EXPECT_NE(opposing.status().message().find("normals 0 and 1 oppose each other (a tight fit"),
            std::string::npos)
      << opposing.status().message();
  // Opposing with a table under them: still no solution.
  Result<Vector3d> slot = ContactBias(Normals({{1, 0, 0}, {-1, 0, 0}, {0, 0, 1}}), 0.005, 0.02);
  EXPECT_FALSE(slot.ok());
  // Four coplanar normals that cannot all be pushed into (a V with a wall behind): no solution.
  Result<Vector3d> four = ContactBias(Normals({{1, 0, 0}, {0, 1, 0}, {-1, -1, 0}}), 0.005, 0.02);
  ASSERT_FALSE(four.ok());
  EXPECT_NE(four.status().message().find("no bias moves 5 mm into all 3 contacts"), std::string::npos)
      << four.status().message();
  // Nearly opposing (a narrow V, 170 degrees apart): solvable but far too large.
  double a = 85.0 * M_PI / 180;
  Result<Vector3d> narrow =
      ContactBias(Normals({{std::cos(a), std::sin(a), 0}, {std::cos(a), -std::sin(a), 0}}), 0.005, 0.02);
  ASSERT_FALSE(narrow.ok());
  EXPECT_NE(narrow.status().message().find("above the limit 20 mm"), std::string::npos)
      << narrow.status().message();
  EXPECT_TRUE(
      ContactBias(Normals({{std::cos(a), std::sin(a), 0}, {std::cos(a), -std::sin(a), 0}}), 0.005, 0.1).ok());
}

}  // namespace
}  // namespace teachsim::robot
