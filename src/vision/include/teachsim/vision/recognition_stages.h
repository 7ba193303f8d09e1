// The recognizer's stages, one function each, for tests and for the benchmark (recognizer.h is the
// API; this is how it works inside). Coordinates: "px" below means undistorted pixels (an ideal
// camera with the real intrinsics), unless a name says `distorted`.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <unordered_map>
#include <vector>

#include "teachsim/geometry/aabb.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/vision/camera.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::vision {

// ---- the box model: vertex i has coordinates (+-sx/2, +-sy/2, +-sz/2) with bit 0 -> x, 1 -> y, 2 -> z
// set meaning +; edge e joins vertices kBoxEdges[e]; face f is -x, +x, -y, +y, -z, +z.
inline constexpr std::array<std::array<int, 2>, 12> kBoxEdges = {{{0, 1}, {2, 3}, {4, 5}, {6, 7},  // along x
                                                                 {0, 2}, {1, 3}, {4, 6}, {5, 7},  // along y
                                                                 {0, 4}, {1, 5}, {2, 6}, {3, 7}}};  // along z
Eigen::Vector3d BoxVertex(const Eigen::Vector3d& size_m, int i);  // in the object frame, m
// The edges of the box not hidden by the box itself when seen from a camera centre given in the
// object frame (hidden-line removal for a convex body: an edge shows when a face beside it faces
// the camera). Bit e of the result is edge e.
uint16_t VisibleBoxEdges(const Eigen::Vector3d& size_m, const Eigen::Vector3d& camera_in_object);
// The ones among them on the outline (one adjacent face towards the camera, the other away).
uint16_t OutlineBoxEdges(const Eigen::Vector3d& size_m, const Eigen::Vector3d& camera_in_object);

// ---- item 1: the image's edges (kept for verification) and lines.
struct EdgeMap {
  // CV_8U, the Canny edge pixels (distorted image): kEdgeOnChain on chains long enough for a line
  // (5 px or more), kEdgeOffChain on shorter ones (which EdgePixelAcross passes over).
  cv::Mat edges;
  // CV_16S, the Sobel derivatives of `smoothed`: the gradient, its unit vector at an edge pixel and
  // its magnitude (GradientMagnitude), computed where asked rather than kept as float images
  // (6.1 MB fewer fresh pages per image at 640 x 480; a one-shot `teachsim recognize` faults in every page it
  // writes, about 10 us each on our 2-core VM).
  cv::Mat dx, dy;
  // CV_32F, the gradient magnitude of the image brought back to linear light (Camera::gamma), for
  // the sub-pixel positions of the editor's edge points (LinearMagnitude); empty for a linear
  // camera, whose own GradientMagnitude it is. A gamma-encoded camera blends an edge pixel's two
  // sides in linear light, so on its grey levels the peak sits towards the darker side (0.1-0.3 px
  // at gamma 2.2, with the lens blur).
  cv::Mat linear_magnitude;
  cv::Mat smoothed;   // CV_8U, the image after the Gaussian (contrast across predicted edges)
  cv::Mat near;       // CV_8U, one bit per pixel (bit x % 8 of byte x / 8 in row y), set where a Canny edge
                      // pixel lies within kEdgeNearPx in x and y (the edges dilated): a quick "no edge
                      // here" for EdgePixelAcross, small enough to stay in the cache; empty: not used
};
inline constexpr int kEdgeNearPx = 2;
inline constexpr uint8_t kEdgeOnChain = 255, kEdgeOffChain = 1;
// The gradient magnitude at pixel (x, y), inside the image: the same float as cv::magnitude on float
// copies of dx and dy (the squares of 16-bit Sobel values at most 1020 are exact).
inline float GradientMagnitude(const EdgeMap& edge_map, int x, int y) {
  const float gx = edge_map.dx.ptr<int16_t>(y)[x], gy = edge_map.dy.ptr<int16_t>(y)[x];
  return std::sqrt(gx * gx + gy * gy);
}
// The unit gradient at pixel (x, y), inside the image, where its magnitude is above 0.
inline std::optional<std::array<float, 2>> UnitGradient(const EdgeMap& edge_map, int x, int y) {
  const float m = GradientMagnitude(edge_map, x, y);
  if (!(m > 0)) return std::nullopt;
  return std::array<float, 2>{edge_map.dx.ptr<int16_t>(y)[x] / m, edge_map.dy.ptr<int16_t>(y)[x] / m};
}
// EdgeMap::linear_magnitude at pixel (x, y), inside the image; GradientMagnitude for a linear camera.
inline float LinearMagnitude(const EdgeMap& edge_map, int x, int y) {
  return edge_map.linear_magnitude.empty() ? GradientMagnitude(edge_map, x, y)
                                           : edge_map.linear_magnitude.ptr<float>(y)[x];
}
// EdgeMap::near of a CV_8U edge image: bit x % 8 of byte x / 8 in row y set where a nonzero pixel
// lies within kEdgeNearPx in x and y (cv::dilate with a square, packed), built on packed rows.
cv::Mat NearEdgeBits(const cv::Mat& edges);
// EdgeMap::near at pixel (x, y), inside the image.
inline bool NearEdge(const EdgeMap& edge_map, int x, int y) {
  return (edge_map.near.ptr<uint8_t>(y)[x >> 3] >> (x & 7) & 1) != 0;
}
// The nearest pixel to coordinate v, floor(v + 0.5), where it lies in [0, size), else -1: for
// v + 0.5 >= 0 truncation is the floor (cheaper than std::floor without SSE4.1); below 0 it is
// outside anyway.
inline int NearestPixel(double v, int size) {
  const double t = v + 0.5;
  return t >= 0 && t < size ? static_cast<int>(t) : -1;
}
// Whether the dilated edges (EdgeMap::near) show no edge pixel around the pixel nearest `pixel`
// (distorted image): then EdgePixelAcross finds none there up to kEdgeNearPx, whatever the unit
// normal. False where it cannot tell (no EdgeMap::near, or the nearest pixel outside the image).
inline bool NoEdgeNear(const EdgeMap& edge_map, const Eigen::Vector2d& pixel) {
  if (edge_map.near.data == nullptr) return false;
  const int x0 = NearestPixel(pixel.x(), edge_map.edges.cols),
            y0 = NearestPixel(pixel.y(), edge_map.edges.rows);
  return x0 >= 0 && y0 >= 0 && !NearEdge(edge_map, x0, y0);
}
// End 0 (a) or 1 (b) of an image line.
inline const Eigen::Vector2d& LineEnd(const ImageLine& line, int end) { return end == 0 ? line.a : line.b; }
// The z component of the cross product of two image vectors.
inline double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

