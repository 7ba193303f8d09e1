#include "teachsim/net/messages.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

namespace teachsim::net {

using json::Json;
using json::Reader;

namespace {

constexpr std::size_t kMaxNameBytes = 256;
constexpr std::size_t kMaxTextBytes = 64 * 1024;
constexpr std::size_t kMaxListItems = 10000;

// ---- field readers (throw json::ParseError naming the field) ----

std::uint64_t ReadSeq(const Reader& r) { return static_cast<std::uint64_t>(r.IntegerInRange(1, kMaxJsonInteger)); }

std::string ReadName(const Reader& r) {
  std::string s = r.NonEmptyString();
  if (s.size() > kMaxNameBytes) r.Fail("must be at most " + std::to_string(kMaxNameBytes) + " bytes long");
  return s;
}

std::string ReadText(const Reader& r) {
  std::string s = r.String();
  if (s.size() > kMaxTextBytes) r.Fail("must be at most " + std::to_string(kMaxTextBytes) + " bytes long");
  return s;
}

void ReadOneOf(const Reader& r, std::initializer_list<std::string_view> allowed) {
  std::string s = r.String();
  if (std::find(allowed.begin(), allowed.end(), s) != allowed.end()) return;
  std::string list;
  for (std::string_view a : allowed) list += (list.empty() ? "\"" : ", \"") + std::string(a) + "\"";
  r.Fail("must be one of " + list + ", got \"" + s + "\"");
}

void ReadTime(const Reader& r) { r.NumberAtLeast(0.0); }

void ReadVector3(const Reader& r) { r.Vector3(); }

// DESIGN.md: {"position": [x, y, z], "quaternion_wxyz": [w, x, y, z]}, a unit quaternion.
void ReadPose(const Reader& r) {
  r.RejectUnknownKeys({"position", "quaternion_wxyz"});
  r.At("position").Vector3();
  Reader q = r.At("quaternion_wxyz");
  q.ExpectSize(4);
  double norm2 = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    double v = q.Index(i).Number();
    norm2 += v * v;
  }
  if (std::abs(std::sqrt(norm2) - 1.0) > 1e-3) {
    q.Fail("must be a unit quaternion, got norm " + json::FormatNumber(std::sqrt(norm2)));
  }
}

void ReadOptionalSessionId(const Reader& r) {
  if (!r.IsNull()) r.IntegerInRange(1, kMaxJsonInteger);
}

std::size_t ReadListSize(const Reader& r) {
  std::size_t n = r.Size();
  if (n > kMaxListItems) r.Fail("must have at most " + std::to_string(kMaxListItems) + " elements");
  return n;
}

void ReadSessionName(const Reader& r) {
  std::string name = r.String();
  if (!IsValidSessionName(name)) {
    r.Fail("must be 1-64 characters of A-Z a-z 0-9 _ . - not starting with '.', got \"" +
           name.substr(0, 80) + "\"");
  }
}

// ---- validators, one per message type ----
#define TS_KEYS(...) r.RejectUnknownKeys({"type", "seq", __VA_ARGS__})

void ValidateEmpty(const Reader& r) { r.RejectUnknownKeys({"type", "seq"}); }

void ValidateHello(const Reader& r) {
  TS_KEYS("client", "protocol");
  ReadName(r.At("client"));
  r.At("protocol").IntegerInRange(1, 1000);
}

void ValidateWelcome(const Reader& r) {
  TS_KEYS("session", "protocol", "server", "lease_holder", "heartbeat_period_s", "link_timeout_s");
  r.At("session").IntegerInRange(1, kMaxJsonInteger);
  r.At("protocol").IntegerInRange(1, 1000);
  ReadName(r.At("server"));
  ReadOptionalSessionId(r.At("lease_holder"));
  r.At("heartbeat_period_s").NumberGreaterThan(0.0);
  r.At("link_timeout_s").NumberGreaterThan(0.0);
}

void ValidateHeartbeat(const Reader& r) {
  TS_KEYS("t_s", "echo_t_s", "hold_s");
  ReadTime(r.At("t_s"));
  bool echo = r.Has("echo_t_s"), hold = r.Has("hold_s");
  if (echo != hold) r.Fail("echo_t_s and hold_s must come together");
  if (echo) {
    ReadTime(r.At("echo_t_s"));
    ReadTime(r.At("hold_s"));
  }
}

void ValidateError(const Reader& r) {
  TS_KEYS("code", "message", "in_reply_to");
  ReadName(r.At("code"));
  ReadText(r.At("message"));
  if (auto s = r.Find("in_reply_to")) ReadSeq(*s);
}

void ValidateLeaseGrant(const Reader& r) {
  TS_KEYS("granted", "holder", "reason");
  r.At("granted").Bool();
  ReadOptionalSessionId(r.At("holder"));
  if (auto s = r.Find("reason")) ReadText(*s);
}

void ValidateLeaseState(const Reader& r) {
  TS_KEYS("holder", "generation");
  ReadOptionalSessionId(r.At("holder"));
  r.At("generation").IntegerInRange(0, kMaxJsonInteger);
}

void ValidateLinkState(const Reader& r) {
  TS_KEYS("state", "stopped", "reason", "silent_s");
  ReadOneOf(r.At("state"), {"up", "lost"});
  r.At("stopped").Bool();
  ReadText(r.At("reason"));
  if (auto s = r.Find("silent_s")) ReadTime(*s);
}

void ValidateRecognitions(const Reader& r) {
  TS_KEYS("frame_seq", "camera", "objects");
  r.At("frame_seq").IntegerInRange(0, kMaxJsonInteger);
  r.At("camera").IntegerInRange(0, 65535);
  Reader objects = r.At("objects");
  std::size_t n = ReadListSize(objects);
  for (std::size_t i = 0; i < n; ++i) {
    Reader o = objects.Index(i);
    o.RejectUnknownKeys({"model", "world_T_object", "score"});
    ReadName(o.At("model"));
    ReadPose(o.At("world_T_object"));
    o.At("score").NumberInRange(0.0, 1.0);
  }
}

void ValidateRobotState(const Reader& r) {
  TS_KEYS("t_s", "joints_rad", "world_T_tool", "force_n", "torque_nm", "gripper_width_m", "moving",
          "stopped");
  ReadTime(r.At("t_s"));
  Reader joints = r.At("joints_rad");
  joints.ExpectSize(6);
  for (std::size_t i = 0; i < 6; ++i) joints.Index(i).Number();
  ReadPose(r.At("world_T_tool"));
  ReadVector3(r.At("force_n"));
  ReadVector3(r.At("torque_nm"));
  r.At("gripper_width_m").NumberAtLeast(0.0);
  r.At("moving").Bool();
  r.At("stopped").Bool();
}

void ValidateProgramSubmit(const Reader& r) {
  TS_KEYS("program_id", "program");
  ReadName(r.At("program_id"));
  // The program's own fields are checked by the plan module's reader at the work site.
  Reader program = r.At("program");
  if (!program.IsObject()) program.Fail("must be an object");
}

void ValidateExecutionProgress(const Reader& r) {
  TS_KEYS("program_id", "command_index", "command_count", "state", "message", "replay");
  ReadName(r.At("program_id"));
  long long count = r.At("command_count").IntegerInRange(0, 1000000);
  r.At("command_index").IntegerInRange(0, count);
  ReadOneOf(r.At("state"), {"running", "done", "failed", "stopped"});
  if (auto s = r.Find("message")) ReadText(*s);
  if (auto s = r.Find("replay")) s->Bool();  // resent on (re)connect: state, not news
}

void ValidateReport(const Reader& r) {
  TS_KEYS("program_id", "ok", "report", "replay");
  ReadName(r.At("program_id"));
  r.At("ok").Bool();
  Reader report = r.At("report");
  if (!report.IsObject()) report.Fail("must be an object");
  if (auto s = r.Find("replay")) s->Bool();  // resent on (re)connect: state, not news
}

void ValidateDraggerInput(const Reader& r) {
  TS_KEYS("object", "phase", "world_T_dragger");
  ReadName(r.At("object"));
  ReadOneOf(r.At("phase"), {"begin", "move", "end"});
  ReadPose(r.At("world_T_dragger"));
}

void ValidatePoseUpdate(const Reader& r) {
  TS_KEYS("t_s", "poses", "sim_rate_hz", "world_T_dragger", "input_seq");
  ReadTime(r.At("t_s"));
  Reader poses = r.At("poses");
  std::size_t n = ReadListSize(poses);
  for (std::size_t i = 0; i < n; ++i) {
    Reader p = poses.Index(i);
    p.RejectUnknownKeys({"object", "world_T_object"});
    ReadName(p.At("object"));
    ReadPose(p.At("world_T_object"));
  }
  if (auto s = r.Find("sim_rate_hz")) s->NumberAtLeast(0.0);
  if (auto s = r.Find("world_T_dragger")) ReadPose(*s);
  if (auto s = r.Find("input_seq")) ReadSeq(*s);
}

void ValidateConsoleCommand(const Reader& r) {
  TS_KEYS("line");
  std::string line = ReadText(r.At("line"));
  if (line.size() > 4096) r.At("line").Fail("must be at most 4096 bytes long");
}

void ValidateConsoleOutput(const Reader& r) {
  TS_KEYS("text", "ok", "in_reply_to");
  ReadText(r.At("text"));
  r.At("ok").Bool();
  if (auto s = r.Find("in_reply_to")) ReadSeq(*s);
}

void ValidateSessionName(const Reader& r) {
  TS_KEYS("name");
  ReadSessionName(r.At("name"));
}

void ReadObjectField(const Reader& r) {
  if (!r.IsObject()) r.Fail("must be an object");
}

void ReadNameList(const Reader& r) {
  std::size_t n = ReadListSize(r);
  for (std::size_t i = 0; i < n; ++i) ReadName(r.Index(i));
}

void ReadPoseList(const Reader& r) {
  std::size_t n = ReadListSize(r);
  for (std::size_t i = 0; i < n; ++i) ReadPose(r.Index(i));
}

// {name, shape}: a model of the library; the shape is checked by the scene reader where it is used.
void ReadModelList(const Reader& r) {
  std::size_t n = ReadListSize(r);
  for (std::size_t i = 0; i < n; ++i) {
    Reader m = r.Index(i);
    m.RejectUnknownKeys({"name", "shape"});
    ReadName(m.At("name"));
    ReadObjectField(m.At("shape"));
  }
}

void ValidateWorldState(const Reader& r) {
  TS_KEYS("revision", "objects", "workpiece", "capture", "dragging", "demonstrations", "models", "cameras",
          "robot", "link", "lease_holder", "busy", "paths", "program", "report", "sim_rate_hz");
  r.At("revision").IntegerInRange(1, kMaxJsonInteger);
  Reader objects = r.At("objects");
  std::size_t n = ReadListSize(objects);
  for (std::size_t i = 0; i < n; ++i) {
    Reader o = objects.Index(i);
    o.RejectUnknownKeys({"name", "fixed", "model", "shape", "world_T_object", "origin"});
    ReadName(o.At("name"));
    o.At("fixed").Bool();
    std::string model = o.At("model").String();
    if (model.size() > kMaxNameBytes) o.At("model").Fail("must be at most 256 bytes long");
    ReadObjectField(o.At("shape"));
    ReadPose(o.At("world_T_object"));
    ReadOneOf(o.At("origin"), {"scene", "recognized"});
  }
  if (!r.At("workpiece").IsNull()) ReadName(r.At("workpiece"));
  ReadNameList(r.At("capture"));
  r.At("dragging").Bool();
  r.At("demonstrations").IntegerInRange(0, kMaxJsonInteger);
  ReadModelList(r.At("models"));
  Reader cameras = r.At("cameras");
  std::size_t nc = ReadListSize(cameras);
  for (std::size_t i = 0; i < nc; ++i) ReadObjectField(cameras.Index(i));
  if (!r.At("robot").IsNull()) ReadObjectField(r.At("robot"));
  Reader link = r.At("link");
  link.RejectUnknownKeys({"state", "stopped", "reason", "rtt_s"});
  ReadOneOf(link.At("state"), {"up", "lost"});
  link.At("stopped").Bool();
  ReadText(link.At("reason"));
  if (!link.At("rtt_s").IsNull()) ReadTime(link.At("rtt_s"));
  ReadOptionalSessionId(r.At("lease_holder"));
  ReadOneOf(r.At("busy"), {"", "planning", "executing"});
  Reader paths = r.At("paths");
  paths.RejectUnknownKeys({"initial", "deformed", "simplified"});
  ReadPoseList(paths.At("initial"));
  ReadPoseList(paths.At("deformed"));
  ReadPoseList(paths.At("simplified"));
  if (!r.At("program").IsNull()) {
    Reader p = r.At("program");
    p.RejectUnknownKeys({"id", "command_count", "listing"});
    ReadName(p.At("id"));
    p.At("command_count").IntegerInRange(0, 1000000);
    ReadText(p.At("listing"));
  }
  if (!r.At("report").IsNull()) {
    Reader p = r.At("report");
    p.RejectUnknownKeys({"program_id", "ok", "summary"});
    ReadName(p.At("program_id"));
    p.At("ok").Bool();
    ReadText(p.At("summary"));
  }
  r.At("sim_rate_hz").NumberAtLeast(0.0);
}

void ValidateWorksiteScene(const Reader& r) {
  TS_KEYS("scene", "models");
  // The scene's own fields are checked by the scene reader at the operator site.
  ReadObjectField(r.At("scene"));
  ReadModelList(r.At("models"));
}

#undef TS_KEYS

using T = MessageType;
constexpr std::array kCatalogue = {
    MessageSpec{T::kHello, "hello", "client", false, false, ValidateHello},
    MessageSpec{T::kWelcome, "welcome", "server", false, false, ValidateWelcome},
    MessageSpec{T::kHeartbeat, "heartbeat", "either", false, false, ValidateHeartbeat},
    MessageSpec{T::kError, "error", "either", false, false, ValidateError},
    MessageSpec{T::kLeaseRequest, "lease_request", "client", false, false, ValidateEmpty},
    MessageSpec{T::kLeaseGrant, "lease_grant", "server", false, false, ValidateLeaseGrant},
    MessageSpec{T::kLeaseRelease, "lease_release", "client", false, false, ValidateEmpty},
    MessageSpec{T::kLeaseState, "lease_state", "server", false, false, ValidateLeaseState},
    MessageSpec{T::kLinkState, "link_state", "server", false, false, ValidateLinkState},
    MessageSpec{T::kResume, "resume", "client", false, true, ValidateEmpty},
    MessageSpec{T::kCameraFrame, "camera_frame", "work site", true, false, nullptr},
    MessageSpec{T::kRecognitions, "recognitions", "work site", false, false, ValidateRecognitions},
    MessageSpec{T::kRobotState, "robot_state", "work site", false, false, ValidateRobotState},
    MessageSpec{T::kProgramSubmit, "program_submit", "operator site", false, true, ValidateProgramSubmit},
    MessageSpec{T::kExecutionProgress, "execution_progress", "work site", false, false,
                ValidateExecutionProgress},
    MessageSpec{T::kReport, "report", "work site", false, false, ValidateReport},
    MessageSpec{T::kResetWorld, "reset_world", "client", false, true, ValidateEmpty},
    MessageSpec{T::kDraggerInput, "dragger_input", "browser", false, true, ValidateDraggerInput},
    MessageSpec{T::kPoseUpdate, "pose_update", "operator site", false, false, ValidatePoseUpdate},
    MessageSpec{T::kConsoleCommand, "console_command", "browser", false, false, ValidateConsoleCommand},
    MessageSpec{T::kConsoleOutput, "console_output", "operator site", false, false, ValidateConsoleOutput},
    MessageSpec{T::kSessionSave, "session_save", "browser", false, false, ValidateSessionName},
    MessageSpec{T::kSessionLoad, "session_load", "browser", false, true, ValidateSessionName},
    MessageSpec{T::kWorldState, "world_state", "operator site", false, false, ValidateWorldState},
    MessageSpec{T::kWorksiteScene, "worksite_scene", "work site", false, false, ValidateWorksiteScene},
};

// The catalogue is indexed by the enum's value.
constexpr bool CatalogueInEnumOrder() {
  for (std::size_t i = 0; i < kCatalogue.size(); ++i) {
    if (static_cast<std::size_t>(kCatalogue[i].type) != i) return false;
  }
  return true;
}
static_assert(CatalogueInEnumOrder(), "kCatalogue rows must follow MessageType's order");
// The binary header carries the enum value: docs/protocol.md documents camera_frame = 10.
static_assert(static_cast<int>(MessageType::kCameraFrame) == 10, "wire value of camera_frame changed");

// Nesting depth of a JSON text, counted outside strings; cheap and bounded before the parser
// builds anything (deep nesting would otherwise cost stack in recursive consumers).
int MaxDepth(std::string_view text) {
  int depth = 0, max_depth = 0;
  bool in_string = false, escaped = false;
  for (char c : text) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') in_string = true;
    else if (c == '{' || c == '[') max_depth = std::max(max_depth, ++depth);
    else if (c == '}' || c == ']') --depth;
  }
  return max_depth;
}

