#include "teachsim/vision/calibration.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

namespace teachsim::vision {
namespace {

Camera PuzzleCamera() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok()) << scene.status().message();
  auto camera = Camera::FromSpec(scene->cameras.at(0));
  EXPECT_TRUE(camera.ok());
  return *camera;
}

// Work-site features of known position in the default scene: the table's far corner and five
// corners of the frame's walls (their bounding box: the walls stand on the table).
std::vector<Eigen::Vector3d> KnownPoints() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok());
  const scene::SceneObject& table = scene->objects.at(static_cast<std::size_t>(scene->FindObject("table")));
  const scene::SceneObject& frame = scene->objects.at(static_cast<std::size_t>(scene->FindObject("frame")));
  geometry::Aabb walls;
  for (const geometry::ShapePart& part : frame.shape.parts()) {
    const geometry::Aabb b = part.convex->WorldBounds(frame.world_T_object * part.shape_T_part);
    if (std::abs(b.min.z()) < 1e-6) walls.Extend(b);
  }
  const geometry::Aabb t = table.shape.WorldBounds(table.world_T_object);
  const Eigen::Vector3d lo = walls.min, hi = walls.max;
  return {{t.min.x(), t.min.y(), t.max.z()}, {lo.x(), lo.y(), hi.z()}, {hi.x(), lo.y(), hi.z()},
          {hi.x(), hi.y(), hi.z()},          {lo.x(), hi.y(), hi.z()}, {hi.x(), hi.y(), lo.z()}};
}

TEST(ChessboardSpecTest, ParsesAndValidates) {
  auto board = ParseBoardSize("9x6", 0.025);
  ASSERT_TRUE(board.ok());
  EXPECT_EQ(board->cols, 9);
  EXPECT_EQ(board->rows, 6);
  EXPECT_EQ(board->CornersInBoard().size(), 54u);
  EXPECT_DOUBLE_EQ(board->CornersInBoard()[10].x(), 0.025);  // row 1, column 1
  EXPECT_DOUBLE_EQ(board->CornersInBoard()[10].y(), 0.025);
  for (const char* bad : {"9", "x6", "9x", "9*6", "ax6", "1x6", "7x7"}) {
    EXPECT_FALSE(ParseBoardSize(bad, 0.025).ok()) << bad;
  }
  EXPECT_FALSE(ParseBoardSize("9x6", -0.01).ok());
}

// Zhang's method from projected corners (no image): the numerical part of calibration alone.
TEST(CalibrationTest, RecoversIntrinsicsFromNoisyCorners) {
  const Camera truth = PuzzleCamera();
  const ChessboardSpec board{9, 6, 0.03};
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, 0.1);
  std::uniform_real_distribution<double> tilt(-0.5, 0.5), shift(-0.12, 0.12), depth(0.45, 0.7);
  std::vector<CalibrationView> views;
  for (int v = 0; v < 12; ++v) {
    const Eigen::Vector3d board_centre(0.5 * 8 * 0.03, 0.5 * 5 * 0.03, 0);
    const Eigen::Quaterniond q = Eigen::AngleAxisd(tilt(rng), Eigen::Vector3d::UnitX()) *
                                 Eigen::AngleAxisd(tilt(rng), Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(tilt(rng) * 0.5, Eigen::Vector3d::UnitZ());
    const geometry::Pose3 camera_T_board(
        q, Eigen::Vector3d(shift(rng), shift(rng) * 0.7, depth(rng)) - q * board_centre);
    CalibrationView view{"view " + std::to_string(v), {}};
    for (const Eigen::Vector3d& p : board.CornersInBoard()) {
      auto pixel = truth.ProjectFromCamera(camera_T_board * p);
      ASSERT_TRUE(pixel.has_value());
      view.corners.push_back(*pixel + Eigen::Vector2d(noise(rng), noise(rng)));
    }
    views.push_back(std::move(view));
  }
  auto result = CalibrateIntrinsics(views, board, 640, 480, IntrinsicsOptions{});
  ASSERT_TRUE(result.ok()) << result.status().message();
  EXPECT_NEAR(result->intrinsics.fx / truth.intrinsics().fx, 1.0, 0.005);
  EXPECT_NEAR(result->intrinsics.fy / truth.intrinsics().fy, 1.0, 0.005);
  EXPECT_NEAR(result->intrinsics.cx, truth.intrinsics().cx, 2.0);
  EXPECT_NEAR(result->intrinsics.cy, truth.intrinsics().cy, 2.0);
  EXPECT_NEAR(result->distortion.k1, truth.distortion().k1, 0.02);
  EXPECT_NEAR(result->rms_px, 0.1 * std::sqrt(2.0), 0.05);
  EXPECT_EQ(result->view_rms_px.size(), views.size());

  // Too few views is an error that says so.
  views.resize(3);
  auto few = CalibrateIntrinsics(views, board, 640, 480, IntrinsicsOptions{});
  ASSERT_FALSE(few.ok());
  EXPECT_NE(few.status().message().find("need at least 5"), std::string::npos) << few.status().message();
}

