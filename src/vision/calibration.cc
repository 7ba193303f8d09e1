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

#include "sampling.h"

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

namespace teachsim::vision {

namespace {

// A sub-pixel edge point: position in the distorted image and in the undistorted one (where the
// lines are fitted), the gradient's unit normal and magnitude.
struct EdgePoint {
  Eigen::Vector2d pixel, ideal;
  Eigen::Vector2d normal;
  double angle = 0;  // of the normal, mod pi
  double weight = 0;
};

// A line n . x = c in undistorted pixels, with what its fit says about its accuracy.
struct EdgeLine {
  Eigen::Vector2d normal{1, 0};
  double c = 0;
  Eigen::Vector2d centroid{0, 0};
  double offset_var = 0;  // variance of c at the centroid, px^2
  double slope_var = 0;   // variance of the direction, rad^2
  double rms_px = 0;
  std::vector<int> members;  // indices into the edge points
};

double AngleDiff(double a, double b) {  // between two directions mod pi
  double d = std::fmod(std::abs(a - b), M_PI);
  return std::min(d, M_PI - d);
}

// Weighted total least squares over `members`; false when degenerate.
bool FitLine(const std::vector<EdgePoint>& points, EdgeLine& line) {
  double w_sum = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (int i : line.members) {
    w_sum += points[static_cast<std::size_t>(i)].weight;
    mean += points[static_cast<std::size_t>(i)].weight * points[static_cast<std::size_t>(i)].ideal;
  }
  if (line.members.size() < 2 || w_sum <= 0) return false;
  mean /= w_sum;
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (int i : line.members) {
    const Eigen::Vector2d d = points[static_cast<std::size_t>(i)].ideal - mean;
    scatter += points[static_cast<std::size_t>(i)].weight * d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(scatter);
  Eigen::Vector2d normal = eigen.eigenvectors().col(0);
  // Keep the normal's sense stable (it is compared by angle mod pi only).
  if (normal.dot(line.normal) < 0) normal = -normal;
  line.normal = normal;
  line.centroid = mean;
  line.c = normal.dot(mean);
  const double n = static_cast<double>(line.members.size());
  const double along_var = eigen.eigenvalues()(1) / w_sum;  // spread along the line, px^2
  const double residual_var = eigen.eigenvalues()(0) / w_sum * n / std::max(1.0, n - 2);
  line.rms_px = std::sqrt(eigen.eigenvalues()(0) / w_sum);
  line.offset_var = residual_var / n;
  line.slope_var = along_var > 0 ? residual_var / (n * along_var) : 1e9;
  return true;
}

// The point minimizing the weighted squared distances to the lines, and its covariance.
bool IntersectLines(const std::vector<EdgeLine>& lines, Eigen::Vector2d& point, Eigen::Matrix2d& covariance,
                    const Eigen::Vector2d& near) {
  // Each line's offset variance at the (expected) intersection: offset at the centroid plus the
  // direction's error levered over the distance from the centroid.
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (const EdgeLine& l : lines) {
    const Eigen::Vector2d t(-l.normal.y(), l.normal.x());
    const double lever = t.dot(near - l.centroid);
    const double var = l.offset_var + l.slope_var * lever * lever + 1e-6;
    a += l.normal * l.normal.transpose() / var;
    b += l.normal * l.c / var;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(a);
  if (!(eigen.eigenvalues()(0) > 1e-9 * eigen.eigenvalues()(1))) return false;
  point = a.ldlt().solve(b);
  covariance = a.inverse();
  return point.allFinite();
}

SnapResult SnapWithCornerSubPix(const cv::Mat& gray, const Eigen::Vector2d& click,
                                const SnapOptions& options) {
  SnapResult r;
  r.pixel = click;
  const int half = std::max(2, static_cast<int>(std::lround(options.window_px / 2)));
  std::vector<cv::Point2f> corner{cv::Point2f(static_cast<float>(click.x()), static_cast<float>(click.y()))};
  try {
    cv::cornerSubPix(gray, corner, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  } catch (const cv::Exception& e) {
    r.reason = std::string("cornerSubPix failed: ") + e.what();
    return r;
  }
  const Eigen::Vector2d snapped(corner[0].x, corner[0].y);
  if (!snapped.allFinite() || (snapped - click).norm() > options.max_offset_px) {
    r.reason = "cornerSubPix moved the point " + json::FormatNumber((snapped - click).norm()) +
               " px (more than " + json::FormatNumber(options.max_offset_px) + ")";
    return r;
  }
  r.snapped = true;
  r.pixel = snapped;
  r.offset_px = (snapped - click).norm();
  return r;
}

}  // namespace

Status SnapOptions::Validate() const {
  auto positive = [](double v) { return v > 0 && std::isfinite(v); };
  if (!positive(window_px) || window_px < 4 || window_px > 64) {
    return Status::InvalidInput("SnapOptions::window_px = " + json::FormatNumber(window_px) +
                                " must be in [4, 64] px");
  }
  if (!positive(max_offset_px)) {
    return Status::InvalidInput("SnapOptions::max_offset_px = " + json::FormatNumber(max_offset_px) +
                                " must be > 0 px");
  }
  if (!(junction_px >= 0) || junction_px >= window_px - 3) {
    return Status::InvalidInput("SnapOptions::junction_px = " + json::FormatNumber(junction_px) +
                                " must be >= 0 and leave at least 3 px of the window");
  }
  if (!(smooth_sigma_px >= 0) || smooth_sigma_px > 5) {
    return Status::InvalidInput("SnapOptions::smooth_sigma_px = " + json::FormatNumber(smooth_sigma_px) +
                                " must be in [0, 5] px");
  }
  if (!(min_gradient >= 0) || !(relative_gradient >= 0 && relative_gradient < 1)) {
    return Status::InvalidInput("SnapOptions: min_gradient must be >= 0 and relative_gradient in [0, 1)");
  }
  if (!(min_step >= 0) || !std::isfinite(min_step)) {
    return Status::InvalidInput("SnapOptions::min_step = " + json::FormatNumber(min_step) + " must be >= 0");
  }
  if (min_edge_points < 3) {
    return Status::InvalidInput("SnapOptions::min_edge_points = " + std::to_string(min_edge_points) +
                                " must be >= 3");
  }
  if (!(min_edge_angle_rad > 0 && min_edge_angle_rad < M_PI / 2)) {
    return Status::InvalidInput("SnapOptions::min_edge_angle_rad = " +
                                json::FormatNumber(min_edge_angle_rad) + " must be in (0, pi/2)");
  }
  return Status::Ok();
}

SnapResult SnapToCorner(const cv::Mat& gray, const Camera& camera, const Eigen::Vector2d& click,
                        const SnapOptions& options) {
  TEACHSIM_CHECK(gray.type() == CV_8UC1);
  SnapResult result;
  result.pixel = click;
  if (!click.allFinite() || !camera.InImage(click)) {
    result.reason = "the click lies outside the image";
    return result;
  }
  if (options.method == SnapMethod::kCornerSubPix) return SnapWithCornerSubPix(gray, click, options);

  // The patch: the window plus a margin for the smoothing and the gradient.
  const int margin = static_cast<int>(std::ceil(options.window_px + 3 * options.smooth_sigma_px + 3));
  const int cu = static_cast<int>(std::lround(click.x())), cv_ = static_cast<int>(std::lround(click.y()));
  const cv::Rect roi = cv::Rect(cu - margin, cv_ - margin, 2 * margin + 1, 2 * margin + 1) &
                       cv::Rect(0, 0, gray.cols, gray.rows);
  cv::Mat patch;
  gray(roi).convertTo(patch, CV_32F);
  if (options.smooth_sigma_px > 0) {
    cv::GaussianBlur(patch, patch, cv::Size(0, 0), options.smooth_sigma_px, options.smooth_sigma_px,
                     cv::BORDER_REPLICATE);
  }
  cv::Mat gx, gy, magnitude;
  cv::Sobel(patch, gx, CV_32F, 1, 0, 3, 1.0 / 8, 0, cv::BORDER_REPLICATE);
  cv::Sobel(patch, gy, CV_32F, 0, 1, 3, 1.0 / 8, 0, cv::BORDER_REPLICATE);
  cv::magnitude(gx, gy, magnitude);

  const Eigen::Vector2d origin(roi.x, roi.y);
  const Eigen::Vector2d click_in_patch = click - origin;
  const double window2 = options.window_px * options.window_px;
  double strongest = 0;
  for (int y = 1; y + 1 < patch.rows; ++y) {
    for (int x = 1; x + 1 < patch.cols; ++x) {
      if ((Eigen::Vector2d(x, y) - click_in_patch).squaredNorm() <= window2) {
        strongest = std::max(strongest, static_cast<double>(magnitude.at<float>(y, x)));
      }
    }
  }
  const double threshold = std::max(options.min_gradient, options.relative_gradient * strongest);
  if (strongest < options.min_gradient) {
    result.reason =
        "no edges near the click (strongest gradient " + json::FormatNumber(strongest) + " gray levels/px)";
    return result;
  }

  // Sub-pixel edge points: local maxima of the gradient magnitude along the gradient, the peak
  // placed by a parabola through three samples.
  std::vector<EdgePoint> points;
  for (int y = 1; y + 1 < patch.rows; ++y) {
    for (int x = 1; x + 1 < patch.cols; ++x) {
      const double m0 = magnitude.at<float>(y, x);
      if (m0 < threshold) continue;
      if ((Eigen::Vector2d(x, y) - click_in_patch).squaredNorm() > window2) continue;
      const Eigen::Vector2d n = Eigen::Vector2d(gx.at<float>(y, x), gy.at<float>(y, x)) / m0;
      const double minus = internal::SampleBilinear(magnitude, x - n.x(), y - n.y());
      const double plus = internal::SampleBilinear(magnitude, x + n.x(), y + n.y());
      if (!(m0 >= minus && m0 > plus)) continue;
      const double curvature = minus - 2 * m0 + plus;
      const double delta = curvature < 0 ? std::clamp(0.5 * (minus - plus) / curvature, -0.5, 0.5) : 0.0;
      EdgePoint e;
      e.pixel = origin + Eigen::Vector2d(x, y) + delta * n;
      auto ideal = camera.UndistortPixel(e.pixel);
      if (!ideal) continue;
      e.ideal = *ideal;
      e.normal = n;
      e.angle = std::fmod(std::atan2(n.y(), n.x()) + 2 * M_PI, M_PI);
      e.weight = m0;
      points.push_back(e);
    }
  }
  auto ideal_click = camera.UndistortPixel(click);
  if (!ideal_click) {
    result.reason = "the lens model has no inverse at the click";
    return result;
  }

  // Lines through (near) the corner, strongest first. A weighted histogram of the gradients'
  // directions (with their sense: an edge between two faces has one polarity all along, the two
  // flanks of a grain stripe have opposite ones) gives a direction; a histogram of offsets along it
  // gives candidate lines, each refined by a fit to the points near it. Of parallel candidates (the
  // face's edge and the grain beside it) the one with the largest step in brightness across it
  // wins: an edge separates two faces, a stripe of grain has the same face on both sides. Points
  // close to the junction are left out (the blur rounds the corner).
  auto angle_of = [](const Eigen::Vector2d& n) {
    return std::fmod(std::atan2(n.y(), n.x()) + 2 * M_PI, 2 * M_PI);
  };
  auto oriented_diff = [](double a, double b) {
    const double d = std::fmod(std::abs(a - b), 2 * M_PI);
    return std::min(d, 2 * M_PI - d);
  };
  const double step_px = 2.5;  // brightness sampled this far either side of an edge point
  auto step_contrast = [&](const EdgeLine& line) {
    double sum = 0;
    for (int i : line.members) {
      const EdgePoint& e = points[static_cast<std::size_t>(i)];
      const Eigen::Vector2d q = e.pixel - origin;
      sum += internal::SampleBilinear(patch, q.x() + step_px * e.normal.x(), q.y() + step_px * e.normal.y()) -
             internal::SampleBilinear(patch, q.x() - step_px * e.normal.x(), q.y() - step_px * e.normal.y());
    }
    return line.members.empty() ? 0.0 : sum / static_cast<double>(line.members.size());
  };
  auto find_lines = [&](const Eigen::Vector2d& corner) {
    std::vector<EdgeLine> lines;
    std::vector<bool> used(points.size(), false);
    const double reach = options.max_offset_px + 1.5;
    const double junction2 = options.junction_px * options.junction_px;
    double first_support = 0;
    std::vector<double> blocked_angles;  // directions tried (mod pi): lines through a corner differ more
    for (int attempt = 0; attempt < 6 && lines.size() < 3; ++attempt) {
      constexpr int kBins = 360;
      std::vector<double> histogram(kBins, 0.0);
      for (std::size_t i = 0; i < points.size(); ++i) {
        if (used[i] || (points[i].ideal - corner).squaredNorm() < junction2) continue;
        // Only points whose edge passes near the corner vote.
        if (std::abs(points[i].normal.dot(points[i].ideal - corner)) > reach) continue;
        const int bin = static_cast<int>(angle_of(points[i].normal) / (2 * M_PI) * kBins) % kBins;
        histogram[static_cast<std::size_t>(bin)] += points[i].weight;
      }
      int best = 0;
      double best_sum = 0;
      for (int b = 0; b < kBins; ++b) {
        const double a = (b + 0.5) * 2 * M_PI / kBins;
        bool blocked = false;
        for (const double x : blocked_angles) {
          if (AngleDiff(x, a) < options.min_edge_angle_rad) blocked = true;
        }
        if (blocked) continue;
        double sum = 0;
        for (int k = -4; k <= 4; ++k) {
          sum += (5 - std::abs(k)) * histogram[static_cast<std::size_t>((b + k + kBins) % kBins)];
        }
        if (sum > best_sum) {
          best_sum = sum;
          best = b;
        }
      }
      if (best_sum <= 0 || (first_support > 0 && best_sum < 0.1 * first_support)) break;
      const double angle = (best + 0.5) * 2 * M_PI / kBins;
      blocked_angles.push_back(std::fmod(angle, M_PI));
      const Eigen::Vector2d normal(std::cos(angle), std::sin(angle));
      // The offset histogram, 0.5 px bins; its peaks are the candidate lines.
      const int offset_bins = static_cast<int>(std::ceil(2 * reach / 0.5));
      std::vector<double> offsets(static_cast<std::size_t>(offset_bins), 0.0);
      for (std::size_t i = 0; i < points.size(); ++i) {
        if (used[i] || oriented_diff(angle_of(points[i].normal), angle) > 0.15) continue;
        if ((points[i].ideal - corner).squaredNorm() < junction2) continue;
        const double d = normal.dot(points[i].ideal - corner);
        if (std::abs(d) >= reach) continue;
        offsets[static_cast<std::size_t>(
            std::clamp(static_cast<int>((d + reach) / 0.5), 0, offset_bins - 1))] += points[i].weight;
      }
      std::vector<double> smoothed(offsets.size(), 0.0);
      double peak = 0;
      for (int b = 0; b < offset_bins; ++b) {
        smoothed[static_cast<std::size_t>(b)] =
            offsets[static_cast<std::size_t>(b)] +
            0.5 * (b > 0 ? offsets[static_cast<std::size_t>(b - 1)] : 0) +
            0.5 * (b + 1 < offset_bins ? offsets[static_cast<std::size_t>(b + 1)] : 0);
        peak = std::max(peak, smoothed[static_cast<std::size_t>(b)]);
      }
      EdgeLine chosen;
      double chosen_contrast = 0;
      for (int b = 0; b < offset_bins; ++b) {
        const double v = smoothed[static_cast<std::size_t>(b)];
        if (v < 0.25 * peak || v <= 0) continue;
        if ((b > 0 && smoothed[static_cast<std::size_t>(b - 1)] > v) ||
            (b + 1 < offset_bins && smoothed[static_cast<std::size_t>(b + 1)] >= v)) {
          continue;  // not a local maximum
        }
        EdgeLine line;
        line.normal = normal;
        line.c = normal.dot(corner) + (b + 0.5) * 0.5 - reach;
        bool ok = false;
        for (int iteration = 0; iteration < 4; ++iteration) {
          line.members.clear();
          const double band = iteration == 0 ? 1.0 : 0.7;
          const double line_angle = angle_of(line.normal);
          for (std::size_t i = 0; i < points.size(); ++i) {
            if (used[i] || oriented_diff(angle_of(points[i].normal), line_angle) > 0.2) continue;
            if ((points[i].ideal - corner).squaredNorm() < junction2) continue;
            if (std::abs(line.normal.dot(points[i].ideal) - line.c) > band) continue;
            line.members.push_back(static_cast<int>(i));
          }
          ok = static_cast<int>(line.members.size()) >= options.min_edge_points && FitLine(points, line);
          if (!ok) break;
        }
        if (!ok) continue;
        const Eigen::Vector2d t(-line.normal.y(), line.normal.x());
        double lo = 1e9, hi = -1e9;
        for (int i : line.members) {
          const double s = t.dot(points[static_cast<std::size_t>(i)].ideal);
          lo = std::min(lo, s);
          hi = std::max(hi, s);
        }
        if (hi - lo < 4 || std::abs(line.normal.dot(corner) - line.c) > reach) continue;
        const double contrast = step_contrast(line);
        if (contrast > chosen_contrast) {
          chosen_contrast = contrast;
          chosen = std::move(line);
        }
      }
      if (chosen.members.empty() || chosen_contrast < options.min_step) continue;
      for (int i : chosen.members) used[static_cast<std::size_t>(i)] = true;
      if (first_support == 0) first_support = best_sum;
      blocked_angles.back() = std::fmod(angle_of(chosen.normal), M_PI);
      lines.push_back(std::move(chosen));
    }
    return lines;
  };

  Eigen::Vector2d corner = *ideal_click;
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
  std::vector<EdgeLine> lines;
  // Twice: the second pass leaves out the points near the first estimate of the corner instead of
  // near the click.
  for (int pass = 0; pass < 2; ++pass) {
    lines = find_lines(corner);
    if (lines.size() < 2) {
      result.reason = lines.empty() ? "no straight edge through the click"
                                    : "only one straight edge through the click (not a corner?)";
      return result;
    }
    Eigen::Vector2d next;
    if (!IntersectLines(lines, next, covariance, corner)) {
      result.reason = "the edges near the click are (nearly) parallel";
      return result;
    }
    // Three lines that do not meet in a point (an edge of something else passing by): keep the two
    // that agree best, i.e. drop the line farthest from the joint intersection.
    if (lines.size() == 3) {
      std::size_t worst = 0;
      double worst_px = 0;
      for (std::size_t i = 0; i < lines.size(); ++i) {
        const double d = std::abs(lines[i].normal.dot(next) - lines[i].c);
        if (d > worst_px) {
          worst_px = d;
          worst = i;
        }
      }
      if (worst_px > 0.75) {
        lines.erase(lines.begin() + static_cast<std::ptrdiff_t>(worst));
        if (!IntersectLines(lines, next, covariance, corner)) {
          result.reason = "the edges near the click are (nearly) parallel";
          return result;
        }
      }
    }
    if ((next - *ideal_click).norm() > options.max_offset_px + 2) {
      result.reason =
          "the edges meet " + json::FormatNumber((next - *ideal_click).norm()) + " px from the click";
      return result;
    }
    corner = next;
  }
  // Back to the distorted image.
  const Intrinsics& k = camera.intrinsics();
  const Eigen::Vector2d snapped =
      camera.NormalizedToPixel({(corner.x() - k.cx) / k.fx, (corner.y() - k.cy) / k.fy});
  const double offset = (snapped - click).norm();
  if (!snapped.allFinite() || offset > options.max_offset_px) {
    result.reason = "the edges meet " + json::FormatNumber(offset) + " px from the click (more than " +
                    json::FormatNumber(options.max_offset_px) + ")";
    return result;
  }
  double rms = 0;
  int n = 0;
  for (const EdgeLine& l : lines) {
    rms += l.rms_px * l.rms_px * static_cast<double>(l.members.size());
    n += static_cast<int>(l.members.size());
  }
  result.snapped = true;
  result.pixel = snapped;
  result.offset_px = offset;
  result.sigma_px = std::sqrt(std::max(0.0, covariance.trace() / 2));
  result.edges = static_cast<int>(lines.size());
  result.edge_rms_px = std::sqrt(rms / std::max(1, n));
  return result;
}

std::vector<SnapResult> SnapCorrespondences(const cv::Mat& gray, const Camera& camera,
                                            std::vector<PointCorrespondence>& points,
                                            const SnapOptions& options) {
  std::vector<SnapResult> results;
  results.reserve(points.size());
  for (PointCorrespondence& p : points) {
    results.push_back(SnapToCorner(gray, camera, p.pixel, options));
    p.pixel = results.back().pixel;
  }
  return results;
}

}  // namespace teachsim::vision