MessageError Error(std::string code, std::string message, std::optional<std::uint64_t> seq = {}) {
  return MessageError{std::move(code), std::move(message), seq};
}

Parsed Fail(MessageError e) {
  Parsed p;
  p.error = std::move(e);
  return p;
}

template <typename U>
U LoadLe(const std::uint8_t* p) {
  U v = 0;
  for (std::size_t i = 0; i < sizeof(U); ++i) v |= static_cast<U>(static_cast<U>(p[i]) << (8 * i));
  return v;
}

template <typename U>
void StoreLe(U v, char* p) {
  for (std::size_t i = 0; i < sizeof(U); ++i) p[i] = static_cast<char>((v >> (8 * i)) & 0xff);
}

}  // namespace

std::span<const MessageSpec> MessageCatalogue() { return kCatalogue; }

const MessageSpec& Spec(MessageType type) {
  auto i = static_cast<std::size_t>(type);
  TEACHSIM_CHECK(i < kCatalogue.size());
  return kCatalogue[i];
}

const MessageSpec* FindSpec(std::string_view name) {
  for (const MessageSpec& s : kCatalogue) {
    if (s.name == name) return &s;
  }
  return nullptr;
}

std::string_view TypeName(MessageType type) { return Spec(type).name; }

int BytesPerPixel(PixelFormat format) {
  switch (format) {
    case PixelFormat::kGray8: return 1;
    case PixelFormat::kRgb8: return 3;
  }
  return 0;
}

