#include "teachsim/base/bench_registry.h"

#include <algorithm>

#include "teachsim/base/status.h"

namespace teachsim {

std::vector<BenchSpec>& BenchRegistry() {
  static std::vector<BenchSpec> registry;
  return registry;
}

BenchRegistration::BenchRegistration(std::string name, std::string help,
                                     std::function<int(const BenchArgs&)> run) {
  auto& registry = BenchRegistry();
  registry.push_back({std::move(name), std::move(help), std::move(run)});
  std::sort(registry.begin(), registry.end(),
            [](const BenchSpec& a, const BenchSpec& b) { return a.name < b.name; });
}

}  // namespace teachsim
