#include "teachsim/worksite/mujoco_world.h"

#include <mujoco/mujoco.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <sstream>

#include "teachsim/base/json.h"
#include "teachsim/robot/kinematics.h"

namespace teachsim::worksite {

struct MjHandles {
  mjModel* model = nullptr;
  mjData* data = nullptr;
  int sensor_force_adr = 0, sensor_torque_adr = 0;
  int joint_qpos[robot::kNumJoints] = {}, joint_dof[robot::kNumJoints] = {};
  int finger_qpos[2] = {}, finger_dof[2] = {};
  int joint_actuator[robot::kNumJoints] = {}, finger_actuator[2] = {};
  int wrist_site = 0, tool_site = 0;
  std::vector<std::pair<std::string, int>> object_bodies;  // scene name -> body id
  geometry::Pose3 flange_T_tool;
  ~MjHandles() {
    if (data) mj_deleteData(data);
    if (model) mj_deleteModel(model);
  }
};

namespace {

std::string Num(double v) { return json::FormatNumber(std::abs(v) < 1e-15 ? 0.0 : v); }
std::string Vec(const Eigen::Vector3d& v) { return Num(v.x()) + " " + Num(v.y()) + " " + Num(v.z()); }
std::string Quat(const Eigen::Quaterniond& q) {
  return Num(q.w()) + " " + Num(q.x()) + " " + Num(q.y()) + " " + Num(q.z());
}
std::string PoseAttrs(const geometry::Pose3& p) {
  return "pos=\"" + Vec(p.translation) + "\" quat=\"" + Quat(p.rotation.normalized()) + "\"";
}

void CollectVertices(const scene::ShapeSpec& spec, const geometry::Pose3& T,
                     std::vector<Eigen::Vector3d>* out) {
  switch (spec.kind) {
    case scene::ShapeSpec::Kind::kBox:
      for (int i = 0; i < 8; ++i) {
        Eigen::Vector3d c((i & 1 ? 0.5 : -0.5) * spec.box_size.x(), (i & 2 ? 0.5 : -0.5) * spec.box_size.y(),
                          (i & 4 ? 0.5 : -0.5) * spec.box_size.z());
        out->push_back(T * c);
      }
      break;
    case scene::ShapeSpec::Kind::kConvex:
      for (const Eigen::Vector3d& v : spec.vertices) out->push_back(T * v);
      break;
    case scene::ShapeSpec::Kind::kParts:
      for (const scene::ShapeSpec::Part& part : spec.parts) CollectVertices(part.shape, T * part.pose, out);
      break;
  }
}

// Geoms of one object (recursing into parts); meshes go to `assets`.
void EmitGeoms(const scene::ShapeSpec& spec, const geometry::Pose3& body_T_shape, const std::string& prefix,
               const std::string& attrs, int* counter, std::ostringstream& geoms,
               std::ostringstream& assets) {
  switch (spec.kind) {
    case scene::ShapeSpec::Kind::kBox:
      geoms << "      <geom name=\"" << prefix << "_" << (*counter)++ << "\" type=\"box\" size=\""
            << Vec(spec.box_size / 2) << "\" " << PoseAttrs(body_T_shape) << " " << attrs << "/>\n";
      break;
    case scene::ShapeSpec::Kind::kConvex: {
      const std::string mesh = prefix + "_mesh_" + std::to_string(*counter);
      assets << "    <mesh name=\"" << mesh << "\" vertex=\"";
      for (const Eigen::Vector3d& v : spec.vertices) assets << Vec(v) << " ";
      assets << "\"/>\n";
      geoms << "      <geom name=\"" << prefix << "_" << (*counter)++ << "\" type=\"mesh\" mesh=\"" << mesh
            << "\" " << PoseAttrs(body_T_shape) << " " << attrs << "/>\n";
      break;
    }
    case scene::ShapeSpec::Kind::kParts:
      for (const scene::ShapeSpec::Part& part : spec.parts) {
        EmitGeoms(part.shape, body_T_shape * part.pose, prefix, attrs, counter, geoms, assets);
      }
      break;
  }
}

std::string BodyName(std::size_t i) { return "object_" + std::to_string(i); }

// The convex part of one robot geom for the renderer, in the geom's frame (MuJoCo sizes are half
// sizes; capsules and cylinders lie along z).
std::shared_ptr<const geometry::ConvexPolyhedron> GeomConvex(int type, const mjtNum* size) {
  std::vector<Eigen::Vector3d> points;
  if (type == mjGEOM_BOX) {
    auto box = geometry::ConvexPolyhedron::Box(2 * Eigen::Vector3d(size[0], size[1], size[2]));
    TEACHSIM_CHECK(box.ok());
    return std::make_shared<const geometry::ConvexPolyhedron>(std::move(box).value());
  }
  if (type == mjGEOM_CYLINDER) {
    for (int k = 0; k < 16; ++k) {
      const double a = 2 * M_PI * k / 16;
      for (double z : {-size[1], size[1]}) points.emplace_back(size[0] * std::cos(a), size[0] * std::sin(a), z);
    }
  } else if (type == mjGEOM_CAPSULE) {
    // Two hemispheres of two latitude rings and a pole each, around the segment's ends.
    const double r = size[0], h = size[1];
    for (double end : {-1.0, 1.0}) {
      points.emplace_back(0, 0, end * (h + r));
      for (double lat : {0.0, M_PI / 4}) {
        for (int k = 0; k < 12; ++k) {
          const double a = 2 * M_PI * (k + (lat > 0 ? 0.5 : 0.0)) / 12;
          points.emplace_back(r * std::cos(lat) * std::cos(a), r * std::cos(lat) * std::sin(a),
                              end * (h + r * std::sin(lat)));
        }
      }
    }
  } else {
    return nullptr;  // the robot has no other geom types
  }
  auto hull = geometry::ConvexPolyhedron::Hull(points);
  TEACHSIM_CHECK(hull.ok());
  return std::make_shared<const geometry::ConvexPolyhedron>(std::move(hull).value());
}

geometry::Pose3 PoseOf(const mjtNum* pos, const mjtNum* quat) {
  return {Eigen::Quaterniond(quat[0], quat[1], quat[2], quat[3]).normalized(),
          Eigen::Vector3d(pos[0], pos[1], pos[2])};
}

}  // namespace

Status MujocoWorldOptions::Validate() const {
  const std::pair<const char*, double> positive[] = {{"timestep_s", timestep_s},
                                                     {"wood_density_kg_m3", wood_density_kg_m3},
                                                     {"finger_friction", finger_friction},
                                                     {"contact_timeconst_s", contact_timeconst_s},
                                                     {"contact_dampratio", contact_dampratio},
                                                     {"pad_timeconst_s", pad_timeconst_s},
                                                     {"joint_kp_nm_per_rad", joint_kp_nm_per_rad},
                                                     {"joint_kv_nms_per_rad", joint_kv_nms_per_rad},
                                                     {"joint_armature_kgm2", joint_armature_kgm2},
                                                     {"finger_kp_n_per_m", finger_kp_n_per_m},
                                                     {"finger_force_limit_n", finger_force_limit_n},
                                                     {"finger_damping_ns_per_m", finger_damping_ns_per_m},
                                                     {"gripper_moving_speed_mps", gripper_moving_speed_mps}};
  for (const auto& [name, value] : positive) {
    if (!(std::isfinite(value) && value > 0)) {
      return Status::InvalidInput(std::string("MujocoWorldOptions::") + name + " = " +
                                  json::FormatNumber(value) + " must be > 0");
    }
  }
  if (!(block_friction >= 0 && std::isfinite(block_friction))) {
    return Status::InvalidInput("MujocoWorldOptions::block_friction = " + json::FormatNumber(block_friction) +
                                " must be >= 0");
  }
  if (!(settle_s >= 0)) return Status::InvalidInput("MujocoWorldOptions::settle_s must be >= 0");
  if (noslip_iterations < 0 || noslip_iterations > 1000) {
    return Status::InvalidInput("MujocoWorldOptions::noslip_iterations = " + std::to_string(noslip_iterations) +
                                " must be in [0, 1000]");
  }
  if (contact_timeconst_s < 2 * timestep_s || pad_timeconst_s < 2 * timestep_s) {
    return Status::InvalidInput("MujocoWorldOptions::contact_timeconst_s must be at least two timesteps");
  }
  return Status::Ok();
}

Status ModelError::Validate() const {
  if (!(position_m >= 0 && std::isfinite(position_m))) {
    return Status::InvalidInput("model error: position " + json::FormatNumber(position_m) +
                                " m must be >= 0");
  }
  if (!(angle_rad >= 0 && angle_rad < M_PI)) {
    return Status::InvalidInput("model error: angle " + json::FormatNumber(angle_rad) +
                                " rad must be in [0, pi)");
  }
  if (!(min_friction >= 0 && max_friction >= min_friction)) {
    return Status::InvalidInput("model error: friction range must satisfy 0 <= min <= max");
  }
  return Status::Ok();
}

PerturbedWorld PerturbScene(const scene::Scene& operator_scene, const ModelError& error) {
  TEACHSIM_CHECK(error.Validate().ok());
  std::mt19937_64 rng(error.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  PerturbedWorld out{operator_scene, 0.0};
  out.block_friction = error.min_friction + (error.max_friction - error.min_friction) * unit(rng);
  // The tops of the fixed objects: a movable object whose lowest point is on one rests there.
  std::vector<double> support_tops;
  for (const scene::SceneObject& o : operator_scene.objects) {
    if (!o.fixed) continue;
    std::vector<Eigen::Vector3d> v;
    CollectVertices(o.shape_spec, o.world_T_object, &v);
    for (const Eigen::Vector3d& p : v) support_tops.push_back(p.z());
  }
  for (scene::SceneObject& o : out.scene.objects) {
    if (o.fixed) continue;
    std::vector<Eigen::Vector3d> v;
    CollectVertices(o.shape_spec, o.world_T_object, &v);
    double lowest = 1e300;
    for (const Eigen::Vector3d& p : v) lowest = std::min(lowest, p.z());
    const bool upright = (o.world_T_object.rotation * Eigen::Vector3d::UnitZ()).z() > std::cos(1e-3);
    const bool on_support = std::any_of(support_tops.begin(), support_tops.end(),
                                        [&](double top) { return std::abs(top - lowest) < 3e-3; });
    const double distance = error.position_m * unit(rng);
    const double angle = error.angle_rad * (2 * unit(rng) - 1);
    Eigen::Vector3d direction, axis;
    if (upright && on_support) {
      const double heading = 2 * M_PI * unit(rng);
      direction = Eigen::Vector3d(std::cos(heading), std::sin(heading), 0);
      axis = Eigen::Vector3d::UnitZ();
    } else {
      const double z = 2 * unit(rng) - 1, phi = 2 * M_PI * unit(rng), r = std::sqrt(1 - z * z);
      direction = Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z);
      const double z2 = 2 * unit(rng) - 1, phi2 = 2 * M_PI * unit(rng), r2 = std::sqrt(1 - z2 * z2);
      axis = Eigen::Vector3d(r2 * std::cos(phi2), r2 * std::sin(phi2), z2);
    }
    o.world_T_object.translation += distance * direction;
    o.world_T_object.rotation = (Eigen::AngleAxisd(angle, axis) * o.world_T_object.rotation).normalized();
  }
  return out;
}

Result<std::string> BuildMjcf(const scene::Scene& scene, const robot::RobotModel& model,
                              const MujocoWorldOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  TEACHSIM_RETURN_IF_ERROR(model.Validate());
  if (!scene.robot) return Status::InvalidInput("the scene places no robot (its \"robot\" entry)");
  std::ostringstream assets, world, x;
  const std::string solref =
      "solref=\"" + Num(options.contact_timeconst_s) + " " + Num(options.contact_dampratio) + "\"";
  const std::string solimp = "solimp=\"0.95 0.99 0.0005\"";
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    const scene::SceneObject& o = scene.objects[i];
    int counter = 0;
    world << "    <body name=\"" << BodyName(i) << "\" " << PoseAttrs(o.world_T_object) << ">\n";
    if (o.fixed) {
      // Friction is the max of a contact's two geoms: fixed geoms stay below the block's own.
      EmitGeoms(o.shape_spec, geometry::Pose3::Identity(), BodyName(i),
                "friction=\"0.05 0.005 0.0001\" rgba=\"0.6 0.5 0.4 1\"", &counter, world, assets);
    } else {
      world << "      <freejoint/>\n";
      EmitGeoms(o.shape_spec, geometry::Pose3::Identity(), BodyName(i),
                "density=\"" + Num(options.wood_density_kg_m3) + "\" friction=\"" +
                    Num(options.block_friction) + " 0.005 0.0001\" rgba=\"0.8 0.6 0.3 1\"",
                &counter, world, assets);
    }
    world << "    </body>\n";
  }

