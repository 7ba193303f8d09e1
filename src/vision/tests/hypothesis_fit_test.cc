// Fitting hypotheses (hypothesis_fit.cc, pose_fit.cc) on synthetic cases with known answers: a
// rendered block converges from a start 15 px and 10 deg off, a line beside an edge does not pull
// the fit, and the analytic Jacobian's fit recovers a perturbed pose exactly. And the shortcuts
// that make matching and edge support fast give the answers of testing everything.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>

#include "dev_set.h"
#include "synthetic_scene.h"
#include "teachsim/vision/recognition_stages.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::vision {
namespace {

using synthetic::RenderBox;
using synthetic::SyntheticCamera;

Model Bar() { return {"bar90", Eigen::Vector3d(0.09, 0.045, 0.045)}; }

geometry::Pose3 OnTable(const Eigen::Vector3d& size, double x, double y, double yaw_rad) {
  return {Eigen::Quaterniond(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())), {x, y, size.z() / 2}};
}

// The visible edges of a box at a pose as image lines (the middle 80 % of each), undistorted px.
std::vector<ImageLine> EdgeLines(const Model& model, const Eigen::Matrix3d& K, const geometry::Pose3& camera_T_object,
                                 std::vector<int>* edges = nullptr) {
  std::vector<ImageLine> lines;
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_object.Inverse().translation);
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector2d a = (K * (camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[e][0]))).hnormalized();
    const Eigen::Vector2d b = (K * (camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[e][1]))).hnormalized();
    lines.push_back({a + 0.1 * (b - a), a + 0.9 * (b - a)});
    if (edges != nullptr) edges->push_back(e);
  }
  return lines;
}

// The hypotheses' rounds fit without the covariance and ask for it once for the pose they keep:
// PoseCovariance there is the fit's own to the bit, and LineResidualRmsPx a zero-step fit's RMS.
TEST(HypothesisFitTest, TheCovarianceAndTheRmsAloneAreTheFitsOwn) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  const geometry::Pose3 camera_T_truth = camera.camera_T_world() * OnTable(bar.box_size_m, 0.02, 0.01, 0.6);
  std::vector<int> edges;
  const std::vector<ImageLine> lines = EdgeLines(bar, K, camera_T_truth, &edges);
  // Noisy lines (0.3-0.9 px off), so that the RMS and the residual variance are not zero.
  std::vector<LineMatch> matches;
  for (size_t i = 0; i < lines.size(); ++i) {
    const Eigen::Vector2d normal =
        Eigen::Vector2d(lines[i].a.y() - lines[i].b.y(), lines[i].b.x() - lines[i].a.x()).normalized();
    matches.push_back({edges[i], lines[i].a + (0.3 + 0.05 * edges[i]) * normal, lines[i].b - 0.4 * normal});
  }
  geometry::Pose3 start = camera_T_truth;
  start.translation += Eigen::Vector3d(0.003, -0.002, 0.001);
  for (const RobustLoss& loss :
       {RobustLoss{RobustLoss::Kind::kHuber, 1.5}, RobustLoss{RobustLoss::Kind::kTukey, 2.0}}) {
    const FitResult with = FitPoseToLines(bar.box_size_m, K, start, matches, 30, loss);
    const FitResult without = FitPoseToLines(bar.box_size_m, K, start, matches, 30, loss, false);
    EXPECT_TRUE(without.covariance_camera.isZero(0));
    EXPECT_EQ(with.camera_T_object.translation, without.camera_T_object.translation);
    EXPECT_GT(with.covariance_camera(0, 0), 0);
    EXPECT_EQ(PoseCovariance(bar.box_size_m, K, without.camera_T_object, matches, loss),
              with.covariance_camera);
    const FitResult on_plane =
        FitPoseOnPlane(bar.box_size_m, K, camera.camera_T_world(), start, matches, 30, loss);
    EXPECT_EQ(PoseCovariance(bar.box_size_m, K, on_plane.camera_T_object, matches, loss),
              on_plane.covariance_camera);
  }
  EXPECT_EQ(LineResidualRmsPx(bar.box_size_m, K, start, matches),
            FitPoseToLines(bar.box_size_m, K, start, matches, 0, 0).rms_px);
  EXPECT_GT(LineResidualRmsPx(bar.box_size_m, K, start, matches), 1);
  EXPECT_EQ(LineResidualRmsPx(bar.box_size_m, K, start, {}), 0);
  EXPECT_TRUE(PoseCovariance(bar.box_size_m, K, start, {}, RobustLoss{}).isZero(0));
}

// A block standing on the table, its start moved on the table by about 15 px in the image and
// turned by 10 deg: the support-plane fit (3 rounds on the plane, then 6 DOF) ends on the block.
TEST(HypothesisFitTest, ARenderedBlockConvergesFromAStart15PxAnd10DegOff) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  RecognizerOptions options;
  for (const double yaw : {0.3, 1.1}) {
    const geometry::Pose3 truth = OnTable(bar.box_size_m, 0.01, -0.01, yaw);
    const cv::Mat image = RenderBox(camera, bar.box_size_m, truth);
    const LineDetection detection = DetectLinesAndEdges(image, camera, options);
    const geometry::Pose3 camera_T_truth = camera.camera_T_world() * truth;
    for (const Eigen::Vector2d& shift : {Eigen::Vector2d(0.012, 0.004), Eigen::Vector2d(-0.006, 0.011)}) {
      geometry::Pose3 start = truth;
      start.translation.head<2>() += shift;
      start.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(10 * M_PI / 180, Eigen::Vector3d::UnitZ())) * start.rotation;
      const geometry::Pose3 camera_T_start = camera.camera_T_world() * start;
      const double start_px = MeanVertexShiftPx(bar, K, camera_T_start, camera_T_truth);
      EXPECT_GT(start_px, 12);
      const HypothesisFit fitted =
          FitSupportHypothesis(bar, K, camera.camera_T_world(), camera_T_start, detection.lines, options);
      EXPECT_FALSE(fitted.failed) << "yaw " << yaw << ", start " << start_px << " px off";
      EXPECT_LT(MeanVertexShiftPx(bar, K, fitted.fit.camera_T_object, camera_T_truth), 0.5)
          << "yaw " << yaw << ", start " << start_px << " px off";
    }
  }
}

