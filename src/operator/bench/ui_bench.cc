// teachsim bench ui: the latency the person feels while dragging (issue 8): a dragger_input sent by
// a WebSocket client on loopback -> the operator site -> the simulator thread steps with it ->
// the pose_update carrying that input's seq arrives back at the client. Median and p99 while the
// simulator runs at its wall-clock rate, with the mouse moving at 50 Hz as a browser sends it.
// The peer figure: the plain round trip of a console command on the same connection (the
// transport's floor, no simulator in the way).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>

#include "teachsim/base/bench_registry.h"
#include "teachsim/net/client.h"
#include "teachsim/operator/service.h"

namespace teachsim::op {
namespace {

using json::Json;
using net::MessageType;
using Clock = std::chrono::steady_clock;

struct Collector : net::ClientHandler {
  std::map<std::uint64_t, Clock::time_point> sent;  // dragger_input seq -> when sent
  std::vector<double> latency_ms, console_ms;
  std::map<std::uint64_t, Clock::time_point> console_sent;
  std::uint64_t last_input_seq = 0;
  double sim_rate_hz = 0;
  bool world = false, granted = false;
  Json cube_pose;
  void OnMessage(net::Client&, const net::Message& m) override {
    const auto now = Clock::now();
    if (m.type == MessageType::kWorldState) {
      world = true;
      for (const Json& o : m.body["objects"]) {
        if (o["name"] == "cube") cube_pose = o["world_T_object"];
      }
    } else if (m.type == MessageType::kLeaseGrant) {
      granted = m.body["granted"].get<bool>();
    } else if (m.type == MessageType::kPoseUpdate && m.body.contains("input_seq")) {
      const std::uint64_t seq = m.body["input_seq"].get<std::uint64_t>();
      sim_rate_hz = m.body.value("sim_rate_hz", 0.0);
      if (seq != last_input_seq) {  // the first update that used this input
        last_input_seq = seq;
        auto it = sent.find(seq);
        if (it != sent.end()) latency_ms.push_back(std::chrono::duration<double, std::milli>(now - it->second).count());
      }
    } else if (m.type == MessageType::kConsoleOutput && m.body.contains("in_reply_to")) {
      auto it = console_sent.find(m.body["in_reply_to"].get<std::uint64_t>());
      if (it != console_sent.end()) console_ms.push_back(std::chrono::duration<double, std::milli>(now - it->second).count());
    }
  }
};

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

int RunUiBench(const BenchArgs& args) {
  auto scene = scene::LoadScene(std::string(TEACHSIM_BENCH_SOURCE_DIR) + "/scenes/puzzle.json");
  if (!scene.ok()) {
    std::fprintf(stderr, "%s\n", scene.status().message().c_str());
    return 2;
  }
  net::SteadyClock clock;
  OperatorOptions o;
  o.http_port = 0;
  o.initial_scene = *scene;
  o.sessions_dir = "/tmp/teachsim-ui-bench-sessions";
  auto service = OperatorService::Create(clock, o);
  if (!service.ok() || !(*service)->Start().ok()) {
    std::fprintf(stderr, "ui bench: cannot start the operator site\n");
    return 1;
  }
  net::EventLoop loop;
  Collector c;
  net::ClientOptions co;
  co.port = (*service)->port();
  co.name = "ui-bench";
  net::Client client(loop, clock, co, c);
  client.Connect();
  if (!loop.RunUntil([&] { return c.world && client.session().has_value(); }, std::chrono::seconds(5)) ||
      !client.Send(MessageType::kLeaseRequest).ok() || !loop.RunUntil([&] { return c.granted; }, std::chrono::seconds(5))) {
    std::fprintf(stderr, "ui bench: no session or lease\n");
    return 1;
  }
  const int moves = args.quick ? 150 : 1000;
  const double x0 = c.cube_pose["position"][0], y0 = c.cube_pose["position"][1], z = c.cube_pose["position"][2];
  auto pose = [&](double x, double y) {
    return Json{{"position", {x, y, z}}, {"quaternion_wxyz", c.cube_pose["quaternion_wxyz"]}};
  };
  (void)client.Send(MessageType::kDraggerInput, {{"object", "cube"}, {"phase", "begin"}, {"world_T_dragger", c.cube_pose}});
  // The mouse circles inside the frame (radius 30 mm about the middle), touching nothing hard:
  // contacts are exercised by the tests; here the path the person's input takes is measured.
  auto next = Clock::now();
  for (int i = 1; i <= moves; ++i) {
    const double a = 2 * M_PI * i / 100.0;
    const double x = 0.5 * x0 + 0.03 * std::cos(a), y = 0.5 * y0 + 0.03 * std::sin(a);
    if (!client.Send(MessageType::kDraggerInput, {{"object", "cube"}, {"phase", "move"}, {"world_T_dragger", pose(x, y)}}).ok()) break;
    c.sent[client.stats().sent] = Clock::now();
    if (i % 10 == 0 && client.Send(MessageType::kConsoleCommand, {{"line", "help"}}).ok()) {
      c.console_sent[client.stats().sent] = Clock::now();
    }
    next += std::chrono::milliseconds(20);
    loop.RunUntil([&] { return Clock::now() >= next; }, std::chrono::milliseconds(25));
  }
  (void)client.Send(MessageType::kDraggerInput, {{"object", "cube"}, {"phase", "end"}, {"world_T_dragger", c.cube_pose}});
  loop.RunFor(std::chrono::milliseconds(200));
  const double median = Percentile(c.latency_ms, 0.5), p99 = Percentile(c.latency_ms, 0.99);
  const double console_median = Percentile(c.console_ms, 0.5), console_p99 = Percentile(c.console_ms, 0.99);
  client.Close();
  loop.RunFor(std::chrono::milliseconds(20));
  (*service)->Stop();
  if (args.json) {
    Json doc = {{"bench", "ui"},
                {"moves_sent", moves},
                {"moves_measured", c.latency_ms.size()},
                {"drag_to_pose_ms", {{"median", median}, {"p99", p99}}},
                {"console_round_trip_ms", {{"median", console_median}, {"p99", console_p99}}},
                {"sim_rate_hz", c.sim_rate_hz},
                {"goal_median_ms", 20.0}};
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    std::printf("ui: dragger_input -> pose_update over loopback WebSocket, simulator running\n");
    std::printf("  %zu of %d moves measured\n", c.latency_ms.size(), moves);
    std::printf("  drag -> pose     median %6.2f ms   p99 %6.2f ms   (goal: median <= 20 ms)\n", median, p99);
    std::printf("  console echo     median %6.2f ms   p99 %6.2f ms   (peer: the transport alone)\n", console_median,
                console_p99);
    std::printf("  simulator        %.0f steps/s wall clock\n", c.sim_rate_hz);
  }
  return c.latency_ms.empty() ? 1 : 0;
}

TEACHSIM_BENCH("ui", "dragger input -> pose update latency over loopback WebSocket while the simulator runs", RunUiBench);

}  // namespace
}  // namespace teachsim::op