// The nearest Canny edge pixel across a predicted edge through `pixel` (distorted image; 0, +1,
// -1, +2, -2, ... px along the unit `normal`, up to max_offset_px) whose gradient runs across the
// edge (within 25 deg): what edge support (2 px) and the editor's fit on edge points (3 px) look for.
struct EdgePixel {
  int x = 0, y = 0;
  float gx = 0, gy = 0;  // the unit gradient there
};
std::optional<EdgePixel> EdgePixelAcross(const EdgeMap& edge_map, const Eigen::Vector2d& pixel,
                                         const Eigen::Vector2d& normal, int max_offset_px);
// The sign of an edge pixel's gradient along `normal`: +1 or -1 (its polarity across the edge).
int EdgeSign(const EdgePixel& edge, const Eigen::Vector2d& normal);
// Whether a predicted edge through `pixel` (distorted image; `normal` its unit normal) has a Canny
// edge pixel within 2 px across it whose gradient runs across it (within 25 deg): edge support.
bool EdgeAcross(const EdgeMap& edge_map, const Eigen::Vector2d& pixel, const Eigen::Vector2d& normal);
// The same with the sign of that edge pixel's gradient along `normal`: +1 or -1, 0 where none is.
int SignedEdgeAcross(const EdgeMap& edge_map, const Eigen::Vector2d& pixel, const Eigen::Vector2d& normal);
struct LineDetection {
  EdgeMap edge_map;
  std::vector<ImageLine> lines;  // undistorted px
  int edge_points = 0;
};
LineDetection DetectLinesAndEdges(const cv::Mat& image_gray8, const Camera& camera,
                                  const RecognizerOptions& options);

// ---- item 2: perceptual groups.
enum class GroupKind : uint8_t { kChain3 = 0, kChain4 = 1, kFork3 = 2 };
inline constexpr int kGroupKinds = 3;
// RecognitionTrace::Fitted::group_kind of the hypotheses that come from no group: a support-plane
// hypothesis (SupportHypotheses) and another model at a candidate's place (AlternativeHypotheses).
inline constexpr int kSupportKind = kGroupKinds;
inline constexpr int kAlternativeKind = kGroupKinds + 1;
int GroupSegments(GroupKind kind);   // 3, 4, 3
int GroupDimension(GroupKind kind);  // length of the index vector: 4, 6, 4
// A group's geometry. Chains: points[0..n] along the chain (points[0] and points[n] are the free
// ends, the others junctions, segment i joins points[i] and points[i+1]). Forks: points[0] is the
// junction and points[1..3] the arms' far ends, counter-clockwise in the image (y down).
struct Group {
  GroupKind kind = GroupKind::kChain3;
  std::array<int, 4> segments{-1, -1, -1, -1};  // indices into the image lines (image groups)
  std::array<Eigen::Vector2d, 5> points{Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero(),
                                        Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};  // px
};
// The index vector: turn angles (rad) and logarithms of length ratios (weighted); invariant to 2D
// translation, rotation and scale, not to reflection.
std::vector<float> IndexVector(const Group& group);
// Junctions: the ends of two lines (first < second) meeting where the lines' intersection lies
// within the gap of both ends, the gap being junction_gap_px or a quarter of the shorter line,
// whichever is larger, at an angle of 15 deg or more. In the order of a loop over the pairs (first,
// then second ascending), then first_end, second_end. Only the lines with considered[i] != 0 (all
// when empty) and finite ends take part.
struct LineJunction {
  int first = 0, first_end = 0, second = 0, second_end = 0;  // lines and their ends (0: a, 1: b)
  Eigen::Vector2d point = Eigen::Vector2d::Zero();           // where the two lines meet, px
};
std::vector<LineJunction> FindJunctions(const std::vector<ImageLine>& lines, double junction_gap_px,
                                        const std::vector<char>& considered = {});
// Connected groups in the image: segments whose ends meet at a junction (line intersection within
// options.junction_gap_px of both ends, at an angle of 15 deg or more: FindJunctions). At most
// max_groups per kind.
std::vector<Group> FindGroups(const std::vector<ImageLine>& lines, const RecognizerOptions& options,
                              int max_groups_per_kind = 4000);

// ---- item 4: Lowe's least-squares fit of model edges to image lines.
struct LineMatch {
  int edge = 0;                    // box edge index
  Eigen::Vector2d a, b;            // the image segment's endpoints, undistorted px
  double weight = 1;               // of its residuals in the fit (an edge point: by its contrast)
};
struct FitResult {
  geometry::Pose3 camera_T_object;
  double rms_px = 0;                               // of the endpoint-to-line residuals
  Eigen::Matrix<double, 6, 6> covariance_camera;   // translation m, rotation rad, camera axes
  int iterations = 0;
  bool converged = false;
};
// Gauss-Newton (with Huber weights when huber_px > 0) on the perpendicular distances of the image
// segments' endpoints to the projected model edges, each match's two residuals weighed by its
// `weight` (1 but for the polish's edge points).
FitResult FitPoseToLines(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K,
                         const geometry::Pose3& camera_T_object_initial, const std::vector<LineMatch>& matches,
                         int max_iterations, double huber_px);
// The robust loss of the fit's residuals: Huber (linear pull beyond scale_px) or Tukey's biweight
// (no pull beyond scale_px: a line that far off is ignored); scale_px <= 0: least squares.
struct RobustLoss {
  enum class Kind : uint8_t { kHuber, kTukey };
  Kind kind = Kind::kHuber;
  double scale_px = 0;
};
// with_covariance false: covariance_camera is left zero (a fit whose pose may be dropped: the
// hypotheses' rounds; PoseCovariance gives it later for the pose kept, to the bit the same).
FitResult FitPoseToLines(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K,
                         const geometry::Pose3& camera_T_object_initial,
                         const std::vector<LineMatch>& matches, int max_iterations, const RobustLoss& loss,
                         bool with_covariance = true);
