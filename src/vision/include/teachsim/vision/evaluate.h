// Scoring recognitions against truth (issue 7, "Show"): which recognition is which block, how far
// off its pose is, and the figures the recognition benchmark reports — recall per visible-fraction
// bin, false positives per image, position error across the view and along the line of sight,
// symmetry-aware rotation error, and their median / p90 / max. Also the loader of the dev set's
// truth file (../shared/data/vision-dev/truth.json; docs/bench_recognize.md).
//
// Blocks are boxes: a box is equal to itself under the proper rotations that permute its sides of
// equal length (4 for distinct sides, 8 with two equal sides, 24 for a cube), so rotation errors
// are the smallest over that group.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/camera.h"

namespace teachsim::vision {

// The proper rotations (object frame) that map a centred box of full side lengths `size_m` onto
// itself: signed permutations with determinant +1 that only exchange sides equal within
// `tolerance_m`. The identity comes first.
std::vector<Eigen::Quaterniond> BoxSymmetries(const Eigen::Vector3d& size_m, double tolerance_m = 1e-6);

// The angle (rad, [0, pi]) of the smallest rotation taking `estimate` to any pose equal to `truth`
// under the symmetry group: min over S of angle(estimate^-1 * truth * S).
double SymmetricRotationError(const Eigen::Quaterniond& world_R_truth, const Eigen::Quaterniond& world_R_estimate,
                              const std::vector<Eigen::Quaterniond>& symmetries);

// A position error split by the camera's line of sight to the true position: `along_m` is the
// (unsigned) component along that line, the monocular camera's weak direction; `across_m` the rest.
struct PositionError {
  double across_m = 0, along_m = 0;
};
PositionError SplitPositionError(const Eigen::Vector3d& truth_in_world, const Eigen::Vector3d& estimate_in_world,
                                 const Eigen::Vector3d& camera_centre_in_world);

// How far off an estimated pose looks in the image: the RMS over the box's 8 corners of the distance
// (px) between each corner's projection at the estimate and at the truth, through the camera's lens,
// the least over the symmetry group (a symmetric box's corners are matched as the symmetry that
// fits best maps them). This is the pose's own reprojection error against the truth, as BOP's
// MSPD but RMS rather than max; unlike a fit's residual it does not depend on where edges were
// found. NaN when a corner is not in front of the camera at either pose.
double SymmetricProjectionRms(const Camera& camera, const Eigen::Vector3d& size_m,
                              const geometry::Pose3& world_T_truth, const geometry::Pose3& world_T_estimate,
                              const std::vector<Eigen::Quaterniond>& symmetries);

// --- Truth ---------------------------------------------------------------------------------------

struct TruthObject {
  std::string name, model;
  geometry::Pose3 world_T_object;  // box centre, box axes
  double visible_fraction = 1;     // visible share of the object's silhouette in the image
  int visible_pixels = 0;
};

// A rectangular frame lying on the table: walls of `wall_m` around an inner opening of
// `inner_m`, `height_m` tall; world_T_frame at the centre of the opening on the table (z = 0).
struct FrameTruth {
  geometry::Pose3 world_T_frame;
  Eigen::Vector2d inner_m = Eigen::Vector2d::Zero();
  double wall_m = 0, height_m = 0;
};

struct TruthCase {
  std::string image;  // path: absolute, or relative to the truth file's folder as loaded
  scene::CameraSpec camera;
  std::optional<FrameTruth> frame;
  std::vector<TruthObject> objects;
};

struct TruthSet {
  std::map<std::string, Eigen::Vector3d> model_sizes_m;  // full box side lengths per model name
  std::vector<TruthCase> cases;
};

// Loads a truth file of the dev-set format: {"models": {name: [x, y, z]}, "cases": [{"image",
// "camera": camera entry + "convention", "frame": pose + inner/wall/height, "objects": [{"name",
// "model", "position", "quaternion_wxyz", "visible_fraction", "visible_pixels", "dims"?}]}]}.
// Image paths are made absolute against the file's folder. Every object's model must be in
// "models" (and its "dims", when given, must equal the model's sizes).
[[nodiscard]] Result<TruthSet> LoadTruthSet(const std::string& path);

// The response of the dev set's cameras (scene::CameraSpec::gamma), which truth.json does not
// carry: its PNGs are POV-Ray's, which blends the light of an edge pixel linearly and writes it
// sRGB-encoded. Measured: on the grey levels, the gradient's peak across the fully visible blocks'
// edges lies 0.16 px inside the true outline (docs/benchmarks.md, session 26).
inline constexpr double kDevSetGamma = 2.2;

// The fixed world a recognizer may be told about: a table (top at z = 0) and the frame, if any.
scene::Scene FixedWorldScene(const std::optional<FrameTruth>& frame);

// --- Matching --------------------------------------------------------------------------------------

struct Detection {
  std::string model;
  geometry::Pose3 world_T_object;
  double score = 0;  // higher is more confident; matching takes detections in this order
  double reprojection_rms_px = std::numeric_limits<double>::quiet_NaN();  // NaN: not reported
};

// When a detection counts as finding a truth object. The thresholds decide "found" (recall); the
// errors of found objects are then reported separately against the goals.
struct MatchOptions {
  double max_across_m = 0.015;                    // a third of a 45 mm block
  double max_along_m = 0.05;                      // depth is the monocular camera's weak direction
  double max_rotation_rad = 20.0 * 3.14159265358979 / 180.0;
  // Objects less visible than this (or entirely outside the image) are not scored: missing them
  // is no miss and finding them no false positive.
  double min_visible_fraction = 0.05;
  [[nodiscard]] Status Validate() const;
};

struct ObjectOutcome {
  int truth = -1;      // index into the truth objects
  int detection = -1;  // the matched detection, or -1 when missed
  double visible_fraction = 0;
  double rotation_error_rad = 0;  // of the match
  PositionError position_error;   // of the match
  double reprojection_rms_px = std::numeric_limits<double>::quiet_NaN();  // the match's own figure
  // SymmetricProjectionRms of the match against its truth; NaN without a camera.
  double truth_projection_rms_px = std::numeric_limits<double>::quiet_NaN();
};

struct ImageEvaluation {
  std::vector<ObjectOutcome> objects;  // every scored truth object, in truth order
  std::vector<int> detection_truth;    // per detection: matched truth index, -1 false, -2 matched an unscored object
  int false_positives = 0;
};

// Greedy matching in order of falling detection score: each detection takes the unmatched truth
// object of its model within the thresholds with the smallest normalised error (the sum of each
// error over its threshold); detections left over, duplicates included, are false positives.
// Fails when a truth object's model has no size in `model_sizes_m` (its symmetries are unknown).
// With `camera` (the image's), each match's truth_projection_rms_px too.
[[nodiscard]] Result<ImageEvaluation> EvaluateImage(
    const std::vector<TruthObject>& truth, const std::vector<Detection>& detections,
    const std::map<std::string, Eigen::Vector3d>& model_sizes_m,
    const Eigen::Vector3d& camera_centre_in_world, const MatchOptions& options,
    const Camera* camera = nullptr);

// Where each false positive of `evaluation` stands: the truth object (scored or not) whose box
// holds the detection's centre, or whose centre the detection's box holds, each box grown by
// margin_m (the nearest centre first when several do); -1 for a false positive at no truth object
// and for every detection that is not a false positive. A wrong model fitted onto a block (a cube on
// one end of a bar, a slab over a bar) stands at it; a pose on the frame, a shadow or the occluder
// stands at none. Fails when a model has no size in `model_sizes_m`.
[[nodiscard]] Result<std::vector<int>> FalsePositiveHosts(
    const std::vector<TruthObject>& truth, const std::vector<Detection>& detections,
    const std::map<std::string, Eigen::Vector3d>& model_sizes_m, const ImageEvaluation& evaluation,
    double margin_m = 0.005);

// The shorter models of the library that would show in the image as the block does: a model with
// the same cross-section (two sides equal to two of the block's, within 1e-6 m) and a shorter third
// side, laid along the block flush with one of its ends, whose outline (the hull of its corners'
// projections, lens distortion removed) holds the centre of every pixel in view of the block within
// `margin_px`. A bar whose far half the dark cylinder hides, or the image border cuts off, shows what
// a cube at its near end would: one image cannot tell them apart. `visible_px` are the centres of the
// block's pixels in view, in image pixels as the camera saw them (distorted). Shortest first; empty
// when no shorter model explains the view, when nothing of the block is in view, or when a corner
// lies behind the camera. Fails when `model` has no size in `model_sizes_m`.
[[nodiscard]] Result<std::vector<std::string>> ShorterModelsInView(
    const std::map<std::string, Eigen::Vector3d>& model_sizes_m, const std::string& model,
    const geometry::Pose3& world_T_object, const Camera& camera,
    const std::vector<Eigen::Vector2d>& visible_px, double margin_px = 2);

// --- Summary ---------------------------------------------------------------------------------------

struct Stats {
  int count = 0;
  double mean = std::numeric_limits<double>::quiet_NaN();
  double median = std::numeric_limits<double>::quiet_NaN();
  double p90 = std::numeric_limits<double>::quiet_NaN();
  double max = std::numeric_limits<double>::quiet_NaN();
};
// Order statistics of the finite values (nearest rank: p90 is the smallest value with at least 90 %
// of the values at or below it).
Stats Summarize(std::vector<double> values);

// The visible-fraction bins of issue 7: [0.7, 1], [0.4, 0.7), [min_visible_fraction, 0.4).
enum class VisibilityBin { kHigh = 0, kMedium = 1, kLow = 2 };
VisibilityBin BinOf(double visible_fraction);
const char* BinName(VisibilityBin bin);  // ">=0.7", "0.4-0.7", "<0.4"

// Issue 7 sets three recall goals: >= 98 % for unoccluded objects, >= 90 % with up to 30 % hidden
// (the >= 0.7 bin) and >= 70 % at half hidden (the 0.4-0.7 bin). Unoccluded is counted apart, as
// at most 1 % hidden (a few pixels of a corner behind something, as two of the dev set's blocks at
// 0.993 and 0.995; the renderer gives a block that nothing hides and that is all in the image 1).
inline constexpr double kUnoccludedFraction = 0.99;

// The goals for a found object's pose.
struct PoseGoals {
  double rotation_rad = 0.5 * 3.14159265358979 / 180.0;
  double across_m = 0.001, along_m = 0.002;
};

// Issue 7's time goal: each 640 x 480 image with up to 6 objects in at most this long, on one core.
inline constexpr double kTimeGoalMs = 50;

// One image's recognition time, with what the method tells of it (each part optional).
struct ImageTime {
  double total_ms = 0;                     // what the figures count (the benchmark: CPU time)
  std::string image;                       // the image's name
  std::map<std::string, double> stage_ms;  // the method's own clock per stage (RecognitionResult::timing_ms)
  std::map<std::string, int> counts;       // what it worked through (lines, corners, fitted hypotheses, ...)
};

// A set of found objects' pose figures.
struct PoseFigures {
  Stats rotation_deg, across_mm, along_mm, reprojection_rms_px, truth_projection_rms_px;
};

// Collects the pose figures of found objects, one sample of each figure per object; what both
// builders below keep of a found object.
class PoseSamples {
 public:
  void Add(const ObjectOutcome& found);
  PoseFigures Build() const;

