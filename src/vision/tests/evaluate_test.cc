#include "teachsim/vision/evaluate.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "teachsim/vision/camera.h"

namespace teachsim::vision {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

Eigen::Quaterniond AxisAngle(const Eigen::Vector3d& axis, double angle_rad) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle_rad, axis.normalized()));
}

std::string DevTruthPath() { return std::string(TEACHSIM_SHARED_DIR) + "/data/vision-dev/truth.json"; }

TEST(BoxSymmetriesTest, GroupOrderFollowsEqualSides) {
  EXPECT_EQ(BoxSymmetries({0.09, 0.06, 0.03}).size(), 4u);    // slab: three distinct sides
  EXPECT_EQ(BoxSymmetries({0.09, 0.045, 0.045}).size(), 8u);  // bar: square cross-section
  EXPECT_EQ(BoxSymmetries({0.06, 0.06, 0.015}).size(), 8u);   // plate
  EXPECT_EQ(BoxSymmetries({0.045, 0.045, 0.045}).size(), 24u);
  for (const Eigen::Quaterniond& s : BoxSymmetries({0.045, 0.045, 0.135})) {
    // Every element maps the box's corners onto corners.
    const Eigen::Vector3d half(0.0225, 0.0225, 0.0675);
    const Eigen::Vector3d image = s * half;
    EXPECT_TRUE(image.cwiseAbs().isApprox(half, 1e-12)) << image.transpose();
  }
}

TEST(RotationErrorTest, CubeTurnedByQuarterTurnsIsExact) {
  const auto cube = BoxSymmetries({0.045, 0.045, 0.045});
  const Eigen::Quaterniond truth = AxisAngle({0.3, -0.5, 0.8}, 0.7);
  for (const Eigen::Vector3d& axis : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0, 1)}) {
    // Turning the cube about its own axis by 90 deg gives the same cube.
    EXPECT_NEAR(SymmetricRotationError(truth, truth * AxisAngle(axis, 90 * kDeg), cube), 0.0, 1e-9);
    // ... and 1 deg more is 1 deg off, whichever axis.
    EXPECT_NEAR(SymmetricRotationError(truth, truth * AxisAngle(axis, 91 * kDeg), cube), 1 * kDeg, 1e-9);
  }
  EXPECT_NEAR(SymmetricRotationError(truth, AxisAngle({1, 1, 0}, 1 * kDeg) * truth, cube), 1 * kDeg, 1e-9);
  // Without symmetry the quarter turn is a quarter turn.
  EXPECT_NEAR(SymmetricRotationError(truth, truth * AxisAngle({1, 0, 0}, 90 * kDeg), {Eigen::Quaterniond::Identity()}),
              90 * kDeg, 1e-9);
}

TEST(RotationErrorTest, BarAboutItsLongAxisIsEqualOnlyForASquareSection) {
  const Eigen::Quaterniond truth = AxisAngle({0, 0, 1}, 0.4);
  const Eigen::Quaterniond turned = truth * AxisAngle({1, 0, 0}, 90 * kDeg);  // x: the long axis
  EXPECT_NEAR(SymmetricRotationError(truth, turned, BoxSymmetries({0.09, 0.045, 0.045})), 0.0, 1e-9);
  EXPECT_NEAR(SymmetricRotationError(truth, turned, BoxSymmetries({0.09, 0.06, 0.03})), 90 * kDeg, 1e-9);
  // Half a turn about any axis is a symmetry of every box.
  EXPECT_NEAR(SymmetricRotationError(truth, truth * AxisAngle({0, 1, 0}, 180 * kDeg), BoxSymmetries({0.09, 0.06, 0.03})),
              0.0, 1e-9);
  // A quarter turn about the long axis leaves a 3-sided box 90 deg away however it is measured.
  EXPECT_NEAR(SymmetricRotationError(truth, truth * AxisAngle({0, 0, 1}, 90 * kDeg), BoxSymmetries({0.09, 0.06, 0.03})),
              90 * kDeg, 1e-9);
}

TEST(RotationErrorTest, SmallErrorsSurviveAnySymmetricRelabelling) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0, 1);
  std::uniform_real_distribution<double> angle(0.01, 5.0);
  for (const Eigen::Vector3d& size :
       {Eigen::Vector3d(0.09, 0.06, 0.03), Eigen::Vector3d(0.06, 0.06, 0.015), Eigen::Vector3d(0.045, 0.045, 0.045)}) {
    const auto group = BoxSymmetries(size);
    for (int i = 0; i < 50; ++i) {
      const Eigen::Quaterniond truth = AxisAngle({n(rng), n(rng), n(rng)}, 3 * angle(rng) / 5);
      const Eigen::Quaterniond equal = truth * group[static_cast<std::size_t>(i) % group.size()];
      const double error = angle(rng) * kDeg;
      const Eigen::Quaterniond estimate = AxisAngle({n(rng), n(rng), n(rng)}, error) * equal;
      EXPECT_NEAR(SymmetricRotationError(truth, estimate, group), error, 1e-9);
    }
  }
}