  // The arm: body i is DH frame i; its pose in body i-1 is our own FK's at q = 0, the hinge is its
  // z axis (theta_i = q_i + offset commutes with TransZ(d_i)). Links are light (their weight
  // is the servos' business) and do not collide: they stay above and outside the work area.
  const auto frames = robot::LinkFrames(model, robot::Joints::Zero());
  const std::string link_geom = "contype=\"0\" conaffinity=\"0\" group=\"1\" rgba=\"0.25 0.25 0.27 1\"";
  std::ostringstream arm;
  arm << "    <body name=\"robot_base\" " << PoseAttrs(scene.robot->world_T_base) << ">\n";
  arm << "      <geom type=\"cylinder\" size=\"0.08 " << Num(model.base_height_m() / 2) << "\" pos=\"0 0 "
      << Num(model.base_height_m() / 2) << "\" " << link_geom << "/>\n";
  std::string indent = "      ";
  for (int i = 0; i < robot::kNumJoints; ++i) {
    const robot::DhJoint& j = model.joints[static_cast<std::size_t>(i)];
    const geometry::Pose3 rel =
        frames[static_cast<std::size_t>(i)].Inverse() * frames[static_cast<std::size_t>(i + 1)];
    arm << indent << "<body name=\"link_" << i + 1 << "\" " << PoseAttrs(rel) << ">\n";
    arm << indent << "  <inertial pos=\"0 0 0\" mass=\"0.5\" diaginertia=\"0.005 0.005 0.005\"/>\n";
    arm << indent << "  <joint name=\"" << j.name << "\" type=\"hinge\" axis=\"0 0 1\" range=\""
        << Num(j.lower_rad) << " " << Num(j.upper_rad) << "\" limited=\"true\" armature=\""
        << Num(options.joint_armature_kgm2) << "\" damping=\"" << Num(options.joint_kv_nms_per_rad)
        << "\"/>\n";
    if (i + 1 < robot::kNumJoints) {
      const Eigen::Vector3d next =
          (frames[static_cast<std::size_t>(i + 1)].Inverse() * frames[static_cast<std::size_t>(i + 2)])
              .translation;
      if (next.norm() > 1e-6) {
        arm << indent << "  <geom type=\"capsule\" fromto=\"0 0 0 " << Vec(next) << "\" size=\"0.04\" "
            << link_geom << "/>\n";
      }
    }
    indent += "  ";
  }
  // The gripper hangs from the flange through the wrist sensor's site; its boxes come from the
  // robot table (robot::GripperSpec), the same the program generator checks against the scene.
  const geometry::Pose3& F_T_tool = model.flange_T_tool;
  const robot::GripperSpec& g = model.gripper;
  const robot::GripperBox palm = robot::GripperBoxes(g, 0.0).front();
  arm << indent << "<body name=\"gripper\" pos=\"0 0 0\">\n";
  arm << indent << "  <site name=\"wrist\" pos=\"0 0 0\"/>\n";
  arm << indent << "  <site name=\"tool\" " << PoseAttrs(F_T_tool) << "/>\n";
  arm << indent << "  <geom name=\"palm\" type=\"box\" size=\"" << Vec(palm.size_m / 2) << "\" "
      << PoseAttrs(F_T_tool * palm.tool_T_box) << " mass=\"0.4\" rgba=\"0.3 0.3 0.3 1\"/>\n";
  const Eigen::Vector3d half = g.finger_size_m / 2;
  const double bare_length = g.finger_size_m.z() - g.pad_length_m;  // finger above its pad
  for (int side = 0; side < 2; ++side) {
    const double s = side == 0 ? 1.0 : -1.0;
    const std::string name = side == 0 ? "finger_left" : "finger_right";
    // The finger body sits at the tool frame; its slide joint is the half width, so the inner
    // face of the finger is at y = +-width / 2.
    arm << indent << "  <body name=\"" << name << "\" " << PoseAttrs(F_T_tool) << ">\n";
    arm << indent << "    <joint name=\"" << name << "\" type=\"slide\" axis=\"0 " << Num(s)
        << " 0\" range=\"0 " << Num(g.max_width_m / 2) << "\" limited=\"true\" damping=\""
        << Num(options.finger_damping_ns_per_m) << "\"/>\n";
    const double pad_mass = 0.03 * g.pad_length_m / g.finger_size_m.z();
    arm << indent << "    <geom name=\"" << name << "_pad\" type=\"box\" size=\"" << Num(half.x()) << " "
        << Num(half.y()) << " " << Num(g.pad_length_m / 2) << "\" pos=\"0 " << Num(s * half.y()) << " "
        << Num(-g.pad_length_m / 2) << "\" mass=\"" << Num(pad_mass)
        << "\" condim=\"4\" solmix=\"1000\" solref=\"" << Num(options.pad_timeconst_s)
        << " 1\" friction=\"" << Num(options.finger_friction) << " 0.02 0.0001\" rgba=\"0.2 0.2 0.2 1\"/>\n";
    if (bare_length > 1e-6) {
      arm << indent << "    <geom name=\"" << name << "_bare\" type=\"box\" size=\"" << Num(half.x()) << " "
          << Num(half.y()) << " " << Num(bare_length / 2) << "\" pos=\"0 " << Num(s * half.y()) << " "
          << Num(-g.pad_length_m - bare_length / 2) << "\" mass=\"" << Num(0.03 - pad_mass)
          << "\" rgba=\"0.3 0.3 0.3 1\"/>\n";
    }
    arm << indent << "  </body>\n";
  }
  arm << indent << "</body>\n";
  for (int i = robot::kNumJoints; i >= 0; --i) {
    indent.resize(indent.size() - 2);
    arm << indent << "</body>\n";
  }

