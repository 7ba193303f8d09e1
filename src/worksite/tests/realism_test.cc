// Our images against the photoreal POV-Ray renders in ../shared/data/vision-dev (same kind of scene,
// exact truth): we render the same scene from the same camera and compare what makes a
// recognizer's job hard, measured the same way on both images.
#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "teachsim/worksite/render.h"

namespace teachsim::worksite {
namespace {

const std::string kDataDir = std::string(TEACHSIM_SHARED_DIR) + "/data/vision-dev";

std::shared_ptr<const geometry::ConvexPolyhedron> Box(const Eigen::Vector3d& size) {
  auto box = geometry::ConvexPolyhedron::Box(size);
  TEACHSIM_CHECK(box.ok());
  return std::make_shared<const geometry::ConvexPolyhedron>(std::move(*box));
}

geometry::Pose3 PoseOf(const json::Json& j) {
  return geometry::ReadPose(
      json::Reader(json::Json{{"position", j["position"]}, {"quaternion_wxyz", j["quaternion_wxyz"]}}));
}

struct Case {
  cv::Mat theirs;
  scene::CameraSpec camera;
  std::vector<RenderObject> objects;  // table, frame, blocks
};

Case LoadCase(int index) {
  auto document = json::ReadFile(kDataDir + "/truth.json");
  TEACHSIM_CHECK(document.ok());
  const json::Json& c = (*document)["cases"][static_cast<std::size_t>(index)];
  Case out;
  out.theirs = cv::imread(kDataDir + "/" + c["image"].get<std::string>(), cv::IMREAD_GRAYSCALE);
  out.camera = scene::ReadCamera(json::Reader(c["camera"]));
  RenderObject table;
  table.name = "table";
  table.material = Material::kTable;
  table.albedo = 0.78;
  table.texture_seed = 1;
  table.parts = {{Box({2.0, 2.0, 0.05}), geometry::Pose3::Translation({0, 0, -0.025})}};
  out.objects.push_back(table);
  const json::Json& f = c["frame"];
  const double iw = f["inner"][0], ih = f["inner"][1], wall = f["wall"], height = f["height"];
  RenderObject frame;
  frame.name = "frame";
  frame.texture_seed = 2;
  frame.world_T_object = PoseOf(f);
  for (double side : {-1.0, 1.0}) {
    frame.parts.push_back({Box({iw + 2 * wall, wall, height}),
                           geometry::Pose3::Translation({0, side * (ih + wall) / 2, height / 2})});
    frame.parts.push_back(
        {Box({wall, ih, height}), geometry::Pose3::Translation({side * (iw + wall) / 2, 0, height / 2})});
  }
  out.objects.push_back(frame);
  for (const json::Json& o : c["objects"]) {
    RenderObject block;
    block.name = o["name"];
    block.model = o["model"];
    block.texture_seed = static_cast<std::uint32_t>(out.objects.size() * 7919);
    block.parts = {{Box(Eigen::Vector3d(o["dims"][0].get<double>(), o["dims"][1].get<double>(),
                                        o["dims"][2].get<double>())),
                    geometry::Pose3::Identity()}};
    block.world_T_object = PoseOf(o);
    out.objects.push_back(block);
  }
  return out;
}

struct Figures {
  double edge_step = 0;      // mean |I(+3 px) - I(-3 px)| across visible block silhouette edges
  double edge_gradient = 0;  // mean peak Sobel magnitude (/8) within 1.5 px of those edges
  double noise_sigma = 0;    // Immerkaer's estimate over region interiors (texture counts as noise)
  int edge_samples = 0;
};

// Block silhouette edges and region interiors come from our label image of the same scene.
Figures Measure(const cv::Mat& image, const cv::Mat& labels, const vision::Camera& camera,
                const std::vector<RenderObject>& objects) {
  cv::Mat gx, gy, magnitude;
  cv::Sobel(image, gx, CV_32F, 1, 0, 3);
  cv::Sobel(image, gy, CV_32F, 0, 1, 3);
  cv::magnitude(gx, gy, magnitude);
  magnitude /= 8.0f;  // gray levels per pixel
  auto label_at = [&](const Eigen::Vector2d& p) {
    const int u = static_cast<int>(std::lround(p.x())), v = static_cast<int>(std::lround(p.y()));
    if (u < 2 || v < 2 || u >= labels.cols - 2 || v >= labels.rows - 2) return -3;
    return static_cast<int>(labels.at<std::int16_t>(v, u));
  };
  auto gray_at = [&](const Eigen::Vector2d& p) {
    return static_cast<double>(
        image.at<std::uint8_t>(static_cast<int>(std::lround(p.y())), static_cast<int>(std::lround(p.x()))));
  };
  Figures fig;
  for (std::size_t oi = 2; oi < objects.size(); ++oi) {
    const RenderObject& o = objects[oi];
    const auto& convex = *o.parts[0].convex;
    for (const geometry::Edge& e : convex.edges()) {
      const Eigen::Vector3d a = o.world_T_object * convex.vertices()[static_cast<std::size_t>(e.v0)];
      const Eigen::Vector3d b = o.world_T_object * convex.vertices()[static_cast<std::size_t>(e.v1)];
      for (double s = 0.1; s <= 0.9; s += 0.05) {
        auto p = camera.Project(a + s * (b - a));
        auto q = camera.Project(a + (s + 0.01) * (b - a));
        if (!p || !q) continue;
        const Eigen::Vector2d t = (*q - *p).normalized(), n(-t.y(), t.x());
        const int l_minus = label_at(*p - 3 * n), l_plus = label_at(*p + 3 * n);
        if (l_minus < -1 || l_plus < -1) continue;
        if ((l_minus == static_cast<int>(oi)) == (l_plus == static_cast<int>(oi)))
          continue;  // not a silhouette
        if (label_at(*p - 1.5 * n) != l_minus || label_at(*p + 1.5 * n) != l_plus) continue;
        fig.edge_step += std::abs(gray_at(*p + 3 * n) - gray_at(*p - 3 * n));
        float peak = 0;
        for (double d = -1.5; d <= 1.5; d += 0.5) {
          const Eigen::Vector2d r = *p + d * n;
          peak = std::max(peak, magnitude.at<float>(static_cast<int>(std::lround(r.y())),
                                                    static_cast<int>(std::lround(r.x()))));
        }
        fig.edge_gradient += peak;
        ++fig.edge_samples;
      }
    }
  }
  if (fig.edge_samples > 0) {
    fig.edge_step /= fig.edge_samples;
    fig.edge_gradient /= fig.edge_samples;
  }
  // Immerkaer (1996): sigma = sqrt(pi/2) / 6 * mean |I * M| over pixels away from any boundary.
  cv::Mat response;
  const cv::Mat kernel = (cv::Mat_<float>(3, 3) << 1, -2, 1, -2, 4, -2, 1, -2, 1);
  cv::filter2D(image, response, CV_32F, kernel);
  double sum = 0;
  long long count = 0;
  for (int v = 4; v < labels.rows - 4; ++v) {
    for (int u = 4; u < labels.cols - 4; ++u) {
      const std::int16_t l = labels.at<std::int16_t>(v, u);
      bool interior = true;
      for (int d = -3; d <= 3 && interior; ++d) {
        interior = labels.at<std::int16_t>(v + d, u) == l && labels.at<std::int16_t>(v, u + d) == l &&
                   labels.at<std::int16_t>(v + d, u + d) == l && labels.at<std::int16_t>(v + d, u - d) == l;
      }
      if (!interior || magnitude.at<float>(v, u) > 12) continue;  // skip creases and shadow edges
      sum += std::abs(response.at<float>(v, u));
      ++count;
    }
  }
  fig.noise_sigma = std::sqrt(M_PI / 2) / 6 * sum / static_cast<double>(std::max<long long>(1, count));
  return fig;
}

TEST(RealismTest, OurImagesAreNoEasierThanThePhotorealOnes) {
  if (!std::filesystem::exists(kDataDir + "/truth.json")) GTEST_SKIP() << kDataDir << " is not present";
  double ours_step = 0, theirs_step = 0, ours_grad = 0, theirs_grad = 0, ours_noise = 0, theirs_noise = 0;
  const std::vector<int> cases{0, 3, 6, 8};
  for (int index : cases) {
    const Case c = LoadCase(index);
    ASSERT_FALSE(c.theirs.empty());
    auto camera = vision::Camera::FromSpec(c.camera);
    ASSERT_TRUE(camera.ok());
    auto renderer = Renderer::Create(*camera, RenderOptions{});
    ASSERT_TRUE(renderer.ok());
    const RenderResult ours = renderer->Render(c.objects, 1);
    const Figures fo = Measure(ours.image, ours.labels, *camera, c.objects);
    const Figures ft = Measure(c.theirs, ours.labels, *camera, c.objects);
    std::printf(
        "case %d (%d edge samples): edge step ours %.1f theirs %.1f; edge gradient ours %.1f theirs %.1f; "
        "noise ours %.2f theirs %.2f\n",
        index, fo.edge_samples, fo.edge_step, ft.edge_step, fo.edge_gradient, ft.edge_gradient,
        fo.noise_sigma, ft.noise_sigma);
    ASSERT_GT(fo.edge_samples, 50);
    ours_step += fo.edge_step / cases.size();
    theirs_step += ft.edge_step / cases.size();
    ours_grad += fo.edge_gradient / cases.size();
    theirs_grad += ft.edge_gradient / cases.size();
    ours_noise += fo.noise_sigma / cases.size();
    theirs_noise += ft.noise_sigma / cases.size();
    if (index == 3) {
      // The picture for docs/images: theirs on the left, ours on the right.
      cv::Mat side;
      cv::hconcat(c.theirs, ours.image, side);
      ASSERT_TRUE(WritePng(::testing::TempDir() + "/realism_side_by_side.png", side).ok());
    }
  }
  std::printf(
      "mean over %zu cases: edge step ours %.1f theirs %.1f; edge gradient ours %.1f theirs %.1f; noise "
      "ours %.2f theirs %.2f (gray levels)\n",
      cases.size(), ours_step, theirs_step, ours_grad, theirs_grad, ours_noise, theirs_noise);
  // No easier: edges no stronger (within 10 %), no less noise and texture in the regions.
  EXPECT_LE(ours_step, 1.1 * theirs_step);
  EXPECT_LE(ours_grad, 1.1 * theirs_grad);
  EXPECT_GE(ours_noise, 0.9 * theirs_noise);
}

}  // namespace
}  // namespace teachsim::worksite
