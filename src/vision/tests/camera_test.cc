#include "teachsim/vision/camera.h"

#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <random>

namespace teachsim::vision {
namespace {

scene::CameraSpec PuzzleCamera() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  EXPECT_TRUE(scene.ok()) << scene.status().message();
  const int i = scene->FindCamera("main");
  EXPECT_GE(i, 0);
  return scene->cameras[static_cast<std::size_t>(i)];
}

Camera StrongDistortionCamera() {
  // Tangential terms and k3 too, so every term of the model is exercised.
  return Camera({700, 690, 330.2, 236.7}, {-0.28, 0.09, 0.0012, -0.0008, -0.01},
                geometry::Pose3::FromAxisAngle(Eigen::Vector3d(0.3, 1, 0.2).normalized(), 2.5,
                                               Eigen::Vector3d(0.1, 0.4, 0.5)),
                640, 480);
}

TEST(CameraTest, BuildsFromTheDefaultSceneCamera) {
  const scene::CameraSpec spec = PuzzleCamera();
  auto camera = Camera::FromSpec(spec);
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  EXPECT_EQ(camera->width(), 640);
  EXPECT_DOUBLE_EQ(camera->intrinsics().fx, 764.0);
  EXPECT_DOUBLE_EQ(camera->distortion().k1, -0.24);
  const scene::CameraSpec back = camera->ToSpec("main");
  EXPECT_EQ(scene::WriteCamera(back), scene::WriteCamera(spec));
  // The camera looks at the work area: the world origin projects into the image.
  auto origin = camera->Project(Eigen::Vector3d::Zero());
  ASSERT_TRUE(origin.has_value());
  EXPECT_TRUE(camera->InImage(*origin));
}

TEST(CameraTest, RejectsBadSpecs) {
  scene::CameraSpec spec = PuzzleCamera();
  spec.fx = -1;
  auto bad = Camera::FromSpec(spec);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("fx"), std::string::npos);
  spec = PuzzleCamera();
  spec.k1 = std::nan("");
  EXPECT_FALSE(Camera::FromSpec(spec).ok());
  spec = PuzzleCamera();
  spec.world_T_camera.rotation.coeffs() *= 2.0;
  EXPECT_FALSE(Camera::FromSpec(spec).ok());
  spec = PuzzleCamera();
  spec.gamma = 0;
  bad = Camera::FromSpec(spec);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("gamma must be in [0.5, 4], got 0"), std::string::npos)
      << bad.status().message();
}

// The response: linear unless the camera entry says otherwise; a gamma goes through the camera and
// back, and only a camera that is not linear writes the field.
TEST(CameraTest, GammaIsLinearUnlessTheEntrySaysOtherwise) {
  scene::CameraSpec spec = PuzzleCamera();
  auto linear = Camera::FromSpec(spec);
  ASSERT_TRUE(linear.ok());
  EXPECT_EQ(linear->gamma(), 1.0);
  EXPECT_FALSE(scene::WriteCamera(linear->ToSpec("main")).contains("gamma"));
  spec.gamma = 2.2;
  auto srgb = Camera::FromSpec(spec);
  ASSERT_TRUE(srgb.ok());
  EXPECT_EQ(srgb->gamma(), 2.2);
  const json::Json written = scene::WriteCamera(srgb->ToSpec("main"));
  EXPECT_EQ(written.at("gamma").get<double>(), 2.2);
  auto read = json::Decode<scene::CameraSpec>(written, "camera.json",
                                              [](const json::Reader& r) { return scene::ReadCamera(r); });
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->gamma, 2.2);
}

TEST(CameraTest, ProjectionMatchesOpenCV) {
  const Camera camera = StrongDistortionCamera();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> xy(-0.25, 0.25), z(0.3, 1.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < 200; ++i) {
    const double depth = z(rng);
    points.emplace_back(xy(rng) * depth * 2, xy(rng) * depth * 1.5, depth);
  }
  const cv::Mat k = (cv::Mat_<double>(3, 3) << 700, 0, 330.2, 0, 690, 236.7, 0, 0, 1);
  const cv::Mat dist = (cv::Mat_<double>(1, 5) << -0.28, 0.09, 0.0012, -0.0008, -0.01);
  std::vector<cv::Point2d> expected;
  cv::projectPoints(points, cv::Mat::zeros(3, 1, CV_64F), cv::Mat::zeros(3, 1, CV_64F), k, dist, expected);
  for (std::size_t i = 0; i < points.size(); ++i) {
    auto pixel = camera.ProjectFromCamera(Eigen::Vector3d(points[i].x, points[i].y, points[i].z));
    ASSERT_TRUE(pixel.has_value());
    EXPECT_NEAR(pixel->x(), expected[i].x, 1e-9);
    EXPECT_NEAR(pixel->y(), expected[i].y, 1e-9);
  }
  // Points behind the camera do not project.
  EXPECT_FALSE(camera.ProjectFromCamera(Eigen::Vector3d(0.1, 0.1, -0.5)).has_value());
}