// A shadow line 3 px beside the bottom edge along its whole length (within the match distance):
// fitting all matched lines (Huber) pulls the pose off; the hypothesis fits keep to the edges.
TEST(HypothesisFitTest, AParallelLine3PxBesideAnEdgeDoesNotPullTheFit) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  RecognizerOptions options;
  const geometry::Pose3 truth = OnTable(bar.box_size_m, 0.02, 0.0, 0.5);
  const geometry::Pose3 camera_T_truth = camera.camera_T_world() * truth;
  std::vector<int> edges;
  std::vector<ImageLine> lines = EdgeLines(bar, K, camera_T_truth, &edges);
  // Beside each visible bottom edge (z = -0.5 sz: vertices without bit 2), on the far side from the box centre.
  const Eigen::Vector2d centre_px = (K * camera_T_truth.translation).hnormalized();
  int shadows = 0;
  for (size_t i = 0; i < edges.size(); ++i) {
    if ((kBoxEdges[static_cast<size_t>(edges[i])][0] & 4) || (kBoxEdges[static_cast<size_t>(edges[i])][1] & 4)) continue;
    const ImageLine& l = lines[i];
    Eigen::Vector2d n = Eigen::Vector2d(-(l.b - l.a).y(), (l.b - l.a).x()).normalized();
    if (n.dot(l.a - centre_px) < 0) n = -n;
    lines.push_back({l.a + 3 * n, l.b + 3 * n});
    ++shadows;
  }
  ASSERT_GE(shadows, 2);
  geometry::Pose3 start = truth;
  start.translation += Eigen::Vector3d(0.002, -0.001, 0);
  start.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.03, Eigen::Vector3d::UnitZ())) * start.rotation;
  const geometry::Pose3 camera_T_start = camera.camera_T_world() * start;

  // What the fit did before: every matched line, Huber weights.
  const EdgeMatchSet all = MatchEdges(bar, K, camera_T_start, lines, options.match_distance_px,
                                      options.match_angle_deg * M_PI / 180);
  const FitResult plain = FitPoseToLines(bar.box_size_m, K, camera_T_start, all.matches, 20, options.huber_px);
  EXPECT_GT(MeanVertexShiftPx(bar, K, plain.camera_T_object, camera_T_truth), 0.3);

  const HypothesisFit support = FitSupportHypothesis(bar, K, camera.camera_T_world(), camera_T_start, lines, options);
  ASSERT_FALSE(support.failed);
  EXPECT_LT(MeanVertexShiftPx(bar, K, support.fit.camera_T_object, camera_T_truth), 0.05);

  // The index path from three of the block's own edges as the group's correspondences.
  std::vector<LineMatch> seed;
  for (size_t i = 0; i < 3; ++i) seed.push_back({edges[i], lines[i].a, lines[i].b});
  geometry::Pose3 camera_T_index = camera_T_start;
  camera_T_index.translation.z() += 0.004;  // off the plane too
  const HypothesisFit index = FitIndexHypothesis(bar, K, camera_T_index, seed, lines, options);
  ASSERT_FALSE(index.failed);
  EXPECT_LT(MeanVertexShiftPx(bar, K, index.fit.camera_T_object, camera_T_truth), 0.05);
}

// A block half hidden beside another of its model: three of its edges have lines, all of the
// other's do, 12 mm and 7 deg away. Matching loosely first (3 match distances), the fit from
// the hidden block's own pose leaves it for the other, which explains more line length; matching
// tightly from the start (tight = true) it stays. The recognizer verifies both poses where the
// first drifted (RecognizerOptions::support_tight_fit_shift_px).
TEST(HypothesisFitTest, ATightFitStaysOnAHalfHiddenBlockThatTheLooseFitLeaves) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  const RecognizerOptions options;
  const geometry::Pose3 camera_T_truth = camera.camera_T_world() * OnTable(bar.box_size_m, 0.02, 0.0, 0.5);
  const geometry::Pose3 camera_T_other = camera.camera_T_world() * OnTable(bar.box_size_m, 0.03, 0.006, 0.62);
  std::vector<ImageLine> lines = EdgeLines(bar, K, camera_T_truth);
  lines.resize(3);
  const std::vector<ImageLine> other = EdgeLines(bar, K, camera_T_other);
  lines.insert(lines.end(), other.begin(), other.end());

  const HypothesisFit loose =
      FitSupportHypothesis(bar, K, camera.camera_T_world(), camera_T_truth, lines, options);
  const HypothesisFit tight =
      FitSupportHypothesis(bar, K, camera.camera_T_world(), camera_T_truth, lines, options, true);
  ASSERT_FALSE(loose.failed);
  ASSERT_FALSE(tight.failed);
  EXPECT_GT(MeanVertexShiftPx(bar, K, loose.fit.camera_T_object, camera_T_truth),
            2 * options.match_distance_px);
  EXPECT_LT(MeanVertexShiftPx(bar, K, loose.fit.camera_T_object, camera_T_other), 0.05);
  EXPECT_LT(MeanVertexShiftPx(bar, K, tight.fit.camera_T_object, camera_T_truth), 0.05);
}

TEST(HypothesisFitTest, OnEdgeMatchesKeepsASplitEdgesPiecesAndDropsALineBesideIt) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  const geometry::Pose3 camera_T_truth = camera.camera_T_world() * OnTable(bar.box_size_m, 0, 0, 0.2);
  std::vector<int> edges;
  const std::vector<ImageLine> lines = EdgeLines(bar, K, camera_T_truth, &edges);
  const ImageLine& l = lines[0];
  const Eigen::Vector2d n = Eigen::Vector2d(-(l.b - l.a).y(), (l.b - l.a).x()).normalized();
  std::vector<LineMatch> matches;
  matches.push_back({edges[0], l.a + 0.5 * n, l.a + 0.4 * (l.b - l.a) + 0.5 * n});  // the edge in two pieces,
  matches.push_back({edges[0], l.a + 0.5 * (l.b - l.a), l.b});                   // 0.5 px apart
  matches.push_back({edges[0], l.a + 4 * n, l.b + 4 * n});                       // a line 4 px beside it
  matches.push_back({edges[1], lines[1].a, lines[1].b});
  const std::vector<LineMatch> on = OnEdgeMatches(bar, K, camera_T_truth, matches, 1.5);
  ASSERT_EQ(on.size(), 3u);
  EXPECT_EQ(on[0].a, matches[0].a);
  EXPECT_EQ(on[1].a, matches[1].a);
  EXPECT_EQ(on[2].edge, edges[1]);
  // Explained length: the lines cover 80 % of every visible edge.
  const double visible = MatchEdges(bar, K, camera_T_truth, {}, 2, 0.1).visible_length_px;
  EXPECT_NEAR(ExplainedLengthPx(bar, K, camera_T_truth, lines, 2, 0.1), 0.8 * visible, 1e-6 * visible);
}

