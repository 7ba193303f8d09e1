#include "teachsim/net/peer.h"

#include <algorithm>

namespace teachsim::net {

using json::Json;

Status PeerOptions::Validate() const {
  TEACHSIM_RETURN_IF_ERROR(limits.Validate());
  return WatchdogOptions{link_timeout_s}.Validate();
}

Peer::Peer(const Clock& clock, PeerOptions options)
    : clock_(&clock),
      options_(std::move(options)),
      watchdog_(clock, WatchdogOptions{options_.link_timeout_s}),
      epoch_(clock.Now()) {
  TEACHSIM_CHECK_MSG(options_.Validate().ok(), "invalid PeerOptions");
}

double Peer::NowSeconds() const { return ToSeconds(clock_->Now() - epoch_); }

void Peer::ResetSequences() {
  out_seq_ = SequenceCounter();
  in_seq_ = SequenceTracker();
  echo_t_s_.reset();
}

Incoming Peer::Refuse(Incoming in, MessageError error) {
  ++stats_.refused;
  Json reply = MakeErrorMessage(out_seq_.Next(), error);
  ++stats_.sent;
  in.replies.push_back({Serialize(reply), false});
  in.error = std::move(error);
  return in;
}

bool Peer::TrackSequence(std::optional<std::uint64_t> seq, Incoming* in) {
  if (!seq) return true;
  SequenceTracker::Observation o = in_seq_.Observe(*seq);
  if (o.verdict == SequenceTracker::Verdict::kDuplicate) {
    ++stats_.seq_duplicates;
    *in = Refuse(std::move(*in), {"duplicate_seq",
                                  "seq: " + std::to_string(*seq) + " repeats or precedes an earlier message (expected " +
                                      std::to_string(o.expected) + "); dropped",
                                  *seq});
    return false;
  }
  if (o.verdict == SequenceTracker::Verdict::kGap) {
    // Reported, and the message itself is still used: TCP lost nothing, the sender skipped.
    ++stats_.seq_gaps;
    MessageError gap{"seq_gap",
                     "seq: expected " + std::to_string(o.expected) + ", got " + std::to_string(*seq) + " (" +
                         std::to_string(o.missing) + " missing)",
                     *seq};
    in->replies.push_back({Serialize(MakeErrorMessage(out_seq_.Next(), gap)), false});
    ++stats_.sent;
  }
  return true;
}

Incoming Peer::OnText(std::string_view text) {
  ++stats_.received;
  Incoming in;
  in.link_event = watchdog_.OnReceived();  // any frame, valid or not, proves the link alive
  Parsed parsed = ParseTextMessage(text, options_.limits);
  // A refused message still used up its number at the sender: track it, so the next is no gap.
  std::optional<std::uint64_t> seq =
      parsed.message ? std::optional<std::uint64_t>(parsed.message->seq) : parsed.error->in_reply_to;
  if (!TrackSequence(seq, &in)) return in;
  if (!parsed.ok()) return Refuse(std::move(in), std::move(*parsed.error));
  if (parsed.message->type == MessageType::kHeartbeat) OnHeartbeat(*parsed.message);
  in.message = std::move(parsed.message);
  return in;
}

Incoming Peer::OnBinary(std::span<const std::uint8_t> bytes) {
  ++stats_.received;
  Incoming in;
  in.link_event = watchdog_.OnReceived();
  Parsed parsed = ParseBinaryMessage(bytes, options_.limits);
  std::optional<std::uint64_t> seq =
      parsed.frame ? std::optional<std::uint64_t>(parsed.frame->header.seq) : parsed.error->in_reply_to;
  if (!TrackSequence(seq, &in)) return in;
  if (!parsed.ok()) return Refuse(std::move(in), std::move(*parsed.error));
  in.frame = std::move(parsed.frame);
  return in;
}

Incoming Peer::OnOversize(bool binary, std::size_t bytes) {
  ++stats_.received;
  Incoming in;
  in.link_event = watchdog_.OnReceived();
  std::size_t limit = binary ? options_.limits.max_binary_bytes : options_.limits.max_json_bytes;
  return Refuse(std::move(in), {"too_large", std::string(binary ? "binary" : "text") + " message of " +
                                                 std::to_string(bytes) + " bytes exceeds the limit of " +
                                                 std::to_string(limit) + " bytes",
                                std::nullopt});
}

void Peer::OnHeartbeat(const Message& heartbeat) {
  echo_t_s_ = heartbeat.body.at("t_s").get<double>();
  echo_received_ = clock_->Now();
  if (heartbeat.body.contains("echo_t_s")) {
    // Our own earlier t_s came back after the peer held it hold_s: the rest is the round trip.
    double rtt = NowSeconds() - heartbeat.body.at("echo_t_s").get<double>() -
                 heartbeat.body.at("hold_s").get<double>();
    if (rtt >= 0) stats_.rtt_s = rtt;
  }
}

Result<OutFrame> Peer::Encode(MessageType type, Json fields) {
  if (Spec(type).binary) return Status::InvalidInput(std::string(TypeName(type)) + " is a binary message");
  if (!fields.is_object()) return Status::InvalidInput(std::string(TypeName(type)) + ": fields must be an object");
  Json message = MakeMessage(type, out_seq_.peek(), std::move(fields));
  TEACHSIM_RETURN_IF_ERROR(ValidateMessage(message));
  std::string text = Serialize(message);
  if (text.size() > options_.limits.max_json_bytes) {
    return Status::InvalidInput(std::string(TypeName(type)) + ": " + std::to_string(text.size()) +
                                " bytes exceed the peer's limit of " + std::to_string(options_.limits.max_json_bytes));
  }
  out_seq_.Next();
  ++stats_.sent;
  return OutFrame{std::move(text), false};
}

Result<OutFrame> Peer::EncodeFrame(BinaryHeader header, std::span<const std::uint8_t> pixels) {
  header.seq = out_seq_.peek();
  TEACHSIM_ASSIGN_OR_RETURN(std::string data, EncodeBinaryFrame(header, pixels));
  if (data.size() > options_.limits.max_binary_bytes) {
    return Status::InvalidInput("camera frame of " + std::to_string(data.size()) + " bytes exceeds the limit of " +
                                std::to_string(options_.limits.max_binary_bytes));
  }
  out_seq_.Next();
  ++stats_.sent;
  return OutFrame{std::move(data), true};
}

OutFrame Peer::Heartbeat() {
  Json fields = {{"t_s", NowSeconds()}};
  if (echo_t_s_) {
    fields["echo_t_s"] = *echo_t_s_;
    fields["hold_s"] = std::max(0.0, ToSeconds(clock_->Now() - echo_received_));
  }
  Json message = MakeMessage(MessageType::kHeartbeat, out_seq_.Next(), std::move(fields));
  ++stats_.sent;
  return {Serialize(message), false};
}

}  // namespace teachsim::net
