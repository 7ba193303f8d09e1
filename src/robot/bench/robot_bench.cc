// teachsim bench robot: the closed-form inverse kinematics (all eight solutions, and the nearest
// within limits) per pose, against a peer that solves the same poses numerically (damped least
// squares on our Jacobian, to the same 1e-9, from the nearby start a control cycle would give it
// and from a cold start);
// and the task controller's cycle time during a contact move (the 100 Hz budget is 10 ms).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>

#include "teachsim/base/bench_registry.h"
#include "teachsim/robot/controller.h"
#include "teachsim/robot/kinematics.h"

namespace teachsim::robot {
namespace {

using Clock = std::chrono::steady_clock;
double Us(Clock::duration d) { return std::chrono::duration<double, std::micro>(d).count(); }

// The peer: Newton steps with damped least squares until the pose error is below 1e-9.
bool NumericIk(const RobotModel& m, const geometry::Pose3& target, Joints q, Joints* out, int* iterations) {
  for (int it = 0; it < 100; ++it) {
    const geometry::Pose3 T = ToolPose(m, q);
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = target.translation - T.translation;
    Eigen::AngleAxisd d(target.rotation * T.rotation.conjugate());
    e.tail<3>() = d.axis() * d.angle();
    if (e.head<3>().norm() < 1e-9 && e.tail<3>().norm() < 1e-9) {
      *out = q;
      *iterations = it;
      return true;
    }
    const Jacobian J = ToolJacobian(m, q);
    const Eigen::Matrix<double, 6, 6> A = J * J.transpose() + 1e-10 * Eigen::Matrix<double, 6, 6>::Identity();
    q += J.transpose() * A.ldlt().solve(e);
  }
  return false;
}

// An ideal plant: joints at their setpoints, a constant light push on the tool.
class IdealIo : public RobotIo {
 public:
  Joints q = Joints::Zero();
  Joints ReadJoints() override { return q; }
  Wrench ReadWristWrench() override { return {Eigen::Vector3d(0.0, 0.0, 0.5), Eigen::Vector3d::Zero()}; }
  GripperState ReadGripper() override { return {0.045, false}; }
  void CommandJoints(const Joints& setpoint) override { q = setpoint; }
  void CommandGripper(double) override {}
};

int Run(const BenchArgs& args) {
  const char* home = std::getenv("TEACHSIM_HOME");
  const std::string path =
      std::string(home != nullptr && *home != '\0' ? home : TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.json";
  auto model = LoadRobotModel(path);
  if (!model.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", model.status().message().c_str());
    return 2;
  }
  const RobotModel& m = *model;
  const int n = args.quick ? 2000 : 100000;
  std::mt19937_64 rng(1);
  std::vector<Joints> joints(n);
  std::vector<geometry::Pose3> poses(n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < kNumJoints; ++j) {
      joints[i][j] =
          std::uniform_real_distribution<double>(m.joints[j].lower_rad, m.joints[j].upper_rad)(rng);
    }
    poses[i] = ToolPose(m, joints[i]);
  }
  // Closed form, all eight.
  double checksum = 0;
  auto t = Clock::now();
  for (int i = 0; i < n; ++i) checksum += SolveToolIk(m, poses[i], joints[i]).solutions[0].q[0];
  const double all_us = Us(Clock::now() - t) / n;
  // Closed form, nearest within limits, from a start 0.01 rad away (one control cycle's motion).
  t = Clock::now();
  int nearest_ok = 0;
  for (int i = 0; i < n; ++i) {
    Result<IkSolution> r = NearestToolIk(m, poses[i], joints[i] + Joints::Constant(0.01));
    nearest_ok += r.ok();
  }
  const double nearest_us = Us(Clock::now() - t) / n;
  // Peer: numeric, same start.
  t = Clock::now();
  int numeric_ok = 0;
  long long iterations = 0;
  for (int i = 0; i < n; ++i) {
    Joints q;
    int it = 0;
    if (NumericIk(m, poses[i], joints[i] + Joints::Constant(0.01), &q, &it)) {
      ++numeric_ok;
      iterations += it;
    }
  }
  const double numeric_us = Us(Clock::now() - t) / n;
  // Peer from a cold start (the ready pose), as a planner without a nearby guess would call it.
  t = Clock::now();
  int cold_ok = 0;
  for (int i = 0; i < n; ++i) {
    Joints q;
    int it = 0;
    cold_ok += NumericIk(m, poses[i], m.ready_rad, &q, &it) && m.WithinLimits(q);
  }
  const double cold_us = Us(Clock::now() - t) / n;

  // Controller cycle during a contact move (impedance, monitor, IK, safety of the next setpoint).
  const geometry::Pose3 world_T_base;
  ControllerOptions options;
  options.safety.workspace = {Eigen::Vector3d::Constant(-2), Eigen::Vector3d::Constant(2)};
  TaskController controller(m, world_T_base, options);
  IdealIo io;
  io.q = m.ready_rad;
  MotionRequest request;
  request.world_T_tool = ToolPose(m, m.ready_rad);
  request.world_T_tool.translation += Eigen::Vector3d(0.05, 0.05, -0.05);
  request.speed_mps = 0.01;
  request.impedance = ImpedanceSpec{};
  if (Status s = controller.StartMotion(request, io, 0); !s.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", s.message().c_str());
    return 1;
  }
  std::vector<double> cycles;
  double time_s = 0;
  while (true) {
    const auto c = Clock::now();
    const bool running = controller.Cycle(io, time_s);
    cycles.push_back(Us(Clock::now() - c));
    if (!running) break;
    time_s += options.cycle_s;
  }
  std::sort(cycles.begin(), cycles.end());
  const double median_us = cycles[cycles.size() / 2], max_us = cycles.back();

  if (args.json) {
    std::printf("%s\n", json::Json{{"benchmark", "robot"},
                                   {"poses", n},
                                   {"ik_all_eight_us", all_us},
                                   {"ik_nearest_us", nearest_us},
                                   {"ik_nearest_solved", nearest_ok},
                                   {"peer_numeric_dls_us", numeric_us},
                                   {"peer_numeric_solved", numeric_ok},
                                   {"peer_numeric_cold_us", cold_us},
                                   {"peer_numeric_cold_solved_within_limits", cold_ok},
                                   {"peer_numeric_mean_iterations",
                                    numeric_ok > 0 ? static_cast<double>(iterations) / numeric_ok : 0.0},
                                   {"controller_cycles", cycles.size()},
                                   {"controller_cycle_median_us", median_us},
                                   {"controller_cycle_max_us", max_us},
                                   {"checksum", checksum}}
                            .dump(2)
                            .c_str());
    return 0;
  }
  std::printf("inverse kinematics of the CRS A465, %d random reachable poses, one core:\n", n);
  std::printf("  closed form, all eight solutions      %7.2f us/pose\n", all_us);
  std::printf("  closed form, nearest within limits    %7.2f us/pose (%d solved)\n", nearest_us, nearest_ok);
  std::printf(
      "  peer: numeric damped least squares    %7.2f us/pose (%d solved, %.1f iterations, one solution)\n",
      numeric_us, numeric_ok, numeric_ok > 0 ? static_cast<double>(iterations) / numeric_ok : 0.0);
  std::printf("  peer: the same from the ready pose      %7.2f us/pose (%d solved within the limits)\n",
              cold_us, cold_ok);
  std::printf(
      "task controller, contact move: %zu cycles, median %.1f us, max %.1f us (budget 10000 us at 100 Hz)\n",
      cycles.size(), median_us, max_us);
  return 0;
}

}  // namespace
}  // namespace teachsim::robot

TEACHSIM_BENCH("robot", "closed-form IK vs numeric DLS per pose; the task controller's cycle time",
               teachsim::robot::Run);