// A fit's covariance (FitResult::covariance_camera) at a pose: the inverse of the robustly weighted
// normal matrix there, scaled by the residual variance; zero without matches.
Eigen::Matrix<double, 6, 6> PoseCovariance(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K,
                                           const geometry::Pose3& camera_T_object,
                                           const std::vector<LineMatch>& matches, const RobustLoss& loss);
// The RMS of the endpoint-to-line residuals at a pose (a fit's rms_px), without fitting; 0 without matches.
double LineResidualRmsPx(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K,
                         const geometry::Pose3& camera_T_object, const std::vector<LineMatch>& matches);

// The same with the object kept on its support plane: 3 parameters (world x, y and a turn about the
// world's vertical through the object's centre); height and tilt stay as the start gave them. Fewer
// ways to drift onto a shadow or grain line than the 6-DOF fit. Covariance: of the full pose.
FitResult FitPoseOnPlane(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world,
                         const geometry::Pose3& camera_T_object_initial, const std::vector<LineMatch>& matches,
                         int max_iterations, double huber_px);
FitResult FitPoseOnPlane(const Eigen::Vector3d& size_m, const Eigen::Matrix3d& K,
                         const geometry::Pose3& camera_T_world,
                         const geometry::Pose3& camera_T_object_initial,
                         const std::vector<LineMatch>& matches, int max_iterations, const RobustLoss& loss,
                         bool with_covariance = true);

// Image lines matched to the predicted visible edges of a box at a pose (undistorted px): each
// line to the nearest edge within max_distance_px and max_angle_rad, overlapping it by half its length.
struct EdgeMatchSet {
  std::vector<LineMatch> matches;
  std::vector<int> segments;      // the image line of each match
  double matched_fraction = 0;    // of the visible predicted length
  double visible_length_px = 0;
};
EdgeMatchSet MatchEdges(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                        const std::vector<ImageLine>& lines, double max_distance_px, double max_angle_rad);
// The matches that lie on their predicted edge at a pose: per edge, the lines whose offset from it
// (mean endpoint distance) is within spread_px of the edge's closest line's. A shadow, grain line or
// neighbouring block's edge running beside the edge is left out; a split edge's pieces stay.
std::vector<LineMatch> OnEdgeMatches(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                                     const std::vector<LineMatch>& matches, double spread_px);
// The image line length a pose explains: the visible predicted edges' length covered by lines
// within max_distance_px and max_angle_rad (MatchEdges), px.
double ExplainedLengthPx(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                         const std::vector<ImageLine>& lines, double max_distance_px, double max_angle_rad);
// A hypothesis fitted (hypothesis_fit.cc): the final pose, whether a round found fewer than 3
// matched edges (or the pose went behind the camera), and the pose after each round (for traces).
struct HypothesisFit {
  FitResult fit;
  bool failed = false;
  std::vector<geometry::Pose3> rounds;
};
// A support-plane hypothesis: fitted on its plane (x, y, yaw) in three rounds matching within 3, 1.5
// and 1 times options.match_distance_px (each round on the lines on their edges, OnEdgeMatches; the
// last with Tukey's biweight), ending at the start or round that explains the most line length within
// 2 px (ExplainedLengthPx); then (options.support_refine_6dof) in 6 DOF, the free pose kept when it
// matches at least as much of the outline with no larger residual and explains no less. `tight`: all
// three rounds match within 1 match distance (the recognizer's second fit of a hypothesis whose
// loose fit drifted off its start, RecognizerOptions::support_tight_fit_shift_px).
HypothesisFit FitSupportHypothesis(const Model& model, const Eigen::Matrix3d& K,
                                   const geometry::Pose3& camera_T_world, const geometry::Pose3& initial,
                                   const std::vector<ImageLine>& lines, const RecognizerOptions& options,
                                   bool tight = false);
// Mean distance between the projections of a box's corresponding vertices at two poses, px.
double MeanVertexShiftPx(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& a,
                         const geometry::Pose3& b);
// An index hypothesis: first on its group's own correspondences (seed_matches), then three rounds on
// the predicted edges' matches within 3, 1.5 and 1 times options.match_distance_px (the later two on
// the lines on their edges, the last with Tukey's biweight), ending at the round that explains the
// most line length within 2 px.
HypothesisFit FitIndexHypothesis(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& initial,
                                 const std::vector<LineMatch>& seed_matches, const std::vector<ImageLine>& lines,
                                 const RecognizerOptions& options);
// The model editor's last step for a block it rested on the table: Lowe's fit again, on the image's
// own edge points instead of its lines. Along each visible predicted edge (every 2 px, away from
// the corners) the nearest Canny pixel within search_px across it whose gradient runs across it, at
// its sub-pixel position (undistorted); two rounds of the fit with Tukey's biweight (2 px) on their
// distances to the predicted edges, on the support plane (x, y, yaw: FitPoseOnPlane) when on_plane,
// else in 6 DOF (which drifts along the camera ray on the dev set: not used there). Lines pick up a
// grain line or shadow beside an edge, and a fragmented edge's pieces weigh by their count; edge
// points near the predicted outline do neither. With weigh_above > 0 (the editor's polish on the
// table: twice RecognizerOptions::canny_high), a point whose Sobel gradient magnitude m exceeds it
// weighs (m / weigh_above)^2, at most 4, the others 1: a point's sub-pixel position varies as the
// image noise over its gradient, so a crisp edge pulls more than a faint one (two faces lit alike,
// a face against a table of its own shade). Unbounded m^2 weights let a shadow's crisp border beside
// a thin plate's faint edge pull it 1.4 mm off (`teachsim bench demo`); these do not (seeds 7-41 of
// `teachsim bench recognize`: rotation p90 0.51 -> 0.45 deg over 6479 found blocks). Not polished
// (ok false) when fewer than 3 edges have 4 points or the fit moves the projected vertices by
// more than 2 px on average.
struct PolishResult {
  bool ok = false;
  FitResult fit;
  int points = 0;      // edge points of the last round
  double rms_px = 0;   // their RMS distance to the polished pose's predicted edges, within the 2 px of Tukey's scale
};
// Whether a point on the predicted outline (camera frame, m) is hidden from the camera by something
// else (the editor: by another recognition); such samples are left out of the polish, since the
// edges found there are the front object's (empty: none is hidden).
using HiddenTest = std::function<bool(const Eigen::Vector3d& point_in_camera)>;
PolishResult PolishPose(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                        const EdgeMap& edge_map, bool on_plane, double search_px = 3,
                        const HiddenTest& hidden = {}, double weigh_above = 0);
