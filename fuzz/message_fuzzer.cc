// libFuzzer harness for the link's message parser (docs/protocol.md): every input, read as a
// text frame and as a binary frame, alone and through a Peer, must give a message or an error,
// never a crash, and the outcomes must be self-consistent (see message_fuzz_target.h).
#include <cstddef>
#include <cstdint>

#include "message_fuzz_target.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  teachsim::net::fuzz::RunMessageInput(data, size);
  return 0;
}
