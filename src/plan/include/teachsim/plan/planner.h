// The program generator (paper §6): the demonstrated workpiece path is deformed as an elastic
// band (Quinlan 1994; paper §6.1) whose nodes move through the task simulator, simplified into a
// few straight segments whose knots carry their contact normals, and turned into a robot program
// with guarded grasp, free moves and compliant, biased, force-verified contact moves (§6.2).
// Given the robot, the grasp is chosen among turns about the tool axis with the arm's inverse
// kinematics (reachable, within the joint limits, away from singularities along the whole program)
// and the gripper's palm and fingers are checked against the scene along it.
#pragma once

#include <set>
#include <string>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/sim/path.h"
#include "teachsim/sim/simulator.h"

namespace teachsim::plan {

struct PlanOptions {
  // Which contacts are required (the rest are unwanted and the band pushes away from them).
  bool destination_required = true;  // the last node's contacts
  bool capture_required = true;      // stretches where the path was captured
  std::vector<std::string> required_objects;  // required wherever the path touches them (override)

  // Deformation (paper §6.1).
  double tension_n = 0.5;              // constant pull toward each neighbour...
  double min_spacing_m = 2e-3;         // ...proportional below this spacing (the paper's stability fix)
  double rotation_tension_nm = 0.01;   // toward the neighbours' orientations
  double repulsion_range_m = 0.013;    // unwanted obstacles closer than this push the node away
  double repulsion_n_per_m = 100.0;    // 2 N at contact, more than the tension
  int max_iterations = 200;
  double converged_m = 5e-5;           // a sweep whose nodes move less than this on average settles the band
  double max_spacing_m = 0.0;          // 0: half the thinnest part in the scene (5 mm lip: 2.5 mm)

  // Simplification.
  double position_tolerance_m = 0.01;  // the band's bends need not be followed closely: every
                                       // shortcut is checked for collisions and clearance...
  double clearance_target_m = 0.01;    // ...and keeps the band's clearance up to this, less 1 mm
  double angle_tolerance_rad = 5.0 * 3.14159265358979323846 / 180.0;

  // The program (paper §6.2).
  double grip_depth_m = 0.012;         // the fingers hold the top of the block
  double free_speed_mps = 0.1;
  double contact_speed_mps = 0.01;
  double bias_depth_m = 5e-3;          // d
  double max_bias_m = 0.02;            // a bias longer than this is the tight-fit case
  double contact_stiffness_n_per_m = 300.0;
  double contact_damping_n_s_per_m = 1000.0;
  double threshold_fraction = 0.4;     // force threshold per normal: this share of stiffness * d
  double retreat_m = 0.05;

  // The grasp, with a robot (GenerateProgram's `robot`): from above, turned about the tool axis by
  // 0, 90, 180 or 270 degrees; the feasible one farthest from the singularities wins.
  double gripper_clearance_m = 2e-3;  // palm and fingers keep this from everything but the workpiece
  double min_wrist_measure = 0.03;    // |sin theta5| all along the program (1.7 deg from the wrist singularity;
                                      // the joint speeds near it are checked as the work site checks them)
  double min_elbow_measure = 0.1;     // |sin| of the elbow angle
  double min_shoulder_m = 0.02;       // wrist centre from joint 1's axis
  double check_step_m = 2e-3;         // sampling of the program's motions for these checks
  double check_step_rad = 0.02;

