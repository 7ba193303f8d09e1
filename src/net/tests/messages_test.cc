#include "teachsim/net/messages.h"

#include <gtest/gtest.h>

#include <set>

namespace teachsim::net {
namespace {

using json::Json;

const Json kPose = {{"position", {0.1, 0.2, 0.0}}, {"quaternion_wxyz", {1.0, 0.0, 0.0, 0.0}}};

// One valid example per JSON message type: the catalogue's documentation in executable form.
Json Example(MessageType type) {
  switch (type) {
    case MessageType::kHello: return {{"client", "operator-site"}, {"protocol", 1}};
    case MessageType::kWelcome:
      return {{"session", 3}, {"protocol", 1}, {"server", "worksite"}, {"lease_holder", nullptr},
              {"heartbeat_period_s", 0.05}, {"link_timeout_s", 0.25}};
    case MessageType::kHeartbeat: return {{"t_s", 1.5}, {"echo_t_s", 1.2}, {"hold_s", 0.01}};
    case MessageType::kError: return {{"code", "invalid_field"}, {"message", "x: missing"}, {"in_reply_to", 4}};
    case MessageType::kLeaseRequest:
    case MessageType::kLeaseRelease:
    case MessageType::kResume:
    case MessageType::kResetWorld: return Json::object();
    case MessageType::kLeaseGrant: return {{"granted", false}, {"holder", 2}, {"reason", "held by session 2"}};
    case MessageType::kLeaseState: return {{"holder", 2}, {"generation", 5}};
    case MessageType::kLinkState: return {{"state", "lost"}, {"stopped", true}, {"reason", "silent for 0.26 s"}, {"silent_s", 0.26}};
    case MessageType::kRecognitions:
      return {{"frame_seq", 17}, {"camera", 0},
              {"objects", {{{"model", "cube45"}, {"world_T_object", kPose}, {"score", 0.83}}}}};
    case MessageType::kRobotState:
      return {{"t_s", 12.0}, {"joints_rad", {0, 0.1, 0.2, 0.3, 0.4, 0.5}}, {"world_T_tool", kPose},
              {"force_n", {0, 0, -1.5}}, {"torque_nm", {0, 0, 0}}, {"gripper_width_m", 0.05},
              {"moving", false}, {"stopped", false}};
    case MessageType::kProgramSubmit: return {{"program_id", "p1"}, {"program", {{"commands", Json::array()}}}};
    case MessageType::kExecutionProgress:
      return {{"program_id", "p1"}, {"command_index", 2}, {"command_count", 5}, {"state", "running"}};
    case MessageType::kReport: return {{"program_id", "p1"}, {"ok", true}, {"report", {{"commands", Json::array()}}}};
    case MessageType::kDraggerInput: return {{"object", "cube45"}, {"phase", "move"}, {"world_T_dragger", kPose}};
    case MessageType::kPoseUpdate:
      return {{"t_s", 3.0}, {"poses", {{{"object", "cube45"}, {"world_T_object", kPose}}}}, {"sim_rate_hz", 240.0}};
    case MessageType::kConsoleCommand: return {{"line", "select cube45"}};
    case MessageType::kConsoleOutput: return {{"text", "selected cube45"}, {"ok", true}, {"in_reply_to", 9}};
    case MessageType::kSessionSave:
    case MessageType::kSessionLoad: return {{"name", "corner-demo_1"}};
    case MessageType::kWorldState:
      return {{"revision", 4},
              {"objects", {{{"name", "cube"}, {"fixed", false}, {"model", "cube45"},
                            {"shape", {{"box", {0.045, 0.045, 0.045}}}}, {"world_T_object", kPose},
                            {"origin", "scene"}}}},
              {"workpiece", "cube"}, {"capture", {"frame"}}, {"dragging", false}, {"demonstrations", 1},
              {"models", {{{"name", "cube45"}, {"shape", {{"box", {0.045, 0.045, 0.045}}}}}}},
              {"cameras", Json::array()}, {"robot", nullptr},
              {"link", {{"state", "up"}, {"stopped", false}, {"reason", "connected"}, {"rtt_s", nullptr}}},
              {"lease_holder", 1}, {"busy", ""},
              {"paths", {{"initial", {kPose, kPose}}, {"deformed", Json::array()}, {"simplified", Json::array()}}},
              {"program", {{"id", "p1"}, {"command_count", 3}, {"listing", "1 grasp"}}},
              {"report", nullptr}, {"sim_rate_hz", 60.5}};
    case MessageType::kWorksiteScene:
      return {{"scene", {{"objects", Json::array()}}},
              {"models", {{{"name", "cube45"}, {"shape", {{"box", {0.045, 0.045, 0.045}}}}}}}};
    case MessageType::kCameraFrame: break;
  }
  return Json();
}

MessageLimits Limits() { return MessageLimits{}; }

Parsed ParseJson(const Json& j) { return ParseTextMessage(j.dump(), Limits()); }

TEST(Messages, CatalogueNamesAreUniqueAndLookUpBothWays) {
  std::set<std::string_view> names;
  for (const MessageSpec& spec : MessageCatalogue()) {
    EXPECT_TRUE(names.insert(spec.name).second) << spec.name;
    EXPECT_EQ(FindSpec(spec.name), &spec);
    EXPECT_EQ(Spec(spec.type).name, spec.name);
    EXPECT_EQ(spec.binary, spec.validate == nullptr) << spec.name;
  }
  EXPECT_EQ(FindSpec("no_such_type"), nullptr);
}

TEST(Messages, EveryJsonTypeHasAValidExampleThatRoundTrips) {
  std::uint64_t seq = 1;
  for (const MessageSpec& spec : MessageCatalogue()) {
    if (spec.binary) continue;
    Json message = MakeMessage(spec.type, seq, Example(spec.type));
    ASSERT_TRUE(ValidateMessage(message).ok()) << spec.name << ": " << ValidateMessage(message).message();
    Parsed parsed = ParseTextMessage(Serialize(message), Limits());
    ASSERT_TRUE(parsed.ok()) << spec.name << ": " << parsed.error->message;
    EXPECT_EQ(parsed.message->type, spec.type);
    EXPECT_EQ(parsed.message->seq, seq);
    EXPECT_EQ(parsed.message->body, message);
    ++seq;
  }
}

TEST(Messages, EveryRequiredFieldIsCheckedAndNamed) {
  // Dropping any non-optional field of any example must be refused, naming that field.
  const std::set<std::pair<MessageType, std::string>> optional = {
      {MessageType::kHeartbeat, "echo_t_s"}, {MessageType::kHeartbeat, "hold_s"},
      {MessageType::kError, "in_reply_to"},  {MessageType::kLeaseGrant, "reason"},
      {MessageType::kLinkState, "silent_s"}, {MessageType::kPoseUpdate, "sim_rate_hz"},
      {MessageType::kConsoleOutput, "in_reply_to"}};
  for (const MessageSpec& spec : MessageCatalogue()) {
    if (spec.binary) continue;
    Json example = Example(spec.type);
    for (auto it = example.begin(); it != example.end(); ++it) {
      if (optional.count({spec.type, it.key()}) != 0) continue;
      Json fields = example;
      fields.erase(it.key());
      Parsed parsed = ParseJson(MakeMessage(spec.type, 1, fields));
      ASSERT_FALSE(parsed.ok()) << spec.name << " without " << it.key();
      EXPECT_EQ(parsed.error->code, "invalid_field");
      EXPECT_EQ(parsed.error->message, std::string(spec.name) + "." + it.key() + ": missing");
      EXPECT_EQ(parsed.error->in_reply_to, 1u);
    }
  }
}

TEST(Messages, WrongTypesAndRangesNameTheFieldAndTheValue) {
  Json m = MakeMessage(MessageType::kRobotState, 7, Example(MessageType::kRobotState));
  m["joints_rad"][3] = "x";
  Parsed p = ParseJson(m);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error->message, "robot_state.joints_rad[3]: must be a number, got string");
  EXPECT_EQ(p.error->in_reply_to, 7u);