// An edge point's weight in PolishPose: 1, or (magnitude / weigh_above)^2 up to 4 when its gradient
// magnitude is above weigh_above (> 0).
double PolishPointWeight(double magnitude, double weigh_above);

// The world extent of a set of points (a recognition's box, a fixed part; at least one point), m.
geometry::Aabb ExtentOf(const std::vector<Eigen::Vector3d>& points);
// Whether `object` rests on `below`: their footprints overlap and its lowest point is within
// `z_tolerance_m` of the other's top.
bool RestsOn(const geometry::Aabb& object, const geometry::Aabb& below, double z_tolerance_m);
// Whether `object`, off the table, stands on the supports it rests on (RestsOn) among `supports`:
// it rests on at least one, and its centre (x, y) lies within `centre_slack_m` of the region where
// its footprint overlaps theirs (the overlaps bounded together: a block bridging two walls stands,
// one whose centre is beyond a wall's edge topples).
bool StandsOnSupports(const geometry::Aabb& object, const std::vector<geometry::Aabb>& supports,
                      double z_tolerance_m, double centre_slack_m);

// The share of a pose's visible predicted edges (by length, sampled every 2 px) that projects into
// the image, 0..1 (0 when a corner is behind the camera): of a block cut far by the image border,
// what is left says too little for the edge-point refit (RecognizerOptions::refit_min_in_image).
double VisibleOutlineInImage(const Model& model, const Camera& camera,
                             const geometry::Pose3& camera_T_object);

// A match set's visible length and matched share restricted to the part of the visible predicted
// edges inside the image (VisibleOutlineInImage; RecognizerOptions::matched_share_in_image): the
// image cannot show a block's edges past its border. Unchanged when the whole outline is inside or
// none of it is.
void MatchedWithinImage(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                        EdgeMatchSet& matched, double min_inside = 0);
// Verification's edge-point refit (RecognizerOptions::edge_point_refit): a fitted pose whose matched lines
// lie off its predicted edges (a grain line or a shadow beside an edge was matched) polished in 6 DOF on
// the image's edge points (PolishPose). The refitted pose when at least refit_min_in_image of its visible
// predicted outline projects into the image (VisibleOutlineInImage), it rests on the table (lowest point
// within table_snap_distance_m of table_top_z, a face within table_snap_max_tilt_deg of level) and its
// edge points' RMS is within refit_max_rms_px; nullopt otherwise (without polishing when the pose is not
// within twice those tolerances of resting on the table to begin with: the polish moves the outline by 2
// px at most).
std::optional<PolishResult> RefitOnEdgePoints(const Model& model, const Camera& camera,
                                              const geometry::Pose3& camera_T_object, const EdgeMap& edge_map,
                                              double table_top_z, const RecognizerOptions& options);

// ---- a second hypothesis source beside the index (paper §7.1: several groupings in parallel;
// §4.3: objects rest on the table): a block at rest stands on one of its faces on a horizontal
// support plane, so its pose has 3 DOF (x, y, yaw) per resting face, and one image corner (an L
// junction of two segments) whose corner lies on the bottom or top plane of the block gives it.
struct SupportPlane {
  double z_m = 0;                                          // world height of the plane, m
  Eigen::Vector2d min_xy = Eigen::Vector2d::Constant(-1);  // where on it a block may stand (world x, y), m
  Eigen::Vector2d max_xy = Eigen::Vector2d::Constant(1);
};
// Two segments whose ends meet (the lines' intersection within options.junction_gap_px, or a
// quarter of the shorter segment, of both ends) at more than 15 deg. The pieces of an edge split by
// a shadow or a crossing line (collinear within 1.5 px and 3 deg, at most 40 px apart) are joined
// first: an arm reaches the joined edge's far end, and its segment is the longest piece.
struct ImageCorner {
  Eigen::Vector2d point = Eigen::Vector2d::Zero();  // the lines' intersection, undistorted px
  std::array<Eigen::Vector2d, 2> arm_end{Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};  // far ends, px
  std::array<int, 2> segments{-1, -1};              // indices into the image lines
};
// Of the samples along an image line (undistorted px; every 3 px, a tenth of it left out at each
// end), the share where it is a thin line such as wood grain, not a block's edge: the darkest (or
// brightest) grey of the smoothed image within 2 px across the line, and the grey 3 px beyond that
// point on both sides, both at least min_grey brighter (or darker) than it and within min_grey of
// each other (no step between two surfaces). A block's face seen edge-on is such a thin strip too.
double LineRidgeShare(const ImageLine& line, const Camera& camera, const EdgeMap& edge_map, double min_grey);
// Whether LineRidgeShare(line, camera, edge_map, min_grey) >= share, the same answer, its samples
// looked at only until the rest cannot change it (a corner's arm is mostly not a thin line).
bool LineRidgeShareAtLeast(const ImageLine& line, const Camera& camera, const EdgeMap& edge_map,
                           double min_grey, double share);
std::vector<ImageCorner> FindCorners(const std::vector<ImageLine>& lines, const RecognizerOptions& options);
// The pieces of one straight edge (split where a shadow, a grain line or another block's edge
// crosses it) joined: lines collinear within 1.5 px and 3 deg whose ends are at most 40 px apart
// along it. representative[i]: the longest piece of line i's edge; extent[r] for a representative
// r: the joined edge (end to end, on r's line); other entries: the line itself.
struct JoinedLines {
  std::vector<int> representative;
  std::vector<ImageLine> extent;
};
JoinedLines JoinCollinearLines(const std::vector<ImageLine>& lines);
// The same from the lines already joined (JoinCollinearLines(lines)): one join serves both
// FindCorners and OccludingContours.
std::vector<ImageCorner> FindCorners(const JoinedLines& joined, const RecognizerOptions& options);
// Corners hidden behind an occluding contour (RecognizerOptions::support_hidden_corners): two joined
// edges (representatives of `joined`) that each run into a contour (their line meets it within
// options.hidden_corner_reach_px of the edge's end, at 15 deg or more) and whose lines meet beyond
// both those ends, at most options.hidden_corner_max_gap_px on, at 20 deg or more. Pairs that are
// already one of `corners` are left out. The arms reach the edges' far ends.
std::vector<ImageCorner> FindHiddenCorners(const JoinedLines& joined, const std::vector<ImageLine>& contours,
                                           const std::vector<ImageCorner>& corners,
                                           const RecognizerOptions& options);
