#include "teachsim/net/auth.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace teachsim::net {
namespace {

namespace fs = std::filesystem;

class TokenFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("teachsim_auth_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& contents) {
    std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << contents;
    return path;
  }
  fs::path dir_;
};

TEST_F(TokenFile, ReadsTheFirstLineTrimmed) {
  Result<Token> token = ReadTokenFile(Write("t", "  0123456789abcdef0123\n# comment\n"));
  ASSERT_TRUE(token.ok()) << token.status().message();
  EXPECT_EQ(token->secret(), "0123456789abcdef0123");
}

TEST_F(TokenFile, MissingEmptyShortOrSpacedFilesGiveClearErrorsWithoutTheContent) {
  Result<Token> missing = ReadTokenFile((dir_ / "nope").string());
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("nope: cannot read token file"), std::string::npos);

  Result<Token> empty = ReadTokenFile(Write("empty", "\n  \n"));
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.status().message().find("token file is empty"), std::string::npos);

  Result<Token> short_token = ReadTokenFile(Write("short", "secret123\n"));
  ASSERT_FALSE(short_token.ok());
  EXPECT_NE(short_token.status().message().find("shorter than 16 bytes"), std::string::npos);
  EXPECT_EQ(short_token.status().message().find("secret123"), std::string::npos);

  Result<Token> spaced = ReadTokenFile(Write("spaced", "0123456789 abcdef0123\n"));
  ASSERT_FALSE(spaced.ok());
  EXPECT_EQ(spaced.status().message().find("abcdef"), std::string::npos);

  Result<Token> folder = ReadTokenFile(dir_.string());
  EXPECT_FALSE(folder.ok());
}

TEST(Auth, ConstantTimeEqualsIsEquality) {
  EXPECT_TRUE(ConstantTimeEquals("0123456789abcdef", "0123456789abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("0123456789abcdeF", "0123456789abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("1123456789abcdef", "0123456789abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("0123456789abcde", "0123456789abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("0123456789abcdef0", "0123456789abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("", "0123456789abcdef"));
  // A prefix padded with NULs must not pass for the secret.
  EXPECT_FALSE(ConstantTimeEquals(std::string_view("ab\0", 3), std::string_view("ab", 2)));
  EXPECT_FALSE(ConstantTimeEquals(std::string_view("ab", 2), std::string_view("ab\0", 3)));
}

TEST(Auth, BearerHeaderParsing) {
  EXPECT_EQ(BearerToken("Bearer abc"), "abc");
  EXPECT_EQ(BearerToken("bearer   abc  "), "abc");
  EXPECT_EQ(BearerToken("Basic abc"), "");
  EXPECT_EQ(BearerToken("Bearer"), "");
  EXPECT_EQ(BearerToken(""), "");
  Token token("0123456789abcdef");
  EXPECT_TRUE(Authorized("Bearer 0123456789abcdef", token));
  EXPECT_FALSE(Authorized("Bearer 0123456789abcdeg", token));
  EXPECT_FALSE(Authorized("0123456789abcdef", token));
  EXPECT_FALSE(Authorized("Bearer ", Token()));  // no token configured authorises nobody
}

}  // namespace
}  // namespace teachsim::net
