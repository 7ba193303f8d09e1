#include "demo_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

namespace teachsim::app::plot {

namespace {

constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;
const cv::Scalar kBlack(0, 0, 0), kGrey(150, 150, 150), kLightGrey(225, 225, 225), kWhite(255, 255, 255);

// Tick positions: 1, 2 or 5 times a power of ten, about `target` of them over [lo, hi].
std::vector<double> Ticks(double lo, double hi, int target) {
  std::vector<double> ticks;
  if (!(hi > lo)) return {lo};
  const double raw = (hi - lo) / std::max(1, target);
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  double step = p;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * p >= raw) {
      step = m * p;
      break;
    }
  }
  for (double t = std::ceil(lo / step - 1e-9) * step; t <= hi + 1e-9 * step; t += step) {
    ticks.push_back(std::abs(t) < 1e-12 * step ? 0.0 : t);
  }
  return ticks;
}

std::string Format(const char* format, double v) {
  char text[64];
  std::snprintf(text, sizeof text, format, v);
  return text;
}

std::string TickLabel(double v, const std::vector<double>& ticks) {
  const double step = ticks.size() > 1 ? ticks[1] - ticks[0] : 1.0;
  const int digits = step >= 1 ? 0 : static_cast<int>(std::ceil(-std::log10(step) - 1e-9));
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", digits, v);
  return text;
}

void DashedLine(cv::Mat& image, cv::Point2d a, cv::Point2d b, cv::Scalar color, int thickness) {
  const double length = std::hypot(b.x - a.x, b.y - a.y);
  const int dashes = std::max(1, static_cast<int>(length / 8));
  for (int i = 0; i < dashes; i += 2) {
    const double t0 = static_cast<double>(i) / dashes, t1 = std::min(1.0, static_cast<double>(i + 1) / dashes);
    cv::line(image, a + (b - a) * t0, a + (b - a) * t1, color, thickness, cv::LINE_AA);
  }
}

// The plot area and its mapping, with axes, grid, tick labels and axis labels drawn.
struct Axes {
  cv::Rect area;
  double x0, x1, y0, y1;
  cv::Point2d Map(double x, double y) const {
    return {area.x + (x - x0) / (x1 - x0) * area.width, area.y + area.height - (y - y0) / (y1 - y0) * area.height};
  }
};

void VerticalText(cv::Mat& image, const std::string& text, cv::Point centre, double scale) {
  int base = 0;
  const cv::Size size = cv::getTextSize(text, kFont, scale, 1, &base);
  cv::Mat patch(size.height + base + 4, size.width + 4, image.type(), kWhite);
  cv::putText(patch, text, cv::Point(2, size.height + 1), kFont, scale, kBlack, 1, cv::LINE_AA);
  cv::Mat rotated;
  cv::rotate(patch, rotated, cv::ROTATE_90_COUNTERCLOCKWISE);
  const cv::Rect where(centre.x - rotated.cols / 2, centre.y - rotated.rows / 2, rotated.cols, rotated.rows);
  const cv::Rect clipped = where & cv::Rect(0, 0, image.cols, image.rows);
  rotated(cv::Rect(clipped.x - where.x, clipped.y - where.y, clipped.width, clipped.height)).copyTo(image(clipped));
}

Axes DrawAxes(cv::Mat& image, const std::string& title, const std::string& x_label, const std::string& y_label,
              double x0, double x1, double y0, double y1, bool x_ticks) {
  Axes axes{cv::Rect(70, 34, image.cols - 90, image.rows - 34 - (x_label.empty() && !x_ticks ? 60 : 58)), x0, x1, y0,
            y1};
  PutText(image, title, cv::Point(12, 22), 0.55, kBlack, 1);
  for (double t : Ticks(y0, y1, 5)) {
    const cv::Point2d p = axes.Map(x0, t);
    cv::line(image, p, cv::Point2d(axes.area.x + axes.area.width, p.y), kLightGrey, 1);
    const std::string label = TickLabel(t, Ticks(y0, y1, 5));
    int base = 0;
    const cv::Size s = cv::getTextSize(label, kFont, 0.4, 1, &base);
    PutText(image, label, cv::Point(static_cast<int>(p.x) - s.width - 6, static_cast<int>(p.y) + s.height / 2), 0.4,
            kBlack);
  }
  if (x_ticks) {
    const std::vector<double> ticks = Ticks(x0, x1, 8);
    for (double t : ticks) {
      const cv::Point2d p = axes.Map(t, y0);
      cv::line(image, p, cv::Point2d(p.x, axes.area.y), kLightGrey, 1);
      cv::line(image, p, p + cv::Point2d(0, 4), kBlack, 1);
      const std::string label = TickLabel(t, ticks);
      int base = 0;
      const cv::Size s = cv::getTextSize(label, kFont, 0.4, 1, &base);
      PutText(image, label, cv::Point(static_cast<int>(p.x) - s.width / 2, static_cast<int>(p.y) + 18), 0.4, kBlack);
    }
  }
  cv::rectangle(image, axes.area, kBlack, 1);
  if (!x_label.empty()) {
    int base = 0;
    const cv::Size s = cv::getTextSize(x_label, kFont, 0.45, 1, &base);
    PutText(image, x_label, cv::Point(axes.area.x + axes.area.width / 2 - s.width / 2, image.rows - 10), 0.45, kBlack);
  }
  if (!y_label.empty()) VerticalText(image, y_label, cv::Point(14, axes.area.y + axes.area.height / 2), 0.45);
  return axes;
}

}  // namespace

