#include "teachsim/scene/scene.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace teachsim::scene {
namespace {

const std::string kPuzzle = std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json";

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("teachsim_scene_test_" + name)).string();
}

TEST(Scene, DefaultSceneLoadsWithItsParts) {
  auto scene = LoadScene(kPuzzle);
  ASSERT_TRUE(scene.ok()) << scene.status().message();
  EXPECT_GE(scene->objects.size(), 7u);
  const int frame = scene->FindObject("frame");
  ASSERT_GE(frame, 0);
  EXPECT_TRUE(scene->objects[frame].fixed);
  EXPECT_GE(scene->objects[frame].shape.parts().size(), 5u);  // four walls and the lip
  int movable = 0;
  for (const auto& o : scene->objects) movable += o.fixed ? 0 : 1;
  EXPECT_GE(movable, 5);
  ASSERT_EQ(scene->cameras.size(), 1u);
  EXPECT_EQ(scene->cameras[0].width, 640);
  ASSERT_TRUE(scene->robot.has_value());
}

TEST(Scene, RoundTripIsIdentical) {
  auto scene = LoadScene(kPuzzle);
  ASSERT_TRUE(scene.ok());
  const std::string path = TempPath("roundtrip.json");
  ASSERT_TRUE(SaveScene(*scene, path).ok());
  auto again = LoadScene(path);
  ASSERT_TRUE(again.ok()) << again.status().message();
  EXPECT_EQ(SceneToJson(*scene).dump(), SceneToJson(*again).dump());
  // And the saved file itself is stable: save(load(save(x))) == save(x).
  const std::string path2 = TempPath("roundtrip2.json");
  ASSERT_TRUE(SaveScene(*again, path2).ok());
  std::ifstream f1(path), f2(path2);
  std::string s1((std::istreambuf_iterator<char>(f1)), {}), s2((std::istreambuf_iterator<char>(f2)), {});
  EXPECT_EQ(s1, s2);
  std::filesystem::remove(path);
  std::filesystem::remove(path2);
}

// One malformed field at a time: each error names the file, the JSON path and the problem.
struct Case {
  const char* name;
  const char* json;
  const char* message;
};

class MalformedScene : public ::testing::TestWithParam<Case> {};

TEST_P(MalformedScene, ErrorNamesFilePathAndProblem) {
  const Case& c = GetParam();
  auto document = json::ParseText(c.json, "x.json");
  Status status = document.ok() ? ParseScene(*document, "x.json").status() : document.status();
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(status.message(), c.message);
  EXPECT_EQ(status.ExitCode(), 2);
}

#define OBJ(fields) "{\"objects\": [" fields "]}"
#define BLOCK(extra) \
  "{\"name\": \"b\", \"fixed\": false, \"shape\": {\"box\": [0.1, 0.1, 0.1]}, " \
  "\"pose\": {\"position\": [0, 0, 0], \"quaternion_wxyz\": [1, 0, 0, 0]}" extra "}"