  m = MakeMessage(MessageType::kRecognitions, 2, Example(MessageType::kRecognitions));
  m["objects"][0]["score"] = 1.5;
  p = ParseJson(m);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error->message, "recognitions.objects[0].score: must be in [0, 1], got 1.5");

  m = MakeMessage(MessageType::kDraggerInput, 2, Example(MessageType::kDraggerInput));
  m["world_T_dragger"]["quaternion_wxyz"] = {1, 1, 0, 0};
  p = ParseJson(m);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error->message.find("dragger_input.world_T_dragger.quaternion_wxyz: must be a unit quaternion"),
            std::string::npos)
      << p.error->message;

  m = MakeMessage(MessageType::kExecutionProgress, 2, Example(MessageType::kExecutionProgress));
  m["command_index"] = 6;  // beyond command_count = 5
  p = ParseJson(m);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error->message, "execution_progress.command_index: must be in [0, 5], got 6");

  m = MakeMessage(MessageType::kSessionLoad, 2, {{"name", "../../etc/passwd"}});
  p = ParseJson(m);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error->message.find("session_load.name: must be 1-64 characters"), std::string::npos);

  m = MakeMessage(MessageType::kHello, 2, Example(MessageType::kHello));
  m["clinet"] = "typo";
  p = ParseJson(m);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error->message.find("hello: unknown field 'clinet'"), std::string::npos) << p.error->message;
}