TEST(PositionErrorTest, SplitsAlongTheLineOfSight) {
  const Eigen::Vector3d camera(0, 0, 1);
  const Eigen::Vector3d truth(0.3, 0, 0.6);  // sight line (0.6, 0, -0.8)
  const Eigen::Vector3d sight(0.6, 0, -0.8), across(0, 1, 0), across2(0.8, 0, 0.6);
  const PositionError e = SplitPositionError(truth, truth + 0.002 * sight + 0.001 * across, camera);
  EXPECT_NEAR(e.along_m, 0.002, 1e-12);
  EXPECT_NEAR(e.across_m, 0.001, 1e-12);
  const PositionError f = SplitPositionError(truth, truth - 0.003 * sight + 0.004 * across2, camera);
  EXPECT_NEAR(f.along_m, 0.003, 1e-12);
  EXPECT_NEAR(f.across_m, 0.004, 1e-12);
}

std::vector<TruthObject> TwoCubesAndASlab() {
  TruthObject a{"a", "cube45", geometry::Pose3(AxisAngle({0, 0, 1}, 0.3), {0.1, 0, 0.0225}), 1.0, 4000};
  TruthObject b{"b", "cube45", geometry::Pose3(AxisAngle({0, 0, 1}, 1.1), {-0.1, 0.05, 0.0225}), 0.5, 2000};
  TruthObject c{"c", "slab", geometry::Pose3(AxisAngle({0, 0, 1}, -0.2), {0, -0.1, 0.015}), 0.2, 800};
  return {a, b, c};
}

const std::map<std::string, Eigen::Vector3d> kSizes = {{"cube45", {0.045, 0.045, 0.045}},
                                                       {"slab", {0.09, 0.06, 0.03}}};

TEST(EvaluateImageTest, MatchesByModelAndPoseAndCountsTheRestAsFalse) {
  const auto truth = TwoCubesAndASlab();
  const Eigen::Vector3d camera(0.5, 0, 0.5);
  std::vector<Detection> detections;
  // a, found with a symmetric orientation (a quarter turn about z) and a small error.
  geometry::Pose3 pa = truth[0].world_T_object;
  pa.rotation = pa.rotation * AxisAngle({0, 0, 1}, 90 * kDeg) * AxisAngle({1, 0, 0}, 0.4 * kDeg);
  pa.translation += Eigen::Vector3d(0, 0.0005, 0);  // across the view (the camera looks along x-z)
  detections.push_back({"cube45", pa, 0.9, 0.3});
  // A duplicate of a with a lower score: false.
  detections.push_back({"cube45", truth[0].world_T_object, 0.5, 0.2});
  // b's place but the wrong model: false.
  detections.push_back({"slab", truth[1].world_T_object, 0.8, 0.2});
  // b, 30 mm off across the view: false (the limit is 15 mm).
  geometry::Pose3 far = truth[1].world_T_object;
  far.translation.y() += 0.03;
  detections.push_back({"cube45", far, 0.7, 0.2});
  // c, found.
  detections.push_back({"slab", truth[2].world_T_object, 0.6, 0.1});
  auto result = EvaluateImage(truth, detections, kSizes, camera, MatchOptions{});
  ASSERT_TRUE(result.ok()) << result.status().message();
  ASSERT_EQ(result->objects.size(), 3u);
  EXPECT_EQ(result->objects[0].detection, 0);
  EXPECT_NEAR(result->objects[0].rotation_error_rad, 0.4 * kDeg, 1e-9);
  EXPECT_NEAR(result->objects[0].position_error.across_m, 0.0005, 1e-9);
  EXPECT_NEAR(result->objects[0].position_error.along_m, 0.0, 1e-9);
  EXPECT_EQ(result->objects[1].detection, -1);
  EXPECT_EQ(result->objects[2].detection, 4);
  EXPECT_EQ(result->false_positives, 3);
  EXPECT_EQ(result->detection_truth, (std::vector<int>{0, -1, -1, -1, 2}));

  SummaryBuilder builder;
  builder.Add(*result, 12.0);
  builder.Add(*EvaluateImage(truth, {}, kSizes, camera, MatchOptions{}), 4.0);
  const Summary s = builder.Build();
  EXPECT_EQ(s.images, 2);
  EXPECT_DOUBLE_EQ(s.Recall(VisibilityBin::kHigh), 0.5);
  EXPECT_DOUBLE_EQ(s.Recall(VisibilityBin::kMedium), 0.0);
  EXPECT_DOUBLE_EQ(s.Recall(VisibilityBin::kLow), 0.5);
  EXPECT_DOUBLE_EQ(s.FalsePositivesPerImage(), 1.5);
  EXPECT_EQ(s.within_goals, 2);  // a: 0.4 deg, 0.5 mm across; c: exact
  EXPECT_EQ(s.poses.rotation_deg.count, 2);
  EXPECT_NEAR(s.poses.rotation_deg.max, 0.4, 1e-9);
  EXPECT_DOUBLE_EQ(s.time_ms.median, 8.0);
  const json::Json j = SummaryToJson(s);
  EXPECT_EQ(j["recall"]["0.4-0.7"]["objects"], 2);
  EXPECT_EQ(j["false_positives"], 3);
}

