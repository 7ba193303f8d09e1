#include "teachsim/vision/calibration.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
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
      p.RejectUnknownKeys({"name", "pixel", "world", "edges"});
      PointCorrespondence c;
      c.name = p.Has("name") ? p.At("name").NonEmptyString() : "point " + std::to_string(i);
      const json::Reader pixel = p.At("pixel");
      pixel.ExpectSize(2);
      c.pixel = {pixel.Index(0).Number(), pixel.Index(1).Number()};
      c.p_in_world = p.At("world").Vector3();
      if (p.Has("edges")) {
        const json::Reader edges = p.At("edges");
        for (std::size_t e = 0; e < edges.Size(); ++e) {
          const Eigen::Vector3d edge = edges.Index(e).Vector3();
          if (!(edge.norm() > 1e-6))
            edges.Index(e).Fail("an edge needs a length > 1e-6 m (direction x length)");
          c.edges_in_world.push_back(edge);
        }
      }
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
    if (!p.edges_in_world.empty()) {
      json::Json edges = json::Json::array();
      for (const Eigen::Vector3d& e : p.edges_in_world) edges.push_back({e.x(), e.y(), e.z()});
      entry["edges"] = std::move(edges);
    }
    list.push_back(std::move(entry));
  }
  return {{"points", list}};
}

Status ExtrinsicsOptions::Validate() const {
  if (!(click_sigma_px > 0) || !std::isfinite(click_sigma_px)) {
    return Status::InvalidInput("extrinsics: click sigma must be > 0 px, got " +
                                json::FormatNumber(click_sigma_px));
  }
  if (!(drop_beyond_sigmas >= 0) || !std::isfinite(drop_beyond_sigmas)) {
    return Status::InvalidInput("extrinsics: drop_beyond_sigmas must be >= 0 (0: keep all points), got " +
                                json::FormatNumber(drop_beyond_sigmas));
  }
  return Status::Ok();
}