// The analytic Jacobian: from a start 5 mm and 3 deg off, noise-free lines give the pose to 1e-9,
// with Huber or Tukey weights alike.
TEST(HypothesisFitTest, TheFitRecoversAPerturbedPoseExactlyWithEitherLoss) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  geometry::Pose3 tilted = OnTable(bar.box_size_m, 0.01, 0.03, 0.7);
  tilted.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 1, 0).normalized())) * tilted.rotation;
  const geometry::Pose3 camera_T_truth = camera.camera_T_world() * tilted;
  std::vector<int> edges;
  const std::vector<ImageLine> lines = EdgeLines(bar, K, camera_T_truth, &edges);
  std::vector<LineMatch> matches;
  for (size_t i = 0; i < lines.size(); ++i) matches.push_back({edges[i], lines[i].a, lines[i].b});
  geometry::Pose3 start = camera_T_truth;
  start.translation += Eigen::Vector3d(0.004, -0.003, 0.002);
  start.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.05, Eigen::Vector3d(0.2, 1, 0.3).normalized())) * start.rotation;
  for (const RobustLoss& loss : {RobustLoss{RobustLoss::Kind::kHuber, 1.5}, RobustLoss{RobustLoss::Kind::kTukey, 20}}) {
    const FitResult fit = FitPoseToLines(bar.box_size_m, K, start, matches, 30, loss);
    EXPECT_LT((fit.camera_T_object.translation - camera_T_truth.translation).norm(), 1e-9);
    EXPECT_LT(fit.camera_T_object.rotation.angularDistance(camera_T_truth.rotation), 1e-9);
    EXPECT_LT(fit.rms_px, 1e-6);
    EXPECT_TRUE(fit.converged);
  }
}

}  // namespace
}  // namespace teachsim::vision

namespace teachsim::vision {
namespace {

// An L corner whose one arm is split 40 px from the corner and starts 15 px short of it (a shadow
// across the edge): neither piece's end is near enough alone, the joined edge gives the corner, its
// arm reaching the far end.
TEST(HypothesisFitTest, ASplitSegmentNearACornerStillGivesTheCorner) {
  RecognizerOptions options;
  const Eigen::Vector2d corner(300, 200), d1(1, 0), d2 = Eigen::Vector2d(0.2, 1).normalized();
  const Eigen::Vector2d n1(0, 1);
  const std::vector<ImageLine> split = {{corner + 15 * d1, corner + 40 * d1 + 0.3 * n1},
                                        {corner + 43 * d1 + 0.2 * n1, corner + 120 * d1},
                                        {corner + 100 * d2, corner + 3 * d2}};
  const std::vector<ImageCorner> corners = FindCorners(split, options);
  ASSERT_EQ(corners.size(), 1u);
  EXPECT_LT((corners[0].point - corner).norm(), 0.5);
  // The arms reach the edges' far ends (the joined arm's end on the longest piece's line).
  const Eigen::Vector2d arm_a = corners[0].segments[0] == 2 ? corners[0].arm_end[1] : corners[0].arm_end[0];
  const Eigen::Vector2d arm_b = corners[0].segments[0] == 2 ? corners[0].arm_end[0] : corners[0].arm_end[1];
  EXPECT_LT((arm_a - (corner + 120 * d1)).norm(), 0.5);
  EXPECT_LT((arm_b - (corner + 100 * d2)).norm(), 1e-9);
  EXPECT_TRUE(corners[0].segments[0] == 1 || corners[0].segments[1] == 1) << "the longest piece";
  const JoinedLines joined = JoinCollinearLines(split);
  EXPECT_EQ(joined.representative, (std::vector<int>{1, 1, 2}));
  EXPECT_LT((joined.extent[1].a - (corner + 15 * d1)).norm(), 0.5);
  EXPECT_LT((joined.extent[1].b - (corner + 120 * d1)).norm(), 0.5);
  // A parallel line 3 px beside the arm is not joined to it.
  std::vector<ImageLine> beside = split;
  beside[0] = {corner + 15 * d1 + 3 * n1, corner + 40 * d1 + 3 * n1};
  for (const ImageCorner& c : FindCorners(beside, options)) EXPECT_GT((c.point - corner).norm(), 2.0);
}

}  // namespace
}  // namespace teachsim::vision