// A camera 0.6 m above the table looking straight down (its x along the world's x, y against it).
Camera TopDownCamera(const Distortion& distortion = {}) {
  const Eigen::Matrix3d world_R_camera = Eigen::Vector3d(1, -1, -1).asDiagonal();
  return Camera(Intrinsics{800, 800, 319.5, 239.5}, distortion,
                geometry::Pose3(Eigen::Quaterniond(world_R_camera), {0, 0, 0.6}), 640, 480);
}

TEST(ProjectionErrorTest, IsZeroUnderSymmetryAndGrowsWithTheShiftInTheImage) {
  const Camera camera = TopDownCamera({-0.2, 0.01, 0, 0, 0});
  const Eigen::Vector3d bar(0.09, 0.045, 0.045);
  const auto symmetries = BoxSymmetries(bar);
  const geometry::Pose3 truth(AxisAngle({0, 0, 1}, 0.3), {0.02, -0.01, 0.0225});
  EXPECT_NEAR(SymmetricProjectionRms(camera, bar, truth, truth, symmetries), 0.0, 1e-9);
  // The bar turned a half turn about its long axis, or a quarter turn (square section): the same bar.
  for (double turn : {90.0, 180.0}) {
    const geometry::Pose3 turned(truth.rotation * AxisAngle({1, 0, 0}, turn * kDeg), truth.translation);
    EXPECT_NEAR(SymmetricProjectionRms(camera, bar, truth, turned, symmetries), 0.0, 1e-9) << turn;
    // Without the symmetry its corners land elsewhere.
    EXPECT_GT(SymmetricProjectionRms(camera, bar, truth, turned, {Eigen::Quaterniond::Identity()}), 10.0)
        << turn;
  }
  // Without distortion, a shift of 1 mm across the view moves each corner by f * 1 mm / its depth
  // (0.555-0.6 m): 1.33-1.44 px.
  const Camera pinhole = TopDownCamera();
  geometry::Pose3 shifted = truth;
  shifted.translation.x() += 0.001;
  const double rms = SymmetricProjectionRms(pinhole, bar, truth, shifted, symmetries);
  EXPECT_GT(rms, 800 * 0.001 / 0.6);
  EXPECT_LT(rms, 800 * 0.001 / 0.555);
  // A pose whose corners are behind the camera has no figure.
  geometry::Pose3 behind = truth;
  behind.translation.z() = 1.0;
  EXPECT_TRUE(std::isnan(SymmetricProjectionRms(pinhole, bar, truth, behind, symmetries)));
}

TEST(EvaluateImageTest, WithTheCameraEachMatchHasItsProjectionErrorAgainstTheTruth) {
  const auto truth = TwoCubesAndASlab();
  const Camera camera = TopDownCamera();
  geometry::Pose3 slab = truth[2].world_T_object;
  slab.translation.y() += 0.0005;
  const std::vector<Detection> detections = {{"cube45", truth[0].world_T_object, 0.9}, {"slab", slab, 0.8}};
  const Eigen::Vector3d eye = camera.world_T_camera().translation;
  auto with = EvaluateImage(truth, detections, kSizes, eye, MatchOptions{}, &camera);
  ASSERT_TRUE(with.ok()) << with.status().message();
  EXPECT_NEAR(with->objects[0].truth_projection_rms_px, 0.0, 1e-9);
  EXPECT_TRUE(std::isnan(with->objects[1].truth_projection_rms_px));  // missed
  EXPECT_NEAR(with->objects[2].truth_projection_rms_px,
              SymmetricProjectionRms(camera, kSizes.at("slab"), truth[2].world_T_object, slab,
                                     BoxSymmetries(kSizes.at("slab"))),
              1e-12);
  EXPECT_GT(with->objects[2].truth_projection_rms_px, 0.6);
  SummaryBuilder builder;
  builder.Add(*with, 1.0);
  const Summary s = builder.Build();
  EXPECT_EQ(s.poses.truth_projection_rms_px.count, 2);
  EXPECT_DOUBLE_EQ(s.poses.truth_projection_rms_px.max, with->objects[2].truth_projection_rms_px);
  EXPECT_DOUBLE_EQ(SummaryToJson(s)["truth_projection_rms_px"]["max"].get<double>(),
                   s.poses.truth_projection_rms_px.max);
  // Without it, none.
  auto without = EvaluateImage(truth, detections, kSizes, eye, MatchOptions{});
  ASSERT_TRUE(without.ok());
  EXPECT_TRUE(std::isnan(without->objects[0].truth_projection_rms_px));
}

