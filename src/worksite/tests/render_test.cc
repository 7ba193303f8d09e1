#include "teachsim/worksite/render.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "teachsim/vision/evaluate.h"

namespace teachsim::worksite {
namespace {

scene::Scene PuzzleScene() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok()) << scene.status().message();
  return *scene;
}

vision::Camera MainCamera(const scene::Scene& scene) {
  auto camera =
      vision::Camera::FromSpec(scene.cameras.at(static_cast<std::size_t>(scene.FindCamera("main"))));
  EXPECT_TRUE(camera.ok());
  return *camera;
}

double Bilinear(const cv::Mat& image, const Eigen::Vector2d& p) {
  const int x = static_cast<int>(std::floor(p.x())), y = static_cast<int>(std::floor(p.y()));
  const double fx = p.x() - x, fy = p.y() - y;
  auto at = [&](int u, int v) {
    u = std::clamp(u, 0, image.cols - 1);
    v = std::clamp(v, 0, image.rows - 1);
    return static_cast<double>(image.at<std::uint8_t>(v, u));
  };
  return (1 - fy) * ((1 - fx) * at(x, y) + fx * at(x + 1, y)) +
         fy * ((1 - fx) * at(x, y + 1) + fx * at(x + 1, y + 1));
}

int LabelAt(const cv::Mat& labels, const Eigen::Vector2d& p) {
  const int u = static_cast<int>(std::lround(p.x())), v = static_cast<int>(std::lround(p.y()));
  if (u < 0 || v < 0 || u >= labels.cols || v >= labels.rows) return -2;
  return labels.at<std::int16_t>(v, u);
}

std::vector<Eigen::Vector3d> BoxCorners(const scene::SceneObject& o) {
  std::vector<Eigen::Vector3d> corners;
  const Eigen::Vector3d half = o.shape_spec.box_size / 2;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d local((i & 1 ? 1 : -1) * half.x(), (i & 2 ? 1 : -1) * half.y(),
                                (i & 4 ? 1 : -1) * half.z());
    corners.push_back(o.world_T_object * local);
  }
  return corners;
}

