// Occluding contours (contours.cc): which image lines count as one, when one runs across a box's
// image, and what one or two of them hide.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "synthetic_scene.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {
namespace {

// A box's image: a 100 x 60 px rectangle (the far face) with a copy 10 px up and right (the near
// face), its outline edges all visible.
BoxImage Rectangle() {
  std::array<Eigen::Vector2d, 8> px;
  for (int v = 0; v < 8; ++v) {
    px[static_cast<size_t>(v)] = Eigen::Vector2d(200 + (v & 1 ? 100 : 0), 200 + (v & 2 ? 60 : 0));
    if (v & 4) px[static_cast<size_t>(v)] += Eigen::Vector2d(10, -10);
  }
  return BoxImage(px, 0x0fff);
}

TEST(ContoursTest, ALineCrossesABoxImageOnlyWhenItRunsAcrossAllOfIt) {
  const BoxImage box = Rectangle();
  // The hull: the two rectangles' outer corners, six of the eight vertices.
  EXPECT_EQ(box.hull_size, 6);
  EXPECT_TRUE(CrossesBoxImage({{250, 100}, {250, 400}}, box));   // top to bottom, past both sides
  EXPECT_TRUE(CrossesBoxImage({{250, 400}, {250, 100}}, box));   // either direction
  EXPECT_TRUE(CrossesBoxImage({{150, 150}, {350, 300}}, box));   // slanted
  EXPECT_FALSE(CrossesBoxImage({{250, 100}, {250, 230}}, box));  // ends inside
  EXPECT_FALSE(CrossesBoxImage({{250, 192}, {250, 400}}, box));  // ends 2 px before the outline
  EXPECT_FALSE(CrossesBoxImage({{400, 100}, {400, 400}}, box));  // beside it
  EXPECT_FALSE(CrossesBoxImage({{100, 50}, {400, 50}}, box));    // above it
  // Along its outline (the far face's bottom edge, y = 260), however far past it: no occluder, the
  // box's image lies on one side of the line (a line along an edge inside the image: below).
  EXPECT_FALSE(CrossesBoxImage({{150, 260}, {400, 260}}, box));
  EXPECT_FALSE(CrossesBoxImage({{150, 261.5}, {400, 261.5}}, box));
  // A short line never does.
  EXPECT_FALSE(CrossesBoxImage({{250, 225}, {250, 241}}, box));
  // Into it: one end beyond, the other inside, told by which end is inside.
  EXPECT_EQ(PassageThroughBoxImage({{250, 100}, {250, 230}}, box), ContourPassage::kIntoAtB);
  EXPECT_EQ(PassageThroughBoxImage({{250, 230}, {250, 100}}, box), ContourPassage::kIntoAtA);
  EXPECT_EQ(PassageThroughBoxImage({{250, 100}, {250, 400}}, box), ContourPassage::kAcross);
  EXPECT_EQ(PassageThroughBoxImage({{250, 200}, {250, 245}}, box), ContourPassage::kNone);  // inside
  EXPECT_EQ(PassageThroughBoxImage({{250, 100}, {250, 195}}, box), ContourPassage::kNone);  // 5 px in
  EXPECT_EQ(PassageThroughBoxImage({{150, 260}, {250, 260}}, box), ContourPassage::kNone);  // its outline
  // An edge inside the box's image, the near face's left one (x = 210, y 190-250), and a line along
  // it: reaching 35 px past the image (15 above, 20 below), that edge; 40 px or more, a flank in
  // front, down across the box or into it.
  EXPECT_EQ(PassageThroughBoxImage({{210, 175}, {210, 280}}, box), ContourPassage::kNone);
  EXPECT_EQ(PassageThroughBoxImage({{210, 100}, {210, 400}}, box), ContourPassage::kAcross);
  EXPECT_EQ(PassageThroughBoxImage({{210, 100}, {210, 230}}, box), ContourPassage::kIntoAtB);
}

// The flanks of a pole whose top is in front of the box: from below it up to y = 220 (inside the
// box's image), each with its darker side towards the pole (OccludingContours' orientation).
TEST(ContoursTest, TwoFlanksThatEndInsideHideTheStripUpToTheirEnds) {
  const BoxImage box = Rectangle();  // x 200-310, y 190-260
  const ImageLine left{{240, 400}, {240, 220}}, right{{270, 220}, {270, 400}};
  std::vector<ContourOccluder> ways;
  ContourOcclusions({left, right}, box, &ways);
  ASSERT_EQ(ways.size(), 1u);  // the strip; neither flank alone hides a side (it ends inside)
  EXPECT_EQ(ways[0].count, 2);
  EXPECT_TRUE(ways[0].Hides({255, 240}));
  EXPECT_FALSE(ways[0].Hides({255, 200}));  // beyond the pole's top
  EXPECT_FALSE(ways[0].Hides({220, 240}));
  EXPECT_FALSE(ways[0].Hides({290, 240}));
  // Not with ends_inside false, nor when the strip is darker beyond one flank than inside.
  ContourOcclusions({left, right}, box, &ways, {.ends_inside = false});
  EXPECT_TRUE(ways.empty());
  ContourOcclusions({left, {{270, 400}, {270, 220}}}, box, &ways);
  EXPECT_TRUE(ways.empty());
  // Nor when they end far apart: 80 px along them, 30 px apart.
  ContourOcclusions({left, {{270, 300}, {270, 400}}}, box, &ways);
  EXPECT_TRUE(ways.empty());

  // One flank inside, the other beside the box (it passes the box by on the right).
  const ImageLine beside{{330, 220}, {330, 400}};
  ASSERT_EQ(PassageThroughBoxImage(beside, box), ContourPassage::kNone);
  ContourOcclusions({left, beside}, box, &ways);
  ASSERT_EQ(ways.size(), 1u);
  EXPECT_TRUE(ways[0].Hides({300, 240}));
  EXPECT_FALSE(ways[0].Hides({300, 200}));
  EXPECT_FALSE(ways[0].Hides({230, 240}));
  // Not when it is farther from the first than the box's image is wide (110 px), with or without
  // the pairing of flanks across.
  ContourOcclusions({left, {{360, 220}, {360, 400}}}, box, &ways);
  EXPECT_TRUE(ways.empty());
  ContourOcclusions({left, {{360, 220}, {360, 400}}}, box, &ways, {.across_beside = true});
  EXPECT_TRUE(ways.empty());
}

// ContourPairing::pole_tops: the strip between flanks that end inside goes on past their ends by half
// its width (a round pole's top), and no farther, nor beyond the flanks' sides.
TEST(ContoursTest, APoleTopHidesHalfTheStripsWidthPastTheFlanksEnds) {
  const BoxImage box = Rectangle();                                             // x 200-310, y 190-260
  const ImageLine left{{240, 400}, {240, 220}}, right{{270, 220}, {270, 400}};  // 30 px apart
  std::vector<ContourOccluder> ways;
  ContourOcclusions({left, right}, box, &ways, {.pole_tops = true});
  ASSERT_EQ(ways.size(), 1u);
  EXPECT_TRUE(ways[0].Hides({255, 240}));
  EXPECT_TRUE(ways[0].Hides({255, 208}));   // 12 px past the ends: under the top
  EXPECT_TRUE(ways[0].Hides({255, 204}));   // 16 px: half the width (15 px) and the end's slack (3 px)
  EXPECT_FALSE(ways[0].Hides({255, 200}));  // 20 px: beyond it
  EXPECT_FALSE(ways[0].Hides({255, 198}));
  EXPECT_TRUE(ways[0].Hides({255, 400}));  // the flanks' outer ends: not lengthened
  EXPECT_FALSE(ways[0].Hides({255, 406}));
  EXPECT_FALSE(ways[0].Hides({225, 208}));
  EXPECT_FALSE(ways[0].Hides({285, 208}));
  // The same flanks drawn from their inner ends (a lighter pole on a darker ground): the same top.
  const ImageLine left_down{{240, 220}, {240, 400}}, right_down{{270, 400}, {270, 220}};
  for (const auto& flanks :
       {std::vector<ImageLine>{left_down, right_down}, std::vector<ImageLine>{right_down, left_down}}) {
    ContourOcclusions(flanks, box, &ways, {.pole_tops = true});
    ASSERT_EQ(ways.size(), 1u);
    EXPECT_TRUE(ways[0].Hides({255, 208}));
    EXPECT_FALSE(ways[0].Hides({255, 198}));
  }

  // One flank inside, the other beside the box, 90 px apart: the top reaches 45 px past the end.
  const ImageLine beside{{330, 220}, {330, 400}};
  ContourOcclusions({left, beside}, box, &ways, {.pole_tops = true});
  ASSERT_EQ(ways.size(), 1u);
  EXPECT_TRUE(ways[0].Hides({300, 180}));   // 40 px past
  EXPECT_FALSE(ways[0].Hides({300, 170}));  // 50 px past
  EXPECT_FALSE(ways[0].Hides({230, 240}));
  // Without pole_tops the strip ends with the flanks.
  ContourOcclusions({left, beside}, box, &ways);
  ASSERT_EQ(ways.size(), 1u);
  EXPECT_FALSE(ways[0].Hides({300, 200}));
}

// A pole whose near flank runs across the box's image and whose far flank passes the box by: with
// ContourPairing::across_beside, the strip between them too, however far apart, when it is on the
// same side of the grey-level step at both.
TEST(ContoursTest, AFlankAcrossPairsWithOneBesideWhenAsked) {
  const BoxImage box = Rectangle();                // x 200-310, y 190-260
  const ImageLine across{{240, 400}, {240, 100}};  // darker towards +x
  const ImageLine beside{{330, 100}, {330, 400}};  // darker towards -x: the pole between them
  ASSERT_EQ(PassageThroughBoxImage(across, box), ContourPassage::kAcross);
  ASSERT_EQ(PassageThroughBoxImage(beside, box), ContourPassage::kNone);
  std::vector<ContourOccluder> ways;
  ContourOcclusions({across, beside}, box, &ways);
  EXPECT_EQ(ways.size(), 2u);  // by default, either side of the one across only
  ContourOcclusions({across, beside}, box, &ways, {.across_beside = true});
  ASSERT_EQ(ways.size(), 3u);
  const ContourOccluder& strip = ways.back();
  EXPECT_EQ(strip.count, 2);
  EXPECT_TRUE(strip.Hides({300, 230}));
  EXPECT_FALSE(strip.Hides({220, 230}));  // the box's part in view
  EXPECT_FALSE(strip.Hides({340, 230}));  // past the far flank
  // Farther off than the box's image is wide (a flank that ends inside would not pair so).
  ContourOcclusions({across, {{450, 100}, {450, 400}}}, box, &ways, {.across_beside = true});
  ASSERT_EQ(ways.size(), 3u);
  EXPECT_TRUE(ways.back().Hides({420, 230}));
  // Not when the step is the other way at the far one (lighter between them there), nor far from
  // parallel.
  ContourOcclusions({across, {{330, 400}, {330, 100}}}, box, &ways, {.across_beside = true});
  EXPECT_EQ(ways.size(), 2u);
  ContourOcclusions({across, {{330, 100}, {600, 300}}}, box, &ways, {.across_beside = true});
  EXPECT_EQ(ways.size(), 2u);
  // Nor with a contour inside the box's image (neither end beyond it: it does not pass through, but
  // it is no flank beside the box either).
  const ImageLine inside{{290, 200}, {290, 250}};  // darker towards -x
  ASSERT_EQ(PassageThroughBoxImage(inside, box), ContourPassage::kNone);
  ContourOcclusions({across, inside}, box, &ways, {.across_beside = true});
  EXPECT_EQ(ways.size(), 2u);
  // With ends_inside off (contours that end inside the box's image left out), the same strip.
  ContourOcclusions({across, beside}, box, &ways, {.ends_inside = false, .across_beside = true});
  EXPECT_EQ(ways.size(), 3u);
}

TEST(ContoursTest, OneContourHidesEitherSideAndTwoTheStripBetweenThem) {
  const BoxImage box = Rectangle();
  std::vector<ContourOccluder> ways;
  ContourOcclusions({{{240, 100}, {240, 400}}}, box, &ways);
  ASSERT_EQ(ways.size(), 2u);
  for (const ContourOccluder& o : ways) EXPECT_EQ(o.count, 1);
  EXPECT_NE(ways[0].Hides({220, 230}), ways[1].Hides({220, 230}));
  EXPECT_NE(ways[0].Hides({260, 230}), ways[1].Hides({260, 230}));
  // Along the contour's length only, and a band of kContourBandPx on the side in view.
  for (const ContourOccluder& o : ways) {
    EXPECT_FALSE(o.Hides({260, 50}));
    EXPECT_FALSE(o.Hides({220, 450}));
    EXPECT_TRUE(o.Hides({241, 230}) && o.Hides({239, 230}));
  }

  // Two nearly parallel contours: either side of each, and the strip between them.
  ContourOcclusions({{{240, 100}, {240, 400}}, {{270, 100}, {275, 400}}}, box, &ways);
  ASSERT_EQ(ways.size(), 5u);
  const ContourOccluder& strip = ways.back();
  EXPECT_EQ(strip.count, 2);
  EXPECT_TRUE(strip.Hides({255, 230}));
  EXPECT_FALSE(strip.Hides({220, 230}));
  EXPECT_FALSE(strip.Hides({290, 230}));
  // Contours that cross each other where they are give no strip; nor do ones far from parallel.
  ContourOcclusions({{{240, 100}, {280, 400}}, {{280, 100}, {240, 400}}}, box, &ways);
  EXPECT_EQ(ways.size(), 4u);
  ContourOcclusions({{{240, 100}, {240, 400}}, {{150, 150}, {350, 300}}}, box, &ways);
  EXPECT_EQ(ways.size(), 4u);
}

// With pairing.sides_bounded, a contour across the box's image hides no side with another across
// beyond it (a pole's near flank does not hide the outline past its far flank): the two outer sides
// and the strip between them are left, each hiding one of the three parts.
TEST(ContoursTest, WithSidesBoundedASideEndsAtTheContourAcrossBeyondIt) {
  const BoxImage box = Rectangle();
  const std::vector<ImageLine> flanks = {{{240, 100}, {240, 400}}, {{270, 100}, {275, 400}}};
  std::vector<ContourOccluder> ways;
  ContourOcclusions(flanks, box, &ways, {.sides_bounded = true});
  ASSERT_EQ(ways.size(), 3u);
  int strips = 0, left = 0, between = 0, right = 0;
  for (const ContourOccluder& o : ways) {
    strips += o.count == 2;
    left += o.Hides({220, 230}), between += o.Hides({255, 230}), right += o.Hides({290, 230});
    // No way hides the part between the flanks together with either part beyond them.
    EXPECT_FALSE(o.Hides({255, 230}) && (o.Hides({220, 230}) || o.Hides({290, 230})));
  }
  EXPECT_EQ(left, 1);
  EXPECT_EQ(between, 1);
  EXPECT_EQ(right, 1);
  EXPECT_EQ(strips, 1);
  // A lone contour across keeps both sides; one that crosses it does not bound it.
  ContourOcclusions({flanks[0]}, box, &ways, {.sides_bounded = true});
  EXPECT_EQ(ways.size(), 2u);
  ContourOcclusions({flanks[0], {{150, 150}, {350, 300}}}, box, &ways, {.sides_bounded = true});
  EXPECT_EQ(ways.size(), 4u);
  // Nor one more than 30 deg from parallel (37 deg) whose line meets the first's beyond its end:
  // each wholly on one side of the other, so only the angle tells them apart from a far flank.
  const std::vector<ImageLine> apart = {{{240, 150}, {240, 300}}, {{260, 170}, {330, 263}}};
  for (const ImageLine& line : apart) ASSERT_EQ(PassageThroughBoxImage(line, box), ContourPassage::kAcross);
  ContourOcclusions(apart, box, &ways, {.sides_bounded = true});
  EXPECT_EQ(ways.size(), 4u);
}

// HidesEach (the support-plane source's loop over an outline's samples) answers as Hides at every
// point: one side, a strip and a pole strip with tops, at random points and at points on the band's
// and the ends' limits.
TEST(ContoursTest, HidingAtManyPointsAnswersAsHidingAtEach) {
  const BoxImage box = Rectangle();
  std::vector<ContourOccluder> ways;
  ContourOcclusions({{{240, 100}, {240, 400}}, {{270, 100}, {275, 400}}}, box, &ways);
  std::vector<ContourOccluder> more;
  // A pole's flanks that end inside (as in TwoFlanksThatEndInsideHideTheStripUpToTheirEnds), its top.
  ContourOcclusions({{{240, 400}, {240, 220}}, {{270, 220}, {270, 400}}}, box, &more, {.pole_tops = true});
  ways.insert(ways.end(), more.begin(), more.end());
  ways.push_back(ContourOccluder{});  // hides nothing
  ASSERT_GE(ways.size(), 7u);
  cv::RNG rng(53);
  std::vector<double> x, y;
  for (int i = 0; i < 2000; ++i)
    x.push_back(rng.uniform(150.0, 350.0)), y.push_back(rng.uniform(50.0, 450.0));
  // On the limits: the band's edge and either end's slack, along each side of each occluder.
  for (const ContourOccluder& o : ways) {
    for (int k = 0; k < o.count; ++k) {
      const ContourOccluder::Side& side = o.sides[static_cast<size_t>(k)];
      for (double t : {-kContourEndPx, 0.0, 0.5 * side.length, side.length + kContourEndPx}) {
        for (double n : {-kContourBandPx, 0.0, 5.0}) {
          const Eigen::Vector2d p = side.a + t * side.along + n * side.toward_hidden;
          x.push_back(p.x()), y.push_back(p.y());
        }
      }
    }
  }
  std::vector<uint8_t> hides(x.size(), 7);
  int total_hidden = 0;
  for (const ContourOccluder& o : ways) {
    const int hidden = o.HidesEach(x.data(), y.data(), static_cast<int>(x.size()), hides.data());
    int expected = 0;
    for (size_t i = 0; i < x.size(); ++i) {
      const bool h = o.Hides({x[i], y[i]});
      expected += h;
      ASSERT_EQ(hides[i], h ? 1 : 0) << "occluder " << (&o - ways.data()) << ", point " << i;
    }
    EXPECT_EQ(hidden, expected);
    total_hidden += hidden;
  }
  EXPECT_GT(total_hidden, 1000);  // the points do fall in what they hide

  // Exactly on the limits: a side along x from the origin, 10 px long, hiding y > -kContourBandPx
  // from t = -kContourEndPx to 10 + kContourEndPx (both ends in, the band's edge out).
  ContourOccluder side;
  side.count = 1;
  side.sides[0].length = 10;
  const double in = std::nextafter(-kContourBandPx, 0.0),
               beyond_end = std::nextafter(10 + kContourEndPx, 20.0);
  const std::vector<double> lx = {
      -kContourEndPx, 10 + kContourEndPx, 5, 5, std::nextafter(-kContourEndPx, -10.0), beyond_end};
  const std::vector<double> ly = {0, 0, -kContourBandPx, in, 0, 0};
  const std::vector<uint8_t> expected = {1, 1, 0, 1, 0, 0};
  std::vector<uint8_t> at_limits(lx.size());
  EXPECT_EQ(side.HidesEach(lx.data(), ly.data(), static_cast<int>(lx.size()), at_limits.data()), 3);
  for (size_t i = 0; i < lx.size(); ++i) {
    EXPECT_EQ(at_limits[i], expected[i]) << "limit point " << i;
    EXPECT_EQ(side.Hides({lx[i], ly[i]}), expected[i] == 1) << "limit point " << i;
  }
}

TEST(ContoursTest, OnlyLongStepEdgesAreOccludingContours) {
  const Camera camera = synthetic::SyntheticCamera();
  cv::Mat image(camera.height(), camera.width(), CV_8U, cv::Scalar(150));
  cv::rectangle(image, cv::Point(300, 0), cv::Point(339, 479), cv::Scalar(20), cv::FILLED);  // a dark pole
  cv::rectangle(image, cv::Point(100, 100), cv::Point(139, 139), cv::Scalar(20),
                cv::FILLED);                                                    // a small square
  cv::line(image, cv::Point(450, 50), cv::Point(450, 400), cv::Scalar(60), 1);  // a thin line
  RecognizerOptions options;
  const LineDetection detection = DetectLinesAndEdges(image, camera, options);
  const std::vector<ImageLine> contours = OccludingContours(detection, camera, options);
  // The pole's two sides, nothing else: the square's sides are short, the thin line has no step.
  ASSERT_EQ(contours.size(), 2u) << detection.lines.size() << " lines";
  for (const ImageLine& c : contours) {
    EXPECT_GT(c.Length(), 400);
    const double x = 0.5 * (c.a.x() + c.b.x());
    EXPECT_TRUE(std::abs(x - 299.5) < 2 || std::abs(x - 339.5) < 2) << x;
    // Oriented with the dark pole towards (-d.y, d.x).
    const Eigen::Vector2d d = (c.b - c.a).normalized();
    EXPECT_GT(Eigen::Vector2d(-d.y(), d.x()).dot(Eigen::Vector2d(319.5, 240) - c.a), 0) << x;
  }
  // The same from the lines joined beforehand, as the recognizer asks (one join for the corners too).
  const std::vector<ImageLine> from_joined =
      OccludingContours(detection, JoinCollinearLines(detection.lines), camera, options);
  ASSERT_EQ(from_joined.size(), contours.size());
  for (size_t k = 0; k < contours.size(); ++k) {
    EXPECT_EQ(from_joined[k].a, contours[k].a);
    EXPECT_EQ(from_joined[k].b, contours[k].b);
  }
  options.contour_min_step_grey = 0;  // the thin line too (an edge either side of it)
  const size_t with_line = OccludingContours(detection, camera, options).size();
  EXPECT_GE(with_line, 3u);
  options.contour_min_length_px = 30;  // and the square's four sides
  EXPECT_EQ(OccludingContours(detection, camera, options).size(), with_line + 4);
}

// A contour hiding everything right of a vertical line at x_px (pin-hole pixels).
ContourOccluder RightOf(double x_px) {
  ContourOccluder o;
  o.sides[0] = {{x_px, 0}, {0, 1}, {1, 0}, 480};
  o.count = 1;
  return o;
}

TEST(ContoursTest, AHiddenEndLeavesTheModelOpenWhenAnotherWouldEndHiddenToo) {
  const Eigen::Matrix3d K = (Eigen::Matrix3d() << 500, 0, 320, 0, 500, 240, 0, 0, 1).finished();
  const Model bar{"bar90", {0.09, 0.045, 0.045}}, cube{"cube45", {0.045, 0.045, 0.045}};
  const Model tall{"tall135", {0.045, 0.045, 0.135}}, slab{"slab", {0.09, 0.06, 0.03}};
  // The bar across the view 0.5 m away: its ends at x = 275 and 365 px, its middle at 320 px.
  const geometry::Pose3 pose(Eigen::Quaterniond::Identity(), {0, 0, 0.5});
  // Its right end hidden from 345 px on: a cube laid from the left end would end in view at 320 px,
  // a tall block (135 mm on its side) hidden at 410 px.
  EXPECT_FALSE(AmbiguousExtent({{bar, cube}}, 0, pose, RightOf(345), K));
  EXPECT_TRUE(AmbiguousExtent({{bar, cube, tall}}, 0, pose, RightOf(345), K));
  EXPECT_FALSE(AmbiguousExtent({{bar, slab}}, 0, pose, RightOf(345), K));  // other sides
  // Hidden from 315 px on, the cube would end hidden too.
  EXPECT_TRUE(AmbiguousExtent({{bar, cube}}, 0, pose, RightOf(315), K));
  // Neither end wholly hidden: the bar's length is seen.
  EXPECT_FALSE(AmbiguousExtent({{bar, cube, tall}}, 0, pose, RightOf(400), K));
}

// A cube laid on the near end of a bar whose middle a dark pole hides passes as hidden only if
// nothing shows past the pole: there, the bar's edges go on where the cube's would end.
TEST(ContoursTest, APoseThatGoesOnPastItsHiddenEndIsTold) {
  const Camera camera = synthetic::SyntheticCamera();
  const Eigen::Vector3d bar(0.09, 0.045, 0.045), cube(0.045, 0.045, 0.045);
  const geometry::Pose3 bar_pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.86, Eigen::Vector3d::UnitZ())),
                                 {0, 0, 0.0225});
  // The cube in the bar's half at -x: its inner face at the bar's centre.
  const geometry::Pose3 cube_pose(bar_pose.rotation, bar_pose * Eigen::Vector3d(-0.0225, 0, 0));
  const geometry::Pose3 camera_T_cube = camera.camera_T_world() * cube_pose;
  const Eigen::Matrix3d K = camera.K();
  // The pole over the bar's centre, a third of the bar's image wide.
  double lo = 1e9, hi = -1e9;
  for (int v = 0; v < 8; ++v) {
    const double x = camera.Project(bar_pose * BoxVertex(bar, v))->x();
    lo = std::min(lo, x), hi = std::max(hi, x);
  }
  const double centre = camera.Project(bar_pose.translation)->x(), half = (hi - lo) / 6;
  auto with_pole = [&](cv::Mat image) {
    cv::rectangle(image, cv::Point(static_cast<int>(centre - half), 0),
                  cv::Point(static_cast<int>(centre + half), image.rows - 1), cv::Scalar(20), cv::FILLED);
    return image;
  };
  const RecognizerOptions options;
  const Model cube_model{"cube45", cube};
  for (const bool bar_there : {true, false}) {
    const cv::Mat image = with_pole(bar_there ? synthetic::RenderBoxes(camera, {{bar, bar_pose}}, 7)
                                              : synthetic::RenderBoxes(camera, {{cube, cube_pose}}, 7));
    const LineDetection detection = DetectLinesAndEdges(image, camera, options);
    const std::vector<ImageLine> contours = OccludingContours(detection, camera, options);
    std::array<Eigen::Vector2d, 8> px;
    for (int v = 0; v < 8; ++v)
      px[static_cast<size_t>(v)] = (K * (camera_T_cube * BoxVertex(cube, v))).hnormalized();
    std::vector<ContourOccluder> ways;
    ContourOcclusions(contours, BoxImage(px, VisibleBoxEdges(cube, camera_T_cube.Inverse().translation)),
                      &ways);
    // The ways that hide the cube's inner face (vertices at +x) and none of its outer one.
    int tried = 0;
    for (const ContourOccluder& way : ways) {
      bool inner_hidden = true, outer_shown = true;
      for (int v = 0; v < 8; ++v) {
        const bool hidden = way.Hides(px[static_cast<size_t>(v)]);
        if (v & 1)
          inner_hidden = inner_hidden && hidden;
        else
          outer_shown = outer_shown && !hidden;
      }
      if (!inner_hidden || !outer_shown) continue;
      ++tried;
      EXPECT_EQ(ContinuesPastHiddenEnd(cube_model, camera, camera_T_cube, way, detection.edge_map, options),
                bar_there)
          << "bar " << bar_there << ", way " << tried;
    }
    // The pole's near side runs across the cube's image (its far side lies beyond), and one side of
    // it hides the inner face.
    EXPECT_EQ(tried, 1) << "bar " << bar_there << ": " << contours.size() << " contours, " << ways.size()
                        << " ways";
  }
}

