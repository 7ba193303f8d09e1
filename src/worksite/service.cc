#include "teachsim/worksite/service.h"

#include <algorithm>
#include <cmath>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <map>
#include <future>
#include <mutex>
#include <thread>
#include <variant>

#include "teachsim/net/event_loop.h"
#include "teachsim/robot/program.h"
#include "teachsim/vision/camera.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::worksite {

using json::Json;
using WallClock = std::chrono::steady_clock;

RenderOptions StreamRenderOptions() {
  RenderOptions o;
  o.supersample = 1;
  return o;
}

scene::CameraSpec ScaleCamera(const scene::CameraSpec& camera, double scale) {
  scene::CameraSpec c = camera;
  c.width = std::max(1, static_cast<int>(std::lround(camera.width * scale)));
  c.height = std::max(1, static_cast<int>(std::lround(camera.height * scale)));
  c.fx = camera.fx * scale;
  c.fy = camera.fy * scale;
  c.cx = (camera.cx + 0.5) * scale - 0.5;
  c.cy = (camera.cy + 0.5) * scale - 0.5;
  return c;
}

Status WorksiteServiceOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(server.Validate());
  if (model_error) TEACHSIM_RETURN_IF_ERROR(model_error->Validate());
  TEACHSIM_RETURN_IF_ERROR(world.Validate());
  TEACHSIM_RETURN_IF_ERROR(controller.Validate());
  TEACHSIM_RETURN_IF_ERROR(render.Validate());
  if (!(time_scale >= 0)) return Status::InvalidInput("worksite: time_scale must be >= 0");
  if (!(camera_period_s >= 0)) return Status::InvalidInput("worksite: camera_period_s must be >= 0");
  if (camera_threads < 1 || camera_threads > 16) return Status::InvalidInput("worksite: camera_threads must be in [1, 16]");
  if (!(stream_scale >= 0.1 && stream_scale <= 1)) return Status::InvalidInput("worksite: stream_scale must be in [0.1, 1]");
  if (!(recognition_period_s > 0)) return Status::InvalidInput("worksite: recognition_period_s must be > 0");
  if (!(robot_state_period_s > 0)) return Status::InvalidInput("worksite: robot_state_period_s must be > 0");
  if (!(max_program_time_s > 0)) return Status::InvalidInput("worksite: max_program_time_s must be > 0");
  if (!(rest_speed_radps > 0)) return Status::InvalidInput("worksite: rest_speed_radps must be > 0");
  return Status::Ok();
}

Json ModelsFromScene(const scene::Scene& scene) {
  Json models = Json::array();
  std::vector<std::string> seen;
  for (const scene::SceneObject& o : scene.objects) {
    if (o.fixed || o.shape_spec.kind != scene::ShapeSpec::Kind::kBox) continue;
    const std::string name = o.model.empty() ? o.name : o.model;
    if (std::find(seen.begin(), seen.end(), name) != seen.end()) continue;
    seen.push_back(name);
    models.push_back({{"name", name}, {"shape", scene::WriteShapeSpec(o.shape_spec)}});
  }
  return models;
}

namespace {

// Work for the world thread, queued by the loop thread.
struct SubmitProgram {
  std::string id;
  robot::Program program;
};
struct ResetWorld {};
struct LinkStop {
  double detected_sim_s = 0;  // the world's time when the watchdog reported the loss
};
using WorldCommand = std::variant<SubmitProgram, ResetWorld, LinkStop>;

// A frame for the camera thread to render.
struct RenderJob {
  std::vector<RenderObject> objects;
  double stamp_s = 0;
  std::uint64_t index = 0;  // frames are sent in this order; a late older one is dropped
};

Json PoseJson(const geometry::Pose3& pose) { return geometry::WritePose(pose); }

Json Vec3Json(const Eigen::Vector3d& v) { return Json::array({v.x(), v.y(), v.z()}); }

}  // namespace

struct WorksiteService::Impl : net::ServerHandler {
  const net::Clock* clock = nullptr;
  scene::Scene scene;        // the nominal scene (what the operator starts from)
  scene::Scene world_scene;  // the simulated truth
  MujocoWorldOptions world_options;
  robot::RobotModel model;
  WorksiteServiceOptions options;
  int camera_index = -1;
  std::optional<Renderer> renderer;

