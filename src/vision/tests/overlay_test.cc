// The overlay of recognitions on the camera image (overlay.h): the outline through the lens, and
// what DrawRecognitions changes in the picture.
#include "teachsim/vision/overlay.h"

#include <gtest/gtest.h>

#include <cmath>

#include "synthetic_scene.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {
namespace {

// The synthetic camera with a strong barrel lens: straight edges image as curves.
Camera BarrelCamera() {
  const Camera pinhole = synthetic::SyntheticCamera();
  Distortion d;
  d.k1 = -0.3;
  d.k2 = 0.08;
  return Camera(pinhole.intrinsics(), d, pinhole.world_T_camera(), pinhole.width(), pinhole.height());
}

const Eigen::Vector3d kBar(0.09, 0.045, 0.045);
const geometry::Pose3 kOnTable(Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ())),
                               Eigen::Vector3d(0.03, -0.02, 0.0225));

TEST(OverlayTest, TheOutlineIsTheVisibleEdgesThroughTheLens) {
  for (const Camera& camera : {synthetic::SyntheticCamera(), BarrelCamera()}) {
    const geometry::Pose3 camera_T_object = camera.camera_T_world() * kOnTable;
    const uint16_t visible = VisibleBoxEdges(kBar, camera_T_object.Inverse().translation);
    int visible_edges = 0;
    for (int e = 0; e < 12; ++e) visible_edges += visible >> e & 1;
    ASSERT_EQ(visible_edges, 9);  // seen from above and a side: three faces
    const auto outline = BoxOutlineInImage(kBar, camera, camera_T_object);
    ASSERT_EQ(static_cast<int>(outline.size()), visible_edges);
    double largest_bend_px = 0;
    for (const std::vector<Eigen::Vector2d>& line : outline) {
      ASSERT_GE(line.size(), 2u);
      // Its ends are box corners as the camera images them.
      for (const Eigen::Vector2d& end : {line.front(), line.back()}) {
        double nearest = 1e9;
        for (int i = 0; i < 8; ++i) {
          nearest = std::min(nearest,
                             (*camera.ProjectFromCamera(camera_T_object * BoxVertex(kBar, i)) - end).norm());
        }
        EXPECT_LT(nearest, 1e-9);
      }
      // Every point lies on the edge's image: undistorted, on the straight line between the ends.
      const Eigen::Vector2d a = *camera.UndistortPixel(line.front()), b = *camera.UndistortPixel(line.back());
      const Eigen::Vector2d normal = Eigen::Vector2d(-(b - a).y(), (b - a).x()).normalized();
      for (size_t k = 0; k < line.size(); ++k) {
        EXPECT_LT(std::abs(normal.dot(*camera.UndistortPixel(line[k]) - a)), 1e-6);
        if (k > 0) {
          EXPECT_LE((line[k] - line[k - 1]).norm(), 8.5);
        }
        // How far the drawn curve leaves the chord between its ends.
        const Eigen::Vector2d chord = (line.back() - line.front()).normalized();
        largest_bend_px = std::max(
            largest_bend_px, std::abs(Eigen::Vector2d(-chord.y(), chord.x()).dot(line[k] - line.front())));
      }
    }
    if (camera.distortion().k1 == 0) {
      EXPECT_LT(largest_bend_px, 1e-9);
    } else {
      EXPECT_GT(largest_bend_px, 0.05);  // the lens bends the edges, and the polylines show it
    }
  }
  // A box behind the camera has no outline in the image.
  const Camera camera = synthetic::SyntheticCamera();
  EXPECT_TRUE(BoxOutlineInImage(kBar, camera, geometry::Pose3::Translation({0, 0, -0.5})).empty());
}

TEST(OverlayTest, DrawsEachRecognitionsOutlineInItsColourAndLeavesTheRestGrey) {
  const Camera camera = BarrelCamera();
  const cv::Mat image(camera.height(), camera.width(), CV_8UC1, cv::Scalar(128));
  const ModelLibrary models{{{"bar90", kBar}, {"cube45", Eigen::Vector3d::Constant(0.045)}}};
  Recognition bar;
  bar.model = "bar90";
  bar.world_T_object = kOnTable;
  bar.score = 0.93;
  Recognition cube;
  cube.model = "cube45";
  cube.world_T_object = geometry::Pose3::Translation({-0.12, 0.1, 0.0225});
  cube.score = 0.88;
  auto drawn = DrawRecognitions(image, camera, models, {bar, cube});
  ASSERT_TRUE(drawn.ok()) << drawn.status().message();
  ASSERT_EQ(drawn->type(), CV_8UC3);
  ASSERT_EQ(drawn->size(), image.size());
  auto colour_at = [&](const Eigen::Vector2d& p) {
    return drawn->at<cv::Vec3b>(static_cast<int>(std::lround(p.y())), static_cast<int>(std::lround(p.x())));
  };
  auto grey = [](const cv::Vec3b& c) { return c[0] == c[1] && c[1] == c[2]; };
  // Along each outline its colour (but where its label or the other's is written over it).
  std::vector<cv::Vec3b> colours;
  for (const Recognition& r : {bar, cube}) {
    const Eigen::Vector3d size = r.model == "bar90" ? kBar : Eigen::Vector3d::Constant(0.045);
    const auto outline = BoxOutlineInImage(size, camera, camera.camera_T_world() * r.world_T_object);
    ASSERT_FALSE(outline.empty());
    int points = 0, coloured = 0;
    for (const std::vector<Eigen::Vector2d>& line : outline) {
      for (const Eigen::Vector2d& p : line) {
        ++points;
        if (!grey(colour_at(p))) {
          ++coloured;
          if (colours.size() < (r.model == "bar90" ? 1u : 2u)) colours.push_back(colour_at(p));
        }
      }
    }
    EXPECT_GT(coloured, 0.8 * points) << r.model << ": " << coloured << " of " << points;
  }
  ASSERT_EQ(colours.size(), 2u);
  EXPECT_NE(colours.front(), colours.back());  // two objects, two colours
  // Away from both, the image is as it was.
  for (const Eigen::Vector2d& p :
       {Eigen::Vector2d(5, 5), Eigen::Vector2d(630, 470), Eigen::Vector2d(600, 20)}) {
    EXPECT_EQ(colour_at(p), cv::Vec3b(128, 128, 128));
  }
  // Not the camera's image: refused, the size named.
  auto wrong = DrawRecognitions(cv::Mat(100, 100, CV_8UC1, cv::Scalar(0)), camera, models, {bar});
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("640x480"), std::string::npos) << wrong.status().message();
  // A model the library does not have: labelled, no outline, no failure.
  Recognition unknown = bar;
  unknown.model = "sphere";
  EXPECT_TRUE(DrawRecognitions(image, camera, models, {unknown}).ok());
}

}  // namespace
}  // namespace teachsim::vision
