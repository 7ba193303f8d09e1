// Chessboard views for calibration: board poses in front of a camera and their images.
#pragma once

#include <cstdint>
#include <vector>

#include "teachsim/geometry/pose.h"
#include "teachsim/vision/calibration.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {

// `count` poses camera_T_board, seeded, tilted up to ~35 degrees and spread over the image, each
// showing every inner corner at least `margin_px` inside the image (the outer squares too).
std::vector<geometry::Pose3> SampleBoardPoses(const vision::Camera& camera,
                                              const vision::ChessboardSpec& board, int count,
                                              std::uint64_t seed, double margin_px = 25.0);

// The board alone in front of the renderer's camera (dark background), at camera_T_board.
RenderResult RenderChessboard(const Renderer& renderer, const vision::ChessboardSpec& board,
                              const geometry::Pose3& camera_T_board, std::uint64_t seed);

}  // namespace teachsim::worksite