namespace teachsim::vision {
namespace {

// A block with square faces: a corner gives each pose twice, with the equal axes swapped; the
// thinning keeps one of them (each kept hypothesis is a place of its own, up to the box's symmetry).
TEST(HypothesisFitTest, SupportHypothesesKeepOnePosePerPlaceUpToSymmetry) {
  const Camera camera = SyntheticCamera();
  const Model cube{"cube45", Eigen::Vector3d(0.045, 0.045, 0.045)};
  const ModelLibrary library{{cube}};
  RecognizerOptions options;
  const geometry::Pose3 truth = OnTable(cube.box_size_m, 0.0, 0.01, 0.35);
  const cv::Mat image = RenderBox(camera, cube.box_size_m, truth);
  const LineDetection detection = DetectLinesAndEdges(image, camera, options);
  const std::vector<SupportHypothesis> hypotheses =
      SupportHypotheses(library, camera, detection, FindCorners(detection.lines, options), {SupportPlane{}}, options);
  ASSERT_FALSE(hypotheses.empty());
  EXPECT_LT((hypotheses.front().world_T_object.translation - truth.translation).norm(), 0.002);
  for (size_t i = 0; i < hypotheses.size(); ++i) {
    for (size_t j = 0; j < i; ++j) {
      const bool same = (hypotheses[i].world_T_object.translation - hypotheses[j].world_T_object.translation).norm() <
                            0.25 * 0.045 &&
                        SymmetricRotationAngle(cube, hypotheses[i].world_T_object, hypotheses[j].world_T_object) < 0.17;
      EXPECT_FALSE(same) << i << " repeats " << j;
    }
  }
}

// A thin dark line (wood grain) drawn on a cube's top face from near one of its top corners: its
// image line is a thin line (LineRidgeShare), the cube's edges are not, and with the corner filter
// on no support-plane hypothesis comes from a corner with the grain as an arm, while the cube is
// still proposed first. By default the filter acts only in cluttered images (150 corners or more).
TEST(HypothesisFitTest, CornersWithAGrainLineAsAnArmProposeNothing) {
  const Camera camera = SyntheticCamera();
  const Model cube{"cube45", Eigen::Vector3d(0.045, 0.045, 0.045)};
  const ModelLibrary library{{cube}};
  const geometry::Pose3 truth = OnTable(cube.box_size_m, 0.0, 0.01, 0.35);
  cv::Mat image = RenderBox(camera, cube.box_size_m, truth);
  // The grain: from 4 px inside the top face's corner nearest the camera, towards and past the
  // face's middle.
  const geometry::Pose3 camera_T_object = camera.camera_T_world() * truth;
  int nearest = 4;
  for (int v = 5; v < 8; ++v) {  // the top vertices (+z)
    if ((camera_T_object * BoxVertex(cube.box_size_m, v)).z() <
        (camera_T_object * BoxVertex(cube.box_size_m, nearest)).z()) {
      nearest = v;
    }
  }
  const Eigen::Vector2d vertex = *camera.Project(truth * BoxVertex(cube.box_size_m, nearest));
  const Eigen::Vector2d middle = *camera.Project(truth * Eigen::Vector3d(0, 0, 0.5 * cube.box_size_m.z()));
  const Eigen::Vector2d along = (middle - vertex).normalized();
  const Eigen::Vector2d grain_a = vertex + 4 * along, grain_b = middle + 0.6 * (middle - vertex);
  auto fixed_point = [](const Eigen::Vector2d& p) {  // 4 bits of sub-pixel
    return cv::Point(static_cast<int>(std::lround(p.x() * 16)), static_cast<int>(std::lround(p.y() * 16)));
  };
  cv::line(image, fixed_point(grain_a), fixed_point(grain_b), cv::Scalar(60), 1, cv::LINE_AA, 4);
  RecognizerOptions options;
  ASSERT_GT(options.support_corner_ridge_share, 0) << "the filter is on by default";
  const int clutter = options.support_corner_ridge_min_corners;
  options.support_corner_ridge_min_corners = 0;  // in every image
  const LineDetection detection = DetectLinesAndEdges(image, camera, options);
  // The grain's image line (a flank of it), and the lines along the cube's edges.
  const Eigen::Vector2d grain_normal(-along.y(), along.x());
  int grain = -1;
  for (size_t i = 0; i < detection.lines.size(); ++i) {
    const ImageLine& l = detection.lines[i];
    if (l.Length() > 20 && std::abs(grain_normal.dot(l.a - grain_a)) < 2.5 &&
        std::abs(grain_normal.dot(l.b - grain_a)) < 2.5) {
      grain = static_cast<int>(i);
    }
  }
  ASSERT_GE(grain, 0) << "the grain line was not detected";
  EXPECT_GE(LineRidgeShare(detection.lines[static_cast<size_t>(grain)], camera, detection.edge_map,
                           options.support_corner_ridge_grey),
            0.8);
  int edges_checked = 0;
  for (const ImageLine& edge : EdgeLines(cube, camera.K(), camera_T_object)) {
    const Eigen::Vector2d d = (edge.b - edge.a).normalized(), n(-d.y(), d.x());
    for (const ImageLine& l : detection.lines) {
      if (l.Length() < 20 || std::abs(n.dot(l.a - edge.a)) > 1.5 || std::abs(n.dot(l.b - edge.a)) > 1.5)
        continue;
      EXPECT_LE(LineRidgeShare(l, camera, detection.edge_map, options.support_corner_ridge_grey), 0.1);
      ++edges_checked;
    }
  }
  EXPECT_GE(edges_checked, 6);
  // The corners with the grain as an arm propose nothing; the cube's own corners still do.
  const std::vector<ImageCorner> corners = FindCorners(detection.lines, options);
  const int grain_edge = JoinCollinearLines(detection.lines).representative[static_cast<size_t>(grain)];
  std::vector<bool> grain_corner(corners.size());
  for (size_t c = 0; c < corners.size(); ++c) {
    grain_corner[c] = corners[c].segments[0] == grain_edge || corners[c].segments[1] == grain_edge;
  }
  ASSERT_NE(std::count(grain_corner.begin(), grain_corner.end(), true), 0)
      << "no corner has the grain as an arm";
  const std::vector<SupportHypothesis> filtered =
      SupportHypotheses(library, camera, detection, corners, {SupportPlane{}}, options);
  ASSERT_FALSE(filtered.empty());
  EXPECT_LT((filtered.front().world_T_object.translation - truth.translation).norm(), 0.002);
  for (const SupportHypothesis& h : filtered) EXPECT_FALSE(grain_corner[static_cast<size_t>(h.corner)]);
  // Given only the grain's corners and no support threshold, they propose poses without the filter
  // (a grain line and the cube's vertical edge make a top corner) and none with it.
  std::vector<ImageCorner> grain_corners;
  for (size_t c = 0; c < corners.size(); ++c) {
    if (grain_corner[c]) grain_corners.push_back(corners[c]);
  }
  RecognizerOptions any_support = options;
  any_support.support_min_score = 0;
  EXPECT_TRUE(
      SupportHypotheses(library, camera, detection, grain_corners, {SupportPlane{}}, any_support).empty());
  any_support.support_corner_ridge_min_corners = static_cast<int>(grain_corners.size()) + 1;  // not cluttered
  EXPECT_FALSE(
      SupportHypotheses(library, camera, detection, grain_corners, {SupportPlane{}}, any_support).empty());
  any_support.support_corner_ridge_min_corners = static_cast<int>(grain_corners.size());
  EXPECT_TRUE(
      SupportHypotheses(library, camera, detection, grain_corners, {SupportPlane{}}, any_support).empty());
  any_support.support_corner_ridge_share = 0;  // off
  EXPECT_FALSE(
      SupportHypotheses(library, camera, detection, grain_corners, {SupportPlane{}}, any_support).empty());
  EXPECT_GT(clutter, static_cast<int>(corners.size())) << "by default this image is not cluttered";
}

// LineRidgeShareAtLeast, which stops looking once the rest of the samples cannot change the
// answer, answers as LineRidgeShare's share compared with the threshold: on the lines of two dev-set
// images (wood grain, block edges, shadows), their halves, the lines turned round, and the lines
// drawn on three times as long (dozens of them leaving the image: samples not counted), at thresholds
// from below 0 to above 1 and NaN, for two grey-level margins.
TEST(HypothesisFitTest, TheRidgeShareThresholdIsDecidedAsTheWholeShareDecidesIt) {
  const std::vector<dev::Case> cases = dev::Cases(dev::Truth());
  ASSERT_GE(cases.size(), 2u);
  int partly = 0, above_half = 0, below_half = 0, compared = 0, leaving = 0;
  for (size_t k : {size_t{0}, cases.size() - 1}) {
    const cv::Mat image = cv::imread(cases[k].image_path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty()) << cases[k].image_path;
    const auto camera = Camera::FromSpec(cases[k].camera);
    ASSERT_TRUE(camera.ok()) << camera.status().message();
    const LineDetection detection = DetectLinesAndEdges(image, *camera, RecognizerOptions{});
    ASSERT_GT(detection.lines.size(), 50u);
    for (const ImageLine& l : detection.lines) {
      const Eigen::Vector2d middle = 0.5 * (l.a + l.b);
      leaving += !camera->InImage(camera->DistortPixel(l.a + 3 * (l.b - l.a)));
      for (const ImageLine& line : {l, ImageLine{l.b, l.a}, ImageLine{l.a, middle}, ImageLine{middle, l.b},
                                    ImageLine{l.a, l.a + 3 * (l.b - l.a)}}) {
        for (double min_grey : {8.0, 4.0}) {
          const double share = LineRidgeShare(line, *camera, detection.edge_map, min_grey);
          partly += share > 0 && share < 1;
          above_half += share >= 0.5;
          below_half += share < 0.5;
          for (double threshold : {-0.1, 0.0, 0.1, 0.25, 1.0 / 3, 0.5, 2.0 / 3, 0.8, 1.0, 1.5, share,
                                   std::numeric_limits<double>::quiet_NaN()}) {
            ASSERT_EQ(LineRidgeShareAtLeast(line, *camera, detection.edge_map, min_grey, threshold),
                      share >= threshold)
                << "line (" << line.a.transpose() << ") - (" << line.b.transpose() << "), share " << share
                << ", threshold " << threshold;
            ++compared;
          }
        }
      }
    }
  }
  // The lines cover the cases that can go wrong: shares strictly between 0 and 1, both answers, and
  // lines drawn on past the image's edge (samples left out of the count).
  EXPECT_GE(leaving, 20);
  EXPECT_GE(partly, 100);
  EXPECT_GE(above_half, 20);
  EXPECT_GE(below_half, 100);
  EXPECT_GT(compared, 10000);
}

// MatchEdges passes over the lines outside the predicted edges' bounding box (grown by the match
// distance) without testing them: the matches are those of testing every line against every edge
// by the rule (nearly parallel, both ends within the distance, overlapping by half its length; the
// nearest edge). Lines of every kind around a bar: on its edges, beside them, across, far away.
TEST(HypothesisFitTest, MatchEdgesFindsWhatTestingEveryLineAgainstEveryEdgeFinds) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  const geometry::Pose3 camera_T_bar = camera.camera_T_world() * OnTable(bar.box_size_m, 0.01, -0.02, 0.7);
  std::vector<ImageLine> lines = EdgeLines(bar, K, camera_T_bar);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 3000; ++i) {
    const ImageLine& edge = lines[static_cast<size_t>(i) % 9];
    const Eigen::Vector2d dir = (edge.b - edge.a).normalized(), n(-dir.y(), dir.x());
    const Eigen::Vector2d start =
        edge.a + (0.5 + 0.8 * u(rng)) * (edge.b - edge.a) + 12 * u(rng) * n +
        (i % 3 == 0 ? Eigen::Vector2d(300 * u(rng), 300 * u(rng)) : Eigen::Vector2d::Zero());
    const double angle = (i % 2 ? 0.15 : 1.5) * u(rng);
    const Eigen::Vector2d d = Eigen::Rotation2Dd(angle) * dir;
    lines.push_back({start, start + (5 + 60 * std::abs(u(rng))) * d});
  }
  for (const double distance : {2.0, 6.0, 18.0}) {
    const double max_angle = 8 * M_PI / 180;
    const EdgeMatchSet set = MatchEdges(bar, K, camera_T_bar, lines, distance, max_angle);
    // The rule, line by line and edge by edge.
    const uint16_t visible = VisibleBoxEdges(bar.box_size_m, camera_T_bar.Inverse().translation);
    std::vector<int> segments, edges;
    for (size_t s = 0; s < lines.size(); ++s) {
      const ImageLine& l = lines[s];
      const Eigen::Vector2d ldir = (l.b - l.a).normalized();
      int best = -1;
      double best_d = 1e300;
      for (int e = 0; e < 12; ++e) {
        if (!(visible >> e & 1)) continue;
        const Eigen::Vector2d a =
            (K * (camera_T_bar * BoxVertex(bar.box_size_m, kBoxEdges[e][0]))).hnormalized();
        const Eigen::Vector2d b =
            (K * (camera_T_bar * BoxVertex(bar.box_size_m, kBoxEdges[e][1]))).hnormalized();
        const Eigen::Vector2d dir = (b - a).normalized(), n(-dir.y(), dir.x());
        if (std::abs(ldir.dot(dir)) < std::cos(max_angle)) continue;
        const double da = std::abs(n.dot(l.a - a)), db = std::abs(n.dot(l.b - a));
        if (da > distance || db > distance) continue;
        const double ta = dir.dot(l.a - a), tb = dir.dot(l.b - a);
        if (std::min(std::max(ta, tb), (b - a).norm()) - std::max(std::min(ta, tb), 0.0) < 0.5 * l.Length())
          continue;
        if (da + db < best_d) best = e, best_d = da + db;
      }
      if (best >= 0) segments.push_back(static_cast<int>(s)), edges.push_back(best);
    }
    EXPECT_EQ(set.segments, segments) << "match distance " << distance;
    ASSERT_EQ(set.matches.size(), edges.size());
    for (size_t i = 0; i < edges.size(); ++i) EXPECT_EQ(set.matches[i].edge, edges[i]);
    EXPECT_GT(segments.size(), 50u);               // lines beside the edges match ...
    EXPECT_LT(segments.size(), lines.size() / 2);  // ... and most do not
  }
}

