#include "demo_pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <variant>

#include "commands.h"
#include "plan_report.h"
#include "teachsim/geometry/distance.h"
#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/sim/demos.h"
#include "teachsim/vision/evaluate.h"
#include "teachsim/worksite/mujoco_world.h"
#include "teachsim/worksite/render.h"

namespace teachsim::app {

namespace {

using Clock = std::chrono::steady_clock;
// Half the simulator's contact distance (paper §7.2: eps_c = 0.5 mm), as in scenes/puzzle.json.
constexpr double kRestingGap = 0.25e-3;
double Seconds(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The demonstrations and the scene objects they move.
struct DemoSpec {
  const char* name;
  const char* workpiece;
};
constexpr DemoSpec kDemos[] = {{"cornering", "cube"}, {"around-corner", "plate"}};

void Progress(const DemoOptions& options, int stage, const std::string& what, const std::string& detail, double s,
              bool ok) {
  if (!options.progress) return;
  std::fprintf(stderr, "[%d/%d] %-28s %s %.1f s%s%s\n", stage, kDemoStages, what.c_str(), ok ? "..." : "FAILED",
               s, detail.empty() ? "" : "  ", detail.c_str());
  std::fflush(stderr);
}

std::string Join(const std::filesystem::path& dir, const std::string& file) { return (dir / file).string(); }

Eigen::Vector3d BoxSize(const scene::SceneObject& object) {
  return object.shape_spec.kind == scene::ShapeSpec::Kind::kBox ? object.shape_spec.box_size : Eigen::Vector3d::Zero();
}

// Smallest distance between two placed shapes (0 when they overlap).
double ShapeDistance(const geometry::Shape& a, const geometry::Pose3& world_T_a, const geometry::Shape& b,
                     const geometry::Pose3& world_T_b) {
  double best = 1e300;
  for (const geometry::ShapePart& pa : a.parts()) {
    for (const geometry::ShapePart& pb : b.parts()) {
      const geometry::DistanceResult d =
          geometry::Distance(*pa.convex, world_T_a * pa.shape_T_part, *pb.convex, world_T_b * pb.shape_T_part);
      best = std::min(best, d.intersecting ? 0.0 : d.distance);
    }
  }
  return best;
}

// The operator site's placement of a block that rests on a support (the table or a fixed object's
// top, within 2 mm): its lowest point goes `gap_m` above the support, the scene file's resting gap
// between the simulator's barrier distance and contact distance (a block exactly on the table
// would touch it, and the simulator refuses a start in touch). Returns the lift, m (0: not resting).
double RestOnSupport(const scene::Scene& fixed_world, double gap_m, scene::SceneObject* block) {
  const geometry::Aabb b = block->shape.WorldBounds(block->world_T_object);
  double best_top = NAN;
  for (const scene::SceneObject& o : fixed_world.objects) {
    for (const geometry::ShapePart& part : o.shape.parts()) {
      const geometry::Aabb p = part.convex->WorldBounds(o.world_T_object * part.shape_T_part);
      const bool under = p.min.x() < b.max.x() && p.max.x() > b.min.x() && p.min.y() < b.max.y() && p.max.y() > b.min.y();
      if (under && std::abs(b.min.z() - p.max.z()) < 2e-3 && !(best_top >= p.max.z())) best_top = p.max.z();
    }
  }
  if (std::isnan(best_top)) return 0.0;
  const double lift = best_top + gap_m - b.min.z();
  block->world_T_object.translation.z() += lift;
  return lift;
}

// The operator site's frame for a recognized box (vision may return any of its symmetric
// equivalents): z as close to up as the box allows, then x nearest the world's x. The planner
// grasps along the block's own axes, so this keeps the gripper's yaw where the arm can turn it.
geometry::Pose3 CanonicalBoxPose(const Eigen::Vector3d& size_m, const geometry::Pose3& pose) {
  geometry::Pose3 best = pose;
  double best_score = -1e300;
  for (const Eigen::Quaterniond& s : vision::BoxSymmetries(size_m)) {
    const Eigen::Quaterniond q = (pose.rotation * s).normalized();
    const Eigen::Vector3d z = q * Eigen::Vector3d::UnitZ(), x = q * Eigen::Vector3d::UnitX();
    const double score = 10.0 * z.z() + x.x();
    if (score > best_score + 1e-12) best_score = score, best = geometry::Pose3(q, pose.translation);
  }
  return best;
}

// Whether the arm reaches a top-down grasp of a box at `world_T_object` (the planner's grasp: the
// fingers hold its top, jaws along its y) and the approach 50 mm above it.
bool GraspReachable(const robot::RobotModel& model, const scene::Scene& scene, const Eigen::Vector3d& size_m,
                    const geometry::Pose3& world_T_object) {
  if (!scene.robot) return true;
  const geometry::Pose3 object_T_tool(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())),
                                      Eigen::Vector3d(0, 0, size_m.z() / 2 - 0.012));
  const geometry::Pose3 base_T_world = scene.robot->world_T_base.Inverse();
  for (double lift : {0.0, 0.05}) {
    geometry::Pose3 world_T_tool = world_T_object * object_T_tool;
    world_T_tool.translation.z() += lift;
    if (!robot::NearestToolIk(model, base_T_world * world_T_tool, model.ready_rad).ok()) return false;
  }
  return true;
}

}  // namespace