  x << "<mujoco model=\"teachsim_worksite\">\n"
    << "  <compiler angle=\"radian\" inertiafromgeom=\"true\"/>\n"
    << "  <option timestep=\"" << Num(options.timestep_s)
    << "\" gravity=\"0 0 -9.81\" integrator=\"Euler\" cone=\"elliptic\" impratio=\"5\" noslip_iterations=\""
    << options.noslip_iterations << "\"/>\n"
    << "  <size njmax=\"1000\" nconmax=\"400\"/>\n"
    << "  <default>\n    <geom " << solref << " " << solimp << " margin=\"0\"/>\n  </default>\n"
    << "  <asset>\n"
    << assets.str() << "  </asset>\n"
    << "  <worldbody>\n"
    << world.str() << arm.str() << "  </worldbody>\n"
    << "  <contact>\n    <exclude body1=\"finger_left\" body2=\"finger_right\"/>\n  </contact>\n"
    << "  <actuator>\n";
  for (const robot::DhJoint& j : model.joints) {
    x << "    <position name=\"servo_" << j.name << "\" joint=\"" << j.name << "\" kp=\""
      << Num(options.joint_kp_nm_per_rad) << "\"/>\n";
  }
  for (const char* name : {"finger_left", "finger_right"}) {
    x << "    <position name=\"servo_" << name << "\" joint=\"" << name << "\" kp=\""
      << Num(options.finger_kp_n_per_m) << "\" forcelimited=\"true\" forcerange=\""
      << Num(-options.finger_force_limit_n) << " " << Num(options.finger_force_limit_n) << "\"/>\n";
  }
  x << "  </actuator>\n"
    << "  <sensor>\n    <force name=\"wrist_force\" site=\"wrist\"/>\n"
    << "    <torque name=\"wrist_torque\" site=\"wrist\"/>\n  </sensor>\n"
    << "</mujoco>\n";
  return x.str();
}