cv::Scalar Palette(int i) {
  static const cv::Scalar colors[] = {{180, 119, 31}, {14, 127, 255}, {44, 160, 44},   {40, 39, 214},
                                      {189, 103, 148}, {75, 86, 140}, {194, 119, 227}, {127, 127, 127}};
  return colors[static_cast<std::size_t>(i) % (sizeof colors / sizeof colors[0])];
}

void PutText(cv::Mat& image, const std::string& text, cv::Point origin, double scale, cv::Scalar color,
             int thickness) {
  cv::putText(image, text, origin, kFont, scale, color, thickness, cv::LINE_AA);
}

void DrawLegend(cv::Mat& image, cv::Point top_left, const std::vector<std::pair<std::string, cv::Scalar>>& entries,
                bool dashed_last) {
  if (entries.empty()) return;
  int width = 0;
  for (const auto& [text, color] : entries) {
    int base = 0;
    width = std::max(width, cv::getTextSize(text, kFont, 0.4, 1, &base).width);
  }
  const cv::Rect box(top_left.x, top_left.y, width + 44, static_cast<int>(entries.size()) * 17 + 8);
  cv::rectangle(image, box, kWhite, cv::FILLED);
  cv::rectangle(image, box, kGrey, 1);
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const int y = top_left.y + 13 + static_cast<int>(i) * 17;
    const cv::Point2d a(top_left.x + 6, y - 4), b(top_left.x + 32, y - 4);
    if (dashed_last && i + 1 == entries.size()) {
      DashedLine(image, a, b, entries[i].second, 2);
    } else {
      cv::line(image, a, b, entries[i].second, 2, cv::LINE_AA);
    }
    PutText(image, entries[i].first, cv::Point(top_left.x + 38, y), 0.4, kBlack);
  }
}

cv::Mat DrawLineChart(const LineChart& chart, int width_px, int height_px) {
  cv::Mat image(height_px, width_px, CV_8UC3, kWhite);
  double x0 = 1e300, x1 = -1e300, y0 = 0, y1 = -1e300;
  for (const Line& l : chart.lines) {
    for (std::size_t i = 0; i < l.x.size() && i < l.y.size(); ++i) {
      if (!std::isfinite(l.x[i]) || !std::isfinite(l.y[i])) continue;
      x0 = std::min(x0, l.x[i]), x1 = std::max(x1, l.x[i]);
      y0 = std::min(y0, l.y[i]), y1 = std::max(y1, l.y[i]);
    }
  }
  if (!(x1 > x0)) x0 = 0, x1 = 1;
  if (!(y1 > y0)) y1 = y0 + 1;
  const double pad = 0.08 * (y1 - y0);
  y1 += pad;
  if (y0 < 0) y0 -= pad;
  const Axes axes = DrawAxes(image, chart.title, chart.x_label, chart.y_label, x0, x1, y0, y1, true);
  if (y0 < 0) cv::line(image, axes.Map(x0, 0), axes.Map(x1, 0), kGrey, 1);
  std::vector<std::pair<std::string, cv::Scalar>> legend;
  for (const Line& l : chart.lines) {
    for (std::size_t i = 1; i < l.x.size() && i < l.y.size(); ++i) {
      if (!std::isfinite(l.y[i - 1]) || !std::isfinite(l.y[i])) continue;
      const cv::Point2d a = axes.Map(l.x[i - 1], l.y[i - 1]), b = axes.Map(l.x[i], l.y[i]);
      if (l.dashed) {
        DashedLine(image, a, b, l.color, l.thickness);
      } else {
        cv::line(image, a, b, l.color, l.thickness, cv::LINE_AA);
      }
    }
    if (!l.label.empty()) legend.emplace_back(l.label, l.color);
  }
  // The legend in the upper-left corner of the plot area.
  int base = 0;
  int width = 0;
  for (const auto& [text, color] : legend) width = std::max(width, cv::getTextSize(text, kFont, 0.4, 1, &base).width);
  DrawLegend(image, cv::Point(axes.area.x + 8, axes.area.y + 6), legend);
  (void)width;
  return image;
}

