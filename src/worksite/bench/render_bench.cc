// teachsim bench render: time per image of the default scene at 640x480 on one core, per
// supersampling factor (the work site must stream >= 5 Hz), and the camera model's undistortion of
// every pixel centre against its peer, cv::undistortPoints run to the same precision.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <opencv2/calib3d.hpp>

#include "teachsim/base/bench_registry.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {
namespace {

double Ms(std::chrono::steady_clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

// CPU time of this thread: on a shared machine wall time also counts other processes.
double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

int Run(const BenchArgs& args) {
  const char* home = std::getenv("TEACHSIM_HOME");
  const std::string path =
      std::string(home != nullptr && *home != '\0' ? home : TEACHSIM_BENCH_SOURCE_DIR) + "/scenes/puzzle.json";
  auto scene = scene::LoadScene(path);
  if (!scene.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", scene.status().message().c_str());
    return 2;
  }
  auto camera = vision::Camera::FromSpec(scene->cameras.at(0));
  if (!camera.ok()) return 2;
  const auto objects = ObjectsFromScene(*scene);
  const int repeats = args.quick ? 2 : 15;
  json::Json rows = json::Json::array();
  for (int ss : {1, 2, 3}) {
    RenderOptions options;
    options.supersample = ss;
    const auto t0 = std::chrono::steady_clock::now();
    auto renderer = Renderer::Create(*camera, options);
    const double setup_ms = Ms(std::chrono::steady_clock::now() - t0);
    if (!renderer.ok()) return 2;
    std::vector<double> times, cpu;
    for (int i = 0; i < repeats; ++i) {
      const auto t = std::chrono::steady_clock::now();
      const double c = ThreadCpuMs();
      const RenderResult result = renderer->Render(objects, static_cast<std::uint64_t>(i));
      cpu.push_back(ThreadCpuMs() - c);
      times.push_back(Ms(std::chrono::steady_clock::now() - t));
    }
    std::sort(times.begin(), times.end());
    std::sort(cpu.begin(), cpu.end());
    rows.push_back({{"supersample", ss},
                    {"setup_ms", setup_ms},
                    {"min_ms", times.front()},
                    {"median_ms", times[times.size() / 2]},
                    {"median_cpu_ms", cpu[cpu.size() / 2]},
                    {"hz", 1000.0 / times[times.size() / 2]}});
  }
  // Peer: undistorting all pixel centres.
  std::vector<cv::Point2d> pixels;
  for (int v = 0; v < camera->height(); ++v) {
    for (int u = 0; u < camera->width(); ++u) pixels.emplace_back(u, v);
  }
  const auto& k = camera->intrinsics();
  const auto& d = camera->distortion();
  const cv::Mat kk = (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  const cv::Mat dist = (cv::Mat_<double>(1, 5) << d.k1, d.k2, d.p1, d.p2, d.k3);
  auto t = std::chrono::steady_clock::now();
  double sum = 0;
  for (const cv::Point2d& p : pixels) sum += camera->PixelToNormalized({p.x, p.y})->x();
  const double ours_ms = Ms(std::chrono::steady_clock::now() - t);
  std::vector<cv::Point2d> normalized;
  t = std::chrono::steady_clock::now();
  cv::undistortPoints(pixels, normalized, kk, dist, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
  const double opencv_ms = Ms(std::chrono::steady_clock::now() - t);
  double worst = 0;
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    const Eigen::Vector2d ours = *camera->PixelToNormalized({pixels[i].x, pixels[i].y});
    worst = std::max(worst, k.fx * (ours - Eigen::Vector2d(normalized[i].x, normalized[i].y)).norm());
  }
  if (args.json) {
    std::printf(
        "%s\n",
        json::Json{{"benchmark", "render"},
                   {"image", {camera->width(), camera->height()}},
                   {"render", rows},
                   {"undistort_all_pixels",
                    {{"ours_ms", ours_ms}, {"opencv_ms", opencv_ms}, {"largest_difference_px", worst}}},
                   {"checksum", sum}}
            .dump(2)
            .c_str());
    return 0;
  }
  std::printf("render %dx%d, default scene, one core (%d images each):\n", camera->width(), camera->height(),
              repeats);
  for (const json::Json& r : rows) {
    std::printf(
        "  supersample %d: set-up %5.0f ms, image min %6.1f ms, median %6.1f ms (%.1f Hz), median CPU %6.1f "
        "ms\n",
        r["supersample"].get<int>(), r["setup_ms"].get<double>(), r["min_ms"].get<double>(),
        r["median_ms"].get<double>(), r["hz"].get<double>(), r["median_cpu_ms"].get<double>());
  }
  std::printf(
      "undistort all %zu pixel centres: ours %.1f ms, cv::undistortPoints (100 iterations max) %.1f ms; "
      "largest difference %.2g px\n",
      pixels.size(), ours_ms, opencv_ms, worst);
  return 0;
}

}  // namespace
}  // namespace teachsim::worksite

TEACHSIM_BENCH("render",
               "time per camera image (640x480, one core) per supersampling; undistortion vs OpenCV",
               teachsim::worksite::Run);
