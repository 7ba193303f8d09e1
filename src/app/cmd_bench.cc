// teachsim bench NAME [--json] [--quick]: the benchmarks each module registers (docs/benchmarks.md).
#include <memory>

#include "commands.h"
#include "teachsim/base/bench_registry.h"

namespace teachsim::app {

void AddBenchCommand(CLI::App& app, Runner* run) {
  struct Options {
    std::string name;
    BenchArgs args;
    bool list = false;
  };
  auto options = std::make_shared<Options>();
  std::string names;
  for (const BenchSpec& spec : BenchRegistry()) names += (names.empty() ? "" : ", ") + spec.name;
  CLI::App* sub = app.add_subcommand("bench", "run a benchmark against its peer (" + names + ")");
  sub->add_option("name", options->name, "benchmark to run")->required(false);
  sub->add_flag("--json", options->args.json, "print the result as JSON");
  sub->add_flag("--quick", options->args.quick, "few samples (a smoke test, not a measurement)");
  sub->add_flag("--list", options->list, "list the benchmarks");
  sub->allow_extras();
  sub->callback([options, run, sub] {
    options->args.extra = sub->remaining();
    *run = [options]() -> int {
      if (options->list || options->name.empty()) {
        for (const BenchSpec& spec : BenchRegistry()) std::printf("%-12s %s\n", spec.name.c_str(), spec.help.c_str());
        return options->list ? 0 : 2;
      }
      for (const BenchSpec& spec : BenchRegistry()) {
        if (spec.name == options->name) return spec.run(options->args);
      }
      return ReportError(Status::InvalidInput("bench: unknown benchmark '" + options->name +
                                              "' (teachsim bench --list names them)"));
    };
  });
}

}  // namespace teachsim::app