  [[nodiscard]] Status Validate() const;
};

struct PlanNode {
  geometry::Pose3 pose;
  std::set<int> required;  // objects whose contact this node must keep
  bool fixed = false;      // endpoints and the ends of required stretches
  std::vector<sim::PathContact> contacts;  // as demonstrated (kept for fixed nodes)
};

struct PlanMetrics {
  double length_before_m = 0.0, length_after_m = 0.0;  // translation path length
  int nodes_before = 0, nodes_deformed = 0, knots = 0, commands = 0, motion_commands = 0;
  double min_clearance_before_m = 0.0;  // to unwanted obstacles, farther along the path from the ends and required
                                        // stretches than the repulsion range plus the workpiece's radius
  double min_clearance_after_m = 0.0;   // ... of the simplified path, over its continuous motion
  int required_nodes = 0;
  bool required_contacts_kept = true;
  int iterations = 0;
  bool band_converged = false;
  double deform_ms = 0.0, simplify_ms = 0.0, total_ms = 0.0;
  // With a robot: the chosen grasp and its margins over the whole program.
  bool robot_checked = false;
  double grasp_yaw_deg = 0.0;                // turn of the grasp about the tool axis
  double min_gripper_clearance_m = 0.0;      // palm and fingers to the scene (the workpiece aside)
  double min_wrist_measure = 0.0, min_elbow_measure = 0.0, min_shoulder_m = 0.0;
};

// One grasp candidate as judged with the robot.
struct GraspReport {
  double yaw_deg = 0.0;  // about the tool axis, from jaws across the workpiece's y
  double width_m = 0.0;  // the workpiece across the jaws
  bool feasible = false;
  std::string problem;   // why not: the command, the place and what is in the way
  double min_gripper_clearance_m = 0.0;
  std::string closest;   // where the gripper came closest: "palm to frame at commands[3] (contact_move) ..."
  double min_wrist_measure = 0.0, min_elbow_measure = 0.0, min_shoulder_m = 0.0;
};

struct PlanResult {
  sim::WorkpiecePath initial, deformed, simplified;
  robot::Program program;
  PlanMetrics metrics;
  std::vector<GraspReport> grasps;  // with a robot: every candidate, in the order tried
};

// `robot` (optional) is the arm the scene places (scene.robot): with it the grasp is chosen and
// checked as above, and a program no grasp can run is refused (Failed) with the reasons; without
// it the grasp is the first candidate, unchecked.
[[nodiscard]] Result<PlanResult> GenerateProgram(const scene::Scene& scene, const sim::WorkpiecePath& path,
                                                 const PlanOptions& options = {},
                                                 const robot::RobotModel* robot = nullptr);

// The pieces, for tests and benchmarks.
struct Band {
  std::vector<PlanNode> nodes;
  int workpiece = -1;
};
[[nodiscard]] Result<Band> MakeBand(const sim::SimWorld& world, const sim::WorkpiecePath& path, const PlanOptions& options);
struct DeformStats {
  int iterations = 0;      // sweeps over the band, all levels
  bool converged = false;  // the final (finest) level settled before max_iterations ran out
};
DeformStats Deform(const sim::SimWorld& world, Band& band, const PlanOptions& options);
std::vector<int> Simplify(const sim::SimWorld& world, const Band& band, const PlanOptions& options);  // knot indices
[[nodiscard]] Result<robot::Program> MakeProgram(const sim::SimWorld& world, const Band& band,
                                                 const std::vector<int>& knots, const PlanOptions& options,
                                                 double grasp_yaw_rad = 0.0);
// Judges a program with the robot placed at world_T_base, starting from its ready joints.
GraspReport CheckWithRobot(const sim::SimWorld& world, const robot::RobotModel& model,
                           const geometry::Pose3& world_T_base, const robot::Program& program,
                           const PlanOptions& options);

// The gripper's tool poses and jaw widths along a program's motions, every step_m / step_rad,
// from `start` (the tool where the program begins); `what` names the command and the part of it.
struct ToolSample {
  geometry::Pose3 world_T_tool;
  double width_m = 0.0;
  std::string what;  // "commands[3] (contact_move) at 40%"
};
std::vector<ToolSample> SampleProgram(const robot::Program& program, const geometry::Pose3& start, double start_width_m,
                                      double step_m, double step_rad);

// Checks over the continuous motion between two workpiece poses (conservative advancement):
// true when nothing comes closer than `clearance_m`. `ignore` objects are skipped.
bool MotionClear(const sim::SimWorld& world, int workpiece, const geometry::Pose3& a, const geometry::Pose3& b,
                 double clearance_m);
// Smallest distance to any object not in `skip` (the workpiece itself is always skipped), up to range.
double Clearance(const sim::SimWorld& world, int workpiece, const geometry::Pose3& pose, const std::set<int>& skip,
                 double range_m);
double ObjectDistance(const sim::SimWorld& world, int workpiece, const geometry::Pose3& pose, int object);
double PathLength(const std::vector<geometry::Pose3>& poses);

}  // namespace teachsim::plan
