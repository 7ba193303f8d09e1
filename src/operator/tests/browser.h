// A browser stand-in for the service tests: a net::Client on its own event loop, run by the test
// thread, recording what the operator site sends.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "teachsim/net/client.h"

namespace teachsim::op::testing {

using json::Json;
using net::MessageType;

struct Browser : net::ClientHandler {
  net::EventLoop loop;
  net::SteadyClock clock;
  std::unique_ptr<net::Client> client;
  std::vector<net::Message> messages;
  std::vector<net::BinaryFrame> frames;
  std::vector<Status> closes;
  std::function<void(const net::Message&)> on_message;

  explicit Browser(std::uint16_t port, net::Token token = {}, std::string path = "/ws") {
    net::ClientOptions co;
    co.port = port;
    co.path = std::move(path);
    co.token = std::move(token);
    co.name = "test-browser";
    client = std::make_unique<net::Client>(loop, clock, co, *this);
    client->Connect();
  }
  ~Browser() override {
    client->Close();
    loop.RunFor(std::chrono::milliseconds(20));
    client.reset();
  }

  void OnMessage(net::Client&, const net::Message& m) override {
    messages.push_back(m);
    if (on_message) on_message(m);
  }
  void OnFrame(net::Client&, const net::BinaryFrame& f) override { frames.push_back(f); }
  void OnClose(net::Client&, const Status& s) override { closes.push_back(s); }

  bool WaitFor(const std::function<bool()>& done, double seconds = 5) {
    return loop.RunUntil(done, net::FromSeconds(seconds));
  }
  std::size_t Count(MessageType type) const {
    std::size_t n = 0;
    for (const auto& m : messages) n += m.type == type ? 1 : 0;
    return n;
  }
  std::optional<Json> Last(MessageType type) const {
    for (auto it = messages.rbegin(); it != messages.rend(); ++it) {
      if (it->type == type) return it->body;
    }
    return std::nullopt;
  }
  // Waits until a message of `type` satisfying `pred` arrives after index `from`.
  std::optional<Json> WaitMessage(MessageType type, const std::function<bool(const Json&)>& pred, std::size_t from = 0,
                                  double seconds = 5) {
    std::optional<Json> found;
    WaitFor([&] {
      for (std::size_t i = from; i < messages.size(); ++i) {
        if (messages[i].type == type && pred(messages[i].body)) {
          found = messages[i].body;
          return true;
        }
      }
      return false;
    }, seconds);
    return found;
  }
  bool Ready() { return WaitFor([&] { return Count(MessageType::kWorldState) > 0 && client->session().has_value(); }); }
  bool TakeLease() {
    if (!client->Send(MessageType::kLeaseRequest).ok()) return false;
    return WaitMessage(MessageType::kLeaseGrant, [](const Json& j) { return j["granted"].get<bool>(); }).has_value();
  }
  std::uint64_t SendGetSeq(MessageType type, Json fields = Json::object()) {
    if (!client->Send(type, std::move(fields)).ok()) return 0;
    return client->stats().sent;  // the frame just numbered (all on this thread)
  }
  // Sends a console command and returns its console_output.
  Json Command(const std::string& line, double seconds = 10) {
    const std::uint64_t seq = SendGetSeq(MessageType::kConsoleCommand, {{"line", line}});
    auto out = WaitMessage(MessageType::kConsoleOutput,
                           [&](const Json& j) { return j.contains("in_reply_to") && j["in_reply_to"] == seq; }, 0, seconds);
    return out ? *out : Json{{"text", "(no answer)"}, {"ok", false}};
  }
  std::optional<Json> WaitWorld(const std::function<bool(const Json&)>& pred, double seconds = 10) {
    return WaitMessage(MessageType::kWorldState, pred, 0, seconds);
  }
};

inline Json PoseJson(double x, double y, double z) {
  return {{"position", {x, y, z}}, {"quaternion_wxyz", {1.0, 0.0, 0.0, 0.0}}};
}

inline const Json* FindObject(const Json& world_state, const std::string& name) {
  for (const Json& o : world_state["objects"]) {
    if (o["name"] == name) return &o;
  }
  return nullptr;
}

}  // namespace teachsim::op::testing
