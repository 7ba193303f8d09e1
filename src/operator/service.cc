#include "teachsim/operator/service.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "teachsim/net/client.h"
#include "teachsim/net/event_loop.h"
#include "teachsim/net/server.h"
#include "teachsim/operator/session.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/sim/path.h"

namespace teachsim::op {

using json::Json;
using net::MessageType;
using WallClock = std::chrono::steady_clock;

Status OperatorOptions::Validate() const {
  if (host.empty()) return Status::InvalidInput("operator: host must not be empty");
  if (sessions_dir.empty()) return Status::InvalidInput("operator: sessions_dir must not be empty");
  if (!(heartbeat_period_s > 0)) return Status::InvalidInput("operator: heartbeat_period_s must be > 0");
  if (!(link_timeout_s > 0)) return Status::InvalidInput("operator: link_timeout_s must be > 0");
  if (!(browser_link_timeout_s > heartbeat_period_s && browser_link_timeout_s <= 60)) {
    return Status::InvalidInput("operator: browser_link_timeout_s must be in (heartbeat_period_s, 60], got " +
                                json::FormatNumber(browser_link_timeout_s));
  }
  if (!(reconnect_period_s > 0)) return Status::InvalidInput("operator: reconnect_period_s must be > 0");
  if (!(sim_rate_hz >= 60 && sim_rate_hz <= 10000)) {
    return Status::InvalidInput("operator: sim_rate_hz must be in [60, 10000], got " + json::FormatNumber(sim_rate_hz));
  }
  if (!(settle_s >= 0)) return Status::InvalidInput("operator: settle_s must be >= 0");
  if (max_path_poses < 2) return Status::InvalidInput("operator: max_path_poses must be >= 2");
  if (!worksite.empty()) {
    auto url = net::ParseWebSocketUrl(worksite);
    if (!url.ok()) return url.status();
  }
  TEACHSIM_RETURN_IF_ERROR(sim.Validate());
  TEACHSIM_RETURN_IF_ERROR(dragger.Validate());
  TEACHSIM_RETURN_IF_ERROR(plan.Validate());
  if (initial_scene) {
    auto checked = sim::SimWorld::Build(*initial_scene, sim);
    if (!checked.ok()) return checked.status();
  }
  return Status::Ok();
}

namespace {

constexpr const char* kHelp =
    "commands:\n"
    "  help                      this list\n"
    "  list                      model objects, workpiece, capture objects, recognitions\n"
    "  status                    link, lease, simulator, program, report\n"
    "  select NAME | select      choose the workpiece (a movable object) | none\n"
    "  capture NAME [on|off]     make NAME a capture object (toggles without on/off)\n"
    "  undo                      remove the last demonstration stroke\n"
    "  confirm                   generate the robot program from the demonstration\n"
    "  execute                   run the program on the work site\n"
    "  resume                    release the work site's latched stop\n"
    "  reset                     reset the work site's world and the model\n"
    "  add INDEX                 add recognition INDEX to the model\n"
    "  delete NAME               remove NAME from the model\n"
    "  save NAME | load NAME     save / load the session";

std::vector<std::string> Words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> words;
  for (std::string w; in >> w;) words.push_back(w);
  return words;
}

std::string Mm(const Eigen::Vector3d& p) {
  char text[96];
  std::snprintf(text, sizeof text, "(%.1f, %.1f, %.1f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return text;
}

double Seconds(WallClock::duration d) { return std::chrono::duration<double>(d).count(); }

// The node of a path at the workpiece's present state (as sim::RunScript records them).
sim::PathNode MakeNode(const sim::SimWorld& world, sim::SimState& state) {
  sim::PathNode node;
  node.time_s = state.time_s;
  node.world_T_workpiece = state.world_T_workpiece;
  for (const sim::Contact& c : sim::CurrentContacts(world, state)) {
    node.contacts.push_back({world.name(c.object), c.point, c.normal, c.distance, c.capture});
  }
  for (int object : state.engaged) node.captured.push_back(world.name(object));
  std::sort(node.captured.begin(), node.captured.end());
  return node;
}

// At most `max` poses, evenly thinned, the last one kept.
Json PoseList(const std::vector<sim::PathNode>& nodes, std::size_t max) {
  Json out = Json::array();
  if (nodes.empty()) return out;
  const std::size_t n = nodes.size();
  const double stride = n <= max ? 1.0 : static_cast<double>(n - 1) / static_cast<double>(max - 1);
  std::size_t last = static_cast<std::size_t>(-1);
  for (double x = 0; x < static_cast<double>(n) + 0.5 && out.size() < max; x += stride) {
    const std::size_t i = std::min(n - 1, static_cast<std::size_t>(x + 0.5));
    if (i == last) continue;
    out.push_back(geometry::WritePose(nodes[i].world_T_workpiece));
    last = i;
  }
  if (last != n - 1) out.back() = geometry::WritePose(nodes.back().world_T_workpiece);
  return out;
}

}  // namespace

// A demonstration stroke: from `begin` to `end` of one drag.
struct Stroke {
  geometry::Pose3 start;                // the workpiece where the stroke began
  std::vector<sim::PathNode> nodes;     // from the start pose on, one per simulator step
  std::vector<std::string> capture;     // capture objects during the stroke
};

// What the simulator thread works on during one stroke.
struct DragJob {
  sim::SimWorld world;
  sim::SimState state;
  std::unique_ptr<sim::Dragger> dragger;
  Eigen::Quaterniond begin_orientation;
  Stroke stroke;
};

struct DragInput {
  geometry::Pose3 world_T_dragger;
  std::uint64_t seq = 0;
  bool end = false;
};

struct OperatorService::Impl {
  const net::Clock* clock = nullptr;
  OperatorOptions options;
  net::EventLoop loop;
  std::unique_ptr<net::Server> server;
  std::unique_ptr<net::Client> client;
  std::unique_ptr<net::LoopThread> loop_thread;
  std::thread sim_thread, planner_thread, tick_thread;
  std::atomic<bool> quit{false};
  bool started = false;
  WallClock::time_point epoch = WallClock::now();

  // ---- the handlers ----
  struct BrowserSide : net::ServerHandler {
    Impl* m;
    void OnOpen(net::Server&, net::SessionId s) override { m->BrowserOpen(s); }
    void OnMessage(net::Server&, net::SessionId s, const net::Message& msg) override { m->BrowserMessage(s, msg); }
    void OnClose(net::Server&, net::SessionId s, const std::string&) override { m->BrowserGone(s); }
    void OnLinkEvent(net::Server&, net::SessionId s, const net::LinkEvent& e) override {
      if (e.kind == net::LinkEvent::Kind::kLost) m->BrowserGone(s);
    }
    void OnLeaseChanged(net::Server&, std::optional<net::SessionId>) override { m->Changed(); }
  } browser_side;
  struct SiteSide : net::ClientHandler {
    Impl* m;
    void OnOpen(net::Client&) override { m->SiteOpen(); }
    void OnMessage(net::Client&, const net::Message& msg) override { m->SiteMessage(msg); }
    void OnFrame(net::Client&, const net::BinaryFrame& f) override { m->SiteFrame(f); }
    void OnClose(net::Client&, const Status& reason) override { m->SiteClosed(reason); }
    void OnLinkEvent(net::Client&, const net::LinkEvent& e) override { m->SiteLink(e); }
  } site_side;