Result<std::unique_ptr<MujocoWorld>> MujocoWorld::Create(const scene::Scene& scene,
                                                         const robot::RobotModel& model,
                                                         const MujocoWorldOptions& options,
                                                         const robot::Joints* start) {
  auto mjcf = BuildMjcf(scene, model, options);
  if (!mjcf.ok()) return mjcf.status();
  std::unique_ptr<MujocoWorld> w(new MujocoWorld());
  w->options_ = options;
  w->mjcf_ = std::move(mjcf).value();
  w->mj_ = std::make_unique<MjHandles>();
  MjHandles& h = *w->mj_;
  h.flange_T_tool = model.flange_T_tool;

  auto vfs = std::make_unique<mjVFS>();  // ~2 MB: not on the stack
  mj_defaultVFS(vfs.get());
  const char* file = "worksite.xml";
  if (mj_makeEmptyFileVFS(vfs.get(), file, static_cast<int>(w->mjcf_.size())) != 0) {
    return Status::Internal("MuJoCo VFS: cannot make the model file");
  }
  const int index = mj_findFileVFS(vfs.get(), file);
  std::memcpy(vfs->filedata[index], w->mjcf_.data(), w->mjcf_.size());
  char error[1000] = "";
  h.model = mj_loadXML(file, vfs.get(), error, sizeof error);
  mj_deleteVFS(vfs.get());
  if (!h.model) return Status::Internal(std::string("MuJoCo rejected the generated MJCF: ") + error);
  h.data = mj_makeData(h.model);

  for (int i = 0; i < robot::kNumJoints; ++i) {
    const std::string& name = model.joints[static_cast<std::size_t>(i)].name;
    const int id = mj_name2id(h.model, mjOBJ_JOINT, name.c_str());
    h.joint_qpos[i] = h.model->jnt_qposadr[id];
    h.joint_dof[i] = h.model->jnt_dofadr[id];
    h.joint_actuator[i] = mj_name2id(h.model, mjOBJ_ACTUATOR, ("servo_" + name).c_str());
  }
  for (int s = 0; s < 2; ++s) {
    const char* name = s == 0 ? "finger_left" : "finger_right";
    const int id = mj_name2id(h.model, mjOBJ_JOINT, name);
    h.finger_qpos[s] = h.model->jnt_qposadr[id];
    h.finger_dof[s] = h.model->jnt_dofadr[id];
    h.finger_actuator[s] = mj_name2id(h.model, mjOBJ_ACTUATOR, (std::string("servo_") + name).c_str());
  }
  h.sensor_force_adr = h.model->sensor_adr[mj_name2id(h.model, mjOBJ_SENSOR, "wrist_force")];
  h.sensor_torque_adr = h.model->sensor_adr[mj_name2id(h.model, mjOBJ_SENSOR, "wrist_torque")];
  h.wrist_site = mj_name2id(h.model, mjOBJ_SITE, "wrist");
  h.tool_site = mj_name2id(h.model, mjOBJ_SITE, "tool");
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    h.object_bodies.emplace_back(scene.objects[i].name, mj_name2id(h.model, mjOBJ_BODY, BodyName(i).c_str()));
  }
  // The renderer's view of the world: the scene's objects, then the robot's bodies and their geoms.
  w->scene_objects_ = ObjectsFromScene(scene);
  const int first_robot_body = mj_name2id(h.model, mjOBJ_BODY, "robot_base");
  for (int b = first_robot_body; b >= 0 && b < h.model->nbody; ++b) {
    RobotBody rb;
    rb.body = b;
    const char* name = mj_id2name(h.model, mjOBJ_BODY, b);
    rb.object.name = std::string(std::strncmp(name, "robot_", 6) == 0 ? "" : "robot_") + name;
    rb.object.model = "robot";
    rb.object.material = Material::kFlat;
    rb.object.albedo = 0.18;  // dark grey arm and gripper
    for (int g = h.model->body_geomadr[b]; g >= 0 && g < h.model->body_geomadr[b] + h.model->body_geomnum[b]; ++g) {
      auto convex = GeomConvex(h.model->geom_type[g], h.model->geom_size + 3 * g);
      if (!convex) continue;
      rb.object.parts.push_back({convex, PoseOf(h.model->geom_pos + 3 * g, h.model->geom_quat + 4 * g)});
    }
    if (!rb.object.parts.empty()) w->robot_bodies_.push_back(std::move(rb));
  }

  const robot::Joints q0 = start ? *start : model.ready_rad;
  const double open = model.gripper.max_width_m / 2 * 0.9;
  for (int i = 0; i < robot::kNumJoints; ++i) {
    h.data->qpos[h.joint_qpos[i]] = q0[i];
    h.data->ctrl[h.joint_actuator[i]] = q0[i];
  }
  for (int s = 0; s < 2; ++s) {
    h.data->qpos[h.finger_qpos[s]] = open;
    h.data->ctrl[h.finger_actuator[s]] = open;
  }
  w->from_ = w->to_ = q0;
  w->interpolation_steps_ = std::max(1, static_cast<int>(std::lround(0.01 / options.timestep_s)));
  w->interpolation_step_ = w->interpolation_steps_;
  mj_forward(h.model, h.data);
  if (options.settle_s > 0) w->Advance(options.settle_s);
  return w;
}

