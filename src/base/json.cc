#include "teachsim/base/json.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace teachsim::json {

namespace {

std::string Child(const std::string& path, std::string_view key) {
  if (path.empty()) return std::string(key);
  return path + "." + std::string(key);
}

// nlohmann reports a byte offset; people want line and column.
std::string LineColumn(std::string_view text, std::size_t byte) {
  byte = std::min(byte, text.size());
  std::size_t line = 1, column = 1;
  for (std::size_t i = 0; i + 1 < byte; ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return "line " + std::to_string(line) + ", column " + std::to_string(column);
}

}  // namespace

std::string FormatNumber(double value) {
  std::ostringstream out;
  out.precision(6);
  out << value;
  return out.str();
}

const char* Reader::TypeName() const {
  return value_->type_name();
}

void Reader::Fail(const std::string& problem) const { throw ParseError(where() + ": " + problem); }

bool Reader::Has(std::string_view key) const {
  return value_->is_object() && value_->find(key) != value_->end();
}

Reader Reader::At(std::string_view key) const {
  if (!value_->is_object()) Fail(std::string("must be an object, got ") + TypeName());
  auto it = value_->find(key);
  if (it == value_->end()) throw ParseError(Child(path_, key) + ": missing");
  return Reader(*it, Child(path_, key));
}

std::optional<Reader> Reader::Find(std::string_view key) const {
  if (!value_->is_object()) Fail(std::string("must be an object, got ") + TypeName());
  auto it = value_->find(key);
  if (it == value_->end()) return std::nullopt;
  return Reader(*it, Child(path_, key));
}

void Reader::RejectUnknownKeys(std::initializer_list<std::string_view> allowed) const {
  if (!value_->is_object()) Fail(std::string("must be an object, got ") + TypeName());
  for (auto it = value_->begin(); it != value_->end(); ++it) {
    if (std::find(allowed.begin(), allowed.end(), it.key()) == allowed.end()) {
      std::string known;
      for (std::string_view k : allowed) known += (known.empty() ? "" : ", ") + std::string(k);
      Fail("unknown field '" + it.key() + "' (expected one of: " + known + ")");
    }
  }
}

std::vector<std::string> Reader::Keys() const {
  if (!value_->is_object()) Fail(std::string("must be an object, got ") + TypeName());
  std::vector<std::string> keys;
  for (auto it = value_->begin(); it != value_->end(); ++it) keys.push_back(it.key());
  return keys;
}

std::size_t Reader::Size() const {
  if (!value_->is_array()) Fail(std::string("must be an array, got ") + TypeName());
  return value_->size();
}

Reader Reader::Index(std::size_t i) const {
  if (!value_->is_array()) Fail(std::string("must be an array, got ") + TypeName());
  if (i >= value_->size()) Fail("index " + std::to_string(i) + " out of range");
  return Reader((*value_)[i], path_ + "[" + std::to_string(i) + "]");
}

void Reader::ExpectSize(std::size_t n) const {
  std::size_t size = Size();
  if (size != n) {
    Fail("must have " + std::to_string(n) + " elements, got " + std::to_string(size));
  }
}

double Reader::Number() const {
  if (!value_->is_number()) Fail(std::string("must be a number, got ") + TypeName());
  double v = value_->get<double>();
  if (!std::isfinite(v)) Fail("must be finite");
  return v;
}

double Reader::NumberAtLeast(double min) const {
  double v = Number();
  if (v < min) Fail("must be >= " + FormatNumber(min) + ", got " + FormatNumber(v));
  return v;
}

double Reader::NumberGreaterThan(double min) const {
  double v = Number();
  if (!(v > min)) Fail("must be > " + FormatNumber(min) + ", got " + FormatNumber(v));
  return v;
}

double Reader::NumberInRange(double min, double max) const {
  double v = Number();
  if (v < min || v > max) {
    Fail("must be in [" + FormatNumber(min) + ", " + FormatNumber(max) + "], got " + FormatNumber(v));
  }
  return v;
}

long long Reader::Integer() const {
  if (value_->is_number_integer()) return value_->get<long long>();
  if (value_->is_number_float()) {
    double v = value_->get<double>();
    if (std::isfinite(v) && v == std::floor(v) && std::abs(v) < 9e15) return static_cast<long long>(v);
  }
  Fail(std::string("must be an integer, got ") + (value_->is_number() ? value_->dump() : TypeName()));
}

long long Reader::IntegerInRange(long long min, long long max) const {
  long long v = Integer();
  if (v < min || v > max) {
    Fail("must be in [" + std::to_string(min) + ", " + std::to_string(max) + "], got " +
         std::to_string(v));
  }
  return v;
}

bool Reader::Bool() const {
  if (!value_->is_boolean()) Fail(std::string("must be true or false, got ") + TypeName());
  return value_->get<bool>();
}

std::string Reader::String() const {
  if (!value_->is_string()) Fail(std::string("must be a string, got ") + TypeName());
  return value_->get<std::string>();
}

std::string Reader::NonEmptyString() const {
  std::string s = String();
  if (s.empty()) Fail("must not be empty");
  return s;
}

Eigen::Vector3d Reader::Vector3() const {
  ExpectSize(3);
  return {Index(0).Number(), Index(1).Number(), Index(2).Number()};
}

Result<Json> ParseText(std::string_view text, const std::string& name) {
  try {
    return Json::parse(text.begin(), text.end());
  } catch (const Json::parse_error& e) {
    std::string what = e.what();
    // Keep nlohmann's reason, drop its "[json.exception.parse_error.101] parse error at ..." prefix.
    auto pos = what.find(": syntax error");
    std::string reason = pos == std::string::npos ? what : what.substr(pos + 2);
    return Status::InvalidInput(name + ": " + LineColumn(text, e.byte) + ": " + reason);
  } catch (const Json::exception& e) {
    // e.g. out_of_range 406 for a number like 1e999: still bad input, never a crash.
    return Status::InvalidInput(name + ": " + e.what());
  }
}

Result<Json> ReadFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return Status::InvalidInput(path + ": is a folder, not a JSON file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound(path + ": cannot open: " + std::strerror(errno));
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) return Status::IoError(path + ": read failed");
  return ParseText(buffer.str(), path);
}

