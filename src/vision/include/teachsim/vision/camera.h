// The camera model: a pin-hole camera with OpenCV's distortion model and axes (paper §4.2;
// DESIGN.md "Conventions"): x right, y down, z forward, pixel centres at integer coordinates,
// distortion k1 k2 p1 p2 k3, pose world_T_camera.
//
// Coordinates used below:
//   pixel       (u, v) in the image as the camera sees it (distorted), px
//   normalized  (x, y) = (X/Z, Y/Z) of a point in the camera frame: the ideal, undistorted image
//               plane at unit depth (what line geometry and pose fitting work in)
//   distorted   normalized coordinates after the lens model, before the intrinsics
// A Camera is built once from a scene::CameraSpec and is then read-only (model apart from state).
#pragma once

#include <Eigen/Core>
#include <optional>
#include <utility>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/scene/scene.h"

namespace teachsim::vision {

struct Intrinsics {
  double fx = 600, fy = 600, cx = 319.5, cy = 239.5;  // px
};

// OpenCV's order and meaning: radial k1 k2 k3, tangential p1 p2.
struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  bool IsZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
  // No tangential terms: each point moves along its own radius (Camera::Undistort's 1-D path).
  bool IsRadial() const { return p1 == 0 && p2 == 0; }
};

// A ray in the world: origin at the camera centre, unit direction.
struct Ray {
  Eigen::Vector3d origin_in_world;
  Eigen::Vector3d direction_in_world;  // unit
};

// An image segment (say, a fitted edge) between two pixel positions.
struct Segment2 {
  Eigen::Vector2d a, b;
};

class Camera {
 public:
  // Fails when the spec's numbers are not finite, focal lengths not > 0, sizes not > 0, or the pose
  // is not a unit quaternion.
  [[nodiscard]] static Result<Camera> FromSpec(const scene::CameraSpec& spec);
  Camera(const Intrinsics& intrinsics, const Distortion& distortion, const geometry::Pose3& world_T_camera,
         int width, int height);

  scene::CameraSpec ToSpec(const std::string& name) const;
  // The same camera (lens, size, gamma) at another pose.
  Camera WithPose(const geometry::Pose3& world_T_camera) const;

  const Intrinsics& intrinsics() const { return intrinsics_; }
  const Distortion& distortion() const { return distortion_; }
  const geometry::Pose3& world_T_camera() const { return world_T_camera_; }
  const geometry::Pose3& camera_T_world() const { return camera_T_world_; }
  int width() const { return width_; }
  int height() const { return height_; }
  Eigen::Matrix3d K() const;
  // The response (scene::CameraSpec::gamma): grey level 255 E^(1 / gamma) for the light E in [0, 1].
  double gamma() const { return gamma_; }
  void set_gamma(double gamma);  // in [kMinGamma, kMaxGamma]
  static constexpr double kMinGamma = 0.5, kMaxGamma = 4.0;

  // True when (u, v) lies on the image: [-0.5, width - 0.5) x [-0.5, height - 0.5).
  bool InImage(const Eigen::Vector2d& pixel) const {  // inline: the recognizer asks it per outline sample
    return pixel.x() >= -0.5 && pixel.y() >= -0.5 && pixel.x() < width_ - 0.5 && pixel.y() < height_ - 0.5;
  }

  // Lens model, normalized -> distorted (OpenCV's equations), and its 2x2 Jacobian.
  Eigen::Vector2d Distort(const Eigen::Vector2d& normalized) const;
  Eigen::Matrix2d DistortJacobian(const Eigen::Vector2d& normalized) const;
  // The inverse: Gauss-Newton on Distort(), seeded with OpenCV's fixed-point step; agrees with
  // cv::undistortPoints run to convergence. Without tangential terms (p1 = p2 = 0) the same root is
  // found along the point's radius, a 1-D Newton. nullopt when it does not converge (a point far
  // outside the field of view, where the polynomial model folds over).
  std::optional<Eigen::Vector2d> Undistort(const Eigen::Vector2d& distorted) const;
  // The same, with Newton started at `start` (the answer for a nearby point: scanning an image).
  std::optional<Eigen::Vector2d> Undistort(const Eigen::Vector2d& distorted,
                                           const Eigen::Vector2d& start) const;

