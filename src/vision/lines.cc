// Item 1 of issue 7 (paper §4.2: "image lines are determined through a least-squares fit to each
// pixel along an edge"): Canny edges, located to sub-pixel precision along the gradient, linked into
// chains, undistorted, split Ramer-style and fitted by least squares.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <utility>

#include "sampling.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

// 8-connected chains of edge pixels; each pixel belongs to one chain. The chains kept (at least 5
// pixels) are marked kEdgeOnChain in `edges`, the pixels of shorter ones kEdgeOffChain (no image of
// its own for the pixels visited: one less fresh image for every recognition to fault in).
std::vector<std::vector<cv::Point>> TraceChains(cv::Mat* edges_io) {
  static constexpr int kDx[8] = {1, 0, -1, 0, 1, -1, -1, 1};
  static constexpr int kDy[8] = {0, 1, 0, -1, 1, 1, -1, -1};
  // Canny's 255 until visited; kVisited on a chain being traced or kept.
  constexpr uint8_t kUnvisited = 255, kVisited = 2;
  static_assert(kEdgeOnChain == kUnvisited && kVisited != kEdgeOffChain && kVisited != 0);
  cv::Mat& edges = *edges_io;
  const int w = edges.cols, h = edges.rows;
  auto is_edge = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < w && y < h && edges.at<uint8_t>(y, x) == kUnvisited;
  };
  auto neighbours = [&](int x, int y) {
    int n = 0;
    for (int k = 0; k < 8; ++k) n += is_edge(x + kDx[k], y + kDy[k]) ? 1 : 0;
    return n;
  };
  std::vector<std::vector<cv::Point>> chains;
  auto walk = [&](int x, int y) {
    std::vector<cv::Point> chain;
    edges.at<uint8_t>(y, x) = kVisited;
    chain.push_back({x, y});
    // Extend in both directions from the seed.
    for (int pass = 0; pass < 2; ++pass) {
      int cx = x, cy = y;
      for (;;) {
        int next = -1;
        for (int k = 0; k < 8; ++k) {  // 4-neighbours first (k < 4)
          if (is_edge(cx + kDx[k], cy + kDy[k])) {
            next = k;
            break;
          }
        }
        if (next < 0) break;
        cx += kDx[next];
        cy += kDy[next];
        edges.at<uint8_t>(cy, cx) = kVisited;
        chain.push_back({cx, cy});
      }
      if (pass == 0) std::reverse(chain.begin(), chain.end());
    }
    if (chain.size() >= 5) {
      chains.push_back(std::move(chain));
    } else {
      for (const cv::Point& p : chain) edges.at<uint8_t>(p) = kEdgeOffChain;
    }
  };
  // Chain ends first, so open chains are traced from one end; then what is left (closed loops).
  for (int y = 0; y < h; ++y) {
    const uint8_t* row = edges.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      if (row[x] == kUnvisited && neighbours(x, y) <= 1) walk(x, y);
    }
  }
  for (int y = 0; y < h; ++y) {
    const uint8_t* row = edges.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      if (row[x] == kUnvisited) walk(x, y);
    }
  }
  for (int y = 0; y < h; ++y) {
    uint8_t* row = edges.ptr<uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      if (row[x] == kVisited) row[x] = kEdgeOnChain;
    }
  }
  return chains;
}

// Least-squares line through points[i..j] (inclusive); endpoints are the projections of the first
// and last points. Returns the RMS distance.
double FitLine(const std::vector<Eigen::Vector2d>& points, int i, int j, ImageLine* line) {
  const int n = j - i + 1;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (int k = i; k <= j; ++k) mean += points[k];
  mean /= n;
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (int k = i; k <= j; ++k) {
    const Eigen::Vector2d d = points[k] - mean;
    cov += d * d.transpose();
  }
  // Direction: the principal eigenvector of the 2x2 scatter (closed form).
  const double a = cov(0, 0), b = cov(0, 1), c = cov(1, 1);
  const double angle = 0.5 * std::atan2(2 * b, a - c);
  const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
  const Eigen::Vector2d normal(-dir.y(), dir.x());
  double ss = 0;
  for (int k = i; k <= j; ++k) ss += std::pow(normal.dot(points[k] - mean), 2);
  line->a = mean + dir * dir.dot(points[i] - mean);
  line->b = mean + dir * dir.dot(points[j] - mean);
  return std::sqrt(ss / n);
}