TEST(EvaluateImageTest, HiddenObjectsAreNotScoredAndUnknownModelsFail) {
  auto truth = TwoCubesAndASlab();
  truth[2].visible_fraction = 0.01;
  const Eigen::Vector3d camera(0.5, 0, 0.5);
  // Finding the hidden slab is neither a hit nor a false positive.
  auto result = EvaluateImage(truth, {{"slab", truth[2].world_T_object, 1.0}}, kSizes, camera, MatchOptions{});
  ASSERT_TRUE(result.ok());
  EXPECT_EQ(result->objects.size(), 2u);
  EXPECT_EQ(result->false_positives, 0);
  EXPECT_EQ(result->detection_truth, std::vector<int>{-2});
  truth[0].model = "wedge";
  auto bad = EvaluateImage(truth, {}, kSizes, camera, MatchOptions{});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("wedge"), std::string::npos);
  MatchOptions options;
  options.max_along_m = -1;
  EXPECT_FALSE(EvaluateImage(TwoCubesAndASlab(), {}, kSizes, camera, options).ok());
}

TEST(EvaluateImageTest, FalsePositivesAreTracedToTheBlockTheyStandAt) {
  const std::map<std::string, Eigen::Vector3d> sizes = {
      {"cube45", {0.045, 0.045, 0.045}}, {"bar90", {0.09, 0.045, 0.045}}, {"slab", {0.09, 0.06, 0.03}}};
  // A bar along x at the origin and a cube 0.2 m away.
  const std::vector<TruthObject> truth = {
      {"bar", "bar90", geometry::Pose3(Eigen::Quaterniond::Identity(), {0, 0, 0.0225}), 0.6, 3000},
      {"cube", "cube45", geometry::Pose3(AxisAngle({0, 0, 1}, 0.4), {0.2, 0, 0.0225}), 1.0, 4000}};
  const Eigen::Vector3d camera(0.5, 0, 0.5);
  const std::vector<Detection> detections = {
      // The cube, found.
      {"cube45", truth[1].world_T_object, 0.9},
      // A cube on the bar's far end (its centre inside the bar): at the bar.
      {"cube45", geometry::Pose3(Eigen::Quaterniond::Identity(), {0.0225, 0, 0.0225}), 0.8},
      // A slab whose box holds the cube's centre but whose centre lies outside the cube: at the cube.
      {"slab", geometry::Pose3(Eigen::Quaterniond::Identity(), {0.2 + 0.04, 0, 0.015}), 0.7},
      // A cube on the table far from both: at no block.
      {"cube45", geometry::Pose3(Eigen::Quaterniond::Identity(), {-0.2, 0.2, 0.0225}), 0.6}};
  auto evaluation = EvaluateImage(truth, detections, sizes, camera, MatchOptions{});
  ASSERT_TRUE(evaluation.ok()) << evaluation.status().message();
  ASSERT_EQ(evaluation->false_positives, 3);
  auto hosts = FalsePositiveHosts(truth, detections, sizes, *evaluation);
  ASSERT_TRUE(hosts.ok()) << hosts.status().message();
  EXPECT_EQ(*hosts, (std::vector<int>{-1, 0, 1, -1}));
  // Moved along the bar until its centre is 33 mm past the bar's end, the cube stands at nothing.
  std::vector<Detection> moved = detections;
  moved[1].world_T_object.translation.x() = 0.045 + 0.0225 + 0.01;
  auto moved_evaluation = EvaluateImage(truth, moved, sizes, camera, MatchOptions{});
  ASSERT_TRUE(moved_evaluation.ok());
  EXPECT_EQ((*FalsePositiveHosts(truth, moved, sizes, *moved_evaluation))[1], -1);
  // A model without a size, and an evaluation of other detections, are errors that say so.
  std::vector<Detection> unknown = detections;
  unknown[3].model = "wedge";
  auto bad = FalsePositiveHosts(truth, unknown, sizes, *evaluation);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("wedge"), std::string::npos);
  EXPECT_FALSE(FalsePositiveHosts(truth, {detections[0]}, sizes, *evaluation).ok());
}

// The image points of the surface of the part of a box between `from` and `to` (object frame), every
// millimetre, through the camera's lens: what a block shows when the rest of it is hidden.
std::vector<Eigen::Vector2d> PartInView(const Camera& camera, const geometry::Pose3& world_T_object,
                                        const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  std::vector<Eigen::Vector2d> out;
  constexpr double kStep = 0.001;
  auto steps = [&](int axis) {
    return std::max(1, static_cast<int>(std::lround((to[axis] - from[axis]) / kStep)));
  };
  for (int fixed = 0; fixed < 3; ++fixed) {
    const int u = (fixed + 1) % 3, v = (fixed + 2) % 3;
    for (const double side : {from[fixed], to[fixed]}) {
      for (int i = 0; i <= steps(u); ++i) {
        for (int j = 0; j <= steps(v); ++j) {
          Eigen::Vector3d p;
          p[fixed] = side;
          p[u] = from[u] + (to[u] - from[u]) * i / steps(u);
          p[v] = from[v] + (to[v] - from[v]) * j / steps(v);
          if (auto px = camera.Project(world_T_object * p)) out.push_back(*px);
        }
      }
    }
  }
  return out;
}