TEST(CameraTest, UndistortAgreesWithOpenCVRunToConvergence) {
  const Camera camera = StrongDistortionCamera();
  const cv::Mat kk = (cv::Mat_<double>(3, 3) << 700, 0, 330.2, 0, 690, 236.7, 0, 0, 1);
  const cv::Mat dist = (cv::Mat_<double>(1, 5) << -0.28, 0.09, 0.0012, -0.0008, -0.01);
  std::vector<cv::Point2d> pixels, normalized;
  for (int v = 0; v < 480; v += 37) {
    for (int u = 0; u < 640; u += 41) pixels.emplace_back(u, v);
  }
  pixels.emplace_back(0, 0);
  pixels.emplace_back(639, 479);
  cv::undistortPoints(pixels, normalized, kk, dist, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 500, 1e-15));
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    auto n = camera.PixelToNormalized(Eigen::Vector2d(pixels[i].x, pixels[i].y));
    ASSERT_TRUE(n.has_value()) << pixels[i];
    EXPECT_NEAR(n->x(), normalized[i].x, 1e-7) << pixels[i];
    EXPECT_NEAR(n->y(), normalized[i].y, 1e-7) << pixels[i];
    // And the round trip is exact to far below a pixel.
    const Eigen::Vector2d back = camera.NormalizedToPixel(*n);
    EXPECT_NEAR((back - Eigen::Vector2d(pixels[i].x, pixels[i].y)).norm(), 0.0, 1e-8);
  }
}

TEST(CameraTest, WarmStartedUndistortionGivesTheSameAnswer) {
  const Camera camera = StrongDistortionCamera();
  Eigen::Vector2d previous(0, 0);
  for (double y = -0.35; y <= 0.35; y += 0.05) {
    for (double x = -0.45; x <= 0.45; x += 0.01) {
      auto cold = camera.Undistort({x, y});
      auto warm = camera.Undistort({x, y}, previous);
      ASSERT_TRUE(cold && warm);
      EXPECT_LT((*cold - *warm).norm(), 1e-12);
      previous = *warm;
    }
  }
}

TEST(CameraTest, DistortJacobianMatchesFiniteDifferences) {
  const Camera camera = StrongDistortionCamera();
  for (const Eigen::Vector2d& n :
       {Eigen::Vector2d(0.1, -0.2), Eigen::Vector2d(-0.4, 0.3), Eigen::Vector2d(0, 0)}) {
    const Eigen::Matrix2d j = camera.DistortJacobian(n);
    const double h = 1e-7;
    for (int c = 0; c < 2; ++c) {
      Eigen::Vector2d dn = Eigen::Vector2d::Zero();
      dn[c] = h;
      const Eigen::Vector2d column = (camera.Distort(n + dn) - camera.Distort(n - dn)) / (2 * h);
      EXPECT_NEAR((column - j.col(c)).norm(), 0.0, 1e-7);
    }
  }
}

TEST(CameraTest, UnprojectedRaysHitThePointsThatProjectedThere) {
  auto camera = Camera::FromSpec(PuzzleCamera());
  ASSERT_TRUE(camera.ok());
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> x(-0.2, 0.2), z(0, 0.1);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d p(x(rng), x(rng), z(rng));
    auto pixel = camera->Project(p);
    ASSERT_TRUE(pixel.has_value());
    auto ray = camera->Unproject(*pixel);
    ASSERT_TRUE(ray.has_value());
    const Eigen::Vector3d to_p = p - ray->origin_in_world;
    // Distance of p from the ray: below a micrometre.
    EXPECT_LT((to_p - to_p.dot(ray->direction_in_world) * ray->direction_in_world).norm(), 1e-9);
    EXPECT_GT(to_p.dot(ray->direction_in_world), 0);
  }
}