void SplitAndFit(const std::vector<Eigen::Vector2d>& points, int i, int j, const RecognizerOptions& options,
                 std::vector<ImageLine>* out, int depth = 0) {
  if (j - i + 1 < 4) return;
  const Eigen::Vector2d p = points[i], q = points[j];
  const double len = (q - p).norm();
  if (len < options.min_segment_length_px && depth > 0) return;
  int worst = -1;
  double worst_d = 0;
  if (len > 1e-9) {
    const Eigen::Vector2d n = Eigen::Vector2d(-(q - p).y(), (q - p).x()) / len;
    for (int k = i + 1; k < j; ++k) {
      const double d = std::abs(n.dot(points[k] - p));
      if (d > worst_d) worst_d = d, worst = k;
    }
  } else {
    worst = (i + j) / 2;
    worst_d = 1e9;
  }
  if (worst_d > options.split_tolerance_px && worst > i && worst < j && depth < 64) {
    SplitAndFit(points, i, worst, options, out, depth + 1);
    SplitAndFit(points, worst, j, options, out, depth + 1);
    return;
  }
  ImageLine line;
  FitLine(points, i, j, &line);
  if (line.Length() >= options.min_segment_length_px) out->push_back(line);
}

// Joins nearly collinear pieces of one edge broken by texture or noise (small gaps).
std::vector<ImageLine> MergeCollinear(std::vector<ImageLine> lines) {
  constexpr double kMaxAngle = 2.0 * M_PI / 180, kMaxOffsetPx = 1.2, kMaxGapPx = 6.0;
  std::sort(lines.begin(), lines.end(), [](const ImageLine& x, const ImageLine& y) { return x.Length() > y.Length(); });
  std::vector<bool> gone(lines.size(), false);
  for (size_t i = 0; i < lines.size(); ++i) {
    if (gone[i]) continue;
    bool merged = true;
    while (merged) {
      merged = false;
      ImageLine& l = lines[i];
      const Eigen::Vector2d dir = (l.b - l.a).normalized();
      const Eigen::Vector2d n(-dir.y(), dir.x());
      for (size_t j = i + 1; j < lines.size(); ++j) {
        if (gone[j]) continue;
        const ImageLine& m = lines[j];
        const Eigen::Vector2d mdir = (m.b - m.a).normalized();
        if (std::abs(dir.x() * mdir.y() - dir.y() * mdir.x()) > std::sin(kMaxAngle)) continue;
        if (std::abs(n.dot(m.a - l.a)) > kMaxOffsetPx || std::abs(n.dot(m.b - l.a)) > kMaxOffsetPx) continue;
        const double ta = dir.dot(m.a - l.a), tb = dir.dot(m.b - l.a), len = l.Length();
        const double lo = std::min(ta, tb), hi = std::max(ta, tb);
        if (lo > len + kMaxGapPx || hi < -kMaxGapPx) continue;  // too far apart along the line
        // The longer piece carries the line; extend it to cover both.
        const double new_lo = std::min(0.0, lo), new_hi = std::max(len, hi);
        const Eigen::Vector2d a = l.a;
        l.a = a + dir * new_lo;
        l.b = a + dir * new_hi;
        gone[j] = true;
        merged = true;
      }
    }
  }
  std::vector<ImageLine> out;
  for (size_t i = 0; i < lines.size(); ++i) {
    if (!gone[i]) out.push_back(lines[i]);
  }
  return out;
}

// The gradient magnitude of the image in linear light (internal::LinearLight), through the same
// Gaussian and Sobel as the lines'.
cv::Mat LinearMagnitudeImage(const cv::Mat& image_gray8, double gamma) {
  // Three float images, not five: the x derivative goes where the linear light was (no longer
  // needed after the blur), and the magnitude where the blur was (no longer needed after the two
  // derivatives). The same calls on the same values, none in place (cv::magnitude in place takes
  // another path for the row's last pixels); 2.5 MB fewer fresh pages at 640 x 480.
  cv::Mat values = internal::LinearLight(image_gray8, gamma);
  cv::Mat blurred, dy;
  cv::GaussianBlur(values, blurred, cv::Size(5, 5), 1.0);
  cv::Sobel(blurred, values, CV_32F, 1, 0, 3);
  cv::Sobel(blurred, dy, CV_32F, 0, 1, 3);
  cv::magnitude(values, dy, blurred);
  return blurred;
}

}  // namespace