cv::Mat DrawBarChart(const BarChart& chart, int width_px, int height_px) {
  cv::Mat image(height_px, width_px, CV_8UC3, kWhite);
  double y1 = 0;
  for (const auto& s : chart.values) {
    for (double v : s) {
      if (std::isfinite(v)) y1 = std::max(y1, v);
    }
  }
  if (!(y1 > 0)) y1 = 1;
  y1 *= 1.18;
  const double n_categories = std::max<std::size_t>(1, chart.categories.size());
  const Axes axes = DrawAxes(image, chart.title, "", chart.y_label, 0, n_categories, 0, y1, false);
  const std::size_t n_series = std::max<std::size_t>(1, chart.series.size());
  const double slot = axes.area.width / n_categories;
  const double bar = 0.8 * slot / static_cast<double>(n_series);
  for (std::size_t c = 0; c < chart.categories.size(); ++c) {
    for (std::size_t s = 0; s < chart.values.size(); ++s) {
      if (c >= chart.values[s].size() || !std::isfinite(chart.values[s][c])) continue;
      const cv::Scalar color = s < chart.colors.size() ? chart.colors[s] : Palette(static_cast<int>(s));
      const double left = axes.area.x + c * slot + 0.1 * slot + static_cast<double>(s) * bar;
      const cv::Point2d top = axes.Map(0, chart.values[s][c]);
      const cv::Rect r(static_cast<int>(left), static_cast<int>(top.y), std::max(1, static_cast<int>(bar) - 2),
                       std::max(1, axes.area.y + axes.area.height - static_cast<int>(top.y)));
      cv::rectangle(image, r, color, cv::FILLED);
      if (!chart.value_format.empty()) {
        const std::string label = Format(chart.value_format.c_str(), chart.values[s][c]);
        int base = 0;
        const cv::Size size = cv::getTextSize(label, kFont, 0.35, 1, &base);
        PutText(image, label, cv::Point(r.x + r.width / 2 - size.width / 2, r.y - 4), 0.35, kBlack);
      }
    }
    // Category label under its slot, on two lines when long.
    std::string label = chart.categories[c];
    int base = 0;
    const double centre = axes.area.x + (c + 0.5) * slot;
    std::vector<std::string> rows = {label};
    if (cv::getTextSize(label, kFont, 0.4, 1, &base).width > slot - 4 && label.find(' ') != std::string::npos) {
      const std::size_t mid = label.size() / 2;
      std::size_t cut = label.rfind(' ', mid);
      if (cut == std::string::npos || cut == 0) cut = label.find(' ');
      rows = {label.substr(0, cut), label.substr(cut + 1)};
    }
    for (std::size_t r = 0; r < rows.size(); ++r) {
      const cv::Size size = cv::getTextSize(rows[r], kFont, 0.4, 1, &base);
      PutText(image, rows[r],
              cv::Point(static_cast<int>(centre) - size.width / 2,
                        axes.area.y + axes.area.height + 18 + static_cast<int>(r) * 16),
              0.4, kBlack);
    }
  }
  std::vector<std::pair<std::string, cv::Scalar>> legend;
  for (std::size_t s = 0; s < chart.series.size(); ++s) {
    if (chart.series.size() > 1 || !chart.series[s].empty()) {
      legend.emplace_back(chart.series[s], s < chart.colors.size() ? chart.colors[s] : Palette(static_cast<int>(s)));
    }
  }
  int base = 0, width = 0;
  for (const auto& [text, color] : legend) width = std::max(width, cv::getTextSize(text, kFont, 0.4, 1, &base).width);
  DrawLegend(image, cv::Point(axes.area.x + axes.area.width - width - 52, axes.area.y + 6), legend);
  return image;
}

namespace {

// Side by side (horizontal) or stacked, on a white background as large as the largest image.
cv::Mat Concat(const std::vector<cv::Mat>& images, bool horizontal) {
  int along = 0, across = 0;
  for (const cv::Mat& m : images) {
    along += horizontal ? m.cols : m.rows;
    across = std::max(across, horizontal ? m.rows : m.cols);
  }
  cv::Mat out = horizontal ? cv::Mat(across, along, CV_8UC3, kWhite) : cv::Mat(along, across, CV_8UC3, kWhite);
  int at = 0;
  for (const cv::Mat& m : images) {
    m.copyTo(out(horizontal ? cv::Rect(at, 0, m.cols, m.rows) : cv::Rect(0, at, m.cols, m.rows)));
    at += horizontal ? m.cols : m.rows;
  }
  return out;
}

}  // namespace