Status MessageLimits::Validate() const {
  if (max_json_bytes < 256) {
    return Status::InvalidInput("MessageLimits::max_json_bytes = " + std::to_string(max_json_bytes) +
                                " must be >= 256");
  }
  if (max_binary_bytes < kBinaryHeaderBytes + 1) {
    return Status::InvalidInput("MessageLimits::max_binary_bytes = " + std::to_string(max_binary_bytes) +
                                " must be > " + std::to_string(kBinaryHeaderBytes));
  }
  if (max_json_depth < 4 || max_json_depth > 512) {
    return Status::InvalidInput("MessageLimits::max_json_depth = " + std::to_string(max_json_depth) +
                                " must be in [4, 512]");
  }
  return Status::Ok();
}

Parsed ParseTextMessage(std::string_view text, const MessageLimits& limits) {
  if (text.size() > limits.max_json_bytes) {
    return Fail(Error("too_large", "text message of " + std::to_string(text.size()) +
                                       " bytes exceeds the limit of " +
                                       std::to_string(limits.max_json_bytes) + " bytes"));
  }
  if (MaxDepth(text) > limits.max_json_depth) {
    return Fail(Error("too_deep", "JSON nested deeper than " + std::to_string(limits.max_json_depth) +
                                      " levels"));
  }
  Json document;
  try {
    Result<Json> parsed = json::ParseText(text, "message");
    if (!parsed.ok()) return Fail(Error("malformed_json", parsed.status().message()));
    document = std::move(parsed).value();
  } catch (const Json::exception& e) {  // e.g. out_of_range 406 on "1e999"
    return Fail(Error("malformed_json", std::string("message: ") + e.what()));
  }
  if (!document.is_object()) {
    return Fail(Error("not_an_object", std::string("message: must be a JSON object, got ") +
                                           document.type_name()));
  }
  // Read the seq first so that every later error can name the message it answers.
  std::optional<std::uint64_t> seq;
  Message message;
  try {
    Reader root(document);
    seq = ReadSeq(root.At("seq"));
  } catch (const json::ParseError& e) {
    return Fail(Error("invalid_field", e.what()));
  }
  std::string type_name;
  try {
    type_name = Reader(document).At("type").String();
  } catch (const json::ParseError& e) {
    return Fail(Error("invalid_field", e.what(), seq));
  }
  const MessageSpec* spec = FindSpec(type_name);
  if (spec == nullptr) {
    return Fail(Error("unknown_type", "type: unknown message type \"" + type_name.substr(0, 64) + "\"", seq));
  }
  if (spec->binary) {
    return Fail(Error("invalid_field", "type: \"" + type_name + "\" travels as a binary frame, not as JSON",
                      seq));
  }
  try {
    // Paths read "robot_state.joints_rad[3]: ..." so the sender sees which message and field.
    spec->validate(Reader(document, std::string(spec->name)));
  } catch (const json::ParseError& e) {
    return Fail(Error("invalid_field", e.what(), seq));
  } catch (const Json::exception& e) {
    return Fail(Error("invalid_field", std::string(spec->name) + ": " + e.what(), seq));
  }
  message.type = spec->type;
  message.seq = *seq;
  message.body = std::move(document);
  Parsed p;
  p.message = std::move(message);
  return p;
}