  // Pixels <-> normalized coordinates through the lens model.
  Eigen::Vector2d NormalizedToPixel(const Eigen::Vector2d& normalized) const;
  std::optional<Eigen::Vector2d> PixelToNormalized(const Eigen::Vector2d& pixel) const;
  // The pixel an ideal (distortion-free) camera with the same intrinsics would see: straight world
  // lines stay straight here, so line fits on undistorted points are valid.
  std::optional<Eigen::Vector2d> UndistortPixel(const Eigen::Vector2d& pixel) const;
  // The inverse: where the lens puts the ideal camera's pixel in the image.
  Eigen::Vector2d DistortPixel(const Eigen::Vector2d& undistorted) const;

  // Projection of a point. nullopt when it is not in front of the camera (z <= min_depth_m).
  std::optional<Eigen::Vector2d> ProjectFromCamera(const Eigen::Vector3d& p_in_camera,
                                                   double min_depth_m = 1e-6) const;
  std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& p_in_world, double min_depth_m = 1e-6) const;

  // The view: the normalized coordinates where the lens model is trusted to image a point on or
  // near the picture. It is the picture's extent before the lens, grown by half the picture on every
  // side, and within 0.98 of the radius at which the radial polynomial stops growing: beyond that
  // radius the model folds points far outside the field of view back into the picture. Fixed at
  // construction.
  // The part of the segment p -> q (camera frame) in front of the camera (z > min_depth_m) and in
  // the view: [t0, t1] along p + t (q - p), exactly [0, 1] when all of it is, nullopt when none is.
  // For samplers along projected edges: a box corner next to the camera plane projects millions of
  // pixels away, and an edge sampled every few pixels from there would take seconds.
  std::optional<std::pair<double, double>> SegmentInView(const Eigen::Vector3d& p_in_camera,
                                                         const Eigen::Vector3d& q_in_camera,
                                                         double min_depth_m = 1e-6) const;

  // The ray through a pixel (unprojection); nullopt where undistortion fails.
  std::optional<Ray> Unproject(const Eigen::Vector2d& pixel) const;
  // The same as a direction in the camera frame with z = 1: (x, y, 1).
  std::optional<Eigen::Vector3d> UnprojectToCamera(const Eigen::Vector2d& pixel) const;

  // Undistorted line geometry for the recognizer. An image segment maps to the segment between
  // its undistorted endpoints in normalized coordinates (a straight world edge images to a curve
  // in the pixel image but to a straight segment in normalized coordinates).
  std::optional<Segment2> SegmentToNormalized(const Segment2& pixel_segment) const;
  // The plane through the camera centre that holds every world point imaging onto the segment's
  // line: its unit normal, in the camera frame (n . p_in_camera = 0).
  std::optional<Eigen::Vector3d> InterpretationPlaneNormal(const Segment2& pixel_segment) const;

 private:
  Intrinsics intrinsics_;
  Distortion distortion_;
  geometry::Pose3 world_T_camera_, camera_T_world_;
  int width_ = 0, height_ = 0;
  double gamma_ = 1.0;
  Eigen::Vector2d view_lo_, view_hi_;  // SegmentInView's box, normalized coordinates
  double view_radius_ = 0;             // ... and its radius (infinite without a fold)
};

// The undistorted line through two normalized points as (a, b, c) with a x + b y + c = 0 and
// a^2 + b^2 = 1.
Eigen::Vector3d LineThrough(const Eigen::Vector2d& p, const Eigen::Vector2d& q);

}  // namespace teachsim::vision