 private:
  std::vector<double> rotation_deg_, across_mm_, along_mm_, rms_px_, truth_projection_px_;
};

struct Summary {
  int images = 0;
  int objects[3] = {0, 0, 0};  // per VisibilityBin
  int found[3] = {0, 0, 0};
  int unoccluded_objects = 0, unoccluded_found = 0;  // visible fraction >= kUnoccludedFraction (in kHigh too)
  int false_positives = 0;
  int within_goals = 0;  // found objects whose pose meets every PoseGoals figure
  PoseFigures poses;     // of the found objects (truth_projection_rms_px: of those that have one)
  Stats time_ms;
  int over_time_goal = 0;                      // images that took longer than kTimeGoalMs
  std::map<std::string, Stats> stage_time_ms;  // per stage, over the images that gave it
  std::optional<ImageTime> slowest;            // the image that took longest (none without images)

  double Recall(VisibilityBin bin) const;  // NaN when the bin is empty
  double RecallUnoccluded() const;         // NaN when there is no unoccluded object
  double FalsePositivesPerImage() const;
};

// Collects the figures over images; add each image's evaluation and its recognition time.
class SummaryBuilder {
 public:
  explicit SummaryBuilder(PoseGoals goals = {}) : goals_(goals) {}
  void Add(const ImageEvaluation& evaluation, const ImageTime& time);
  void Add(const ImageEvaluation& evaluation, double time_ms) {
    Add(evaluation, ImageTime{time_ms, {}, {}, {}});
  }
  Summary Build() const;