// The scene of the placement tests below: a bar on the table in the synthetic camera's view, in a
// library of a cube and the bar (model 1).
struct BarOnTheTable {
  Camera camera = synthetic::SyntheticCamera();
  Model bar{"bar90", {0.09, 0.045, 0.045}};
  ModelLibrary library{{Model{"cube45", {0.045, 0.045, 0.045}}, bar}};
  geometry::Pose3 bar_pose{Eigen::Quaterniond(Eigen::AngleAxisd(0.86, Eigen::Vector3d::UnitZ())),
                           {0, 0, 0.0225}};
};

// A bar on the table whose middle a dark pole hides (a third of the bar's image wide): placements
// short of the support threshold with the pole near their corner are scored again on the outline in
// view; they come after all those in full view, best first, where these leave room under
// max_support_hypotheses, and support_contour_reserve of them past it.
TEST(ContoursTest, PlacementsBehindAContourFillTheRoomThoseInViewLeaveAndTheirReserve) {
  const auto& [camera, bar, library, bar_pose] = BarOnTheTable();
  double lo = 1e9, hi = -1e9;
  for (int v = 0; v < 8; ++v) {
    const double x = camera.Project(bar_pose * BoxVertex(bar.box_size_m, v))->x();
    lo = std::min(lo, x), hi = std::max(hi, x);
  }
  const double centre = camera.Project(bar_pose.translation)->x(), half = (hi - lo) / 6;
  cv::Mat image = synthetic::RenderBoxes(camera, {{bar.box_size_m, bar_pose}}, 7);
  cv::rectangle(image, cv::Point(static_cast<int>(centre - half), 0),
                cv::Point(static_cast<int>(centre + half), image.rows - 1), cv::Scalar(20), cv::FILLED);
  RecognizerOptions options;
  const LineDetection detection = DetectLinesAndEdges(image, camera, options);
  const std::vector<ImageLine> contours = OccludingContours(detection, camera, options);
  const std::vector<ImageCorner> corners = FindCorners(detection.lines, options);
  auto hypotheses = [&](int max, const std::vector<ImageLine>& occluding, int reserve = 0) {
    options.max_support_hypotheses = max;
    options.support_contour_reserve = reserve;
    return SupportHypotheses(library, camera, detection, corners, {SupportPlane{}}, options, occluding);
  };
  auto count_behind = [](const std::vector<SupportHypothesis>& hs) {
    return std::count_if(hs.begin(), hs.end(), [](const SupportHypothesis& h) { return h.behind_contour; });
  };

  // Room for all: those in full view first (the bar where it stands the best of them), then those
  // behind the pole, each part best first.
  const std::vector<SupportHypothesis> all = hypotheses(100, contours);
  const auto behind = count_behind(all);
  const auto in_view = static_cast<std::ptrdiff_t>(all.size()) - behind;
  ASSERT_GE(behind, 2) << contours.size() << " contours";  // to tell a reserve of one from more
  ASSERT_GE(in_view, 1);
  EXPECT_EQ(all.front().model, 1);
  EXPECT_LT((all.front().world_T_object.translation - bar_pose.translation).norm(), 0.002);
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(all.size()); ++i) {
    const SupportHypothesis& h = all[static_cast<size_t>(i)];
    EXPECT_EQ(h.behind_contour, i >= in_view) << "hypothesis " << i;
    EXPECT_GE(h.score, 0);
    if (i > 0 && i != in_view) {
      EXPECT_LE(h.score, all[static_cast<size_t>(i - 1)].score) << "hypothesis " << i;
    }
  }

  // No room left by those in full view: none behind; room for one more: the best behind.
  const std::vector<SupportHypothesis> no_room = hypotheses(static_cast<int>(in_view), contours);
  EXPECT_EQ(no_room.size(), static_cast<size_t>(in_view));
  EXPECT_EQ(count_behind(no_room), 0);
  const std::vector<SupportHypothesis> one_more = hypotheses(static_cast<int>(in_view) + 1, contours);
  ASSERT_EQ(one_more.size(), static_cast<size_t>(in_view) + 1);
  EXPECT_TRUE(one_more.back().behind_contour);
  EXPECT_EQ(one_more.back().score, all[static_cast<size_t>(in_view)].score);
  // No room left, but a reserve: that many behind past the cap, best first (all of them when it is
  // larger); with room for one more and a reserve of one, still one.
  const std::vector<SupportHypothesis> reserved = hypotheses(static_cast<int>(in_view), contours, 1);
  ASSERT_EQ(reserved.size(), static_cast<size_t>(in_view) + 1);
  EXPECT_TRUE(reserved.back().behind_contour);
  EXPECT_EQ(reserved.back().score, all[static_cast<size_t>(in_view)].score);
  EXPECT_EQ(hypotheses(static_cast<int>(in_view), contours, 1000).size(), all.size());
  EXPECT_EQ(hypotheses(static_cast<int>(in_view) + 1, contours, 1).size(), static_cast<size_t>(in_view) + 1);

  // Without the contours, the same ones in full view and none behind.
  const std::vector<SupportHypothesis> unaided = hypotheses(100, {});
  ASSERT_EQ(unaided.size(), static_cast<size_t>(in_view));
  EXPECT_EQ(count_behind(unaided), 0);
  for (size_t i = 0; i < unaided.size(); ++i) EXPECT_EQ(unaided[i].score, all[i].score) << "hypothesis " << i;
}