Parsed ParseBinaryMessage(std::span<const std::uint8_t> bytes, const MessageLimits& limits) {
  if (bytes.size() > limits.max_binary_bytes) {
    return Fail(Error("too_large", "binary message of " + std::to_string(bytes.size()) +
                                       " bytes exceeds the limit of " +
                                       std::to_string(limits.max_binary_bytes) + " bytes"));
  }
  if (bytes.size() < kBinaryHeaderBytes) {
    return Fail(Error("bad_binary_header", "binary message of " + std::to_string(bytes.size()) +
                                               " bytes is shorter than the " +
                                               std::to_string(kBinaryHeaderBytes) + "-byte header"));
  }
  const std::uint8_t* p = bytes.data();
  if (std::memcmp(p, kBinaryMagic, 4) != 0) {
    return Fail(Error("bad_binary_header", "binary header: magic must be \"TSB1\""));
  }
  BinaryHeader h;
  std::uint64_t seq = LoadLe<std::uint64_t>(p + 8);
  std::optional<std::uint64_t> valid_seq;
  if (seq >= 1 && seq <= static_cast<std::uint64_t>(kMaxJsonInteger)) valid_seq = seq;
  else return Fail(Error("bad_binary_header", "binary header: seq = " + std::to_string(seq) + " must be in [1, 2^53-1]"));
  std::uint8_t type = p[4];
  if (type >= kCatalogue.size() || !kCatalogue[type].binary) {
    return Fail(Error("unknown_type", "binary header: type = " + std::to_string(type) +
                                          " is not a binary message type", valid_seq));
  }
  std::uint8_t format = p[5];
  if (format != static_cast<std::uint8_t>(PixelFormat::kGray8) &&
      format != static_cast<std::uint8_t>(PixelFormat::kRgb8)) {
    return Fail(Error("bad_binary_header", "binary header: format = " + std::to_string(format) +
                                               " must be 1 (gray8) or 2 (rgb8)", valid_seq));
  }
  h.type = static_cast<MessageType>(type);
  h.format = static_cast<PixelFormat>(format);
  h.camera = LoadLe<std::uint16_t>(p + 6);
  h.seq = seq;
  h.width = LoadLe<std::uint32_t>(p + 16);
  h.height = LoadLe<std::uint32_t>(p + 20);
  std::uint64_t stamp_bits = LoadLe<std::uint64_t>(p + 24);
  std::memcpy(&h.stamp_s, &stamp_bits, sizeof(double));
  if (h.width < 1 || h.width > kMaxImageSide || h.height < 1 || h.height > kMaxImageSide) {
    return Fail(Error("bad_binary_header", "binary header: image size " + std::to_string(h.width) + "x" +
                                               std::to_string(h.height) + " must be within 1.." +
                                               std::to_string(kMaxImageSide) + " per side", valid_seq));
  }
  if (!std::isfinite(h.stamp_s) || h.stamp_s < 0) {
    return Fail(Error("bad_binary_header", "binary header: stamp_s must be finite and >= 0", valid_seq));
  }
  std::uint64_t expected = std::uint64_t{h.width} * h.height * BytesPerPixel(h.format);
  std::uint64_t got = bytes.size() - kBinaryHeaderBytes;
  if (got != expected) {
    return Fail(Error("bad_binary_header", "binary frame: " + std::to_string(h.width) + "x" +
                                               std::to_string(h.height) + " pixels need " +
                                               std::to_string(expected) + " bytes after the header, got " +
                                               std::to_string(got), valid_seq));
  }
  Parsed parsed;
  parsed.frame.emplace();
  parsed.frame->header = h;
  parsed.frame->pixels.assign(bytes.begin() + kBinaryHeaderBytes, bytes.end());
  return parsed;
}