TEST(ShorterModelsInViewTest, ABarWhoseFarHalfIsHiddenShowsAsACube) {
  const std::map<std::string, Eigen::Vector3d> sizes = {{"cube45", {0.045, 0.045, 0.045}},
                                                        {"bar90", {0.09, 0.045, 0.045}},
                                                        {"tall135", {0.045, 0.045, 0.135}},
                                                        {"slab", {0.09, 0.06, 0.03}}};
  // A camera 0.5 m off, 40 deg above the table, with barrel distortion, looking at the origin.
  const Eigen::Vector3d eye(0.3, 0.25, 0.32);
  const Eigen::Vector3d z = (-eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  Eigen::Matrix3d world_R_camera;
  world_R_camera << x, z.cross(x), z;
  const Camera camera(Intrinsics{760, 760, 319.5, 239.5}, Distortion{-0.2, 0.01, 0, 0, 0},
                      geometry::Pose3(Eigen::Quaterniond(world_R_camera), eye), 640, 480);
  const geometry::Pose3 bar(AxisAngle({0, 0, 1}, 0.5), {0.01, -0.02, 0.0225});
  const Eigen::Vector3d half(0.045, 0.0225, 0.0225);
  auto shorter = [&](const std::string& model, const geometry::Pose3& pose,
                     const std::vector<Eigen::Vector2d>& px) {
    auto r = ShorterModelsInView(sizes, model, pose, camera, px);
    EXPECT_TRUE(r.ok()) << r.status().message();
    return r.ok() ? *r : std::vector<std::string>{"error"};
  };
  using Names = std::vector<std::string>;
  // All of the bar in view: no shorter model shows so.
  EXPECT_EQ(shorter("bar90", bar, PartInView(camera, bar, -half, half)), Names{});
  // Either half alone: a cube at that end.
  EXPECT_EQ(shorter("bar90", bar, PartInView(camera, bar, {0, -0.0225, -0.0225}, half)), Names{"cube45"});
  EXPECT_EQ(shorter("bar90", bar, PartInView(camera, bar, -half, {0, 0.0225, 0.0225})), Names{"cube45"});
  // Half a millimetre more (under a pixel here) is within the margin; 4 mm more (about 5 px) is not.
  EXPECT_EQ(shorter("bar90", bar, PartInView(camera, bar, {-0.0005, -0.0225, -0.0225}, half)),
            Names{"cube45"});
  EXPECT_EQ(shorter("bar90", bar, PartInView(camera, bar, {-0.004, -0.0225, -0.0225}, half)), Names{});
  // A standing tall block: its lowest third shows as a cube or a bar on end (shortest first), its
  // lowest two thirds as a bar alone.
  const geometry::Pose3 tall(AxisAngle({0, 0, 1}, -0.2), {-0.02, 0.03, 0.0675});
  const Eigen::Vector3d tall_half(0.0225, 0.0225, 0.0675);
  EXPECT_EQ(shorter("tall135", tall, PartInView(camera, tall, -tall_half, {0.0225, 0.0225, -0.0225})),
            (Names{"cube45", "bar90"}));
  EXPECT_EQ(shorter("tall135", tall, PartInView(camera, tall, -tall_half, {0.0225, 0.0225, 0.0225})),
            Names{"bar90"});
  // A cube has no shorter model of its section, nor a slab.
  const geometry::Pose3 cube(AxisAngle({0, 0, 1}, 0.1), {0, 0, 0.0225});
  EXPECT_EQ(
      shorter("cube45", cube, PartInView(camera, cube, {-0.0225, -0.0225, -0.0225}, {0, 0.0225, 0.0225})),
      Names{});
  const geometry::Pose3 slab(Eigen::Quaterniond::Identity(), {0, 0, 0.015});
  EXPECT_EQ(shorter("slab", slab, PartInView(camera, slab, {-0.045, -0.03, -0.015}, {0, 0.03, 0.015})),
            Names{});
  // Nothing in view: nothing to explain. A model without a size is an error that names it.
  EXPECT_EQ(shorter("bar90", bar, {}), Names{});
  auto unknown = ShorterModelsInView(sizes, "wedge", bar, camera, {{100, 100}});
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("wedge"), std::string::npos);
}

TEST(SummaryTest, UnoccludedObjectsAreCountedApartFromTheHighBin) {
  // Four objects of the >= 0.7 bin; only the two at most 1 % hidden are unoccluded.
  ImageEvaluation image;
  for (const auto& [fraction, detection] :
       std::vector<std::pair<double, int>>{{1.0, 0}, {0.995, -1}, {0.98, 1}, {0.8, -1}}) {
    ObjectOutcome o;
    o.truth = static_cast<int>(image.objects.size());
    o.visible_fraction = fraction;
    o.detection = detection;
    image.objects.push_back(o);
  }
  SummaryBuilder builder;
  builder.Add(image, 1.0);
  const Summary s = builder.Build();
  EXPECT_EQ(s.objects[static_cast<int>(VisibilityBin::kHigh)], 4);
  EXPECT_DOUBLE_EQ(s.Recall(VisibilityBin::kHigh), 0.5);
  EXPECT_EQ(s.unoccluded_objects, 2);
  EXPECT_EQ(s.unoccluded_found, 1);
  EXPECT_DOUBLE_EQ(s.RecallUnoccluded(), 0.5);
  const json::Json j = SummaryToJson(s);
  EXPECT_EQ(j["recall_unoccluded"]["objects"], 2);
  EXPECT_EQ(j["recall_unoccluded"]["found"], 1);
  EXPECT_DOUBLE_EQ(j["recall_unoccluded"]["min_visible_fraction"].get<double>(), kUnoccludedFraction);
  EXPECT_TRUE(std::isnan(SummaryBuilder().Build().RecallUnoccluded()));
}