// Occluding contours (contours.cc, RecognizerOptions::occlusion_contours): the image's straight
// edges of at least options.contour_min_length_px, collinear pieces joined (JoinCollinearLines),
// with a median grey-level step across them of at least options.contour_min_step_grey (a wood
// grain line is no outline), each taken for the outline of something in front that the library
// does not hold. Each runs from a to b with its darker side towards (-d.y, d.x), d = b - a (by the
// median signed step).
std::vector<ImageLine> OccludingContours(const LineDetection& detection, const Camera& camera,
                                         const RecognizerOptions& options);
// The same with detection.lines already joined (JoinCollinearLines(detection.lines)).
std::vector<ImageLine> OccludingContours(const LineDetection& detection, const JoinedLines& joined,
                                         const Camera& camera, const RecognizerOptions& options);
// A box's image: its vertices' pin-hole projections (undistorted px), their convex hull, and its
// visible edges (VisibleBoxEdges).
struct BoxImage {
  BoxImage(const std::array<Eigen::Vector2d, 8>& vertices_px, uint16_t visible);
  std::array<Eigen::Vector2d, 8> px;
  uint16_t visible_edges = 0;
  int hull[8] = {0, 0, 0, 0, 0, 0, 0, 0};  // indices into px, counter-clockwise (y up)
  int hull_size = 0;
};
// How a contour passes through a box's image: across it (it enters and leaves the hull at least
// 4 px inside its own ends), or into it (one end 4 px or more beyond the hull, the other not: the
// end of something in front lies over the box), at least 10 px of it inside the hull, and along none
// of the visible edges (both ends of one within 3 px of its line) unless it reaches 40 px or more past
// the hull, its two ends together (a flank in front that runs along one of the box's edges); else
// kNone.
enum class ContourPassage : uint8_t { kNone, kAcross, kIntoAtA, kIntoAtB };  // kIntoAtB: b is inside
ContourPassage PassageThroughBoxImage(const ImageLine& contour, const BoxImage& box);
bool CrossesBoxImage(const ImageLine& contour, const BoxImage& box);  // passage kAcross
// What contours hide: one side of a contour along its length, or the strip between two; samples
// within kContourBandPx of a contour on the side in view count as hidden too (the contour's own edge
// confounds their support).
inline constexpr double kContourBandPx = 2, kContourEndPx = 3;
struct ContourOccluder {
  struct Side {
    Eigen::Vector2d a = Eigen::Vector2d::Zero(), along = Eigen::Vector2d::UnitX(),
                    toward_hidden = Eigen::Vector2d::UnitY();  // undistorted px; unit vectors
    double length = 0;
    bool Hides(const Eigen::Vector2d& px) const { return HidesAt(px.x(), px.y()); }
    // The same, written out: the one arithmetic of Hides and ContourOccluder::HidesEach.
    bool HidesAt(double x, double y) const {
      const double dx = x - a.x(), dy = y - a.y();
      const double t = along.x() * dx + along.y() * dy;
      return (t >= -kContourEndPx) & (t <= length + kContourEndPx) &
             (toward_hidden.x() * dx + toward_hidden.y() * dy > -kContourBandPx);
    }
  };
  std::array<Side, 2> sides;
  int count = 0;  // 1: one side of sides[0]; 2: the strip between them
  bool Hides(const Eigen::Vector2d& px) const {
    return count > 0 && sides[0].Hides(px) && (count < 2 || sides[1].Hides(px));
  }
  // Hides at n points (x[i], y[i]) into hides[i] (0 or 1), through Side::HidesAt without early
  // exits, in one loop over the points (the support-plane source's outline samples); the number
  // hidden.
  int HidesEach(const double* x, const double* y, int n, uint8_t* hides) const;
};
// Which pairs of contours ContourOcclusions takes besides two across a box's image.
struct ContourPairing {
  bool ends_inside = true;     // contours that end inside the box's image (a pole whose top is in front)
  bool across_beside = false;  // one across with one beside the box (a pole whose far side passes it by)
  bool pole_tops = false;      // a strip whose flanks end inside goes on past their ends by half its width
  bool sides_bounded = false;  // no side of one across with another across beyond it (the strip instead)
};
// The ways the contours that pass through a box's image (PassageThroughBoxImage) can hide part of it:
// either side of each that runs across it, and the strip between each two of them within 30 deg of
// parallel that do not meet inside it, where two that end inside come from the same side (the flanks
// of a pole whose top is in front of the box: the strip ends with the shorter one), or one that ends
// inside with one beside the box no farther from it than the box's image is wide; such a pair's far
// ends alike (no farther apart along them than they are apart) and the strip on the same side of the
// grey-level step at both (OccludingContours' orientation). pairing.ends_inside false: only contours
// across. pairing.across_beside: also the strip between one across and one beside the box (its line
// clear of the box's image), at any distance, the strip on the same side of the step at both (it hides no
// more than the side of the one across does; what it adds is the far side's bound, past which a longer model
// would show: AmbiguousExtent). pairing.pole_tops: a strip between flanks of which one or both end
// inside goes on past those ends by half its width (a round pole's top; ExtendOverPoleTop), the flank
// beside the box of such a pair lengthened as far that way. pairing.sides_bounded: no side of one
// across that has another across beyond it, within 30 deg of parallel and neither meeting the
// other's line (past a pole's far flank the outline is in view; the strip between them is kept).
void ContourOcclusions(const std::vector<ImageLine>& contours, const BoxImage& box,
                       std::vector<ContourOccluder>* occlusions, ContourPairing pairing = {});