TEST(Messages, EnvelopeProblemsGetTheirOwnCodes) {
  struct Case {
    std::string text, code, message_part;
  };
  const std::vector<Case> cases = {
      {"{\"type\": \"hello\", \"seq\": 1", "malformed_json", "message: line 1, column"},
      {"", "malformed_json", "message:"},
      {"[1, 2]", "not_an_object", "must be a JSON object, got array"},
      {"{\"type\": \"hello\"}", "invalid_field", "seq: missing"},
      {"{\"type\": \"hello\", \"seq\": 0}", "invalid_field", "seq: must be in [1, 9007199254740991], got 0"},
      {"{\"type\": \"hello\", \"seq\": 1.5}", "invalid_field", "seq: must be an integer"},
      {"{\"seq\": 4}", "invalid_field", "type: missing"},
      {"{\"type\": \"teleport\", \"seq\": 4}", "unknown_type", "type: unknown message type \"teleport\""},
      {"{\"type\": \"camera_frame\", \"seq\": 4}", "invalid_field", "travels as a binary frame"},
      {"{\"type\": \"heartbeat\", \"seq\": 4, \"t_s\": 1e999}", "malformed_json", "number overflow"},
      {std::string(100, '[') + std::string(100, ']'), "too_deep", "nested deeper than 64"},
  };
  for (const Case& c : cases) {
    Parsed p = ParseTextMessage(c.text, Limits());
    ASSERT_FALSE(p.ok()) << c.text;
    EXPECT_EQ(p.error->code, c.code) << c.text;
    EXPECT_NE(p.error->message.find(c.message_part), std::string::npos) << c.text << " -> " << p.error->message;
  }
  // The seq is reported back once it could be read.
  EXPECT_EQ(ParseTextMessage("{\"type\": \"teleport\", \"seq\": 4}", Limits()).error->in_reply_to, 4u);
}

TEST(Messages, OversizedTextIsRefusedBeforeParsing) {
  MessageLimits limits;
  limits.max_json_bytes = 1024;
  std::string text = Serialize(MakeMessage(MessageType::kConsoleCommand, 1, {{"line", std::string(2000, 'a')}}));
  Parsed p = ParseTextMessage(text, limits);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error->code, "too_large");
  EXPECT_EQ(p.error->message, "text message of " + std::to_string(text.size()) + " bytes exceeds the limit of 1024 bytes");
}

