// Runs the `teachsim` program (TEACHSIM_BINARY) from a test and captures its exit status and output.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

namespace teachsim::worksite::testing {

struct CommandRun {
  int status = -1;
  std::string out, err;
};

inline std::string Slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// `teachsim ARGS`; ctest runs every test as its own process, in parallel: the capture files are
// per process.
inline CommandRun Teachsim(const std::string& args) {
  const std::string stem = ::testing::TempDir() + "/teachsim_cli_" + std::to_string(::getpid());
  const std::string command =
      std::string(TEACHSIM_BINARY) + " " + args + " > " + stem + "_out.txt 2> " + stem + "_err.txt";
  const int raw = std::system(command.c_str());
  CommandRun run;
  run.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  run.out = Slurp(stem + "_out.txt");
  run.err = Slurp(stem + "_err.txt");
  return run;
}

}  // namespace teachsim::worksite::testing
