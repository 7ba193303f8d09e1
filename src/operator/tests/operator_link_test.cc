// The two sites linked over loopback: the work-site service (MuJoCo world) and the operator site.
// A program crosses the token-authenticated link and runs; a link cut mid-execution brings the
// robot to a controlled stop within the limits (measured in simulated time), latched until
// resume; a reconnect resynchronises the state; the browser sees it all.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <future>

#include "browser.h"
#include "teachsim/operator/service.h"
#include "teachsim/operator/session.h"
#include "teachsim/plan/planner.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/sim/demos.h"
#include "teachsim/sim/script.h"
#include "teachsim/worksite/execute.h"
#include "teachsim/worksite/service.h"

namespace teachsim::op {
namespace {

using namespace testing;

const net::Token kToken("0123456789abcdef0123456789abcdef");

scene::Scene Puzzle() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok()) << scene.status().message();
  return *scene;
}

// The cornering demonstration (sim::CorneringScript) and its program, made once.
struct Demo {
  sim::WorkpiecePath path;
  robot::Program program;
};
const Demo& Cornering() {
  static const Demo demo = [] {
    Demo d;
    scene::Scene scene = Puzzle();
    auto world = sim::SimWorld::Build(scene, {});
    auto script = sim::CorneringScript(scene);
    auto path = sim::RunScript(*world, *script, {}, nullptr);
    EXPECT_TRUE(path.ok());
    d.path = *path;
    auto planned = plan::GenerateProgram(scene, d.path);
    EXPECT_TRUE(planned.ok()) << planned.status().message();
    d.program = planned->program;
    return d;
  }();
  return demo;
}

std::unique_ptr<worksite::WorksiteService> StartWorksite(const net::Clock& clock, double time_scale,
                                                         double camera_period_s = 0) {
  scene::Scene scene = Puzzle();
  auto model = robot::LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/" + scene.robot->model + ".json");
  EXPECT_TRUE(model.ok());
  worksite::WorksiteServiceOptions o;
  o.server.token = kToken;
  o.time_scale = time_scale;
  o.camera_period_s = camera_period_s;
  o.recognize = false;  // the index build takes a while; recognition has its own tests (vision)
  auto site = worksite::WorksiteService::Create(clock, scene, *model, o);
  EXPECT_TRUE(site.ok()) << site.status().message();
  EXPECT_TRUE((*site)->Start().ok());
  return std::move(site).value();
}

