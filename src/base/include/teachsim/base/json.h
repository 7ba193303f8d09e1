// Reading JSON with errors that name the JSON path, and writing files atomically.
//
// Parsers walk a document with json::Reader; every accessor checks the type and range it expects
// and otherwise throws json::ParseError("objects[3].shape.box[1]: must be > 0, got -0.02").
// Exceptions stay inside parsers: ParseFile()/Parse() catch them and return a Status prefixed
// with the file name (STYLE.md, "three channels for trouble").
#pragma once

#include <Eigen/Core>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "teachsim/base/status.h"

namespace teachsim::json {

using Json = nlohmann::json;

class ParseError : public std::runtime_error {
 public:
  explicit ParseError(const std::string& message) : std::runtime_error(message) {}
};

class Reader {
 public:
  explicit Reader(const Json& value, std::string path = {}) : value_(&value), path_(std::move(path)) {}

  const Json& raw() const { return *value_; }
  // "objects[3].shape", or "(root)" for the document itself.
  std::string where() const { return path_.empty() ? "(root)" : path_; }

  bool IsObject() const { return value_->is_object(); }
  bool IsArray() const { return value_->is_array(); }
  bool IsNull() const { return value_->is_null(); }

  // Object access. At() requires the key; Find() returns nullopt when it is absent.
  bool Has(std::string_view key) const;
  Reader At(std::string_view key) const;
  std::optional<Reader> Find(std::string_view key) const;
  // Fails on any key outside `allowed`, to catch misspelt fields ("quaternion_xyzw").
  void RejectUnknownKeys(std::initializer_list<std::string_view> allowed) const;
  std::vector<std::string> Keys() const;

  // Array access.
  std::size_t Size() const;  // requires an array
  Reader Index(std::size_t i) const;
  // Requires an array of exactly n elements.
  void ExpectSize(std::size_t n) const;

  double Number() const;  // a finite number
  double NumberAtLeast(double min) const;
  double NumberGreaterThan(double min) const;
  double NumberInRange(double min, double max) const;
  long long Integer() const;
  long long IntegerInRange(long long min, long long max) const;
  bool Bool() const;
  std::string String() const;
  std::string NonEmptyString() const;
  Eigen::Vector3d Vector3() const;  // [x, y, z], finite

  [[noreturn]] void Fail(const std::string& problem) const;

 private:
  const char* TypeName() const;
  const Json* value_;
  std::string path_;
};

// Reads and parses a JSON file. Errors: "FILE: cannot open: ..." or "FILE: line L, column C: ...".
[[nodiscard]] Result<Json> ReadFile(const std::string& path);
// Parses text; `name` stands in for the file name in error messages.
[[nodiscard]] Result<Json> ParseText(std::string_view text, const std::string& name);

// Runs `parse(reader)` over a parsed document; a ParseError becomes InvalidInput "name: path: problem".
template <typename T, typename F>
Result<T> Decode(const Json& document, const std::string& name, F&& parse) {
  try {
    return parse(Reader(document));
  } catch (const ParseError& e) {
    return Status::InvalidInput(name + ": " + e.what());
  } catch (const Json::exception& e) {
    return Status::InvalidInput(name + ": " + e.what());
  }
}

// Formats a double for paths in messages: 6 significant digits ("-0.02").
std::string FormatNumber(double value);

// Writes `contents` to `path` atomically: a temporary file in the same folder, flushed and synced,
// then renamed over the target, so a crash never leaves a half-written file behind.
[[nodiscard]] Status WriteFileAtomic(const std::string& path, std::string_view contents);
// The document pretty-printed with a trailing newline, written atomically.
[[nodiscard]] Status WriteJsonFile(const std::string& path, const Json& document);

}  // namespace teachsim::json
