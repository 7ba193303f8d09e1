#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "loopback.h"

namespace teachsim::net {
namespace {

using json::Json;
using namespace testing;
namespace fs = std::filesystem;

constexpr auto kWait = 5s;  // generous bound: a failing test ends, it never hangs
const std::string kSecret = "s3cr3t-t0ken-for-tests-0123456789";

ServerOptions QuietServer() {
  ServerOptions o;
  o.heartbeat_period_s = 0.05;
  return o;
}

ClientOptions ClientFor(const Server& server) {
  ClientOptions o;
  o.port = server.port();
  return o;
}

struct Harness {
  EventLoop loop;
  SteadyClock clock;
  ServerRecorder server_events;
  std::unique_ptr<Server> server;

  Status Start(ServerOptions options) {
    server = std::make_unique<Server>(loop, clock, std::move(options), server_events);
    return server->Start();
  }
  bool Until(const std::function<bool()>& done, Duration timeout = kWait) { return loop.RunUntil(done, timeout); }
};

TEST(Server, ListensOnLoopbackOnAnEphemeralPortAndTalks) {
  Harness h;
  ASSERT_TRUE(h.Start(QuietServer()).ok());
  EXPECT_NE(h.server->port(), 0);
  EXPECT_EQ(h.server->options().host, "127.0.0.1");
  ClientRecorder events;
  ClientOptions co = ClientFor(*h.server);
  co.name = "test-client";
  Client client(h.loop, h.clock, co, events);
  client.Connect();
  ASSERT_TRUE(h.Until([&] { return client.session().has_value() && !h.server_events.messages.empty(); }));
  // welcome first, with the session number; the hello reached the server handler.
  ASSERT_FALSE(events.messages.empty());
  EXPECT_EQ(events.messages[0].type, MessageType::kWelcome);
  EXPECT_EQ(events.messages[0].seq, 1u);
  EXPECT_EQ(*client.session(), h.server_events.opened.at(0));
  EXPECT_EQ(h.server_events.messages[0].second.type, MessageType::kHello);
  EXPECT_EQ(h.server->Info(*client.session())->client_name, "test-client");
  EXPECT_EQ(h.server->Info(*client.session())->remote.rfind("127.0.0.1:", 0), 0u);

  ASSERT_TRUE(client.Send(MessageType::kConsoleCommand, {{"line", "help"}}).ok());
  h.server_events.on_message = [](Server& server, SessionId id, const Message& m) {
    if (m.type == MessageType::kConsoleCommand) {
      (void)server.Send(id, MessageType::kConsoleOutput,
                        {{"text", "commands: help"}, {"ok", true}, {"in_reply_to", m.seq}});
    }
  };
  ASSERT_TRUE(h.Until([&] { return events.Count(MessageType::kConsoleOutput) == 1; }));
  EXPECT_EQ(events.OfType(MessageType::kConsoleOutput)[0].body["text"], "commands: help");
  // Heartbeats flow both ways and measure a round trip.
  ASSERT_TRUE(h.Until([&] { return client.stats().rtt_s.has_value(); }));
  EXPECT_LT(*client.stats().rtt_s, 0.1);
  EXPECT_EQ(client.link(), LinkState::kUp);
}

TEST(Server, StartsAndStopsManyTimesCleanly) {
  EventLoop loop;
  SteadyClock clock;
  for (int i = 0; i < 15; ++i) {
    ServerRecorder server_events;
    ClientRecorder events;
    auto server = std::make_unique<Server>(loop, clock, QuietServer(), server_events);
    ASSERT_TRUE(server->Start().ok());
    auto client = std::make_unique<Client>(loop, clock, ClientFor(*server), events);
    client->Connect();
    ASSERT_TRUE(loop.RunUntil([&] { return client->session().has_value(); }, kWait)) << "round " << i;
    if (i % 2 == 0) {
      server.reset();  // server goes first: the client sees the close
      ASSERT_TRUE(loop.RunUntil([&] { return !events.closes.empty(); }, kWait)) << "round " << i;
      client.reset();
    } else {
      client.reset();
      server.reset();
    }
    loop.RunFor(5ms);
  }
}

TEST(Server, SeveralSessionsAtOnceAndBroadcast) {
  Harness h;
  ASSERT_TRUE(h.Start(QuietServer()).ok());
  std::vector<std::unique_ptr<ClientRecorder>> events;
  std::vector<std::unique_ptr<Client>> clients;
  for (int i = 0; i < 5; ++i) {
    events.push_back(std::make_unique<ClientRecorder>());
    clients.push_back(std::make_unique<Client>(h.loop, h.clock, ClientFor(*h.server), *events.back()));
    clients.back()->Connect();
  }
  ASSERT_TRUE(h.Until([&] { return h.server->Sessions().size() == 5; }));
  EXPECT_EQ(h.server->Broadcast(MessageType::kLinkState, {{"state", "up"}, {"stopped", false}, {"reason", "test"}}), 5u);
  ASSERT_TRUE(h.Until([&] {
    for (auto& e : events) {
      if (e->Count(MessageType::kLinkState) != 1) return false;
    }
    return true;
  }));
  clients[2]->Close();
  ASSERT_TRUE(h.Until([&] { return h.server_events.closed.size() == 1; }));
  EXPECT_EQ(h.server->Sessions().size(), 4u);
}

TEST(Server, WrongOrMissingTokenGets401AndNoUpgrade) {
  Harness h;
  ServerOptions options = QuietServer();
  options.token = Token(kSecret);
  ASSERT_TRUE(h.Start(options).ok());
  const std::string upgrade =
      "GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
  for (const std::string& auth : std::vector<std::string>{std::string(), "Authorization: Bearer wrong-token-0123456789\r\n",
                                  "Authorization: Bearer " + kSecret + "x\r\n",
                                  "Authorization: Basic " + kSecret + "\r\n"}) {
    std::string response = RawHttp(h.loop, h.server->port(), upgrade + auth + "\r\n");
    EXPECT_EQ(StatusLine(response), "HTTP/1.1 401 Unauthorized") << auth;
    EXPECT_EQ(response.find("101"), std::string::npos);
    EXPECT_EQ(Body(response), "");  // nothing else
    EXPECT_EQ(response.find(kSecret), std::string::npos);
  }
  // Plain HTTP needs the token too, and so does garbage: it learns nothing but 401.
  EXPECT_EQ(StatusLine(RawHttp(h.loop, h.server->port(), "GET / HTTP/1.1\r\nHost: x\r\n\r\n")),
            "HTTP/1.1 401 Unauthorized");
  std::string garbage = RawHttp(h.loop, h.server->port(), "\x16\x03\x01 hello\r\n\r\n");
  EXPECT_EQ(StatusLine(garbage), "HTTP/1.1 401 Unauthorized");
  EXPECT_EQ(Body(garbage), "");
  EXPECT_TRUE(h.server_events.opened.empty());

  ClientRecorder refused_events;
  ClientOptions co = ClientFor(*h.server);
  co.token = Token("not-the-token-0123456789");
  Client refused(h.loop, h.clock, co, refused_events);
  refused.Connect();
  ASSERT_TRUE(h.Until([&] { return !refused_events.closes.empty(); }));
  EXPECT_NE(refused_events.closes[0].message().find("HTTP 401 Unauthorized"), std::string::npos)
      << refused_events.closes[0].message();
  EXPECT_EQ(refused_events.closes[0].message().find("not-the-token"), std::string::npos);
  EXPECT_EQ(refused_events.opens, 0);
  EXPECT_TRUE(h.server_events.opened.empty());

  ClientRecorder accepted_events;
  co.token = Token(kSecret);
  Client accepted(h.loop, h.clock, co, accepted_events);
  accepted.Connect();
  ASSERT_TRUE(h.Until([&] { return accepted.session().has_value(); }));
  EXPECT_EQ(h.server_events.opened.size(), 1u);
}

class Robustness : public ::testing::Test {
 protected:
  void SetUp() override {
    ServerOptions options = QuietServer();
    options.limits.max_json_bytes = 4096;
    options.limits.max_binary_bytes = 64 * 1024;
    options.max_send_queue_bytes = 1 << 20;
    ASSERT_TRUE(h_.Start(options).ok());
    ClientOptions co = ClientFor(*h_.server);
    co.send_hello = false;  // this test numbers its raw messages itself
    client_ = std::make_unique<Client>(h_.loop, h_.clock, co, events_);
    client_->Connect();
    ASSERT_TRUE(h_.Until([&] { return client_->session().has_value(); }));
  }