MujocoWorld::~MujocoWorld() = default;

robot::Joints MujocoWorld::ReadJoints() {
  robot::Joints q;
  for (int i = 0; i < robot::kNumJoints; ++i) q[i] = mj_->data->qpos[mj_->joint_qpos[i]];
  return q;
}

robot::Wrench MujocoWorld::ReadWristWrench() {
  // The sensor reads what the flange exerts on the gripper, in the flange frame; the environment's
  // wrench on the tool is its opposite (plus the gripper's weight, which the controller tares).
  const mjtNum* s = mj_->data->sensordata;
  const Eigen::Vector3d f_flange =
      -Eigen::Vector3d(s[mj_->sensor_force_adr], s[mj_->sensor_force_adr + 1], s[mj_->sensor_force_adr + 2]);
  const Eigen::Vector3d t_flange = -Eigen::Vector3d(s[mj_->sensor_torque_adr], s[mj_->sensor_torque_adr + 1],
                                                    s[mj_->sensor_torque_adr + 2]);
  const geometry::Pose3& F_T_tool = mj_->flange_T_tool;
  robot::Wrench w;
  w.force_n = F_T_tool.rotation.conjugate() * f_flange;
  w.torque_nm = F_T_tool.rotation.conjugate() * (t_flange - F_T_tool.translation.cross(f_flange));
  return w;
}