  // ---- state (loop thread) ----
  scene::Scene model;                    // the world model
  std::vector<std::string> recognized;   // objects added from recognitions
  std::optional<scene::Scene> site_scene;  // the work site's nominal scene
  Json models = Json::array();
  std::optional<std::string> workpiece;
  std::vector<std::string> capture;
  std::vector<Stroke> strokes;
  std::optional<sim::WorkpiecePath> initial_path, deformed, simplified;
  std::optional<robot::Program> program;
  std::string program_id;
  int program_counter = 0;
  std::optional<SessionReport> report;
  std::string busy;
  std::uint64_t revision = 1;
  // the drag
  bool dragging = false;
  net::SessionId drag_session = 0;
  std::string drag_object;
  // the work-site link
  bool site_connected = false, site_lost = false, site_stopped = false;
  std::string site_reason = "not connected";
  WallClock::time_point site_closed_at = WallClock::now();
  bool site_reconnect_due = false;
  bool reconnecting = false;
  Json last_recognitions;  // as received (frame_seq of the work site)
  Json last_progress;      // the last execution_progress (without "replay"), null before one
  std::optional<net::BinaryFrame> last_frame;
  std::map<net::SessionId, std::deque<std::pair<std::uint64_t, std::uint64_t>>> frame_seqs;  // site seq -> ours
  WallClock::time_point last_robot_state_relay{};
  double sim_rate_hz = 0;

  mutable std::mutex snapshot_mutex;
  OperatorSnapshot snap;

  // ---- the simulator thread's mailbox ----
  std::mutex drag_mutex;
  std::condition_variable drag_cv;
  std::unique_ptr<DragJob> job;
  DragInput input;

  // ======== state changes ========

  void UpdateSnapshot() {
    std::lock_guard lock(snapshot_mutex);
    snap.revision = revision;
    snap.objects.clear();
    for (const auto& o : model.objects) snap.objects.push_back(o.name);
    snap.workpiece = workpiece;
    snap.capture = capture;
    snap.dragging = dragging;
    snap.strokes = static_cast<int>(strokes.size());
    snap.path_nodes = initial_path ? initial_path->nodes.size() : 0;
    snap.has_program = program.has_value();
    snap.busy = busy;
    snap.worksite_connected = site_connected && !site_lost;
    snap.worksite_stopped = site_stopped;
    snap.last_report_ok = report ? std::optional<bool>(report->ok) : std::nullopt;
    snap.sim_rate_hz = sim_rate_hz;
  }

  // The placed robot's table from options.robots_dir (loaded once per model name), or null.
  mutable std::optional<robot::RobotModel> robot_table;
  mutable std::string robot_table_tried;
  const robot::RobotModel* RobotTable() const {
    if (!model.robot || options.robots_dir.empty()) return nullptr;
    if (robot_table_tried != model.robot->model) {
      robot_table_tried = model.robot->model;
      const std::string file = (std::filesystem::path(options.robots_dir) / (model.robot->model + ".json")).string();
      auto loaded = robot::LoadRobotModel(file);
      robot_table.reset();
      if (loaded.ok()) {
        robot_table = std::move(loaded).value();
      } else {
        std::fprintf(stderr, "operator: no robot table (no whole-arm view, grasps not checked against the arm): %s\n",
                     loaded.status().message().c_str());
      }
    }
    return robot_table ? &*robot_table : nullptr;
  }

  std::string ObjectOrigin(const std::string& name) const {
    return std::find(recognized.begin(), recognized.end(), name) != recognized.end() ? "recognized" : "scene";
  }

  std::optional<double> SiteRtt() const {
    if (!client || !site_connected) return std::nullopt;
    return client->stats().rtt_s;
  }

  Json LinkJson() const {
    const std::optional<double> rtt = SiteRtt();
    return {{"state", site_connected && !site_lost ? "up" : "lost"},
            {"stopped", site_stopped},
            {"reason", site_reason},
            {"rtt_s", rtt ? Json(*rtt) : Json(nullptr)}};
  }

  Json WorldState() const {
    Json objects = Json::array();
    for (const auto& o : model.objects) {
      objects.push_back({{"name", o.name},
                         {"fixed", o.fixed},
                         {"model", o.model},
                         {"shape", scene::WriteShapeSpec(o.shape_spec)},
                         {"world_T_object", geometry::WritePose(o.world_T_object)},
                         {"origin", ObjectOrigin(o.name)}});
    }
    Json cameras = Json::array();
    for (const auto& c : model.cameras) cameras.push_back(scene::WriteCamera(c));
    Json robot = nullptr;
    if (model.robot) {
      robot = {{"model", model.robot->model}, {"base", geometry::WritePose(model.robot->world_T_base)}};
      if (const robot::RobotModel* table = RobotTable()) robot["kinematics"] = robot::RobotModelToJson(*table);
    }
    std::vector<sim::PathNode> demo;
    if (initial_path) {
      demo = initial_path->nodes;
    } else {
      for (const Stroke& s : strokes) demo.insert(demo.end(), s.nodes.begin(), s.nodes.end());
    }
    Json paths = {{"initial", PoseList(demo, options.max_path_poses)},
                  {"deformed", deformed ? PoseList(deformed->nodes, options.max_path_poses) : Json::array()},
                  {"simplified", simplified ? PoseList(simplified->nodes, options.max_path_poses) : Json::array()}};
    Json program_json = nullptr;
    if (program) {
      program_json = {{"id", program_id},
                      {"command_count", program->commands.size()},
                      {"listing", robot::ProgramListing(*program)}};
    }
    Json report_json = nullptr;
    if (report) report_json = {{"program_id", report->program_id}, {"ok", report->ok}, {"summary", ReportSummary(*report)}};
    std::optional<net::SessionId> holder = server ? server->lease().holder() : std::nullopt;
    return {{"revision", revision},
            {"objects", objects},
            {"workpiece", workpiece ? Json(*workpiece) : Json(nullptr)},
            {"capture", capture},
            {"dragging", dragging},
            {"demonstrations", strokes.size()},
            {"models", models},
            {"cameras", cameras},
            {"robot", robot},
            {"link", LinkJson()},
            {"lease_holder", holder ? Json(*holder) : Json(nullptr)},
            {"busy", busy},
            {"paths", paths},
            {"program", program_json},
            {"report", report_json},
            {"sim_rate_hz", sim_rate_hz}};
  }

  static std::string ReportSummary(const SessionReport& r) {
    const Json& j = r.report;
    std::string text = r.ok ? "SUCCESS" : "FAILED";
    if (j.contains("message") && j["message"].is_string() && !j["message"].get<std::string>().empty()) {
      text += ": " + j["message"].get<std::string>();
    }
    if (j.contains("commands") && j["commands"].is_array()) {
      std::size_t reached = 0;
      for (const Json& c : j["commands"]) {
        if (c.is_object() && c.contains("status") && c["status"] == "reached") ++reached;
      }
      text += "; " + std::to_string(reached) + "/" + std::to_string(j["commands"].size()) + " commands reached";
    }
    if (j.contains("contacts_verified") && j["contacts_verified"].is_boolean()) {
      text += j["contacts_verified"].get<bool>() ? ", contacts verified" : ", contacts NOT verified";
    }
    if (j.contains("workpiece") && j["workpiece"].is_object() && j["workpiece"].contains("position_error_m")) {
      const Json& w = j["workpiece"];
      char buf[96];
      std::snprintf(buf, sizeof buf, "; workpiece %.1f mm / %.1f deg from the intent",
                    w["position_error_m"].get<double>() * 1e3,
                    w.contains("angle_error_deg") ? w["angle_error_deg"].get<double>() : 0.0);
      text += buf;
    }
    return text;
  }