Status DemoOptions::Validate() const {
  if (which != "cornering" && which != "around-corner" && which != "all") {
    return Status::InvalidInput("demo: unknown demonstration '" + which + "' (cornering, around-corner or all)");
  }
  auto non_negative = [](double v, const char* name) {
    return std::isfinite(v) && v >= 0 ? Status::Ok()
                                      : Status::InvalidInput(std::string("DemoOptions::") + name + " must be >= 0");
  };
  TEACHSIM_RETURN_IF_ERROR(non_negative(block_shift_m, "block_shift_m"));
  TEACHSIM_RETURN_IF_ERROR(non_negative(block_yaw_rad, "block_yaw_rad"));
  TEACHSIM_RETURN_IF_ERROR(non_negative(block_gap_m, "block_gap_m"));
  TEACHSIM_RETURN_IF_ERROR(non_negative(camera_shift_m, "camera_shift_m"));
  TEACHSIM_RETURN_IF_ERROR(non_negative(camera_angle_rad, "camera_angle_rad"));
  if (out_dir.empty()) return Status::InvalidInput("demo: --out must name a folder");
  return Status::Ok();
}

bool DemoResult::success() const {
  if (world.failed_stage != 0 || runs.empty()) return false;
  return std::all_of(runs.begin(), runs.end(), [](const DemoRun& r) { return r.success; });
}

double BoxRotationError(const Eigen::Vector3d& size_m, const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return vision::SymmetricRotationError(a, b, vision::BoxSymmetries(size_m));
}

