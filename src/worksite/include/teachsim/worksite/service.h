// The work-site service (`teachsim worksite`, issue 8 item 2; DESIGN.md "Processes"): a MuJoCo
// world standing for reality (the scene perturbed by a model error), served over the
// token-authenticated link of docs/protocol.md. It streams camera frames (rendered from the
// world's current state, robot included), robot state and wrist forces, accepts verified robot
// programs from the lease holder, executes them in paced real time with execution_progress and
// the final report, and resets its world on request.
//
// The link watchdog (protocol.md, "Heartbeats and the link watchdog"): when the controlling
// session (the lease holder) falls silent for link_timeout_s or disconnects, the robot is brought
// to a controlled stop (TaskController::RequestStop: the setpoint decelerates to rest within
// 50 ms) and the stop is latched until that operator sends `resume`; link_state reports it, with
// the simulated time the robot took to come to rest.
//
// Threads: the service's own event loop (the server and every message), the world thread (the
// physics at 1 kHz and the controller at 100 Hz, paced against the wall clock), and the camera
// thread (renders frames from snapshots the world thread hands over). The world belongs to the
// world thread alone; the loop learns about it from messages posted to it.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "teachsim/base/status.h"
#include "teachsim/net/clock.h"
#include "teachsim/net/server.h"
#include "teachsim/robot/controller.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/worksite/execute.h"
#include "teachsim/worksite/mujoco_world.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {

// The renderer's options for the stream: one sample per pixel (2x2 anti-aliasing costs four times
// as much, and the stream must keep 5 Hz on a loaded two-core machine), the rest as RenderOptions.
RenderOptions StreamRenderOptions();

// The camera with its image scaled by `scale` (pixel centres at integer coordinates, as OpenCV:
// c' = (c + 0.5) s - 0.5; f' = f s; the distortion acts on normalized coordinates and stays).
scene::CameraSpec ScaleCamera(const scene::CameraSpec& camera, double scale);

struct WorksiteServiceOptions {
  net::ServerOptions server;              // address, token, heartbeat and link timeout
  std::optional<ModelError> model_error;  // none: the world is the scene itself
  MujocoWorldOptions world;
  robot::ControllerOptions controller = WorksiteControllerOptions();
  // Simulated seconds per wall-clock second while a program runs (1: real time, as a real robot
  // would; 0: as fast as the machine allows). Idle, the world always runs in real time.
  double time_scale = 1.0;
  double camera_period_s = 1.0 / 6;   // 6 Hz frames (wall clock; >= 5 Hz asked); 0: no camera stream
  std::string camera;                 // the scene camera to stream; empty: the first one
  RenderOptions render = StreamRenderOptions();
  int camera_threads = 2;             // frames rendered in parallel (each frame on one thread)
  // The stream's image size relative to the camera's (0.5: 320x240 for a 640x480 camera), so that
  // 5 Hz holds on a loaded two-core machine; the intrinsics scale with it (see ScaleCamera).
  double stream_scale = 0.5;
  // Recognition (paper §4; vision::Recognizer) on a thread of its own, continuously on full-size
  // images of the world's latest state, at most once per recognition_period_s; the models are the
  // scene's movable boxes (ModelsFromScene). Off: no recognitions are sent.
  bool recognize = true;
  double recognition_period_s = 1.0;
  std::string recognizer_cache_dir;  // the model-view index cache; empty: built at start, not kept
  double robot_state_period_s = 0.05;  // 20 Hz (wall clock)
  double max_program_time_s = 600;     // simulated; a program still running then has failed
  double rest_speed_radps = 0.01;      // the robot is at rest when no joint moves faster
  [[nodiscard]] Status Validate() const;
};

// What the service did, for tests and the status line.
struct WorksiteStats {
  bool latched = false;                // stopped after a link loss, until `resume`
  bool executing = false;
  double sim_time_s = 0;
  long programs_started = 0, programs_finished = 0;
  long frames_rendered = 0;
  long recognitions = 0;             // results sent
  double last_recognition_ms = 0;
  std::string recognizer_error;      // why recognition is off, if it failed to start
  double last_render_ms = 0;
  // The last link-loss stop: simulated seconds from the watchdog's event to the robot at rest
  // (joints slower than rest_speed_radps), and whether a program was running then.
  std::optional<double> last_stop_s;
  bool last_stop_during_execution = false;
  std::optional<std::string> last_report_program;
  bool last_report_ok = false;
};

class WorksiteService {
 public:
  // `scene` must place a robot; `model` is its table. The service runs its own event loop.
  [[nodiscard]] static Result<std::unique_ptr<WorksiteService>> Create(const net::Clock& clock,
                                                                       const scene::Scene& scene,
                                                                       const robot::RobotModel& model,
                                                                       WorksiteServiceOptions options);
  ~WorksiteService();
  WorksiteService(const WorksiteService&) = delete;
  WorksiteService& operator=(const WorksiteService&) = delete;

  // Listens and starts the threads. Errors name the address.
  [[nodiscard]] Status Start();
  // Stops the threads and closes every session. Idempotent.
  void Stop();
  std::uint16_t port() const;
  WorksiteStats stats() const;

  struct Impl;

 private:
  explicit WorksiteService(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The model library the work site announces (worksite_scene.models): every movable box-shaped
// object of the scene, named by its `model` field, else by its name.
json::Json ModelsFromScene(const scene::Scene& scene);

}  // namespace teachsim::worksite
