// The link watchdog over real sockets: deterministic with a manual clock (timers off, Tick() by
// hand), and once with real time over loopback.
#include <gtest/gtest.h>

#include <cstdlib>

#include "loopback.h"

namespace teachsim::net {
namespace {

using json::Json;
using namespace testing;

constexpr auto kWait = 5s;

TEST(Link, ServerWatchdogWithAManualClockIsDeterministic) {
  EventLoop loop;
  ManualClock clock;
  ServerRecorder server_events;
  ServerOptions so;
  so.heartbeat_period_s = 0;  // no timers: this test decides when time passes
  so.link_timeout_s = 0.25;
  Server server(loop, clock, so, server_events);
  ASSERT_TRUE(server.Start().ok());
  ClientRecorder events;
  ClientOptions co;
  co.port = server.port();
  co.heartbeat_period_s = 0;
  Client client(loop, clock, co, events);
  client.Connect();
  ASSERT_TRUE(loop.RunUntil([&] { return client.session().has_value() && !server_events.messages.empty(); }, kWait));
  SessionId id = *client.session();

  // Heartbeats every 50 ms of manual time: never lost.
  for (int i = 0; i < 20; ++i) {
    clock.AdvanceSeconds(0.05);
    client.Tick();
    std::size_t received = server.Info(id)->stats.received;
    ASSERT_TRUE(loop.RunUntil([&] { return server.Info(id)->stats.received > received; }, kWait));
    server.Tick();
  }
  EXPECT_TRUE(server_events.link_events.empty());
  // Silence: 250 ms is still fine, 251 ms is lost, reported once.
  clock.AdvanceSeconds(0.25);
  server.Tick();
  EXPECT_EQ(server_events.CountLinks(id, LinkEvent::Kind::kLost), 0u);
  clock.AdvanceSeconds(0.001);
  server.Tick();
  ASSERT_EQ(server_events.CountLinks(id, LinkEvent::Kind::kLost), 1u);
  EXPECT_NEAR(server_events.link_events.back().second.silent_s, 0.251, 1e-9);
  server.Tick();
  EXPECT_EQ(server_events.CountLinks(id, LinkEvent::Kind::kLost), 1u);
  EXPECT_EQ(server.Info(id)->link, LinkState::kLost);
  // The client speaks again: restored.
  client.Tick();
  ASSERT_TRUE(loop.RunUntil([&] { return server_events.CountLinks(id, LinkEvent::Kind::kRestored) == 1; }, kWait));
  EXPECT_EQ(server.Info(id)->link, LinkState::kUp);

  // The client's own watchdog: the server falls silent.
  server.Tick();
  std::size_t heard = client.stats().received;
  ASSERT_TRUE(loop.RunUntil([&] { return client.stats().received > heard; }, kWait));
  client.Tick();
  ASSERT_EQ(client.link(), LinkState::kUp);
  std::size_t before = events.link_events.size();
  clock.AdvanceSeconds(0.25);
  client.Tick();
  EXPECT_EQ(events.link_events.size(), before);
  clock.AdvanceSeconds(0.001);
  client.Tick();
  ASSERT_EQ(events.link_events.size(), before + 1);
  EXPECT_EQ(events.link_events.back().kind, LinkEvent::Kind::kLost);
  EXPECT_EQ(client.link(), LinkState::kLost);
}

TEST(Link, CutClientIsSeenLostWithinTimeoutPlusOneHeartbeatOverLoopback) {
  EventLoop loop;
  SteadyClock clock;
  ServerRecorder server_events;
  ServerOptions so;
  so.heartbeat_period_s = 0.05;
  so.link_timeout_s = 0.25;
  Server server(loop, clock, so, server_events);
  ASSERT_TRUE(server.Start().ok());
  ClientRecorder events;
  ClientOptions co;
  co.port = server.port();
  co.heartbeat_period_s = 0.05;
  Client client(loop, clock, co, events);
  client.Connect();
  ASSERT_TRUE(loop.RunUntil([&] { return client.session().has_value(); }, kWait));
  SessionId id = *client.session();
  // A healthy link stays up for a while (20 Hz heartbeats both ways).
  loop.RunFor(400ms);
  EXPECT_EQ(server_events.CountLinks(id, LinkEvent::Kind::kLost), 0u);
  EXPECT_GE(server.Info(id)->stats.received, 5u);

  // Cut the client's traffic without closing the socket, like a pulled cable.
  std::uint64_t received = server.Info(id)->stats.received;
  client.PauseHeartbeats(true);
  // The moment of silence is the client's last frame's arrival; measure from the pause, which is
  // no earlier, so the bound holds a fortiori.
  auto cut = std::chrono::steady_clock::now();
  ASSERT_TRUE(loop.RunUntil([&] { return server_events.CountLinks(id, LinkEvent::Kind::kLost) == 1; }, kWait));
  double detected_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - cut).count();
  std::printf("link lost detected %.1f ms after the cut (bound 300 ms), %llu frames before\n", detected_s * 1e3,
              static_cast<unsigned long long>(received));
  // + scheduling slack for a loaded 2-core machine (more under the sanitizers, which slow timers).
  const double slack_s = std::getenv("TEACHSIM_SANITIZER_BUILD") != nullptr ? 0.15 : 0.03;
  EXPECT_LE(detected_s, 0.25 + 0.05 + slack_s);
  EXPECT_GE(detected_s, 0.25 - 0.05 - 0.01);  // not before the timeout (the last heartbeat may be 50 ms old)