// Whether a pose hidden in part by a contour occluder goes on past it: an edge that runs from the
// outline in view into the hidden part, continued past its hidden end over its own length, finds
// image edges with a grey-level step across them (RecognizerOptions::min_step_grey) along 20 px or
// more in a row. A block whose middle is hidden shows its far end beyond the occluder; a smaller
// model fitted to the near end (a cube at a bar's end) would otherwise pass as hidden there too.
// The occluder's pixels are pin-hole ones (camera.K()). Defined in recognizer.cc.
bool ContinuesPastHiddenEnd(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                            const ContourOccluder& occluder, const EdgeMap& edge_map,
                            const RecognizerOptions& options);
// Whether the part of a pose in view leaves its model open: an end face of the box wholly hidden
// by the occluder (its extent along that axis unseen) while another model of the library with the
// same two other sides (within 2 mm), laid from the end in view, would end hidden as well (a bar
// whose far end a contour hides is as much a longer block, or a shorter one). K: the pin-hole
// intrinsics the occluder's pixels are in.
bool AmbiguousExtent(const ModelLibrary& models, int model_index, const geometry::Pose3& camera_T_object,
                     const ContourOccluder& occluder, const Eigen::Matrix3d& K);
// Whether a pose's image ends at an occluding contour inside another's image: an edge of `inner`'s
// outline (its hull), 10 px long or more, lies along a contour or behind it (both its ends at most
// 2.5 px on the contour's lighter side and 25 px on its darker side), the contour running on past
// both the edge's ends by 10 px and a third of the edge's length or more, its darker side away from
// `inner`'s image (something in front, whose outline goes on where the block's would turn), and the
// edge's middle inside `outer`'s image (2 px in or more). A shorter model fitted onto the part in
// view of a longer block whose rest a pole hides ends so, along the pole or a little behind it; a
// block that ends where it seems to shows its own end edge, which the contour does not run past.
bool EndsAtContourInside(const BoxImage& inner, const BoxImage& outer,
                         const std::vector<ImageLine>& contours);
// The image direction (unit, undistorted px) in which a world point at pixel `px` moves when it
// rises along the world's z axis (towards or away from the vertical vanishing point).
Eigen::Vector2d UpImageDirection(const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world, const Eigen::Vector2d& px);
// An arm of a corner as a vertical edge: +1 when it runs up from the corner (the corner is on the
// block's bottom plane), -1 down (top plane), 0 when its image direction is more than tolerance_rad
// from the vertical through the corner.
int VerticalArm(const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_world, const Eigen::Vector2d& corner_px,
                const Eigen::Vector2d& arm_end_px, double tolerance_rad);
struct SupportHypothesis {
  int model = 0;                     // index into the library
  geometry::Pose3 world_T_object;    // the block resting on the plane
  double score = 0;                  // edge support along the visible predicted edges before any fit, 0..1
  int corner = 0;                    // into the corners
  int plane = 0;                     // into the planes
  bool behind_contour = false;       // scored on the side of an occluding contour in view (the score
                                     // times that side's share): its fit is judged only as hidden there
};
// The image segments that verified candidates matched, and the models of those candidates: a
// hypothesis whose segments are all claimed is not fitted again (the index's groups: by any model;
// a support hypothesis' corner: by its own model, RecognizerOptions::skip_corners_claimed_by_any_model).
class SegmentClaims {
 public:
  static constexpr int kAnyModel = -1;
  explicit SegmentClaims(size_t segments) : models_(segments) {}
  void Claim(int segment, int model) {
    std::vector<int>& m = models_[static_cast<size_t>(segment)];
    if (std::find(m.begin(), m.end(), model) == m.end()) m.push_back(model);
  }
  // By a candidate of `model`, or of any model (kAnyModel).
  bool Claimed(int segment, int model) const {
    const std::vector<int>& m = models_[static_cast<size_t>(segment)];
    return model == kAnyModel ? !m.empty() : std::find(m.begin(), m.end(), model) != m.end();
  }
  bool BothClaimed(int a, int b, int model) const { return Claimed(a, model) && Claimed(b, model); }

 private:
  std::vector<std::vector<int>> models_;  // per segment
};

// The placements scored so far, by model and centre (its micrometre cell), so that the same box is
// scored once (SupportHypotheses, AlternativeHypotheses). Three image lines meeting give three
// corners that share arms, and a box whose two horizontal sides are equal gives each placement twice,
// the arms' roles swapped (a cube six times among a candidate's alternatives): on the renders of
// seed 7, 81 000 of 274 000 support-plane placements were such repeats. A repeat scores as its first
// and can never be kept beside it (the thinning, SamePlace), so leaving it out changes nothing but
// the time.
class PlaceSet {
 public:
  explicit PlaceSet(const ModelLibrary& models) : models_(models) {}
  // Adds the box of `model` at `pose`; false when it was there already, up to the box's symmetries
  // (SymmetricRotationAngle under 1e-6 rad, the centre rounded to the same micrometre in x, y and z;
  // two centres a fraction of a micrometre apart across a rounding boundary count as two boxes, which
  // costs a repeat's score and nothing else).
  bool Insert(int model, const geometry::Pose3& pose);

 private:
  struct Place {
    int model;
    long long x, y, z;  // µm
    bool operator==(const Place&) const = default;
  };
  struct PlaceHash {
    size_t operator()(const Place& p) const;
  };
  const ModelLibrary& models_;
  std::unordered_map<Place, std::vector<Eigen::Quaterniond>, PlaceHash> places_;
};

// Every pose that a corner gives on each plane for each model and resting face, filtered by the
// arms' perpendicularity on the plane and their lengths against the model's edges, scored by edge
// support (detection.edge_map), and thinned to the best per model and place: at most
// options.max_support_hypotheses, best first, each with score >= options.support_min_score. Then
// those short of it with one of the `contours` near their corner, scored again on the side in view
// (behind_contour), best first: they take the room left under the cap, or
// options.support_contour_reserve places if that is more (past the cap).
std::vector<SupportHypothesis> SupportHypotheses(const ModelLibrary& models, const Camera& camera,
                                                 const LineDetection& detection,
                                                 const std::vector<ImageCorner>& corners,
                                                 const std::vector<SupportPlane>& planes,
                                                 const RecognizerOptions& options,
                                                 const std::vector<ImageLine>& contours = {});