namespace {

// PredictedPositionCovariance with a sigma per point.
Result<Eigen::Matrix3d> PositionCovariance(const Camera& camera,
                                           const std::vector<Eigen::Vector3d>& points_in_world,
                                           const std::vector<double>& sigmas_px) {
  for (const double sigma_px : sigmas_px) {
    if (!(sigma_px > 0) || !std::isfinite(sigma_px)) {
      return Status::InvalidInput("extrinsics: pixel sigma must be > 0 px, got " +
                                  json::FormatNumber(sigma_px));
    }
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
    return camera.WithPose(geometry::Pose3(q.normalized(), pose.translation + dp));
  };
  Eigen::MatrixXd jacobian(2 * static_cast<Eigen::Index>(points_in_world.size()), 6);
  for (int k = 0; k < 6; ++k) {
    const Camera plus = moved(k, step), minus = moved(k, -step);
    for (std::size_t i = 0; i < points_in_world.size(); ++i) {
      const auto a = plus.Project(points_in_world[i]), b = minus.Project(points_in_world[i]);
      if (!a || !b) {
        return Status::InvalidInput("extrinsics: point " + std::to_string(i) + " lies behind the camera");
      }
      jacobian.block<2, 1>(2 * static_cast<Eigen::Index>(i), k) = (*a - *b) / (2 * step * sigmas_px[i]);
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
  const Eigen::Matrix<double, 6, 6> covariance = ldlt.solve(Eigen::Matrix<double, 6, 6>::Identity());
  return Eigen::Matrix3d(covariance.topLeftCorner<3, 3>());
}

// Levenberg-Marquardt on the reprojection error weighted by 1 / sigma_i^2, from (rvec, tvec);
// cv::solvePnPRefineLM has no weights.
void RefineWeighted(const std::vector<cv::Point3d>& world, const std::vector<cv::Point2d>& pixels,
                    const std::vector<double>& weights, const cv::Mat& k, const cv::Mat& dist, cv::Mat& rvec,
                    cv::Mat& tvec) {
  auto cost_of = [&](const cv::Mat& r, const cv::Mat& t) {
    std::vector<cv::Point2d> projected;
    cv::projectPoints(world, r, t, k, dist, projected);
    double cost = 0;
    for (std::size_t i = 0; i < world.size(); ++i) {
      const cv::Point2d d = projected[i] - pixels[i];
      cost += weights[i] * (d.x * d.x + d.y * d.y);
    }
    return cost;
  };
  double lambda = 1e-3;
  double cost = cost_of(rvec, tvec);
  for (int iteration = 0; iteration < 100; ++iteration) {
    std::vector<cv::Point2d> projected;
    cv::Mat jacobian;
    cv::projectPoints(world, rvec, tvec, k, dist, projected, jacobian);
    Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    for (std::size_t i = 0; i < world.size(); ++i) {
      for (int row = 0; row < 2; ++row) {
        Eigen::Matrix<double, 6, 1> j;
        for (int c = 0; c < 6; ++c) j(c) = jacobian.at<double>(static_cast<int>(2 * i) + row, c);
        const double r = row == 0 ? projected[i].x - pixels[i].x : projected[i].y - pixels[i].y;
        a += weights[i] * j * j.transpose();
        g += weights[i] * j * r;
      }
    }
    bool improved = false;
    for (int attempt = 0; attempt < 10 && !improved; ++attempt) {
      Eigen::Matrix<double, 6, 6> damped = a;
      damped.diagonal() *= 1 + lambda;
      const Eigen::Matrix<double, 6, 1> delta = -damped.ldlt().solve(g);
      cv::Mat r = rvec.clone(), t = tvec.clone();
      for (int c = 0; c < 3; ++c) {
        r.at<double>(c) += delta(c);
        t.at<double>(c) += delta(c + 3);
      }
      const double next = cost_of(r, t);
      if (next < cost) {
        improved = true;
        rvec = r;
        tvec = t;
        const bool converged = cost - next < 1e-14 * (1 + cost);
        cost = next;
        lambda = std::max(1e-9, lambda / 10);
        if (converged) return;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) return;
  }
}

}  // namespace

Result<Eigen::Matrix3d> PredictedPositionCovariance(const Camera& camera,
                                                    const std::vector<Eigen::Vector3d>& points_in_world,
                                                    double sigma_px) {
  return PositionCovariance(camera, points_in_world, std::vector<double>(points_in_world.size(), sigma_px));
}

Result<ExtrinsicsResult> CalibrateExtrinsics(const Camera& camera,
                                             const std::vector<PointCorrespondence>& points,
                                             const ExtrinsicsOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  if (points.size() < 4) {
    return Status::InvalidInput("extrinsics: needs at least 4 points, got " + std::to_string(points.size()));
  }
  std::vector<double> sigmas;
  for (const PointCorrespondence& p : points) {
    if (!p.pixel.allFinite() || !p.p_in_world.allFinite()) {
      return Status::InvalidInput("extrinsics: point '" + p.name + "' is not finite");
    }
    if (!(p.sigma_px >= 0) || !std::isfinite(p.sigma_px)) {
      return Status::InvalidInput("extrinsics: point '" + p.name + "' has sigma " +
                                  json::FormatNumber(p.sigma_px) + " px, expected >= 0 (0: the click sigma)");
    }
    sigmas.push_back(p.sigma_px > 0 ? p.sigma_px : options.click_sigma_px);
  }
  const cv::Mat k = CameraMatrix(camera.intrinsics());
  const cv::Mat dist = DistCoeffs(camera.distortion());
  std::vector<bool> dropped(points.size(), false);
  ExtrinsicsResult result;
  for (;;) {
    std::vector<cv::Point3d> world;
    std::vector<cv::Point2d> pixels;
    std::vector<double> weights;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (dropped[i]) continue;
      const PointCorrespondence& p = points[i];
      world.emplace_back(p.p_in_world.x(), p.p_in_world.y(), p.p_in_world.z());
      pixels.emplace_back(p.pixel.x(), p.pixel.y());
      weights.push_back(1 / (sigmas[i] * sigmas[i]));
    }
    cv::Mat rvec, tvec;
    try {
      if (!cv::solvePnP(world, pixels, k, dist, rvec, tvec, false, cv::SOLVEPNP_SQPNP)) {
        return Status::Failed("extrinsics: PnP found no pose (are the points collinear or mislabelled?)");
      }
      cv::solvePnPRefineLM(world, pixels, k, dist, rvec, tvec,
                           cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-12));
      if (*std::min_element(weights.begin(), weights.end()) !=
          *std::max_element(weights.begin(), weights.end())) {
        RefineWeighted(world, pixels, weights, k, dist, rvec, tvec);
      }
    } catch (const cv::Exception& e) {
      return Status::Failed(std::string("extrinsics: OpenCV failed: ") + e.what());
    }
    const geometry::Pose3 camera_T_world = PoseFromRvecTvec(rvec, tvec);
    result = ExtrinsicsResult{};
    result.world_T_camera = camera_T_world.Inverse();
    result.dropped = dropped;
    const Camera solved = camera.WithPose(result.world_T_camera);
    double sum = 0;
    int used = 0;
    std::size_t worst = points.size();
    double worst_ratio = 0;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const PointCorrespondence& p = points[i];
      auto projected = solved.Project(p.p_in_world);
      if (!projected) {
        return Status::Failed("extrinsics: point '" + p.name +
                              "' lies behind the solved camera (mislabelled points?)");
      }
      const double r = (*projected - p.pixel).norm();
      result.residuals_px.push_back(r);
      if (dropped[i]) continue;
      sum += r * r;
      ++used;
      // The residual of a point is smaller than its error (the pose follows it), so compare with
      // its sigma per coordinate times sqrt(2) for the distance.
      const double ratio = r / (std::sqrt(2.0) * sigmas[i]);
      if (r > 1 && ratio > worst_ratio) {
        worst_ratio = ratio;
        worst = i;
      }
    }
    result.rms_px = std::sqrt(sum / static_cast<double>(used));
    std::vector<Eigen::Vector3d> in_world;
    std::vector<double> used_sigmas;
    for (std::size_t i = 0; i < points.size(); ++i) {
      if (dropped[i]) continue;
      in_world.push_back(points[i].p_in_world);
      used_sigmas.push_back(sigmas[i]);
    }
    auto covariance = PositionCovariance(solved, in_world, used_sigmas);
    if (!covariance.ok()) return covariance.status();
    result.position_covariance_m2 = *covariance;
    result.position_sigma_m = std::sqrt(covariance->trace());
    if (options.drop_beyond_sigmas > 0 && worst < points.size() && worst_ratio > options.drop_beyond_sigmas &&
        used > 5) {
      dropped[worst] = true;
      continue;
    }
    return result;
  }
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
  if (!(band_px >= 1.5 && band_px <= 10) || !(edge_length_px >= 4 && edge_length_px <= 60) ||
      !(max_turn_rad > 0 && max_turn_rad < 0.5)) {
    return Status::InvalidInput(
        "SnapOptions: band_px must be in [1.5, 10] px, edge_length_px in [4, 60] px and "
        "max_turn_rad in (0, 0.5), got " +
        json::FormatNumber(band_px) + ", " + json::FormatNumber(edge_length_px) + ", " +
        json::FormatNumber(max_turn_rad));
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
  cv::Mat patch = internal::LinearLight(gray(roi), camera.gamma());
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
  const Eigen::Vector2d snapped = camera.DistortPixel(corner);
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
                                            const SnapOptions& options, double click_sigma_px) {
  std::vector<SnapResult> results;
  results.reserve(points.size());
  const std::vector<PointCorrespondence> clicked = points;
  if (options.method == SnapMethod::kEdgeLines && options.use_model && points.size() >= 4) {
    ExtrinsicsOptions first;
    first.click_sigma_px = click_sigma_px > 0 ? click_sigma_px : 0.5;
    std::vector<PointCorrespondence> current = clicked;
    for (PointCorrespondence& p : current) p.sigma_px = 0;
    bool guided = false;
    // Twice: the pose from the clicks, then the one from the snapped points, predicts the edges.
    for (int round = 0; round < 2; ++round) {
      auto pose = CalibrateExtrinsics(camera, current, first);
      if (!pose.ok()) break;
      const Camera posed = camera.WithPose(pose->world_T_camera);
      std::vector<SnapResult> round_results;
      for (std::size_t i = 0; i < clicked.size(); ++i) {
        round_results.push_back(SnapToModelCorner(gray, posed, clicked[i], options));
        current[i].pixel = round_results.back().pixel;
        current[i].sigma_px =
            round_results.back().snapped ? std::max(round_results.back().sigma_px, 0.02) : 0;
      }
      results = std::move(round_results);
      guided = true;
    }
    if (guided) {
      points = current;
      return results;
    }
    results.clear();
  }
  for (PointCorrespondence& p : points) {
    results.push_back(SnapToCorner(gray, camera, p.pixel, options));
    p.pixel = results.back().pixel;
    if (results.back().snapped && results.back().sigma_px > 0)
      p.sigma_px = std::max(results.back().sigma_px, 0.02);
  }
  return results;
}

}  // namespace teachsim::vision

// ---------------------------------------------------------------------------------------------
// Model-guided snapping: blurred steps fitted along the predicted edges.