// Random lines for the pair searches below: pieces of edges split at random (collinear within a
// few degrees, some across the 0/180 deg wrap of directions), L junctions with gaps, and lines
// anywhere, 2-300 px long; one of zero length, one not finite, and, with far_line, one far off
// (which makes the grid's cells large).
std::vector<ImageLine> PairSearchLines(unsigned seed, bool far_line) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<ImageLine> lines;
  const Eigen::Vector2d size(640, 480);
  for (int k = 0; k < 120; ++k) {
    const Eigen::Vector2d start(size.x() * u(rng), size.y() * u(rng));
    const double angle = k % 4 == 0 ? 0.03 * (u(rng) - 0.5) + (u(rng) < 0.5 ? 0 : M_PI) : 2 * M_PI * u(rng);
    const Eigen::Vector2d dir(std::cos(angle), std::sin(angle)), normal(-dir.y(), dir.x());
    const double length = 2 + 298 * u(rng);
    switch (k % 3) {
      case 0: {  // an edge in pieces: gaps up to 60 px, up to 2 px and 4 deg off its line
        double t = 0;
        for (int piece = 0; piece < 4; ++piece) {
          const double piece_length = 5 + 60 * u(rng);
          const Eigen::Vector2d turned = Eigen::Rotation2Dd(0.07 * (u(rng) - 0.5)) * dir;
          const Eigen::Vector2d a = start + t * dir + 2 * (u(rng) - 0.5) * normal;
          lines.push_back({a, a + piece_length * turned});
          t += piece_length + 60 * u(rng);
        }
        break;
      }
      case 1: {  // an L junction: the second line starts up to 20 px from the first's end
        const Eigen::Vector2d b = start + length * dir;
        const Eigen::Vector2d turned = Eigen::Rotation2Dd(0.3 + 2.5 * u(rng)) * dir;
        const Eigen::Vector2d c = b + 20 * Eigen::Vector2d(u(rng) - 0.5, u(rng) - 0.5);
        lines.push_back({start, b});
        lines.push_back({c, c + (2 + 298 * u(rng)) * turned});
        break;
      }
      default:
        lines.push_back({start, start + length * dir});
    }
  }
  if (far_line) lines.push_back({Eigen::Vector2d(1e7, -3e6), Eigen::Vector2d(1e7 + 40, -3e6 + 30)});
  lines.push_back({Eigen::Vector2d(100, 100), Eigen::Vector2d(100, 100)});
  lines.push_back({Eigen::Vector2d(std::nan(""), 100), Eigen::Vector2d(120, 100)});
  std::shuffle(lines.begin(), lines.end(), rng);
  return lines;
}