// Other models at a candidate's place: a wrong model fitted onto a real block (a plate on a slab, a
// cube on one end of a bar) shares a bottom corner and the directions of its horizontal edges with
// the real block. For a pose at rest (an axis within options.table_snap_max_tilt_deg of the
// vertical), every model of the library on each of its faces, anchored at each of the pose's four
// bottom corners and reaching inwards from it along the same horizontal directions, scored by edge
// support (coarse samples first, as SupportHypotheses): the best options.alternatives_per_model
// distinct placements per model (SupportHypotheses' thinning) with score >= options.support_min_score,
// the pose itself left out, best first. Nothing for a pose not at rest.
std::vector<SupportHypothesis> AlternativeHypotheses(const ModelLibrary& models, const Camera& camera,
                                                     const LineDetection& detection, int model_index,
                                                     const geometry::Pose3& world_T_object,
                                                     const RecognizerOptions& options);

// ---- item 5: the evidence for a pose (what verification decides on).
// The known fixed world's visible edges in the (distorted) image: a block's predicted edge lying
// along one of them is explained by the fixed world already and is no evidence for the block.
struct FixedEdgeMap {
  // CV_16U (CV_32S past max_16bit_pieces entries): 1 + the index in `direction` of the fixed edge
  // piece drawn within 2 px, 0 where none; empty when no fixed edge is drawn. Half the pages of a
  // float image of directions.
  cv::Mat piece;
  // Per distinct direction, its cosine and sine (the direction rad in [0, pi), as float): no
  // trigonometry per query.
  std::vector<std::array<float, 2>> direction;
};
// The visible edges of the fixed world's parts, drawn 5 px wide in pieces of about 6 px. Tests
// lower max_16bit_pieces to reach the 32-bit image.
FixedEdgeMap ProjectFixedEdges(const scene::Scene* fixed_world, const Camera& camera,
                               int max_16bit_pieces = 65535);
// Whether a predicted edge through `pixel` with unit `normal` runs along a fixed edge (within 15 deg).
bool OnFixedEdge(const FixedEdgeMap& fixed, const Eigen::Vector2d& pixel, const Eigen::Vector2d& normal);

// What a pose predicts alone, weighed against the image (the selection's pairwise test, see
// RecognizerOptions::conflict_balance_margin): the samples of the pose's predicted outline (as in
// its edge support) that lie on none of `others`' visible projected edges (within 3 px and 15 deg)
// and on no fixed edge, each +1 where the image shows a step edge across it (an edge pixel with its
// gradient across and a grey-level step as in the step rule), -1 where the image shows contrast
// across it but no edge, 0 where it shows neither (a lit face against the lit table). Where a wrong
// model overlaps a block, the two outlines share most of the block's edges: the right one's own
// edges are in the image, the wrong one's run over a face or the table.
int OwnOutlineBalance(const Model& model, const geometry::Pose3& camera_T_object,
                      const std::vector<std::pair<const Model*, geometry::Pose3>>& others,
                      const Camera& camera, const EdgeMap& edge_map, const FixedEdgeMap& fixed,
                      const RecognizerOptions& options);
// The grey level of the bare table: the median of EdgeMap::smoothed over every other pixel in x
// and y (a work-site camera sees mostly table).
int TableGrey(const EdgeMap& edge_map);
// What a pose claims alone in the image (the selection's pairwise test, see
// RecognizerOptions::conflict_bare_table_share): the points every 2 px (pin-hole pixels) at least
// 4 px inside its box's image (the hull of its corners' projections) and at least 4 px outside each
// of `others`' images (its rival's and the other recognitions'), and inside the picture; of those,
// the ones that look like the bare table: no Canny edge pixel near (EdgeMap::near, kEdgeNearPx) and a
// smoothed grey within 15 of `table_grey`. Nothing where its image or one of the others' reaches
// behind the camera.
struct ClaimedAlone {
  int samples = 0, bare = 0;
};
ClaimedAlone BareTableBeyond(const Model& model, const geometry::Pose3& camera_T_object,
                             const std::vector<std::pair<const Model*, geometry::Pose3>>& others,
                             const Camera& camera, const EdgeMap& edge_map, int table_grey);
// The recognitions that stand on bare table (RecognizerOptions::max_bare_table_share): each one's claim
// alone against all the others (BareTableBeyond); the barest is dropped while `share` or more of its
// claim, 10 points at least, is bare table, and the rest are judged again without it. Positions into
// `recognitions` (model, camera_T_object), in the order dropped; none when `share` is 0.
std::vector<size_t> StandingOnBareTable(
    const std::vector<std::pair<const Model*, geometry::Pose3>>& recognitions, const Camera& camera,
    const EdgeMap& edge_map, int table_grey, double share);
// The recognitions that the others explain away (RecognizerOptions::min_own_balance): each one's
// OwnOutlineBalance against all the others; the weakest is dropped while it is under the minimum, and
// the rest are judged again without it. Positions into `recognitions` (model, camera_T_object), in
// the order dropped; none when the minimum is 0.
std::vector<size_t> ExplainedAway(const std::vector<std::pair<const Model*, geometry::Pose3>>& recognitions,
                                  const Camera& camera, const EdgeMap& edge_map, const FixedEdgeMap& fixed,
                                  const RecognizerOptions& options);
// One side of the selection's pairwise test: its own-outline balance (OwnOutlineBalance), its rank
// (net edge support times evidence score) and the share of its visible outline inside the image
// (VisibleOutlineInImage).
struct PairwiseSide {
  int own = 0;
  double rank = 0;
  double in_image = 1;
  // The other side's box lies within this one's (WithinBox) and its image ends at an occluding
  // contour inside this one's (EndsAtContourInside).
  bool holds_other = false;
  // The RMS of its matched lines against its pose (px), its evidence score (the one it ranks by) and
  // its model (index into the library).
  double rms_px = 0;
  double score = 0;
  int model = -1;
  // What it claims alone (BareTableBeyond), where the test weighs it; else none.
  ClaimedAlone alone;
};
// The selection's pairwise decision: the candidate replaces its rival when its own balance reaches
// RecognizerOptions::conflict_balance_margin and either the rival's own is at most 3 (nothing of it
// alone is in the image), or the candidate's own leads the rival's by conflict_own_lead samples
// while the candidate ranks at least conflict_rank_share of the rival (conflict_within_rank_share,
// when lower, where the candidate holds its rival: PairwiseSide::holds_other); or, where neither own balance
// reaches the margin (either sign), when a larger share of the candidate's outline is inside the
// image by conflict_in_image_lead while it ranks at least conflict_tie_rank_share of the rival. Where
// the candidate's own balance reaches the margin, also when it is another model than the rival, its
// lines fit it closer, their RMS at most conflict_rms_ratio of the rival's, and its evidence score
// leads by conflict_score_lead.
bool ReplacesRival(const PairwiseSide& candidate, const PairwiseSide& rival,
                   const RecognizerOptions& options);
