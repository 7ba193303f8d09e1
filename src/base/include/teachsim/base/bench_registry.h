// Named benchmarks for `teachsim bench NAME [--json]`. Each module's bench/ folder registers its
// benchmarks here; the app lists and runs them. Registration happens at static-initialisation
// time in object files linked straight into the executable (never dropped by the linker).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "teachsim/base/status.h"

namespace teachsim {

struct BenchArgs {
  bool json = false;          // print the machine-readable JSON document instead of a table
  bool quick = false;         // fewer samples: used by the smoke test that keeps benches alive
  std::vector<std::string> extra;  // further arguments, passed to Google Benchmark where used
};

struct BenchSpec {
  std::string name;
  std::string help;
  std::function<int(const BenchArgs&)> run;  // returns the process exit status
};

// The registry: sorted by name on access.
std::vector<BenchSpec>& BenchRegistry();

struct BenchRegistration {
  BenchRegistration(std::string name, std::string help, std::function<int(const BenchArgs&)> run);
};

}  // namespace teachsim

#define TEACHSIM_BENCH(name, help, function) \
  static const ::teachsim::BenchRegistration TEACHSIM_CONCAT(teachsim_bench_, __LINE__)(name, help, function)