  // Sends one raw frame and returns the error it provoked.
  Json ErrorFor(std::string data, bool binary = false) {
    std::size_t before = events_.Count(MessageType::kError);
    EXPECT_TRUE(client_->SendRaw(std::move(data), binary).ok());
    EXPECT_TRUE(h_.Until([&] { return events_.Count(MessageType::kError) > before; }));
    std::vector<Message> errors = events_.OfType(MessageType::kError);
    return errors.empty() ? Json() : errors.back().body;
  }

  void ExpectStillUsable(std::uint64_t seq) {
    std::size_t before = h_.server_events.messages.size();
    ASSERT_TRUE(client_->SendRaw(R"({"type": "console_command", "seq": )" + std::to_string(seq) + R"(, "line": "list"})", false).ok());
    ASSERT_TRUE(h_.Until([&] { return h_.server_events.messages.size() > before; }));
    EXPECT_EQ(h_.server_events.messages.back().second.body["line"], "list");
    EXPECT_EQ(h_.server->Sessions().size(), 1u);
  }

  Harness h_;
  ClientRecorder events_;
  std::unique_ptr<Client> client_;
};

TEST_F(Robustness, MalformedJsonIsAnsweredAndTheConnectionStaysUsable) {
  Json e = ErrorFor("{\"type\": \"console_command\", \"seq\": ");
  EXPECT_EQ(e["code"], "malformed_json");
  EXPECT_NE(e["message"].get<std::string>().find("line 1, column"), std::string::npos) << e;
  ExpectStillUsable(1);
  EXPECT_TRUE(h_.server_events.messages.size() == 1);
}

TEST_F(Robustness, UnknownTypeIsAnsweredNamingTheType) {
  Json e = ErrorFor(R"({"type": "self_destruct", "seq": 1})");
  EXPECT_EQ(e["code"], "unknown_type");
  EXPECT_EQ(e["message"], "type: unknown message type \"self_destruct\"");
  EXPECT_EQ(e["in_reply_to"], 1);
  ExpectStillUsable(2);
}

TEST_F(Robustness, MissingFieldIsAnsweredNamingTheField) {
  Json e = ErrorFor(R"({"type": "dragger_input", "seq": 1, "object": "cube", "phase": "move"})");
  EXPECT_EQ(e["code"], "invalid_field");
  EXPECT_EQ(e["message"], "dragger_input.world_T_dragger: missing");
  ExpectStillUsable(2);
  EXPECT_EQ(h_.server_events.messages.size(), 1u);  // the refused one never reached the service
}

TEST_F(Robustness, OversizedTextAndBinaryAreDrainedAnsweredAndTheConnectionStaysUsable) {
  std::string big = R"({"type": "console_command", "seq": 1, "line": ")" + std::string(200 * 1024, 'a') + "\"}";
  Json e = ErrorFor(big);
  EXPECT_EQ(e["code"], "too_large");
  EXPECT_EQ(e["message"], "text message of " + std::to_string(big.size()) + " bytes exceeds the limit of 4096 bytes");
  ExpectStillUsable(1);  // an unread message's seq cannot be known: 1 is still next
  Json eb = ErrorFor(std::string(100 * 1024, '\x01'), true);
  EXPECT_EQ(eb["code"], "too_large");
  EXPECT_NE(eb["message"].get<std::string>().find("binary message of 102400 bytes exceeds the limit of 65536"),
            std::string::npos);
  ExpectStillUsable(2);
}

TEST_F(Robustness, GarbageBinaryIsAnswered) {
  Json e = ErrorFor("not an image at all, but long enough for a header", true);
  EXPECT_EQ(e["code"], "bad_binary_header");
  ExpectStillUsable(1);
}

TEST_F(Robustness, SequenceGapsAndDuplicatesAreReported) {
  ExpectStillUsable(1);
  // seq 2 and 3 never sent: a gap, reported, and the message still delivered.
  Json gap = ErrorFor(R"({"type": "console_command", "seq": 4, "line": "gap"})");
  EXPECT_EQ(gap["code"], "seq_gap");
  EXPECT_EQ(gap["message"], "seq: expected 2, got 4 (2 missing)");
  ASSERT_TRUE(h_.Until([&] { return h_.server_events.messages.size() == 2; }));
  // A replayed seq is dropped.
  Json dup = ErrorFor(R"({"type": "console_command", "seq": 4, "line": "replay"})");
  EXPECT_EQ(dup["code"], "duplicate_seq");
  ExpectStillUsable(5);
  EXPECT_EQ(h_.server_events.messages.size(), 3u);
  EXPECT_EQ(h_.server->Info(*client_->session())->stats.seq_gaps, 1u);
}

TEST_F(Robustness, ProtocolMismatchIsRefusedAndClosed) {
  Json e = ErrorFor(R"({"type": "hello", "seq": 1, "client": "future", "protocol": 99})");
  EXPECT_EQ(e["code"], "protocol_mismatch");
  ASSERT_TRUE(h_.Until([&] { return !events_.closes.empty(); }));
}

TEST(Server, BinaryFramesTravelBothWays) {
  Harness h;
  ASSERT_TRUE(h.Start(QuietServer()).ok());
  ClientRecorder events;
  Client client(h.loop, h.clock, ClientFor(*h.server), events);
  client.Connect();
  ASSERT_TRUE(h.Until([&] { return client.session().has_value(); }));
  std::vector<std::uint8_t> pixels(320 * 240);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<std::uint8_t>(i % 251);
  BinaryHeader header;
  header.width = 320;
  header.height = 240;
  header.stamp_s = 1.5;
  EXPECT_EQ(h.server->BroadcastFrame(header, pixels), 1u);
  ASSERT_TRUE(h.Until([&] { return events.frames.size() == 1; }));
  EXPECT_EQ(events.frames[0].pixels, pixels);
  EXPECT_EQ(events.frames[0].header.width, 320u);
  ASSERT_TRUE(client.SendFrame(header, pixels).ok());
  ASSERT_TRUE(h.Until([&] { return h.server_events.frames.size() == 1; }));
  EXPECT_EQ(h.server_events.frames[0].second.pixels, pixels);
  EXPECT_TRUE(events.OfType(MessageType::kError).empty());  // no gap: frames share the seq stream
}

TEST(Server, LeaseIsExclusiveOverTheWire) {
  Harness h;
  ASSERT_TRUE(h.Start(QuietServer()).ok());
  ClientRecorder a_events, b_events;
  auto a = std::make_unique<Client>(h.loop, h.clock, ClientFor(*h.server), a_events);
  Client b(h.loop, h.clock, ClientFor(*h.server), b_events);
  a->Connect();
  b.Connect();
  ASSERT_TRUE(h.Until([&] { return a->session() && b.session(); }));
  SessionId a_id = *a->session(), b_id = *b.session();

  ASSERT_TRUE(a->Send(MessageType::kLeaseRequest).ok());
  ASSERT_TRUE(h.Until([&] { return a_events.Count(MessageType::kLeaseGrant) == 1; }));
  EXPECT_EQ(a_events.OfType(MessageType::kLeaseGrant)[0].body["granted"], true);
  ASSERT_TRUE(h.Until([&] { return b_events.Count(MessageType::kLeaseState) == 1; }));
  EXPECT_EQ(b_events.OfType(MessageType::kLeaseState)[0].body["holder"], a_id);

  ASSERT_TRUE(b.Send(MessageType::kLeaseRequest).ok());
  ASSERT_TRUE(h.Until([&] { return b_events.Count(MessageType::kLeaseGrant) == 1; }));
  Json refused = b_events.OfType(MessageType::kLeaseGrant)[0].body;
  EXPECT_EQ(refused["granted"], false);
  EXPECT_EQ(refused["holder"], a_id);

  // A command from the watcher is refused; from the holder it reaches the service.
  ASSERT_TRUE(b.Send(MessageType::kResetWorld).ok());
  ASSERT_TRUE(h.Until([&] { return b_events.Count(MessageType::kError) == 1; }));
  Json error = b_events.OfType(MessageType::kError)[0].body;
  EXPECT_EQ(error["code"], "not_lease_holder");
  EXPECT_EQ(error["message"], "reset_world: read-only: the controller lease is held by session " + std::to_string(a_id));
  ASSERT_TRUE(a->Send(MessageType::kResetWorld).ok());
  ASSERT_TRUE(h.Until([&] {
    for (const auto& [id, m] : h.server_events.messages) {
      if (m.type == MessageType::kResetWorld) return true;
    }
    return false;
  }));
  for (const auto& [id, m] : h.server_events.messages) {
    if (m.type == MessageType::kResetWorld) {
      EXPECT_EQ(id, a_id);
    }
  }
  // Watching stays possible: read-only messages from b still pass.
  ASSERT_TRUE(b.Send(MessageType::kConsoleCommand, {{"line", "list"}}).ok());
  ASSERT_TRUE(h.Until([&] { return h.server_events.messages.back().first == b_id; }));

  // The holder disconnects: the lease is free, everybody hears it, b takes it.
  a.reset();
  ASSERT_TRUE(h.Until([&] { return !h.server->lease().holder().has_value(); }));
  ASSERT_TRUE(h.Until([&] { return b_events.Count(MessageType::kLeaseState) == 2; }));
  EXPECT_TRUE(b_events.OfType(MessageType::kLeaseState)[1].body["holder"].is_null());
  ASSERT_TRUE(b.Send(MessageType::kLeaseRequest).ok());
  ASSERT_TRUE(h.Until([&] { return h.server->lease().holder() == b_id; }));
  // Explicit release.
  ASSERT_TRUE(b.Send(MessageType::kLeaseRelease).ok());
  ASSERT_TRUE(h.Until([&] { return !h.server->lease().holder().has_value(); }));
  EXPECT_EQ(h.server_events.lease_changes.size(), 4u);
}

class StaticServer : public ::testing::Test {
 protected:
  void SetUp() override {
    base_ = fs::temp_directory_path() / ("teachsim_static_server_" + std::to_string(::getpid()));
    fs::create_directories(base_ / "web" / "js");
    std::ofstream(base_ / "web" / "index.html") << "<html>teachsim</html>";
    std::ofstream(base_ / "web" / "js" / "app.js") << "export const x = 1;";
    std::ofstream(base_ / "secret.txt") << "TOP-SECRET";
    ServerOptions options = QuietServer();
    options.static_root = (base_ / "web").string();
    ASSERT_TRUE(h_.Start(options).ok());
  }
  void TearDown() override { fs::remove_all(base_); }
  std::string Get(const std::string& target, const std::string& method = "GET") {
    return RawHttp(h_.loop, h_.server->port(), method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");
  }
  fs::path base_;
  Harness h_;
};

TEST_F(StaticServer, ServesFilesWithTheirMimeTypes) {
  std::string index = Get("/");
  EXPECT_EQ(StatusLine(index), "HTTP/1.1 200 OK");
  EXPECT_NE(index.find("Content-Type: text/html; charset=utf-8"), std::string::npos);
  EXPECT_EQ(Body(index), "<html>teachsim</html>");
  std::string js = Get("/js/app.js?v=1");
  EXPECT_EQ(StatusLine(js), "HTTP/1.1 200 OK");
  EXPECT_NE(js.find("Content-Type: text/javascript; charset=utf-8"), std::string::npos);
  EXPECT_EQ(Body(js), "export const x = 1;");
  std::string head = Get("/js/app.js", "HEAD");
  EXPECT_EQ(StatusLine(head), "HTTP/1.1 200 OK");
  EXPECT_NE(head.find("Content-Length: 19"), std::string::npos);
  EXPECT_EQ(Body(head), "");
}

TEST_F(StaticServer, MissingFilesAre404AndOtherMethods405) {
  EXPECT_EQ(StatusLine(Get("/nope.js")), "HTTP/1.1 404 Not Found");
  EXPECT_EQ(StatusLine(Get("/js/app.js", "POST")), "HTTP/1.1 405 Method Not Allowed");
  // A WebSocket upgrade on an unknown path is not upgraded.
  std::string response = RawHttp(h_.loop, h_.server->port(),
                                 "GET /other HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                                 "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n");
  EXPECT_EQ(StatusLine(response), "HTTP/1.1 404 Not Found");
}

TEST_F(StaticServer, TraversalAttemptsNeverServeOutsideTheRoot) {
  for (const char* target : {"/../secret.txt", "/js/../../secret.txt", "/%2e%2e/secret.txt", "/%2E%2E%2Fsecret.txt",
                             "/js/%2e%2e/%2e%2e/secret.txt", "/..%5csecret.txt", "//../secret.txt"}) {
    std::string response = Get(target);
    EXPECT_EQ(StatusLine(response), "HTTP/1.1 400 Bad Request") << target;
    EXPECT_EQ(response.find("TOP-SECRET"), std::string::npos) << target;
  }
  // Garbage instead of HTTP is refused and does not disturb the server.
  std::string garbage = RawHttp(h_.loop, h_.server->port(), "\x16\x03\x01 not http at all\r\n\r\n");
  EXPECT_EQ(StatusLine(garbage), "HTTP/1.1 400 Bad Request");
  EXPECT_EQ(StatusLine(Get("/")), "HTTP/1.1 200 OK");
}

}  // namespace
}  // namespace teachsim::net