// Whether `inner`'s box lies within `outer`'s, each of its vertices within 5 mm of it: a shorter
// model fitted onto the part in view of a longer block (a cube on a bar's end).
bool WithinBox(const Model& outer, const geometry::Pose3& camera_T_outer, const Model& inner,
               const geometry::Pose3& camera_T_inner);
struct PoseEvidence {
  double matched_fraction = 0;  // of the visible predicted edge length covered by matched lines
  double support_fraction = 0;  // of the informative sample points along the visible edges (an edge pixel
                                // across, or contrast across the edge) those with an edge pixel across
  double coverage = 0;          // supported sample points of all sample points along the visible edges
  double supported_px = 0;      // supported length, px
  double rms_px = 0;            // of the matched lines' endpoints to their predicted edges
  double rms_closest_px = 0;    // the same over each predicted edge's closest lines (a shadow line beside it left out)
  int matches = 0;
  int continued_ends = 0;       // edge ends where an image edge runs on past the corner (see ContinuedEdgeEnds)
  int long_continued_ends = 0;  // ... for most of the edge's length
  // Leaving out the samples along the fixed world's edges (explained already):
  double fixed_share = 0;       // of the samples, those along a fixed edge
  double free_support_fraction = 0, free_coverage = 0, free_supported_px = 0;
  double polarity = 0;          // of the supported samples, those whose edge's gradient has its edge's majority sign
  double edges_supported = 0;   // visible edges of >= 20 px with half their free samples supported
  double edges_visible = 0;     // visible edges of >= 20 px
  double step_supported_px = 0; // supported length where the grey level steps across the edge (not a thin line):
                                // RecognizerOptions::min_step_grey between step_offset_px either side
};
PoseEvidence EvaluatePose(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                          const LineDetection& detection, const RecognizerOptions& options,
                          const FixedEdgeMap* fixed = nullptr);
// The evidence along the outline alone (EvaluatePose's sample-by-sample fields: support, coverage,
// step-supported length, polarity, ...), without matching lines (the matched share and the residuals
// stay 0): what NetSupportPx needs, for ranking many nearby poses by it.
PoseEvidence EvaluateOutline(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                             const LineDetection& detection, const RecognizerOptions& options);
// How likely the evidence is of a true pose (within 3 px of a real block of the model), 0..1: a
// logistic regression over the evidence's fields, fitted by tools/fit_evidence_weights.py on the
// hypotheses of the benchmark's rendered scenes (seeds 7 and 8) and checked on scenes it never saw
// (seeds 9-13) and on the POV-Ray dev set (docs/benchmarks.md). Verification accepts a pose that passes
// its rules with a score >= RecognizerOptions::min_evidence_score, or any pose with a score >=
// RecognizerOptions::accept_evidence_score.
double EvidenceScore(const PoseEvidence& evidence);
// The selection's rank of a pose: its supported length where the grey level steps across the edge,
// less its unsupported outline (step_supported_px * (2 - 1 / coverage)).
double NetSupportPx(const PoseEvidence& evidence);

// ---- measuring: at which stage the recognizer lost a true object (issue 7's "measure first").
enum class LossStage : uint8_t {
  kSegments,      // fewer than 3 of its visible edges have an image line along them
  kGroups,        // no perceptual group made only of its edges, and no hypothesis (index or support) started near it
  kHypotheses,    // no fitted hypothesis of its model started near its pose (index, ranking or cap)
  kFit,           // hypotheses started near it, none converged onto it
  kVerification,  // a fit converged onto it and verification or culling rejected it
  kSelection,     // it was a candidate; non-maximum suppression or the support rule dropped it
  kAccepted,      // it was recognized (near its true pose)
};
inline constexpr int kLossStages = 7;
const char* LossStageName(LossStage stage);
inline constexpr int kSecondLookVerdicts = 8;
const char* SecondLookName(RecognitionTrace::SecondLook::Verdict verdict);
struct StageLoss {
  LossStage stage = LossStage::kSegments;
  int visible_edges = 0, edges_with_lines = 0;
  double extent_px = 0;                           // the true pose's projected size
  double best_start_px = 1e9, best_end_px = 1e9;  // the fitted hypotheses' closest start and end
  std::vector<double> best_start_rounds_px;       // the closest start's distance after each fit round
  RecognitionTrace::Outcome verification = RecognitionTrace::Outcome::kFitFailed;  // for kVerification
  // For kVerification: the occlusion pass's second look nearest to passing among the fits that
  // converged onto it (why the pass did not take the block either).
  RecognitionTrace::SecondLook second_look;
};
// camera_T_truth: the true pose; model_index: its model in the recognizer's library; trace from
// Recognize on the same image with the same options.
StageLoss ClassifyLoss(const Model& model, int model_index, const Camera& camera, const geometry::Pose3& camera_T_truth,
                       const LineDetection& detection, const std::vector<Group>& groups,
                       const RecognitionTrace& trace);

// ---- item 5/6 helpers: the smallest translation separating two convex sets of vertices with the
// given candidate axes (separating-axis test). depth <= 0 means they do not overlap.
struct Penetration {
  double depth_m = 0;
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // move the first set this way by depth_m
};
// General form: vertex sets in one frame and the candidate axes (unit; face normals and edge
// cross products of both sets for convex polyhedra).
Penetration VertexSetPenetration(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                                 const std::vector<Eigen::Vector3d>& axes);
Penetration BoxBoxPenetration(const Eigen::Vector3d& size_a, const geometry::Pose3& world_T_a,
                              const Eigen::Vector3d& size_b, const geometry::Pose3& world_T_b,
                              bool horizontal_only);

}  // namespace teachsim::vision
