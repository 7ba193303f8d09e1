// The program generator (paper §6): the demonstrated workpiece path is deformed as an elastic
// band (Quinlan 1994; paper §6.1) whose nodes move through the task simulator, simplified into a
// few straight segments whose knots carry their contact normals, and turned into a robot program
// with guarded grasp, free moves and compliant, biased, force-verified contact moves (§6.2).
#pragma once

#include <set>
#include <string>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/robot/program.h"
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
};

struct PlanResult {
  sim::WorkpiecePath initial, deformed, simplified;
  robot::Program program;
  PlanMetrics metrics;
};

[[nodiscard]] Result<PlanResult> GenerateProgram(const scene::Scene& scene, const sim::WorkpiecePath& path,
                                                 const PlanOptions& options = {});

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
                                                 const std::vector<int>& knots, const PlanOptions& options);

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