// The time goal is per image: the summary counts the images over it (at the goal is not over), keeps
// each stage's figures over the images that gave it, and names the slowest image with its stages and
// counts.
TEST(SummaryTest, TimesAreSummarizedPerStageWithTheSlowestImageNamed) {
  const ImageEvaluation image;
  SummaryBuilder builder;
  builder.Add(image, ImageTime{12.0, "a", {{"lines", 2.0}, {"fit", 10.0}}, {{"lines", 100}}});
  builder.Add(image, ImageTime{kTimeGoalMs, "b", {{"lines", 4.0}, {"fit", 46.0}}, {{"lines", 300}}});
  builder.Add(image, ImageTime{kTimeGoalMs + 0.5, "c", {{"lines", 9.0}, {"fit", 41.5}}, {{"lines", 700}}});
  builder.Add(image, 3.0);  // a method that tells no stages
  const Summary s = builder.Build();
  EXPECT_EQ(s.over_time_goal, 1);
  ASSERT_EQ(s.stage_time_ms.size(), 2u);
  EXPECT_EQ(s.stage_time_ms.at("lines").count, 3);
  EXPECT_DOUBLE_EQ(s.stage_time_ms.at("lines").mean, 5.0);
  EXPECT_DOUBLE_EQ(s.stage_time_ms.at("lines").max, 9.0);
  EXPECT_DOUBLE_EQ(s.stage_time_ms.at("fit").median, 41.5);
  ASSERT_TRUE(s.slowest.has_value());
  EXPECT_EQ(s.slowest->image, "c");
  EXPECT_DOUBLE_EQ(s.time_ms.max, s.slowest->total_ms);
  const json::Json j = SummaryToJson(s);
  EXPECT_EQ(j["images_over_time_goal"], 1);
  EXPECT_DOUBLE_EQ(j["time_goal_ms"].get<double>(), kTimeGoalMs);
  EXPECT_DOUBLE_EQ(j["stage_time_ms"]["lines"]["mean"].get<double>(), 5.0);
  EXPECT_EQ(j["slowest_image"]["image"], "c");
  EXPECT_DOUBLE_EQ(j["slowest_image"]["stage_ms"]["lines"].get<double>(), 9.0);
  EXPECT_EQ(j["slowest_image"]["counts"]["lines"], 700);
  // No image: no slowest one, and no stage.
  const json::Json none = SummaryToJson(SummaryBuilder().Build());
  EXPECT_TRUE(none["slowest_image"].is_null());
  EXPECT_TRUE(none["stage_time_ms"].empty());
  EXPECT_EQ(none["images_over_time_goal"], 0);
}

