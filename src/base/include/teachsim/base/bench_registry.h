// Named benchmarks for `teachsim bench NAME [--json]`. Each module's bench/ folder registers its
// benchmarks here; the app lists and runs them. Registration happens at static-initialisation
// time in object files linked straight into the executable (never dropped by the linker).
#pragma once

#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "teachsim/base/status.h"

namespace teachsim {

struct BenchArgs {
  bool json = false;          // print the machine-readable JSON document instead of a table
  bool quick = false;         // fewer samples: used by the smoke test that keeps benches alive
  std::vector<std::string> extra;  // further arguments, passed to Google Benchmark where used
};

// A benchmark's own arguments (BenchArgs::extra), for the benchmarks that pass none to Google
// Benchmark: each name in `with_value` takes one ("--seeds 10" or "--seeds=10"), each in `flags`
// none. Anything else, or a missing value, is an InvalidInput error that names the argument and
// lists the ones `bench` takes.
struct BenchOptions {
  std::map<std::string, std::string> values;  // by name; the last one given
  std::set<std::string> flags;                // those given
};
[[nodiscard]] Result<BenchOptions> ParseBenchOptions(const std::string& bench,
                                                     const std::vector<std::string>& extra,
                                                     const std::vector<std::string>& with_value,
                                                     const std::vector<std::string>& flags);
// `text` as a whole number in [min, max], written in decimal digits only; otherwise an
// InvalidInput error "WHAT: 'TEXT' is not a whole number from MIN to MAX".
[[nodiscard]] Result<long long> ParseBenchCount(const std::string& what, const std::string& text,
                                                long long min, long long max);

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