  net::EventLoop loop;
  std::unique_ptr<net::Server> server;
  std::unique_ptr<net::LoopThread> loop_thread;
  std::thread world_thread, recognize_thread;
  // World thread -> recognition thread.
  std::mutex recognize_mutex;
  std::condition_variable recognize_cv;
  std::optional<RenderJob> recognize_job;
  std::atomic<bool> recognizing{false};
  std::map<net::SessionId, std::uint64_t> last_frame_seq;  // loop thread: per session
  std::vector<std::thread> camera_threads;
  std::atomic<bool> quit{false};
  bool started = false;

  // Loop thread -> world thread.
  std::mutex command_mutex;
  std::deque<WorldCommand> commands;
  // World thread -> camera thread.
  std::mutex render_mutex;
  std::condition_variable render_cv;
  std::deque<RenderJob> render_jobs;
  std::atomic<int> rendering{0};  // jobs queued or being rendered
  std::uint64_t frames_queued = 0;  // world thread
  std::uint64_t last_frame_sent = 0;  // loop thread

  std::atomic<double> sim_time_s{0};
  std::atomic<bool> latched{false};
  std::atomic<bool> executing{false};

  mutable std::mutex stats_mutex;
  WorksiteStats stats;

  // Loop thread only.
  std::optional<net::SessionId> controller;  // the lease holder whose link the watchdog guards
  bool controller_lost = false;
  Json last_link_state = {{"state", "up"}, {"stopped", false}, {"reason", "no operator yet"}};
  std::optional<Json> last_robot_state, last_progress, last_report;

  // ---- the loop thread ----

  Json SceneMessage() const { return {{"scene", scene::SceneToJson(scene)}, {"models", ModelsFromScene(scene)}}; }

  void SendLinkState(Json fields) {
    last_link_state = std::move(fields);
    server->Broadcast(net::MessageType::kLinkState, last_link_state);
  }

  void OnOpen(net::Server& s, net::SessionId session) override {
    // Resynchronise the whole state at once (issue 8: within 1 s of a reconnect).
    (void)s.Send(session, net::MessageType::kWorksiteScene, SceneMessage());
    (void)s.Send(session, net::MessageType::kLinkState, last_link_state);
    if (last_robot_state) (void)s.Send(session, net::MessageType::kRobotState, *last_robot_state);
    // The last execution's progress and report describe the state; marked as replays so that a
    // receiver that has seen them does not take them for new events (docs/protocol.md).
    auto replay = [](Json fields) {
      fields["replay"] = true;
      return fields;
    };
    if (last_progress) (void)s.Send(session, net::MessageType::kExecutionProgress, replay(*last_progress));
    if (last_report) (void)s.Send(session, net::MessageType::kReport, replay(*last_report));
  }

  void Refuse(net::Server& s, net::SessionId session, const net::Message& m, const std::string& code,
              const std::string& text) {
    (void)s.Send(session, net::MessageType::kError, {{"code", code}, {"message", text}, {"in_reply_to", m.seq}});
  }

  void Queue(WorldCommand command) {
    std::lock_guard lock(command_mutex);
    commands.push_back(std::move(command));
  }

  void OnMessage(net::Server& s, net::SessionId session, const net::Message& m) override {
    switch (m.type) {
      case net::MessageType::kProgramSubmit: {
        if (latched) {
          Refuse(s, session, m, "stopped",
                 "program_submit: the robot is stopped and latched after a link loss; send resume first");
          return;
        }
        if (executing) {
          Refuse(s, session, m, "busy", "program_submit: a program is running");
          return;
        }
        const std::string id = m.body.at("program_id").get<std::string>();
        // Only verified programs cross the link: the program reader's checks, then the
        // controller's safety checks before any motion.
        auto program = robot::ParseProgram(m.body.at("program"), "program_submit.program");
        if (!program.ok()) {
          Refuse(s, session, m, "invalid_program", program.status().message());
          return;
        }
        executing = true;
        Queue(SubmitProgram{id, std::move(program).value()});
        return;
      }
      case net::MessageType::kResetWorld:
        Queue(ResetWorld{});
        return;
      case net::MessageType::kHello:  // the server has checked the protocol; nothing to answer
        return;
      case net::MessageType::kResume:
        if (latched) {
          latched = false;
          SendLinkState({{"state", controller_lost ? "lost" : "up"}, {"stopped", false},
                         {"reason", "resumed by the operator"}});
        }
        return;
      default:
        Refuse(s, session, m, "unexpected",
               std::string(net::TypeName(m.type)) + ": not a message the work site takes");
        return;
    }
  }