  // Something in world_state changed: a new revision to every browser.
  void Changed() {
    ++revision;
    UpdateSnapshot();
    if (!server) return;
    Json state = WorldState();
    server->Broadcast(MessageType::kWorldState, state);
  }

  void Console(net::SessionId session, const std::string& text, bool ok, std::optional<std::uint64_t> in_reply_to) {
    Json fields = {{"text", text}, {"ok", ok}};
    if (in_reply_to) fields["in_reply_to"] = *in_reply_to;
    (void)server->Send(session, MessageType::kConsoleOutput, fields);
  }
  void ConsoleAll(const std::string& text, bool ok) {
    server->Broadcast(MessageType::kConsoleOutput, {{"text", text}, {"ok", ok}});
  }

  void Post(std::function<void()> fn) {
    loop.Post([this, fn = std::move(fn)] {
      if (!quit) fn();
    });
  }

  // ======== the model ========

  void ClearDemonstration() {
    strokes.clear();
    initial_path.reset();
    deformed.reset();
    simplified.reset();
    program.reset();
  }

  void SetModel(const scene::Scene& scene) {
    model = scene;
    recognized.clear();
    workpiece.reset();
    capture.clear();
    ClearDemonstration();
    report.reset();
  }

  scene::SceneObject* FindObject(const std::string& name) {
    const int i = model.FindObject(name);
    return i < 0 ? nullptr : &model.objects[static_cast<std::size_t>(i)];
  }

  // ======== console ========

  struct Reply {
    std::string text;
    bool ok = true;
  };

  static Reply Fail(std::string text) { return {std::move(text), false}; }

  Reply CmdList() const {
    std::string out = "objects:\n";
    for (const auto& o : model.objects) {
      out += "  " + o.name + (o.fixed ? "  fixed" : "  movable") + (o.model.empty() ? "" : "  model " + o.model) + "  at " +
             Mm(o.world_T_object.translation) + (ObjectOrigin(o.name) == "recognized" ? "  (recognized)" : "") + "\n";
    }
    out += "workpiece: " + (workpiece ? *workpiece : std::string("none")) + "\n";
    out += "capture:";
    for (const auto& c : capture) out += " " + c;
    out += capture.empty() ? " none\n" : "\n";
    out += "recognitions:";
    if (last_recognitions.is_object() && last_recognitions.contains("objects") && !last_recognitions["objects"].empty()) {
      out += "\n";
      std::size_t i = 0;
      for (const Json& r : last_recognitions["objects"]) {
        const geometry::Pose3 pose = geometry::ReadPose(json::Reader(r["world_T_object"]));
        char score[32];
        std::snprintf(score, sizeof score, "%.2f", r["score"].get<double>());
        out += "  [" + std::to_string(i++) + "] " + r["model"].get<std::string>() + "  score " + score + "  at " +
               Mm(pose.translation) + "\n";
      }
    } else {
      out += " none\n";
    }
    out.pop_back();
    return {out};
  }

  Reply CmdStatus() const {
    std::optional<net::SessionId> holder = server->lease().holder();
    const std::optional<double> rtt = SiteRtt();
    char text[512];
    std::snprintf(text, sizeof text,
                  "work site: %s%s (%s)%s\nlease: %s\nsimulator: %.0f steps/s%s\nbusy: %s\nprogram: %s\nreport: %s",
                  site_connected && !site_lost ? "up" : "lost", site_stopped ? ", robot stopped (latched)" : "",
                  site_reason.c_str(), rtt ? (", rtt " + json::FormatNumber(*rtt * 1e3) + " ms").c_str() : "",
                  holder ? ("session " + std::to_string(*holder)).c_str() : "free", sim_rate_hz,
                  dragging ? " (dragging)" : "", busy.empty() ? "no" : busy.c_str(),
                  program ? (program_id + ", " + std::to_string(program->commands.size()) + " commands").c_str() : "none",
                  report ? ReportSummary(*report).c_str() : "none");
    return {text};
  }

  Reply CmdSelect(const std::vector<std::string>& w) {
    if (w.size() == 1) {
      if (workpiece) ClearDemonstration();
      workpiece.reset();
      return {"no workpiece"};
    }
    if (w.size() != 2) return Fail("usage: select NAME");
    const scene::SceneObject* o = FindObject(w[1]);
    if (o == nullptr) return Fail("select: no object \"" + w[1] + "\" in the model (see list)");
    if (o->fixed) return Fail("select: \"" + w[1] + "\" is fixed; choose a movable object");
    if (workpiece && *workpiece == w[1]) return {"workpiece " + w[1] + " (already selected)"};
    ClearDemonstration();
    workpiece = w[1];
    std::erase(capture, w[1]);
    return {"workpiece " + w[1]};
  }

  Reply CmdCapture(const std::vector<std::string>& w) {
    if (w.size() < 2 || w.size() > 3 || (w.size() == 3 && w[2] != "on" && w[2] != "off")) {
      return Fail("usage: capture NAME [on|off]");
    }
    if (FindObject(w[1]) == nullptr) return Fail("capture: no object \"" + w[1] + "\" in the model");
    if (workpiece && *workpiece == w[1]) return Fail("capture: \"" + w[1] + "\" is the workpiece");
    const bool is = std::find(capture.begin(), capture.end(), w[1]) != capture.end();
    const bool want = w.size() == 3 ? w[2] == "on" : !is;
    if (want && !is) capture.push_back(w[1]);
    if (!want) std::erase(capture, w[1]);
    return {"capture " + w[1] + (want ? " on" : " off")};
  }

  Reply CmdUndo() {
    if (strokes.empty()) return Fail("undo: nothing demonstrated");
    const Stroke last = strokes.back();
    strokes.pop_back();
    if (scene::SceneObject* o = FindObject(workpiece.value_or(""))) o->world_T_object = last.start;
    initial_path.reset();
    deformed.reset();
    simplified.reset();
    program.reset();
    return {"undone: the workpiece is back at " + Mm(last.start.translation) + "; " + std::to_string(strokes.size()) +
            " stroke(s) left"};
  }

  sim::WorkpiecePath DemonstratedPath() const {
    sim::WorkpiecePath path;
    path.workpiece = *workpiece;
    path.step_s = options.sim.step_s;
    double t0 = 0;
    for (const Stroke& s : strokes) {
      for (const auto& c : s.capture) {
        if (std::find(path.capture_objects.begin(), path.capture_objects.end(), c) == path.capture_objects.end()) {
          path.capture_objects.push_back(c);
        }
      }
      const bool first = path.nodes.empty();
      for (std::size_t i = first ? 0 : 1; i < s.nodes.size(); ++i) {
        sim::PathNode node = s.nodes[i];
        node.time_s += t0;
        path.nodes.push_back(std::move(node));
      }
      if (!path.nodes.empty()) t0 = path.nodes.back().time_s;
    }
    return path;
  }