robot::GripperState MujocoWorld::ReadGripper() {
  const mjData* d = mj_->data;
  robot::GripperState g;
  g.width_m = d->qpos[mj_->finger_qpos[0]] + d->qpos[mj_->finger_qpos[1]];
  g.moving = std::abs(d->qvel[mj_->finger_dof[0]]) + std::abs(d->qvel[mj_->finger_dof[1]]) >
             options_.gripper_moving_speed_mps;
  return g;
}

void MujocoWorld::CommandJoints(const robot::Joints& setpoint_rad) {
  for (int i = 0; i < robot::kNumJoints; ++i) from_[i] = mj_->data->ctrl[mj_->joint_actuator[i]];
  to_ = setpoint_rad;
  interpolation_step_ = 0;
}

void MujocoWorld::CommandGripper(double width_m) {
  const double half = std::max(0.0, width_m / 2);
  for (int s = 0; s < 2; ++s) mj_->data->ctrl[mj_->finger_actuator[s]] = half;
}

void MujocoWorld::Advance(double dt_s) {
  const long n = std::max(1L, std::lround(dt_s / options_.timestep_s));
  for (long k = 0; k < n; ++k) {
    if (interpolation_step_ < interpolation_steps_) {
      ++interpolation_step_;
      const double a = static_cast<double>(interpolation_step_) / interpolation_steps_;
      for (int i = 0; i < robot::kNumJoints; ++i) {
        mj_->data->ctrl[mj_->joint_actuator[i]] = from_[i] + (to_[i] - from_[i]) * a;
      }
    }
    mj_step(mj_->model, mj_->data);
    ++steps_;
  }
}

