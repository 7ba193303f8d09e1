// Figures for the demo report, drawn with OpenCV: line and bar charts with axes, ticks, labels and
// legends, and a flat-shaded projection of a scene (painter's algorithm) for the model view.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "teachsim/geometry/shape.h"
#include "teachsim/vision/camera.h"

namespace teachsim::app::plot {

// Colours (BGR) used across the report, so a series keeps its colour from figure to figure.
cv::Scalar Palette(int i);

struct Line {
  std::string label;  // empty: not in the legend
  std::vector<double> x, y;
  cv::Scalar color;
  bool dashed = false;
  int thickness = 2;
};

struct LineChart {
  std::string title, x_label, y_label;
  std::vector<Line> lines;
};
cv::Mat DrawLineChart(const LineChart& chart, int width_px, int height_px);

struct BarChart {
  std::string title, y_label;
  std::vector<std::string> categories;  // along x
  std::vector<std::string> series;      // legend; one bar per series in each category
  std::vector<std::vector<double>> values;  // [series][category]; NaN: no bar
  std::vector<cv::Scalar> colors;           // per series (empty: the palette)
  std::string value_format = "%.1f";        // label on top of each bar ("" : none)
};
cv::Mat DrawBarChart(const BarChart& chart, int width_px, int height_px);

// Side by side (top-aligned, white padding).
cv::Mat HConcat(const std::vector<cv::Mat>& images);
cv::Mat VConcat(const std::vector<cv::Mat>& images);

// A solid to draw in a model view: convex parts placed in the world, a colour and an opacity.
struct Solid {
  std::vector<geometry::ShapePart> parts;  // shape_T_part
  geometry::Pose3 world_T_shape;
  double scale = 1.0;  // about the shape's origin (half-size ghost blocks: 0.5)
  cv::Scalar color;
  double alpha = 1.0;  // < 1: blended over what is behind
  bool background = false;  // drawn first, whatever its depth (the table)
};
struct Polyline3 {
  std::vector<Eigen::Vector3d> points_in_world;
  cv::Scalar color;
  int thickness = 2;
  bool markers = false;
};
// Faces sorted far to near (the scenes are boxes apart from each other, so the order is right
// almost everywhere), Lambert-shaded, outlined; then the polylines on top.
cv::Mat DrawModelView(const vision::Camera& camera, const std::vector<Solid>& solids,
                      const std::vector<Polyline3>& lines, const std::string& title);

// A camera looking from `eye` at `target` (z up), distortion-free.
vision::Camera LookAtCamera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int width_px, int height_px,
                            double focal_px);

// Text helpers.
void PutText(cv::Mat& image, const std::string& text, cv::Point origin, double scale, cv::Scalar color,
             int thickness = 1);
void DrawLegend(cv::Mat& image, cv::Point top_left, const std::vector<std::pair<std::string, cv::Scalar>>& entries,
                bool dashed_last = false);

}  // namespace teachsim::app::plot