TEST(CameraTest, StraightWorldEdgesAreStraightInNormalizedCoordinates) {
  auto camera = Camera::FromSpec(PuzzleCamera());
  ASSERT_TRUE(camera.ok());
  // A table edge from one side of the view to the other: curved in pixels (barrel distortion)...
  const Eigen::Vector3d a(-0.25, -0.15, 0.0), b(0.25, -0.15, 0.0);
  const Eigen::Vector2d pa = *camera->Project(a), pb = *camera->Project(b),
                        pm = *camera->Project((a + b) / 2);
  const Eigen::Vector3d pixel_line = LineThrough(pa, pb);
  EXPECT_GT(std::abs(pixel_line.head<2>().dot(pm) + pixel_line.z()), 1.0)
      << "the edge should curve by > 1 px";
  // ...straight after undistortion.
  auto segment = camera->SegmentToNormalized({pa, pb});
  ASSERT_TRUE(segment.has_value());
  const Eigen::Vector3d line = LineThrough(segment->a, segment->b);
  const Eigen::Vector2d nm = *camera->PixelToNormalized(pm);
  EXPECT_LT(std::abs(line.head<2>().dot(nm) + line.z()), 1e-9);
  auto ideal = camera->UndistortPixel(pm);
  ASSERT_TRUE(ideal.has_value());
  const Eigen::Vector3d ideal_line = LineThrough(*camera->UndistortPixel(pa), *camera->UndistortPixel(pb));
  EXPECT_LT(std::abs(ideal_line.head<2>().dot(*ideal) + ideal_line.z()), 1e-6);
  // The interpretation plane holds every point of the edge.
  auto normal = camera->InterpretationPlaneNormal({pa, pb});
  ASSERT_TRUE(normal.has_value());
  for (double t : {0.0, 0.3, 0.77, 1.0}) {
    const Eigen::Vector3d p_in_camera = camera->camera_T_world() * (a + t * (b - a));
    EXPECT_LT(std::abs(normal->dot(p_in_camera)), 1e-9);
  }
}

// DistortPixel puts an ideal camera's pixel back where the lens images it: it undoes UndistortPixel
// across the picture, and agrees with projecting the pixel's ray.
TEST(CameraTest, DistortPixelUndoesUndistortPixel) {
  auto camera = Camera::FromSpec(PuzzleCamera());
  ASSERT_TRUE(camera.ok());
  const Eigen::Matrix3d K_inv = camera->K().inverse();
  for (double u : {0.0, 100.5, 319.5, 639.0}) {
    for (double v : {0.0, 240.25, 479.0}) {
      const auto ideal = camera->UndistortPixel({u, v});
      ASSERT_TRUE(ideal.has_value());
      EXPECT_LT((camera->DistortPixel(*ideal) - Eigen::Vector2d(u, v)).norm(), 1e-9) << u << ", " << v;
      EXPECT_LT(
          (camera->DistortPixel(*ideal) - *camera->ProjectFromCamera(K_inv * ideal->homogeneous())).norm(),
          1e-9);
    }
  }
}

// A lens without tangential terms is undistorted along each point's radius (a 1-D Newton); a
// tangential term too small to change any sum (1e-300) sends the same lens through the 2-D Newton.
// Both give the same point, cold and warm started, and refuse the same points past the fold.
TEST(CameraTest, RadialLensUndistortsAsTheGeneralNewtonDoes) {
  for (const Distortion& lens : {Distortion{-0.25, 0.02, 0, 0, 0}, Distortion{-0.28, 0.09, 0, 0, -0.01},
                                 Distortion{0.05, 0.0, 0, 0, 0}, Distortion{-0.4, 0, 0, 0, 0}}) {
    const Camera radial({700, 690, 330.2, 236.7}, lens, geometry::Pose3::Identity(), 640, 480);
    Distortion nudged = lens;
    nudged.p1 = 1e-300;
    const Camera general({700, 690, 330.2, 236.7}, nudged, geometry::Pose3::Identity(), 640, 480);
    int refused = 0;
    for (double y = -0.9; y <= 0.9; y += 0.05) {
      Eigen::Vector2d previous(0, 0);  // the answer for the point before, along the row
      bool have_previous = false;
      for (double x = -1.2; x <= 1.2; x += 0.01) {
        const auto a = radial.Undistort({x, y});
        const auto b = general.Undistort({x, y});
        ASSERT_EQ(a.has_value(), b.has_value()) << lens.k1 << " at " << x << ", " << y;
        if (!a) {
          ++refused;
          have_previous = false;
          continue;
        }
        EXPECT_LT((*a - *b).norm(), 1e-13) << lens.k1 << " at " << x << ", " << y;
        // Within the image's field (a 640 x 480 image at 700 px focal length reaches 0.47, 0.34):
        // the round trip, and the answer warm started from the neighbour's, as the renderer scans.
        // (Far out, where the polynomial has several roots, a warm start may find another, as
        // the 2-D Newton's does.)
        if (std::abs(x) > 0.5 || std::abs(y) > 0.4) continue;
        EXPECT_LT((radial.Distort(*a) - Eigen::Vector2d(x, y)).norm(), 1e-13);
        const auto warm = radial.Undistort({x, y}, have_previous ? previous : *a);
        ASSERT_TRUE(warm.has_value()) << lens.k1 << " at " << x << ", " << y;
        EXPECT_LT((*warm - *a).norm(), 1e-13);
        previous = *warm;
        have_previous = true;
      }
    }
    // The centre maps to itself; a pincushion lens never folds here, the strongest barrel lens does.
    EXPECT_EQ(*radial.Undistort({0, 0}), Eigen::Vector2d(0, 0));
    if (lens.k1 > 0) {
      EXPECT_EQ(refused, 0);
    }
    if (lens.k1 <= -0.4) {
      EXPECT_GT(refused, 0);
    }
  }
}

