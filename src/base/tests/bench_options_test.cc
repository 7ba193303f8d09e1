// The benchmarks' own arguments: values in both spellings, flags, and every bad argument answered
// with an error that names it.
#include <gtest/gtest.h>

#include "teachsim/base/bench_registry.h"

namespace teachsim {
namespace {

Result<BenchOptions> Parse(const std::vector<std::string>& extra) {
  return ParseBenchOptions("demo", extra, {"--seeds", "--out"}, {"--no-peer"});
}

TEST(BenchOptionsTest, ValuesInBothSpellingsAndFlags) {
  auto parsed = Parse({"--seeds", "3", "--no-peer", "--out=a=b", "--seeds=4"});
  ASSERT_TRUE(parsed.ok()) << parsed.status().message();
  EXPECT_EQ(parsed->values.at("--seeds"), "4");  // the last one given
  EXPECT_EQ(parsed->values.at("--out"), "a=b");  // split at the first '='
  EXPECT_EQ(parsed->flags, std::set<std::string>{"--no-peer"});
  parsed = Parse({});
  ASSERT_TRUE(parsed.ok());
  EXPECT_TRUE(parsed->values.empty());
  EXPECT_TRUE(parsed->flags.empty());
}

TEST(BenchOptionsTest, BadArgumentsAreNamed) {
  struct Bad {
    std::vector<std::string> extra;
    std::string message;
  };
  for (const Bad& bad :
       {Bad{{"--seed", "3"},
            "bench demo: unknown argument '--seed' (it takes --seeds VALUE, --out VALUE, --no-peer)"},
        Bad{{"--seeds"}, "bench demo: --seeds needs a value"},
        Bad{{"--no-peer=1"}, "unknown argument '--no-peer=1'"}, Bad{{"3"}, "unknown argument '3'"}}) {
    const auto parsed = Parse(bad.extra);
    ASSERT_FALSE(parsed.ok()) << bad.message;
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidInput);
    EXPECT_NE(parsed.status().message().find(bad.message), std::string::npos) << parsed.status().message();
  }
  const auto none = ParseBenchOptions("robot", {"--x"}, {}, {});
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("(it takes no arguments of its own)"), std::string::npos);
}

TEST(BenchOptionsTest, CountsAreWholeNumbersInRange) {
  EXPECT_EQ(*ParseBenchCount("--seeds", "10", 1, 1000), 10);
  EXPECT_EQ(*ParseBenchCount("--seeds", "1000", 1, 1000), 1000);
  EXPECT_EQ(*ParseBenchCount("--seeds", "007", 1, 1000), 7);
  for (const std::string text :
       {"", "0", "1001", "-3", "+3", "3.5", "1e3", " 3", "abc", "99999999999999999999999"}) {
    const auto parsed = ParseBenchCount("--seeds", text, 1, 1000);
    ASSERT_FALSE(parsed.ok()) << text;
    EXPECT_EQ(parsed.status().message(), "--seeds: '" + text + "' is not a whole number from 1 to 1000");
  }
}

}  // namespace
}  // namespace teachsim
