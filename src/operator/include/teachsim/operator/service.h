// The operator-site service (`teachsim operator`, issue 8 item 3; DESIGN.md "Processes"): serves
// the browser UI (static files and the WebSocket of docs/protocol.md, "Browser ↔ operator") and
// links to the work site with the shared token. It keeps the world model and edits it (add a
// recognized object, delete one), the workpiece selection and capture objects; turns dragger input
// into task-simulator steps on a thread of its own at a fixed wall-clock rate (paper §5) and
// streams the poses; records the demonstration stroke by stroke (undo removes the last); on
// `confirm` generates the program on a worker thread (paper §6); on `execute` sends it to the work
// site and relays progress and the report; saves and loads sessions.
//
// Threads: the service's own event loop runs the browser server, the work-site client and every
// piece of state; the simulator thread and the planner worker post their results to it.
// (Namespace `op`: `operator` is a C++ keyword.)
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "teachsim/base/status.h"
#include "teachsim/net/auth.h"
#include "teachsim/net/clock.h"
#include "teachsim/plan/planner.h"
#include "teachsim/scene/scene.h"
#include "teachsim/sim/dragger.h"
#include "teachsim/sim/simulator.h"

namespace teachsim::op {

struct OperatorOptions {
  std::string host = "127.0.0.1";  // the browser server: loopback unless told otherwise
  std::uint16_t http_port = 8080;  // 0: a free port (see OperatorService::port())
  std::string web_root;            // static files; empty: none
  std::string sessions_dir = "sessions";
  // The robot tables (robots/NAME.json) for the model view's whole arm: world_state.robot carries
  // the placed robot's kinematics when its table is found here. Empty: no arm is drawn.
  std::string robots_dir;
  // The work site: "HOST:PORT" or "ws://HOST:PORT/PATH"; empty: none (the model is
  // `initial_scene`, programs cannot be executed).
  std::string worksite;
  net::Token token;                       // for the work-site link
  std::optional<scene::Scene> initial_scene;  // the model before (or without) the work site's scene
  double heartbeat_period_s = 0.05;
  double link_timeout_s = 0.25;  // the work-site link: silence that stops the robot (issue 8)
  // The browser link: silence after which a page counts as lost (its drag ends). Longer than the
  // work site's: browsers throttle timers in background tabs to about 1 Hz, and a page's drag
  // moves only the model, never the robot. The session is closed after
  // max(5 s, 2 x this) of silence; a closed socket releases the lease at once.
  double browser_link_timeout_s = 2.0;
  double reconnect_period_s = 0.5;  // after the work-site link closed
  // The demonstration (paper §5): simulator steps per wall-clock second (each step is
  // sim.step_s of simulated time: the paper's 50 ms, run faster when the machine allows).
  double sim_rate_hz = 100;
  sim::SimOptions sim;
  sim::DraggerOptions dragger;
  double settle_s = 1.0;  // after a stroke ends, the workpiece settles for at most this long (simulated)
  plan::PlanOptions plan;
  std::size_t max_path_poses = 2000;  // world_state.paths lists are thinned to this many
  [[nodiscard]] Status Validate() const;
};

// What the service holds now, for tests (read on any thread; a copy).
struct OperatorSnapshot {
  std::uint64_t revision = 0;
  std::vector<std::string> objects;
  std::optional<std::string> workpiece;
  std::vector<std::string> capture;
  bool dragging = false;
  int strokes = 0;
  std::size_t path_nodes = 0;
  bool has_program = false;
  std::string busy;
  bool worksite_connected = false;
  bool worksite_stopped = false;
  std::optional<bool> last_report_ok;
  double sim_rate_hz = 0;
};

class OperatorService {
 public:
  [[nodiscard]] static Result<std::unique_ptr<OperatorService>> Create(const net::Clock& clock,
                                                                       OperatorOptions options);
  ~OperatorService();
  OperatorService(const OperatorService&) = delete;
  OperatorService& operator=(const OperatorService&) = delete;

  // Listens for browsers and connects to the work site (reconnecting until stopped).
  [[nodiscard]] Status Start();
  void Stop();  // idempotent
  std::uint16_t port() const;
  OperatorSnapshot snapshot() const;
  // Drops the work-site connection's TCP socket without a close frame, as a pulled cable would
  // (for tests and drills); the service reconnects by itself.
  void CutWorksiteLink();

  struct Impl;

 private:
  explicit OperatorService(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace teachsim::op