// A bar on the table whose far end a short dark pole hides, the pole's top inside the bar's image
// (its two flanks end there, neither runs across): the support-plane source scores the bar where
// it stands on the outline beside the flanks' strip only with support_pole_ends and
// contour_pole_ends (its whole outline shows too little support).
TEST(ContoursTest, APlacementBesideAPoleWhoseTopIsInFrontNeedsSupportPoleEnds) {
  const auto& [camera, bar, library, bar_pose] = BarOnTheTable();
  const geometry::Pose3 camera_T_bar = camera.camera_T_world() * bar_pose;
  std::array<Eigen::Vector2d, 8> px;
  for (int v = 0; v < 8; ++v) {
    px[static_cast<size_t>(v)] = (camera.K() * (camera_T_bar * BoxVertex(bar.box_size_m, v))).hnormalized();
  }
  double lo = 1e9, hi = -1e9, top = 1e9, bottom = -1e9;
  for (const Eigen::Vector2d& p : px) {
    lo = std::min(lo, p.x()), hi = std::max(hi, p.x());
    top = std::min(top, p.y()), bottom = std::max(bottom, p.y());
  }
  // The pole over the bar's right part (from 0.25 to 1.15 of its image's width), from the image's
  // bottom up to 0.3 of the way down the bar's image.
  cv::Mat image = synthetic::RenderBoxes(camera, {{bar.box_size_m, bar_pose}}, 7);
  const double centre = lo + 0.7 * (hi - lo), half = (hi - lo) / 2.2;
  cv::rectangle(image,
                cv::Point(static_cast<int>(centre - half), static_cast<int>(top + 0.3 * (bottom - top))),
                cv::Point(static_cast<int>(centre + half), image.rows - 1), cv::Scalar(20), cv::FILLED);
  RecognizerOptions options;
  const LineDetection detection = DetectLinesAndEdges(image, camera, options);
  const std::vector<ImageLine> contours = OccludingContours(detection, camera, options);
  const std::vector<ImageCorner> corners = FindCorners(detection.lines, options);
  const BoxImage box_image(px, VisibleBoxEdges(bar.box_size_m, camera_T_bar.Inverse().translation));
  ASSERT_GE(contours.size(), 2u);
  for (const ImageLine& c : contours) EXPECT_FALSE(CrossesBoxImage(c, box_image));

  // Whether a hypothesis is the bar where it stands; whether that one is judged behind a contour.
  auto at_bar = [&](bool support_pole_ends, bool contour_pole_ends, bool* behind) {
    options.support_pole_ends = support_pole_ends;
    options.contour_pole_ends = contour_pole_ends;
    for (const SupportHypothesis& h :
         SupportHypotheses(library, camera, detection, corners, {SupportPlane{}}, options, contours)) {
      if (h.model == 1 && (h.world_T_object.translation - bar_pose.translation).norm() < 0.002) {
        *behind = h.behind_contour;
        return true;
      }
    }
    return false;
  };
  bool behind = false;
  EXPECT_TRUE(at_bar(true, true, &behind));
  EXPECT_TRUE(behind);
  EXPECT_FALSE(at_bar(false, true, &behind));
  EXPECT_FALSE(at_bar(true, false, &behind));
}