cv::Mat HConcat(const std::vector<cv::Mat>& images) { return Concat(images, true); }

cv::Mat VConcat(const std::vector<cv::Mat>& images) { return Concat(images, false); }

vision::Camera LookAtCamera(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int width_px, int height_px,
                            double focal_px) {
  // OpenCV axes: z forward, x right, y down.
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.col(0) = x, r.col(1) = y, r.col(2) = z;
  vision::Intrinsics k;
  k.fx = k.fy = focal_px;
  k.cx = (width_px - 1) / 2.0, k.cy = (height_px - 1) / 2.0;
  return vision::Camera(k, vision::Distortion{}, geometry::Pose3(Eigen::Quaterniond(r), eye), width_px, height_px);
}

cv::Mat DrawModelView(const vision::Camera& camera, const std::vector<Solid>& solids,
                      const std::vector<Polyline3>& lines, const std::string& title) {
  cv::Mat image(camera.height(), camera.width(), CV_8UC3, cv::Scalar(246, 240, 235));
  const Eigen::Vector3d light = Eigen::Vector3d(0.4, -0.3, 0.87).normalized();
  struct Polygon {
    std::vector<cv::Point> points;
    double depth;
    cv::Scalar fill;
    double alpha;
    bool background;
  };
  std::vector<Polygon> polygons;
  const geometry::Pose3& camera_T_world = camera.camera_T_world();
  for (const Solid& solid : solids) {
    for (const geometry::ShapePart& part : solid.parts) {
      const geometry::ConvexPolyhedron& convex = *part.convex;
      for (const geometry::Face& face : convex.faces()) {
        std::vector<cv::Point> points;
        double depth = 0;
        bool visible = true;
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();
        for (int v : face.vertices) {
          const Eigen::Vector3d p_in_shape = part.shape_T_part * convex.vertices()[static_cast<std::size_t>(v)];
          const Eigen::Vector3d p_in_world = solid.world_T_shape * (solid.scale * p_in_shape);
          const Eigen::Vector3d p_in_camera = camera_T_world * p_in_world;
          centre += p_in_camera;
          const auto pixel = camera.ProjectFromCamera(p_in_camera, 1e-3);
          if (!pixel) {
            visible = false;
            break;
          }
          points.emplace_back(static_cast<int>(std::lround(pixel->x() * 16)), static_cast<int>(std::lround(pixel->y() * 16)));
          depth += p_in_camera.z();
        }
        if (!visible || points.size() < 3) continue;
        centre /= static_cast<double>(face.vertices.size());
        const Eigen::Vector3d n_in_world = solid.world_T_shape.Rotate(part.shape_T_part.Rotate(face.normal));
        if ((camera_T_world.Rotate(n_in_world)).dot(centre) >= 0) continue;  // back face
        const double shade = 0.55 + 0.45 * std::max(0.0, n_in_world.dot(light));
        polygons.push_back({points, depth / static_cast<double>(points.size()), solid.color * shade, solid.alpha,
                            solid.background});
      }
    }
  }
  std::stable_sort(polygons.begin(), polygons.end(), [](const Polygon& a, const Polygon& b) {
    if (a.background != b.background) return a.background;
    return a.depth > b.depth;
  });
  for (const Polygon& p : polygons) {
    if (p.alpha >= 1.0) {
      cv::fillConvexPoly(image, p.points, p.fill, cv::LINE_AA, 4);
    } else {
      cv::Mat overlay = image.clone();
      cv::fillConvexPoly(overlay, p.points, p.fill, cv::LINE_AA, 4);
      cv::addWeighted(overlay, p.alpha, image, 1.0 - p.alpha, 0, image);
    }
    std::vector<std::vector<cv::Point>> outline = {p.points};
    cv::polylines(image, outline, true, p.fill * 0.45, 1, cv::LINE_AA, 4);
  }
  for (const Polyline3& l : lines) {
    std::vector<cv::Point> points;
    for (const Eigen::Vector3d& p : l.points_in_world) {
      if (const auto pixel = camera.Project(p, 1e-3)) {
        points.emplace_back(static_cast<int>(std::lround(pixel->x() * 16)), static_cast<int>(std::lround(pixel->y() * 16)));
      }
    }
    if (points.size() >= 2) {
      std::vector<std::vector<cv::Point>> poly = {points};
      cv::polylines(image, poly, false, l.color, l.thickness, cv::LINE_AA, 4);
    }
    if (l.markers) {
      for (const cv::Point& p : points) cv::circle(image, p, 4 * 16, l.color, cv::FILLED, cv::LINE_AA, 4);
    }
  }
  PutText(image, title, cv::Point(10, 22), 0.55, kBlack, 1);
  return image;
}

}  // namespace teachsim::app::plot