// FindJunctions looks only at the lines with an end near one of each line's ends: it finds what
// testing every pair finds, in the same order, for any gap and any set of lines considered; a
// line with an end that is not finite meets none.
TEST(HypothesisFitTest, JunctionsAreThoseOfTestingEveryPair) {
  for (const unsigned seed : {1u, 2u, 3u, 4u, 5u, 6u}) {
    const std::vector<ImageLine> lines = PairSearchLines(seed, seed > 3);
    std::vector<char> some(lines.size());
    for (size_t i = 0; i < lines.size(); ++i) some[i] = i % 3 != 0;
    for (const double gap : {4.0, 12.0, 40.0}) {
      for (const std::vector<char>& considered : {std::vector<char>{}, some}) {
        const std::vector<LineJunction> found = FindJunctions(lines, gap, considered);
        std::vector<LineJunction> all;
        const int n = static_cast<int>(lines.size());
        auto takes_part = [&](int i) {
          const ImageLine& l = lines[static_cast<size_t>(i)];
          return (considered.empty() || considered[static_cast<size_t>(i)] != 0) && l.a.allFinite() &&
                 l.b.allFinite();
        };
        for (int i = 0; i < n; ++i) {
          for (int j = i + 1; j < n; ++j) {
            if (!takes_part(i) || !takes_part(j)) continue;
            const ImageLine &li = lines[static_cast<size_t>(i)], &lj = lines[static_cast<size_t>(j)];
            const Eigen::Vector2d di = (li.b - li.a).normalized(), dj = (lj.b - lj.a).normalized();
            const double s = Cross2(di, dj);
            if (std::abs(s) < std::sin(15.0 * M_PI / 180)) continue;
            const double g = std::max(gap, 0.25 * std::min(li.Length(), lj.Length()));
            for (int ei = 0; ei < 2; ++ei) {
              for (int ej = 0; ej < 2; ++ej) {
                const Eigen::Vector2d p = ei == 0 ? li.a : li.b, q = ej == 0 ? lj.a : lj.b;
                const Eigen::Vector2d x = p + Cross2(q - p, dj) / s * di;
                if ((p - q).squaredNorm() <= 4 * g * g && (x - p).norm() <= g && (x - q).norm() <= g) {
                  all.push_back({i, ei, j, ej, x});
                }
              }
            }
          }
        }
        ASSERT_EQ(found.size(), all.size()) << "seed " << seed << " gap " << gap;
        for (size_t k = 0; k < all.size(); ++k) {
          EXPECT_EQ(found[k].first, all[k].first);
          EXPECT_EQ(found[k].first_end, all[k].first_end);
          EXPECT_EQ(found[k].second, all[k].second);
          EXPECT_EQ(found[k].second_end, all[k].second_end);
          EXPECT_EQ(found[k].point, all[k].point);
        }
        EXPECT_GT(all.size(), considered.empty() ? 80u : 30u) << "seed " << seed << " gap " << gap;
      }
    }
  }
}

// JoinCollinearLines tests each line only against those of nearly its direction: it joins what
// testing every pair joins (the same pieces, which fixes the longest piece and the extent), across
// the 0/180 deg wrap too.
TEST(HypothesisFitTest, JoiningCollinearPiecesTriesEveryPairThatCanJoin) {
  for (const unsigned seed : {1u, 2u, 3u}) {
    const std::vector<ImageLine> lines = PairSearchLines(seed, true);
    const int n = static_cast<int>(lines.size());
    // Every pair: collinear within 3 deg and 1.5 px, at most 40 px apart along the longer line.
    std::vector<int> parent(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) parent[static_cast<size_t>(i)] = i;
    auto find = [&](int i) {
      while (parent[static_cast<size_t>(i)] != i) i = parent[static_cast<size_t>(i)];
      return i;
    };
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n; ++j) {
        const ImageLine &li = lines[static_cast<size_t>(i)], &lj = lines[static_cast<size_t>(j)];
        if (!(li.Length() >= 1e-9 && lj.Length() >= 1e-9) || !li.a.allFinite() || !li.b.allFinite() ||
            !lj.a.allFinite() || !lj.b.allFinite()) {
          continue;
        }
        const Eigen::Vector2d di = (li.b - li.a) / li.Length();
        if (std::abs(di.dot((lj.b - lj.a) / lj.Length())) < std::cos(3 * M_PI / 180)) continue;
        const ImageLine& longer = li.Length() >= lj.Length() ? li : lj;
        const ImageLine& shorter = li.Length() >= lj.Length() ? lj : li;
        const Eigen::Vector2d dl = (longer.b - longer.a).normalized(), nl(-dl.y(), dl.x());
        if (std::abs(nl.dot(shorter.a - longer.a)) > 1.5 || std::abs(nl.dot(shorter.b - longer.a)) > 1.5)
          continue;
        const double ta = di.dot(lj.a - li.a), tb = di.dot(lj.b - li.a);
        if (std::max(std::min(ta, tb) - li.Length(), -std::max(ta, tb)) > 40) continue;
        parent[static_cast<size_t>(find(j))] = find(i);
      }
    }
    const JoinedLines joined = JoinCollinearLines(lines);
    int in_joins = 0;
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        const bool together =
            joined.representative[static_cast<size_t>(i)] == joined.representative[static_cast<size_t>(j)];
        ASSERT_EQ(together, find(i) == find(j)) << "seed " << seed << " lines " << i << " " << j;
      }
      in_joins += joined.representative[static_cast<size_t>(i)] != i;
    }
    EXPECT_GT(in_joins, 40) << "seed " << seed;
  }
}

// The part of each line inside the image (Liang-Barsky clipping; the synthetic camera has no
// distortion): what a detector finds of edges cut by the image border.
std::vector<ImageLine> ClippedToImage(const std::vector<ImageLine>& lines, const Camera& camera) {
  std::vector<ImageLine> out;
  for (const ImageLine& l : lines) {
    const Eigen::Vector2d d = l.b - l.a;
    double t0 = 0, t1 = 1;
    const double p[4] = {-d.x(), d.x(), -d.y(), d.y()};
    const double q[4] = {l.a.x(), camera.width() - 1 - l.a.x(), l.a.y(), camera.height() - 1 - l.a.y()};
    bool inside = true;
    for (int k = 0; k < 4 && inside; ++k) {
      if (p[k] == 0) {
        inside = q[k] >= 0;
      } else if (p[k] < 0) {
        t0 = std::max(t0, q[k] / p[k]);
      } else {
        t1 = std::min(t1, q[k] / p[k]);
      }
    }
    if (inside && t1 - t0 > 1e-9) out.push_back({l.a + t0 * d, l.a + t1 * d});
  }
  return out;
}

