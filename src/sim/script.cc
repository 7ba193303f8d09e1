#include "teachsim/sim/script.h"

#include <algorithm>
#include <chrono>
#include <map>

namespace teachsim::sim {

using json::Json;
using json::Reader;

Json ScriptToJson(const DragScript& script) {
  Json capture = Json::array();
  for (const CaptureInterval& c : script.capture) {
    Json entry{{"object", c.object}, {"from_s", c.from_s}};
    if (c.to_s < 1e299) entry["to_s"] = c.to_s;
    capture.push_back(entry);
  }
  Json keyframes = Json::array();
  for (const Keyframe& k : script.keyframes) {
    Json entry{{"time_s", k.time_s}, {"position", {k.position.x(), k.position.y(), k.position.z()}}};
    if (k.orientation) {
      const Eigen::Quaterniond& q = *k.orientation;
      entry["quaternion_wxyz"] = {q.w(), q.x(), q.y(), q.z()};
    }
    keyframes.push_back(entry);
  }
  Json out{{"workpiece", script.workpiece}, {"capture", capture}, {"keyframes", keyframes}, {"settle_s", script.settle_s}};
  if (script.start_pose) out["start_pose"] = geometry::WritePose(*script.start_pose);
  return out;
}

Result<DragScript> ParseScript(const Json& document, const std::string& name) {
  return json::Decode<DragScript>(document, name, [](const Reader& r) {
    r.RejectUnknownKeys({"workpiece", "capture", "keyframes", "settle_s", "start_pose", "comment"});
    DragScript script;
    script.workpiece = r.At("workpiece").NonEmptyString();
    if (auto capture = r.Find("capture")) {
      for (std::size_t i = 0; i < capture->Size(); ++i) {
        Reader c = capture->Index(i);
        c.RejectUnknownKeys({"object", "from_s", "to_s"});
        CaptureInterval interval;
        interval.object = c.At("object").NonEmptyString();
        interval.from_s = c.Has("from_s") ? c.At("from_s").NumberAtLeast(0.0) : 0.0;
        if (c.Has("to_s")) interval.to_s = c.At("to_s").NumberAtLeast(interval.from_s);
        script.capture.push_back(interval);
      }
    }
    Reader keyframes = r.At("keyframes");
    if (keyframes.Size() == 0) keyframes.Fail("must have at least one keyframe");
    for (std::size_t i = 0; i < keyframes.Size(); ++i) {
      Reader k = keyframes.Index(i);
      k.RejectUnknownKeys({"time_s", "position", "quaternion_wxyz"});
      Keyframe frame;
      frame.time_s = k.At("time_s").NumberAtLeast(0.0);
      if (!script.keyframes.empty() && frame.time_s <= script.keyframes.back().time_s) {
        k.At("time_s").Fail("must increase (previous keyframe at " + json::FormatNumber(script.keyframes.back().time_s) + ")");
      }
      frame.position = k.At("position").Vector3();
      if (k.Has("quaternion_wxyz")) {
        Json pose{{"position", {0, 0, 0}}, {"quaternion_wxyz", k.At("quaternion_wxyz").raw()}};
        try {
          frame.orientation = geometry::ReadPose(Reader(pose)).rotation;
        } catch (const json::ParseError&) {
          k.At("quaternion_wxyz").Fail("must be a unit quaternion [w, x, y, z]");
        }
      }
      script.keyframes.push_back(frame);
    }
    if (r.Has("settle_s")) script.settle_s = r.At("settle_s").NumberInRange(0.0, 600.0);
    if (r.Has("start_pose")) script.start_pose = geometry::ReadPose(r.At("start_pose"));
    if (script.keyframes.back().time_s > 3600.0) r.At("keyframes").Fail("a script may last at most 3600 s");
    return script;
  });
}

Result<DragScript> LoadScript(const std::string& file) {
  auto document = json::ReadFile(file);
  if (!document.ok()) return document.status();
  return ParseScript(*document, file);
}

std::string DescribeContacts(const std::vector<PathContact>& contacts) {
  std::map<std::string, int> count;
  for (const PathContact& c : contacts) ++count[c.object];
  std::string out;
  for (const auto& [object, n] : count) out += (out.empty() ? "" : " ") + object + "(" + std::to_string(n) + ")";
  return out.empty() ? "none" : out;
}

namespace {

Keyframe DraggerAt(const DragScript& script, double t) {
  const auto& k = script.keyframes;
  if (t <= k.front().time_s) return k.front();
  if (t >= k.back().time_s) return k.back();
  auto next = std::upper_bound(k.begin(), k.end(), t, [](double time, const Keyframe& f) { return time < f.time_s; });
  const Keyframe& b = *next;
  const Keyframe& a = *(next - 1);
  const double u = (t - a.time_s) / (b.time_s - a.time_s);
  Keyframe out;
  out.time_s = t;
  out.position = a.position + u * (b.position - a.position);
  if (a.orientation && b.orientation) out.orientation = a.orientation->slerp(u, *b.orientation);
  else if (b.orientation) out.orientation = b.orientation;
  return out;
}

PathNode MakeNode(const SimWorld& world, const SimState& state, const std::vector<Contact>& contacts) {
  PathNode node;
  node.time_s = state.time_s;
  node.world_T_workpiece = state.world_T_workpiece;
  for (const Contact& c : contacts) {
    node.contacts.push_back({world.name(c.object), c.point, c.normal, c.distance, c.capture});
  }
  for (int object : state.engaged) node.captured.push_back(world.name(object));
  std::sort(node.captured.begin(), node.captured.end());
  return node;
}

}  // namespace

Result<WorkpiecePath> RunScript(const SimWorld& world, const DragScript& script, const DraggerOptions& dragger_options,
                                RunSummary* summary, const std::function<void(double, double)>& progress) {
  TEACHSIM_RETURN_IF_ERROR(dragger_options.Validate());
  for (const CaptureInterval& c : script.capture) {
    const int index = world.scene.FindObject(c.object);
    if (index < 0) return Status::NotFound("script: capture object '" + c.object + "' is not in the scene");
    if (c.object == script.workpiece) return Status::InvalidInput("script: the workpiece cannot capture itself");
  }
  SimWorld local;
  const SimWorld* w = &world;
  if (script.start_pose) {
    // The workpiece starts elsewhere: a world with the object moved (obstacle parts rebuilt).
    const int index = world.scene.FindObject(script.workpiece);
    if (index < 0) return Status::NotFound("no object named '" + script.workpiece + "' in the scene");
    scene::Scene moved = world.scene;
    moved.objects[static_cast<std::size_t>(index)].world_T_object = *script.start_pose;
    auto built = SimWorld::Build(std::move(moved), world.options);
    if (!built.ok()) return built.status();
    local = std::move(built).value();
    w = &local;
  }
  auto started = StartDrag(*w, script.workpiece);
  if (!started.ok()) return started.status();
  SimState state = std::move(started).value();

  const scene::SceneObject& wp = w->scene.objects[static_cast<std::size_t>(state.workpiece)];
  const geometry::Aabb local_box = wp.shape.WorldBounds(geometry::Pose3::Identity());
  Dragger dragger(state.world_T_workpiece, local_box.Size() * 0.5 + Eigen::Vector3d::Constant(0.01), dragger_options);

  WorkpiecePath path;
  path.workpiece = script.workpiece;
  path.step_s = w->options.step_s;
  for (const CaptureInterval& c : script.capture) {
    if (std::find(path.capture_objects.begin(), path.capture_objects.end(), c.object) == path.capture_objects.end()) {
      path.capture_objects.push_back(c.object);
    }
  }
  path.nodes.push_back(MakeNode(*w, state, CurrentContacts(*w, state)));

  const auto wall_start = std::chrono::steady_clock::now();
  const double end_keyframes = script.keyframes.back().time_s;
  const double end_time = end_keyframes + script.settle_s;
  int quiet_steps = 0;
  while (state.time_s < end_time - 1e-9) {
    // Capture objects in force at this time.
    state.capture.clear();
    for (const CaptureInterval& c : script.capture) {
      if (state.time_s + 1e-9 >= c.from_s && state.time_s < c.to_s) {
        const int index = w->scene.FindObject(c.object);
        if (std::find(state.capture.begin(), state.capture.end(), index) == state.capture.end()) {
          state.capture.push_back(index);
        }
      }
    }
    std::erase_if(state.engaged, [&](int object) {
      return std::find(state.capture.begin(), state.capture.end(), object) == state.capture.end();
    });
    const Keyframe target = DraggerAt(script, state.time_s);
    geometry::Pose3 dragger_pose(target.orientation.value_or(state.world_T_workpiece.rotation), target.position);
    dragger.SetPose(dragger_pose, target.orientation.has_value());
    const auto step_start = std::chrono::steady_clock::now();
    StepResult step = Step(*w, state, dragger.Force(state.world_T_workpiece));
    if (summary != nullptr) {
      summary->step_us.push_back(
          std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - step_start).count());
    }
    path.nodes.push_back(MakeNode(*w, state, CurrentContacts(*w, state)));
    if (progress) progress(state.time_s, end_time);
    // Settled: after the last keyframe, five quiet steps (under 0.1 mm/s and 0.01 rad/s of motion).
    const double moved = step.fraction * (step.velocity.linear.norm() + step.velocity.angular.norm() * 0.02);
    if (state.time_s >= end_keyframes && moved < 1e-4) {
      if (++quiet_steps >= 5) break;
    } else {
      quiet_steps = 0;
    }
  }
  if (summary != nullptr) {
    summary->steps = state.stats.steps;
    summary->simulated_s = state.time_s;
    summary->wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    summary->min_distance_m = state.stats.min_distance_m;
    summary->queries_per_step =
        state.stats.steps > 0 ? static_cast<double>(state.stats.distance_queries) / static_cast<double>(state.stats.steps) : 0.0;
    summary->sticking_events = state.stats.sticking_events;
    summary->sticking_resolved = state.stats.sticking_resolved;
    summary->final_contacts = path.nodes.back().contacts;
    summary->final_pose = state.world_T_workpiece;
  }
  return path;
}

}  // namespace teachsim::sim
