#include "teachsim/vision/calibration.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

namespace teachsim::vision {

namespace {

std::vector<cv::Point3f> BoardPoints(const ChessboardSpec& board) {
  std::vector<cv::Point3f> points;
  for (const Eigen::Vector3d& p : board.CornersInBoard()) {
    points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
  }
  return points;
}

geometry::Pose3 PoseFromRvecTvec(const cv::Mat& rvec, const cv::Mat& tvec) {
  cv::Mat r;
  cv::Rodrigues(rvec, r);
  Eigen::Matrix3d rotation;
  cv::cv2eigen(r, rotation);
  Eigen::Vector3d t(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  return geometry::Pose3(Eigen::Quaterniond(rotation).normalized(), t);
}

cv::Mat CameraMatrix(const Intrinsics& k) {
  return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
}

cv::Mat DistCoeffs(const Distortion& d) { return (cv::Mat_<double>(1, 5) << d.k1, d.k2, d.p1, d.p2, d.k3); }

bool IsImageFile(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  static const std::set<std::string> kExtensions{".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm"};
  return kExtensions.count(ext) > 0;
}

}  // namespace

Status ChessboardSpec::Validate() const {
  if (cols < 2 || rows < 2) {
    return Status::InvalidInput("chessboard: needs at least 2x2 inner corners, got " + std::to_string(cols) +
                                "x" + std::to_string(rows));
  }
  if (cols == rows) {
    // A square pattern is ambiguous under a 90-degree turn; OpenCV's ordering would flip between views.
    return Status::InvalidInput(
        "chessboard: " + std::to_string(cols) + "x" + std::to_string(rows) +
        " is square; use different corner counts (e.g. 9x6) so the orientation is unique");
  }
  if (!(square_m > 0) || !std::isfinite(square_m)) {
    return Status::InvalidInput("chessboard: square size must be > 0 m, got " + json::FormatNumber(square_m));
  }
  return Status::Ok();
}

std::vector<Eigen::Vector3d> ChessboardSpec::CornersInBoard() const {
  std::vector<Eigen::Vector3d> corners;
  corners.reserve(static_cast<std::size_t>(cols * rows));
  for (int i = 0; i < rows; ++i) {
    for (int j = 0; j < cols; ++j) corners.emplace_back(j * square_m, i * square_m, 0.0);
  }
  return corners;
}

Result<ChessboardSpec> ParseBoardSize(const std::string& text, double square_m) {
  ChessboardSpec board;
  board.square_m = square_m;
  const std::size_t x = text.find_first_of("xX");
  auto bad = [&] {
    return Status::InvalidInput("--board: expected COLSxROWS inner corners (e.g. 9x6), got '" + text + "'");
  };
  if (x == std::string::npos || x == 0 || x + 1 >= text.size()) return bad();
  const std::string a = text.substr(0, x), b = text.substr(x + 1);
  auto digits = [](const std::string& s) {
    return !s.empty() && s.size() < 5 &&
           std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
  };
  if (!digits(a) || !digits(b)) return bad();
  board.cols = std::stoi(a);
  board.rows = std::stoi(b);
  TEACHSIM_RETURN_IF_ERROR(board.Validate());
  return board;
}

std::optional<std::vector<Eigen::Vector2d>> FindChessboardCorners(const cv::Mat& gray,
                                                                  const ChessboardSpec& board) {
  TEACHSIM_CHECK(gray.type() == CV_8UC1);
  std::vector<cv::Point2f> corners;
  const cv::Size pattern(board.cols, board.rows);
  const bool found = cv::findChessboardCorners(
      gray, pattern, corners,
      cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK);
  if (!found || corners.size() != static_cast<std::size_t>(board.cols * board.rows)) return std::nullopt;
  // The refinement window must stay inside one square: half the smallest corner spacing, at most 11 px.
  double spacing = 1e9;
  for (int i = 0; i < board.rows; ++i) {
    for (int j = 0; j + 1 < board.cols; ++j) {
      const cv::Point2f d = corners[static_cast<std::size_t>(i * board.cols + j + 1)] -
                            corners[static_cast<std::size_t>(i * board.cols + j)];
      spacing = std::min(spacing, std::hypot(static_cast<double>(d.x), static_cast<double>(d.y)));
    }
  }
  const int half = std::clamp(static_cast<int>(spacing * 0.4), 2, 11);
  cv::cornerSubPix(gray, corners, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 60, 1e-4));
  std::vector<Eigen::Vector2d> out;
  out.reserve(corners.size());
  for (const cv::Point2f& c : corners) out.emplace_back(c.x, c.y);
  return out;
}

Status IntrinsicsOptions::Validate() const {
  if (min_views < 3) {
    return Status::InvalidInput("IntrinsicsOptions::min_views = " + std::to_string(min_views) +
                                " must be >= 3");
  }
  return Status::Ok();
}

Result<IntrinsicsResult> CalibrateIntrinsics(const std::vector<CalibrationView>& views,
                                             const ChessboardSpec& board, int width, int height,
                                             const IntrinsicsOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  TEACHSIM_RETURN_IF_ERROR(board.Validate());
  if (static_cast<int>(views.size()) < options.min_views) {
    return Status::InvalidInput("calibration: " + std::to_string(views.size()) +
                                " usable views, need at least " + std::to_string(options.min_views));
  }
  const std::vector<cv::Point3f> board_points = BoardPoints(board);
  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> image_points;
  for (const CalibrationView& view : views) {
    if (view.corners.size() != board_points.size()) {
      return Status::InvalidInput(view.name + ": " + std::to_string(view.corners.size()) +
                                  " corners, expected " + std::to_string(board_points.size()));
    }
    object_points.push_back(board_points);
    std::vector<cv::Point2f> corners;
    for (const Eigen::Vector2d& c : view.corners) {
      corners.emplace_back(static_cast<float>(c.x()), static_cast<float>(c.y()));
    }
    image_points.push_back(std::move(corners));
  }
  int flags = 0;
  if (options.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (options.fix_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  cv::Mat k = cv::Mat::eye(3, 3, CV_64F), dist = cv::Mat::zeros(1, 5, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  double rms = 0;
  try {
    rms = cv::calibrateCamera(object_points, image_points, cv::Size(width, height), k, dist, rvecs, tvecs,
                              flags,
                              cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
  } catch (const cv::Exception& e) {
    return Status::Failed(std::string("calibration: OpenCV failed: ") + e.what());
  }
  IntrinsicsResult result;
  result.intrinsics = {k.at<double>(0, 0), k.at<double>(1, 1), k.at<double>(0, 2), k.at<double>(1, 2)};
  result.distortion = {dist.at<double>(0), dist.at<double>(1), dist.at<double>(2), dist.at<double>(3),
                       dist.at<double>(4)};
  result.width = width;
  result.height = height;
  result.rms_px = rms;
  for (std::size_t v = 0; v < views.size(); ++v) {
    std::vector<cv::Point2f> projected;
    cv::projectPoints(board_points, rvecs[v], tvecs[v], k, dist, projected);
    double sum = 0;
    for (std::size_t i = 0; i < projected.size(); ++i) {
      const cv::Point2f d = projected[i] - image_points[v][i];
      sum += static_cast<double>(d.x) * d.x + static_cast<double>(d.y) * d.y;
    }
    result.view_rms_px.push_back(std::sqrt(sum / static_cast<double>(projected.size())));
    result.camera_T_board.push_back(PoseFromRvecTvec(rvecs[v], tvecs[v]));
  }
  return result;
}

Result<FolderCalibration> CalibrateIntrinsicsFromFolder(const std::string& folder,
                                                        const ChessboardSpec& board,
                                                        const IntrinsicsOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(board.Validate());
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) {
    return Status::NotFound(folder + ": no such folder (--images must name a folder of chessboard images)");
  }
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    if (entry.is_regular_file() && IsImageFile(entry.path())) files.push_back(entry.path());
  }
  if (ec) return Status::IoError(folder + ": cannot list the folder: " + ec.message());
  std::sort(files.begin(), files.end());
  if (files.empty())
    return Status::InvalidInput(folder + ": no images (.png, .jpg, .bmp, .tif) in the folder");

  FolderCalibration out;
  std::vector<CalibrationView> views;
  int width = 0, height = 0;
  for (const std::filesystem::path& file : files) {
    const std::string path = file.string();
    cv::Mat gray = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (gray.empty()) {
      out.skipped.push_back({path, "cannot read the image (missing, unreadable or not an image)"});
      continue;
    }
    if (width == 0) {
      width = gray.cols;
      height = gray.rows;
    } else if (gray.cols != width || gray.rows != height) {
      out.skipped.push_back({path, "size " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) +
                                       " differs from the first image's " + std::to_string(width) + "x" +
                                       std::to_string(height)});
      continue;
    }
    auto corners = FindChessboardCorners(gray, board);
    if (!corners) {
      out.skipped.push_back({path, "chessboard " + std::to_string(board.cols) + "x" +
                                       std::to_string(board.rows) + " (inner corners) not found"});
      continue;
    }
    views.push_back({path, std::move(*corners)});
    out.used.push_back(path);
  }
  if (static_cast<int>(views.size()) < options.min_views) {
    std::string message = folder + ": " + std::to_string(views.size()) + " usable chessboard views of " +
                          std::to_string(files.size()) + " images, need at least " +
                          std::to_string(options.min_views);
    for (const SkippedImage& s : out.skipped) message += "\n  " + s.path + ": " + s.reason;
    return Status::InvalidInput(message);
  }
  auto result = CalibrateIntrinsics(views, board, width, height, options);
  if (!result.ok()) return result.status();
  out.result = std::move(*result);
  return out;
}

Result<std::vector<PointCorrespondence>> ParsePointCorrespondences(const json::Json& document,
                                                                   const std::string& name) {
  return json::Decode<std::vector<PointCorrespondence>>(document, name, [](const json::Reader& root) {
    root.RejectUnknownKeys({"points", "comment"});
    const json::Reader points = root.At("points");
    std::vector<PointCorrespondence> out;
    for (std::size_t i = 0; i < points.Size(); ++i) {
      const json::Reader p = points.Index(i);
      p.RejectUnknownKeys({"name", "pixel", "world"});
      PointCorrespondence c;
      c.name = p.Has("name") ? p.At("name").NonEmptyString() : "point " + std::to_string(i);
      const json::Reader pixel = p.At("pixel");
      pixel.ExpectSize(2);
      c.pixel = {pixel.Index(0).Number(), pixel.Index(1).Number()};
      c.p_in_world = p.At("world").Vector3();
      out.push_back(std::move(c));
    }
    if (out.size() < 4)
      points.Fail("needs at least 4 points (6 or more recommended), got " + std::to_string(out.size()));
    return out;
  });
}

Result<std::vector<PointCorrespondence>> LoadPointCorrespondences(const std::string& path) {
  auto document = json::ReadFile(path);
  if (!document.ok()) return document.status();
  return ParsePointCorrespondences(*document, path);
}

json::Json PointCorrespondencesToJson(const std::vector<PointCorrespondence>& points) {
  json::Json list = json::Json::array();
  for (const PointCorrespondence& p : points) {
    json::Json entry{{"pixel", {p.pixel.x(), p.pixel.y()}},
                     {"world", {p.p_in_world.x(), p.p_in_world.y(), p.p_in_world.z()}}};
    if (!p.name.empty()) entry["name"] = p.name;
    list.push_back(std::move(entry));
  }
  return {{"points", list}};
}

Status ExtrinsicsOptions::Validate() const {
  if (!(click_sigma_px > 0) || !std::isfinite(click_sigma_px)) {
    return Status::InvalidInput("extrinsics: click sigma must be > 0 px, got " +
                                json::FormatNumber(click_sigma_px));
  }
  return Status::Ok();
}

Result<Eigen::Matrix3d> PredictedPositionCovariance(const Camera& camera,
                                                    const std::vector<Eigen::Vector3d>& points_in_world,
                                                    double sigma_px) {
  if (!(sigma_px > 0) || !std::isfinite(sigma_px)) {
    return Status::InvalidInput("extrinsics: pixel sigma must be > 0 px, got " +
                                json::FormatNumber(sigma_px));
  }
  if (points_in_world.size() < 3) {
    return Status::InvalidInput("extrinsics: the pose needs at least 3 points, got " +
                                std::to_string(points_in_world.size()));
  }
  // Parameters: the camera position in the world (m) and a rotation increment in the camera frame
  // (rad). The position block of the inverse information does not depend on how rotation is
  // parameterized. Central differences: the projection is smooth, and a step of 1e-6 keeps both the
  // truncation and the rounding error far below 1e-6 of the derivative.
  const double step = 1e-6;
  const geometry::Pose3& pose = camera.world_T_camera();
  auto moved = [&](int k, double h) {
    Eigen::Vector3d dp = Eigen::Vector3d::Zero(), dw = Eigen::Vector3d::Zero();
    (k < 3 ? dp : dw)(k % 3) = h;
    const Eigen::Quaterniond q =
        pose.rotation *
        Eigen::Quaterniond(Eigen::AngleAxisd(
            dw.norm(), dw.norm() > 0 ? Eigen::Vector3d(dw.normalized()) : Eigen::Vector3d::UnitX()));
    return Camera(camera.intrinsics(), camera.distortion(),
                  geometry::Pose3(q.normalized(), pose.translation + dp), camera.width(), camera.height());
  };
  Eigen::MatrixXd jacobian(2 * static_cast<Eigen::Index>(points_in_world.size()), 6);
  for (int k = 0; k < 6; ++k) {
    const Camera plus = moved(k, step), minus = moved(k, -step);
    for (std::size_t i = 0; i < points_in_world.size(); ++i) {
      const auto a = plus.Project(points_in_world[i]), b = minus.Project(points_in_world[i]);
      if (!a || !b) {
        return Status::InvalidInput("extrinsics: point " + std::to_string(i) + " lies behind the camera");
      }
      jacobian.block<2, 1>(2 * static_cast<Eigen::Index>(i), k) = (*a - *b) / (2 * step);
    }
  }
  const Eigen::Matrix<double, 6, 6> information = jacobian.transpose() * jacobian;
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(information);
  // Relative to the largest eigenvalue: a rank-deficient set (collinear points) has an information
  // matrix whose smallest eigenvalue is rounding noise.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eigen(information);
  if (ldlt.info() != Eigen::Success || eigen.eigenvalues()(0) <= 1e-12 * eigen.eigenvalues()(5)) {
    return Status::InvalidInput("extrinsics: the points do not determine the camera's pose (collinear?)");
  }
  const Eigen::Matrix<double, 6, 6> covariance =
      sigma_px * sigma_px * ldlt.solve(Eigen::Matrix<double, 6, 6>::Identity());
  return Eigen::Matrix3d(covariance.topLeftCorner<3, 3>());
}

Result<ExtrinsicsResult> CalibrateExtrinsics(const Camera& camera,
                                             const std::vector<PointCorrespondence>& points,
                                             const ExtrinsicsOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  if (points.size() < 4) {
    return Status::InvalidInput("extrinsics: needs at least 4 points, got " + std::to_string(points.size()));
  }
  std::vector<cv::Point3d> world;
  std::vector<cv::Point2d> pixels;
  for (const PointCorrespondence& p : points) {
    if (!p.pixel.allFinite() || !p.p_in_world.allFinite()) {
      return Status::InvalidInput("extrinsics: point '" + p.name + "' is not finite");
    }
    world.emplace_back(p.p_in_world.x(), p.p_in_world.y(), p.p_in_world.z());
    pixels.emplace_back(p.pixel.x(), p.pixel.y());
  }
  const cv::Mat k = CameraMatrix(camera.intrinsics());
  const cv::Mat dist = DistCoeffs(camera.distortion());
  cv::Mat rvec, tvec;
  try {
    if (!cv::solvePnP(world, pixels, k, dist, rvec, tvec, false, cv::SOLVEPNP_SQPNP)) {
      return Status::Failed("extrinsics: PnP found no pose (are the points collinear or mislabelled?)");
    }
    cv::solvePnPRefineLM(world, pixels, k, dist, rvec, tvec,
                         cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-12));
  } catch (const cv::Exception& e) {
    return Status::Failed(std::string("extrinsics: OpenCV failed: ") + e.what());
  }
  const geometry::Pose3 camera_T_world = PoseFromRvecTvec(rvec, tvec);
  ExtrinsicsResult result;
  result.world_T_camera = camera_T_world.Inverse();
  const Camera solved(camera.intrinsics(), camera.distortion(), result.world_T_camera, camera.width(),
                      camera.height());
  double sum = 0;
  for (const PointCorrespondence& p : points) {
    auto projected = solved.Project(p.p_in_world);
    if (!projected) {
      return Status::Failed("extrinsics: point '" + p.name +
                            "' lies behind the solved camera (mislabelled points?)");
    }
    const double r = (*projected - p.pixel).norm();
    result.residuals_px.push_back(r);
    sum += r * r;
  }
  result.rms_px = std::sqrt(sum / static_cast<double>(points.size()));
  std::vector<Eigen::Vector3d> in_world;
  for (const PointCorrespondence& p : points) in_world.push_back(p.p_in_world);
  auto covariance = PredictedPositionCovariance(solved, in_world, options.click_sigma_px);
  if (!covariance.ok()) return covariance.status();
  result.position_covariance_m2 = *covariance;
  result.position_sigma_m = std::sqrt(covariance->trace());
  return result;
}

}  // namespace teachsim::vision
