// Item 1's comparison (issue 7): our sub-pixel Canny chains + Ramer + least squares against
// OpenCV's LSD (and FastLineDetector from ximgproc when installed) on the dev set. The figure is
// the share of the true, fully visible box edges' length found by a segment within 1 px and 3 deg
// (undistorted coordinates for ours; the others' segments are undistorted at their endpoints, as
// the recognizer would have to), and the time per image.
#include <gtest/gtest.h>

#include <chrono>
#include <opencv2/imgproc.hpp>

#include "dev_set.h"
#include "teachsim/vision/recognition_stages.h"

#ifdef TEACHSIM_HAVE_FLD
#include <opencv2/ximgproc/fast_line_detector.hpp>
#endif

namespace teachsim::vision {
namespace {

struct Figure {
  double found_px = 0, total_px = 0, time_ms = 0;
  size_t segments = 0;
};

// Share of the true edges (undistorted px) covered by segments on them.
void Score(const std::vector<ImageLine>& lines, const std::vector<ImageLine>& truth, Figure* f) {
  for (const ImageLine& t : truth) {
    const double len = t.Length();
    const Eigen::Vector2d dir = (t.b - t.a) / len, n(-dir.y(), dir.x());
    std::vector<std::pair<double, double>> covered;
    for (const ImageLine& l : lines) {
      const Eigen::Vector2d ld = (l.b - l.a).normalized();
      if (std::abs(ld.dot(dir)) < std::cos(3 * M_PI / 180)) continue;
      if (std::abs(n.dot(l.a - t.a)) > 1.0 || std::abs(n.dot(l.b - t.a)) > 1.0) continue;
      double s0 = dir.dot(l.a - t.a), s1 = dir.dot(l.b - t.a);
      if (s0 > s1) std::swap(s0, s1);
      covered.push_back({std::max(0.0, s0), std::min(len, s1)});
    }
    std::sort(covered.begin(), covered.end());
    double end = 0, sum = 0;
    for (const auto& [a, b] : covered) {
      if (b <= end) continue;
      sum += b - std::max(a, end);
      end = b;
    }
    f->found_px += sum;
    f->total_px += len;
  }
}

ImageLine Undistorted(const Camera& camera, const cv::Vec4f& s) {
  const Intrinsics& k = camera.intrinsics();
  auto u = [&](double x, double y) {
    const auto n = camera.PixelToNormalized({x, y});
    return n ? Eigen::Vector2d(k.fx * n->x() + k.cx, k.fy * n->y() + k.cy) : Eigen::Vector2d(x, y);
  };
  return {u(s[0], s[1]), u(s[2], s[3])};
}

TEST(LineDetectorComparisonTest, OursFindsAtLeastAsMuchOfTheTrueEdgesAsLsd) {
  const json::Json truth = dev::Truth();
  const ModelLibrary models = dev::Models(truth);
  Figure ours, lsd, fld;
  using Clock = std::chrono::steady_clock;
  auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  for (const dev::Case& c : dev::Cases(truth)) {
    const cv::Mat image = cv::imread(c.image_path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty());
    auto camera = Camera::FromSpec(c.camera);
    ASSERT_TRUE(camera.ok());
    std::vector<ImageLine> true_edges;
    for (const dev::TrueObject& o : c.objects) {
      if (o.visible_fraction < 0.99) continue;
      const Model& m = *std::find_if(models.models.begin(), models.models.end(),
                                     [&](const Model& x) { return x.name == o.model; });
      const geometry::Pose3 camera_T_object = camera->camera_T_world() * o.world_T_object;
      const uint16_t visible = VisibleBoxEdges(m.box_size_m, camera_T_object.Inverse().translation);
      for (int e = 0; e < 12; ++e) {
        if (!(visible >> e & 1)) continue;
        const Eigen::Vector3d p = camera->K() * (camera_T_object * BoxVertex(m.box_size_m, kBoxEdges[e][0]));
        const Eigen::Vector3d q = camera->K() * (camera_T_object * BoxVertex(m.box_size_m, kBoxEdges[e][1]));
        true_edges.push_back({p.head<2>() / p.z(), q.head<2>() / q.z()});
      }
    }
    auto t0 = Clock::now();
    const std::vector<ImageLine> mine = DetectLines(image, *camera, RecognizerOptions());
    auto t1 = Clock::now();
    ours.time_ms += ms(t0, t1);
    ours.segments += mine.size();
    Score(mine, true_edges, &ours);

    cv::Ptr<cv::LineSegmentDetector> detector = cv::createLineSegmentDetector(cv::LSD_REFINE_STD);
    std::vector<cv::Vec4f> raw;
    t0 = Clock::now();
    detector->detect(image, raw);
    std::vector<ImageLine> theirs;
    for (const cv::Vec4f& s : raw) theirs.push_back(Undistorted(*camera, s));
    t1 = Clock::now();
    lsd.time_ms += ms(t0, t1);
    lsd.segments += theirs.size();
    Score(theirs, true_edges, &lsd);
#ifdef TEACHSIM_HAVE_FLD
    cv::Ptr<cv::ximgproc::FastLineDetector> fast = cv::ximgproc::createFastLineDetector();
    raw.clear();
    t0 = Clock::now();
    fast->detect(image, raw);
    theirs.clear();
    for (const cv::Vec4f& s : raw) theirs.push_back(Undistorted(*camera, s));
    t1 = Clock::now();
    fld.time_ms += ms(t0, t1);
    fld.segments += theirs.size();
    Score(theirs, true_edges, &fld);
#endif
  }
  const double n = 12;
  std::printf("true edge length found (within 1 px, 3 deg) / time per image / segments per image:\n");
  std::printf("  ours (sub-pixel Canny + Ramer + LSQ) %.1f %%  %.1f ms  %.0f\n", 100 * ours.found_px / ours.total_px,
              ours.time_ms / n, ours.segments / n);
  std::printf("  OpenCV LSD                          %.1f %%  %.1f ms  %.0f\n", 100 * lsd.found_px / lsd.total_px,
              lsd.time_ms / n, lsd.segments / n);
#ifdef TEACHSIM_HAVE_FLD
  std::printf("  OpenCV FastLineDetector             %.1f %%  %.1f ms  %.0f\n", 100 * fld.found_px / fld.total_px,
              fld.time_ms / n, fld.segments / n);
#endif
  EXPECT_GE(ours.found_px / ours.total_px, lsd.found_px / lsd.total_px - 0.02);
}

}  // namespace
}  // namespace teachsim::vision
