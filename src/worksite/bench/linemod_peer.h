// The recognition benchmark's peer: OpenCV's LINE-MOD (Hinterstoisser et al., PAMI 2012;
// cv::linemod in opencv_contrib's rgbd module), color-gradient modality on the monochrome image.
//
// Templates come from our own renders (worksite::Renderer) of each box model alone, centred on the
// optical axis of a template camera, over the view sphere (a quarter of it: every box is equal to
// itself under half turns about its axes), at several distances; rotations about the optical axis
// are exact image rotations of those renders. A match's pose is its template's pose moved onto the
// ray through the match's object centre, at the template's distance scaled by the focal lengths'
// ratio. The test image is undistorted first (templates come from an ideal camera).
#pragma once

#include <Eigen/Core>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/rgbd/linemod.hpp>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/vision/camera.h"
#include "teachsim/vision/evaluate.h"

namespace teachsim::worksite {

struct LinemodOptions {
  double template_focal_px = 760;  // the template camera's focal length, px
  // Template distances, m (at template_focal_px): scale steps of ~15 % over the work area's range.
  std::vector<double> distances_m = {0.40, 0.47, 0.55, 0.65, 0.77, 0.91};
  double view_step_deg = 18;      // spacing of viewing directions on the view sphere
  double in_plane_step_deg = 18;  // steps of rotation about the optical axis
  // ColorGradient: weak / strong gradient magnitude thresholds and features per template.
  float weak_threshold = 10, strong_threshold = 55;
  int num_features = 63;
  std::vector<int> pyramid_t = {5, 8};  // LINE-MOD's T per pyramid level (OpenCV's defaults)
  float match_threshold = 90;           // similarity, percent
  int max_detections = 10;              // per image, after non-maximum suppression
  double suppression_radius = 0.75;     // of the smaller template's smaller side: one object per place
  [[nodiscard]] Status Validate() const;
  // A key of everything that shapes the templates (the cache file name).
  std::string TemplateKey() const;
};

struct LinemodDetection {
  vision::Detection detection;  // world pose, score = similarity / 100
  geometry::Pose3 camera_T_object;
  int template_id = -1;
};

class LinemodPeer {
 public:
  // Renders and extracts the templates, or reads them from cache_dir (empty: no cache) when a file
  // for these models and options is there.
  [[nodiscard]] static Result<LinemodPeer> Create(const std::map<std::string, Eigen::Vector3d>& model_sizes_m,
                                                  const LinemodOptions& options, const std::string& cache_dir);

  // image: 8-bit monochrome as the camera saw it (distorted).
  std::vector<LinemodDetection> Detect(const cv::Mat& image_gray8, const vision::Camera& camera) const;

  int num_templates() const;
  bool loaded_from_cache() const { return loaded_from_cache_; }
  double build_s() const { return build_s_; }

 private:
  struct TemplateInfo {
    geometry::Pose3 camera_T_object;  // in the template camera: centre on the optical axis
    Eigen::Vector2d centre_offset_px = Eigen::Vector2d::Zero();  // object centre minus bounding-box corner
    double size_px = 0;                                          // smaller side of the bounding box
  };
  LinemodOptions options_;
  cv::Ptr<cv::linemod::Detector> detector_;
  std::map<std::string, std::vector<TemplateInfo>> info_;  // per class (model), per template id
  bool loaded_from_cache_ = false;
  double build_s_ = 0;
};

// The image an ideal camera with the same intrinsics would see (bilinear remap).
cv::Mat UndistortImage(const cv::Mat& image, const vision::Camera& camera);

}  // namespace teachsim::worksite