scene::Scene PerturbWorld(const scene::Scene& scene, const DemoOptions& options, const robot::RobotModel* model) {
  scene::Scene world = scene;
  if (options.seed == 0) return world;
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  // The work area: the table's top, less a margin of the block's radius.
  geometry::Aabb table_bounds;
  bool have_table = false;
  for (const scene::SceneObject& o : scene.objects) {
    if (o.fixed && o.name == "table") {
      table_bounds = o.shape.WorldBounds(o.world_T_object);
      have_table = true;
    }
  }
  for (std::size_t i = 0; i < world.objects.size(); ++i) {
    scene::SceneObject& o = world.objects[i];
    if (o.fixed) continue;
    const geometry::Pose3 nominal = o.world_T_object;
    // Only blocks resting upright move (in x, y and yaw), so they still rest where they land.
    if ((nominal.rotation * Eigen::Vector3d::UnitZ()).z() < std::cos(1e-3)) continue;
    // A block the arm can grasp where the file puts it stays graspable where it lands.
    const Eigen::Vector3d size = BoxSize(o);
    const bool keep_reachable = model != nullptr && size.z() > 0 && GraspReachable(*model, scene, size, nominal);
    for (int attempt = 0; attempt < 200; ++attempt) {
      const double r = options.block_shift_m * std::sqrt(unit(rng)), heading = 2 * M_PI * unit(rng);
      const double yaw = options.block_yaw_rad * (2 * unit(rng) - 1);
      geometry::Pose3 candidate = nominal;
      candidate.translation += Eigen::Vector3d(r * std::cos(heading), r * std::sin(heading), 0);
      candidate.rotation = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * nominal.rotation).normalized();
      bool fits = true;
      if (have_table) {
        const geometry::Aabb b = o.shape.WorldBounds(candidate);
        fits = b.min.x() >= table_bounds.min.x() && b.max.x() <= table_bounds.max.x() &&
               b.min.y() >= table_bounds.min.y() && b.max.y() <= table_bounds.max.y();
      }
      for (std::size_t j = 0; fits && j < world.objects.size(); ++j) {
        if (j == i) continue;
        const scene::SceneObject& other = world.objects[j];
        // The block rests on the table: its distance to the table is its resting gap, not a clash.
        if (other.fixed && other.name == "table") continue;
        fits = ShapeDistance(o.shape, candidate, other.shape, other.world_T_object) >= options.block_gap_m;
      }
      if (fits && keep_reachable) fits = GraspReachable(*model, scene, size, candidate);
      if (fits) {
        o.world_T_object = candidate;
        break;
      }
    }
  }
  // The camera: its centre moved within a ball, its orientation turned about a random axis.
  for (scene::CameraSpec& camera : world.cameras) {
    Eigen::Vector3d shift;
    do {
      shift = Eigen::Vector3d(2 * unit(rng) - 1, 2 * unit(rng) - 1, 2 * unit(rng) - 1);
    } while (shift.norm() > 1.0);
    Eigen::Vector3d axis;
    do {
      axis = Eigen::Vector3d(2 * unit(rng) - 1, 2 * unit(rng) - 1, 2 * unit(rng) - 1);
    } while (axis.norm() > 1.0 || axis.norm() < 1e-3);
    const double angle = options.camera_angle_rad * unit(rng);
    camera.world_T_camera.translation += options.camera_shift_m * shift;
    camera.world_T_camera.rotation =
        (Eigen::AngleAxisd(angle, axis.normalized()) * camera.world_T_camera.rotation).normalized();
  }
  return world;
}

