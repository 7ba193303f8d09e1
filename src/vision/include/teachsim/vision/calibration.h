// Camera calibration with OpenCV (paper §4.2): intrinsics off-line from chessboard views (the paper
// used Tsai's method; Zhang's, in cv::calibrateCamera, is today's equivalent), the camera's pose from
// work-site features of known position (PnP). Formats: docs/formats/camera.md.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/camera.h"

namespace teachsim::vision {

// A planar chessboard. cols x rows counts the INNER corners (where four squares meet), as OpenCV
// does: a board of 10 x 7 squares has 9 x 6 inner corners. The board frame has its origin at the
// first inner corner, x along a row of corners, y along a column, z into the board (away from a
// camera that sees its printed face), so corner (i, j) sits at (j * square, i * square, 0).
struct ChessboardSpec {
  int cols = 9;
  int rows = 6;
  double square_m = 0.025;
  [[nodiscard]] Status Validate() const;
  std::vector<Eigen::Vector3d> CornersInBoard() const;  // row by row, as OpenCV orders them
};

// "COLSxROWS" (e.g. "9x6") -> cols, rows; square_m is left at the caller's value.
[[nodiscard]] Result<ChessboardSpec> ParseBoardSize(const std::string& text, double square_m);

// The inner corners of the board in a monochrome 8-bit image, refined to sub-pixel accuracy
// (cv::cornerSubPix); nullopt when the whole board is not found.
std::optional<std::vector<Eigen::Vector2d>> FindChessboardCorners(const cv::Mat& gray,
                                                                  const ChessboardSpec& board);

struct IntrinsicsOptions {
  int min_views = 5;            // fewer usable views is an error
  bool fix_k3 = true;           // k3 is poorly observed at ordinary fields of view
  bool fix_tangential = false;  // p1 = p2 = 0
  [[nodiscard]] Status Validate() const;
};

// The corners found in one image.
struct CalibrationView {
  std::string name;  // the image file, for messages
  std::vector<Eigen::Vector2d> corners;
};

struct IntrinsicsResult {
  Intrinsics intrinsics;
  Distortion distortion;
  int width = 0, height = 0;
  double rms_px = 0;                            // reprojection RMS over all corners
  std::vector<double> view_rms_px;              // per view
  std::vector<geometry::Pose3> camera_T_board;  // per view
};

// Zhang's calibration (cv::calibrateCamera) from the corners of >= options.min_views views.
[[nodiscard]] Result<IntrinsicsResult> CalibrateIntrinsics(const std::vector<CalibrationView>& views,
                                                           const ChessboardSpec& board, int width, int height,
                                                           const IntrinsicsOptions& options);

struct SkippedImage {
  std::string path;
  std::string reason;  // "cannot read the image", "board not found", ...
};

struct FolderCalibration {
  IntrinsicsResult result;
  std::vector<std::string> used;
  std::vector<SkippedImage> skipped;
};

// Every image in `folder` (.png .jpg .jpeg .bmp .tif .tiff, sorted by name): unreadable images,
// images whose size differs from the first readable one and images without the whole board are
// named in `skipped`; too few views is an InvalidInput error that lists them.
[[nodiscard]] Result<FolderCalibration> CalibrateIntrinsicsFromFolder(const std::string& folder,
                                                                      const ChessboardSpec& board,
                                                                      const IntrinsicsOptions& options);

// A pixel position paired with the world point it shows (say, a frame corner the operator clicked).
struct PointCorrespondence {
  std::string name;
  Eigen::Vector2d pixel;       // px, as seen in the (distorted) image
  Eigen::Vector3d p_in_world;  // m
  // The pixel's standard error per coordinate, px; 0: ExtrinsicsOptions::click_sigma_px. Snapping
  // sets it from the edge fits, and the pose weights each point by it.
  double sigma_px = 0;
  // The straight 3-D edges that leave the point (world frame, m: direction times the length over
  // which the edge runs straight). Snapping looks for the image edges along their projections;
  // empty: the six world-axis directions (box-shaped features), of unknown length.
  std::vector<Eigen::Vector3d> edges_in_world = {};
};

// POINTS.json: {"points": [{"name": "...", "pixel": [u, v], "world": [x, y, z]}, ...]}.
[[nodiscard]] Result<std::vector<PointCorrespondence>> LoadPointCorrespondences(const std::string& path);
[[nodiscard]] Result<std::vector<PointCorrespondence>> ParsePointCorrespondences(const json::Json& document,
                                                                                 const std::string& name);
json::Json PointCorrespondencesToJson(const std::vector<PointCorrespondence>& points);

struct ExtrinsicsOptions {
  // The assumed click noise: independent Gaussian, per pixel coordinate, for points whose own
  // sigma_px is 0. With equal sigmas only the predicted uncertainty depends on it, not the solution.
  double click_sigma_px = 0.5;
  // A point whose residual exceeds this many of its sigmas (times sqrt 2, for the distance) and
  // 1 px is dropped and the pose solved again without it, worst first, while more than 5 points
  // remain; 0: none are dropped.
  double drop_beyond_sigmas = 0;
  [[nodiscard]] Status Validate() const;
};

struct ExtrinsicsResult {
  geometry::Pose3 world_T_camera;
  double rms_px = 0;
  std::vector<double> residuals_px;  // per point, in input order
  std::vector<bool> dropped;         // per point: left out of the solution (drop_beyond_sigmas)
  // The camera position's predicted covariance (world frame, m^2) for options.click_sigma_px, from
  // the Jacobian at the solution (PredictedPositionCovariance), and its RMS error sqrt(trace), m.
  Eigen::Matrix3d position_covariance_m2 = Eigen::Matrix3d::Zero();
  double position_sigma_m = 0;
};

// The camera's pose from >= 4 correspondences and the camera's intrinsics and distortion: SQPnP for
// a global start, then Levenberg-Marquardt refinement of the reprojection error, each point weighted
// by 1 / sigma^2 (the maximum-likelihood pose for Gaussian pixel noise; it attains the predicted
// covariance below).
[[nodiscard]] Result<ExtrinsicsResult> CalibrateExtrinsics(const Camera& camera,
                                                           const std::vector<PointCorrespondence>& points,
                                                           const ExtrinsicsOptions& options = {});

// Sub-pixel snapping of a clicked point to the image corner it marks. The work site's features of
// known position are 3-D corners (frame and table) where two or three straight edges meet; the
// operator's click is good to about half a pixel, which leaves the camera position at ~2.2 mm RMS
// (the Cramer-Rao bound for the recommended six points). The edges near the click, fitted to
// sub-pixel edge points over ~10 px each, locate their meeting point far better than the click.
enum class SnapMethod {
  kEdgeLines,     // sub-pixel edge points -> lines (undistorted) -> their least-squares intersection
  kCornerSubPix,  // OpenCV's cornerSubPix (gradients orthogonal to the corner), the baseline
};

struct SnapOptions {
  SnapMethod method = SnapMethod::kEdgeLines;
  double window_px = 12;       // edge points within this radius of the click (image-only snapping)
  double max_offset_px = 4;    // a snap farther from the click is refused (kept as clicked)
  double junction_px = 3;      // edge points this close to the corner are left out: blur rounds it
  double smooth_sigma_px = 1;  // Gaussian smoothing before the gradient (sensor noise, texture)
  // An edge point needs a gradient of at least max(min_gradient, relative_gradient x the strongest
  // in the window), gray levels per px: weak grain inside a face does not make lines.
  double min_gradient = 3;
  double relative_gradient = 0.1;
  // A line needs a step in brightness across it of at least this much, gray levels (sampled 2.5 px
  // either side): an edge between two faces, not a stripe of grain within one.
  double min_step = 8;
  int min_edge_points = 6;          // a line needs this many edge points, spread over >= 4 px
  double min_edge_angle_rad = 0.2;  // two lines closer in direction than this do not make a corner
  // Model guidance (SnapCorrespondences with kEdgeLines): a first pose from the clicks predicts
  // each point's edges; a blurred step is fitted in a band of +-band_px along each, edge_length_px
  // long, beyond the junction. A fitted edge must stay within max_turn_rad of its predicted direction.
  bool use_model = true;
  double band_px = 4;
  double edge_length_px = 14;
  double max_turn_rad = 0.08;
  [[nodiscard]] Status Validate() const;
};

struct SnapResult {
  bool snapped = false;         // false: `pixel` is the click, `reason` says why
  Eigen::Vector2d pixel{0, 0};  // the snapped corner (or the click), px in the distorted image
  double offset_px = 0;         // distance from the click
  // Confidence: the snapped position's standard error per coordinate, px, propagated from the line
  // fits' residuals (kEdgeLines). Model-guided (SnapToModelCorner), it is calibrated for the grain's
  // correlation: on rendered work-site images |error| / (sqrt 2 sigma) has median 0.76, p95 1.95.
  // Image only (SnapToCorner), read it as a relative figure. 0 for kCornerSubPix.
  double sigma_px = 0;
  int edges = 0;           // lines that met at the corner (kEdgeLines)
  double edge_rms_px = 0;  // RMS distance of the edge points from their lines (SnapToCorner only)
  std::string reason;
};

// Snaps `click` (px) to the corner of `gray` (CV_8UC1) near it. The camera's distortion straightens
// the edges before the lines are fitted (a straight world edge is straight there).
SnapResult SnapToCorner(const cv::Mat& gray, const Camera& camera, const Eigen::Vector2d& click,
                        const SnapOptions& options);

// Model-guided snapping of one point (kEdgeLines): `camera` carries a pose estimate (say, PnP from
// the clicks). The point's 3-D edges (PointCorrespondence::edges_in_world) project to predicted
// lines through its predicted pixel; along each, a blurred step (erf profile: two brightnesses, the
// line's offset and direction, the blur's width) is fitted to the pixels of a band beyond the
// junction (leaving out more of it the narrower the angle to the next edge), so neither the
// junction's rounding nor a gradient peak's bias moves the line. Steps too weak or turned away from
// the prediction are not edges (a grain stripe or a shadow line runs elsewhere); two or more edges
// are intersected. sigma_px comes from the fits. The click bounds the snap (max_offset_px).
SnapResult SnapToModelCorner(const cv::Mat& gray, const Camera& camera, const PointCorrespondence& point,
                             const SnapOptions& options);

// Every point's pixel snapped (points that cannot be snapped keep their click): one result per point.
// kEdgeLines with use_model and >= 4 points: a first pose from the clicks guides SnapToModelCorner,
// then the pose from the snapped points guides it once more; each point's sigma_px is set (the
// snap's, or click_sigma_px for a point kept as clicked). Otherwise each click is snapped alone
// (SnapToCorner).
std::vector<SnapResult> SnapCorrespondences(const cv::Mat& gray, const Camera& camera,
                                            std::vector<PointCorrespondence>& points,
                                            const SnapOptions& options, double click_sigma_px = 0.5);

// The Cramer-Rao bound on the camera position (world frame, m^2) when `points_in_world` are seen by
// `camera` (at its pose) with independent Gaussian pixel noise of sigma_px per coordinate:
// sigma^2 (J^T J)^-1 restricted to the position, J the Jacobian of the distorted projections with
// respect to the camera's position and orientation. Lets one compare candidate point sets without
// images. Fails when a point does not project or the pose is not determined (too few points, or
// points in a degenerate configuration).
[[nodiscard]] Result<Eigen::Matrix3d> PredictedPositionCovariance(
    const Camera& camera, const std::vector<Eigen::Vector3d>& points_in_world, double sigma_px);

}  // namespace teachsim::vision