// A block cut by the image's left border: the lines on its edges inside the image match about the
// same share of what the image can show as lines on a whole block do, while of the whole visible
// edges they match only about that share times the part inside (RecognizerOptions::
// matched_share_in_image). A block wholly inside, and one behind the camera, keep their share.
TEST(HypothesisFitTest, TheMatchedShareCountsOnlyTheOutlineInsideTheImage) {
  const Camera camera = SyntheticCamera();
  const Eigen::Matrix3d K = camera.K();
  const Model bar = Bar();
  const double max_angle = 8 * M_PI / 180;
  const geometry::Pose3 world_T_inside = OnTable(bar.box_size_m, 0.01, -0.02, 0.7);
  const geometry::Pose3 camera_T_inside = camera.camera_T_world() * world_T_inside;
  ASSERT_DOUBLE_EQ(VisibleOutlineInImage(bar, camera, camera_T_inside), 1);
  const EdgeMatchSet whole =
      MatchEdges(bar, K, camera_T_inside, EdgeLines(bar, K, camera_T_inside), 6, max_angle);
  EdgeMatchSet same = whole;
  MatchedWithinImage(bar, camera, camera_T_inside, same);
  EXPECT_EQ(same.matched_fraction, whole.matched_fraction);
  EXPECT_EQ(same.visible_length_px, whole.visible_length_px);
  EXPECT_NEAR(whole.matched_fraction, 0.8, 0.01);  // the middle 80 % of each edge

  geometry::Pose3 world_T_cut = world_T_inside;
  while (VisibleOutlineInImage(bar, camera, camera.camera_T_world() * world_T_cut) > 0.55) {
    world_T_cut.translation += Eigen::Vector3d(-0.001, -0.001, 0);  // towards the image's left
  }
  const geometry::Pose3 camera_T_cut = camera.camera_T_world() * world_T_cut;
  const double inside = VisibleOutlineInImage(bar, camera, camera_T_cut);
  EdgeMatchSet cut =
      MatchEdges(bar, K, camera_T_cut, ClippedToImage(EdgeLines(bar, K, camera_T_cut), camera), 6, max_angle);
  const EdgeMatchSet before = cut;
  EXPECT_LT(before.matched_fraction, 0.6);
  MatchedWithinImage(bar, camera, camera_T_cut, cut);
  EXPECT_NEAR(cut.visible_length_px, inside * before.visible_length_px, 1e-9);
  EXPECT_NEAR(cut.matched_fraction, before.matched_fraction / inside, 1e-9);
  EXPECT_NEAR(cut.matched_fraction, 0.8, 0.1);
  EXPECT_GT(cut.matched_fraction, RecognizerOptions{}.min_matched_edge_fraction);
  // Not for a pose with less of its outline inside than asked (RecognizerOptions::
  // matched_share_min_in_image): there a wrong model reaching past the border is unconstrained.
  EdgeMatchSet mostly_outside = before;
  MatchedWithinImage(bar, camera, camera_T_cut, mostly_outside, inside + 0.01);
  EXPECT_EQ(mostly_outside.matched_fraction, before.matched_fraction);

  const geometry::Pose3 behind(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, -1));
  EdgeMatchSet far = before;
  MatchedWithinImage(bar, camera, behind, far);
  EXPECT_EQ(far.matched_fraction, before.matched_fraction);
}

// The edge map keeps the 16-bit Sobel images only: the magnitude computed where asked is, at every
// pixel, the float cv::magnitude gives on float copies of them, and the unit gradient is the
// Sobel vector divided by it.
TEST(HypothesisFitTest, TheGradientIsComputedWhereAskedAsOpenCvComputesIt) {
  const Camera camera = SyntheticCamera();
  const Model bar = Bar();
  const cv::Mat image = RenderBox(camera, bar.box_size_m, OnTable(bar.box_size_m, 0.01, -0.02, 0.7));
  const LineDetection detection = DetectLinesAndEdges(image, camera, RecognizerOptions());
  const EdgeMap& edge_map = detection.edge_map;
  ASSERT_EQ(edge_map.dx.type(), CV_16S);
  cv::Mat fdx, fdy, magnitude;
  edge_map.dx.convertTo(fdx, CV_32F);
  edge_map.dy.convertTo(fdy, CV_32F);
  cv::magnitude(fdx, fdy, magnitude);
  int positive = 0;
  for (int y = 0; y < magnitude.rows; ++y) {
    for (int x = 0; x < magnitude.cols; ++x) {
      const float m = magnitude.at<float>(y, x);
      ASSERT_EQ(GradientMagnitude(edge_map, x, y), m) << x << ", " << y;
      const auto unit = UnitGradient(edge_map, x, y);
      ASSERT_EQ(unit.has_value(), m > 0) << x << ", " << y;
      if (!unit) continue;
      ++positive;
      EXPECT_EQ((*unit)[0], fdx.at<float>(y, x) / m);
      EXPECT_EQ((*unit)[1], fdy.at<float>(y, x) / m);
    }
  }
  EXPECT_GT(positive, 10000);
}

// The edge image holds 255 on chains long enough for a line and 1 on shorter ones, and an edge
// query passes over the shorter ones.
TEST(HypothesisFitTest, EdgeQueriesPassOverChainsTooShortForALine) {
  const Camera camera = SyntheticCamera();
  const Model bar = Bar();
  cv::Mat image = RenderBox(camera, bar.box_size_m, OnTable(bar.box_size_m, 0.01, -0.02, 0.7));
  // A few specks on the table: short closed Canny chains.
  for (int i = 0; i < 6; ++i) cv::circle(image, cv::Point(40 + 25 * i, 40), 1, cv::Scalar(0), cv::FILLED);
  const LineDetection detection = DetectLinesAndEdges(image, camera, RecognizerOptions());
  int on_chain = 0, off_chain = 0;
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      const uint8_t v = detection.edge_map.edges.at<uint8_t>(y, x);
      ASSERT_TRUE(v == 0 || v == kEdgeOnChain || v == kEdgeOffChain) << int{v} << " at " << x << ", " << y;
      on_chain += v == kEdgeOnChain;
      off_chain += v == kEdgeOffChain;
    }
  }
  EXPECT_GT(on_chain, 500);
  // By hand: one edge pixel with its gradient along +x, found across a vertical edge through it as
  // a chain pixel and not as a pixel of a short chain.
  EdgeMap map;
  map.edges = cv::Mat::zeros(20, 20, CV_8U);
  map.dx = cv::Mat::zeros(20, 20, CV_16S);
  map.dy = cv::Mat::zeros(20, 20, CV_16S);
  map.dx.at<int16_t>(10, 10) = 400;
  const Eigen::Vector2d at(9.2, 10), across(1, 0);
  map.edges.at<uint8_t>(10, 10) = kEdgeOffChain;
  EXPECT_FALSE(EdgePixelAcross(map, at, across, 2));
  map.edges.at<uint8_t>(10, 10) = kEdgeOnChain;
  const std::optional<EdgePixel> found = EdgePixelAcross(map, at, across, 2);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->x, 10);
  EXPECT_EQ(found->gx, 1.0f);
  EXPECT_EQ(found->gy, 0.0f);
  EXPECT_GT(off_chain, 0);  // the specks
}