  void OnLeaseChanged(net::Server& s, std::optional<net::SessionId> holder) override {
    if (holder) {
      const bool was_lost = controller_lost;
      controller = holder;
      controller_lost = false;
      if (was_lost || latched) {
        SendLinkState({{"state", "up"}, {"stopped", latched.load()},
                       {"reason", latched ? "operator reconnected; stopped until resume" : "operator reconnected"}});
      }
      return;
    }
    // Released explicitly by a session that is still there and speaking: it no longer controls.
    if (controller) {
      auto info = s.Info(*controller);
      if (info && info->link == net::LinkState::kUp) controller.reset();
    }
  }

  void LinkLost(net::SessionId session, const net::LinkEvent& event) {
    if (!controller || *controller != session || controller_lost) return;
    controller_lost = true;
    const bool was_latched = latched.exchange(true);
    if (!was_latched) Queue(LinkStop{sim_time_s.load()});
    Json fields = {{"state", "lost"}, {"stopped", true},
                   {"reason", "operator link lost (" + event.reason + "): controlled stop, latched until resume"}};
    if (event.silent_s > 0) fields["silent_s"] = event.silent_s;
    SendLinkState(std::move(fields));
  }

  void OnLinkEvent(net::Server&, net::SessionId session, const net::LinkEvent& event) override {
    if (event.kind == net::LinkEvent::Kind::kLost) {
      LinkLost(session, event);
    } else if (controller && *controller == session && controller_lost) {
      controller_lost = false;
      SendLinkState({{"state", "up"}, {"stopped", latched.load()},
                     {"reason", latched ? "operator link restored; stopped until resume" : "operator link restored"}});
    }
  }

  void OnClose(net::Server&, net::SessionId session, const std::string& reason) override {
    LinkLost(session, net::LinkEvent{net::LinkEvent::Kind::kLost, 0, "disconnected: " + reason});
  }

  // Runs on the loop: posted by the other threads.
  void Post(std::function<void()> fn) {
    loop.Post([this, fn = std::move(fn)] {
      if (server && !quit) fn();
    });
  }

  // ---- the world thread ----

  struct Execution {
    std::string id;
    robot::Program program;
    std::unique_ptr<robot::TaskController> controller;
    double t_s = 0;        // controller time since the start
    double sim_t0_s = 0;   // world time at the start
    WallClock::time_point wall0;
    std::size_t last_command = static_cast<std::size_t>(-1);
  };

  void PostProgress(const std::string& id, std::size_t index, std::size_t count, const std::string& state,
                    const std::string& message) {
    Json fields = {{"program_id", id}, {"command_index", std::min(index, count)}, {"command_count", count},
                   {"state", state}};
    if (!message.empty()) fields["message"] = message;
    Post([this, fields] {
      last_progress = fields;
      server->Broadcast(net::MessageType::kExecutionProgress, fields);
    });
  }

  void PostReport(const std::string& id, bool ok, Json report) {
    Json fields = {{"program_id", id}, {"ok", ok}, {"report", std::move(report)}};
    Post([this, fields] {
      last_report = fields;
      server->Broadcast(net::MessageType::kReport, fields);
    });
    std::lock_guard lock(stats_mutex);
    ++stats.programs_finished;
    stats.last_report_program = id;
    stats.last_report_ok = ok;
  }

  ExecuteOptions ReportOptions() const {
    ExecuteOptions o;
    o.controller = options.controller;
    o.world = world_options;
    o.model_error = options.model_error;
    o.max_time_s = options.max_program_time_s;
    return o;
  }

