// Every file of the fuzzer's seed corpus and regression cases through the fuzz target, in the
// normal build: no crash, and the target's invariants hold (it aborts otherwise).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include "message_fuzz_target.h"

namespace teachsim::net {
namespace {

namespace fs = std::filesystem;

std::vector<fs::path> FilesIn(const fs::path& folder) {
  std::vector<fs::path> files;
  if (!fs::is_directory(folder)) return files;
  for (const auto& entry : fs::directory_iterator(folder)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(Corpus, EverySeedAndRegressionInputIsHandled) {
  const fs::path root = fs::path(TEACHSIM_SOURCE_DIR) / "fuzz";
  std::vector<fs::path> files = FilesIn(root / "corpus" / "messages");
  std::size_t seeds = files.size();
  for (const fs::path& f : FilesIn(root / "regressions" / "messages")) files.push_back(f);
  ASSERT_GE(seeds, 20u) << "the seed corpus holds one file per message type at least";
  ASSERT_GT(files.size(), seeds) << "regression cases are kept in fuzz/regressions/messages";
  std::size_t valid = 0;
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    std::string data = ReadAll(f);
    fuzz::RunMessageInput(reinterpret_cast<const std::uint8_t*>(data.data()), data.size());
    MessageLimits limits;
    valid += ParseTextMessage(data, limits).ok() || ParseBinaryMessage(std::span(reinterpret_cast<const std::uint8_t*>(data.data()), data.size()), limits).ok();
  }
  // The seeds are mostly valid messages (the fuzzer mutates from there).
  EXPECT_GE(valid, seeds / 2);
}

}  // namespace
}  // namespace teachsim::net