cv::Mat NearEdgeBits(const cv::Mat& edges) {
  TEACHSIM_CHECK(edges.type() == CV_8UC1);
  static_assert(kEdgeNearPx == 2, "the shifts below dilate by 2 px");
  const int cols = edges.cols, rows = edges.rows, bytes = (cols + 7) / 8, words = (cols + 63) / 64;
  // Each row's pixels as bits in 64-bit words (bit j of word i is pixel 64 i + j), dilated along the
  // row by shifts that carry across words; then each output row is the OR of the five rows around
  // it. No dilated byte image (300 KB fresh per recognition at 640 x 480) in between.
  std::vector<uint64_t> wide(static_cast<size_t>(rows) * words);
  std::vector<uint64_t> packed(static_cast<size_t>(words));
  const uint64_t last_mask = cols % 64 == 0 ? ~0ull : (1ull << (cols % 64)) - 1;
  for (int y = 0; y < rows; ++y) {
    const uint8_t* in = edges.ptr<uint8_t>(y);
    std::fill(packed.begin(), packed.end(), 0);
    int x = 0;
    for (; x + 8 <= cols; x += 8) {
      uint64_t eight;
      std::memcpy(&eight, in + x, 8);
      if (eight == 0) continue;
      // Each byte's bits ORed into its lowest (masks keep the bytes apart), then the eight low bits
      // gathered by one multiplication into the top byte: the byte at address x + i to bit i.
      eight |= eight >> 4 & 0x0f0f0f0f0f0f0f0full;
      eight |= eight >> 2 & 0x3333333333333333ull;
      eight |= eight >> 1 & 0x5555555555555555ull;
      uint64_t byte_bits = 0;
      if constexpr (std::endian::native == std::endian::little) {
        byte_bits = (eight & 0x0101010101010101ull) * 0x0102040810204080ull >> 56;
      } else {
        for (int i = 0; i < 8; ++i) byte_bits |= static_cast<uint64_t>(in[x + i] != 0) << i;
      }
      packed[static_cast<size_t>(x >> 6)] |= byte_bits << (x & 63);
    }
    for (; x < cols; ++x) {
      if (in[x]) packed[static_cast<size_t>(x >> 6)] |= 1ull << (x & 63);
    }
    uint64_t* out = &wide[static_cast<size_t>(y) * words];
    for (int i = 0; i < words; ++i) {
      const uint64_t w = packed[static_cast<size_t>(i)];
      const uint64_t before = i > 0 ? packed[static_cast<size_t>(i - 1)] : 0;
      const uint64_t after = i + 1 < words ? packed[static_cast<size_t>(i + 1)] : 0;
      // Pixel x is set where x - 2 .. x + 2 has an edge: shifted up (from lower x) and down.
      uint64_t d = w | w << 1 | w << 2 | before >> 63 | before >> 62;
      d |= w >> 1 | w >> 2 | after << 63 | after << 62;
      out[i] = i + 1 == words ? d & last_mask : d;
    }
  }
  cv::Mat near(rows, bytes, CV_8U);
  std::vector<uint64_t> row(static_cast<size_t>(words));
  for (int y = 0; y < rows; ++y) {
    std::fill(row.begin(), row.end(), 0);
    for (int v = std::max(0, y - kEdgeNearPx); v <= std::min(rows - 1, y + kEdgeNearPx); ++v) {
      const uint64_t* src = &wide[static_cast<size_t>(v) * words];
      for (int i = 0; i < words; ++i) row[static_cast<size_t>(i)] |= src[i];
    }
    uint8_t* bits = near.ptr<uint8_t>(y);
    for (int b = 0; b < bytes; ++b)
      bits[b] = static_cast<uint8_t>(row[static_cast<size_t>(b >> 3)] >> (8 * (b & 7)));
  }
  return near;
}