// The operator clicks six features of known position (a table corner and five frame corners) at
// whole pixels, i.e. with up to 0.5 px of error per coordinate; PnP recovers the camera within 2 mm.
// (With Gaussian click noise of sigma 0.5 px the RMS error is about 2.5 mm for this geometry: the
// Cramer-Rao limit of six points 300 px apart at 0.7 m, not a solver matter.)
TEST(CalibrationTest, RecoversCameraPoseFromSixKnownPoints) {
  const Camera truth = PuzzleCamera();
  const std::vector<Eigen::Vector3d> corners = KnownPoints();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> noise(-0.5, 0.5);
  double sum_mm2 = 0;
  const int trials = 50;
  for (int trial = 0; trial < trials; ++trial) {
    std::vector<PointCorrespondence> points;
    for (std::size_t i = 0; i < corners.size(); ++i) {
      auto pixel = truth.Project(corners[i]);
      ASSERT_TRUE(pixel.has_value());
      ASSERT_TRUE(truth.InImage(*pixel));
      points.push_back(
          {"corner " + std::to_string(i), *pixel + Eigen::Vector2d(noise(rng), noise(rng)), corners[i]});
    }
    auto result = CalibrateExtrinsics(truth, points);
    ASSERT_TRUE(result.ok()) << result.status().message();
    const double error_mm =
        (result->world_T_camera.translation - truth.world_T_camera().translation).norm() * 1e3;
    sum_mm2 += error_mm * error_mm;
    EXPECT_LT(result->rms_px, 0.6);
    EXPECT_LT(geometry::RotationAngle(result->world_T_camera, truth.world_T_camera()), 0.01);
  }
  const double rms_mm = std::sqrt(sum_mm2 / trials);
  std::printf("camera position error, RMS over %d trials: %.2f mm\n", trials, rms_mm);
  EXPECT_LT(rms_mm, 2.0);

  // Noise-free clicks give the exact pose.
  std::vector<PointCorrespondence> exact;
  for (const Eigen::Vector3d& p : corners) exact.push_back({"", *truth.Project(p), p});
  auto result = CalibrateExtrinsics(truth, exact);
  ASSERT_TRUE(result.ok());
  EXPECT_LT((result->world_T_camera.translation - truth.world_T_camera().translation).norm(), 1e-6);
  EXPECT_LT(result->rms_px, 1e-6);
}

TEST(CalibrationTest, PointFilesAreValidated) {
  const std::string dir = ::testing::TempDir() + "/points_test";
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/points.json";
  {
    std::ofstream f(path);
    f << R"({"points": [{"name": "a", "pixel": [1, 2], "world": [0, 0, 0]},
                        {"name": "b", "pixel": [1, 2, 3], "world": [0, 0, 0]}]})";
  }
  auto bad = LoadPointCorrespondences(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("points[1].pixel"), std::string::npos) << bad.status().message();
  EXPECT_NE(bad.status().message().find(path), std::string::npos);

  std::vector<PointCorrespondence> four{
      {"a", {1, 2}, {0, 0, 0}}, {"b", {3, 4}, {1, 0, 0}}, {"c", {5, 6}, {0, 1, 0}}, {"d", {7, 8}, {0, 0, 1}}};
  auto round_trip = ParsePointCorrespondences(PointCorrespondencesToJson(four), "mem");
  ASSERT_TRUE(round_trip.ok()) << round_trip.status().message();
  EXPECT_EQ(round_trip->at(3).name, "d");
  EXPECT_EQ(round_trip->at(2).pixel, Eigen::Vector2d(5, 6));
  four.pop_back();
  auto three = ParsePointCorrespondences(PointCorrespondencesToJson(four), "mem");
  ASSERT_FALSE(three.ok());
  EXPECT_NE(three.status().message().find("at least 4"), std::string::npos);

  auto missing =
      CalibrateIntrinsicsFromFolder(dir + "/no_such_folder", ChessboardSpec{}, IntrinsicsOptions{});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().message().find("no_such_folder"), std::string::npos);
}

}  // namespace
}  // namespace teachsim::vision