  void Finish(Execution& e, MujocoWorld& world, const std::string& override_message = {}) {
    ExecuteResult result;
    result.report = e.controller->report();
    if (!result.report.finished) {
      result.report.success = false;
      result.report.message = override_message.empty()
                                  ? "the program did not finish within " + json::FormatNumber(options.max_program_time_s) + " s"
                                  : override_message;
    }
    result.success = result.report.success;
    result.stopped = result.report.stopped;
    result.message = result.report.message;
    result.block_friction = world_options.block_friction;
    if (world_scene.FindObject(e.program.workpiece) >= 0) {
      result.final_world_T_workpiece = world.ObjectPose(e.program.workpiece);
      result.has_intent = IntendedWorkpiecePose(e.program, &result.intended_world_T_workpiece);
      if (result.has_intent) {
        result.workpiece_position_error_m =
            geometry::TranslationDistance(result.final_world_T_workpiece, result.intended_world_T_workpiece);
        result.workpiece_angle_error_rad =
            geometry::RotationAngle(result.final_world_T_workpiece, result.intended_world_T_workpiece);
      }
    }
    result.simulated_s = world.time_s() - e.sim_t0_s;
    result.wall_s = std::chrono::duration<double>(WallClock::now() - e.wall0).count();
    result.physics_steps = world.steps();
    const std::size_t count = e.program.commands.size();
    const std::string state = result.success ? "done" : result.stopped ? "stopped" : "failed";
    PostProgress(e.id, result.success ? count : e.controller->current_command(), count, state, result.message);
    PostReport(e.id, result.success, ExecuteResultToJson(result, ReportOptions()));
    executing = false;
  }

  Json RobotState(MujocoWorld& world, double joint_speed) {
    const robot::Joints q = world.ReadJoints();
    const robot::Wrench w = world.ReadWristWrench();
    const robot::GripperState g = world.ReadGripper();
    Json joints = Json::array();
    for (int i = 0; i < 6; ++i) joints.push_back(q[i]);
    return {{"t_s", world.time_s()},
            {"joints_rad", joints},
            {"world_T_tool", PoseJson(world.TrueToolPose())},
            {"force_n", Vec3Json(w.force_n)},
            {"torque_nm", Vec3Json(w.torque_nm)},
            {"gripper_width_m", std::max(0.0, g.width_m)},
            {"moving", joint_speed > options.rest_speed_radps || g.moving},
            {"stopped", latched.load()}};
  }

  Result<std::unique_ptr<MujocoWorld>> MakeWorld() { return MujocoWorld::Create(world_scene, model, world_options); }

