// Status and Result<T>: the second of the three channels for trouble (STYLE.md): bad input or a
// failure the caller can handle. Messages name the place (file, JSON path, field), the value and
// what was expected.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace teachsim {

enum class StatusCode {
  kOk = 0,
  kInvalidInput,  // malformed file, message or option: the user can fix it (exit status 2)
  kNotFound,      // a named file, object or camera does not exist (exit status 2)
  kIoError,       // reading or writing failed
  kFailed,        // the task itself failed (exit status 1)
  kInternal,      // a bug; should not happen
};

class [[nodiscard]] Status {
 public:
  Status() = default;
  static Status Ok() { return Status(); }
  static Status InvalidInput(std::string message) {
    return Status(StatusCode::kInvalidInput, std::move(message));
  }
  static Status NotFound(std::string message) {
    return Status(StatusCode::kNotFound, std::move(message));
  }
  static Status IoError(std::string message) {
    return Status(StatusCode::kIoError, std::move(message));
  }
  static Status Failed(std::string message) { return Status(StatusCode::kFailed, std::move(message)); }
  static Status Internal(std::string message) {
    return Status(StatusCode::kInternal, std::move(message));
  }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }

  // "prefix: message", e.g. the file name in front of a parser's JSON path.
  Status WithPrefix(std::string_view prefix) const {
    if (ok()) return *this;
    return Status(code_, std::string(prefix) + ": " + message_);
  }

  // The process exit status DESIGN.md assigns: 0 done, 1 task failed, 2 bad input.
  int ExitCode() const;

 private:
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : data_(std::move(value)) {}           // NOLINT(google-explicit-constructor)
  Result(Status status) : data_(std::move(status)) {     // NOLINT(google-explicit-constructor)
    if (std::get<Status>(data_).ok()) data_ = Status::Internal("Result built from an ok Status");
  }

  bool ok() const { return std::holds_alternative<T>(data_); }
  const Status& status() const {
    static const Status kOk;
    return ok() ? kOk : std::get<Status>(data_);
  }
  T& value() & { return std::get<T>(data_); }
  const T& value() const& { return std::get<T>(data_); }
  T&& value() && { return std::get<T>(std::move(data_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

 private:
  std::variant<T, Status> data_;
};

namespace internal {
[[noreturn]] void CheckFailed(const char* file, int line, const char* condition, const char* message);
}  // namespace internal

}  // namespace teachsim

#define TEACHSIM_RETURN_IF_ERROR(expr)               \
  do {                                               \
    ::teachsim::Status teachsim_status_ = (expr);    \
    if (!teachsim_status_.ok()) return teachsim_status_; \
  } while (false)

#define TEACHSIM_CONCAT_INNER(a, b) a##b
#define TEACHSIM_CONCAT(a, b) TEACHSIM_CONCAT_INNER(a, b)
#define TEACHSIM_ASSIGN_OR_RETURN(lhs, expr) \
  TEACHSIM_ASSIGN_OR_RETURN_IMPL(TEACHSIM_CONCAT(teachsim_result_, __LINE__), lhs, expr)
#define TEACHSIM_ASSIGN_OR_RETURN_IMPL(result, lhs, expr) \
  auto result = (expr);                                   \
  if (!result.ok()) return result.status();               \
  lhs = std::move(result).value()

// The first channel: a broken invariant (a bug). Stays on in every build, release included.
#define TEACHSIM_CHECK(condition)                                                     \
  do {                                                                                \
    if (!(condition)) ::teachsim::internal::CheckFailed(__FILE__, __LINE__, #condition, ""); \
  } while (false)
#define TEACHSIM_CHECK_MSG(condition, message)                                              \
  do {                                                                                      \
    if (!(condition))                                                                       \
      ::teachsim::internal::CheckFailed(__FILE__, __LINE__, #condition, (message));         \
  } while (false)