  Reply CmdConfirm() {
    if (!busy.empty()) return Fail("confirm: busy (" + busy + ")");
    if (!workpiece || strokes.empty()) return Fail("confirm: nothing demonstrated (select a block and drag it first)");
    if (dragging) return Fail("confirm: a drag is in progress");
    sim::WorkpiecePath path = DemonstratedPath();
    if (path.nodes.size() < 2) return Fail("confirm: the demonstration has no motion");
    scene::Scene start = model;
    start.objects[static_cast<std::size_t>(start.FindObject(*workpiece))].world_T_object = strokes.front().start;
    busy = "planning";
    initial_path = path;
    deformed.reset();
    simplified.reset();
    program.reset();
    if (planner_thread.joinable()) planner_thread.join();
    const std::size_t nodes = path.nodes.size();
    // With the robot's table the planner chooses a grasp the arm can follow and keeps the gripper clear of
    // the scene; the thread gets its own copy (the table may be reloaded while it plans).
    std::optional<robot::RobotModel> arm;
    if (const robot::RobotModel* table = RobotTable()) arm = *table;
    planner_thread = std::thread([this, start = std::move(start), path = std::move(path), arm = std::move(arm)] {
      auto t0 = WallClock::now();
      auto planned = std::make_shared<Result<plan::PlanResult>>(
          plan::GenerateProgram(start, path, options.plan, arm ? &*arm : nullptr));
      const double ms = Seconds(WallClock::now() - t0) * 1e3;
      Post([this, planned, ms] { Planned(*planned, ms); });
    });
    return {"generating the program from " + std::to_string(nodes) + " path nodes (" + std::to_string(strokes.size()) +
            " stroke(s)) ..."};
  }

  void Planned(const Result<plan::PlanResult>& planned, double ms) {
    busy.clear();
    if (!planned.ok()) {
      ConsoleAll("program generation failed: " + planned.status().message(), false);
      Changed();
      return;
    }
    deformed = planned->deformed;
    simplified = planned->simplified;
    program = planned->program;
    program_id = "p" + std::to_string(++program_counter);
    const plan::PlanMetrics& m = planned->metrics;
    char text[400];
    std::snprintf(text, sizeof text,
                  "program %s: %d commands (%d motions), %d knots; path %.0f -> %.0f mm; clearance %.1f mm; required "
                  "contacts %s; %.0f ms",
                  program_id.c_str(), m.commands, m.motion_commands, m.knots, m.length_before_m * 1e3,
                  m.length_after_m * 1e3, m.min_clearance_after_m * 1e3, m.required_contacts_kept ? "kept" : "LOST", ms);
    ConsoleAll(std::string(text) + "\n" + robot::ProgramListing(*program), true);
    Changed();
  }

  Reply CmdExecute() {
    if (!busy.empty()) return Fail("execute: busy (" + busy + ")");
    if (!program) return Fail("execute: no program (confirm first)");
    if (!client || !site_connected || site_lost) return Fail("execute: the work site is not connected");
    if (site_stopped) return Fail("execute: the work site's robot is stopped and latched; type resume first");
    Json fields = {{"program_id", program_id}, {"program", robot::ProgramToJson(*program)}};
    if (Status s = client->Send(MessageType::kProgramSubmit, fields); !s.ok()) return Fail("execute: " + s.message());
    busy = "executing";
    report.reset();
    return {"program " + program_id + " sent to the work site (" + std::to_string(program->commands.size()) +
            " commands)"};
  }

  Reply CmdResume() {
    if (!client || !site_connected) return Fail("resume: the work site is not connected");
    if (Status s = client->Send(MessageType::kResume); !s.ok()) return Fail("resume: " + s.message());
    return {"resume sent to the work site"};
  }

  Reply CmdReset() {
    if (dragging) return Fail("reset: a drag is in progress");
    if (busy == "planning") return Fail("reset: busy (planning)");
    std::string text;
    if (client && site_connected) {
      if (Status s = client->Send(MessageType::kResetWorld); !s.ok()) return Fail("reset: " + s.message());
      text = "the work site resets its world; ";
    }
    if (site_scene) {
      SetModel(*site_scene);
    } else if (options.initial_scene) {
      SetModel(*options.initial_scene);
    }
    busy.clear();
    return {text + "the model is back at the work site's scene"};
  }

  // The model editor (paper §4.3): the operator adds recognition INDEX to the model. Its rules:
  //  * an object whose lowest point is within kRestSnap_m of a fixed object's top (the table, the
  //    frame) rests on it: it is moved along z to kRestClearance_m above it (the monocular pose is
  //    least sure along the camera axis; the scene files keep the same clearance);
  //  * a recognition overlapping a movable model object of the same model is that object seen
  //    again: its pose is corrected (no duplicate);
  //  * nothing may interpenetrate: a pose that intersects another object is refused.
  static constexpr double kRestSnap_m = 0.01;
  static constexpr double kRestClearance_m = 0.25e-3;

  static bool Overlap(const geometry::Aabb& a, const geometry::Aabb& b) {
    return (a.min.array() < b.max.array()).all() && (b.min.array() < a.max.array()).all();
  }

  // Rests `object` on the highest fixed support under it whose top is within kRestSnap_m of its
  // lowest point; returns the support's name, or "" when it rests on nothing.
  std::string RestOnSupport(scene::SceneObject& object) const {
    const geometry::Aabb box = object.shape.WorldBounds(object.world_T_object);
    const scene::SceneObject* best = nullptr;
    double best_top = -1e300;
    for (const auto& o : model.objects) {
      if (!o.fixed) continue;
      for (const geometry::ShapePart& part : o.shape.parts()) {
        const geometry::Aabb b = part.convex->WorldBounds(o.world_T_object * part.shape_T_part);
        const bool under = b.min.x() < box.max.x() && box.min.x() < b.max.x() && b.min.y() < box.max.y() &&
                           box.min.y() < b.max.y();
        if (under && std::abs(box.min.z() - b.max.z()) <= kRestSnap_m && b.max.z() > best_top) {
          best = &o;
          best_top = b.max.z();
        }
      }
    }
    if (best == nullptr) return "";
    object.world_T_object.translation.z() += best_top + kRestClearance_m - box.min.z();
    return best->name;
  }

