// The link's messages (docs/protocol.md): JSON text frames for control, each an object
// {"type": ..., "seq": N, ...fields}, and binary frames for camera images (a 32-byte header, then
// pixels). Every message a peer sends carries the next number of that sender's sequence (1, 2, 3,
// ... per connection, text and binary alike); the receiver detects gaps and duplicates.
//
// Every incoming message is validated against the catalogue before anything acts on it: the type
// is known, every field is present with the right type and range, no field is unknown. A message
// that fails gets a MessageError whose text names the field ("welcome.session: must be an integer,
// got \"x\""); the server answers it with an "error" message and carries on.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"

namespace teachsim::net {

inline constexpr int kProtocolVersion = 1;
// Largest integer a browser's JSON.parse keeps exactly (2^53 - 1): the top of every seq and id.
inline constexpr long long kMaxJsonInteger = 9007199254740991LL;

enum class MessageType : std::uint8_t {
  kHello,
  kWelcome,
  kHeartbeat,
  kError,
  kLeaseRequest,
  kLeaseGrant,
  kLeaseRelease,
  kLeaseState,
  kLinkState,
  kResume,
  kCameraFrame,  // binary
  kRecognitions,
  kRobotState,
  kProgramSubmit,
  kExecutionProgress,
  kReport,
  kResetWorld,
  kDraggerInput,
  kPoseUpdate,
  kConsoleCommand,
  kConsoleOutput,
  kSessionSave,
  kSessionLoad,
  kWorldState,     // operator -> browser: the whole operator state (docs/protocol.md)
  kWorksiteScene,  // work site -> operator: its nominal scene and model library
};

// One row of the catalogue.
struct MessageSpec {
  MessageType type;
  std::string_view name;     // the "type" string on the wire
  std::string_view sent_by;  // documentation: "client", "server", "work site", "either", ...
  bool binary = false;       // travels as a binary frame
  bool needs_lease = false;  // refused from a session that does not hold the controller lease
  // Checks the fields of a JSON message (the whole object, "type" and "seq" included); throws
  // json::ParseError naming the field. Null for binary messages.
  void (*validate)(const json::Reader& message) = nullptr;
};

std::span<const MessageSpec> MessageCatalogue();
const MessageSpec& Spec(MessageType type);
const MessageSpec* FindSpec(std::string_view name);  // null if unknown
std::string_view TypeName(MessageType type);

// A validated JSON message. `body` is the whole object, "type" and "seq" included.
struct Message {
  MessageType type = MessageType::kError;
  std::uint64_t seq = 0;
  json::Json body;
};

// Image pixel layouts in a camera frame.
enum class PixelFormat : std::uint8_t { kGray8 = 1, kRgb8 = 2 };
int BytesPerPixel(PixelFormat format);

// The binary frame header (docs/protocol.md, "Binary frames"): little-endian, 32 bytes.
inline constexpr std::size_t kBinaryHeaderBytes = 32;
inline constexpr char kBinaryMagic[4] = {'T', 'S', 'B', '1'};
inline constexpr std::uint32_t kMaxImageSide = 16384;
struct BinaryHeader {
  MessageType type = MessageType::kCameraFrame;
  PixelFormat format = PixelFormat::kGray8;
  std::uint16_t camera = 0;  // index of the camera in the work site's scene
  std::uint64_t seq = 0;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  double stamp_s = 0;  // capture time on the sender's clock, seconds
};

struct BinaryFrame {
  BinaryHeader header;
  std::vector<std::uint8_t> pixels;  // row-major, height rows of width * BytesPerPixel bytes
};

struct MessageLimits {
  std::size_t max_json_bytes = 1 << 20;    // 1 MiB
  std::size_t max_binary_bytes = 8 << 20;  // 8 MiB, header included
  int max_json_depth = 64;                 // nesting of objects and arrays
  [[nodiscard]] Status Validate() const;
};

// Why an incoming message was refused. `code` is one of the codes in docs/protocol.md
// ("too_large", "malformed_json", "too_deep", "not_an_object", "unknown_type", "invalid_field",
// "bad_binary_header", "bad_sequence", ...); `message` names the problem and the field.
struct MessageError {
  std::string code;
  std::string message;
  std::optional<std::uint64_t> in_reply_to;  // the refused message's seq, when it could be read
};

// The outcome of parsing one frame: exactly one of message / frame / error is set.
struct Parsed {
  std::optional<Message> message;
  std::optional<BinaryFrame> frame;
  std::optional<MessageError> error;
  bool ok() const { return !error.has_value(); }
};

// Parses and validates a text frame. Never throws; any input gives a message or an error.
Parsed ParseTextMessage(std::string_view text, const MessageLimits& limits);
// Parses and validates a binary frame.
Parsed ParseBinaryMessage(std::span<const std::uint8_t> bytes, const MessageLimits& limits);

// Builds a message object: {"type": name, "seq": seq} plus `fields` (an object).
json::Json MakeMessage(MessageType type, std::uint64_t seq, json::Json fields = json::Json::object());
// Validates an outgoing message; InvalidInput names the field. Catches a service's mistakes
// before they reach the peer.
[[nodiscard]] Status ValidateMessage(const json::Json& message);
// Serialises a message (invalid UTF-8 replaced, never throws).
std::string Serialize(const json::Json& message);
// The "error" message answering `error`.
json::Json MakeErrorMessage(std::uint64_t seq, const MessageError& error);

// Encodes a camera frame. `pixels.size()` must equal width * height * BytesPerPixel(format).
[[nodiscard]] Result<std::string> EncodeBinaryFrame(const BinaryHeader& header,
                                                    std::span<const std::uint8_t> pixels);

// Outgoing sequence numbers: 1, 2, 3, ... per connection.
class SequenceCounter {
 public:
  std::uint64_t Next() { return next_++; }
  std::uint64_t peek() const { return next_; }

 private:
  std::uint64_t next_ = 1;
};

// Incoming sequence numbers: each should be the last plus one. A larger one is a gap (accepted,
// the missing count reported); a smaller or equal one is a duplicate or replay (to be dropped).
class SequenceTracker {
 public:
  enum class Verdict { kInOrder, kGap, kDuplicate };
  struct Observation {
    Verdict verdict = Verdict::kInOrder;
    std::uint64_t expected = 1;  // what was expected
    std::uint64_t missing = 0;   // kGap: how many numbers were skipped
  };
  Observation Observe(std::uint64_t seq);
  std::uint64_t last() const { return last_; }
  std::uint64_t gaps() const { return gaps_; }
  std::uint64_t missing_total() const { return missing_total_; }
  std::uint64_t duplicates() const { return duplicates_; }

 private:
  std::uint64_t last_ = 0;
  std::uint64_t gaps_ = 0;
  std::uint64_t missing_total_ = 0;
  std::uint64_t duplicates_ = 0;
};

// Session names for session_save/session_load: 1-64 of [A-Za-z0-9_.-], not starting with '.',
// so a name can never leave the sessions folder.
bool IsValidSessionName(std::string_view name);

}  // namespace teachsim::net