double MujocoWorld::time_s() const { return mj_->data->time; }

geometry::Pose3 MujocoWorld::ObjectPose(const std::string& name) const {
  for (const auto& [object, body] : mj_->object_bodies) {
    if (object != name) continue;
    const mjtNum* p = mj_->data->xpos + 3 * body;
    const mjtNum* q = mj_->data->xquat + 4 * body;
    return {Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized(), Eigen::Vector3d(p[0], p[1], p[2])};
  }
  TEACHSIM_CHECK_MSG(false, ("no object " + name).c_str());
  return {};
}

geometry::Pose3 MujocoWorld::TrueToolPose() const {
  const mjtNum* p = mj_->data->site_xpos + 3 * mj_->tool_site;
  const mjtNum* R = mj_->data->site_xmat + 9 * mj_->tool_site;
  Eigen::Matrix3d m;
  m << R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8];
  return {Eigen::Quaterniond(m).normalized(), Eigen::Vector3d(p[0], p[1], p[2])};
}

std::vector<RenderObject> MujocoWorld::RenderObjects() const {
  std::vector<RenderObject> out = scene_objects_;
  for (std::size_t i = 0; i < out.size() && i < mj_->object_bodies.size(); ++i) {
    const int body = mj_->object_bodies[i].second;
    out[i].world_T_object = PoseOf(mj_->data->xpos + 3 * body, mj_->data->xquat + 4 * body);
  }
  for (const RobotBody& rb : robot_bodies_) {
    out.push_back(rb.object);
    out.back().world_T_object = PoseOf(mj_->data->xpos + 3 * rb.body, mj_->data->xquat + 4 * rb.body);
  }
  return out;
}