namespace {

// Stages 1 and 2: the work site's world and camera image; the recognizer; the operator's model.
Status BuildWorld(const DemoOptions& options, const robot::RobotModel& model, const std::filesystem::path& dir,
                  DemoWorld* w) {
  w->truth_scene = PerturbWorld(w->file_scene, options, &model);
  const int camera_index = w->truth_scene.FindCamera("main");
  if (camera_index < 0 && w->truth_scene.cameras.empty()) {
    return Status::InvalidInput(options.scene_path + ": cameras: the demo needs the work site's camera");
  }
  w->camera_spec = w->truth_scene.cameras[static_cast<std::size_t>(std::max(camera_index, 0))];
  auto camera = vision::Camera::FromSpec(w->camera_spec);
  if (!camera.ok()) return camera.status().WithPrefix(options.scene_path);

  // --- 1: the camera image of the settled MuJoCo world.
  auto t0 = Clock::now();
  auto world = worksite::MujocoWorld::Create(w->truth_scene, model, worksite::MujocoWorldOptions{});
  if (!world.ok()) return world.status().WithPrefix("the work site's world");
  for (const scene::SceneObject& o : w->truth_scene.objects) {
    if (o.fixed) continue;
    w->truth.push_back({o.name, o.model.empty() ? o.name : o.model, BoxSize(o), (*world)->ObjectPose(o.name), false});
  }
  auto renderer = worksite::Renderer::Create(*camera, worksite::RenderOptions{});
  if (!renderer.ok()) return renderer.status();
  // What the camera sees: the settled blocks, the frame, the table and the arm at its ready pose.
  const worksite::RenderResult rendered = renderer->Render((*world)->RenderObjects(), options.seed + 1);
  w->image = rendered.image;
  TEACHSIM_RETURN_IF_ERROR(worksite::WritePng(Join(dir, "camera.png"), w->image));
  TEACHSIM_RETURN_IF_ERROR(
      json::WriteJsonFile(Join(dir, "camera.truth.json"), worksite::TruthToJson(rendered, w->camera_spec, options.seed + 1)));
  TEACHSIM_RETURN_IF_ERROR(scene::SaveScene(w->truth_scene, Join(dir, "world.scene.json")));
  w->times.push_back({kDemoStageNames[0], Seconds(t0)});
  char detail[128];
  std::snprintf(detail, sizeof detail, "%dx%d, seed %llu", camera->width(), camera->height(),
                static_cast<unsigned long long>(options.seed));
  Progress(options, 1, kDemoStageNames[0], detail, w->times.back().wall_s, true);

  // --- 2: recognition. The recognizer sees only the image, the calibrated camera and the fixed world.
  t0 = Clock::now();
  scene::Scene fixed_world;
  for (const scene::SceneObject& o : w->file_scene.objects) {
    if (o.fixed) fixed_world.objects.push_back(o);
  }
  auto recognized = RecognizeBlocks(options.scene_path, w->image, *camera, fixed_world, options.cache_dir);
  if (!recognized.ok()) {
    w->times.push_back({kDemoStageNames[1], Seconds(t0)});
    w->failed_stage = 2;
    w->message = "the recognizer failed: " + recognized.status().message();
    Progress(options, 2, kDemoStageNames[1], w->message, w->times.back().wall_s, false);
    return Status::Ok();
  }
  w->recognitions = std::move(recognized->objects);
  for (DemoRecognition& r : w->recognitions) r.world_T_object = CanonicalBoxPose(r.box_size_m, r.world_T_object);
  w->recognizer_timing_ms = std::move(recognized->timing_ms);
  w->recognizer_from_cache = recognized->from_cache;

  // Names in the operator's model: the scene file's object of that model when this recognition is
  // the nearest of its model to where the file expects it (so the demonstrations find "cube" and
  // "plate"), else model_k.
  std::vector<bool> named(w->recognitions.size(), false);
  for (const scene::SceneObject& o : w->file_scene.objects) {
    if (o.fixed) continue;
    const std::string m = o.model.empty() ? o.name : o.model;
    int best = -1;
    double best_d = 1e300;
    for (std::size_t k = 0; k < w->recognitions.size(); ++k) {
      if (named[k] || w->recognitions[k].model != m) continue;
      const double d = (w->recognitions[k].world_T_object.translation - o.world_T_object.translation).norm();
      if (d < best_d) best_d = d, best = static_cast<int>(k);
    }
    if (best >= 0) {
      w->recognitions[static_cast<std::size_t>(best)].name = o.name;
      named[static_cast<std::size_t>(best)] = true;
    }
  }
  for (std::size_t k = 0, n = 0; k < w->recognitions.size(); ++k) {
    if (!named[k]) w->recognitions[k].name = w->recognitions[k].model + "_" + std::to_string(++n);
  }
  // Scored against the truth (the report's errors only: the model is built from the recognitions).
  for (DemoRecognition& r : w->recognitions) {
    double best_d = 0.05;
    for (DemoTruthObject& t : w->truth) {
      if (t.model != r.model) continue;
      const double d = (t.world_T_object.translation - r.world_T_object.translation).norm();
      if (d < best_d) {
        best_d = d;
        r.truth_name = t.name;
        r.position_error_m = d;
        r.rotation_error_rad = BoxRotationError(r.box_size_m, r.world_T_object.rotation, t.world_T_object.rotation);
      }
    }
    for (DemoTruthObject& t : w->truth) t.recognized = t.recognized || t.name == r.truth_name;
  }
  // The operator's model: the calibrated fixed world, the camera, the robot, the recognized blocks.
  w->operator_scene = fixed_world;
  w->operator_scene.cameras = {w->camera_spec};
  w->operator_scene.robot = w->file_scene.robot;
  for (DemoRecognition& r : w->recognitions) {
    scene::SceneObject block = scene::BoxObject(r.name, false, r.box_size_m, r.world_T_object);
    block.model = r.model;
    const double lift = RestOnSupport(fixed_world, kRestingGap, &block);
    if (lift != 0.0) {
      r.world_T_object = block.world_T_object;
      char note[96];
      std::snprintf(note, sizeof note, "operator site: rests %.2f mm above its support (%+.2f mm)", kRestingGap * 1e3,
                    lift * 1e3);
      r.adjustments.push_back(note);
    }
    w->operator_scene.objects.push_back(std::move(block));
  }
  TEACHSIM_RETURN_IF_ERROR(scene::SaveScene(w->operator_scene, Join(dir, "operator.scene.json")));
  w->times.push_back({kDemoStageNames[1], Seconds(t0)});
  int missed = 0;
  for (const DemoTruthObject& t : w->truth) missed += t.recognized ? 0 : 1;
  char rdetail[160];
  std::snprintf(rdetail, sizeof rdetail, "%zu blocks recognized, %d of %zu missed%s", w->recognitions.size(), missed,
                w->truth.size(), w->recognizer_from_cache ? " (index from the cache)" : "");
  Progress(options, 2, kDemoStageNames[1], rdetail, w->times.back().wall_s, true);
  return Status::Ok();
}

void Fail(const DemoOptions& options, DemoRun* run, int stage, const std::string& message, double s) {
  run->failed_stage = stage;
  run->message = message;
  if (stage > 2) run->times.push_back({kDemoStageNames[stage - 1], s});  // stages 1-2 are the world's
  Progress(options, stage, std::string(kDemoStageNames[stage - 1]) + " (" + run->name + ")", message, s, false);
}

// Stages 3 to 6 of one demonstration on the operator's model; the work site's world is the truth.
Status RunOne(const DemoOptions& options, const DemoSpec& spec, const DemoWorld& w, const robot::RobotModel& model,
              const std::filesystem::path& dir, DemoRun* run) {
  run->name = spec.name;
  run->workpiece = spec.workpiece;
  const int file_index = w.file_scene.FindObject(spec.workpiece);
  if (file_index < 0) {
    return Status::InvalidInput(options.scene_path + ": objects: the " + run->name + " demonstration needs '" +
                                spec.workpiece + "' (as in scenes/puzzle.json)");
  }
  const scene::SceneObject& file_object = w.file_scene.objects[static_cast<std::size_t>(file_index)];
  run->workpiece_model = file_object.model.empty() ? file_object.name : file_object.model;
  const std::string label = " (" + run->name + ")";

  // --- 3: the demonstration, on the operator's model.
  auto t0 = Clock::now();
  const int wp = w.operator_scene.FindObject(spec.workpiece);
  if (wp < 0) {
    std::string seen;
    for (const DemoRecognition& r : w.recognitions) seen += (seen.empty() ? "" : ", ") + r.model;
    Fail(options, run, 2,
         "no block of model '" + run->workpiece_model + "' (the workpiece '" + spec.workpiece +
             "') was recognized; recognized: " + (seen.empty() ? std::string("nothing") : seen),
         0.0);
    return Status::Ok();
  }
  const geometry::Pose3 start = w.operator_scene.objects[static_cast<std::size_t>(wp)].world_T_object;
  Result<sim::DragScript> script = Status::Internal("unset");
  if (run->name == "cornering") {
    // The operator drags the block from where vision put it into the corner (Figure 1).
    sim::CorneringVariation v;
    const Eigen::Vector3d x_axis = start.rotation * Eigen::Vector3d::UnitX();
    v.start_x_m = start.translation.x();
    v.start_y_m = start.translation.y();
    v.start_yaw_rad = std::atan2(x_axis.y(), x_axis.x());
    script = sim::CorneringScript(w.operator_scene, v);
    if (script.ok()) {
      script->start_pose = start;
      script->keyframes.front().position = start.translation;
    }
  } else {
    script = sim::AroundCornerScript(w.operator_scene);
  }
  if (!script.ok()) return script.status().WithPrefix(options.scene_path);
  run->script = *script;
  auto sim_world = sim::SimWorld::Build(w.operator_scene, {});
  if (!sim_world.ok()) {
    Fail(options, run, 3, "the operator's model is not a valid simulator world: " + sim_world.status().message(),
         Seconds(t0));
    return Status::Ok();
  }
  auto path = sim::RunScript(*sim_world, *script, {}, &run->sim_summary);
  if (!path.ok()) {
    Fail(options, run, 3, "the task simulator refused the demonstration: " + path.status().message(), Seconds(t0));
    return Status::Ok();
  }
  run->path = *path;
  run->path_file = run->name + ".path.json";
  TEACHSIM_RETURN_IF_ERROR(sim::SavePath(*path, Join(dir, run->path_file)));
  TEACHSIM_RETURN_IF_ERROR(json::WriteJsonFile(Join(dir, run->name + ".drags.json"), sim::ScriptToJson(*script)));
  if (run->sim_summary.sticking_events > 0) {
    Fail(options, run, 3,
         "the workpiece stuck " + std::to_string(run->sim_summary.sticking_events) + " times during the demonstration",
         Seconds(t0));
    return Status::Ok();
  }
  run->times.push_back({kDemoStageNames[2], Seconds(t0)});
  Progress(options, 3, kDemoStageNames[2] + label,
           std::to_string(path->nodes.size()) + " nodes, final contacts " +
               sim::DescribeContacts(run->sim_summary.final_contacts),
           run->times.back().wall_s, true);

  // --- 4: the program (paper §6).
  t0 = Clock::now();
  auto planned = plan::GenerateProgram(w.operator_scene, *path, {}, &model);
  if (!planned.ok()) {
    Fail(options, run, 4, "the program generator failed: " + planned.status().message(), Seconds(t0));
    return Status::Ok();
  }
  run->plan = std::move(*planned);
  run->program_file = run->name + ".program.json";
  TEACHSIM_RETURN_IF_ERROR(
      WritePlanOutputs(*run->plan, Join(dir, run->program_file), Join(dir, run->name + ".")));
  if (!run->plan->metrics.required_contacts_kept) {
    Fail(options, run, 4, "the deformed path lost a required contact", Seconds(t0));
    return Status::Ok();
  }
  run->times.push_back({kDemoStageNames[3], Seconds(t0)});
  char pdetail[160];
  std::snprintf(pdetail, sizeof pdetail, "%d knots, %d commands, path %.0f -> %.0f mm", run->plan->metrics.knots,
                run->plan->metrics.commands, run->plan->metrics.length_before_m * 1e3,
                run->plan->metrics.length_after_m * 1e3);
  Progress(options, 4, kDemoStageNames[3] + label, pdetail, run->times.back().wall_s, true);

  // --- 5: execution on the work site's world, the truth (the perturbed scene; the robot's
  // placement is calibrated and the same in both).
  t0 = Clock::now();
  auto progress = [&](const std::string& line) {
    if (options.progress) std::fprintf(stderr, "        %s\n", line.c_str());
  };
  auto executed = worksite::Execute(w.truth_scene, model, run->plan->program, run->execute_options, progress);
  if (!executed.ok()) {
    Fail(options, run, 5, "the work site refused the program: " + executed.status().message(), Seconds(t0));
    return Status::Ok();
  }
  run->execution = std::move(*executed);
  run->report_file = run->name + ".report.json";
  TEACHSIM_RETURN_IF_ERROR(json::WriteJsonFile(Join(dir, run->report_file),
                                               worksite::ExecuteResultToJson(*run->execution, run->execute_options)));
  const robot::ExecutionReport& report = run->execution->report;
  // The first command that did not end well decides the stage: one that was not reached failed
  // the execution; one reached with a contact unverified failed the verification.
  bool reached = report.finished;
  for (const robot::CommandReport& c : report.commands) {
    if (c.status == robot::CommandStatus::kReached && c.contacts_verified) continue;
    reached = c.status == robot::CommandStatus::kReached;
    break;
  }
  const double exec_s = Seconds(t0);
  if (!reached) {
    Fail(options, run, 5, run->execution->message, exec_s);
    return Status::Ok();
  }
  run->times.push_back({kDemoStageNames[4], exec_s});
  char edetail[160];
  std::snprintf(edetail, sizeof edetail, "%zu commands, %.1f s simulated, peak %.1f N", report.commands.size(),
                run->execution->simulated_s, report.peak_force_n);
  Progress(options, 5, kDemoStageNames[4] + label, edetail, exec_s, true);

  // --- 6: the monitor's verdicts on the contacts.
  t0 = Clock::now();
  int contacts = 0, verified = 0;
  for (const robot::CommandReport& c : report.commands) {
    for (const robot::ContactCheck& k : c.contacts) {
      ++contacts;
      verified += k.verified ? 1 : 0;
    }
  }
  if (!run->execution->success) {
    Fail(options, run, 6, run->execution->message, Seconds(t0));
    return Status::Ok();
  }
  run->success = true;
  run->times.push_back({kDemoStageNames[5], Seconds(t0)});
  char vdetail[160];
  std::snprintf(vdetail, sizeof vdetail, "%d of %d contacts verified; workpiece %.1f mm / %.1f deg from the intent",
                verified, contacts, run->execution->workpiece_position_error_m * 1e3,
                run->execution->workpiece_angle_error_rad * 180 / M_PI);
  Progress(options, 6, kDemoStageNames[5] + label, vdetail, run->times.back().wall_s, true);
  return Status::Ok();
}

}  // namespace