namespace teachsim::vision {

namespace {

// The pixels around a point: gray levels and their undistorted (ideal) positions, where straight
// world edges are straight lines.
struct IdealPatch {
  cv::Rect roi;
  cv::Mat values;  // CV_32F, the gray levels in linear light (no smoothing: the fit models the blur)
  std::vector<Eigen::Vector2d> ideal;  // row-major over roi
};

// The ideal positions come from a grid of exact undistortions every 4 px, interpolated bilinearly
// (the lens model's curvature makes that good to ~0.002 px), which keeps a patch cheap.
std::optional<IdealPatch> MakeIdealPatch(const cv::Mat& gray, const Camera& camera,
                                         const Eigen::Vector2d& centre, int radius) {
  IdealPatch patch;
  const int cu = static_cast<int>(std::lround(centre.x())), cv_ = static_cast<int>(std::lround(centre.y()));
  patch.roi = cv::Rect(cu - radius, cv_ - radius, 2 * radius + 1, 2 * radius + 1) &
              cv::Rect(0, 0, gray.cols, gray.rows);
  if (patch.roi.width < 8 || patch.roi.height < 8) return std::nullopt;
  patch.values = internal::LinearLight(gray(patch.roi), camera.gamma());
  constexpr int kStep = 4;
  const int gw = patch.roi.width / kStep + 2, gh = patch.roi.height / kStep + 2;
  std::vector<Eigen::Vector2d> grid(static_cast<std::size_t>(gw * gh));
  for (int j = 0; j < gh; ++j) {
    for (int i = 0; i < gw; ++i) {
      auto ideal = camera.UndistortPixel(Eigen::Vector2d(patch.roi.x + i * kStep, patch.roi.y + j * kStep));
      if (!ideal) return std::nullopt;
      grid[static_cast<std::size_t>(j * gw + i)] = *ideal;
    }
  }
  patch.ideal.resize(static_cast<std::size_t>(patch.roi.area()));
  for (int y = 0; y < patch.roi.height; ++y) {
    const int j = y / kStep;
    const double fy = static_cast<double>(y - j * kStep) / kStep;
    for (int x = 0; x < patch.roi.width; ++x) {
      const int i = x / kStep;
      const double fx = static_cast<double>(x - i * kStep) / kStep;
      auto at = [&](int a, int b) { return grid[static_cast<std::size_t>(b * gw + a)]; };
      patch.ideal[static_cast<std::size_t>(y * patch.roi.width + x)] =
          (1 - fy) * ((1 - fx) * at(i, j) + fx * at(i + 1, j)) +
          fy * ((1 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1));
    }
  }
  return patch;
}

double NormalCdf(double u) { return 0.5 * std::erfc(-u / std::sqrt(2.0)); }
double NormalPdf(double u) { return std::exp(-0.5 * u * u) / std::sqrt(2 * M_PI); }

// A straight edge predicted from the model: from `corner` (ideal px) along unit `direction`.
struct PredictedEdge {
  Eigen::Vector2d direction{1, 0};
  double length_px = 1e9;  // how far the edge runs straight in the image
  double r_min = 3, r_max = 17;
};

// The fitted step: the line n . x = c (ideal px) with the profile a + b Phi((n . x - c) / s).
struct StepFit {
  bool ok = false;
  Eigen::Vector2d normal{1, 0};
  double c = 0;
  double a = 0, b = 0, s = 1;
  double turn_rad = 0;     // from the predicted direction
  Eigen::Vector2d centre;  // the band's centre on the line
  double offset_var = 0, slope_var = 0;
  double rms = 0;
  int pixels = 0;
};

// Fits a blurred step to the pixels of `patch` in the band along `edge` from `corner`: offset
// `start_offset` from the predicted line, +-half_width across it. The two faces' brightnesses may
// each vary linearly (shading across a face, the table's mottle, a face's grain on average):
// constants would turn and shift the line to absorb such a slope. Damped Gauss-Newton over the six
// brightness terms, the line's offset and turn and the blur; the line is parameterized about the
// band's centre so that offset and turn are nearly independent.
StepFit FitStep(const IdealPatch& patch, const Eigen::Vector2d& corner, const PredictedEdge& edge,
                double start_offset, double half_width, int iterations, bool free_turn,
                double offset_tolerance_px = 0) {
  StepFit fit;
  const Eigen::Vector2d t0 = edge.direction, n0(-t0.y(), t0.x());
  const Eigen::Vector2d centre = corner + t0 * 0.5 * (edge.r_min + edge.r_max);
  const double half_length = std::max(1.0, 0.5 * (edge.r_max - edge.r_min));
  std::vector<Eigen::Vector2d> xs;
  std::vector<double> vs;
  for (int y = 0; y < patch.roi.height; ++y) {
    for (int x = 0; x < patch.roi.width; ++x) {
      const Eigen::Vector2d q = patch.ideal[static_cast<std::size_t>(y * patch.roi.width + x)] - corner;
      const double along = t0.dot(q), across = n0.dot(q) - start_offset;
      if (along < edge.r_min || along > edge.r_max || std::abs(across) > half_width) continue;
      xs.push_back(q + corner - centre);
      vs.push_back(patch.values.at<float>(y, x));
    }
  }
  const int n = static_cast<int>(xs.size());
  constexpr int kParams =
      9;  // dark side a0 a_along a_across, bright side b0 b_along b_across, offset, turn, blur
  using Vector = Eigen::Matrix<double, kParams, 1>;
  using Matrix = Eigen::Matrix<double, kParams, kParams>;
  if (n < 30) return fit;
  Vector p = Vector::Zero();
  p(6) = start_offset;
  p(8) = 1.0;
  {  // Start: no slopes, no turn, blur 1 px, the two brightnesses by linear least squares.
    Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
    Eigen::Vector2d r = Eigen::Vector2d::Zero();
    for (int i = 0; i < n; ++i) {
      const double phi = NormalCdf(n0.dot(xs[static_cast<std::size_t>(i)]) - start_offset);
      const Eigen::Vector2d f(1 - phi, phi);
      m += f * f.transpose();
      r += f * vs[static_cast<std::size_t>(i)];
    }
    if (std::abs(m.determinant()) < 1e-9) return fit;
    const Eigen::Vector2d ab = m.ldlt().solve(r);
    p(0) = ab(0);
    p(3) = ab(1);
  }
  auto evaluate = [&](const Vector& q, Matrix* jtj, Vector* jtr) {
    const Eigen::Vector2d nn = std::cos(q(7)) * n0 + std::sin(q(7)) * t0;
    const Eigen::Vector2d dn = -std::sin(q(7)) * n0 + std::cos(q(7)) * t0;
    double sse = 0;
    // The Jacobian's rows and the residuals, multiplied out at the end (one matrix product is far
    // cheaper than a rank update per pixel).
    Eigen::Matrix<double, Eigen::Dynamic, kParams> rows_j;
    Eigen::VectorXd rows_r;
    if (jtj) {
      rows_j.resize(n, kParams);
      rows_r.resize(n);
    }
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d& x = xs[static_cast<std::size_t>(i)];
      const double along = t0.dot(x) / half_length, across = n0.dot(x) / half_width;
      const double dark = q(0) + q(1) * along + q(2) * across;
      const double bright = q(3) + q(4) * along + q(5) * across;
      const double u = (nn.dot(x) - q(6)) / q(8);
      const double cdf = NormalCdf(u), pdf = NormalPdf(u);
      const double r = dark + (bright - dark) * cdf - vs[static_cast<std::size_t>(i)];
      sse += r * r;
      if (jtj) {
        const double k = (bright - dark) * pdf / q(8);
        rows_j.row(i) << 1 - cdf, (1 - cdf) * along, (1 - cdf) * across, cdf, cdf * along, cdf * across, -k,
            k * dn.dot(x), -k * u;
        rows_r(i) = r;
      }
    }
    if (jtj) {
      jtj->noalias() = rows_j.transpose().lazyProduct(rows_j);  // small: no blocking
      *jtr = rows_j.transpose() * rows_r;
    }
    return sse;
  };
  Matrix jtj;
  Vector jtr;
  double sse = evaluate(p, &jtj, &jtr);
  double lambda = 1e-3;
  for (int iteration = 0; iteration < iterations; ++iteration) {
    bool improved = false;
    for (int attempt = 0; attempt < 8 && !improved; ++attempt) {
      Matrix damped = jtj;
      for (int d = 0; d < kParams; ++d) damped(d, d) += lambda * std::max(jtj(d, d), 1e-9);
      if (!free_turn) {  // the predicted direction held: the offset alone is found first
        damped.row(7).setZero();
        damped.col(7).setZero();
        damped(7, 7) = 1;
      }
      Vector step = damped.ldlt().solve(jtr);
      if (!free_turn) step(7) = 0;
      Vector next = p - step;
      next(8) = std::clamp(next(8), 0.3, 4.0);
      // The band is placed about the start: a line that leaves it fits something else.
      next(6) = std::clamp(next(6), start_offset - 2, start_offset + 2);
      next(7) = std::clamp(next(7), -0.15, 0.15);
      const double next_sse = evaluate(next, nullptr, nullptr);
      if (std::isfinite(next_sse) && next_sse < sse) {
        improved = true;
        // Converged: the cost no longer falls, or (when asked) the line and blur move by less
        // than the tolerance.
        const bool converged = sse - next_sse < 1e-10 * sse ||
                               (std::abs(step(6)) < offset_tolerance_px && std::abs(step(8)) < offset_tolerance_px);
        p = next;
        sse = evaluate(p, &jtj, &jtr);
        lambda = std::max(1e-7, lambda / 10);
        if (converged) iteration = iterations;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
  }
  const Eigen::Vector2d nn = std::cos(p(7)) * n0 + std::sin(p(7)) * t0;
  fit.normal = nn;
  fit.a = p(0);
  fit.b = p(3) - p(0);
  fit.s = p(8);
  fit.turn_rad = p(7);
  fit.centre = centre + nn * p(6);
  fit.c = nn.dot(centre) + p(6);
  fit.pixels = n;
  fit.rms = std::sqrt(sse / n);
  // The residuals include the faces' grain, correlated over a few pixels: the variances from the
  // normal equations are scaled up by that (kCorrelation pixels per independent sample).
  constexpr double kCorrelation = 4;
  const Matrix covariance =
      sse / std::max(1, n - kParams) * kCorrelation * jtj.ldlt().solve(Matrix::Identity());
  fit.offset_var = covariance(6, 6);
  fit.slope_var = covariance(7, 7);
  fit.ok = std::isfinite(fit.c) && std::isfinite(fit.offset_var) && fit.offset_var >= 0;
  return fit;
}

// The offset (from the predicted line) of the strongest step within +-reach, 0.25 px steps: a
// linear fit of the two brightnesses with a 1 px blur at each offset.
double CoarseOffset(const IdealPatch& patch, const Eigen::Vector2d& corner, const PredictedEdge& edge,
                    double reach, double half_width) {
  const Eigen::Vector2d t0 = edge.direction, n0(-t0.y(), t0.x());
  std::vector<std::pair<double, double>> samples;  // across, value
  for (int y = 0; y < patch.roi.height; ++y) {
    for (int x = 0; x < patch.roi.width; ++x) {
      const Eigen::Vector2d q = patch.ideal[static_cast<std::size_t>(y * patch.roi.width + x)] - corner;
      const double along = t0.dot(q), across = n0.dot(q);
      if (along < edge.r_min || along > edge.r_max || std::abs(across) > reach + half_width) continue;
      samples.emplace_back(across, patch.values.at<float>(y, x));
    }
  }
  double best = 0, best_step = -1;
  for (double offset = -reach; offset <= reach + 1e-9; offset += 0.25) {
    Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
    Eigen::Vector2d r = Eigen::Vector2d::Zero();
    for (const auto& [across, value] : samples) {
      if (std::abs(across - offset) > half_width) continue;
      const Eigen::Vector2d f(1, NormalCdf(across - offset));
      m += f * f.transpose();
      r += f * value;
    }
    if (std::abs(m.determinant()) < 1e-6) continue;
    // Prefer the predicted position among equal steps.
    const double step = std::abs(m.ldlt().solve(r)(1)) * (1 - 0.02 * std::abs(offset));
    if (step > best_step) {
      best_step = step;
      best = offset;
    }
  }
  return best;
}

// The ideal pixel of a point in the world (no distortion), nullopt behind the camera.
std::optional<Eigen::Vector2d> IdealProjection(const Camera& camera, const Eigen::Vector3d& p_in_world) {
  const Eigen::Vector3d p = camera.camera_T_world() * p_in_world;
  if (p.z() < 1e-6) return std::nullopt;
  const Intrinsics& k = camera.intrinsics();
  return Eigen::Vector2d(k.fx * p.x() / p.z() + k.cx, k.fy * p.y() / p.z() + k.cy);
}

}  // namespace

SnapResult SnapToModelCorner(const cv::Mat& gray, const Camera& camera, const PointCorrespondence& point,
                             const SnapOptions& options) {
  TEACHSIM_CHECK(gray.type() == CV_8UC1);
  SnapResult result;
  result.pixel = point.pixel;
  auto predicted = IdealProjection(camera, point.p_in_world);
  if (!predicted || !point.pixel.allFinite()) {
    result.reason = "the point does not project into the image";
    return result;
  }
  // The candidate edges: the given ones, or the six world-axis directions.
  std::vector<Eigen::Vector3d> edges_3d = point.edges_in_world;
  if (edges_3d.empty()) {
    for (int axis = 0; axis < 3; ++axis) {
      for (const double sign : {1.0, -1.0}) {
        Eigen::Vector3d d = Eigen::Vector3d::Zero();
        d(axis) = sign;
        edges_3d.push_back(d);
      }
    }
  }
  std::vector<PredictedEdge> candidates;
  for (const Eigen::Vector3d& e : edges_3d) {
    const double length_m = e.norm();
    if (!(length_m > 0)) continue;
    // The image direction from a short step along the edge (the projection of a straight edge is a
    // straight line in the ideal image), its length from the far end.
    auto near = IdealProjection(camera, point.p_in_world + e * std::min(1.0, 1e-3 / length_m));
    if (!near || (*near - *predicted).norm() < 1e-9) continue;
    PredictedEdge edge;
    edge.direction = (*near - *predicted).normalized();
    if (point.edges_in_world.empty()) {
      edge.length_px = 1e9;
    } else if (auto far = IdealProjection(camera, point.p_in_world + e)) {
      edge.length_px = edge.direction.dot(*far - *predicted);
    }
    candidates.push_back(edge);
  }
  const double hw = options.band_px, reach = options.max_offset_px;
  // The junction left out: beyond it the band (+-hw, plus the blur) is clear of the other edges.
  // Before the edges are known (first pass), candidates within ~20 degrees of each other are not
  // kept apart: one of such a pair is usually hidden (its faces turned away), and the fit along the
  // other finds the visible one, or turns too far and is dropped.
  auto set_range = [&](std::vector<PredictedEdge>& edges, bool found) {
    for (std::size_t i = 0; i < edges.size(); ++i) {
      double sine = 1;
      for (std::size_t j = 0; j < edges.size(); ++j) {
        if (j == i) continue;
        const double cosine = edges[i].direction.dot(edges[j].direction);
        const double sj = std::sqrt(std::max(0.0, 1 - cosine * cosine));
        if (cosine > 0 && (found || sj > 0.34)) sine = std::min(sine, sj);
      }
      edges[i].r_min = std::max(options.junction_px, (hw + 2.5) / std::max(sine, 0.1));
      edges[i].r_max = std::min(edges[i].r_min + options.edge_length_px, edges[i].length_px - 2.5);
    }
  };
  Eigen::Vector2d corner = *predicted;
  std::vector<PredictedEdge> edges = candidates;
  std::vector<StepFit> fits;
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
  for (int pass = 0; pass < 3; ++pass) {
    set_range(edges, pass > 0);
    double extent = 0;
    for (const PredictedEdge& e : edges) extent = std::max(extent, e.r_max);
    const int radius = static_cast<int>(std::ceil(std::min(extent, 60.0) + hw + reach + 3));
    const Eigen::Vector2d corner_pixel = camera.DistortPixel(corner);
    auto patch = MakeIdealPatch(gray, camera, corner_pixel, radius);
    if (!patch) {
      result.reason = "the point lies too close to the image border or beyond the lens model";
      return result;
    }
    std::vector<PredictedEdge> found;
    fits.clear();
    for (const PredictedEdge& e : edges) {
      if (e.r_max - e.r_min < 4) continue;
      const double start = pass == 0 ? CoarseOffset(*patch, corner, e, reach, hw) : 0.0;
      StepFit fit = FitStep(*patch, corner, e, start, hw, 30, /*free_turn=*/false);
      if (!fit.ok) continue;
      // Once more with the band centred on the fitted line.
      const double offset = fit.c - fit.normal.dot(corner);
      if (std::abs(offset) < reach + 1) {
        PredictedEdge turned = e;
        turned.direction = Eigen::Vector2d(fit.normal.y(), -fit.normal.x());
        if (turned.direction.dot(e.direction) < 0) turned.direction = -turned.direction;
        const Eigen::Vector2d n1(-turned.direction.y(), turned.direction.x());
        fit = FitStep(*patch, corner, turned, n1.dot(fit.normal) > 0 ? offset : -offset, hw, 30,
                      /*free_turn=*/true);
        if (!fit.ok) continue;
      }
      const Eigen::Vector2d n0(-e.direction.y(), e.direction.x());
      fit.turn_rad = std::acos(std::clamp(std::abs(n0.dot(fit.normal)), 0.0, 1.0));
      const double offset_now = std::abs(fit.c - fit.normal.dot(corner));
      if (std::abs(fit.b) < options.min_step || std::abs(fit.turn_rad) > options.max_turn_rad ||
          offset_now > reach || fit.s < 0.5 || fit.s > 2.0) {
        continue;
      }
      found.push_back(e);
      fits.push_back(fit);
    }
    if (fits.size() < 2) {
      result.reason = fits.empty() ? "no edge of the model found near the point"
                                   : "only one edge of the model found near the point";
      return result;
    }
    std::vector<EdgeLine> lines;
    for (const StepFit& f : fits) {
      EdgeLine l;
      l.normal = f.normal;
      l.c = f.c;
      l.centroid = f.centre;
      l.offset_var = f.offset_var;
      l.slope_var = f.slope_var;
      l.rms_px = f.rms;
      lines.push_back(l);
    }
    Eigen::Vector2d next;
    if (!IntersectLines(lines, next, covariance, corner)) {
      result.reason = "the edges found near the point are (nearly) parallel";
      return result;
    }
    corner = next;
    edges = found;  // the next pass leaves out the junction by the edges that are there
  }
  const Eigen::Vector2d snapped = camera.DistortPixel(corner);
  const double offset = (snapped - point.pixel).norm();
  if (!snapped.allFinite() || offset > options.max_offset_px) {
    result.reason = "the edges meet " + json::FormatNumber(offset) + " px from the click (more than " +
                    json::FormatNumber(options.max_offset_px) + ")";
    return result;
  }
  result.snapped = true;
  result.pixel = snapped;
  result.offset_px = offset;
  result.sigma_px = std::sqrt(std::max(0.0, covariance.trace() / 2));
  result.edges = static_cast<int>(fits.size());
  return result;
}

}  // namespace teachsim::vision

// ---------------------------------------------------------------------------------------------
// Model-based pose refinement: the pose fitted to stations along the model's edges.

namespace teachsim::vision {

Status EdgeFitOptions::Validate() const {
  auto in = [](double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; };
  if (!in(station_length_px, 3, 40) || !in(station_spacing_px, 1, 100) || !in(band_px, 1.5, 10) ||
      !in(max_offset_px, 0.25, 10)) {
    return Status::InvalidInput(
        "EdgeFitOptions: station_length_px must be in [3, 40], station_spacing_px in [1, 100], band_px in "
        "[1.5, 10] and max_offset_px in [0.25, 10] px, got " +
        json::FormatNumber(station_length_px) + ", " + json::FormatNumber(station_spacing_px) + ", " +
        json::FormatNumber(band_px) + ", " + json::FormatNumber(max_offset_px));
  }
  if (!in(min_step, 0, 1e3) || !in(clearance_px, 0, 50) || !in(relative_step, 0, 1)) {
    return Status::InvalidInput("EdgeFitOptions: min_step must be >= 0, clearance_px in [0, 50] px and "
                                "relative_step in [0, 1], got " +
                                json::FormatNumber(min_step) + ", " + json::FormatNumber(clearance_px) + ", " +
                                json::FormatNumber(relative_step));
  }
  if (!in(edge_bias_px, 0, 100) || !in(edge_bias_per_spread, 0, 100)) {
    return Status::InvalidInput("EdgeFitOptions: edge_bias_px must be in [0, 100] px and edge_bias_per_spread "
                                "in [0, 100], got " +
                                json::FormatNumber(edge_bias_px) + ", " + json::FormatNumber(edge_bias_per_spread));
  }
  if (!in(grain_correlation_px, 0, 1000)) {
    return Status::InvalidInput("EdgeFitOptions: grain_correlation_px must be in [0, 1000] px, got " +
                                json::FormatNumber(grain_correlation_px));
  }
  if (min_stations < 1 || rounds < 1 || rounds > 10 || !in(tukey_c, 1, 100)) {
    return Status::InvalidInput("EdgeFitOptions: min_stations must be >= 1, rounds in [1, 10] and tukey_c "
                                "in [1, 100], got " +
                                std::to_string(min_stations) + ", " + std::to_string(rounds) + ", " +
                                json::FormatNumber(tukey_c));
  }
  return Status::Ok();
}

namespace {

Eigen::Vector2d IdealToPixel(const Camera& camera, const Eigen::Vector2d& ideal) {
  const Intrinsics& k = camera.intrinsics();
  return camera.NormalizedToPixel({(ideal.x() - k.cx) / k.fx, (ideal.y() - k.cy) / k.fy});
}

std::string DirectionLabel(const Eigen::Vector3d& e) {
  const double length = e.norm();
  for (int axis = 0; axis < 3; ++axis) {
    if (std::abs(std::abs(e(axis)) - length) < 1e-9 * (1 + length)) {
      return std::string(e(axis) > 0 ? "+" : "-") + "xyz"[axis] + " " +
             json::FormatNumber(std::round(length * 1e4) / 10) + " mm";
    }
  }
  return "(" + json::FormatNumber(e.x()) + ", " + json::FormatNumber(e.y()) + ", " + json::FormatNumber(e.z()) +
         ") m";
}

// Distance from p to the segment a-b (2-D).
double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double t = ab.squaredNorm() > 0 ? std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
  return (a + t * ab - p).norm();
}

geometry::Pose3 Moved(const geometry::Pose3& base, const Eigen::Matrix<double, 6, 1>& d) {
  const Eigen::Vector3d w = d.tail<3>();
  const double angle = w.norm();
  const Eigen::Quaterniond turn(
      Eigen::AngleAxisd(angle, angle > 0 ? Eigen::Vector3d(w / angle) : Eigen::Vector3d::UnitX()));
  return geometry::Pose3((base.rotation * turn).normalized(), base.translation + d.head<3>());
}

}  // namespace

EdgeStation FitEdgeStation(const cv::Mat& gray, const Camera& camera, const Eigen::Vector2d& ideal_point,
                           const Eigen::Vector2d& ideal_direction, const EdgeFitOptions& options) {
  TEACHSIM_CHECK(gray.type() == CV_8UC1);
  EdgeStation station;
  const Eigen::Vector2d t0 = ideal_direction.normalized();
  station.normal = Eigen::Vector2d(-t0.y(), t0.x());
  station.ideal = ideal_point;
  const Eigen::Vector2d pixel = IdealToPixel(camera, ideal_point);
  // Beyond the lens polynomial's fold an ideal point maps back into the image: check the round trip.
  auto back = camera.UndistortPixel(pixel);
  if (!pixel.allFinite() || !back || (*back - ideal_point).norm() > 0.01) {
    station.reason = "beyond the lens model";
    return station;
  }
  const double half = 0.5 * options.station_length_px, reach = options.max_offset_px;
  const int radius =
      static_cast<int>(std::ceil(std::hypot(half, options.band_px + reach) * 1.2 + 2));  // 1.2: the lens's scale
  if (pixel.x() - radius < 0 || pixel.y() - radius < 0 || pixel.x() + radius > gray.cols - 1 ||
      pixel.y() + radius > gray.rows - 1) {
    station.reason = "too near the image's border";
    return station;
  }
  auto patch = MakeIdealPatch(gray, camera, pixel, radius);
  if (!patch) {
    station.reason = "beyond the lens model";
    return station;
  }
  PredictedEdge edge;
  edge.direction = t0;
  edge.r_min = -half;
  edge.r_max = half;
  const double start = CoarseOffset(*patch, ideal_point, edge, reach, options.band_px);
  const StepFit fit = FitStep(*patch, ideal_point, edge, start, options.band_px, 30, /*free_turn=*/false,
                                /*offset_tolerance_px=*/1e-3);
  if (!fit.ok) {
    station.reason = "no step could be fitted";
    return station;
  }
  // The direction is held, so the fit's normal is the predicted one.
  station.offset_px = fit.c - station.normal.dot(ideal_point);
  station.ideal = ideal_point + station.normal * station.offset_px;
  station.sigma_px = std::sqrt(fit.offset_var);
  station.step = fit.b;
  station.blur_px = fit.s;
  if (std::abs(fit.b) < options.min_step) {
    station.reason = "step " + json::FormatNumber(std::abs(fit.b)) + " gray levels, under " +
                     json::FormatNumber(options.min_step);
  } else if (fit.s < 0.5 || fit.s > 2.0) {
    station.reason = "blur " + json::FormatNumber(fit.s) + " px outside 0.5-2 px";
  } else if (std::abs(station.offset_px) > reach) {
    station.reason = "step " + json::FormatNumber(station.offset_px) + " px from the prediction";
  } else {
    station.ok = true;
  }
  return station;
}

std::vector<ModelEdge> ModelEdgesOf(const std::vector<PointCorrespondence>& points) {
  std::vector<ModelEdge> edges;
  // b lies on segment e (within 1e-6 m of it).
  auto on = [](const ModelEdge& e, const Eigen::Vector3d& p) {
    const Eigen::Vector3d ab = e.to_in_world - e.from_in_world;
    const double t = std::clamp((p - e.from_in_world).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
    return (e.from_in_world + t * ab - p).norm() < 1e-6;
  };
  for (const PointCorrespondence& p : points) {
    for (const Eigen::Vector3d& e : p.edges_in_world) {
      if (!(e.norm() > 1e-6)) continue;
      ModelEdge edge{p.name + " along " + DirectionLabel(e), p.p_in_world, p.p_in_world + e};
      bool duplicate = false;
      for (ModelEdge& existing : edges) {
        if (on(existing, edge.from_in_world) && on(existing, edge.to_in_world)) {
          duplicate = true;  // the same segment, or a part of one already there
          break;
        }
        if (on(edge, existing.from_in_world) && on(edge, existing.to_in_world)) {
          existing = edge;  // a longer one
          duplicate = true;
          break;
        }
      }
      if (!duplicate) edges.push_back(std::move(edge));
    }
  }
  return edges;
}

Result<EdgePoseSolution> SolvePoseToEdges(const Camera& camera, const std::vector<ModelEdge>& edges,
                                          const std::vector<EdgeObservation>& observations,
                                          const std::vector<PointCorrespondence>& points,
                                          const EdgeFitOptions& options, double click_sigma_px) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  if (!(click_sigma_px > 0)) return Status::InvalidInput("edge fit: click sigma must be > 0 px");
  for (const EdgeObservation& o : observations) {
    if (o.edge < 0 || o.edge >= static_cast<int>(edges.size()) || !(o.sigma_px > 0) || !o.ideal.allFinite()) {
      return Status::InvalidInput("edge fit: an observation names edge " + std::to_string(o.edge) + " of " +
                                  std::to_string(edges.size()) + " or has sigma " +
                                  json::FormatNumber(o.sigma_px) + " px (expected > 0)");
    }
  }
  const std::size_t n_obs = observations.size();
  const std::size_t n_points = options.use_points ? points.size() : 0;
  const Eigen::Index measured = static_cast<Eigen::Index>(n_obs + 2 * n_points);
  if (measured < 6) {
    return Status::InvalidInput("edge fit: " + std::to_string(measured) + " residuals, need >= 6");
  }
  // With edge_bias_px, each edge gets an offset of its own (px, along its normal) with that prior
  // sigma: a stripe of grain beside an edge moves all its stations alike, so an edge's offset is
  // worth no more than that however many stations it has, while its direction still counts in full.
  std::vector<double> bias_sigma(edges.size());
  bool biased = false;
  for (std::size_t e = 0; e < edges.size(); ++e) {
    bias_sigma[e] = edges[e].offset_sigma_px > 0 ? edges[e].offset_sigma_px : options.edge_bias_px;
    biased = biased || bias_sigma[e] > 0;
  }
  // An edge without a prior sigma while others have one: its offset held at 0.
  for (double& b : bias_sigma) b = b > 0 ? b : 1e-9;
  const Eigen::Index n_bias = biased ? static_cast<Eigen::Index>(edges.size()) : 0;
  const Eigen::Index rows = measured + n_bias, cols = 6 + n_bias;
  const Eigen::Matrix3d k_inv_t = camera.K().inverse().transpose();
  // Normalized residuals (over each sigma) at a pose and edge offsets; false when a point falls
  // behind the camera.
  auto residuals = [&](const geometry::Pose3& world_T_camera, const Eigen::VectorXd& bias, Eigen::VectorXd& r) {
    r.resize(rows);
    const geometry::Pose3 camera_T_world = world_T_camera.Inverse();
    std::vector<Eigen::Vector3d> lines(edges.size());
    for (std::size_t e = 0; e < edges.size(); ++e) {
      // The plane through the camera centre and the edge, as a line in homogeneous pixels.
      const Eigen::Vector3d a = camera_T_world * edges[e].from_in_world, b = camera_T_world * edges[e].to_in_world;
      Eigen::Vector3d l = k_inv_t * a.cross(b);
      const double norm = std::hypot(l.x(), l.y());
      if (!(norm > 0)) return false;
      lines[e] = l / norm;
    }
    for (std::size_t i = 0; i < n_obs; ++i) {
      const EdgeObservation& o = observations[i];
      const double offset = biased ? bias(o.edge) : 0.0;
      r(static_cast<Eigen::Index>(i)) =
          (lines[static_cast<std::size_t>(o.edge)].dot(Eigen::Vector3d(o.ideal.x(), o.ideal.y(), 1)) - offset) /
          o.sigma_px;
    }
    if (n_points > 0) {
      const Camera posed = camera.WithPose(world_T_camera);
      for (std::size_t i = 0; i < n_points; ++i) {
        auto projected = posed.Project(points[i].p_in_world);
        if (!projected) return false;
        const double sigma = points[i].sigma_px > 0 ? points[i].sigma_px : click_sigma_px;
        r.segment<2>(static_cast<Eigen::Index>(n_obs + 2 * i)) = (*projected - points[i].pixel) / sigma;
      }
    }
    for (Eigen::Index e = 0; e < n_bias; ++e) r(measured + e) = bias(e) / bias_sigma[static_cast<std::size_t>(e)];
    return r.allFinite();
  };
  auto jacobian = [&](const geometry::Pose3& pose, const Eigen::VectorXd& bias, Eigen::MatrixXd& j) {
    j.setZero(rows, cols);
    Eigen::VectorXd plus, minus;
    for (int c = 0; c < 6; ++c) {
      const double h = 1e-6;
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d(c) = h;
      if (!residuals(Moved(pose, d), bias, plus) || !residuals(Moved(pose, -d), bias, minus)) return false;
      j.col(c) = (plus - minus) / (2 * h);
    }
    for (std::size_t i = 0; biased && i < n_obs; ++i) {
      j(static_cast<Eigen::Index>(i), 6 + observations[i].edge) = -1 / observations[i].sigma_px;
    }
    for (Eigen::Index e = 0; e < n_bias; ++e) j(measured + e, 6 + e) = 1 / bias_sigma[static_cast<std::size_t>(e)];
    return true;
  };
  auto tukey = [&](double u, double scale) {
    const double x = u / (options.tukey_c * scale);
    return std::abs(x) >= 1 ? 0.0 : (1 - x * x) * (1 - x * x);
  };
  auto robust_scale = [&](const Eigen::VectorXd& r) {
    std::vector<double> a;
    for (std::size_t i = 0; i < n_obs; ++i) a.push_back(std::abs(r(static_cast<Eigen::Index>(i))));
    if (a.empty()) {
      for (Eigen::Index i = 0; i < measured; ++i) a.push_back(std::abs(r(i)));
    }
    std::nth_element(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(a.size() / 2), a.end());
    return std::max(0.05, 1.4826 * a[a.size() / 2]);
  };

  geometry::Pose3 pose = camera.world_T_camera();
  Eigen::VectorXd bias = Eigen::VectorXd::Zero(n_bias);
  Eigen::VectorXd r;
  if (!residuals(pose, bias, r)) return Status::Failed("edge fit: the model lies behind the starting camera");
  Eigen::VectorXd w(rows);
  double scale = robust_scale(r);
  Eigen::MatrixXd j;
  for (int outer = 0; outer < 20; ++outer) {
    // Tukey's weights from the current residuals (a point's two coordinates share one weight; the
    // offsets' priors are not robust).
    scale = robust_scale(r);
    for (Eigen::Index i = 0; i < rows; ++i) w(i) = i < measured ? tukey(r(i), scale) : 1.0;
    for (std::size_t i = 0; i < n_points; ++i) {
      const Eigen::Index at = static_cast<Eigen::Index>(n_obs + 2 * i);
      w(at) = w(at + 1) = tukey(r.segment<2>(at).norm(), scale);
    }
    auto cost_of = [&](const Eigen::VectorXd& x) { return (w.array() * x.array().square()).sum(); };
    double cost = cost_of(r);
    double lambda = 1e-4;
    double moved_total = 0;
    for (int iteration = 0; iteration < 30; ++iteration) {
      if (!jacobian(pose, bias, j)) return Status::Failed("edge fit: the model falls behind the camera");
      const Eigen::MatrixXd a = j.transpose() * w.asDiagonal() * j;
      const Eigen::VectorXd g = j.transpose() * (w.array() * r.array()).matrix();
      bool improved = false, converged = false;
      for (int attempt = 0; attempt < 10 && !improved; ++attempt) {
        Eigen::MatrixXd damped = a;
        damped.diagonal() += lambda * a.diagonal().cwiseMax(1e-12);
        const Eigen::VectorXd delta = -damped.ldlt().solve(g);
        if (!delta.allFinite()) break;
        const geometry::Pose3 next = Moved(pose, delta.head<6>());
        const Eigen::VectorXd next_bias = bias + delta.tail(n_bias);
        Eigen::VectorXd next_r;
        if (!residuals(next, next_bias, next_r)) {
          lambda *= 10;
          continue;
        }
        const double next_cost = cost_of(next_r);
        if (next_cost <= cost) {
          improved = true;
          // Converged: the cost falls by a negligible share, or the step is far below a micrometre.
          converged = cost - next_cost <= 1e-10 * cost || delta.norm() < 1e-10;
          pose = next;
          bias = next_bias;
          r = next_r;
          cost = next_cost;
          moved_total += delta.norm();
          lambda = std::max(1e-9, lambda / 10);
        } else {
          lambda *= 10;
        }
      }
      if (!improved || converged) break;
    }
    if (outer > 0 && moved_total < 1e-9) break;
  }
  if (!jacobian(pose, bias, j)) return Status::Failed("edge fit: the model falls behind the camera");
  const Eigen::MatrixXd information = j.transpose() * w.asDiagonal() * j;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(information);
  if (!(eigen.eigenvalues()(0) > 1e-12 * eigen.eigenvalues()(cols - 1))) {
    return Status::Failed("edge fit: the edges and points found do not determine the camera's pose");
  }
  EdgePoseSolution solution;
  solution.world_T_camera = pose;
  solution.scale = scale;
  const Eigen::MatrixXd covariance =
      scale * scale * information.ldlt().solve(Eigen::MatrixXd::Identity(cols, cols));
  solution.position_covariance_m2 = covariance.topLeftCorner<3, 3>();
  solution.edge_offsets_px.assign(edges.size(), 0.0);
  for (Eigen::Index e = 0; e < n_bias; ++e) solution.edge_offsets_px[static_cast<std::size_t>(e)] = bias(e);
  for (std::size_t i = 0; i < n_obs; ++i) {
    // The distance to the projected edge itself (its offset not taken off).
    const double offset = biased ? bias(observations[i].edge) : 0.0;
    solution.residuals_px.push_back(r(static_cast<Eigen::Index>(i)) * observations[i].sigma_px + offset);
    solution.weights.push_back(w(static_cast<Eigen::Index>(i)));
  }
  const Camera posed = camera.WithPose(pose);
  for (const PointCorrespondence& p : points) {
    auto projected = posed.Project(p.p_in_world);
    solution.point_residuals_px.push_back(projected ? (*projected - p.pixel).norm() : NAN);
  }
  return solution;
}

Result<EdgePoseResult> FitPoseToEdges(const cv::Mat& gray, const Camera& camera,
                                      const std::vector<PointCorrespondence>& points,
                                      const EdgeFitOptions& options, double click_sigma_px,
                                      const std::function<void(const std::string&)>& progress) {
  TEACHSIM_CHECK(gray.type() == CV_8UC1);
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  const std::vector<ModelEdge> edges = ModelEdgesOf(points);
  if (edges.empty()) {
    return Status::InvalidInput("edge fit: no point has edges (\"edges\" in the points file)");
  }
  Camera current = camera;
  EdgePoseResult result;
  EdgePoseSolution solution;
  std::vector<EdgeObservation> observations;
  const double half = 0.5 * options.station_length_px;
  // Stations clear of other edges: the station's pixels (a rectangle half x band about its centre)
  // and the blur.
  const double clear_of_others = std::hypot(half, options.band_px) + options.clearance_px + 1;
  for (int round = 0; round < options.rounds; ++round) {
    EdgeFitOptions o = options;
    if (round > 0) o.max_offset_px = std::max(0.5, options.max_offset_px / 2);
    const geometry::Pose3 camera_T_world = current.world_T_camera().Inverse();
    std::vector<std::optional<std::pair<Eigen::Vector2d, Eigen::Vector2d>>> projected(edges.size());
    for (std::size_t e = 0; e < edges.size(); ++e) {
      auto a = IdealProjection(current, edges[e].from_in_world), b = IdealProjection(current, edges[e].to_in_world);
      const double za = (camera_T_world * edges[e].from_in_world).z(), zb = (camera_T_world * edges[e].to_in_world).z();
      if (a && b && za > 0.05 && zb > 0.05 && (*b - *a).norm() > 1) projected[e] = std::make_pair(*a, *b);
    }
    observations.clear();
    result.edges.assign(edges.size(), EdgeReport{});
    for (std::size_t e = 0; e < edges.size(); ++e) {
      EdgeReport& report = result.edges[e];
      report.name = edges[e].name;
      if (!projected[e]) continue;
      const auto [a, b] = *projected[e];
      const double length = (b - a).norm();
      const Eigen::Vector2d t = (b - a) / length;
      const double margin = half + o.band_px + o.clearance_px;
      if (length - 2 * margin < 0) continue;
      const int count = static_cast<int>(std::floor((length - 2 * margin) / o.station_spacing_px)) + 1;
      const double first = 0.5 * (length - (count - 1) * o.station_spacing_px);
      std::vector<EdgeStation> stations;
      for (int s = 0; s < count; ++s) {
        const Eigen::Vector2d centre = a + t * (first + s * o.station_spacing_px);
        bool clear = true;
        for (std::size_t other = 0; other < edges.size() && clear; ++other) {
          if (other == e || !projected[other]) continue;
          clear = SegmentDistance(centre, projected[other]->first, projected[other]->second) > clear_of_others;
        }
        if (!clear) continue;
        EdgeStation station = FitEdgeStation(gray, current, centre, t, o);
        if (station.reason == "too near the image's border" || station.reason == "beyond the lens model") continue;
        ++report.stations;
        if (station.ok) stations.push_back(station);
      }
      if (stations.empty()) continue;
      // The edge's polarity and typical step: a station of the other polarity or a much weaker step
      // sees something else there (an occluder, a shadow's edge, a stripe of grain).
      std::vector<double> steps;
      for (const EdgeStation& s : stations) steps.push_back(s.step);
      std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
      const double median = steps[steps.size() / 2];
      std::vector<EdgeObservation> kept;
      for (const EdgeStation& s : stations) {
        if (s.step * median <= 0 || std::abs(s.step) < o.relative_step * std::abs(median)) continue;
        kept.push_back({static_cast<int>(e), s.ideal, std::hypot(s.sigma_px, 0.02)});
      }
      if (static_cast<int>(kept.size()) < o.min_stations) continue;
      report.fitted = static_cast<int>(kept.size());
      observations.insert(observations.end(), kept.begin(), kept.end());
    }
    auto solved = SolvePoseToEdges(current, edges, observations, points, options, click_sigma_px);
    if (!solved.ok()) return solved.status();
    if (options.grain_correlation_px > 0) {
      // The stripes of grain beside an edge move its stations alike over a stretch of it: each edge's
      // own spread of residuals (robust) counts as an error shared by the stations within
      // grain_correlation_px, so a grainy edge weighs less than a clean one of the same length.
      std::vector<std::vector<double>> spread(edges.size());
      for (std::size_t i = 0; i < observations.size(); ++i) {
        spread[static_cast<std::size_t>(observations[i].edge)].push_back(std::abs(solved->residuals_px[i]));
      }
      std::vector<double> edge_sigma(edges.size(), 0.0);
      for (std::size_t e = 0; e < edges.size(); ++e) {
        std::vector<double>& a = spread[e];
        if (a.empty()) continue;
        std::nth_element(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(a.size() / 2), a.end());
        edge_sigma[e] = 1.4826 * a[a.size() / 2];
      }
      const double shared = std::max(1.0, options.grain_correlation_px / o.station_spacing_px);
      for (EdgeObservation& ob : observations) {
        const double g = edge_sigma[static_cast<std::size_t>(ob.edge)];
        ob.sigma_px = std::sqrt(ob.sigma_px * ob.sigma_px + g * g * shared);
      }
      std::vector<ModelEdge> with_offsets = edges;
      if (options.edge_bias_per_spread > 0) {
        // A grainy edge (its stations scattered about it) is likely shifted as a whole by the
        // grain as well: its offset gets a prior of that scale; a clean one (the table's) keeps
        // its offset nearly fixed.
        for (std::size_t e = 0; e < edges.size(); ++e) {
          with_offsets[e].offset_sigma_px = std::max(0.02, options.edge_bias_per_spread * edge_sigma[e]);
        }
      }
      solved = SolvePoseToEdges(current, with_offsets, observations, points, options, click_sigma_px);
      if (!solved.ok()) return solved.status();
    }
    solution = std::move(*solved);
    current = camera.WithPose(solution.world_T_camera);
    if (progress) {
      int used = 0, edges_used = 0;
      double sum2 = 0;
      for (std::size_t i = 0; i < observations.size(); ++i) {
        if (solution.weights[i] > 0.5) {
          ++used;
          sum2 += solution.residuals_px[i] * solution.residuals_px[i];
        }
      }
      for (const EdgeReport& report : result.edges) edges_used += report.fitted > 0 ? 1 : 0;
      const Eigen::Vector3d& p = solution.world_T_camera.translation;
      char line[256];
      std::snprintf(line, sizeof line,
                    "round %d: %d stations on %d edges (%d kept), RMS %.3f px; camera at (%.1f, %.1f, %.1f) mm",
                    round + 1, static_cast<int>(observations.size()), edges_used, used,
                    used > 0 ? std::sqrt(sum2 / used) : 0.0, p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
      progress(line);
    }
  }
  double sum2 = 0;
  std::vector<double> edge_sum2(edges.size(), 0.0);
  for (std::size_t i = 0; i < observations.size(); ++i) {
    if (!(solution.weights[i] > 0.5)) continue;
    const std::size_t e = static_cast<std::size_t>(observations[i].edge);
    ++result.edges[e].used;
    edge_sum2[e] += solution.residuals_px[i] * solution.residuals_px[i];
    sum2 += solution.residuals_px[i] * solution.residuals_px[i];
    ++result.stations_used;
  }
  for (std::size_t e = 0; e < edges.size(); ++e) {
    if (result.edges[e].used > 0) result.edges[e].rms_px = std::sqrt(edge_sum2[e] / result.edges[e].used);
    if (e < solution.edge_offsets_px.size()) result.edges[e].offset_px = solution.edge_offsets_px[e];
  }
  result.station_rms_px = result.stations_used > 0 ? std::sqrt(sum2 / result.stations_used) : 0;
  ExtrinsicsResult& x = result.extrinsics;
  x.world_T_camera = solution.world_T_camera;
  x.residuals_px = solution.point_residuals_px;
  x.dropped.assign(points.size(), false);
  double point_sum2 = 0;
  for (const double r : x.residuals_px) point_sum2 += r * r;
  x.rms_px = points.empty() ? 0 : std::sqrt(point_sum2 / static_cast<double>(points.size()));
  x.position_covariance_m2 = solution.position_covariance_m2;
  x.position_sigma_m = std::sqrt(std::max(0.0, solution.position_covariance_m2.trace()));
  return result;
}

}  // namespace teachsim::vision
