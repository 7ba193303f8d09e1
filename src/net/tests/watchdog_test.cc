#include "teachsim/net/watchdog.h"

#include <gtest/gtest.h>

#include "teachsim/net/peer.h"

namespace teachsim::net {
namespace {

using json::Json;

TEST(Watchdog, SilenceBeyondTheTimeoutIsLostOnceThenTrafficRestores) {
  ManualClock clock;
  LinkWatchdog dog(clock, WatchdogOptions{0.25});
  EXPECT_EQ(dog.state(), LinkState::kIdle);
  EXPECT_FALSE(dog.Check());  // no link yet: nothing to lose
  EXPECT_FALSE(dog.OnConnected());
  EXPECT_EQ(dog.state(), LinkState::kUp);
  // Heartbeats every 50 ms keep it up indefinitely.
  for (int i = 0; i < 100; ++i) {
    clock.AdvanceSeconds(0.05);
    EXPECT_FALSE(dog.OnReceived());
    EXPECT_FALSE(dog.Check());
  }
  // Then silence: still up at exactly 250 ms, lost just after.
  clock.AdvanceSeconds(0.25);
  EXPECT_FALSE(dog.Check());
  clock.AdvanceSeconds(0.001);
  std::optional<LinkEvent> lost = dog.Check();
  ASSERT_TRUE(lost);
  EXPECT_EQ(lost->kind, LinkEvent::Kind::kLost);
  EXPECT_NEAR(lost->silent_s, 0.251, 1e-9);
  EXPECT_EQ(lost->reason, "silent for 0.251 s");
  EXPECT_EQ(dog.state(), LinkState::kLost);
  clock.AdvanceSeconds(1.0);
  EXPECT_FALSE(dog.Check());  // reported once, not on every check
  std::optional<LinkEvent> restored = dog.OnReceived();
  ASSERT_TRUE(restored);
  EXPECT_EQ(restored->kind, LinkEvent::Kind::kRestored);
  EXPECT_EQ(dog.state(), LinkState::kUp);
}

TEST(Watchdog, DisconnectIsLostAtOnceAndReconnectRestores) {
  ManualClock clock;
  LinkWatchdog dog(clock, WatchdogOptions{0.25});
  (void)dog.OnConnected();
  clock.AdvanceSeconds(0.01);
  std::optional<LinkEvent> lost = dog.OnDisconnected();
  ASSERT_TRUE(lost);
  EXPECT_EQ(lost->reason, "disconnected");
  EXPECT_FALSE(dog.OnDisconnected());
  EXPECT_FALSE(dog.Check());
  std::optional<LinkEvent> restored = dog.OnConnected();
  ASSERT_TRUE(restored);
  EXPECT_EQ(restored->kind, LinkEvent::Kind::kRestored);
  EXPECT_EQ(restored->reason, "reconnected");
}

TEST(Watchdog, DetectionLatencyIsTheTimeoutPlusAtMostOneCheckPeriod) {
  // The watchdog is checked every heartbeat period (50 ms); wherever the silence starts within
  // a period, it is reported within timeout + one period.
  for (int offset_ms = 0; offset_ms < 50; offset_ms += 7) {
    ManualClock clock;
    LinkWatchdog dog(clock, WatchdogOptions{0.25});
    (void)dog.OnConnected();
    clock.AdvanceSeconds(offset_ms * 1e-3);
    (void)dog.OnReceived();  // last sign of life
    double elapsed = 0;
    clock.AdvanceSeconds((50 - offset_ms) * 1e-3);  // to the next check
    elapsed += (50 - offset_ms) * 1e-3;
    while (!dog.Check()) {
      clock.AdvanceSeconds(0.05);
      elapsed += 0.05;
      ASSERT_LT(elapsed, 1.0);
    }
    EXPECT_GT(elapsed, 0.25);
    EXPECT_LE(elapsed, 0.25 + 0.05 + 1e-9) << "offset " << offset_ms << " ms";
  }
}

// The checking thread starved for a second (a busy machine, a long handler before the timer's):
// the late check does not call the link lost, since heartbeats may be waiting in the socket behind
// it; read, they keep the link up. With nothing waiting, the next check, a period later, reports the
// loss.
TEST(Watchdog, AStarvedCheckerDefersTheVerdictToItsNextCheck) {
  for (bool heartbeats_waiting : {true, false}) {
    ManualClock clock;
    LinkWatchdog dog(clock, WatchdogOptions{0.25});
    (void)dog.OnConnected();
    for (int i = 0; i < 4; ++i) {
      clock.AdvanceSeconds(0.05);
      (void)dog.OnReceived();
      EXPECT_FALSE(dog.Check());
    }
    clock.AdvanceSeconds(1.0);
    EXPECT_FALSE(dog.Check()) << "a check a second late must not decide";
    EXPECT_EQ(dog.state(), LinkState::kUp);
    if (heartbeats_waiting) {
      EXPECT_FALSE(dog.OnReceived());
    }
    clock.AdvanceSeconds(0.05);
    const std::optional<LinkEvent> next = dog.Check();
    if (heartbeats_waiting) {
      EXPECT_FALSE(next);
      EXPECT_EQ(dog.state(), LinkState::kUp);
    } else {
      ASSERT_TRUE(next);
      EXPECT_EQ(next->kind, LinkEvent::Kind::kLost);
      EXPECT_NEAR(next->silent_s, 1.05, 1e-9);
    }
  }
}

TEST(Watchdog, OptionsAreValidated) {
  EXPECT_FALSE(WatchdogOptions{0.0}.Validate().ok());
  EXPECT_FALSE(WatchdogOptions{-1.0}.Validate().ok());
  EXPECT_TRUE(WatchdogOptions{0.25}.Validate().ok());
}

// Two Peers wired back to back: the whole message layer without sockets.
TEST(Peer, HeartbeatsMeasureRoundTripWithAManualClock) {
  ManualClock clock;
  Peer a(clock, PeerOptions{}), b(clock, PeerOptions{});
  (void)a.OnConnected();
  (void)b.OnConnected();
  OutFrame ha = a.Heartbeat();
  clock.AdvanceSeconds(0.004);  // a -> b takes 4 ms
  Incoming at_b = b.OnText(ha.data);
  ASSERT_TRUE(at_b.message);
  EXPECT_TRUE(at_b.replies.empty());
  clock.AdvanceSeconds(0.030);  // b holds the echo 30 ms until its own heartbeat
  OutFrame hb = b.Heartbeat();
  clock.AdvanceSeconds(0.006);  // b -> a takes 6 ms
  Incoming at_a = a.OnText(hb.data);
  ASSERT_TRUE(at_a.message);
  ASSERT_TRUE(a.stats().rtt_s.has_value());
  EXPECT_NEAR(*a.stats().rtt_s, 0.010, 1e-9);
}

TEST(Peer, RefusedMessagesAreAnsweredAndTheNextOneIsAccepted) {
  ManualClock clock;
  Peer a(clock, PeerOptions{}), b(clock, PeerOptions{});
  Incoming bad = b.OnText(R"({"type": "console_command", "seq": 1})");
  ASSERT_TRUE(bad.error);
  ASSERT_EQ(bad.replies.size(), 1u);
  Incoming reply = a.OnText(bad.replies[0].data);
  ASSERT_TRUE(reply.message);
  EXPECT_EQ(reply.message->type, MessageType::kError);
  EXPECT_EQ(reply.message->body["code"], "invalid_field");
  EXPECT_EQ(reply.message->body["message"], "console_command.line: missing");
  EXPECT_EQ(reply.message->body["in_reply_to"], 1);
  // The refused message used up seq 1, so seq 2 is in order: no gap reported.
  Incoming good = b.OnText(R"({"type": "console_command", "seq": 2, "line": "help"})");
  ASSERT_TRUE(good.message);
  EXPECT_TRUE(good.replies.empty());
  EXPECT_EQ(b.stats().refused, 1u);
}

TEST(Peer, GapsAreReportedAndDuplicatesDropped) {
  ManualClock clock;
  Peer b(clock, PeerOptions{});
  ASSERT_TRUE(b.OnText(R"({"type": "reset_world", "seq": 1})").message);
  Incoming gap = b.OnText(R"({"type": "reset_world", "seq": 4})");
  ASSERT_TRUE(gap.message);  // still delivered
  ASSERT_EQ(gap.replies.size(), 1u);
  Json reply = Json::parse(gap.replies[0].data);
  EXPECT_EQ(reply["code"], "seq_gap");
  EXPECT_EQ(reply["message"], "seq: expected 2, got 4 (2 missing)");
  Incoming dup = b.OnText(R"({"type": "reset_world", "seq": 4})");
  EXPECT_FALSE(dup.message);  // dropped
  ASSERT_TRUE(dup.error);
  EXPECT_EQ(dup.error->code, "duplicate_seq");
  EXPECT_EQ(b.stats().seq_gaps, 1u);
  EXPECT_EQ(b.stats().seq_duplicates, 1u);
}

TEST(Peer, OutgoingMessagesAreNumberedAndBadOnesNotSent) {
  ManualClock clock;
  Peer a(clock, PeerOptions{});
  Result<OutFrame> first = a.Encode(MessageType::kResetWorld);
  ASSERT_TRUE(first.ok());
  Result<OutFrame> bad = a.Encode(MessageType::kConsoleCommand, {{"line", 42}});
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "console_command.line: must be a string, got number");
  Result<OutFrame> second = a.Encode(MessageType::kConsoleCommand, {{"line", "help"}});
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(Json::parse(first->data)["seq"], 1);
  EXPECT_EQ(Json::parse(second->data)["seq"], 2);  // the refused one took no number
}

}  // namespace
}  // namespace teachsim::net