INSTANTIATE_TEST_SUITE_P(
    EachField, MalformedScene,
    ::testing::Values(
        Case{"syntax", "{\"objects\": [",
             "x.json: line 1, column 13: syntax error while parsing value - unexpected end of input; "
             "expected '[', '{', or a literal"},
        Case{"no_objects", "{}", "x.json: objects: missing"},
        Case{"objects_not_array", "{\"objects\": 3}", "x.json: objects: must be an array, got number"},
        Case{"negative_box",
             OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"box\": [0.1, -0.02, 0.1]}, \"pose\": "
                 "{\"position\": [0, 0, 0], \"quaternion_wxyz\": [1, 0, 0, 0]}}"),
             "x.json: objects[0].shape.box[1]: must be > 0, got -0.02"},
        Case{"box_size",
             OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"box\": [0.1, 0.1]}, \"pose\": "
                 "{\"position\": [0, 0, 0], \"quaternion_wxyz\": [1, 0, 0, 0]}}"),
             "x.json: objects[0].shape.box: must have 3 elements, got 2"},
        Case{"no_name", OBJ("{\"fixed\": true}"), "x.json: objects[0].name: missing"},
        Case{"empty_name", OBJ("{\"name\": \"\", \"fixed\": true}"),
             "x.json: objects[0].name: must not be empty"},
        Case{"fixed_string", OBJ("{\"name\": \"b\", \"fixed\": \"yes\"}"),
             "x.json: objects[0].fixed: must be true or false, got string"},
        Case{"unknown_field", OBJ(BLOCK(", \"colour\": 3")),
             "x.json: objects[0]: unknown field 'colour' (expected one of: name, fixed, model, shape, pose)"},
        Case{"two_shapes",
             OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"box\": [1, 1, 1], \"parts\": []}}"),
             "x.json: objects[0].shape: must have exactly one of \"box\", \"convex\", \"parts\""},
        Case{"flat_convex",
             OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"convex\": {\"vertices\": "
                 "[[0,0,0],[1,0,0],[0,1,0],[1,1,0]]}}}"),
             "x.json: objects[0].shape.convex.vertices: the vertices are coplanar: they span no volume"},
        Case{"empty_parts", OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"parts\": []}}"),
             "x.json: objects[0].shape.parts: must not be empty"},
        Case{"bad_quaternion",
             OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"box\": [1, 1, 1]}, \"pose\": "
                 "{\"position\": [0, 0, 0], \"quaternion_wxyz\": [0, 0, 0, 0]}}"),
             "x.json: objects[0].pose.quaternion_wxyz: must be a unit quaternion [w, x, y, z], got norm 0"},
        Case{"position_text",
             OBJ("{\"name\": \"b\", \"fixed\": true, \"shape\": {\"box\": [1, 1, 1]}, \"pose\": "
                 "{\"position\": [0, \"a\", 0], \"quaternion_wxyz\": [1, 0, 0, 0]}}"),
             "x.json: objects[0].pose.position[1]: must be a number, got string"},
        Case{"duplicate_name", OBJ(BLOCK("") "," BLOCK("")),
             "x.json: objects[1].name: duplicate object name 'b'"},
        Case{"camera_fx",
             "{\"objects\": [], \"cameras\": [{\"name\": \"c\", \"width\": 640, \"height\": 480, \"fx\": -1, "
             "\"fy\": 1, "
             "\"cx\": 1, \"cy\": 1, \"k1\": 0, \"k2\": 0, \"p1\": 0, \"p2\": 0, \"k3\": 0, \"position\": "
             "[0,0,1], "
             "\"quaternion_wxyz\": [1,0,0,0]}]}",
             "x.json: cameras[0].fx: must be > 0, got -1"},
        Case{"camera_gamma",
             "{\"objects\": [], \"cameras\": [{\"name\": \"c\", \"width\": 640, \"height\": 480, \"fx\": 1, "
             "\"fy\": 1, "
             "\"cx\": 1, \"cy\": 1, \"k1\": 0, \"k2\": 0, \"p1\": 0, \"p2\": 0, \"k3\": 0, \"gamma\": 9, "
             "\"position\": [0,0,1], \"quaternion_wxyz\": [1,0,0,0]}]}",
             "x.json: cameras[0].gamma: must be in [0.5, 4], got 9"},
        Case{"camera_width",
             "{\"objects\": [], \"cameras\": [{\"name\": \"c\", \"width\": 6.5, \"height\": 480}]}",
             "x.json: cameras[0].width: must be an integer, got 6.5"},
        Case{"robot_base", "{\"objects\": [], \"robot\": {\"model\": \"crs_a465\"}}",
             "x.json: robot.base: missing"}),
    [](const ::testing::TestParamInfo<Case>& param_info) { return std::string(param_info.param.name); });

TEST(Scene, MissingFileAndFolderAreClearErrors) {
  auto missing = LoadScene("/nonexistent/scene.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().message(), "/nonexistent/scene.json: cannot open: No such file or directory");
  auto folder = LoadScene("/tmp");
  ASSERT_FALSE(folder.ok());
  EXPECT_EQ(folder.status().message(), "/tmp: is a folder, not a JSON file");
}

TEST(Json, AtomicWriteReplacesWholeFileAndLeavesNoTemporary) {
  const std::string dir = TempPath("atomic");
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/f.json";
  ASSERT_TRUE(json::WriteFileAtomic(path, "first version, longer than the second\n").ok());
  ASSERT_TRUE(json::WriteFileAtomic(path, "second\n").ok());
  std::ifstream in(path);
  std::string text((std::istreambuf_iterator<char>(in)), {});
  EXPECT_EQ(text, "second\n");
  int files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1);
  EXPECT_FALSE(json::WriteFileAtomic(dir + "/no/such/folder/f.json", "x").ok());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace teachsim::scene

namespace teachsim::scene {
namespace {
// nlohmann throws out_of_range, not parse_error, for a number past double's range.
TEST(Json, HugeNumberIsBadInputNotACrash) {
  auto parsed = json::ParseText("{\"objects\": [1e999]}", "x.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidInput);
  EXPECT_EQ(parsed.status().message().rfind("x.json: ", 0), 0u);
}
}  // namespace
}  // namespace teachsim::scene
