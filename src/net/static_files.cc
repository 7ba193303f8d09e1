#include "teachsim/net/static_files.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <filesystem>
#include <utility>

namespace teachsim::net {

namespace fs = std::filesystem;

namespace {

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

bool IsWithin(const fs::path& root, const fs::path& path) {
  auto r = root.begin(), p = path.begin();
  for (; r != root.end(); ++r, ++p) {
    if (p == path.end() || *r != *p) return false;
  }
  return true;
}

}  // namespace

Result<std::string> PercentDecode(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] != '%') {
      out += text[i];
      continue;
    }
    if (i + 2 >= text.size()) return Status::InvalidInput("malformed percent escape");
    int hi = HexValue(text[i + 1]), lo = HexValue(text[i + 2]);
    if (hi < 0 || lo < 0) return Status::InvalidInput("malformed percent escape");
    char c = static_cast<char>(hi * 16 + lo);
    if (c == '\0') return Status::InvalidInput("encoded NUL in path");
    out += c;
    i += 2;
  }
  return out;
}

Result<std::string> ResolveStaticPath(const std::string& root, std::string_view target) {
  if (target.empty() || target.front() != '/') return Status::InvalidInput("request target must start with '/'");
  std::string_view path_part = target.substr(0, target.find_first_of("?#"));
  TEACHSIM_ASSIGN_OR_RETURN(std::string decoded, PercentDecode(path_part));
  if (decoded.find('\\') != std::string::npos || decoded.find('\0') != std::string::npos) {
    return Status::InvalidInput("request path contains a backslash or NUL");
  }
  // Refuse any ".." segment outright (after decoding, so %2e%2e is caught too) rather than
  // normalising it away: no legitimate UI URL contains one.
  std::size_t start = 0;
  while (start <= decoded.size()) {
    std::size_t end = decoded.find('/', start);
    if (end == std::string::npos) end = decoded.size();
    std::string_view segment(decoded.data() + start, end - start);
    if (segment == "..") return Status::InvalidInput("request path leaves the web root ('..')");
    if (!segment.empty() && segment.front() == '.' && segment != ".") {
      return Status::NotFound("hidden files are not served");
    }
    start = end + 1;
  }
  std::error_code ec;
  fs::path root_path = fs::canonical(root, ec);
  if (ec) return Status::NotFound(root + ": web root does not exist");
  fs::path candidate = root_path / fs::path(decoded).relative_path();
  if (fs::is_directory(candidate, ec)) candidate /= "index.html";
  fs::path resolved = fs::canonical(candidate, ec);
  if (ec) return Status::NotFound("no such file");
  if (!IsWithin(root_path, resolved)) return Status::InvalidInput("request path leaves the web root");
  if (!fs::is_regular_file(resolved, ec)) return Status::NotFound("not a regular file");
  return resolved.string();
}

std::string_view MimeType(std::string_view path) {
  static constexpr std::array<std::pair<std::string_view, std::string_view>, 20> kTypes = {{
      {".html", "text/html; charset=utf-8"},
      {".htm", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"},
      {".mjs", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".json", "application/json"},
      {".map", "application/json"},
      {".txt", "text/plain; charset=utf-8"},
      {".md", "text/markdown; charset=utf-8"},
      {".png", "image/png"},
      {".jpg", "image/jpeg"},
      {".jpeg", "image/jpeg"},
      {".gif", "image/gif"},
      {".svg", "image/svg+xml"},
      {".ico", "image/x-icon"},
      {".wasm", "application/wasm"},
      {".glb", "model/gltf-binary"},
      {".gltf", "model/gltf+json"},
      {".woff2", "font/woff2"},
      {".woff", "font/woff"},
  }};
  std::size_t dot = path.rfind('.');
  std::size_t slash = path.rfind('/');
  if (dot == std::string_view::npos || (slash != std::string_view::npos && dot < slash)) {
    return "application/octet-stream";
  }
  std::string ext(path.substr(dot));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const auto& [e, type] : kTypes) {
    if (e == ext) return type;
  }
  return "application/octet-stream";
}

}  // namespace teachsim::net
