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

Result<BenchOptions> ParseBenchOptions(const std::string& bench, const std::vector<std::string>& extra,
                                       const std::vector<std::string>& with_value,
                                       const std::vector<std::string>& flags) {
  auto taken = [&] {
    std::string list;
    for (const std::string& name : with_value) list += (list.empty() ? "" : ", ") + name + " VALUE";
    for (const std::string& name : flags) list += (list.empty() ? "" : ", ") + name;
    return list.empty() ? std::string("no arguments of its own") : list;
  };
  auto among = [](const std::vector<std::string>& names, const std::string& name) {
    return std::find(names.begin(), names.end(), name) != names.end();
  };
  BenchOptions out;
  for (std::size_t i = 0; i < extra.size(); ++i) {
    const std::string& arg = extra[i];
    const std::size_t equals = arg.find('=');
    const std::string name = arg.substr(0, equals);
    if (equals == std::string::npos && among(flags, name)) {
      out.flags.insert(name);
    } else if (among(with_value, name)) {
      if (equals != std::string::npos) {
        out.values[name] = arg.substr(equals + 1);
      } else if (i + 1 < extra.size()) {
        out.values[name] = extra[++i];
      } else {
        return Status::InvalidInput("bench " + bench + ": " + name + " needs a value");
      }
    } else {
      return Status::InvalidInput("bench " + bench + ": unknown argument '" + arg + "' (it takes " + taken() +
                                  ")");
    }
  }
  return out;
}

Result<long long> ParseBenchCount(const std::string& what, const std::string& text, long long min,
                                  long long max) {
  auto error = [&] {
    return Status::InvalidInput(what + ": '" + text + "' is not a whole number from " + std::to_string(min) +
                                " to " + std::to_string(max));
  };
  // Digits only (no sign, space or exponent), and few enough that the value cannot overflow.
  if (text.empty() || text.size() > 18 || text.find_first_not_of("0123456789") != std::string::npos)
    return error();
  const long long value = std::stoll(text);
  if (value < min || value > max) return error();
  return value;
}

}  // namespace teachsim