  Reply CmdAdd(const std::vector<std::string>& w) {
    if (w.size() != 2) return Fail("usage: add INDEX (see list)");
    if (!last_recognitions.is_object() || last_recognitions["objects"].empty()) return Fail("add: no recognitions yet");
    std::size_t index = 0;
    try {
      std::size_t used = 0;
      const unsigned long v = std::stoul(w[1], &used);
      if (used != w[1].size()) throw std::invalid_argument("trailing");
      index = v;
    } catch (const std::exception&) {
      return Fail("add: INDEX must be a number, got \"" + w[1] + "\"");
    }
    const Json& list = last_recognitions["objects"];
    if (index >= list.size()) return Fail("add: no recognition " + w[1] + " (there are " + std::to_string(list.size()) + ")");
    const Json& r = list[index];
    const std::string model_name = r["model"].get<std::string>();
    const Json* shape = nullptr;
    for (const Json& m : models) {
      if (m["name"] == model_name) shape = &m["shape"];
    }
    if (shape == nullptr) return Fail("add: the work site's models have no \"" + model_name + "\"");
    scene::SceneObject object;
    try {
      object.shape_spec = scene::ReadShapeSpec(json::Reader(*shape, "models." + model_name + ".shape"));
      object.world_T_object = geometry::ReadPose(json::Reader(r["world_T_object"]));
    } catch (const json::ParseError& e) {
      return Fail(std::string("add: ") + e.what());
    }
    auto built = scene::BuildShape(object.shape_spec);
    if (!built.ok()) return Fail("add: " + built.status().message());
    object.shape = std::move(built).value();
    object.fixed = false;
    object.model = model_name;
    const std::string support = RestOnSupport(object);
    // The same object seen again: a movable model object of this model that the recognition overlaps.
    const geometry::Aabb box = object.shape.WorldBounds(object.world_T_object);
    int same = -1;
    for (std::size_t i = 0; i < model.objects.size(); ++i) {
      const scene::SceneObject& o = model.objects[i];
      if (!o.fixed && o.model == model_name && Overlap(box, o.shape.WorldBounds(o.world_T_object))) {
        same = static_cast<int>(i);
        break;
      }
    }
    scene::Scene trial = model;
    if (same >= 0) {
      object.name = model.objects[static_cast<std::size_t>(same)].name;
      trial.objects[static_cast<std::size_t>(same)].world_T_object = object.world_T_object;
    } else {
      for (int n = 1;; ++n) {
        object.name = model_name + "_" + std::to_string(n);
        if (model.FindObject(object.name) < 0) break;
      }
      trial.objects.push_back(object);
    }
    // No interpenetration: the simulator must be able to start a drag of it where it is.
    auto world = sim::SimWorld::Build(std::move(trial), options.sim);
    if (!world.ok()) return Fail("add: " + world.status().message());
    if (auto state = sim::StartDrag(*world, object.name); !state.ok()) {
      return Fail("add: " + model_name + " at " + Mm(object.world_T_object.translation) + " is refused: " +
                  state.status().message() + " (delete that object first, or wait for a better recognition)");
    }
    const std::string rests = support.empty() ? "" : ", resting on " + support;
    if (std::find(recognized.begin(), recognized.end(), object.name) == recognized.end()) {
      recognized.push_back(object.name);
    }
    if (same >= 0) {
      scene::SceneObject& o = model.objects[static_cast<std::size_t>(same)];
      const double moved_mm = (o.world_T_object.translation - object.world_T_object.translation).norm() * 1e3;
      o.world_T_object = object.world_T_object;
      // The demonstration started from the old pose of the scene.
      if (!strokes.empty() || program) ClearDemonstration();
      char text[64];
      std::snprintf(text, sizeof text, " (moved %.1f mm)", moved_mm);
      return {"updated " + object.name + " from recognition " + w[1] + ": at " + Mm(object.world_T_object.translation) +
              text + rests};
    }
    model.objects.push_back(object);
    if (!strokes.empty() || program) ClearDemonstration();
    return {"added " + object.name + " at " + Mm(object.world_T_object.translation) + rests};
  }

  Reply CmdDelete(const std::vector<std::string>& w) {
    if (w.size() != 2) return Fail("usage: delete NAME");
    const int i = model.FindObject(w[1]);
    if (i < 0) return Fail("delete: no object \"" + w[1] + "\" in the model");
    if (dragging && drag_object == w[1]) return Fail("delete: \"" + w[1] + "\" is being dragged");
    if (workpiece && *workpiece == w[1]) {
      workpiece.reset();
      ClearDemonstration();
    }
    model.objects.erase(model.objects.begin() + i);
    std::erase(capture, w[1]);
    std::erase(recognized, w[1]);
    if (!strokes.empty()) ClearDemonstration();  // the demonstration saw the deleted object
    return {"deleted " + w[1]};
  }

  std::string SessionFile(const std::string& name) const {
    return (std::filesystem::path(options.sessions_dir) / (name + ".json")).string();
  }

  Reply CmdSave(const std::vector<std::string>& w) {
    if (w.size() != 2 || !net::IsValidSessionName(w[1])) {
      return Fail("usage: save NAME (1-64 of A-Z a-z 0-9 _ . -, not starting with '.')");
    }
    SessionData s;
    s.scene = model;
    s.recognized = recognized;
    s.workpiece = workpiece;
    s.capture = capture;
    if (initial_path) {
      s.path = initial_path;
    } else if (workpiece && !strokes.empty()) {
      s.path = DemonstratedPath();
    }
    s.deformed = deformed;
    s.simplified = simplified;
    s.program = program;
    s.program_id = program_id;
    s.report = report;
    std::error_code ec;
    std::filesystem::create_directories(options.sessions_dir, ec);
    if (ec) return Fail("save: " + options.sessions_dir + ": cannot create folder: " + ec.message());
    const std::string file = SessionFile(w[1]);
    if (Status st = SaveSession(s, file); !st.ok()) return Fail("save: " + st.message());
    return {"saved " + file};
  }

  Reply CmdLoad(const std::vector<std::string>& w) {
    if (w.size() != 2 || !net::IsValidSessionName(w[1])) {
      return Fail("usage: load NAME (1-64 of A-Z a-z 0-9 _ . -, not starting with '.')");
    }
    if (dragging || !busy.empty()) return Fail("load: busy");
    const std::string file = SessionFile(w[1]);
    auto loaded = LoadSession(file);
    if (!loaded.ok()) return Fail("load: " + loaded.status().message());
    // The model must stay simulable (no interpenetration) before it replaces the present one.
    if (auto checked = sim::SimWorld::Build(loaded->scene, options.sim); !checked.ok()) {
      return Fail("load: " + file + ": scene: " + checked.status().message());
    }
    SetModel(loaded->scene);
    recognized = loaded->recognized;
    workpiece = loaded->workpiece;
    capture = loaded->capture;
    if (loaded->path && workpiece && loaded->path->workpiece == *workpiece && !loaded->path->nodes.empty()) {
      Stroke s;
      s.start = loaded->path->nodes.front().world_T_workpiece;
      s.nodes = loaded->path->nodes;
      s.capture = loaded->path->capture_objects;
      strokes.push_back(std::move(s));
      if (loaded->program) initial_path = loaded->path;
    }
    deformed = loaded->deformed;
    simplified = loaded->simplified;
    program = loaded->program;
    program_id = loaded->program_id.empty() && program ? "p" + std::to_string(++program_counter) : loaded->program_id;
    report = loaded->report;
    return {"loaded " + file + ": " + std::to_string(model.objects.size()) + " objects" +
            (workpiece ? ", workpiece " + *workpiece : "") + (program ? ", program " + program_id : "")};
  }