// Blocks rendered from the default scene: their silhouette edges lie where the camera model
// projects them (distortion included), to well within half a pixel, and so do their corners.
TEST(RenderTest, BlockEdgesAndCornersLandWhereTheCameraModelProjectsThem) {
  const scene::Scene scene = PuzzleScene();
  const vision::Camera camera = MainCamera(scene);
  auto renderer = Renderer::Create(camera, RenderOptions::HighContrast());
  ASSERT_TRUE(renderer.ok()) << renderer.status().message();
  std::vector<RenderObject> objects = ObjectsFromScene(scene);
  for (RenderObject& o : objects) {
    o.material = Material::kFlat;
    o.albedo = o.name == "table" ? 0.2 : 0.95;
  }
  const RenderResult result = renderer->Render(objects, 1);

  int edge_samples = 0;
  double worst_edge_px = 0, sum_edge_px = 0;
  int corners_checked = 0;
  double worst_corner_px = 0;
  for (std::size_t oi = 0; oi < scene.objects.size(); ++oi) {
    const scene::SceneObject& o = scene.objects[oi];
    if (o.fixed) continue;
    const std::vector<Eigen::Vector3d> c = BoxCorners(o);
    // The top face: corners 4..7 (local +z, the blocks stand upright), in order around the face.
    const std::vector<Eigen::Vector3d> top{c[4], c[5], c[7], c[6]};
    for (int e = 0; e < 4; ++e) {
      const Eigen::Vector3d a = top[static_cast<std::size_t>(e)],
                            b = top[static_cast<std::size_t>((e + 1) % 4)];
      for (double s = 0.1; s <= 0.9; s += 0.02) {
        const Eigen::Vector2d p = *camera.Project(a + s * (b - a));
        const Eigen::Vector2d tangent =
            (*camera.Project(a + (s + 0.01) * (b - a)) - *camera.Project(a + (s - 0.01) * (b - a)))
                .normalized();
        const Eigen::Vector2d normal(-tangent.y(), tangent.x());
        // Only silhouette edges: the object on one side, one other object or the table on the other.
        const int inside = LabelAt(result.labels, p - 3 * normal),
                  outside = LabelAt(result.labels, p + 3 * normal);
        const bool in_first = inside == static_cast<int>(oi);
        const int other = in_first ? outside : inside;
        if (!(in_first || outside == static_cast<int>(oi)) || other == static_cast<int>(oi) || other < -1)
          continue;
        bool clean = true;
        for (double t = 1; t <= 4.5; t += 0.5) {
          const int l_minus = LabelAt(result.labels, p - t * normal),
                    l_plus = LabelAt(result.labels, p + t * normal);
          clean = clean && (in_first ? (l_minus == static_cast<int>(oi) && l_plus == other)
                                     : (l_plus == static_cast<int>(oi) && l_minus == other));
        }
        if (!clean) continue;
        const double lo = Bilinear(result.image, p - 3.5 * normal),
                     hi = Bilinear(result.image, p + 3.5 * normal);
        if (std::abs(hi - lo) < 60) continue;
        const double level = (lo + hi) / 2;
        // The 50 % crossing of the anti-aliased step, searched along the normal.
        double crossing = 1e9;
        double prev = Bilinear(result.image, p - 3.0 * normal);
        for (double t = -3.0 + 0.02; t <= 3.0; t += 0.02) {
          const double now = Bilinear(result.image, p + t * normal);
          if ((prev - level) * (now - level) <= 0 && prev != now) {
            const double cross_t = t - 0.02 + 0.02 * (level - prev) / (now - prev);
            if (std::abs(cross_t) < std::abs(crossing)) crossing = cross_t;
          }
          prev = now;
        }
        ASSERT_LT(std::abs(crossing), 5.0) << o.name << " edge " << e << " s " << s;
        worst_edge_px = std::max(worst_edge_px, std::abs(crossing));
        sum_edge_px += std::abs(crossing);
        ++edge_samples;
      }
    }
    // Corners: sub-pixel corner detection from a start 1.5 px away converges onto the projection.
    for (const Eigen::Vector3d& corner : top) {
      const Eigen::Vector2d p = *camera.Project(corner);
      std::set<int> labels;
      for (int dv = -5; dv <= 5; ++dv) {
        for (int du = -5; du <= 5; ++du) labels.insert(LabelAt(result.labels, p + Eigen::Vector2d(du, dv)));
      }
      // A clean corner: this object and exactly one other thing around it.
      if (labels.size() != 2 || !labels.count(static_cast<int>(oi)) || labels.count(-2)) continue;
      std::vector<cv::Point2f> points{
          cv::Point2f(static_cast<float>(p.x() + 1.1), static_cast<float>(p.y() - 1.0))};
      cv::cornerSubPix(result.image, points, cv::Size(4, 4), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
      const double error = (Eigen::Vector2d(points[0].x, points[0].y) - p).norm();
      worst_corner_px = std::max(worst_corner_px, error);
      ++corners_checked;
    }
  }
  std::printf("edge samples %d: mean %.3f px, worst %.3f px; corners %d: worst %.3f px\n", edge_samples,
              sum_edge_px / std::max(1, edge_samples), worst_edge_px, corners_checked, worst_corner_px);
  EXPECT_GE(edge_samples, 100);
  EXPECT_LT(worst_edge_px, 0.5);
  EXPECT_LT(sum_edge_px / edge_samples, 0.15);
  EXPECT_GE(corners_checked, 4);
  EXPECT_LT(worst_corner_px, 0.5);
}

TEST(RenderTest, SameSeedGivesByteIdenticalImages) {
  const scene::Scene scene = PuzzleScene();
  auto renderer = Renderer::Create(MainCamera(scene), RenderOptions{});
  ASSERT_TRUE(renderer.ok());
  const auto objects = ObjectsFromScene(scene);
  std::vector<std::uint8_t> a, b, c;
  cv::imencode(".png", renderer->Render(objects, 7).image, a);
  cv::imencode(".png", renderer->Render(objects, 7).image, b);
  cv::imencode(".png", renderer->Render(objects, 8).image, c);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  // A second renderer built from the same inputs agrees too (nothing hidden carries over).
  auto again = Renderer::Create(MainCamera(scene), RenderOptions{});
  ASSERT_TRUE(again.ok());
  std::vector<std::uint8_t> d;
  cv::imencode(".png", again->Render(objects, 7).image, d);
  EXPECT_EQ(a, d);
}

// A camera with a gamma: the same light, blended and blurred linearly, written as 255 (E / 255)^(1 /
// gamma); the same picture otherwise (noise off to compare pixel by pixel).
TEST(RenderTest, AGammaCameraEncodesTheLinearPicture) {
  const scene::Scene scene = PuzzleScene();
  RenderOptions options;
  options.noise_sigma = 0;
  vision::Camera srgb = MainCamera(scene);
  srgb.set_gamma(2.2);
  auto linear_renderer = Renderer::Create(MainCamera(scene), options);
  auto srgb_renderer = Renderer::Create(srgb, options);
  ASSERT_TRUE(linear_renderer.ok() && srgb_renderer.ok());
  const auto objects = ObjectsFromScene(scene);
  const RenderResult linear = linear_renderer->Render(objects, 7),
                     encoded = srgb_renderer->Render(objects, 7);
  int compared = 0, brighter = 0;
  for (int v = 0; v < linear.image.rows; ++v) {
    for (int u = 0; u < linear.image.cols; ++u) {
      const double g = linear.image.at<std::uint8_t>(v, u);
      if (g < 10 || g > 250) continue;  // where the encoding's slope makes rounding count
      const double expected = 255.0 * std::pow(g / 255.0, 1 / 2.2);
      ASSERT_NEAR(encoded.image.at<std::uint8_t>(v, u), expected, 2.0) << "pixel " << u << ", " << v;
      ++compared;
      brighter += encoded.image.at<std::uint8_t>(v, u) > g;
    }
  }
  EXPECT_GT(compared, 200000);
  EXPECT_EQ(brighter, compared);  // mid greys come out brighter
}

TEST(RenderTest, VisibleFractionCountsOcclusionAndTheImageBorder) {
  const scene::Scene scene = PuzzleScene();
  const vision::Camera camera = MainCamera(scene);
  auto renderer = Renderer::Create(camera, RenderOptions::HighContrast());
  ASSERT_TRUE(renderer.ok());
  auto cube = geometry::ConvexPolyhedron::Box(Eigen::Vector3d(0.045, 0.045, 0.045));
  ASSERT_TRUE(cube.ok());
  auto convex = std::make_shared<const geometry::ConvexPolyhedron>(std::move(*cube));
  RenderObject block;
  block.name = "cube";
  block.parts = {{convex, geometry::Pose3::Identity()}};
  block.world_T_object = geometry::Pose3::Translation(Eigen::Vector3d(0, 0, 0.0225));
  // Alone in the middle of the view: all of it visible.
  const RenderResult alone = renderer->Render({block}, 1);
  ASSERT_EQ(alone.objects.size(), 1u);
  EXPECT_GT(alone.objects[0].visible_pixels, 2000);
  EXPECT_NEAR(alone.objects[0].visible_fraction, 1.0, 1e-9);

  // A second cube between it and the camera hides part of it.
  RenderObject front = block;
  front.name = "front";
  const Eigen::Vector3d towards_camera =
      (camera.world_T_camera().translation - Eigen::Vector3d(0, 0, 0.0225)).normalized();
  front.world_T_object =
      geometry::Pose3::Translation(Eigen::Vector3d(0.02, 0, 0.0225) + 0.1 * towards_camera);
  const RenderResult occluded = renderer->Render({block, front}, 1);
  const double expected =
      static_cast<double>(occluded.objects[0].visible_pixels) / alone.objects[0].visible_pixels;
  EXPECT_LT(occluded.objects[0].visible_fraction, 0.9);
  EXPECT_GT(occluded.objects[0].visible_fraction, 0.05);
  EXPECT_NEAR(occluded.objects[0].visible_fraction, expected, 0.01);

  // Half out of the image: put its centre on the ray through the middle of the left border.
  const vision::Ray ray = *camera.Unproject(Eigen::Vector2d(-0.5, 239.5));
  const double t = (0.0225 - ray.origin_in_world.z()) / ray.direction_in_world.z();
  RenderObject edge = block;
  edge.world_T_object = geometry::Pose3::Translation(ray.origin_in_world + t * ray.direction_in_world);
  const RenderResult clipped = renderer->Render({edge}, 1);
  EXPECT_NEAR(clipped.objects[0].visible_fraction, 0.5, 0.1);
}

// The labels give each object its pixels in view; a bar whose far half the image border cuts off
// shows in them what a cube at its near end would (vision::ShorterModelsInView), a bar in full view
// or one that reaches well past its middle into the image does not.
TEST(RenderTest, PixelsInViewTellWhatAShorterBlockWouldShowAlike) {
  const scene::Scene scene = PuzzleScene();
  const vision::Camera camera = MainCamera(scene);
  auto renderer = Renderer::Create(camera, RenderOptions::HighContrast());
  ASSERT_TRUE(renderer.ok());
  const Eigen::Vector3d size(0.09, 0.045, 0.045);
  auto box = geometry::ConvexPolyhedron::Box(size);
  ASSERT_TRUE(box.ok());
  RenderObject bar;
  bar.name = "bar";
  bar.model = "bar90";
  bar.parts = {
      {std::make_shared<const geometry::ConvexPolyhedron>(std::move(*box)), geometry::Pose3::Identity()}};
  // Its long axis along the image's rows, as they run over the table.
  Eigen::Vector3d along = camera.world_T_camera().rotation * Eigen::Vector3d::UnitX();
  along.z() = 0;
  const Eigen::Quaterniond yaw =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitX(), along.normalized());
  // The bar's centre on the table where the ray through image column u, middle row, meets its height.
  auto bar_at_column = [&](double u) {
    const vision::Ray ray = *camera.Unproject(Eigen::Vector2d(u, 239.5));
    const double t = (0.0225 - ray.origin_in_world.z()) / ray.direction_in_world.z();
    RenderObject o = bar;
    o.world_T_object = geometry::Pose3(yaw, ray.origin_in_world + t * ray.direction_in_world);
    return o;
  };
  const std::map<std::string, Eigen::Vector3d> sizes = {{"cube45", {0.045, 0.045, 0.045}}, {"bar90", size}};
  auto shorter = [&](const RenderObject& o) {
    const RenderResult result = renderer->Render({o}, 1);
    const std::vector<std::vector<Eigen::Vector2d>> in_view = PixelsInView(result);
    EXPECT_EQ(in_view.size(), 1u);
    EXPECT_EQ(static_cast<int>(in_view[0].size()), result.objects[0].visible_pixels);
    for (const Eigen::Vector2d& p : in_view[0]) EXPECT_EQ(LabelAt(result.labels, p), 0) << p.transpose();
    auto names = vision::ShorterModelsInView(sizes, "bar90", o.world_T_object, camera, in_view[0]);
    EXPECT_TRUE(names.ok()) << names.status().message();
    // The region's outline: some of its pixels, far fewer, and the same answer.
    const std::vector<std::vector<Eigen::Vector2d>> outline = OutlinePixelsInView(result);
    EXPECT_EQ(outline.size(), 1u);
    EXPECT_GT(outline[0].size(), 0u);
    EXPECT_LT(5 * outline[0].size(), in_view[0].size());
    for (const Eigen::Vector2d& p : outline[0]) EXPECT_EQ(LabelAt(result.labels, p), 0) << p.transpose();
    auto from_outline = vision::ShorterModelsInView(sizes, "bar90", o.world_T_object, camera, outline[0]);
    EXPECT_TRUE(from_outline.ok() && names.ok() && *from_outline == *names);
    return names.ok() ? *names : std::vector<std::string>{"error"};
  };
  using Names = std::vector<std::string>;
  EXPECT_EQ(shorter(bar_at_column(319.5)), Names{});
  // Its middle 15 px left of the image: the half in view is a cube's.
  EXPECT_EQ(shorter(bar_at_column(-15)), Names{"cube45"});
  // Its middle 30 px into the image: more than a cube in view.
  EXPECT_EQ(shorter(bar_at_column(30)), Names{});
}

