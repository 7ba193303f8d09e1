// The task simulator (paper §5): the workpiece moves under first-order dynamics with contact
// forces from Baraff's LCP, and each step's motion is the minimum of the barrier potential along
// its spatial velocity, searched only over the part of the step that conservative advancement
// proves free, so no pose and no motion between poses ever comes closer than zero to anything.
//
// Model apart from state (STYLE.md): SimWorld is built once from a scene and never changes while
// a drag runs; SimState carries the workpiece pose, the capture set and the warm-start caches.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/contact.h"
#include "teachsim/geometry/distance.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/geometry/shape.h"
#include "teachsim/scene/scene.h"

namespace teachsim::sim {

struct SimOptions {
  double step_s = 0.05;                 // the paper's 20 Hz
  double contact_distance_m = 0.5e-3;   // eps_c: closer counts as contact
  double barrier_distance_m = 0.1e-3;   // eps_b: the barrier rises below this
  double capture_distance_m = 2e-3;     // eps_o: captured contact is kept within this
  double translation_gain = 0.1;        // d_t, m/s per N
  double rotation_gain = 49.0;          // d_r, rad/s per N m (d_t / (45 mm)^2: a block's size)
  double barrier_constant_j = 1e-3;     // K; keeps a 4 N push above eps_b / 2
  double max_speed_mps = 0.4;           // the paper's 400 mm/s
  double max_angular_speed_radps = 3.0;
  double settle_force_n = 1.0;          // virtual gravity toward the table; 0 turns it off
  double search_tolerance = 1e-3;       // of s in [0, 1], for the line search
  bool line_search_golden = false;      // true: the paper's plain golden section over the bracket
  [[nodiscard]] Status Validate() const;
};

// A part of an obstacle, placed in the world.
struct ObstaclePart {
  int object = 0;  // index into SimWorld::objects
  const geometry::ConvexPolyhedron* convex = nullptr;
  geometry::Pose3 world_T_part;
  geometry::Aabb bounds;
};

struct SimWorld {
  scene::Scene scene;  // owns the shapes
  SimOptions options;
  // Every part of every object, placed at the scene's poses. The workpiece's own parts are
  // skipped at run time.
  std::vector<ObstaclePart> parts;

  static Result<SimWorld> Build(scene::Scene scene, const SimOptions& options);
  const std::string& name(int object) const { return scene.objects[static_cast<std::size_t>(object)].name; }
};

struct Contact {
  int object = 0;
  Eigen::Vector3d point;         // world, on the obstacle
  Eigen::Vector3d normal;        // world, unit, from the obstacle toward the workpiece
  double distance = 0.0;         // m
  bool capture = false;          // the object is a capture object engaged in this contact
};

struct SimStats {
  long steps = 0;
  long distance_queries = 0;
  long sticking_resolved = 0;   // steps that were blocked and then moved after re-projection
  long sticking_events = 0;     // steps that stayed blocked although the force could move the workpiece
  double min_distance_m = 1e300;  // smallest distance ever certified, over the continuous motion
};

struct SimState {
  int workpiece = -1;                 // object index
  geometry::Pose3 world_T_workpiece;
  double time_s = 0.0;
  std::vector<int> capture;           // objects the workpiece must keep contact with, once made
  std::vector<int> engaged;           // capture objects contact has been made with
  std::vector<geometry::DistanceCache> caches;  // per (workpiece part, obstacle part)
  SimStats stats;
};

// Starts a drag of `workpiece` (its pose from the scene). Fails if the name is unknown, the
// object is fixed, or it intersects something.
Result<SimState> StartDrag(const SimWorld& world, const std::string& workpiece);

struct StepInput {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();    // applied, world, at the workpiece origin
  Eigen::Vector3d torque_nm = Eigen::Vector3d::Zero();  // applied, world
};

struct StepResult {
  std::vector<Contact> contacts;     // at the start of the step (what the forces saw)
  geometry::Twist velocity;          // after the LCP and the barrier terms
  double fraction = 1.0;             // s: the share of the step taken
  double min_distance_m = 1e300;     // certified over the step's motion
  int distance_queries = 0;
  bool blocked = false;              // a force could move it, yet it did not move
};

StepResult Step(const SimWorld& world, SimState& state, const StepInput& input);

// The contacts of the workpiece at its current pose (pairs within eps_c).
std::vector<Contact> CurrentContacts(const SimWorld& world, SimState& state);

}  // namespace teachsim::sim
