// The work-site service on loopback with the net client: the token, refusals of malformed,
// oversized and invalid input, the state sent on connect, and the link watchdog stopping a moving
// robot is tested with the operator site (src/operator/tests/operator_link_test.cc).
#include <gtest/gtest.h>

#include <chrono>
#include <functional>

#include "teachsim/net/client.h"
#include "teachsim/robot/program.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/worksite/service.h"

namespace teachsim::worksite {
namespace {

using json::Json;
using net::MessageType;

const net::Token kToken("fedcba9876543210fedcba9876543210");

struct Peer : net::ClientHandler {
  net::EventLoop loop;
  net::SteadyClock clock;
  std::unique_ptr<net::Client> client;
  std::vector<net::Message> messages;
  std::vector<Status> closes;
  explicit Peer(std::uint16_t port, net::Token token) {
    net::ClientOptions co;
    co.port = port;
    co.token = std::move(token);
    client = std::make_unique<net::Client>(loop, clock, co, *this);
    client->Connect();
  }
  ~Peer() override {
    client->Close();
    loop.RunFor(std::chrono::milliseconds(20));
    client.reset();
  }
  void OnMessage(net::Client&, const net::Message& m) override { messages.push_back(m); }
  void OnClose(net::Client&, const Status& s) override { closes.push_back(s); }
  std::size_t Count(MessageType t) const {
    return static_cast<std::size_t>(std::count_if(messages.begin(), messages.end(), [&](const auto& m) { return m.type == t; }));
  }
  std::optional<Json> Wait(MessageType t, const std::function<bool(const Json&)>& pred, std::size_t from = 0, double s = 5) {
    std::optional<Json> found;
    loop.RunUntil([&] {
      for (std::size_t i = from; i < messages.size(); ++i) {
        if (messages[i].type == t && pred(messages[i].body)) {
          found = messages[i].body;
          return true;
        }
      }
      return false;
    }, net::FromSeconds(s));
    return found;
  }
  bool Lease() {
    loop.RunUntil([&] { return client->session().has_value(); }, std::chrono::seconds(5));
    return client->Send(MessageType::kLeaseRequest).ok() &&
           Wait(MessageType::kLeaseGrant, [](const Json& j) { return j["granted"].get<bool>(); }).has_value();
  }
};

std::unique_ptr<WorksiteService> Start(const net::Clock& clock) {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok());
  auto model = robot::LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/" + scene->robot->model + ".json");
  EXPECT_TRUE(model.ok());
  WorksiteServiceOptions o;
  o.server.token = kToken;
  o.camera_period_s = 0;  // the camera stream has its own test (operator_link_test)
  o.recognize = false;
  auto site = WorksiteService::Create(clock, *scene, *model, o);
  EXPECT_TRUE(site.ok()) << site.status().message();
  EXPECT_TRUE((*site)->Start().ok());
  return std::move(site).value();
}

TEST(WorksiteService, WrongTokenGetsNothing) {
  net::SteadyClock clock;
  auto site = Start(clock);
  Peer wrong(site->port(), net::Token("0000000000000000000000000000000000"));
  ASSERT_TRUE(wrong.loop.RunUntil([&] { return !wrong.closes.empty(); }, std::chrono::seconds(5)));
  EXPECT_NE(wrong.closes[0].message().find("401"), std::string::npos) << wrong.closes[0].message();
  EXPECT_TRUE(wrong.messages.empty());
}

TEST(WorksiteService, ConnectGivesSceneLinkAndRobotStateAndBadInputIsAnswered) {
  net::SteadyClock clock;
  auto site = Start(clock);
  Peer p(site->port(), kToken);
  ASSERT_TRUE(p.Wait(MessageType::kWorksiteScene, [](const Json&) { return true; }).has_value());
  Json scene = *p.Wait(MessageType::kWorksiteScene, [](const Json&) { return true; });
  EXPECT_EQ(scene["scene"]["objects"].size(), 7u);
  EXPECT_EQ(scene["models"].size(), 5u);  // cube45, bar90, tall135, plate15, slab
  ASSERT_TRUE(p.Wait(MessageType::kLinkState, [](const Json& j) { return !j["stopped"].get<bool>(); }).has_value());
  p.loop.RunFor(std::chrono::milliseconds(1000));
  EXPECT_GE(p.Count(MessageType::kRobotState), 15u);  // 20 Hz
  ASSERT_TRUE(p.Lease());
  // Malformed, oversized, unknown type, wrong message for the site, invalid program.
  ASSERT_TRUE(p.client->SendRaw("{\"type\":", false).ok());
  EXPECT_TRUE(p.Wait(MessageType::kError, [](const Json& j) { return j["code"] == "malformed_json"; }).has_value());
  ASSERT_TRUE(p.client->SendRaw(std::string(1100000, 'a'), false).ok());
  EXPECT_TRUE(p.Wait(MessageType::kError, [](const Json& j) { return j["code"] == "too_large"; }).has_value());
  ASSERT_TRUE(p.client->Send(MessageType::kConsoleCommand, {{"line", "help"}}).ok());
  EXPECT_TRUE(p.Wait(MessageType::kError, [](const Json& j) { return j["code"] == "unexpected"; }).has_value());
  // Only verified programs cross the link: a malformed one is refused, nothing moves.
  ASSERT_TRUE(p.client->Send(MessageType::kProgramSubmit, {{"program_id", "bad"}, {"program", {{"commands", "many"}}}}).ok());
  EXPECT_TRUE(p.Wait(MessageType::kError, [](const Json& j) { return j["code"] == "invalid_program"; }).has_value());
  // Last: a raw message's seq (99) moves the server's expected seq past the client's own.
  ASSERT_TRUE(p.client->SendRaw("{\"type\": \"launch\", \"seq\": 99}", false).ok());
  EXPECT_TRUE(p.Wait(MessageType::kError, [](const Json& j) { return j["code"] == "unknown_type"; }).has_value());
  EXPECT_TRUE(p.client->connected());
  EXPECT_EQ(site->stats().programs_started, 0);
}

}  // namespace
}  // namespace teachsim::worksite