Status WriteFileAtomic(const std::string& path, std::string_view contents) {
  namespace fs = std::filesystem;
  fs::path target(path);
  fs::path folder = target.has_parent_path() ? target.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) {
    return Status::NotFound(path + ": cannot write: folder " + folder.string() + " does not exist");
  }
  std::string temp = (folder / ("." + target.filename().string() + ".tmp-XXXXXX")).string();
  int fd = ::mkstemp(temp.data());
  if (fd < 0) return Status::IoError(path + ": cannot create temporary file: " + std::strerror(errno));
  std::size_t written = 0;
  while (written < contents.size()) {
    ssize_t n = ::write(fd, contents.data() + written, contents.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      std::string reason = std::strerror(errno);
      ::close(fd);
      ::unlink(temp.c_str());
      return Status::IoError(path + ": write failed: " + reason);
    }
    written += static_cast<std::size_t>(n);
  }
  ::fchmod(fd, 0644);
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    ::unlink(temp.c_str());
    return Status::IoError(path + ": cannot flush: " + std::strerror(errno));
  }
  if (::rename(temp.c_str(), path.c_str()) != 0) {
    std::string reason = std::strerror(errno);
    ::unlink(temp.c_str());
    return Status::IoError(path + ": cannot rename into place: " + reason);
  }
  return Status::Ok();
}

Status WriteJsonFile(const std::string& path, const Json& document) {
  return WriteFileAtomic(path, document.dump(2) + "\n");
}

}  // namespace teachsim::json