// NearEdgeBits is cv::dilate with a (2 kEdgeNearPx + 1) square, packed 8 pixels to a byte: on
// random edge images of every width from 1 to 140 px (words of 64 bits, bytes, and what is left
// over), sparse and dense, with edges on the borders.
TEST(HypothesisFitTest, NearEdgeBitsAreTheDilatedEdgesPacked) {
  std::mt19937 rng(5);
  const cv::Mat square =
      cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * kEdgeNearPx + 1, 2 * kEdgeNearPx + 1));
  int set_bits = 0, clear_bits = 0;
  for (int cols = 1; cols <= 140; ++cols) {
    for (double density : {0.002, 0.03, 0.3}) {
      const int rows = 1 + static_cast<int>(rng() % 12);
      cv::Mat edges = cv::Mat::zeros(rows, cols, CV_8U);
      std::bernoulli_distribution on(density);
      for (int y = 0; y < rows; ++y) {
        for (int x = 0; x < cols; ++x) {
          if (on(rng)) edges.at<uint8_t>(y, x) = static_cast<uint8_t>(1 + rng() % 255);
        }
      }
      if (cols % 7 == 0) edges.at<uint8_t>(rows - 1, cols - 1) = 255;  // the last byte's last bit
      cv::Mat dilated;
      cv::dilate(edges, dilated, square);
      const cv::Mat near = NearEdgeBits(edges);
      ASSERT_EQ(near.rows, rows);
      ASSERT_EQ(near.cols, (cols + 7) / 8);
      for (int y = 0; y < rows; ++y) {
        for (int b = 0; b < near.cols; ++b) {
          for (int bit = 0; bit < 8; ++bit) {
            const int x = 8 * b + bit;
            const bool got = (near.at<uint8_t>(y, b) >> bit & 1) != 0;
            const bool want = x < cols && dilated.at<uint8_t>(y, x) != 0;
            ASSERT_EQ(got, want) << cols << " x " << rows << " at (" << x << ", " << y << ")";
            (got ? set_bits : clear_bits)++;
          }
        }
      }
    }
  }
  EXPECT_GT(set_bits, 10000);
  EXPECT_GT(clear_bits, 10000);
}

// EdgePixelAcross (and QuickSupport, by NoEdgeNear) first looks at the dilated edges
// (EdgeMap::near, kEdgeNearPx in x and y) and answers "none" where no edge pixel lies near: the
// same answer as looking along the normal pixel by pixel, for points anywhere in the image (on
// edges, beside them, on blank table) and normals in every direction, the image's axes included.
TEST(HypothesisFitTest, TheDilatedEdgesAnswerEdgeQueriesAsTheEdgesDo) {
  const Camera camera = SyntheticCamera();
  const Model bar = Bar();
  const cv::Mat image = RenderBox(camera, bar.box_size_m, OnTable(bar.box_size_m, 0.01, -0.02, 0.7));
  const LineDetection detection = DetectLinesAndEdges(image, camera, RecognizerOptions());
  ASSERT_FALSE(detection.edge_map.near.empty());
  EdgeMap plain = detection.edge_map;
  plain.near.release();
  std::vector<cv::Point> edge_pixels;
  cv::findNonZero(detection.edge_map.edges, edge_pixels);
  ASSERT_GT(edge_pixels.size(), 500u);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> x(-3, camera.width() + 3), y(-3, camera.height() + 3),
      turn(0, 2 * M_PI), jitter(-3.5, 3.5);
  std::uniform_int_distribution<size_t> pick(0, edge_pixels.size() - 1);
  // Points answered by the dilated edges alone (no edge pixel near), points beside an edge pixel
  // that the search looked at and found none, edge pixels found.
  int blank = 0, beside = 0, found = 0;
  for (int i = 0; i < 200000; ++i) {
    const double a = i % 10 == 0 ? (i / 10 % 4) * M_PI / 2 : turn(rng);
    const Eigen::Vector2d normal(std::cos(a), std::sin(a));
    // Every other point within 3.5 px of an edge pixel (most of the image is blank table): the
    // dilation's border is where a wrong answer would show.
    const cv::Point e = edge_pixels[pick(rng)];
    const Eigen::Vector2d pixel =
        i % 2 ? Eigen::Vector2d(x(rng), y(rng)) : Eigen::Vector2d(e.x + jitter(rng), e.y + jitter(rng));
    for (int offset : {0, 1, 2, 3}) {
      const std::optional<EdgePixel> fast = EdgePixelAcross(detection.edge_map, pixel, normal, offset);
      const std::optional<EdgePixel> slow = EdgePixelAcross(plain, pixel, normal, offset);
      ASSERT_EQ(fast.has_value(), slow.has_value()) << pixel.transpose() << " normal " << normal.transpose();
      if (slow) {
        EXPECT_EQ(fast->x, slow->x);
        EXPECT_EQ(fast->y, slow->y);
        ++found;
      }
    }
    const int cx = static_cast<int>(std::floor(pixel.x() + 0.5)), cy = static_cast<int>(std::floor(pixel.y() + 0.5));
    const bool inside = cx >= 0 && cy >= 0 && cx < camera.width() && cy < camera.height();
    // NoEdgeNear, the support scores' first look, tells where no search finds an edge pixel.
    ASSERT_EQ(NoEdgeNear(detection.edge_map, pixel), inside && !NearEdge(detection.edge_map, cx, cy));
    EXPECT_FALSE(NoEdgeNear(plain, pixel));
    if (!inside) continue;
    if (NoEdgeNear(detection.edge_map, pixel)) {
      ASSERT_FALSE(EdgePixelAcross(plain, pixel, normal, kEdgeNearPx));
      ++blank;
    } else if (!EdgePixelAcross(plain, pixel, normal, kEdgeNearPx)) {
      ++beside;
    }
  }
  EXPECT_GT(found, 50000);   // points on the block's edges were among them
  EXPECT_GT(blank, 90000);   // most points off the edges were answered by the dilated edges alone
  EXPECT_GT(beside, 30000);  // and many near the dilation's border were searched and had none
}

}  // namespace
}  // namespace teachsim::vision