// A flat box image: the rectangle [x0, x1] x [y0, y1] with four points inside it (not on its hull).
BoxImage Flat(double x0, double y0, double x1, double y1) {
  std::array<Eigen::Vector2d, 8> px = {Eigen::Vector2d(x0, y0), Eigen::Vector2d(x1, y0),
                                       Eigen::Vector2d(x0, y1), Eigen::Vector2d(x1, y1)};
  const Eigen::Vector2d middle(0.5 * (x0 + x1), 0.5 * (y0 + y1));
  for (int v = 4; v < 8; ++v)
    px[static_cast<size_t>(v)] = middle + Eigen::Vector2d(v & 1 ? 1 : -1, v & 2 ? 1 : -1);
  return BoxImage(px, 0x0fff);
}

// A cube's image at the end of a bar's (the cube's right end at x = 245, inside the bar's): it ends at
// a contour along that end, or up to 25 px in front of it, that runs on past both its corners with its
// darker side away from the cube (a pole in front); not when the darker side is the cube's, the
// contour stops short of a corner, lies more than 25 px over the cube or leaves the end 3 px in view,
// is turned 10 deg about the end's middle, or where the cube's end is the bar's end too, or is under
// 10 px long.
TEST(ContoursTest, AShorterPoseEndsAtAContourInsideALongerOnesImage) {
  const BoxImage cube = Flat(200, 200, 245, 240), bar = Flat(200, 200, 320, 240);
  const ImageLine pole{{245, 290}, {245, 150}};  // darker side (-d.y, d.x) = +x: away from the cube
  EXPECT_TRUE(EndsAtContourInside(cube, bar, {pole}));
  EXPECT_TRUE(EndsAtContourInside(cube, bar, {{{246.5, 290}, {246.5, 150}}}));  // 1.5 px off, in front
  EXPECT_TRUE(EndsAtContourInside(cube, bar, {{{230, 290}, {230, 150}}}));      // the end 15 px behind it
  EXPECT_TRUE(EndsAtContourInside(cube, bar, {{{220, 290}, {220, 150}}}));      // 25 px
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {{{219, 290}, {219, 150}}}));     // 26 px
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {{{248, 290}, {248, 150}}}));     // the end 3 px in view
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {{{245, 150}, {245, 290}}}));     // darker towards the cube
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {{{245, 290}, {245, 195}}}));     // 5 px past one corner
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {{{245, 290}, {245, 187}}}));     // 13 px: under a third of 40
  EXPECT_TRUE(EndsAtContourInside(cube, bar, {{{245, 290}, {245, 186}}}));      // 14 px
  const double turn = 10 * M_PI / 180;
  const Eigen::Vector2d mid(245, 220), dir(std::sin(turn), -std::cos(turn));
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {{mid - 70 * dir, mid + 70 * dir}}));  // turned 10 deg
  EXPECT_FALSE(EndsAtContourInside(cube, Flat(200, 200, 245, 240), {pole}));         // the same end
  EXPECT_FALSE(EndsAtContourInside(cube, bar, {}));
  EXPECT_FALSE(EndsAtContourInside(Flat(200, 200, 245, 208), bar, {pole}));  // an end 8 px long
  EXPECT_TRUE(EndsAtContourInside(Flat(200, 200, 245, 210), bar, {pole}));   // 10 px
}