  void WorldLoop(std::unique_ptr<MujocoWorld> world) {
    const double cycle_s = options.controller.cycle_s;
    std::optional<Execution> exec;
    bool stop_pending = false;  // a link stop waits for the robot to come to rest
    double stop_detected_s = 0;
    robot::Joints q_prev = world->ReadJoints();
    WallClock::time_point wall_base = WallClock::now();
    double sim_base = world->time_s();
    double pace_scale = 1.0;
    WallClock::time_point next_state = wall_base, next_frame = wall_base, next_recognition = wall_base;
    while (!quit) {
      // Commands from the loop.
      std::deque<WorldCommand> todo;
      {
        std::lock_guard lock(command_mutex);
        todo.swap(commands);
      }
      for (WorldCommand& command : todo) {
        if (auto* submit = std::get_if<SubmitProgram>(&command)) {
          Execution e;
          e.id = submit->id;
          e.program = std::move(submit->program);
          e.controller = std::make_unique<robot::TaskController>(model, scene.robot->world_T_base, options.controller);
          e.sim_t0_s = world->time_s();
          e.wall0 = WallClock::now();
          {
            std::lock_guard lock(stats_mutex);
            ++stats.programs_started;
          }
          if (Status s = e.controller->Start(e.program, *world, 0.0); !s.ok()) {
            PostProgress(e.id, 0, e.program.commands.size(), "failed", s.message());
            Finish(e, *world, "refused: " + s.message());
            continue;
          }
          exec = std::move(e);
        } else if (std::holds_alternative<ResetWorld>(command)) {
          if (exec) {
            exec->controller->RequestStop();
            Finish(*exec, *world, "stopped: the world was reset");
            exec.reset();
          }
          auto fresh = MakeWorld();
          if (fresh.ok()) {
            world = std::move(fresh).value();
            q_prev = world->ReadJoints();
            wall_base = WallClock::now();
            sim_base = world->time_s();
          }
          Post([this] { server->Broadcast(net::MessageType::kWorksiteScene, SceneMessage()); });
        } else if (auto* stop = std::get_if<LinkStop>(&command)) {
          if (exec) exec->controller->RequestStop();
          stop_pending = true;
          stop_detected_s = stop->detected_sim_s;
          std::lock_guard lock(stats_mutex);
          stats.last_stop_during_execution = exec.has_value();
        }
      }
      // One controller cycle, then the physics for one period.
      if (exec) {
        const bool running = exec->controller->Cycle(*world, exec->t_s);
        const std::size_t current = exec->controller->current_command();
        const std::size_t count = exec->program.commands.size();
        const bool timed_out = running && exec->t_s > options.max_program_time_s;
        if (!running || timed_out) {
          Finish(*exec, *world);
          exec.reset();
        } else if (current != exec->last_command) {
          exec->last_command = current;
          const std::string type = exec->controller->report().commands[current].type;
          PostProgress(exec->id, current, count, "running", "commands[" + std::to_string(current) + "] " + type);
        }
      }
      world->Advance(cycle_s);
      if (exec) exec->t_s += cycle_s;
      const double now_s = world->time_s();
      sim_time_s = now_s;
      const robot::Joints q = world->ReadJoints();
      const double joint_speed = (q - q_prev).cwiseAbs().maxCoeff() / cycle_s;
      q_prev = q;
      if (stop_pending && joint_speed < options.rest_speed_radps &&
          (!exec || !exec->controller->running() || exec->controller->stopping())) {
        const double stop_s = std::max(0.0, now_s - stop_detected_s);
        stop_pending = false;
        {
          std::lock_guard lock(stats_mutex);
          stats.last_stop_s = stop_s;
        }
        char text[200];
        std::snprintf(text, sizeof text, "robot at rest %.3f s (simulated) after the link loss; latched until resume",
                      stop_s);
        Post([this, reason = std::string(text), stop_s] {
          Json fields = last_link_state;
          fields["stopped"] = latched.load();
          fields["reason"] = reason;
          SendLinkState(std::move(fields));
        });
      }
      const WallClock::time_point wall_now = WallClock::now();
      if (wall_now >= next_state) {
        next_state = wall_now + std::chrono::duration_cast<WallClock::duration>(
                                    std::chrono::duration<double>(options.robot_state_period_s));
        Post([this, fields = RobotState(*world, joint_speed)] {
          last_robot_state = fields;
          server->Broadcast(net::MessageType::kRobotState, fields);
        });
      }
      if (renderer && wall_now >= next_frame && rendering < options.camera_threads) {
        // On a fixed schedule (not "period after the last"), so the rate does not drift below it.
        next_frame += std::chrono::duration_cast<WallClock::duration>(std::chrono::duration<double>(options.camera_period_s));
        if (next_frame < wall_now) next_frame = wall_now;
        {
          std::lock_guard lock(render_mutex);
          render_jobs.push_back(RenderJob{world->RenderObjects(), now_s, ++frames_queued});
          ++rendering;
        }
        render_cv.notify_one();
      }
      if (options.recognize && wall_now >= next_recognition && !recognizing) {
        next_recognition = wall_now + std::chrono::duration_cast<WallClock::duration>(
                                          std::chrono::duration<double>(options.recognition_period_s));
        {
          std::lock_guard lock(recognize_mutex);
          recognize_job = RenderJob{world->RenderObjects(), now_s, 0};
          recognizing = true;
        }
        recognize_cv.notify_one();
      }
      {
        std::lock_guard lock(stats_mutex);
        stats.sim_time_s = now_s;
        stats.executing = exec.has_value();
        stats.latched = latched;
      }
      // Pacing: real time when idle, time_scale while a program runs (0: unpaced).
      const double scale = exec ? options.time_scale : 1.0;
      if (scale != pace_scale) {
        pace_scale = scale;
        wall_base = wall_now;
        sim_base = now_s;
      }
      if (scale > 0) {
        const auto target = wall_base + std::chrono::duration_cast<WallClock::duration>(
                                            std::chrono::duration<double>((now_s - sim_base) / scale));
        if (wall_now > target + std::chrono::milliseconds(200)) {
          // Fell behind (a loaded machine): carry on from here rather than rush to catch up.
          wall_base = wall_now;
          sim_base = now_s;
        } else {
          std::this_thread::sleep_until(target);
        }
      }
    }
  }

  // ---- the recognition thread ----