Result<DemoResult> RunDemoPipeline(const DemoOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  const auto t0 = Clock::now();
  DemoResult result;
  result.options = options;
  auto scene = scene::LoadScene(options.scene_path);
  if (!scene.ok()) return scene.status();
  if (!scene->robot) return Status::InvalidInput(options.scene_path + ": robot: missing (the demo executes on it)");
  auto model = robot::LoadRobotModel(DataPath("robots/" + scene->robot->model + ".json"));
  if (!model.ok()) return model.status();
  const std::filesystem::path dir(options.out_dir);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status::IoError(options.out_dir + ": cannot create the folder: " + ec.message());

  result.world.file_scene = std::move(*scene);
  TEACHSIM_RETURN_IF_ERROR(BuildWorld(options, *model, dir, &result.world));
  for (const DemoSpec& spec : kDemos) {
    if (options.which != "all" && options.which != spec.name) continue;
    DemoRun run;
    if (result.world.failed_stage != 0) {
      run.name = spec.name;
      run.workpiece = spec.workpiece;
      run.failed_stage = result.world.failed_stage;
      run.message = result.world.message;
    } else {
      TEACHSIM_RETURN_IF_ERROR(RunOne(options, spec, result.world, *model, dir, &run));
    }
    result.runs.push_back(std::move(run));
  }
  result.total_s = Seconds(t0);
  return result;
}

}  // namespace teachsim::app