// A block's corner behind a pole: two edges that run into the pole's flank (x = 100) and whose lines
// meet beyond it, at (130, 100), give a corner there; not an edge along the flank, an edge that ends
// short of it, a pair already a corner, or a corner further beyond than the limit.
TEST(ContoursTest, EdgesRunningIntoAContourMeetAtAHiddenCorner) {
  const ImageLine flank{{100, 0}, {100, 200}};
  const Eigen::Vector2d hidden(130, 100);
  auto towards = [&](const Eigen::Vector2d& far, double stop_x) {
    const Eigen::Vector2d d = hidden - far;
    return ImageLine{far, far + (stop_x - far.x()) / d.x() * d};
  };
  const std::vector<ImageLine> lines = {
      towards({40, 70}, 99),    // 0: ends 1 px before the flank
      towards({60, 170}, 98),   // 1: ends 2 px before it
      {{97, 20}, {97, 60}},     // 2: along the flank
      {{10, 10}, {50, 20}},     // 3: ends far from it
      towards({20, 140}, 80)};  // 4: aimed at the corner, but ends 20 px left of the flank
  const JoinedLines joined = JoinCollinearLines(lines);
  RecognizerOptions options;
  const std::vector<ImageCorner> found = FindHiddenCorners(joined, {flank}, {}, options);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_LT((found[0].point - hidden).norm(), 1e-6);
  const std::array<int, 2> pair = {std::min(found[0].segments[0], found[0].segments[1]),
                                   std::max(found[0].segments[0], found[0].segments[1])};
  EXPECT_EQ(pair, (std::array<int, 2>{0, 1}));
  // The arms reach the edges' far ends.
  for (int k = 0; k < 2; ++k) {
    const ImageLine& own = lines[static_cast<size_t>(found[0].segments[static_cast<size_t>(k)])];
    EXPECT_LT((found[0].arm_end[static_cast<size_t>(k)] - own.a).norm(), 1e-9);
  }
  // No contour, or the pair already an image corner: none.
  EXPECT_TRUE(FindHiddenCorners(joined, {}, {}, options).empty());
  ImageCorner known;
  known.segments = {1, 0};
  EXPECT_TRUE(FindHiddenCorners(joined, {flank}, {known}, options).empty());
  // The corner is 33 px beyond line 0's end and 45 px beyond line 1's: not within 44 px, within 46.
  options.hidden_corner_max_gap_px = 44;
  EXPECT_TRUE(FindHiddenCorners(joined, {flank}, {}, options).empty());
  options.hidden_corner_max_gap_px = 46;
  EXPECT_EQ(FindHiddenCorners(joined, {flank}, {}, options).size(), 1u);
  // Line 4 (its line meets the flank 21 px on) joins when the reach is 22 px: it meets 0 and 1 there.
  options.hidden_corner_max_gap_px = 120;
  options.hidden_corner_reach_px = 22;
  EXPECT_EQ(FindHiddenCorners(joined, {flank}, {}, options).size(), 3u);
}

}  // namespace
}  // namespace teachsim::vision