// A method that finds one easy block precisely can have smaller medians than one that finds every
// block: on the blocks both found the figures compare the same blocks, and each method's count of
// blocks where its figure is the smaller shows who wins block by block.
TEST(PairedSummaryTest, ComparesOnlyTheObjectsBothMethodsFound) {
  auto outcome = [](int truth, int detection, double rotation_deg, double rms_px, double off_px) {
    ObjectOutcome o;
    o.truth = truth;
    o.detection = detection;
    o.visible_fraction = 1;
    o.rotation_error_rad = rotation_deg * kDeg;
    o.position_error.across_m = 1e-3 * (truth + 1);
    o.reprojection_rms_px = rms_px;
    o.truth_projection_rms_px = off_px;
    return o;
  };
  ImageEvaluation first, second;
  // Truth 0: both found it, the first more precisely; truth 1: both, the second closer to the
  // truth; truth 2: only the first found it (its large errors must not enter); truth 3: only the
  // second; truth 4: both, the second's residual unreported (NaN).
  first.objects = {outcome(0, 0, 0.1, 0.3, 0.2), outcome(1, 1, 0.4, 0.5, 0.6), outcome(2, 2, 9.0, 4.0, 9.0),
                   outcome(3, -1, 0, 0, 0), outcome(4, 3, 0.2, 0.4, 0.3)};
  second.objects = {outcome(0, 0, 0.3, 0.6, 0.5), outcome(1, 2, 0.2, 0.1, 0.1), outcome(2, -1, 0, 0, 0),
                    outcome(3, 1, 0.01, 0.01, 0.01), outcome(4, 3, 0.2, std::nan(""), 0.4)};
  PairedBuilder builder;
  ASSERT_TRUE(builder.Add(first, second).ok());
  const PairedSummary s = builder.Build();
  EXPECT_EQ(s.objects, 3);
  EXPECT_EQ(s.a.rotation_deg.count, 3);
  EXPECT_NEAR(s.a.rotation_deg.median, 0.2, 1e-9);
  EXPECT_NEAR(s.b.rotation_deg.median, 0.2, 1e-9);
  EXPECT_NEAR(s.a.rotation_deg.max, 0.4, 1e-9);  // truth 2's 9 deg left out
  EXPECT_EQ(s.b.reprojection_rms_px.count, 2);   // the NaN left out
  EXPECT_DOUBLE_EQ(s.a.across_mm.max, 5.0);      // truth 4's, in mm
  EXPECT_EQ(s.a_smaller_rotation, 1);            // truth 0; truth 4 is a tie
  EXPECT_EQ(s.b_smaller_rotation, 1);            // truth 1
  EXPECT_EQ(s.a_smaller_reprojection, 1);
  EXPECT_EQ(s.b_smaller_reprojection, 1);  // truth 4 counts for neither
  EXPECT_EQ(s.a_smaller_truth_projection, 2);
  EXPECT_EQ(s.b_smaller_truth_projection, 1);
  const json::Json j = PairedSummaryToJson(s, "ours", "theirs");
  EXPECT_EQ(j["objects"], 3);
  EXPECT_NEAR(j["ours"]["truth_projection_rms_px"]["median"].get<double>(), 0.3, 1e-9);
  EXPECT_NEAR(j["theirs"]["truth_projection_rms_px"]["median"].get<double>(), 0.4, 1e-9);
  EXPECT_EQ(j["ours_smaller"]["truth_projection_rms_px"], 2);
  EXPECT_EQ(j["theirs_smaller"]["reprojection_rms_px"], 1);
  // Nothing found by both: no figures (null medians), no error.
  const json::Json none = PairedSummaryToJson(PairedBuilder().Build(), "ours", "theirs");
  EXPECT_EQ(none["objects"], 0);
  EXPECT_TRUE(none["ours"]["rotation_error_deg"]["median"].is_null());
}

// Evaluations of different truth lists cannot be paired: the error says how they differ, and the
// refused image adds nothing, not even the pairs before the one that differs.
TEST(PairedSummaryTest, EvaluationsOfOtherObjectsAreRefused) {
  ImageEvaluation a, b;
  a.objects.resize(2);
  b.objects.resize(1);
  PairedBuilder builder;
  const Status count = builder.Add(a, b);
  ASSERT_FALSE(count.ok());
  EXPECT_NE(count.message().find("2 and 1 truth objects"), std::string::npos) << count.message();
  a.objects[0].truth = 0;
  a.objects[0].detection = 0;  // found by both: a pair, were the image taken
  a.objects[1].truth = 2;
  b.objects = {a.objects[0], a.objects[1]};
  b.objects[1].truth = 1;
  const Status order = builder.Add(a, b);
  ASSERT_FALSE(order.ok());
  EXPECT_NE(order.message().find("scored object 1 is truth object 2 in one evaluation and 1"),
            std::string::npos)
      << order.message();
  EXPECT_EQ(builder.Build().objects, 0);
}

TEST(SummarizeTest, NearestRankQuantiles) {
  const Stats s = Summarize({5, 1, 4, 2, 3, 6, 7, 8, 9, 10, std::nan("")});
  EXPECT_EQ(s.count, 10);
  EXPECT_DOUBLE_EQ(s.mean, 5.5);
  EXPECT_DOUBLE_EQ(s.median, 5.5);
  EXPECT_DOUBLE_EQ(s.p90, 9);
  EXPECT_DOUBLE_EQ(s.max, 10);
  EXPECT_EQ(Summarize({}).count, 0);
  EXPECT_TRUE(std::isnan(Summarize({}).mean));
  EXPECT_EQ(BinOf(0.7), VisibilityBin::kHigh);
  EXPECT_EQ(BinOf(0.69), VisibilityBin::kMedium);
  EXPECT_EQ(BinOf(0.39), VisibilityBin::kLow);
}

TEST(TruthSetTest, LoadsTheDevSet) {
  auto set = LoadTruthSet(DevTruthPath());
  ASSERT_TRUE(set.ok()) << set.status().message();
  EXPECT_EQ(set->cases.size(), 12u);
  EXPECT_EQ(set->model_sizes_m.size(), 5u);
  EXPECT_TRUE(set->model_sizes_m.at("bar90").isApprox(Eigen::Vector3d(0.09, 0.045, 0.045)));
  const TruthCase& c = set->cases[0];
  EXPECT_TRUE(std::filesystem::exists(c.image)) << c.image;
  EXPECT_EQ(c.camera.width, 640);
  EXPECT_NEAR(c.camera.k1, -0.2424409387594719, 1e-15);
  ASSERT_TRUE(c.frame.has_value());
  EXPECT_DOUBLE_EQ(c.frame->wall_m, 0.02);
  ASSERT_EQ(c.objects.size(), 6u);
  EXPECT_EQ(c.objects[4].model, "bar90");
  EXPECT_NEAR(c.objects[4].visible_fraction, 0.229244016115017, 1e-15);
  const scene::Scene world = FixedWorldScene(c.frame);
  ASSERT_EQ(world.objects.size(), 2u);
  // The frame's walls reach 30 mm above the table, 120 mm either side of its centre along x.
  const geometry::Aabb bounds = world.objects[1].shape.WorldBounds(geometry::Pose3::Identity());
  EXPECT_NEAR(bounds.max.z(), 0.03, 1e-12);
  EXPECT_NEAR(bounds.max.x(), 0.12, 1e-12);
  EXPECT_NEAR(bounds.max.y(), 0.10, 1e-12);
}

