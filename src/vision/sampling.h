#pragma once
// Private to the vision module: sub-pixel image sampling shared by the line detector, the
// recognizer's evidence and the calibration's corner snapping.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>

namespace teachsim::vision::internal {

// Bilinear sample at (x, y) in pixels, clamped to a cols x rows image, of the values at(x, y)
// returns at its pixels.
template <typename At>
inline float SampleBilinearAt(At at, int cols, int rows, double x, double y) {
  x = std::clamp(x, 0.0, cols - 1.001);
  y = std::clamp(y, 0.0, rows - 1.001);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const double fx = x - x0, fy = y - y0;
  return static_cast<float>((1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) +
                            fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1)));
}

// Bilinear sample of a one-channel image of T (CV_32F: float; CV_8U: uint8_t) at (x, y) in pixels,
// clamped to the image.
template <typename T = float>
inline float SampleBilinear(const cv::Mat& m, double x, double y) {
  return SampleBilinearAt([&m](int px, int py) { return m.ptr<T>(py)[px]; }, m.cols, m.rows, x, y);
}

// Bilinear sample of an 8-bit grey image at a pixel.
inline float SampleGrey(const cv::Mat& grey8, const Eigen::Vector2d& p) {
  return SampleBilinear<uint8_t>(grey8, p.x(), p.y());
}

// 8-bit grey levels as CV_32F; for a camera with a gamma (Camera::gamma) brought back to linear
// light, 255 (g / 255)^gamma, where a blurred step is symmetric: on the encoded levels its middle
// sits towards the darker side.
inline cv::Mat LinearLight(const cv::Mat& gray8, double gamma) {
  cv::Mat values;
  if (gamma == 1.0) {
    gray8.convertTo(values, CV_32F);
    return values;
  }
  cv::Mat to_linear(1, 256, CV_32F);
  for (int g = 0; g < 256; ++g)
    to_linear.at<float>(g) = static_cast<float>(255.0 * std::pow(g / 255.0, gamma));
  cv::LUT(gray8, to_linear, values);
  return values;
}

// The sub-pixel offset of an edge pixel along its unit gradient (gx, gy): the peak of a parabola
// through the gradient magnitude (at(x, y) at a pixel of a cols x rows image) at -1, 0, +1 along it,
// within half a pixel (0 when not a peak).
template <typename At>
inline double SubPixelEdgeOffsetAt(At at, int cols, int rows, int x, int y, double gx, double gy) {
  const double m0 = at(x, y);
  const double mm = SampleBilinearAt(at, cols, rows, x - gx, y - gy);
  const double mp = SampleBilinearAt(at, cols, rows, x + gx, y + gy);
  const double denom = mm - 2.0 * m0 + mp;
  return denom < 0 ? std::clamp(0.5 * (mm - mp) / denom, -0.5, 0.5) : 0.0;
}

}  // namespace teachsim::vision::internal