  Reply RunCommand(net::SessionId session, const std::string& line) {
    const std::vector<std::string> w = Words(line);
    if (w.empty()) return Fail("empty command; type help");
    const std::string& c = w[0];
    if (c == "help") return {kHelp};
    if (c == "list") return CmdList();
    if (c == "status") return CmdStatus();
    static const char* kKnown[] = {"select", "capture", "undo",   "confirm", "execute", "resume",
                                   "reset",  "add",     "delete", "save",    "load"};
    if (std::find(std::begin(kKnown), std::end(kKnown), c) == std::end(kKnown)) {
      return Fail("unknown command \"" + c + "\"; type help");
    }
    if (c != "save" && !server->lease().Holds(session)) {
      auto holder = server->lease().holder();
      return Fail("read-only: " + c + " needs the controller lease" +
                  (holder ? " (held by session " + std::to_string(*holder) + ")" : " (send lease_request)"));
    }
    if (dragging && c != "save") return Fail(c + ": a drag is in progress");
    if (c == "select") return CmdSelect(w);
    if (c == "capture") return CmdCapture(w);
    if (c == "undo") return CmdUndo();
    if (c == "confirm") return CmdConfirm();
    if (c == "execute") return CmdExecute();
    if (c == "resume") return CmdResume();
    if (c == "reset") return CmdReset();
    if (c == "add") return CmdAdd(w);
    if (c == "delete") return CmdDelete(w);
    if (c == "save") return CmdSave(w);
    return CmdLoad(w);
  }

  void Command(net::SessionId session, const std::string& line, std::uint64_t seq) {
    const std::uint64_t before = revision;
    Reply r = RunCommand(session, line);
    Console(session, r.text, r.ok, seq);
    // Every command that may change the model, selection, paths or program republishes the state.
    const std::string verb = Words(line).empty() ? "" : Words(line)[0];
    if (r.ok && verb != "help" && verb != "list" && verb != "status" && verb != "save" && revision == before) Changed();
  }

  // ======== the browsers ========

  void BrowserOpen(net::SessionId session) {
    if (Status st = server->Send(session, MessageType::kWorldState, WorldState()); !st.ok()) {
      // A service's own mistake (the outgoing message failed validation): say so loudly.
      std::fprintf(stderr, "operator: world_state not sent: %s\n", st.message().c_str());
    }
    (void)server->Send(session, MessageType::kLinkState, SiteLinkStateMessage());
    if (last_frame) SendFrameTo(session, *last_frame);
    if (last_recognitions.is_object()) SendRecognitionsTo(session, last_recognitions);
    if (last_progress.is_object()) (void)server->Send(session, MessageType::kExecutionProgress, ReplayOf(last_progress));
  }

  void BrowserGone(net::SessionId session) {
    frame_seqs.erase(session);
    if (dragging && drag_session == session) EndDrag(std::nullopt, 0);
  }

  void Refuse(net::SessionId session, const net::Message& m, const std::string& text) {
    (void)server->Send(session, MessageType::kError,
                       {{"code", "invalid_command"}, {"message", text}, {"in_reply_to", m.seq}});
  }

  void BrowserMessage(net::SessionId session, const net::Message& m) {
    switch (m.type) {
      case MessageType::kConsoleCommand:
        Command(session, m.body["line"].get<std::string>(), m.seq);
        return;
      case MessageType::kSessionSave:
        Command(session, "save " + m.body["name"].get<std::string>(), m.seq);
        return;
      case MessageType::kSessionLoad:
        Command(session, "load " + m.body["name"].get<std::string>(), m.seq);
        return;
      case MessageType::kResetWorld:
        Command(session, "reset", m.seq);
        return;
      case MessageType::kHello:  // the server has checked the protocol; nothing to answer
        return;
      case MessageType::kResume:
        Command(session, "resume", m.seq);
        return;
      case MessageType::kDraggerInput: {
        const std::string object = m.body["object"].get<std::string>();
        const std::string phase = m.body["phase"].get<std::string>();
        const geometry::Pose3 pose = geometry::ReadPose(json::Reader(m.body["world_T_dragger"]));
        if (phase == "begin") {
          if (Status s = BeginDrag(session, object, pose, m.seq); !s.ok()) Refuse(session, m, s.message());
          return;
        }
        if (!dragging || drag_session != session || drag_object != object) {
          Refuse(session, m, "dragger_input." + phase + ": no drag of \"" + object + "\" in progress (send begin)");
          return;
        }
        if (phase == "move") {
          {
            std::lock_guard lock(drag_mutex);
            input.world_T_dragger = pose;
            input.seq = m.seq;
          }
          drag_cv.notify_one();
        } else {
          EndDrag(pose, m.seq);
        }
        return;
      }
      default:
        Refuse(session, m, std::string(net::TypeName(m.type)) + ": not a message the operator site takes");
        return;
    }
  }

  // ======== the drag and the simulator thread ========

  Status BeginDrag(net::SessionId session, const std::string& object, const geometry::Pose3& pose, std::uint64_t seq) {
    if (dragging) return Status::Failed("dragger_input.begin: a drag is already in progress");
    if (!busy.empty()) return Status::Failed("dragger_input.begin: busy (" + busy + ")");
    const scene::SceneObject* o = FindObject(object);
    if (o == nullptr) return Status::InvalidInput("dragger_input.object: no object \"" + object + "\" in the model");
    if (o->fixed) return Status::InvalidInput("dragger_input.object: \"" + object + "\" is fixed");
    if (!workpiece || *workpiece != object) {
      ClearDemonstration();
      workpiece = object;
      std::erase(capture, object);
    }
    auto world = sim::SimWorld::Build(model, options.sim);
    if (!world.ok()) return world.status();
    auto state = sim::StartDrag(*world, object);
    if (!state.ok()) return state.status();
    auto j = std::make_unique<DragJob>();
    j->world = std::move(world).value();
    j->state = std::move(state).value();
    for (const auto& c : capture) {
      const int i = j->world.scene.FindObject(c);
      if (i >= 0) j->state.capture.push_back(i);
    }
    const geometry::Aabb box = o->shape.WorldBounds(geometry::Pose3::Identity());
    j->dragger = std::make_unique<sim::Dragger>(j->state.world_T_workpiece,
                                                box.Size() * 0.5 + Eigen::Vector3d::Constant(0.01), options.dragger);
    j->begin_orientation = pose.rotation;
    j->stroke.start = j->state.world_T_workpiece;
    j->stroke.capture = capture;
    j->stroke.nodes.push_back(MakeNode(j->world, j->state));
    // Strokes continue the demonstration; the program of an earlier one is void now.
    initial_path.reset();
    deformed.reset();
    simplified.reset();
    program.reset();
    {
      std::lock_guard lock(drag_mutex);
      job = std::move(j);
      input = DragInput{pose, seq, false};
    }
    drag_cv.notify_one();
    dragging = true;
    drag_session = session;
    drag_object = object;
    Changed();
    return Status::Ok();
  }

  void EndDrag(std::optional<geometry::Pose3> pose, std::uint64_t seq) {
    {
      std::lock_guard lock(drag_mutex);
      if (pose) input.world_T_dragger = *pose;
      if (seq) input.seq = seq;
      input.end = true;
    }
    drag_cv.notify_one();
  }

  // The stroke is over (posted by the simulator thread).
  void StrokeDone(Stroke stroke, double rate_hz) {
    dragging = false;
    sim_rate_hz = rate_hz;
    if (scene::SceneObject* o = FindObject(drag_object); o && !stroke.nodes.empty()) {
      o->world_T_object = stroke.nodes.back().world_T_workpiece;
    }
    if (stroke.nodes.size() > 1 && workpiece && *workpiece == drag_object) strokes.push_back(std::move(stroke));
    Changed();
  }

