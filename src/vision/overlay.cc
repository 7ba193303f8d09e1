// Recognitions drawn over the camera image (overlay.h).
#include "teachsim/vision/overlay.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <string>

#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

constexpr double kMaxStepPx = 8;  // between two points of an edge's polyline
constexpr int kMaxPoints = 400;   // per edge (an edge across the whole picture needs ~100)

// Colours that stand out on a grey image and from each other (BGR).
const std::array<cv::Scalar, 6> kPalette = {cv::Scalar(0, 165, 255), cv::Scalar(255, 160, 0),
                                            cv::Scalar(60, 220, 60), cv::Scalar(230, 60, 230),
                                            cv::Scalar(40, 40, 235), cv::Scalar(0, 230, 230)};

cv::Point2d At(const Eigen::Vector2d& p) { return {p.x(), p.y()}; }

}  // namespace

std::vector<std::vector<Eigen::Vector2d>> BoxOutlineInImage(const Eigen::Vector3d& size_m,
                                                            const Camera& camera,
                                                            const geometry::Pose3& camera_T_object) {
  std::vector<std::vector<Eigen::Vector2d>> polylines;
  const uint16_t visible = VisibleBoxEdges(size_m, camera_T_object.Inverse().translation);
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector3d a = camera_T_object * BoxVertex(size_m, kBoxEdges[static_cast<size_t>(e)][0]);
    const Eigen::Vector3d b = camera_T_object * BoxVertex(size_m, kBoxEdges[static_cast<size_t>(e)][1]);
    const auto in_view = camera.SegmentInView(a, b);
    if (!in_view) continue;
    const auto [t0, t1] = *in_view;
    const auto p0 = camera.ProjectFromCamera(a + t0 * (b - a));
    const auto p1 = camera.ProjectFromCamera(a + t1 * (b - a));
    if (!p0 || !p1) continue;
    // The lens bends an edge by little between its ends: the chord's length sets the spacing.
    const int n = std::clamp(static_cast<int>(std::ceil((*p1 - *p0).norm() / kMaxStepPx)), 1, kMaxPoints);
    std::vector<Eigen::Vector2d> line;
    for (int i = 0; i <= n; ++i) {
      const double t = t0 + (t1 - t0) * i / n;
      if (const auto p = camera.ProjectFromCamera(a + t * (b - a))) line.push_back(*p);
    }
    if (line.size() >= 2) polylines.push_back(std::move(line));
  }
  return polylines;
}

Result<cv::Mat> DrawRecognitions(const cv::Mat& image, const Camera& camera, const ModelLibrary& models,
                                 const std::vector<Recognition>& objects) {
  if (image.empty() || image.type() != CV_8UC1 || image.cols != camera.width() ||
      image.rows != camera.height()) {
    return Status::InvalidInput("the overlay needs the camera's grey image (" +
                                std::to_string(camera.width()) + "x" + std::to_string(camera.height()) +
                                ", 8 bit)");
  }
  cv::Mat out;
  cv::cvtColor(image, out, cv::COLOR_GRAY2BGR);
  struct Label {
    std::string text;
    cv::Point at;
    cv::Scalar colour;
  };
  std::vector<Label> labels;
  for (size_t i = 0; i < objects.size(); ++i) {
    const Recognition& r = objects[i];
    const cv::Scalar colour = kPalette[i % kPalette.size()];
    const geometry::Pose3 camera_T_object = camera.camera_T_world() * r.world_T_object;
    const auto model = std::find_if(models.models.begin(), models.models.end(),
                                    [&](const Model& m) { return m.name == r.model; });
    if (model != models.models.end()) {
      for (const std::vector<Eigen::Vector2d>& line :
           BoxOutlineInImage(model->box_size_m, camera, camera_T_object)) {
        for (size_t k = 1; k < line.size(); ++k)
          cv::line(out, At(line[k - 1]), At(line[k]), colour, 2, cv::LINE_AA);
      }
    }
    const auto centre = camera.ProjectFromCamera(camera_T_object.translation);
    if (!centre || !camera.InImage(*centre)) continue;
    char text[96];
    std::snprintf(text, sizeof(text), "#%zu %s %.2f", i, r.model.c_str(), r.score);
    labels.push_back(
        {text,
         cv::Point(static_cast<int>(std::lround(centre->x())), static_cast<int>(std::lround(centre->y()))),
         colour});
  }
  // Labels over all outlines, dark-edged to read on any grey, kept inside the picture.
  for (const Label& l : labels) {
    int baseline = 0;
    const cv::Size size = cv::getTextSize(l.text, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, &baseline);
    const cv::Point at(std::clamp(l.at.x - size.width / 2, 1, std::max(1, out.cols - size.width - 1)),
                       std::clamp(l.at.y + size.height / 2, size.height + 1,
                                  std::max(size.height + 1, out.rows - baseline - 1)));
    cv::putText(out, l.text, at, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
    cv::putText(out, l.text, at, cv::FONT_HERSHEY_SIMPLEX, 0.45, l.colour, 1, cv::LINE_AA);
  }
  return out;
}

}  // namespace teachsim::vision
