// Recognitions drawn over the camera image, for checking them by eye (teachsim recognize --overlay;
// the recognition benchmark's close-ups of missed blocks): each box's visible edges projected through
// the lens.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/vision/camera.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::vision {

// The edges of a box (side lengths size_m, centred on its frame) that face the camera, as polylines
// in image pixels through the lens: of each edge, the part in the camera's view
// (Camera::SegmentInView), with a point at least every 8 px so the lens' curvature shows. Edges
// that other objects hide are not left out. A box wholly behind the camera gives none.
std::vector<std::vector<Eigen::Vector2d>> BoxOutlineInImage(const Eigen::Vector3d& size_m,
                                                            const Camera& camera,
                                                            const geometry::Pose3& camera_T_object);

// The grey camera image (CV_8UC1, the camera's size) in colour with each recognition's outline at
// its pose after the model editor (a colour per object, 2 px wide) and a label "#i model score" at
// its centre (none when the centre is outside the picture), i being its index in `objects` (as in
// RESULT.json). Recognitions of a model not in `models` are labelled only. Fails on an empty image or
// one of another size or type.
[[nodiscard]] Result<cv::Mat> DrawRecognitions(const cv::Mat& image, const Camera& camera,
                                               const ModelLibrary& models,
                                               const std::vector<Recognition>& objects);

}  // namespace teachsim::vision