  Json PoseUpdate(const DragJob& j, double rate_hz, std::uint64_t seq) const {
    Json fields = {{"t_s", Seconds(WallClock::now() - epoch)},
                   {"poses", Json::array({{{"object", j.world.name(j.state.workpiece)},
                                           {"world_T_object", geometry::WritePose(j.state.world_T_workpiece)}}})},
                   {"sim_rate_hz", rate_hz},
                   {"world_T_dragger", geometry::WritePose(j.dragger->world_T_dragger())}};
    if (seq > 0) fields["input_seq"] = seq;
    return fields;
  }

  void SimLoop() {
    const auto period = std::chrono::duration_cast<WallClock::duration>(std::chrono::duration<double>(1.0 / options.sim_rate_hz));
    for (;;) {
      std::unique_ptr<DragJob> j;
      {
        std::unique_lock lock(drag_mutex);
        drag_cv.wait(lock, [&] { return quit.load() || job != nullptr; });
        if (quit) return;
        j = std::move(job);
      }
      std::deque<WallClock::time_point> recent;  // step times over the last second: the rate
      auto next = WallClock::now();
      double rate = 0;
      for (;;) {
        DragInput in;
        {
          std::lock_guard lock(drag_mutex);
          in = input;
        }
        if (quit) return;
        if (in.end) break;
        const bool rotate = in.world_T_dragger.rotation.angularDistance(j->begin_orientation) > 1e-3;
        j->dragger->SetPose(rotate ? in.world_T_dragger
                                   : geometry::Pose3(j->state.world_T_workpiece.rotation, in.world_T_dragger.translation),
                            rotate);
        sim::Step(j->world, j->state, j->dragger->Force(j->state.world_T_workpiece));
        j->stroke.nodes.push_back(MakeNode(j->world, j->state));
        const auto now = WallClock::now();
        recent.push_back(now);
        while (!recent.empty() && now - recent.front() > std::chrono::seconds(1)) recent.pop_front();
        const double span = recent.size() > 1 ? Seconds(recent.back() - recent.front()) : 0;
        rate = span > 0.2 ? static_cast<double>(recent.size() - 1) / span : options.sim_rate_hz;
        Post([this, fields = PoseUpdate(*j, rate, in.seq)] {
          sim_rate_hz = fields["sim_rate_hz"].get<double>();
          server->Broadcast(MessageType::kPoseUpdate, fields);
        });
        // The next step: on the schedule, or as soon as a new input arrives once half a period
        // has passed (the person's input is used at once: latency, not the rate, is what they feel).
        next += period;
        if (now > next + period * 5) next = now;  // fell behind: no burst of catch-up steps
        {
          std::unique_lock lock(drag_mutex);
          const std::uint64_t used = in.seq;
          drag_cv.wait_until(lock, now + period / 2, [&] { return quit.load() || input.end; });  // at most 2x the rate
          drag_cv.wait_until(lock, next, [&] { return quit.load() || input.end || input.seq != used; });
          if (WallClock::now() < next) next = WallClock::now();
        }
      }
      // Let go: the workpiece settles (no dragger force) for at most settle_s, as a script's end.
      int quiet = 0;
      for (double t = 0; t < options.settle_s && quiet < 5; t += options.sim.step_s) {
        j->dragger->SetPose(j->state.world_T_workpiece, false);
        sim::StepResult step = sim::Step(j->world, j->state, j->dragger->Force(j->state.world_T_workpiece));
        j->stroke.nodes.push_back(MakeNode(j->world, j->state));
        const double moved = step.fraction * (step.velocity.linear.norm() + step.velocity.angular.norm() * 0.02);
        quiet = moved < 1e-4 ? quiet + 1 : 0;
      }
      Post([this, fields = PoseUpdate(*j, rate, 0)] { server->Broadcast(MessageType::kPoseUpdate, fields); });
      Post([this, stroke = std::make_shared<Stroke>(std::move(j->stroke)), rate] { StrokeDone(std::move(*stroke), rate); });
    }
  }

  // ======== the work site ========

  Json SiteLinkStateMessage() const {
    return {{"state", site_connected && !site_lost ? "up" : "lost"}, {"stopped", site_stopped}, {"reason", site_reason}};
  }

  void SiteStateChanged() {
    server->Broadcast(MessageType::kLinkState, SiteLinkStateMessage());
    Changed();
  }

  void SiteOpen() {
    site_connected = true;
    site_lost = false;
    site_reason = "connected to " + options.worksite;
    SiteStateChanged();
  }

  void SiteClosed(const Status& reason) {
    if (reconnecting) return;  // our own Reconnect(): the new connection is on its way
    site_connected = false;
    site_lost = true;
    site_reason = "work site disconnected: " + reason.message();
    site_closed_at = WallClock::now();
    site_reconnect_due = true;
    if (busy == "executing") busy.clear();
    SiteStateChanged();
  }

  void SiteLink(const net::LinkEvent& e) {
    if (e.kind == net::LinkEvent::Kind::kLost) {
      if (!site_connected) return;
      site_lost = true;
      site_reason = "work site link lost: " + e.reason;
      SiteStateChanged();
      // A silent link is dropped and dialled again: the work site has stopped the robot already,
      // and a fresh session resynchronises everything.
      if (client->connected()) Post([this] { Redial(); });
    } else if (site_connected) {
      site_lost = false;
      site_reason = "work site link restored";
      SiteStateChanged();
    }
  }

  void SendFrameTo(net::SessionId session, const net::BinaryFrame& frame) {
    if (!server->SendFrame(session, frame.header, frame.pixels).ok()) return;
    auto info = server->Info(session);
    if (!info) return;
    auto& seqs = frame_seqs[session];
    seqs.emplace_back(frame.header.seq, info->stats.sent);
    while (seqs.size() > 16) seqs.pop_front();
  }

  void SendRecognitionsTo(net::SessionId session, Json fields) {
    std::uint64_t ours = 0;
    const std::uint64_t theirs = fields["frame_seq"].get<std::uint64_t>();
    for (const auto& [site_seq, local_seq] : frame_seqs[session]) {
      if (site_seq == theirs) ours = local_seq;
    }
    fields["frame_seq"] = ours;
    (void)server->Send(session, MessageType::kRecognitions, fields);
  }

  void SiteFrame(const net::BinaryFrame& frame) {
    last_frame = frame;
    for (net::SessionId s : server->Sessions()) SendFrameTo(s, frame);
  }

  static Json ReplayOf(Json fields) {
    fields["replay"] = true;
    return fields;
  }

  static Json Fields(const net::Message& m) {
    Json f = m.body;
    f.erase("type");
    f.erase("seq");
    return f;
  }