TEST(Messages, ErrorMessagesSerializeEvenWithInvalidUtf8) {
  Parsed p = ParseTextMessage("{\"type\": \"\xff\xfe\", \"seq\": 1}", Limits());
  ASSERT_FALSE(p.ok());
  std::string text = Serialize(MakeErrorMessage(1, *p.error));
  Parsed back = ParseTextMessage(text, Limits());
  ASSERT_TRUE(back.ok()) << back.error->message;
  EXPECT_EQ(back.message->type, MessageType::kError);
}

TEST(Messages, OutgoingValidationCatchesServiceMistakes) {
  Status s = ValidateMessage(MakeMessage(MessageType::kPoseUpdate, 3, {{"t_s", -1.0}, {"poses", Json::array()}}));
  EXPECT_EQ(s.message(), "pose_update.t_s: must be >= 0, got -1");
}

std::vector<std::uint8_t> Gradient(std::uint32_t width, std::uint32_t height, int channels) {
  std::vector<std::uint8_t> pixels(std::size_t{width} * height * channels);
  for (std::size_t i = 0; i < pixels.size(); ++i) pixels[i] = static_cast<std::uint8_t>(i * 7);
  return pixels;
}

TEST(BinaryFrames, RoundTripKeepsHeaderAndPixels) {
  for (PixelFormat format : {PixelFormat::kGray8, PixelFormat::kRgb8}) {
    BinaryHeader h;
    h.format = format;
    h.camera = 2;
    h.seq = 123456789012ULL;
    h.width = 64;
    h.height = 48;
    h.stamp_s = 12.25;
    std::vector<std::uint8_t> pixels = Gradient(64, 48, BytesPerPixel(format));
    Result<std::string> encoded = EncodeBinaryFrame(h, pixels);
    ASSERT_TRUE(encoded.ok()) << encoded.status().message();
    EXPECT_EQ(encoded->size(), kBinaryHeaderBytes + pixels.size());
    EXPECT_EQ(encoded->substr(0, 4), "TSB1");
    Parsed p = ParseBinaryMessage(std::span(reinterpret_cast<const std::uint8_t*>(encoded->data()), encoded->size()),
                                  MessageLimits{});
    ASSERT_TRUE(p.ok()) << p.error->message;
    EXPECT_EQ(p.frame->header.type, MessageType::kCameraFrame);
    EXPECT_EQ(p.frame->header.format, format);
    EXPECT_EQ(p.frame->header.camera, 2);
    EXPECT_EQ(p.frame->header.seq, 123456789012ULL);
    EXPECT_EQ(p.frame->header.width, 64u);
    EXPECT_EQ(p.frame->header.height, 48u);
    EXPECT_EQ(p.frame->header.stamp_s, 12.25);
    EXPECT_EQ(p.frame->pixels, pixels);
  }
}

TEST(BinaryFrames, HeaderLayoutIsTheDocumentedOne) {
  BinaryHeader h;
  h.seq = 0x0102030405060708ULL & 0x000FFFFFFFFFFFFFULL;
  h.width = 2;
  h.height = 1;
  h.camera = 0x0a0b;
  std::vector<std::uint8_t> pixels = {9, 8};
  std::string e = EncodeBinaryFrame(h, pixels).value();
  EXPECT_EQ(static_cast<std::uint8_t>(e[4]), static_cast<std::uint8_t>(MessageType::kCameraFrame));
  EXPECT_EQ(static_cast<std::uint8_t>(e[5]), 1);  // gray8
  EXPECT_EQ(static_cast<std::uint8_t>(e[6]), 0x0b);  // camera, little-endian
  EXPECT_EQ(static_cast<std::uint8_t>(e[7]), 0x0a);
  EXPECT_EQ(static_cast<std::uint8_t>(e[8]), 0x08);  // seq, little-endian
  EXPECT_EQ(static_cast<std::uint8_t>(e[16]), 2);     // width
  EXPECT_EQ(static_cast<std::uint8_t>(e[20]), 1);     // height
  EXPECT_EQ(static_cast<std::uint8_t>(e[32]), 9);     // first pixel
}