LineDetection DetectLinesAndEdges(const cv::Mat& image_gray8, const Camera& camera,
                                  const RecognizerOptions& options) {
  TEACHSIM_CHECK(image_gray8.type() == CV_8UC1);
  LineDetection out;
  cv::Mat blurred, dx, dy;
  cv::GaussianBlur(image_gray8, blurred, cv::Size(5, 5), 1.0);
  cv::Sobel(blurred, dx, CV_16S, 1, 0, 3);
  cv::Sobel(blurred, dy, CV_16S, 0, 1, 3);
  cv::Canny(dx, dy, out.edge_map.edges, options.canny_low, options.canny_high, true);
  out.edge_map.smoothed = blurred;
  out.edge_map.near = NearEdgeBits(out.edge_map.edges);

  // No float images of the gradient (EdgeMap::dx): where the magnitude is asked for, it is computed.
  out.edge_map.dx = dx;
  out.edge_map.dy = dy;
  if (camera.gamma() != 1.0)
    out.edge_map.linear_magnitude = LinearMagnitudeImage(image_gray8, camera.gamma());
  const EdgeMap& edge_map = out.edge_map;
  auto magnitude_at = [&edge_map](int x, int y) { return GradientMagnitude(edge_map, x, y); };

  const Intrinsics& k = camera.intrinsics();
  const std::vector<std::vector<cv::Point>> chains = TraceChains(&out.edge_map.edges);
  std::vector<Eigen::Vector2d> points;
  for (const std::vector<cv::Point>& chain : chains) {
    points.clear();
    std::optional<Eigen::Vector2d> last;
    for (const cv::Point& p : chain) {
      // Sub-pixel: the peak of a parabola through the gradient magnitude across the edge.
      Eigen::Vector2d pixel(p.x, p.y);
      if (const auto unit = UnitGradient(edge_map, p.x, p.y)) {
        const Eigen::Vector2d g((*unit)[0], (*unit)[1]);
        pixel += g * internal::SubPixelEdgeOffsetAt(magnitude_at, dx.cols, dx.rows, p.x, p.y, g.x(), g.y());
      }
      ++out.edge_points;
      // Undistort (Newton, warm-started from the previous point of the chain).
      const Eigen::Vector2d distorted((pixel.x() - k.cx) / k.fx, (pixel.y() - k.cy) / k.fy);
      std::optional<Eigen::Vector2d> normalized =
          last ? camera.Undistort(distorted, *last) : camera.Undistort(distorted);
      if (!normalized) continue;
      last = normalized;
      points.emplace_back(k.fx * normalized->x() + k.cx, k.fy * normalized->y() + k.cy);
    }
    if (points.size() >= 4) SplitAndFit(points, 0, static_cast<int>(points.size()) - 1, options, &out.lines);
  }
  out.lines = MergeCollinear(std::move(out.lines));
  return out;
}

std::vector<ImageLine> DetectLines(const cv::Mat& image_gray8, const Camera& camera,
                                   const RecognizerOptions& options) {
  return DetectLinesAndEdges(image_gray8, camera, options).lines;
}

std::optional<EdgePixel> EdgePixelAcross(const EdgeMap& edge_map, const Eigen::Vector2d& pixel,
                                         const Eigen::Vector2d& normal, int max_offset_px) {
  // The hottest loop of the recognizer (every support hypothesis and verified pose samples it): the
  // nearest pixel by floor(v + 0.5), and the unit gradient from the Sobel images (no trigonometry).
  static const float cos_tol = static_cast<float>(std::cos(25 * M_PI / 180));
  const int cols = edge_map.edges.cols, rows = edge_map.edges.rows;
  // Every pixel looked at below lies within max_offset_px of the nearest one in x and y (floor(v + d
  // + 0.5) - floor(v + 0.5) is within [-2, 2] for |d| <= 2): where the dilated edges show none
  // around it, there is none (most samples of a wrong pose, and the answer is the same).
  if (max_offset_px <= kEdgeNearPx && NoEdgeNear(edge_map, pixel)) return std::nullopt;
  const float nx = static_cast<float>(normal.x()), ny = static_cast<float>(normal.y());
  for (int o = 0; o <= 2 * max_offset_px; ++o) {
    const int offset = (o + 1) / 2 * (o % 2 ? 1 : -1);
    const int x = NearestPixel(pixel.x() + offset * normal.x(), cols);
    const int y = NearestPixel(pixel.y() + offset * normal.y(), rows);
    if (x < 0 || y < 0) continue;
    if (edge_map.edges.ptr<uint8_t>(y)[x] != kEdgeOnChain) continue;
    const auto unit = UnitGradient(edge_map, x, y);
    if (!unit) continue;
    const auto [gx, gy] = *unit;
    if (std::abs(gx * nx + gy * ny) >= cos_tol) return EdgePixel{x, y, gx, gy};
  }
  return std::nullopt;
}