Json MakeMessage(MessageType type, std::uint64_t seq, Json fields) {
  Json message = fields.is_object() ? std::move(fields) : Json::object();
  message["type"] = std::string(TypeName(type));
  message["seq"] = seq;
  return message;
}

Status ValidateMessage(const Json& message) {
  if (!message.is_object()) return Status::InvalidInput("message: must be a JSON object");
  try {
    Reader root(message);
    ReadSeq(root.At("seq"));
    std::string type_name = root.At("type").String();
    const MessageSpec* spec = FindSpec(type_name);
    if (spec == nullptr) return Status::InvalidInput("type: unknown message type \"" + type_name + "\"");
    if (spec->binary) return Status::InvalidInput("type: \"" + type_name + "\" is a binary message");
    spec->validate(Reader(message, std::string(spec->name)));
  } catch (const json::ParseError& e) {
    return Status::InvalidInput(e.what());
  } catch (const Json::exception& e) {
    return Status::InvalidInput(e.what());
  }
  return Status::Ok();
}

std::string Serialize(const Json& message) {
  return message.dump(-1, ' ', false, Json::error_handler_t::replace);
}

Json MakeErrorMessage(std::uint64_t seq, const MessageError& error) {
  Json fields = {{"code", error.code}, {"message", error.message.substr(0, kMaxTextBytes)}};
  if (error.in_reply_to) fields["in_reply_to"] = *error.in_reply_to;
  return MakeMessage(MessageType::kError, seq, std::move(fields));
}