TEST(BinaryFrames, BadHeadersAreRefusedWithTheReason) {
  BinaryHeader h;
  h.seq = 5;
  h.width = 4;
  h.height = 4;
  std::vector<std::uint8_t> pixels(16, 1);
  std::string good = EncodeBinaryFrame(h, pixels).value();
  auto parse = [](const std::string& bytes, MessageLimits limits = {}) {
    return ParseBinaryMessage(std::span(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()), limits);
  };
  struct Case {
    std::string bytes, code, part;
  };
  std::string bad_magic = good, bad_type = good, bad_format = good, zero_width = good, short_pixels = good;
  bad_magic[0] = 'X';
  bad_type[4] = 3;  // error: not a binary type
  bad_format[5] = 9;
  for (int i = 16; i < 20; ++i) zero_width[i] = 0;
  short_pixels.pop_back();
  const std::vector<Case> cases = {
      {good.substr(0, 10), "bad_binary_header", "shorter than the 32-byte header"},
      {bad_magic, "bad_binary_header", "magic must be \"TSB1\""},
      {bad_type, "unknown_type", "type = 3 is not a binary message type"},
      {bad_format, "bad_binary_header", "format = 9"},
      {zero_width, "bad_binary_header", "image size 0x4"},
      {short_pixels, "bad_binary_header", "need 16 bytes after the header, got 15"},
  };
  for (const Case& c : cases) {
    Parsed p = parse(c.bytes);
    ASSERT_FALSE(p.ok()) << c.part;
    EXPECT_EQ(p.error->code, c.code) << p.error->message;
    EXPECT_NE(p.error->message.find(c.part), std::string::npos) << p.error->message;
  }
  MessageLimits small;
  small.max_binary_bytes = 40;
  Parsed p = parse(good, small);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.error->code, "too_large");
}

TEST(Sequences, GapsAndDuplicatesAreDetected) {
  SequenceTracker t;
  EXPECT_EQ(t.Observe(1).verdict, SequenceTracker::Verdict::kInOrder);
  EXPECT_EQ(t.Observe(2).verdict, SequenceTracker::Verdict::kInOrder);
  SequenceTracker::Observation gap = t.Observe(5);
  EXPECT_EQ(gap.verdict, SequenceTracker::Verdict::kGap);
  EXPECT_EQ(gap.expected, 3u);
  EXPECT_EQ(gap.missing, 2u);
  EXPECT_EQ(t.Observe(5).verdict, SequenceTracker::Verdict::kDuplicate);
  EXPECT_EQ(t.Observe(4).verdict, SequenceTracker::Verdict::kDuplicate);
  EXPECT_EQ(t.Observe(6).verdict, SequenceTracker::Verdict::kInOrder);
  EXPECT_EQ(t.gaps(), 1u);
  EXPECT_EQ(t.missing_total(), 2u);
  EXPECT_EQ(t.duplicates(), 2u);
  EXPECT_EQ(t.last(), 6u);
}

TEST(Sequences, SessionNamesCannotEscapeTheSessionsFolder) {
  EXPECT_TRUE(IsValidSessionName("corner-demo_1.v2"));
  for (const std::string& bad : std::vector<std::string>{"", ".hidden", "..", "a/b", "a\\b", "a b", std::string(65, 'a'), std::string("a\0b", 3)}) {
    EXPECT_FALSE(IsValidSessionName(bad)) << bad;
  }
}

}  // namespace
}  // namespace teachsim::net
