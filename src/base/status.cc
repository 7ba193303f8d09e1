#include "teachsim/base/status.h"

namespace teachsim {

int Status::ExitCode() const {
  switch (code_) {
    case StatusCode::kOk:
      return 0;
    case StatusCode::kFailed:
      return 1;
    case StatusCode::kInvalidInput:
    case StatusCode::kNotFound:
    case StatusCode::kIoError:
      return 2;
    case StatusCode::kInternal:
      return 3;
  }
  return 3;
}

namespace internal {
void CheckFailed(const char* file, int line, const char* condition, const char* message) {
  std::fprintf(stderr, "teachsim: internal error at %s:%d: check failed: %s %s\n", file, line,
               condition, message);
  std::fflush(stderr);
  std::abort();
}
}  // namespace internal

}  // namespace teachsim