Result<std::string> EncodeBinaryFrame(const BinaryHeader& header, std::span<const std::uint8_t> pixels) {
  if (!Spec(header.type).binary) {
    return Status::InvalidInput("BinaryHeader::type = " + std::string(TypeName(header.type)) +
                                " is not a binary message type");
  }
  if (BytesPerPixel(header.format) == 0) return Status::InvalidInput("BinaryHeader::format is unknown");
  if (header.width < 1 || header.width > kMaxImageSide || header.height < 1 || header.height > kMaxImageSide) {
    return Status::InvalidInput("BinaryHeader: image size " + std::to_string(header.width) + "x" +
                                std::to_string(header.height) + " out of range");
  }
  if (header.seq < 1 || header.seq > static_cast<std::uint64_t>(kMaxJsonInteger)) {
    return Status::InvalidInput("BinaryHeader::seq = " + std::to_string(header.seq) + " must be >= 1");
  }
  if (!std::isfinite(header.stamp_s) || header.stamp_s < 0) {
    return Status::InvalidInput("BinaryHeader::stamp_s must be finite and >= 0");
  }
  std::uint64_t expected = std::uint64_t{header.width} * header.height * BytesPerPixel(header.format);
  if (pixels.size() != expected) {
    return Status::InvalidInput("EncodeBinaryFrame: " + std::to_string(pixels.size()) + " pixel bytes, expected " +
                                std::to_string(expected));
  }
  std::string out(kBinaryHeaderBytes + pixels.size(), '\0');
  std::memcpy(out.data(), kBinaryMagic, 4);
  out[4] = static_cast<char>(header.type);
  out[5] = static_cast<char>(header.format);
  StoreLe<std::uint16_t>(header.camera, out.data() + 6);
  StoreLe<std::uint64_t>(header.seq, out.data() + 8);
  StoreLe<std::uint32_t>(header.width, out.data() + 16);
  StoreLe<std::uint32_t>(header.height, out.data() + 20);
  std::uint64_t stamp_bits;
  std::memcpy(&stamp_bits, &header.stamp_s, sizeof(double));
  StoreLe<std::uint64_t>(stamp_bits, out.data() + 24);
  if (!pixels.empty()) std::memcpy(out.data() + kBinaryHeaderBytes, pixels.data(), pixels.size());
  return out;
}

SequenceTracker::Observation SequenceTracker::Observe(std::uint64_t seq) {
  Observation o;
  o.expected = last_ + 1;
  if (seq == o.expected) {
    o.verdict = Verdict::kInOrder;
    last_ = seq;
  } else if (seq > o.expected) {
    o.verdict = Verdict::kGap;
    o.missing = seq - o.expected;
    ++gaps_;
    missing_total_ += o.missing;
    last_ = seq;
  } else {
    o.verdict = Verdict::kDuplicate;
    ++duplicates_;
  }
  return o;
}

bool IsValidSessionName(std::string_view name) {
  if (name.empty() || name.size() > 64 || name.front() == '.') return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '.' || c == '-';
  });
}

}  // namespace teachsim::net
