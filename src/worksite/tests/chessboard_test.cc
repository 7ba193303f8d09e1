#include "teachsim/worksite/chessboard.h"

#include <gtest/gtest.h>

namespace teachsim::worksite {
namespace {

vision::Camera MainCamera() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok()) << scene.status().message();
  auto camera =
      vision::Camera::FromSpec(scene->cameras.at(static_cast<std::size_t>(scene->FindCamera("main"))));
  EXPECT_TRUE(camera.ok());
  return *camera;
}

// Calibration from 15 rendered chessboard views (shading, blur and sensor noise included) recovers
// the camera: fx, fy within 0.5 %, cx, cy within 2 px, k1 within 0.02.
TEST(ChessboardTest, CalibrationFromFifteenRenderedViewsRecoversTheCamera) {
  const vision::Camera truth = MainCamera();
  const vision::ChessboardSpec board{9, 6, 0.02};
  auto renderer = Renderer::Create(truth, RenderOptions{});
  ASSERT_TRUE(renderer.ok()) << renderer.status().message();
  const std::vector<geometry::Pose3> poses = SampleBoardPoses(truth, board, 15, 42);
  ASSERT_EQ(poses.size(), 15u);
  std::vector<vision::CalibrationView> views;
  double worst_corner_px = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const RenderResult image = RenderChessboard(*renderer, board, poses[i], 100 + i);
    auto corners = vision::FindChessboardCorners(image.image, board);
    ASSERT_TRUE(corners.has_value()) << "view " << i;
    // Detected corners sit on the projected ones (OpenCV may number the board from either end).
    const std::vector<Eigen::Vector3d> in_board = board.CornersInBoard();
    double forward = 0, backward = 0;
    for (std::size_t k = 0; k < in_board.size(); ++k) {
      const Eigen::Vector2d p = *truth.ProjectFromCamera(poses[i] * in_board[k]);
      forward = std::max(forward, ((*corners)[k] - p).norm());
      backward = std::max(backward, ((*corners)[in_board.size() - 1 - k] - p).norm());
    }
    worst_corner_px = std::max(worst_corner_px, std::min(forward, backward));
    views.push_back({"view " + std::to_string(i), std::move(*corners)});
  }
  EXPECT_LT(worst_corner_px, 0.5);
  auto result =
      vision::CalibrateIntrinsics(views, board, truth.width(), truth.height(), vision::IntrinsicsOptions{});
  ASSERT_TRUE(result.ok()) << result.status().message();
  std::printf("corners within %.3f px; RMS %.3f px; fx %.2f fy %.2f cx %.2f cy %.2f k1 %.4f k2 %.4f\n",
              worst_corner_px, result->rms_px, result->intrinsics.fx, result->intrinsics.fy,
              result->intrinsics.cx, result->intrinsics.cy, result->distortion.k1, result->distortion.k2);
  EXPECT_NEAR(result->intrinsics.fx / truth.intrinsics().fx, 1.0, 0.005);
  EXPECT_NEAR(result->intrinsics.fy / truth.intrinsics().fy, 1.0, 0.005);
  EXPECT_NEAR(result->intrinsics.cx, truth.intrinsics().cx, 2.0);
  EXPECT_NEAR(result->intrinsics.cy, truth.intrinsics().cy, 2.0);
  EXPECT_NEAR(result->distortion.k1, truth.distortion().k1, 0.02);
  EXPECT_LT(result->rms_px, 0.3);
}

TEST(ChessboardTest, AnEmptyImageHasNoBoard) {
  const vision::Camera truth = MainCamera();
  auto renderer = Renderer::Create(truth, RenderOptions{});
  ASSERT_TRUE(renderer.ok());
  const RenderResult empty = renderer->Render({}, 1);
  EXPECT_FALSE(vision::FindChessboardCorners(empty.image, vision::ChessboardSpec{9, 6, 0.02}).has_value());
}

}  // namespace
}  // namespace teachsim::worksite