 private:
  PoseGoals goals_;
  Summary counts_;
  PoseSamples poses_;
  std::vector<double> time_ms_;
  std::map<std::string, std::vector<double>> stage_ms_;
};

json::Json SummaryToJson(const Summary& summary);

// One recall figure as the summaries give it: {"objects", "found", "recall"} (null when there are
// no objects).
json::Json RecallToJson(int objects, int found);

// --- Paired comparison ---------------------------------------------------------------------------

// Two methods' pose figures on the objects that both found. Each method's own medians are taken
// over the objects it found, and a method that finds few objects, only the easy ones, can look
// more precise than one that finds many; on the same objects the figures compare like with like.
struct PairedSummary {
  int objects = 0;   // found by both
  PoseFigures a, b;  // the first method's figures on them, the second's
  // Objects on which the first method's figure is smaller than the second's, for the rotation
  // error, the reprojection RMS and the error against the truth's projection (ties and objects that
  // lack either figure count for neither).
  int a_smaller_rotation = 0, a_smaller_reprojection = 0, a_smaller_truth_projection = 0;
  int b_smaller_rotation = 0, b_smaller_reprojection = 0, b_smaller_truth_projection = 0;
};

// Collects the pairs over images: add the two methods' evaluations of each image (made against the
// same truth objects, in the same order).
class PairedBuilder {
 public:
  // Fails, adding nothing, when the two evaluations are not of the same truth objects.
  [[nodiscard]] Status Add(const ImageEvaluation& a, const ImageEvaluation& b);
  PairedSummary Build() const;

 private:
  PairedSummary counts_;
  PoseSamples a_, b_;
};

// {"objects", FIRST: figures, SECOND: figures, "FIRST_smaller": counts, "SECOND_smaller": counts},
// with the two methods' names as given (they must differ); the figures as SummaryToJson names them.
json::Json PairedSummaryToJson(const PairedSummary& summary, const std::string& first,
                               const std::string& second);

}  // namespace teachsim::vision