  // Traffic again: restored on the same session.
  client.PauseHeartbeats(false);
  ASSERT_TRUE(loop.RunUntil([&] { return server_events.CountLinks(id, LinkEvent::Kind::kRestored) == 1; }, kWait));

  // A hard cut (socket closed, no close frame): lost at once on the server, and on the client.
  client.Abort();
  ASSERT_TRUE(loop.RunUntil([&] { return server_events.CountLinks(id, LinkEvent::Kind::kLost) == 2; }, kWait));
  ASSERT_TRUE(loop.RunUntil([&] { return !events.closes.empty(); }, kWait));
  EXPECT_EQ(client.link(), LinkState::kLost);
  EXPECT_FALSE(client.connected());

  // Reconnect when asked: a new session, sequence numbers start again, link restored.
  client.Reconnect();
  ASSERT_TRUE(loop.RunUntil([&] { return client.session().has_value(); }, kWait));
  EXPECT_NE(*client.session(), id);
  EXPECT_EQ(client.link(), LinkState::kUp);
  ASSERT_FALSE(events.link_events.empty());
  EXPECT_EQ(events.link_events.back().kind, LinkEvent::Kind::kRestored);
  EXPECT_EQ(events.link_events.back().reason, "reconnected");
  EXPECT_EQ(events.OfType(MessageType::kWelcome).back().seq, 1u);
  EXPECT_TRUE(events.OfType(MessageType::kError).empty());
}

TEST(Link, SilentSessionsAreClosedEventually) {
  EventLoop loop;
  SteadyClock clock;
  ServerRecorder server_events;
  ServerOptions so;
  so.heartbeat_period_s = 0.02;
  so.link_timeout_s = 0.05;
  so.close_after_silence_s = 0.2;
  Server server(loop, clock, so, server_events);
  ASSERT_TRUE(server.Start().ok());
  ClientRecorder events;
  ClientOptions co;
  co.port = server.port();
  co.heartbeat_period_s = 0.02;
  co.link_timeout_s = 0.05;
  Client client(loop, clock, co, events);
  client.Connect();
  ASSERT_TRUE(loop.RunUntil([&] { return client.session().has_value(); }, kWait));
  client.PauseHeartbeats(true);
  ASSERT_TRUE(loop.RunUntil([&] { return server_events.closed.size() == 1; }, kWait));
  ASSERT_TRUE(loop.RunUntil([&] { return !events.closes.empty(); }, kWait));
}

TEST(Link, ConnectingToNothingFailsCleanly) {
  EventLoop loop;
  SteadyClock clock;
  ClientRecorder events;
  ClientOptions co;
  {
    // A port that was just free: bind, note it, close.
    ServerRecorder ignored;
    Server probe(loop, clock, ServerOptions{}, ignored);
    ASSERT_TRUE(probe.Start().ok());
    co.port = probe.port();
  }
  Client client(loop, clock, co, events);
  client.Connect();
  ASSERT_TRUE(loop.RunUntil([&] { return !events.closes.empty(); }, kWait));
  EXPECT_NE(events.closes[0].message().find("cannot connect"), std::string::npos) << events.closes[0].message();
  EXPECT_EQ(events.opens, 0);
  EXPECT_TRUE(events.link_events.empty());
}

TEST(Link, ListeningOnABusyPortNamesTheAddress) {
  EventLoop loop;
  SteadyClock clock;
  ServerRecorder a_events, b_events;
  Server a(loop, clock, ServerOptions{}, a_events);
  ASSERT_TRUE(a.Start().ok());
  ServerOptions o;
  o.port = a.port();
  Server b(loop, clock, o, b_events);
  Status s = b.Start();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("127.0.0.1:" + std::to_string(a.port()) + ": cannot listen"), std::string::npos) << s.message();
  o.host = "localhost.invalid";
  EXPECT_FALSE(Server(loop, clock, o, b_events).Start().ok());
}

}  // namespace
}  // namespace teachsim::net

namespace teachsim::net {
namespace {

TEST(Url, WebSocketUrlsAndHostPort) {
  Result<WebSocketUrl> a = ParseWebSocketUrl("ws://127.0.0.1:9000/link");
  ASSERT_TRUE(a.ok()) << a.status().message();
  EXPECT_EQ(a->host, "127.0.0.1");
  EXPECT_EQ(a->port, 9000);
  EXPECT_EQ(a->path, "/link");
  Result<WebSocketUrl> b = ParseWebSocketUrl("worksite.lan:8765");
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->host, "worksite.lan");
  EXPECT_EQ(b->path, "/ws");
  Result<WebSocketUrl> c = ParseWebSocketUrl("ws://[::1]:80/ws");
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->host, "::1");
  for (const char* bad : {"http://x:1/", "x", "x:", ":80", "x:0", "x:65536", "x:80a", "ws://[::1]/ws"}) {
    Result<WebSocketUrl> r = ParseWebSocketUrl(bad);
    EXPECT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.status().message().find(std::string("\"") + bad + "\""), std::string::npos) << r.status().message();
  }
}

}  // namespace
}  // namespace teachsim::net