  void RecognizeLoop() {
    // The model-view index takes a while to build: here, not in Start().
    vision::ModelLibrary library;
    for (const scene::SceneObject& o : scene.objects) {
      if (o.fixed || o.shape_spec.kind != scene::ShapeSpec::Kind::kBox) continue;
      const std::string name = o.model.empty() ? o.name : o.model;
      bool seen = false;
      for (const vision::Model& m : library.models) seen = seen || m.name == name;
      if (!seen) library.models.push_back({name, o.shape_spec.box_size});
    }
    scene::Scene fixed_world = scene;
    std::erase_if(fixed_world.objects, [](const scene::SceneObject& o) { return !o.fixed; });
    auto fail = [&](const Status& s) {
      std::lock_guard lock(stats_mutex);
      stats.recognizer_error = s.message();
    };
    if (library.models.empty() || camera_index < 0) return fail(Status::InvalidInput("no models or no camera"));
    auto camera = vision::Camera::FromSpec(scene.cameras[static_cast<std::size_t>(camera_index)]);
    if (!camera.ok()) return fail(camera.status());
    auto full = Renderer::Create(*camera, RenderOptions{});
    if (!full.ok()) return fail(full.status());
    auto recognizer = vision::Recognizer::Create(library, vision::RecognizerOptions{}, options.recognizer_cache_dir);
    if (!recognizer.ok()) return fail(recognizer.status());
    std::uint64_t index = 0;
    for (;;) {
      RenderJob job;
      {
        std::unique_lock lock(recognize_mutex);
        recognize_cv.wait(lock, [&] { return quit.load() || recognize_job.has_value(); });
        if (quit) return;
        job = std::move(*recognize_job);
        recognize_job.reset();
      }
      const auto t0 = WallClock::now();
      RenderResult image = full->Render(job.objects, 1000000 + ++index);
      auto result = recognizer->Recognize(image.image, *camera, &fixed_world);
      const double ms = std::chrono::duration<double, std::milli>(WallClock::now() - t0).count();
      if (result.ok()) {
        Json objects = Json::array();
        for (const vision::Recognition& r : result->objects) {
          objects.push_back({{"model", r.model},
                             {"world_T_object", PoseJson(r.world_T_object)},
                             {"score", std::clamp(r.score, 0.0, 1.0)}});
        }
        const int cam = camera_index;
        Post([this, objects, cam] {
          // frame_seq: the camera_frame of this session most recently sent (the same state, at the
          // stream's scale).
          for (net::SessionId session : server->Sessions()) {
            (void)server->Send(session, net::MessageType::kRecognitions,
                               {{"frame_seq", last_frame_seq.count(session) ? last_frame_seq[session] : 0},
                                {"camera", cam},
                                {"objects", objects}});
          }
        });
      }
      {
        std::lock_guard lock(stats_mutex);
        if (result.ok()) ++stats.recognitions;
        else stats.recognizer_error = result.status().message();
        stats.last_recognition_ms = ms;
      }
      recognizing = false;
    }
  }

  // ---- the camera thread ----

  void CameraLoop() {
    for (;;) {
      RenderJob job;
      {
        std::unique_lock lock(render_mutex);
        render_cv.wait(lock, [&] { return quit.load() || !render_jobs.empty(); });
        if (quit) return;
        job = std::move(render_jobs.front());
        render_jobs.pop_front();
      }
      const auto t0 = WallClock::now();
      RenderResult image = renderer->Render(job.objects, job.index);
      const double ms = std::chrono::duration<double, std::milli>(WallClock::now() - t0).count();
      {
        std::lock_guard lock(stats_mutex);
        ++stats.frames_rendered;
        stats.last_render_ms = ms;
      }
      net::BinaryHeader header;
      header.type = net::MessageType::kCameraFrame;
      header.format = net::PixelFormat::kGray8;
      header.camera = static_cast<std::uint16_t>(camera_index);
      header.width = static_cast<std::uint32_t>(image.image.cols);
      header.height = static_cast<std::uint32_t>(image.image.rows);
      header.stamp_s = job.stamp_s;
      auto pixels = std::make_shared<std::vector<std::uint8_t>>();
      pixels->reserve(static_cast<std::size_t>(image.image.total()));
      for (int r = 0; r < image.image.rows; ++r) {
        const std::uint8_t* row = image.image.ptr<std::uint8_t>(r);
        pixels->insert(pixels->end(), row, row + image.image.cols);
      }
      Post([this, header, pixels, index = job.index] {
        if (index < last_frame_sent) return;  // a newer frame went out already
        last_frame_sent = index;
        server->BroadcastFrame(header, *pixels);
        for (net::SessionId session : server->Sessions()) {
          if (auto info = server->Info(session)) last_frame_seq[session] = info->stats.sent;
        }
      });
      --rendering;
    }
  }
};