TEST(TruthSetTest, ErrorsNameTheFieldAndValue) {
  const std::string path = ::testing::TempDir() + "/evaluate_bad_truth.json";
  {
    std::ofstream f(path);
    f << R"({"models": {"cube45": [0.045, 0.045, 0.045]}, "cases": [{"image": "x.png", "camera": )"
      << R"({"width": 640, "height": 480, "fx": 700, "fy": 700, "cx": 319.5, "cy": 239.5, "k1": 0, "k2": 0,)"
      << R"( "p1": 0, "p2": 0, "k3": 0, "position": [0, 0, 1], "quaternion_wxyz": [0, 1, 0, 0]},)"
      << R"( "objects": [{"name": "a", "model": "cube", "position": [0, 0, 0.0225],)"
      << R"( "quaternion_wxyz": [1, 0, 0, 0], "visible_fraction": 1, "visible_pixels": 10}]}]})";
  }
  auto set = LoadTruthSet(path);
  ASSERT_FALSE(set.ok());
  EXPECT_NE(set.status().message().find("cases[0].objects[0].model"), std::string::npos) << set.status().message();
  EXPECT_NE(set.status().message().find("\"cube\""), std::string::npos);
  std::filesystem::remove(path);
}

// The dev set's poses are box centres in the world frame, its cameras world_T_camera with OpenCV's
// axes and distortion: the outline of every fully visible block, projected through our camera
// model, lies on strong image edges; 4 px beside it lies on much weaker ones.
TEST(TruthSetTest, DevSetOutlinesLieOnImageEdges) {
  auto set = LoadTruthSet(DevTruthPath());
  ASSERT_TRUE(set.ok()) << set.status().message();
  int checked = 0;
  for (const TruthCase& c : set->cases) {
    const cv::Mat image = cv::imread(c.image, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty()) << c.image;
    cv::Mat gx, gy, magnitude;
    cv::Sobel(image, gx, CV_32F, 1, 0);
    cv::Sobel(image, gy, CV_32F, 0, 1);
    cv::magnitude(gx, gy, magnitude);
    auto camera = Camera::FromSpec(c.camera);
    ASSERT_TRUE(camera.ok());
    for (const TruthObject& o : c.objects) {
      if (o.visible_fraction < 0.999) continue;
      const Eigen::Vector3d half = set->model_sizes_m.at(o.model) / 2;
      // Outline: the 3D edges whose projections bound the silhouette (both faces beside the edge,
      // one facing the camera and one not).
      const Eigen::Vector3d eye_in_object = o.world_T_object.Inverse() * c.camera.world_T_camera.translation;
      double on = 0, beside = 0;
      int samples = 0;
      for (int axis = 0; axis < 3; ++axis) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        for (int su : {-1, 1}) {
          for (int sv : {-1, 1}) {
            const bool face_u = su * eye_in_object[u] > half[u], face_v = sv * eye_in_object[v] > half[v];
            if (face_u == face_v) continue;  // not on the silhouette
            for (int k = 1; k < 20; ++k) {
              Eigen::Vector3d p;
              p[axis] = half[axis] * (2.0 * k / 20 - 1);
              p[u] = su * half[u];
              p[v] = sv * half[v];
              auto pixel = camera->Project(o.world_T_object * p);
              auto centre = camera->Project(o.world_T_object.translation);
              ASSERT_TRUE(pixel && centre);
              // Outward in the image: away from the projected centre.
              const Eigen::Vector2d out = (*pixel - *centre).normalized();
              const Eigen::Vector2d off = *pixel + 4.0 * out;
              if (!camera->InImage(*pixel) || !camera->InImage(off)) continue;
              on += magnitude.at<float>(static_cast<int>(std::lround(pixel->y())),
                                        static_cast<int>(std::lround(pixel->x())));
              beside += magnitude.at<float>(static_cast<int>(std::lround(off.y())), static_cast<int>(std::lround(off.x())));
              ++samples;
            }
          }
        }
      }
      ASSERT_GT(samples, 40) << c.image << " " << o.name;
      EXPECT_GT(on, 3.0 * beside) << c.image << " " << o.name << ": mean gradient on the outline " << on / samples
                                  << ", 4 px outside " << beside / samples;
      ++checked;
    }
  }
  EXPECT_GE(checked, 20);  // 25 blocks are fully visible in the 12 images
}

}  // namespace
}  // namespace teachsim::vision
