#include "teachsim/net/auth.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace teachsim::net {

Result<Token> ReadTokenFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return Status::InvalidInput(path + ": token file is a folder");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound(path + ": cannot read token file: " + std::strerror(errno));
  std::string first_line;
  std::getline(in, first_line);
  if (in.bad()) return Status::IoError(path + ": cannot read token file");
  const char* space = " \t\r\n\v\f";
  std::size_t begin = first_line.find_first_not_of(space);
  if (begin == std::string::npos) {
    return Status::InvalidInput(path + ": token file is empty (its first line must hold the shared secret)");
  }
  std::size_t end = first_line.find_last_not_of(space);
  std::string secret = first_line.substr(begin, end - begin + 1);
  if (secret.size() < kMinTokenBytes) {
    return Status::InvalidInput(path + ": token is shorter than " + std::to_string(kMinTokenBytes) +
                                " bytes; use a longer random secret (e.g. `openssl rand -hex 32`)");
  }
  for (char c : secret) {
    // It travels in an HTTP header: visible ASCII only.
    if (static_cast<unsigned char>(c) < 0x21 || static_cast<unsigned char>(c) > 0x7e) {
      return Status::InvalidInput(path + ": token must be printable ASCII without spaces");
    }
  }
  return Token(std::move(secret));
}

bool ConstantTimeEquals(std::string_view given, std::string_view expected) {
  // Touch every byte of `expected` whatever `given` holds; the loop bound and the work per byte
  // never depend on the secret's contents. volatile keeps the compiler from exiting early.
  volatile unsigned char diff = given.size() == expected.size() ? 0 : 1;
  for (std::size_t i = 0; i < expected.size(); ++i) {
    unsigned char g = i < given.size() ? static_cast<unsigned char>(given[i]) : 0;
    diff = static_cast<unsigned char>(diff | (g ^ static_cast<unsigned char>(expected[i])));
  }
  return diff == 0;
}

std::string_view BearerToken(std::string_view header) {
  constexpr std::string_view kScheme = "bearer ";
  if (header.size() <= kScheme.size()) return {};
  for (std::size_t i = 0; i < kScheme.size(); ++i) {
    char c = header[i];
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
    if (c != kScheme[i]) return {};
  }
  std::string_view token = header.substr(kScheme.size());
  while (!token.empty() && token.front() == ' ') token.remove_prefix(1);
  while (!token.empty() && token.back() == ' ') token.remove_suffix(1);
  return token;
}

bool Authorized(std::string_view header, const Token& expected) {
  if (expected.empty()) return false;
  return ConstantTimeEquals(BearerToken(header), expected.secret());
}

}  // namespace teachsim::net