WorksiteService::WorksiteService(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

WorksiteService::~WorksiteService() { Stop(); }

Result<std::unique_ptr<WorksiteService>> WorksiteService::Create(const net::Clock& clock, const scene::Scene& scene,
                                                                 const robot::RobotModel& model,
                                                                 WorksiteServiceOptions options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  if (!scene.robot) return Status::InvalidInput("worksite: the scene places no robot (its \"robot\" entry)");
  auto impl = std::make_unique<Impl>();
  impl->clock = &clock;
  impl->scene = scene;
  impl->world_scene = scene;
  impl->world_options = options.world;
  if (options.model_error) {
    PerturbedWorld perturbed = PerturbScene(scene, *options.model_error);
    impl->world_scene = std::move(perturbed.scene);
    impl->world_options.block_friction = perturbed.block_friction;
  }
  impl->model = model;
  if (options.camera_period_s > 0 && !scene.cameras.empty()) {
    impl->camera_index = options.camera.empty() ? 0 : scene.FindCamera(options.camera);
    if (impl->camera_index < 0) return Status::InvalidInput("worksite: the scene has no camera \"" + options.camera + "\"");
    auto camera = vision::Camera::FromSpec(
        ScaleCamera(scene.cameras[static_cast<std::size_t>(impl->camera_index)], options.stream_scale));
    if (!camera.ok()) return camera.status();
    auto renderer = Renderer::Create(*camera, options.render);
    if (!renderer.ok()) return renderer.status();
    impl->renderer.emplace(std::move(renderer).value());
  }
  impl->options = std::move(options);
  return std::unique_ptr<WorksiteService>(new WorksiteService(std::move(impl)));
}

Status WorksiteService::Start() {
  Impl& m = *impl_;
  if (m.started) return Status::Failed("worksite: already started");
  auto world = m.MakeWorld();
  if (!world.ok()) return world.status();
  m.server = std::make_unique<net::Server>(m.loop, *m.clock, m.options.server, m);
  if (Status s = m.server->Start(); !s.ok()) {
    m.server.reset();
    return s;
  }
  m.started = true;
  m.sim_time_s = (*world)->time_s();
  m.loop_thread = std::make_unique<net::LoopThread>(m.loop);
  m.world_thread = std::thread([&m, w = std::move(world).value()]() mutable { m.WorldLoop(std::move(w)); });
  if (m.options.recognize) m.recognize_thread = std::thread([&m] { m.RecognizeLoop(); });
  if (m.renderer) {
    for (int i = 0; i < m.options.camera_threads; ++i) m.camera_threads.emplace_back([&m] { m.CameraLoop(); });
  }
  return Status::Ok();
}

void WorksiteService::Stop() {
  Impl& m = *impl_;
  if (!m.started) return;
  m.started = false;
  m.quit = true;
  m.render_cv.notify_all();
  if (m.world_thread.joinable()) m.world_thread.join();
  m.recognize_cv.notify_all();
  if (m.recognize_thread.joinable()) m.recognize_thread.join();
  for (std::thread& t : m.camera_threads) t.join();
  m.camera_threads.clear();
  std::promise<void> stopped;
  m.loop.Post([&m, &stopped] {
    m.server->Stop();
    stopped.set_value();
  });
  stopped.get_future().wait_for(std::chrono::seconds(5));
  m.loop_thread.reset();
  m.server.reset();
}

std::uint16_t WorksiteService::port() const { return impl_->server ? impl_->server->port() : 0; }

WorksiteStats WorksiteService::stats() const {
  std::lock_guard lock(impl_->stats_mutex);
  WorksiteStats s = impl_->stats;
  s.latched = impl_->latched;
  return s;
}

}  // namespace teachsim::worksite