std::string MujocoWorld::DescribeContacts() const {
  std::string out;
  const mjModel* m = mj_->model;
  const mjData* d = mj_->data;
  auto body_name = [&](int geom) {
    const int body = m->geom_bodyid[geom];
    for (const auto& [object, id] : mj_->object_bodies) {
      if (id == body) return object;
    }
    const char* name = mj_id2name(m, mjOBJ_BODY, body);
    return std::string(name ? name : "?");
  };
  for (int c = 0; c < d->ncon; ++c) {
    const mjContact& con = d->contact[c];
    mjtNum f6[6];
    mj_contactForce(m, d, c, f6);
    char line[300];
    std::snprintf(line, sizeof line, "%s - %s: normal %.2f N, friction %.2f N, depth %.2f mm, normal (%.2f, %.2f, %.2f)\n",
                  body_name(con.geom1).c_str(), body_name(con.geom2).c_str(), f6[0], std::hypot(f6[1], f6[2]),
                  -con.dist * 1e3, con.frame[0], con.frame[1], con.frame[2]);
    out += line;
  }
  return out;
}

Eigen::Vector3d MujocoWorld::ContactForceOn(const std::string& name) const {
  int body = -1;
  for (const auto& [object, id] : mj_->object_bodies) {
    if (object == name) body = id;
  }
  if (body < 0) body = mj_name2id(mj_->model, mjOBJ_BODY, name.c_str());
  TEACHSIM_CHECK_MSG(body >= 0, ("no object " + name).c_str());
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  for (int c = 0; c < mj_->data->ncon; ++c) {
    const mjContact& con = mj_->data->contact[c];
    const int b1 = mj_->model->geom_bodyid[con.geom1], b2 = mj_->model->geom_bodyid[con.geom2];
    if (b1 != body && b2 != body) continue;
    mjtNum f6[6];
    mj_contactForce(mj_->model, mj_->data, c, f6);
    // Contact frame: rows of con.frame; the force acts on geom2 along +normal (from geom1 to geom2).
    Eigen::Vector3d f = Eigen::Vector3d::Zero();
    for (int r = 0; r < 3; ++r) {
      f += f6[r] * Eigen::Vector3d(con.frame[3 * r], con.frame[3 * r + 1], con.frame[3 * r + 2]);
    }
    total += b2 == body ? f : -f;
  }
  return total;
}

}  // namespace teachsim::worksite
