// The MuJoCo-simulated work site (issue 5, item 4): the MJCF generated from a scene — table and
// frame as fixed bodies, blocks as free wooden bodies — and the arm from the robot table (a
// Puma-type chain placed with our own forward kinematics, a parallel-jaw gripper with two slide
// fingers, a wrist force/torque sensor on a site between flange and gripper, position servos on
// the joints and fingers). MujocoWorld is a robot::RobotIo: the controller reads only joint
// positions, the wrist wrench and the gripper state; the ground truth (object poses) is for the
// report and the tests only. Loaded from a string through MuJoCo's VFS, no GL.
#pragma once

#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/robot/robot_io.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {

struct MujocoWorldOptions {
  double timestep_s = 0.001;        // the joint servos' 1 kHz
  double wood_density_kg_m3 = 600;  // blocks (pine/beech-like)
  double block_friction = 0.3;      // block against table/frame (the fingers' pads grip at 1.0)
  double finger_friction = 1.0;
  // Contacts: stiff and well damped (MuJoCo solref time constant, damping ratio), so that a 45 mm
  // block neither sinks into the table nor jitters on it.
  double contact_timeconst_s = 0.004;
  double contact_dampratio = 1.0;
  // MuJoCo's friction is soft: a held block creeps in the jaws under any sustained load (here
  // 0.2 mm/s under the 1.5 N of a biased contact move: 3 mm over the around-corner program,
  // which ate the bias and failed its verification). The no-slip pass makes static friction
  // hold, as rubber pads squeezing at 7.5-15 N do against a few newtons. 0: MuJoCo's default.
  int noslip_iterations = 10;
  // The finger pads are rubber: their contacts are softer (they dominate the pair's solref), which
  // also stands for the compliance of a real wrist sensor between the stiff arm and the world.
  double pad_timeconst_s = 0.015;
  // Joint servos: an industrial arm's stiff position loop behind a high gear ratio (armature is
  // the reflected rotor inertia).
  double joint_kp_nm_per_rad = 10000;
  double joint_kv_nms_per_rad = 140;  // about critical with the armature
  double joint_armature_kgm2 = 0.5;
  // Gripper: each finger's position servo, its force limit (the grip) and its damping (the
  // closing speed, about force / damping).
  double finger_kp_n_per_m = 3000;
  double finger_force_limit_n = 15;
  double finger_damping_ns_per_m = 120;
  double gripper_moving_speed_mps = 0.002;  // fingers slower than this count as stopped
  double settle_s = 0.3;                    // the world runs this long before the robot starts
  [[nodiscard]] Status Validate() const;
};

// The generated MJCF (for inspection: `teachsim execute --mjcf FILE` writes it).
[[nodiscard]] Result<std::string> BuildMjcf(const scene::Scene& scene, const robot::RobotModel& model,
                                            const MujocoWorldOptions& options);

// What vision leaves behind (issue 5, item 5): every movable object moved by up to position_m in a
// random direction and turned by up to angle_rad; objects resting on a fixed support move only in
// x, y and yaw so that they stay resting. The block friction is drawn from [min, max].
struct ModelError {
  double position_m = 0;
  double angle_rad = 0;
  std::uint64_t seed = 1;
  double min_friction = 0.1, max_friction = 0.5;
  [[nodiscard]] Status Validate() const;
};
struct PerturbedWorld {
  scene::Scene scene;     // the simulated world's truth
  double block_friction;  // drawn from the seed
};
PerturbedWorld PerturbScene(const scene::Scene& operator_scene, const ModelError& error);

struct MjHandles;  // mjModel / mjData, kept out of this header

class MujocoWorld : public robot::RobotIo {
 public:
  // The scene must place a robot (scene.robot); the arm starts at model.ready_rad (or `start`).
  [[nodiscard]] static Result<std::unique_ptr<MujocoWorld>> Create(const scene::Scene& scene,
                                                                   const robot::RobotModel& model,
                                                                   const MujocoWorldOptions& options,
                                                                   const robot::Joints* start = nullptr);
  ~MujocoWorld() override;
  MujocoWorld(const MujocoWorld&) = delete;
  MujocoWorld& operator=(const MujocoWorld&) = delete;

  // RobotIo: what a real robot offers.
  robot::Joints ReadJoints() override;
  robot::Wrench ReadWristWrench() override;
  robot::GripperState ReadGripper() override;
  void CommandJoints(const robot::Joints& setpoint_rad) override;
  void CommandGripper(double width_m) override;

  // Runs the physics for dt_s (whole timesteps); joint setpoints are interpolated linearly from the
  // previous command to the new one over the first controller period (the servo interpolator).
  void Advance(double dt_s);

  // Ground truth, for the report and the tests (never given to the controller).
  double time_s() const;
  geometry::Pose3 ObjectPose(const std::string& name) const;      // a scene object's body
  geometry::Pose3 TrueToolPose() const;                           // the tool site, world
  Eigen::Vector3d ContactForceOn(const std::string& name) const;  // sum of contact forces on its geoms, world
  // What the work site's camera sees now (issue 6: "of the MuJoCo world, robot included"): the
  // scene's objects at their simulated poses (materials and grain as ObjectsFromScene gives
  // them), then the robot: one dark grey object per arm link ("robot_base", "robot_link_1" ...
  // "robot_link_6", "robot_gripper", "robot_finger_left", "robot_finger_right"), capsules and
  // cylinders as 12- and 16-sided hulls. For Renderer::Render.
  std::vector<RenderObject> RenderObjects() const;
  // Every active contact, one line each: the two bodies, the normal force and the friction (N),
  // the penetration (mm). For people debugging a program on the work site.
  std::string DescribeContacts() const;
  long steps() const { return steps_; }
  double timestep_s() const { return options_.timestep_s; }
  const std::string& mjcf() const { return mjcf_; }

 private:
  MujocoWorld() = default;
  std::unique_ptr<MjHandles> mj_;
  MujocoWorldOptions options_;
  std::string mjcf_;
  std::vector<RenderObject> scene_objects_;  // the simulated world's scene, poses as at Create
  struct RobotBody {
    int body = 0;
    RenderObject object;  // parts in the body frame; world_T_object set per call
  };
  std::vector<RobotBody> robot_bodies_;
  robot::Joints from_ = robot::Joints::Zero(), to_ = robot::Joints::Zero();
  int interpolation_step_ = 0, interpolation_steps_ = 10;
  long steps_ = 0;
};

}  // namespace teachsim::worksite