TEST(OperatorLink, LinkCutMidExecutionStopsTheRobotAndReconnectResynchronises) {
  net::SteadyClock clock;
  const Demo& demo = Cornering();
  auto site = StartWorksite(clock, 1.0);  // real time, as a robot runs
  auto first = std::make_unique<Browser>(site->port(), kToken);
  ASSERT_TRUE(first->WaitFor([&] { return first->Count(MessageType::kWorksiteScene) > 0; }));
  ASSERT_TRUE(first->TakeLease());
  ASSERT_TRUE(first->client->Send(MessageType::kProgramSubmit, {{"program_id", "cut1"}, {"program", robot::ProgramToJson(demo.program)}}).ok());
  // Wait until the arm is moving in the middle of the program (past the approach).
  ASSERT_TRUE(first->WaitMessage(MessageType::kExecutionProgress, [](const Json& j) {
    return j["state"] == "running" && j["command_index"].get<int>() >= 1;
  }, 0, 30).has_value());
  ASSERT_TRUE(first->WaitMessage(MessageType::kRobotState, [](const Json& j) { return j["moving"].get<bool>(); }, 0, 10).has_value());
  // Cut: the operator falls silent (a pulled cable: the socket stays open, nothing arrives).
  first->client->PauseHeartbeats(true);
  const auto cut = std::chrono::steady_clock::now();
  std::optional<double> stop_s;
  while (std::chrono::steady_clock::now() - cut < std::chrono::seconds(5)) {
    first->loop.RunFor(std::chrono::milliseconds(10));
    if ((stop_s = site->stats().last_stop_s)) break;
  }
  ASSERT_TRUE(stop_s.has_value()) << "the robot never came to rest";
  std::printf("link cut: robot at rest %.3f s (simulated) after the watchdog's event\n", *stop_s);
  EXPECT_LE(*stop_s, 0.1);
  worksite::WorksiteStats stats = site->stats();
  EXPECT_TRUE(stats.latched);
  EXPECT_TRUE(stats.last_stop_during_execution);
  // The aborted program's report is sent once the execution thread has wound down (slow under the
  // sanitizers): reconnect after it, so that what the new session gets is replayed state.
  const auto wound_down = std::chrono::steady_clock::now();
  while (!site->stats().last_report_program && std::chrono::steady_clock::now() - wound_down < std::chrono::seconds(10)) {
    first->loop.RunFor(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(site->stats().last_report_program.has_value()) << "the stopped program never reported";
  first->loop.RunFor(std::chrono::milliseconds(300));  // the service's loop broadcasts the report it posted
  first.reset();

  // Reconnect: the whole state within 1 s.
  const auto t0 = std::chrono::steady_clock::now();
  Browser second(site->port(), kToken);
  ASSERT_TRUE(second.WaitFor([&] {
    return second.Count(MessageType::kWorksiteScene) > 0 && second.Count(MessageType::kLinkState) > 0 &&
           second.Count(MessageType::kRobotState) > 0 && second.Count(MessageType::kReport) > 0;
  }, 1.0));
  std::printf("resynchronised in %.0f ms\n",
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  EXPECT_TRUE((*second.Last(MessageType::kLinkState))["stopped"].get<bool>());
  EXPECT_EQ((*second.Last(MessageType::kExecutionProgress))["state"], "stopped");
  EXPECT_FALSE((*second.Last(MessageType::kReport))["ok"].get<bool>());
  // State, not news: the replayed progress and report say so.
  EXPECT_TRUE(second.Last(MessageType::kExecutionProgress)->value("replay", false));
  EXPECT_TRUE(second.Last(MessageType::kReport)->value("replay", false));
  EXPECT_TRUE((*second.Last(MessageType::kRobotState))["stopped"].get<bool>());
  // Latched: no program until resume.
  ASSERT_TRUE(second.TakeLease());
  ASSERT_TRUE(second.client->Send(MessageType::kProgramSubmit, {{"program_id", "cut2"}, {"program", robot::ProgramToJson(demo.program)}}).ok());
  ASSERT_TRUE(second.WaitMessage(MessageType::kError, [](const Json& j) { return j["code"] == "stopped"; }).has_value());
  const std::size_t n = second.messages.size();
  ASSERT_TRUE(second.client->Send(MessageType::kResume).ok());
  ASSERT_TRUE(second.WaitMessage(MessageType::kLinkState, [](const Json& j) { return !j["stopped"].get<bool>(); }, n).has_value());
  EXPECT_FALSE(site->stats().latched);
}

TEST(OperatorLink, WrongTokenMalformedAndInvalidProgramsAreRefused) {
  net::SteadyClock clock;
  auto site = StartWorksite(clock, 0);
  {
    Browser intruder(site->port(), net::Token("not-the-token-at-all-0000"));
    ASSERT_TRUE(intruder.WaitFor([&] { return !intruder.closes.empty(); }));
    EXPECT_NE(intruder.closes[0].message().find("401"), std::string::npos) << intruder.closes[0].message();
    EXPECT_TRUE(intruder.messages.empty());
  }
  {
    Browser anonymous(site->port());
    ASSERT_TRUE(anonymous.WaitFor([&] { return !anonymous.closes.empty(); }));
    EXPECT_TRUE(anonymous.messages.empty());
  }
  Browser b(site->port(), kToken);
  ASSERT_TRUE(b.WaitFor([&] { return b.Count(MessageType::kWorksiteScene) > 0; }));
  ASSERT_TRUE(b.client->SendRaw("[1, 2", false).ok());
  ASSERT_TRUE(b.WaitMessage(MessageType::kError, [](const Json& j) { return j["code"] == "malformed_json"; }).has_value());
  ASSERT_TRUE(b.client->SendRaw(std::string(3 << 20, ' '), false).ok());
  ASSERT_TRUE(b.WaitMessage(MessageType::kError, [](const Json& j) { return j["code"] == "too_large"; }).has_value());
  // Lease-only without the lease.
  ASSERT_TRUE(b.client->Send(MessageType::kProgramSubmit, {{"program_id", "x"}, {"program", Json::object()}}).ok());
  ASSERT_TRUE(b.WaitMessage(MessageType::kError, [](const Json& j) { return j["code"] == "not_lease_holder"; }).has_value());
  ASSERT_TRUE(b.TakeLease());
  // A program that does not pass the program reader never runs.
  ASSERT_TRUE(b.client->Send(MessageType::kProgramSubmit, {{"program_id", "x"}, {"program", {{"commands", "many"}}}}).ok());
  auto invalid = b.WaitMessage(MessageType::kError, [](const Json& j) { return j["code"] == "invalid_program"; });
  ASSERT_TRUE(invalid.has_value());
  EXPECT_NE((*invalid)["message"].get<std::string>().find("program_submit.program"), std::string::npos) << (*invalid)["message"];
  EXPECT_TRUE(b.client->connected());
  EXPECT_EQ(site->stats().programs_started, 0);
}

TEST(OperatorLink, ConfirmExecuteReportThroughTheOperatorSite) {
  net::SteadyClock clock;
  auto site = StartWorksite(clock, 0);  // unpaced: the test need not wait in real time
  const std::string sessions =
      (std::filesystem::temp_directory_path() / ("teachsim-link-" + std::to_string(::getpid()))).string();
  std::filesystem::remove_all(sessions);
  std::filesystem::create_directories(sessions);
  // The cornering demonstration as a saved session, loaded by the browser.
  SessionData s;
  s.scene = Puzzle();
  s.workpiece = "cube";
  s.path = Cornering().path;
  ASSERT_TRUE(SaveSession(s, sessions + "/corner.json").ok());

  OperatorOptions o;
  o.http_port = 0;
  o.sessions_dir = sessions;
  o.worksite = "127.0.0.1:" + std::to_string(site->port());
  o.token = kToken;
  auto op_service = OperatorService::Create(clock, o);
  ASSERT_TRUE(op_service.ok()) << op_service.status().message();
  ASSERT_TRUE((*op_service)->Start().ok());
  Browser b((*op_service)->port());
  ASSERT_TRUE(b.Ready());
  auto linked = b.WaitWorld([](const Json& j) { return j["link"]["state"] == "up" && j["objects"].size() == 7; });
  ASSERT_TRUE(linked.has_value()) << b.Last(MessageType::kWorldState)->dump();
  EXPECT_EQ((*linked)["models"].size(), 5u);
  ASSERT_TRUE(b.TakeLease());
  Json loaded = b.Command("load corner");
  ASSERT_TRUE(loaded["ok"].get<bool>()) << loaded["text"];
  ASSERT_TRUE(b.Command("confirm")["ok"].get<bool>());
  auto planned = b.WaitWorld([](const Json& j) { return !j["program"].is_null(); }, 60);
  ASSERT_TRUE(planned.has_value());
  // The operator's program is the cornering program (the same path through the same generator).
  EXPECT_EQ((*planned)["program"]["listing"], robot::ProgramListing(Cornering().program));
  Json execute = b.Command("execute");
  ASSERT_TRUE(execute["ok"].get<bool>()) << execute["text"];
  auto reported = b.WaitWorld([](const Json& j) { return !j["report"].is_null(); }, 120);
  ASSERT_TRUE(reported.has_value());
  // The work site runs it as `teachsim execute` does (worksite::Execute, the same controller and
  // world): the same verdict.
  scene::Scene scene = Puzzle();
  auto model = robot::LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/" + scene.robot->model + ".json");
  // (On another thread: the browser keeps its heartbeats going meanwhile.)
  auto running = std::async(std::launch::async, [&] {
    return worksite::Execute(scene, *model, Cornering().program, worksite::ExecuteOptions{});
  });
  b.WaitFor([&] { return running.wait_for(std::chrono::seconds(0)) == std::future_status::ready; }, 120);
  auto direct = running.get();
  ASSERT_TRUE(direct.ok()) << direct.status().message();
  std::printf("service: %s\nexecute: %s\n", (*reported)["report"]["summary"].get<std::string>().c_str(),
              direct->message.c_str());
  EXPECT_EQ((*reported)["report"]["ok"].get<bool>(), direct->success) << (*reported)["report"]["summary"];
  EXPECT_EQ((*reported)["busy"], "");
  EXPECT_GT(b.Count(MessageType::kExecutionProgress), 2u);
  EXPECT_EQ(b.Count(MessageType::kReport), 1u);
  EXPECT_GT(b.Count(MessageType::kRobotState), 0u);

  // The operator's link is cut (TCP dropped): the work site stops and latches; the operator
  // reconnects by itself and the browser sees the latched stop, then resume clears it.
  const std::size_t n = b.messages.size();
  (*op_service)->CutWorksiteLink();
  auto stopped = b.WaitWorld([](const Json& j) { return j["link"]["state"] == "up" && j["link"]["stopped"].get<bool>(); }, 5);
  ASSERT_TRUE(stopped.has_value()) << b.Last(MessageType::kWorldState)->at("link").dump() << " latched "
                                   << site->stats().latched;
  EXPECT_TRUE(site->stats().latched);
  // The reconnect resynchronised the state without replaying old events as news: the work site's
  // replayed progress and report (marked "replay") matched what the operator had, so the browser
  // got no second report, no progress event and no console line about them.
  auto after_cut = [&](MessageType type, const std::function<bool(const Json&)>& pred) {
    std::size_t count = 0;
    for (std::size_t i = n; i < b.messages.size(); ++i) count += b.messages[i].type == type && pred(b.messages[i].body) ? 1 : 0;
    return count;
  };
  auto any = [](const Json&) { return true; };
  EXPECT_EQ(after_cut(MessageType::kReport, any), 0u);
  EXPECT_EQ(after_cut(MessageType::kExecutionProgress, any), 0u);
  EXPECT_EQ(after_cut(MessageType::kConsoleOutput, [](const Json& j) {
              const std::string text = j["text"].get<std::string>();
              return text.rfind("report ", 0) == 0 || text.rfind("execution ", 0) == 0;
            }), 0u);
  EXPECT_TRUE((*stopped)["report"].is_object());  // the report is still the state
  // A browser connecting now gets the execution's last progress as state (marked as a replay).
  {
    Browser late((*op_service)->port());
    ASSERT_TRUE(late.Ready());
    auto progress = late.WaitMessage(MessageType::kExecutionProgress, [](const Json&) { return true; }, 0, 2);
    ASSERT_TRUE(progress.has_value());
    EXPECT_TRUE(progress->value("replay", false));
    EXPECT_NE((*progress)["state"], "running");
  }
  Json resume = b.Command("resume");
  EXPECT_TRUE(resume["ok"].get<bool>()) << resume["text"];
  ASSERT_TRUE(b.WaitWorld([](const Json& j) { return j["link"]["state"] == "up" && !j["link"]["stopped"].get<bool>(); }, 5));
  (*op_service)->Stop();
  site->Stop();
  std::filesystem::remove_all(sessions);
}

TEST(OperatorLink, WorkSiteStreamsCameraFramesAtFiveHertz) {
  net::SteadyClock clock;
  auto site = StartWorksite(clock, 1.0, worksite::WorksiteServiceOptions{}.camera_period_s);
  Browser b(site->port(), kToken);
  ASSERT_TRUE(b.WaitFor([&] { return !b.frames.empty(); }, 10));
  const std::size_t first = b.frames.size();
  const auto t0 = std::chrono::steady_clock::now();
  b.loop.RunFor(std::chrono::seconds(3));
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double hz = static_cast<double>(b.frames.size() - first) / s;
  std::printf("camera frames: %.1f Hz, render %.0f ms\n", hz, site->stats().last_render_ms);
  // The rate is a speed goal measured in Release; the sanitizer build (3-10x slower rendering)
  // checks only that the stream flows.
  EXPECT_GE(hz, std::getenv("TEACHSIM_SANITIZER_BUILD") ? 0.5 : 5.0);
  const net::BinaryFrame& f = b.frames.back();
  EXPECT_EQ(f.header.width, 320u);  // the stream's half scale of the 640x480 camera
  EXPECT_EQ(f.header.height, 240u);
  EXPECT_EQ(f.header.format, net::PixelFormat::kGray8);
  // Not a blank image: the table, frame and blocks give contrast.
  int lo = 255, hi = 0;
  for (std::uint8_t p : f.pixels) {
    lo = std::min<int>(lo, p);
    hi = std::max<int>(hi, p);
  }
  EXPECT_GT(hi - lo, 60);
  EXPECT_GE(b.Count(MessageType::kRobotState), std::getenv("TEACHSIM_SANITIZER_BUILD") ? 5u : 40u);  // ~20 Hz
}

// A stand-in work site that announces the puzzle scene and a fixed set of recognitions.
struct FakeSite : net::ServerHandler {
  net::EventLoop loop;
  net::SteadyClock clock;
  scene::Scene scene = Puzzle();
  Json recognitions;
  std::unique_ptr<net::Server> server;
  std::unique_ptr<net::LoopThread> thread;

  explicit FakeSite(Json objects) : recognitions{{"frame_seq", 0}, {"camera", 0}, {"objects", std::move(objects)}} {
    net::ServerOptions o;
    o.token = kToken;
    server = std::make_unique<net::Server>(loop, clock, o, *this);
    EXPECT_TRUE(server->Start().ok());
    thread = std::make_unique<net::LoopThread>(loop);
  }
  ~FakeSite() override {
    std::promise<void> done;
    loop.Post([&] {
      server->Stop();
      done.set_value();
    });
    done.get_future().wait();
    thread.reset();
  }
  void OnOpen(net::Server& s, net::SessionId session) override {
    (void)s.Send(session, MessageType::kWorksiteScene,
                 {{"scene", scene::SceneToJson(scene)}, {"models", worksite::ModelsFromScene(scene)}});
    (void)s.Send(session, MessageType::kRecognitions, recognitions);
  }
};

Json Recognition(const std::string& model, double x, double y, double z) {
  return {{"model", model}, {"world_T_object", PoseJson(x, y, z)}, {"score", 0.8}};
}

TEST(OperatorLink, TheModelEditorRestsCorrectsAddsAndRefusesRecognitions) {
  // 0: the cube seen 0.8 mm off and sunk 0.5 mm into the table; 1: a bar where the model has
  // nothing, hovering 3 mm; 2: a cube inside the plate.
  FakeSite site(Json::array({Recognition("cube45", 0.0308, 0.02, 0.02275 - 0.0005),
                             Recognition("bar90", 0.0, 0.2, 0.02275 + 0.003),
                             Recognition("cube45", 0.19, -0.09, 0.02)}));
  net::SteadyClock clock;
  OperatorOptions o;
  o.http_port = 0;
  o.worksite = "127.0.0.1:" + std::to_string(site.server->port());
  o.token = kToken;
  auto op_service = OperatorService::Create(clock, o);
  ASSERT_TRUE(op_service.ok()) << op_service.status().message();
  ASSERT_TRUE((*op_service)->Start().ok());
  Browser b((*op_service)->port());
  ASSERT_TRUE(b.Ready());
  ASSERT_TRUE(b.WaitWorld([](const Json& j) { return j["objects"].size() == 7 && !j["models"].empty(); }).has_value());
  ASSERT_TRUE(b.WaitMessage(MessageType::kRecognitions, [](const Json& j) { return j["objects"].size() == 3; }).has_value());
  ASSERT_TRUE(b.TakeLease());

  // The cube seen again: its pose is corrected (no duplicate), resting 0.25 mm above the table.
  Json out = b.Command("add 0");
  ASSERT_TRUE(out["ok"].get<bool>()) << out["text"];
  EXPECT_EQ(out["text"].get<std::string>().rfind("updated cube from recognition 0", 0), 0u) << out["text"];
  EXPECT_NE(out["text"].get<std::string>().find("resting on table"), std::string::npos) << out["text"];
  auto w = b.WaitWorld([](const Json& j) { return FindObject(j, "cube") && (*FindObject(j, "cube"))["origin"] == "recognized"; });
  ASSERT_TRUE(w.has_value());
  EXPECT_EQ((*w)["objects"].size(), 7u);
  const Json& cube = (*FindObject(*w, "cube"))["world_T_object"]["position"];
  EXPECT_NEAR(cube[0].get<double>(), 0.0308, 1e-9);
  EXPECT_NEAR(cube[2].get<double>(), 0.0225 + 0.25e-3, 1e-9);

  // Nothing of that model there: a new movable object, resting on the table.
  out = b.Command("add 1");
  ASSERT_TRUE(out["ok"].get<bool>()) << out["text"];
  EXPECT_EQ(out["text"].get<std::string>().rfind("added bar90_1 ", 0), 0u) << out["text"];
  w = b.WaitWorld([](const Json& j) { return FindObject(j, "bar90_1") != nullptr; });
  ASSERT_TRUE(w.has_value());
  const Json& bar = *FindObject(*w, "bar90_1");
  EXPECT_EQ(bar["origin"], "recognized");
  EXPECT_FALSE(bar["fixed"].get<bool>());
  EXPECT_NEAR(bar["world_T_object"]["position"][2].get<double>(), 0.0225 + 0.25e-3, 1e-9);

  // Inside the plate: refused, naming it; the model is unchanged.
  const std::uint64_t revision = (*op_service)->snapshot().revision;
  out = b.Command("add 2");
  EXPECT_FALSE(out["ok"].get<bool>());
  EXPECT_NE(out["text"].get<std::string>().find("plate"), std::string::npos) << out["text"];
  EXPECT_EQ((*op_service)->snapshot().objects.size(), 8u);
  EXPECT_EQ((*op_service)->snapshot().revision, revision);
  // Indices out of range and read-only watchers are refused too.
  EXPECT_FALSE(b.Command("add 3")["ok"].get<bool>());
  Browser watcher((*op_service)->port());
  ASSERT_TRUE(watcher.Ready());
  EXPECT_EQ(watcher.Command("add 1")["text"].get<std::string>().rfind("read-only", 0), 0u);
  (*op_service)->Stop();
}

}  // namespace
}  // namespace teachsim::op
