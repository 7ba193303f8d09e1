// Camera calibration with OpenCV (paper §4.2): intrinsics off-line from chessboard views (the paper
// used Tsai's method; Zhang's, in cv::calibrateCamera, is today's equivalent), the camera's pose from
// work-site features of known position (PnP). Formats: docs/formats/camera.md.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <functional>
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

// ---------------------------------------------------------------------------------------------
// Model-based pose refinement (Lowe-style): the pose fitted to the image's edges directly. Every
// straight 3-D edge of the points (PointCorrespondence::edges_in_world, direction x length) is a
// model edge; along its projection a blurred step is fitted at many short stations, each giving a
// sub-pixel point on the edge, and the pose is the one whose projected edges pass closest to those
// points (robust weights), together with the (snapped) points themselves. The wood's growth rings
// run along the walls, so a ring beside an edge shifts all its stations alike: each edge may shift
// as a whole (an offset of its own, its prior scaled by its stations' spread) and then still fixes
// the pose by its direction (docs/formats/calibration.md, `--edge-fit`).

struct EdgeFitOptions {
  double station_length_px = 8;   // the pixels of one station: this long along the edge,
  double station_spacing_px = 8;  // one station every this many px along it,
  double band_px = 4;             // +-this across it
  // The step is looked for within +-this of the predicted line (the pose from the points is
  // good to about a pixel); the refit after the first pose fit looks within half of it.
  double max_offset_px = 2;
  double min_step = 8;  // gray levels: a weaker step is no edge
  // A station is kept this far (px, beyond its own half length and the band) from the edge's
  // ends and from the other model edges: junctions round off, and another edge's step is not this one.
  double clearance_px = 2.5;
  // Of an edge's stations, one whose step is under this share of the edge's median step, or of
  // the other polarity, sees something else (an occluder, a shadow).
  double relative_step = 0.5;
  int min_stations = 3;  // an edge with fewer stations is not used
  // The grain's stripes run along the frame's edges and move neighbouring stations alike: each
  // station's sigma gets its edge's (robust) residual spread, counted once per this many px of
  // edge. 0: the fits' own sigmas only.
  double grain_correlation_px = 24;
  // Each edge's offset is a free parameter with this prior sigma (px): a stripe of grain beside an
  // edge moves all its stations alike. 0: no such offsets.
  double edge_bias_px = 0;
  // With grain_correlation_px: after each round's first solve, each edge's offset prior is this
  // many times its stations' robust spread about it (>= 0.02 px). 0: edge_bias_px for all.
  double edge_bias_per_spread = 1.5;
  int rounds = 2;        // predict -> measure -> fit, this many times
  double tukey_c = 4;    // robust weights: Tukey's biweight at this many robust standard deviations
  // Weight of the points (their pixel and sigma_px, or the click sigma) beside the edges' stations.
  bool use_points = true;
  [[nodiscard]] Status Validate() const;
};

// One station's fit: a point on the edge (ideal = undistorted pixels) and what the fit says of it.
struct EdgeStation {
  bool ok = false;
  Eigen::Vector2d ideal{0, 0};   // the fitted edge's point nearest the station's centre
  Eigen::Vector2d normal{1, 0};  // the predicted (held) normal
  double offset_px = 0;          // from the predicted line along `normal`
  double sigma_px = 0;           // the offset's standard error (grain correlation included)
  double step = 0;               // brightness change across the edge along `normal`, gray levels
  double blur_px = 0;
  std::string reason;            // when !ok
};

// Fits a blurred step (erf profile, two faces whose brightness may vary linearly, the blur's width)
// to the pixels of `gray` within +-options.band_px of the line through `ideal_point` along unit
// `ideal_direction` (both in the ideal image of `camera`'s intrinsics and distortion), for
// station_length_px along it, the direction held. Not ok: too weak a step, the step beyond
// max_offset_px, an implausible blur, or too near the image's border.
EdgeStation FitEdgeStation(const cv::Mat& gray, const Camera& camera, const Eigen::Vector2d& ideal_point,
                           const Eigen::Vector2d& ideal_direction, const EdgeFitOptions& options);