// The outline of a region: its pixels with a 4-neighbour of another label or outside the image.
TEST(RenderTest, OutlinePixelsInViewAreTheRegionsRim) {
  RenderResult result;
  result.objects.resize(2);
  result.labels = cv::Mat(6, 8, CV_16SC1, cv::Scalar(-1));
  result.labels(cv::Rect(1, 1, 5, 4)).setTo(0);  // a 5 x 4 block inside the image: 14 on its rim
  result.labels(cv::Rect(6, 0, 2, 6)).setTo(1);  // a 2 x 6 strip along the right border: all 12
  result.labels.at<std::int16_t>(2, 3) = 1;      // a pixel of 1 inside 0: its 4 neighbours join the rim
  const auto outline = OutlinePixelsInView(result);
  const auto all = PixelsInView(result);
  ASSERT_EQ(outline.size(), 2u);
  EXPECT_EQ(all[0].size(), 19u);
  EXPECT_EQ(outline[0].size(), 14u + 3u);  // the rim, and the 3 inner pixels beside the one of 1
  EXPECT_EQ(outline[1].size(), 13u);
  for (int k = 0; k < 2; ++k) {
    for (const Eigen::Vector2d& p : outline[static_cast<size_t>(k)])
      EXPECT_NE(std::find(all[static_cast<size_t>(k)].begin(), all[static_cast<size_t>(k)].end(), p),
                all[static_cast<size_t>(k)].end());
  }
  const std::vector<Eigen::Vector2d> inner = {{2, 2}, {4, 2}, {3, 3}};
  for (const Eigen::Vector2d& p : inner)
    EXPECT_NE(std::find(outline[0].begin(), outline[0].end(), p), outline[0].end()) << p.transpose();
}

TEST(RenderTest, RejectsBadOptions) {
  const scene::Scene scene = PuzzleScene();
  RenderOptions options;
  options.supersample = 0;
  auto bad = Renderer::Create(MainCamera(scene), options);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("supersample"), std::string::npos);
  options = RenderOptions{};
  options.noise_sigma = -1;
  EXPECT_FALSE(Renderer::Create(MainCamera(scene), options).ok());
}

}  // namespace
}  // namespace teachsim::worksite