TEST(CameraTest, UndistortRefusesPointsBeyondTheFold) {
  // k1 < 0 alone: r_d = r (1 + k1 r^2) peaks at r = 1/sqrt(-3 k1); beyond its peak value no preimage.
  const Camera camera({500, 500, 320, 240}, {-0.4, 0, 0, 0, 0}, geometry::Pose3::Identity(), 640, 480);
  const double r_peak = 1 / std::sqrt(1.2);
  const double rd_peak = r_peak * (1 - 0.4 * r_peak * r_peak);
  EXPECT_TRUE(camera.Undistort(Eigen::Vector2d(rd_peak * 0.9, 0)).has_value());
  EXPECT_FALSE(camera.Undistort(Eigen::Vector2d(rd_peak * 1.1, 0)).has_value());
}

TEST(CameraTest, SegmentInViewHoldsWhatThePictureShows) {
  const Camera camera = StrongDistortionCamera();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 639), v(0, 479), depth(0.2, 2), far(-30, 30);
  int clipped = 0;
  for (int i = 0; i < 2000; ++i) {
    // A point the picture shows, joined to a point anywhere (behind the camera too).
    const auto ray = camera.UnprojectToCamera({u(rng), v(rng)});
    if (!ray) continue;
    const Eigen::Vector3d p = depth(rng) * *ray;
    const Eigen::Vector3d q(far(rng), far(rng), far(rng));
    const auto range = camera.SegmentInView(p, q);
    ASSERT_TRUE(range.has_value());
    EXPECT_EQ(range->first, 0);  // the end in the picture is in view
    ASSERT_LE(range->first, range->second);
    ASSERT_LE(range->second, 1);
    // The part in view is in front and within a picture and a half of the image: nowhere near the
    // millions of pixels a point next to the camera plane projects to.
    for (double s : {0.0, 0.5, 1.0}) {
      const Eigen::Vector3d x = p + (range->first + s * (range->second - range->first)) * (q - p);
      ASSERT_GT(x.z(), 0);
      const auto px = camera.ProjectFromCamera(x);
      ASSERT_TRUE(px.has_value());
      EXPECT_LT(std::abs(px->x() - 320), 1000);
      EXPECT_LT(std::abs(px->y() - 240), 800);
    }
    clipped += range->second < 1 ? 1 : 0;
  }
  EXPECT_GT(clipped, 1500);  // most far ends lie outside the view
  // A segment wholly in view is kept whole, exactly.
  const auto whole = camera.SegmentInView({-0.05, 0.02, 0.5}, {0.04, -0.03, 0.7});
  ASSERT_TRUE(whole.has_value());
  EXPECT_EQ(whole->first, 0);
  EXPECT_EQ(whole->second, 1);
  // Behind the camera, or beside it, none is.
  EXPECT_FALSE(camera.SegmentInView({0, 0, -0.5}, {0.1, 0, -0.2}).has_value());
  EXPECT_FALSE(camera.SegmentInView({5, 0, 0.5}, {6, 0.1, 0.5}).has_value());
}

TEST(CameraTest, SegmentInViewLeavesOutWhatTheLensModelFoldsIntoThePicture) {
  // k1 = -0.4: r_d = r (1 - 0.4 r^2) peaks at r = 0.91, and a point at r = 1.8 (61 deg off the axis)
  // "projects" to x = 320 - 0.53 * 500 = 54 px, inside the picture, mirrored.
  const Camera camera({500, 500, 320, 240}, {-0.4, 0, 0, 0, 0}, geometry::Pose3::Identity(), 640, 480);
  const Eigen::Vector3d folded(1.8, 0, 1);
  const auto px = camera.ProjectFromCamera(folded);
  ASSERT_TRUE(px.has_value());
  ASSERT_TRUE(camera.InImage(*px));
  EXPECT_FALSE(camera.SegmentInView(folded, folded + Eigen::Vector3d(0, 0.01, 0)).has_value());
  // A segment from the axis out past the fold is cut at 0.98 of the fold's radius.
  const auto range = camera.SegmentInView({0, 0, 1}, {2, 0, 1});
  ASSERT_TRUE(range.has_value());
  EXPECT_EQ(range->first, 0);
  EXPECT_NEAR(2 * range->second, 0.98 / std::sqrt(1.2), 2e-3);
}

}  // namespace
}  // namespace teachsim::vision