namespace {

// LineRidgeShare's samples, each judged ridge or not, in order along the line until
// `decided(ridges, counted, left)` (the counts so far, and the samples not yet looked at) says the
// answer is known. The final counts, or those at which it stopped.
template <typename Decided>
std::pair<int, int> CountRidges(const ImageLine& line, const Camera& camera, const EdgeMap& edge_map,
                                double min_grey, Decided decided) {
  const double length = line.Length();
  if (!(length > 1)) return {0, 0};
  const Eigen::Vector2d along = (line.b - line.a) / length;
  // The line found along a thin line is one of its flanks (Canny marks both): its darkest (or
  // brightest) grey within kCorePx, and the grey kSidePx beyond that point on either side.
  constexpr double kSpacingPx = 3, kEndShare = 0.1, kCorePx = 2, kSidePx = 3;
  const int n = std::max(3, static_cast<int>((1 - 2 * kEndShare) * length / kSpacingPx));
  int counted = 0, ridges = 0;
  for (int i = 0; i < n; ++i) {
    if (decided(ridges, counted, n - i)) break;
    const Eigen::Vector2d u = line.a + (kEndShare + (1 - 2 * kEndShare) * (i + 0.5) / n) * (line.b - line.a);
    const Eigen::Vector2d c = camera.DistortPixel(u);
    if (!camera.InImage(c)) continue;
    const Eigen::Vector2d d = (camera.DistortPixel(u + along) - c).normalized(), normal(-d.y(), d.x());
    ++counted;
    float darkest = 256, brightest = -1;
    double dark_at = 0, bright_at = 0;
    for (double o = -kCorePx; o <= kCorePx + 1e-9; o += 0.5) {
      const float g = internal::SampleGrey(edge_map.smoothed, c + o * normal);
      if (g < darkest) darkest = g, dark_at = o;
      if (g > brightest) brightest = g, bright_at = o;
    }
    // Both sides at least min_grey brighter than a dark core (or darker than a bright one), and
    // within min_grey of each other.
    auto thin = [&](double at, float core, bool dark) {
      const float left = internal::SampleGrey(edge_map.smoothed, c + (at - kSidePx) * normal);
      const float right = internal::SampleGrey(edge_map.smoothed, c + (at + kSidePx) * normal);
      const float stands_out = dark ? std::min(left, right) - core : core - std::max(left, right);
      return stands_out >= min_grey && std::abs(left - right) < min_grey;
    };
    ridges += thin(dark_at, darkest, true) || thin(bright_at, brightest, false);
  }
  return {ridges, counted};
}

double Share(int ridges, int counted) { return counted > 0 ? static_cast<double>(ridges) / counted : 0; }

}  // namespace

double LineRidgeShare(const ImageLine& line, const Camera& camera, const EdgeMap& edge_map, double min_grey) {
  const auto [ridges, counted] =
      CountRidges(line, camera, edge_map, min_grey, [](int, int, int) { return false; });
  return Share(ridges, counted);
}

bool LineRidgeShareAtLeast(const ImageLine& line, const Camera& camera, const EdgeMap& edge_map,
                           double min_grey, double share) {
  // With `left` samples to come, the final share lies between ridges / (counted + left) (none of
  // them a ridge) and (ridges + left) / (counted + left) (all of them); leaving a sample out of the
  // count (off the image) keeps it within. Rounding a quotient is monotonic: where a bound already
  // decides the comparison, the final share, computed the same way, decides it alike.
  bool answer = false, early = false;
  const auto [ridges, counted] = CountRidges(line, camera, edge_map, min_grey, [&](int r, int c, int left) {
    const double most = static_cast<double>(r + left) / (c + left);
    const double least = static_cast<double>(r) / (c + left);
    if (most < share)
      answer = false, early = true;
    else if (least >= share && c > 0)
      answer = true, early = true;
    return early;
  });
  return early ? answer : Share(ridges, counted) >= share;
}

int EdgeSign(const EdgePixel& edge, const Eigen::Vector2d& normal) {
  return edge.gx * static_cast<float>(normal.x()) + edge.gy * static_cast<float>(normal.y()) > 0 ? 1 : -1;
}

int SignedEdgeAcross(const EdgeMap& edge_map, const Eigen::Vector2d& pixel, const Eigen::Vector2d& normal) {
  const std::optional<EdgePixel> p = EdgePixelAcross(edge_map, pixel, normal, 2);
  return p ? EdgeSign(*p, normal) : 0;
}

bool EdgeAcross(const EdgeMap& edge_map, const Eigen::Vector2d& pixel, const Eigen::Vector2d& normal) {
  return SignedEdgeAcross(edge_map, pixel, normal) != 0;
}

}  // namespace teachsim::vision