  void SiteMessage(const net::Message& m) {
    switch (m.type) {
      case MessageType::kWelcome:
        (void)client->Send(MessageType::kLeaseRequest);
        return;
      case MessageType::kLeaseGrant:
        if (!m.body["granted"].get<bool>()) {
          ConsoleAll("work site: the controller lease is held by another operator; watching only", false);
        }
        return;
      case MessageType::kWorksiteScene: {
        auto scene = scene::ParseScene(m.body["scene"], "worksite_scene.scene");
        if (!scene.ok()) {
          ConsoleAll("work site sent a bad scene: " + scene.status().message(), false);
          return;
        }
        const bool first = !site_scene.has_value();
        site_scene = std::move(scene).value();
        models = m.body["models"];
        if (first && model.objects.empty()) SetModel(*site_scene);
        if (first && !model.objects.empty() && model.cameras.empty()) model.cameras = site_scene->cameras;
        if (first && !model.robot) model.robot = site_scene->robot;
        Changed();
        return;
      }
      case MessageType::kLinkState: {
        site_stopped = m.body["stopped"].get<bool>();
        site_reason = "work site: " + m.body["reason"].get<std::string>();
        SiteStateChanged();
        return;
      }
      case MessageType::kRobotState: {
        const auto now = WallClock::now();
        if (now - last_robot_state_relay < std::chrono::milliseconds(90)) return;  // ~10 Hz to browsers
        last_robot_state_relay = now;
        server->Broadcast(MessageType::kRobotState, Fields(m));
        return;
      }
      case MessageType::kRecognitions:
        last_recognitions = Fields(m);
        for (net::SessionId s : server->Sessions()) SendRecognitionsTo(s, last_recognitions);
        return;
      case MessageType::kExecutionProgress: {
        // A replay (sent on every (re)connection) is the state as it is: taken silently when it is
        // what we have, announced once when it is news (it changed while the link was down).
        Json f = Fields(m);
        const bool replay = f.value("replay", false);
        f.erase("replay");
        if (replay && last_progress == f) return;
        last_progress = f;
        const std::string state = f["state"].get<std::string>();
        bool changed = false;
        if (replay && state == "running" && busy.empty()) {
          busy = "executing";  // still running at the work site
          changed = true;
        }
        if (replay && state != "running" && busy == "executing") {
          busy.clear();
          changed = true;
        }
        server->Broadcast(MessageType::kExecutionProgress, replay ? ReplayOf(f) : f);
        std::string line = "execution " + f["program_id"].get<std::string>() + ": " + state + ", command " +
                           std::to_string(f["command_index"].get<long long>()) + "/" +
                           std::to_string(f["command_count"].get<long long>());
        if (f.contains("message")) line += " " + f["message"].get<std::string>();
        if (replay) line += " (learnt on reconnecting to the work site)";
        ConsoleAll(line, state != "failed" && state != "stopped");
        if (changed) Changed();
        return;
      }
      case MessageType::kReport: {
        Json f = Fields(m);
        const bool replay = f.value("replay", false);
        f.erase("replay");
        const std::string id = f["program_id"].get<std::string>();
        const bool ok = f["ok"].get<bool>();
        if (replay && report && report->program_id == id && report->ok == ok && report->report == f["report"]) return;
        server->Broadcast(MessageType::kReport, replay ? ReplayOf(f) : f);
        report = SessionReport{id, ok, f["report"]};
        if (busy == "executing") busy.clear();
        ConsoleAll("report " + report->program_id + ": " + ReportSummary(*report) +
                       (replay ? " (learnt on reconnecting to the work site)" : ""),
                   report->ok);
        Changed();
        return;
      }
      case MessageType::kError: {
        std::string text = "work site: " + m.body["message"].get<std::string>();
        if (busy == "executing") {
          busy.clear();
          Changed();
        }
        ConsoleAll(text, false);
        return;
      }
      default:
        return;
    }
  }

  // Drops the connection (if any) and dials again; the close of the old one is no news.
  void Redial() {
    if (site_connected) {
      site_connected = false;
      site_lost = true;
      if (busy == "executing") busy.clear();
    }
    reconnecting = true;
    client->Reconnect();
    reconnecting = false;
  }

  // Every 100 ms on the loop: reconnects the work site.
  void Tick() {
    if (client && site_reconnect_due && !client->connected() &&
        Seconds(WallClock::now() - site_closed_at) >= options.reconnect_period_s) {
      site_reconnect_due = false;
      site_reason = "connecting to " + options.worksite;
      Redial();
    }
  }
};

OperatorService::OperatorService(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

OperatorService::~OperatorService() { Stop(); }

Result<std::unique_ptr<OperatorService>> OperatorService::Create(const net::Clock& clock, OperatorOptions options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  auto impl = std::make_unique<Impl>();
  impl->clock = &clock;
  impl->browser_side.m = impl.get();
  impl->site_side.m = impl.get();
  if (options.initial_scene) impl->SetModel(*options.initial_scene);
  if (options.worksite.empty()) impl->site_reason = "no work site";
  impl->options = std::move(options);
  impl->UpdateSnapshot();
  return std::unique_ptr<OperatorService>(new OperatorService(std::move(impl)));
}

Status OperatorService::Start() {
  Impl& m = *impl_;
  if (m.started) return Status::Failed("operator: already started");
  net::ServerOptions so;
  so.host = m.options.host;
  so.port = m.options.http_port;
  so.name = "teachsim-operator";
  so.static_root = m.options.web_root;
  so.heartbeat_period_s = m.options.heartbeat_period_s;
  so.link_timeout_s = m.options.browser_link_timeout_s;
  so.close_after_silence_s = std::max(so.close_after_silence_s, 2 * m.options.browser_link_timeout_s);
  m.server = std::make_unique<net::Server>(m.loop, *m.clock, so, m.browser_side);
  if (Status s = m.server->Start(); !s.ok()) {
    m.server.reset();
    return s;
  }
  if (!m.options.worksite.empty()) {
    auto url = net::ParseWebSocketUrl(m.options.worksite);
    if (!url.ok()) return url.status();
    net::ClientOptions co;
    co.host = url->host;
    co.port = url->port;
    co.path = url->path;
    co.token = m.options.token;
    co.name = "teachsim-operator";
    co.heartbeat_period_s = m.options.heartbeat_period_s;
    co.link_timeout_s = m.options.link_timeout_s;
    m.client = std::make_unique<net::Client>(m.loop, *m.clock, co, m.site_side);
    m.site_reason = "connecting to " + m.options.worksite;
    m.client->Connect();
  }
  m.started = true;
  m.loop_thread = std::make_unique<net::LoopThread>(m.loop);
  m.sim_thread = std::thread([&m] { m.SimLoop(); });
  m.tick_thread = std::thread([&m] {
    while (!m.quit) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      m.Post([&m] { m.Tick(); });
    }
  });
  return Status::Ok();
}

void OperatorService::Stop() {
  Impl& m = *impl_;
  if (!m.started) return;
  m.started = false;
  // Close the sessions on the loop, then stop the threads that post to it.
  std::promise<void> closed;
  m.loop.Post([&m, &closed] {
    if (m.client) m.client->Close();
    m.server->Stop();
    closed.set_value();
  });
  closed.get_future().wait_for(std::chrono::seconds(5));
  m.quit = true;
  m.drag_cv.notify_all();
  if (m.sim_thread.joinable()) m.sim_thread.join();
  if (m.tick_thread.joinable()) m.tick_thread.join();
  if (m.planner_thread.joinable()) m.planner_thread.join();
  m.loop_thread.reset();
  m.client.reset();
  m.server.reset();
}

std::uint16_t OperatorService::port() const { return impl_->server ? impl_->server->port() : 0; }

void OperatorService::CutWorksiteLink() {
  Impl& m = *impl_;
  m.Post([&m] {
    if (m.client && m.client->connected()) m.client->Abort();
  });
}

OperatorSnapshot OperatorService::snapshot() const {
  std::lock_guard lock(impl_->snapshot_mutex);
  return impl_->snap;
}

}  // namespace teachsim::op
