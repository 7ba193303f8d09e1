#include "teachsim/net/static_files.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace teachsim::net {
namespace {

namespace fs = std::filesystem;

class StaticFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    base_ = fs::temp_directory_path() / ("teachsim_static_test_" + std::to_string(::getpid()));
    root_ = base_ / "web";
    fs::create_directories(root_ / "js");
    std::ofstream(root_ / "index.html") << "<html>ui</html>";
    std::ofstream(root_ / "js" / "app.js") << "console.log(1)";
    std::ofstream(root_ / "js" / "index.html") << "js index";
    std::ofstream(root_ / ".env") << "hidden";
    std::ofstream(base_ / "secret.txt") << "secret";
    fs::create_symlink(base_ / "secret.txt", root_ / "link.txt");
  }
  void TearDown() override { fs::remove_all(base_); }
  fs::path base_, root_;
};

TEST_F(StaticFiles, ResolvesFilesAndFolderIndexes) {
  EXPECT_EQ(ResolveStaticPath(root_.string(), "/").value(), fs::canonical(root_ / "index.html").string());
  EXPECT_EQ(ResolveStaticPath(root_.string(), "/js/app.js?v=3#x").value(), fs::canonical(root_ / "js/app.js").string());
  EXPECT_EQ(ResolveStaticPath(root_.string(), "/js/").value(), fs::canonical(root_ / "js/index.html").string());
  EXPECT_EQ(ResolveStaticPath(root_.string(), "/js/%61pp.js").value(), fs::canonical(root_ / "js/app.js").string());
}

TEST_F(StaticFiles, TraversalEncodedOrNotNeverLeavesTheRoot) {
  for (const char* target : {"/../secret.txt", "/js/../../secret.txt", "/%2e%2e/secret.txt", "/%2E%2E/secret.txt",
                             "/..%2fsecret.txt", "/js/%2e%2e%2f%2e%2e%2fsecret.txt", "/..\\secret.txt",
                             "/%5c..%5csecret.txt", "/index.html%00.js", "/%zz", "/%2"}) {
    Result<std::string> r = ResolveStaticPath(root_.string(), target);
    EXPECT_FALSE(r.ok()) << target << " -> " << (r.ok() ? r.value() : "");
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidInput) << target;
  }
  // A symlink pointing out of the root is not followed out.
  EXPECT_FALSE(ResolveStaticPath(root_.string(), "/link.txt").ok());
  EXPECT_EQ(ResolveStaticPath(root_.string(), "/.env").status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ResolveStaticPath(root_.string(), "/nope.html").status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(ResolveStaticPath(root_.string(), "relative").ok());
}

TEST(MimeTypes, CommonWebTypes) {
  EXPECT_EQ(MimeType("/a/index.html"), "text/html; charset=utf-8");
  EXPECT_EQ(MimeType("three.module.js"), "text/javascript; charset=utf-8");
  EXPECT_EQ(MimeType("x.MJS"), "text/javascript; charset=utf-8");
  EXPECT_EQ(MimeType("style.css"), "text/css; charset=utf-8");
  EXPECT_EQ(MimeType("scene.json"), "application/json");
  EXPECT_EQ(MimeType("shot.png"), "image/png");
  EXPECT_EQ(MimeType("m.wasm"), "application/wasm");
  EXPECT_EQ(MimeType("folder.d/noext"), "application/octet-stream");
}

}  // namespace
}  // namespace teachsim::net
