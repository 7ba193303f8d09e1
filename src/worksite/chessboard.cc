#include "teachsim/worksite/chessboard.h"

#include <cmath>
#include <random>

namespace teachsim::worksite {

std::vector<geometry::Pose3> SampleBoardPoses(const vision::Camera& camera,
                                              const vision::ChessboardSpec& board, int count,
                                              std::uint64_t seed, double margin_px) {
  // std::mt19937_64 is fully specified by the standard; the distributions are done by hand so
  // the poses are the same with every standard library.
  std::mt19937_64 rng(seed);
  auto uniform = [&rng](double lo, double hi) {
    return lo + (hi - lo) * (static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0));
  };
  const double s = board.square_m;
  const Eigen::Vector3d centre_in_board((board.cols - 1) * s / 2, (board.rows - 1) * s / 2, 0);
  // Depth at which the board spans about 60 % of the image width.
  const double board_width = (board.cols + 1) * s;
  const double base_depth = camera.intrinsics().fx * board_width / (0.6 * camera.width());
  std::vector<geometry::Pose3> poses;
  for (int attempt = 0; attempt < 10000 && static_cast<int>(poses.size()) < count; ++attempt) {
    const Eigen::Quaterniond q = Eigen::AngleAxisd(uniform(-0.6, 0.6), Eigen::Vector3d::UnitX()) *
                                 Eigen::AngleAxisd(uniform(-0.6, 0.6), Eigen::Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(uniform(-0.3, 0.3), Eigen::Vector3d::UnitZ());
    const double depth = base_depth * uniform(0.8, 1.3);
    const Eigen::Vector3d centre_in_camera(
        uniform(-0.25, 0.25) * depth * camera.width() / camera.intrinsics().fx,
        uniform(-0.25, 0.25) * depth * camera.height() / camera.intrinsics().fy, depth);
    const geometry::Pose3 camera_T_board(q.normalized(), centre_in_camera - q * centre_in_board);
    // The printed face must face the camera: board z points away from it.
    if ((camera_T_board.rotation * Eigen::Vector3d::UnitZ()).dot(centre_in_camera.normalized()) < 0.3)
      continue;
    bool inside = true;
    for (double x = -s; x <= board.cols * s + 1e-9 && inside; x += s) {
      for (double y = -s; y <= board.rows * s + 1e-9 && inside; y += s) {
        auto pixel = camera.ProjectFromCamera(camera_T_board * Eigen::Vector3d(x, y, 0));
        inside = pixel && pixel->x() >= margin_px && pixel->y() >= margin_px &&
                 pixel->x() <= camera.width() - 1 - margin_px &&
                 pixel->y() <= camera.height() - 1 - margin_px;
      }
    }
    if (inside) poses.push_back(camera_T_board);
  }
  return poses;
}

RenderResult RenderChessboard(const Renderer& renderer, const vision::ChessboardSpec& board,
                              const geometry::Pose3& camera_T_board, std::uint64_t seed) {
  const geometry::Pose3 world_T_board = renderer.camera().world_T_camera() * camera_T_board;
  return renderer.Render({ChessboardObject(board, world_T_board)}, seed);
}

}  // namespace teachsim::worksite
