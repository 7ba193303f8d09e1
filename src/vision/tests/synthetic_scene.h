// Synthetic cases with known answers for the recognizer's tests: a camera looking down at a table
// and boxes drawn as flat-shaded faces (exact renders: no distortion, area-sampled polygons).
#pragma once

#include <opencv2/imgproc.hpp>
#include <utility>
#include <vector>

#include "teachsim/vision/camera.h"

namespace teachsim::vision::synthetic {

// A camera 0.6 m from the origin, looking down at 45 degrees; no distortion, so that polygons
// drawn with OpenCV are exact renders.
inline Camera SyntheticCamera() {
  const Eigen::Vector3d centre(0.35, -0.3, 0.45);
  const Eigen::Vector3d z = (-centre).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_R_camera;
  world_R_camera << x, y, z;
  return Camera({760, 760, 319.5, 239.5}, {}, {Eigen::Quaterniond(world_R_camera), centre}, 640, 480);
}

// Renders boxes as flat-shaded faces (painter's order, farthest first) on a grey table with a
// little noise: the grey of a face depends on its normal, as under a distant light (face_grey +
// face_light * the cosine). Drawn 4x
// larger and averaged down (area sampling, exact pixel-centre convention).
inline cv::Mat RenderBoxes(const Camera& camera,
                           const std::vector<std::pair<Eigen::Vector3d, geometry::Pose3>>& boxes,
                           uint32_t seed, double table_grey = 90, double face_grey = 140,
                           double face_light = 110) {
  constexpr int kSuper = 4;
  cv::Mat image(kSuper * camera.height(), kSuper * camera.width(), CV_8U, cv::Scalar(table_grey));
  std::vector<std::pair<double, size_t>> order;
  for (size_t i = 0; i < boxes.size(); ++i) {
    order.push_back({-(camera.camera_T_world() * boxes[i].second.translation).z(), i});
  }
  std::sort(order.begin(), order.end());
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.5, 1).normalized();
  for (const auto& [depth, i] : order) {
    const auto& [size, pose] = boxes[i];
    const Eigen::Vector3d c = (camera.camera_T_world() * pose).Inverse().translation;
    for (int axis = 0; axis < 3; ++axis) {
      for (int side = 0; side < 2; ++side) {
        const double s = side ? 1 : -1;
        if (s * c[axis] <= 0.5 * size[axis]) continue;  // faces away
        std::vector<cv::Point> polygon;
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
        const int corners[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
        for (const auto& k : corners) {
          Eigen::Vector3d p;
          p[axis] = s * 0.5 * size[axis];
          p[a1] = (k[0] ? 0.5 : -0.5) * size[a1];
          p[a2] = (k[1] ? 0.5 : -0.5) * size[a2];
          const Eigen::Vector2d px = *camera.Project(pose * p);
          // Low-res pixel centre u is at kSuper * (u + 0.5) - 0.5 in the large image; 4 bits of sub-pixel.
          polygon.emplace_back(static_cast<int>(std::lround((kSuper * (px.x() + 0.5) - 0.5) * 16)),
                               static_cast<int>(std::lround((kSuper * (px.y() + 0.5) - 0.5) * 16)));
        }
        Eigen::Vector3d normal = Eigen::Vector3d::Zero();
        normal[axis] = s;
        const double shade = std::max(0.0, light.dot(pose.Rotate(normal)));
        cv::fillConvexPoly(image, polygon, cv::Scalar(face_grey + face_light * shade), cv::LINE_8, 4);
      }
    }
  }
  cv::resize(image, image, cv::Size(camera.width(), camera.height()), 0, 0, cv::INTER_AREA);
  cv::Mat noise(image.size(), CV_8S);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0, 2);
  cv::Mat out;
  cv::add(image, noise, out, cv::noArray(), CV_8U);
  return out;
}

// One box on the table (RenderBoxes with a single box).
inline cv::Mat RenderBox(const Camera& camera, const Eigen::Vector3d& size, const geometry::Pose3& pose, uint32_t seed = 5) {
  return RenderBoxes(camera, {{size, pose}}, seed);
}

}  // namespace teachsim::vision::synthetic
