// teachsim robot urdf|listing|check: the arm's table and robot programs (docs/formats/robot.md,
// docs/formats/program.md).
//   teachsim robot urdf [--robot FILE] [--out FILE]       the URDF generated from a robot table
//   teachsim robot listing --program FILE                 validate a program, print one line per command
//   teachsim robot check --program FILE [--scene FILE]    the safety checks, from the ready pose
#include <cstdio>
#include <memory>

#include "commands.h"
#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/robot/safety.h"
#include "teachsim/scene/scene.h"

namespace teachsim::app {

namespace {

struct RobotOptions {
  std::string robot;
  std::string out;
  std::string program;
  std::string scene;
};

int RunUrdf(const RobotOptions& o) {
  auto model = robot::LoadRobotModel(o.robot.empty() ? DataPath("robots/crs_a465.json") : o.robot);
  if (!model.ok()) return ReportError(model.status());
  std::string urdf = robot::RobotModelToUrdf(*model);
  if (o.out.empty()) {
    std::fputs(urdf.c_str(), stdout);
    return 0;
  }
  if (Status s = json::WriteFileAtomic(o.out, urdf); !s.ok()) return ReportError(s);
  std::printf("wrote %s\n", o.out.c_str());
  return 0;
}

int RunListing(const RobotOptions& o) {
  auto program = robot::LoadProgram(o.program);
  if (!program.ok()) return ReportError(program.status());
  std::fputs(robot::ProgramListing(*program).c_str(), stdout);
  return 0;
}

int RunCheck(const RobotOptions& o) {
  auto program = robot::LoadProgram(o.program);
  if (!program.ok()) return ReportError(program.status());
  auto scene = scene::LoadScene(o.scene.empty() ? DataPath("scenes/puzzle.json") : o.scene);
  if (!scene.ok()) return ReportError(scene.status());
  if (!scene->robot) return ReportError(Status::InvalidInput(o.scene + ": the scene places no robot"));
  auto model = robot::LoadRobotModel(DataPath("robots/" + scene->robot->model + ".json"));
  if (!model.ok()) return ReportError(model.status());
  robot::SafetyOptions safety;
  Status s = robot::CheckProgram(*model, scene->robot->world_T_base, *program, model->ready_rad,
                                 robot::MotionLimits{}, safety);
  if (!s.ok()) return ReportError(s);
  std::printf("%s: %zu commands pass the safety checks from %s's ready pose\n", o.program.c_str(),
              program->commands.size(), model->name.c_str());
  return 0;
}

}  // namespace

void AddRobotCommand(CLI::App& app, Runner* run) {
  auto o = std::make_shared<RobotOptions>();
  CLI::App* sub =
      app.add_subcommand("robot", "the arm's table (URDF) and robot programs (listing, safety check)");
  sub->require_subcommand(1);
  CLI::App* urdf = sub->add_subcommand("urdf", "print or write the URDF generated from a robot table");
  urdf->add_option("--robot", o->robot, "robot table (default robots/crs_a465.json)");
  urdf->add_option("--out", o->out, "write the URDF here instead of printing it");
  urdf->callback([o, run] { *run = [o] { return RunUrdf(*o); }; });
  CLI::App* listing =
      sub->add_subcommand("listing", "validate a robot program and print one line per command");
  listing->add_option("--program", o->program, "program (JSON, docs/formats/program.md)")->required();
  listing->callback([o, run] { *run = [o] { return RunListing(*o); }; });
  CLI::App* check = sub->add_subcommand("check", "run a program's safety checks from the robot's ready pose");
  check->add_option("--program", o->program, "program (JSON, docs/formats/program.md)")->required();
  check->add_option("--scene", o->scene, "scene placing the robot (default scenes/puzzle.json)");
  check->callback([o, run] { *run = [o] { return RunCheck(*o); }; });
}

}  // namespace teachsim::app