// A straight model edge, world frame (m).
struct ModelEdge {
  std::string name;
  Eigen::Vector3d from_in_world{0, 0, 0}, to_in_world{0, 0, 0};
  // The prior sigma of the edge's offset in the image (px; EdgeFitOptions::edge_bias_px); 0: the
  // options' value.
  double offset_sigma_px = 0;
};

// The model edges of the points: each point's edges_in_world from its position, duplicates (the same
// segment from its other end, or a part of a longer one) merged.
std::vector<ModelEdge> ModelEdgesOf(const std::vector<PointCorrespondence>& points);

// A measured point on model edge `edge` (ideal pixels) with its standard error.
struct EdgeObservation {
  int edge = 0;
  Eigen::Vector2d ideal{0, 0};
  double sigma_px = 0.1;
};

struct EdgePoseSolution {
  geometry::Pose3 world_T_camera;
  std::vector<double> residuals_px;  // per observation: signed distance to its projected edge, ideal px
  std::vector<double> weights;       // per observation: the final robust weight (0: rejected), 0..1
  std::vector<double> point_residuals_px;  // per point (distorted px)
  Eigen::Matrix3d position_covariance_m2 = Eigen::Matrix3d::Zero();  // from the weighted Jacobian
  double scale = 1;  // the robust standard deviation of the normalized residuals
  std::vector<double> edge_offsets_px;  // per edge: its fitted offset (edge_bias_px > 0), else 0
};

// The pose minimizing the robust (Tukey, tukey_c x a robust scale) sum of squared normalized
// distances of the observations from their projected model edges plus, with use_points, the points'
// reprojection errors over their sigmas (0: click_sigma_px), by Gauss-Newton with damping from
// `camera`'s pose. Fails when the pose is not determined.
[[nodiscard]] Result<EdgePoseSolution> SolvePoseToEdges(const Camera& camera, const std::vector<ModelEdge>& edges,
                                                        const std::vector<EdgeObservation>& observations,
                                                        const std::vector<PointCorrespondence>& points,
                                                        const EdgeFitOptions& options, double click_sigma_px);

// Per model edge, what the fit used.
struct EdgeReport {
  std::string name;
  int stations = 0;  // along its visible length
  int fitted = 0;    // with an accepted step
  int used = 0;      // of those, kept by the robust weights (weight > 0.5)
  double rms_px = 0;  // of the used stations' distances to the projected edge at the final pose
  double offset_px = 0;  // the edge's fitted offset from its projection (edge_bias_*), px
};

struct EdgePoseResult {
  ExtrinsicsResult extrinsics;  // residuals_px: the points' at the final pose; covariance from all
  std::vector<EdgeReport> edges;
  int stations_used = 0;
  double station_rms_px = 0;  // over the used stations
};

// The whole model-based refinement on an image: from `camera`'s pose (say, PnP from the snapped
// points), `rounds` times: every model edge of `points` sampled at stations along its projection
// (inside the image, clear of ends and other edges), the steps fitted (FitEdgeStation), stations
// that disagree with their edge's polarity or strength left out, and the pose solved
// (SolvePoseToEdges). `progress`, when set, is told each round's stations and RMS.
[[nodiscard]] Result<EdgePoseResult> FitPoseToEdges(const cv::Mat& gray, const Camera& camera,
                                                    const std::vector<PointCorrespondence>& points,
                                                    const EdgeFitOptions& options, double click_sigma_px,
                                                    const std::function<void(const std::string&)>& progress = {});

// The Cramer-Rao bound on the camera position (world frame, m^2) when `points_in_world` are seen by
// `camera` (at its pose) with independent Gaussian pixel noise of sigma_px per coordinate:
// sigma^2 (J^T J)^-1 restricted to the position, J the Jacobian of the distorted projections with
// respect to the camera's position and orientation. Lets one compare candidate point sets without
// images. Fails when a point does not project or the pose is not determined (too few points, or
// points in a degenerate configuration).
[[nodiscard]] Result<Eigen::Matrix3d> PredictedPositionCovariance(
    const Camera& camera, const std::vector<Eigen::Vector3d>& points_in_world, double sigma_px);

}  // namespace teachsim::vision
