// Work-site link authentication: a shared secret read once from a file and sent by the client as
// "Authorization: Bearer <token>" on the HTTP upgrade request. The server compares it in constant
// time before upgrading; a peer without the right token gets "401 Unauthorized" and nothing else.
// Tokens never appear in logs or error messages.
#pragma once

#include <string>
#include <string_view>

#include "teachsim/base/status.h"

namespace teachsim::net {

// A secret that does not print itself.
class Token {
 public:
  Token() = default;
  explicit Token(std::string secret) : secret_(std::move(secret)) {}
  bool empty() const { return secret_.empty(); }
  const std::string& secret() const { return secret_; }

 private:
  std::string secret_;
};

inline constexpr std::size_t kMinTokenBytes = 16;

// Reads the token file: the first line without surrounding white space. Errors name the file and
// the problem ("cannot read", "is empty", "shorter than 16 bytes"), never the content.
[[nodiscard]] Result<Token> ReadTokenFile(const std::string& path);

// Compares in time that depends only on expected.size(), not on where the inputs differ.
bool ConstantTimeEquals(std::string_view given, std::string_view expected);

// The token of an "Authorization" header value "Bearer <token>" (scheme case-insensitive), or an
// empty view when the header has another form.
std::string_view BearerToken(std::string_view authorization_header);

// Whether the header value carries `expected` (constant-time in the token comparison).
bool Authorized(std::string_view authorization_header, const Token& expected);

}  // namespace teachsim::net
