// End to end on the photoreal dev set (issue 7 "Show"): recognition rate per visible-fraction bin,
// false positives, pose errors, time. The thresholds are ones the method meets on all 12 images
// (it was not tuned image by image); the figures are printed for the report.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <opencv2/imgproc.hpp>

#include "dev_set.h"
#include "teachsim/vision/evaluate.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {
namespace {

// The truth's `position` is the box's centre: the true boxes' visible edges lie on image edges far
// more often than the edges of the same boxes moved by 5 mm. (Not all of them: a lit face in front
// of the lit table shows no edge in these images, about a third of the visible edge length.)
TEST(DevSetTest, TruthPosesAreBoxCentresOnTheImageEdges) {
  const json::Json truth = dev::Truth();
  const ModelLibrary models = dev::Models(truth);
  int samples = 0, supported = 0, supported_moved = 0;
  for (const dev::Case& c : dev::Cases(truth)) {
    const cv::Mat image = cv::imread(c.image_path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty()) << c.image_path;
    auto camera = Camera::FromSpec(c.camera);
    ASSERT_TRUE(camera.ok());
    const LineDetection d = DetectLinesAndEdges(image, *camera, RecognizerOptions());
    cv::Mat near;
    cv::dilate(d.edge_map.edges, near, cv::Mat::ones(5, 5, CV_8U));
    for (const dev::TrueObject& o : c.objects) {
      if (o.visible_fraction < 0.99) continue;
      const Model& m = *std::find_if(models.models.begin(), models.models.end(),
                                     [&](const Model& x) { return x.name == o.model; });
      const geometry::Pose3 camera_T_object = camera->camera_T_world() * o.world_T_object;
      const uint16_t visible = VisibleBoxEdges(m.box_size_m, camera_T_object.Inverse().translation);
      for (int e = 0; e < 12; ++e) {
        if (!(visible >> e & 1)) continue;
        for (double t = 0.15; t < 0.9; t += 0.1) {
          const Eigen::Vector3d p = o.world_T_object * ((1 - t) * BoxVertex(m.box_size_m, kBoxEdges[e][0]) +
                                                        t * BoxVertex(m.box_size_m, kBoxEdges[e][1]));
          const auto px = camera->Project(p);
          const auto moved = camera->Project(p + Eigen::Vector3d(0.005, 0, 0));
          if (!px || !moved || !camera->InImage(*px) || !camera->InImage(*moved)) continue;
          ++samples;
          auto on_edge = [&](const Eigen::Vector2d& q) {
            return near.at<uint8_t>(static_cast<int>(std::lround(q.y())), static_cast<int>(std::lround(q.x()))) ? 1 : 0;
          };
          supported += on_edge(*px);
          supported_moved += on_edge(*moved);
        }
      }
    }
  }
  ASSERT_GT(samples, 500);
  EXPECT_GT(static_cast<double>(supported) / samples, 0.6) << supported << " of " << samples;
  EXPECT_LT(static_cast<double>(supported_moved) / samples, 0.6 * supported / samples) << supported_moved;
}

struct Bin {
  int objects = 0, found = 0;
};

TEST(DevSetTest, RecognizesTheBlocksOfTheTwelveImages) {
  const json::Json truth = dev::Truth();
  const ModelLibrary models = dev::Models(truth);
  const std::string cache = ::testing::TempDir() + "/teachsim-devset-index";
  const RecognizerOptions options;
  auto recognizer = Recognizer::Create(models, options, cache);
  ASSERT_TRUE(recognizer.ok()) << recognizer.status().message();
  Bin bins[3];  // >= 0.7, 0.4-0.7, < 0.4
  Bin unoccluded;  // visible fraction >= kUnoccludedFraction (in bins[0] too)
  int false_positives = 0, images = 0;
  std::vector<double> position_errors_mm, rotation_errors_deg, depth_errors_mm, rms_px, times_ms, raw_position_mm;
  const char* debug_dir = std::getenv("TEACHSIM_VISION_DEBUG_DIR");
  for (const dev::Case& c : dev::Cases(truth)) {
    ++images;
    const cv::Mat image = cv::imread(c.image_path, cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty());
    auto camera = Camera::FromSpec(c.camera);
    ASSERT_TRUE(camera.ok());
    auto result = recognizer->Recognize(image, *camera, &c.fixed_world);
    ASSERT_TRUE(result.ok()) << result.status().message();
    times_ms.push_back(result->timing_ms.back().second);
    std::vector<bool> used(result->objects.size(), false);
    for (const dev::TrueObject& o : c.objects) {
      Bin& bin = bins[o.visible_fraction >= 0.7 ? 0 : o.visible_fraction >= 0.4 ? 1 : 2];
      const bool whole = o.visible_fraction >= kUnoccludedFraction;
      ++bin.objects;
      unoccluded.objects += whole ? 1 : 0;
      const Model& m = *std::find_if(models.models.begin(), models.models.end(),
                                     [&](const Model& x) { return x.name == o.model; });
      for (size_t k = 0; k < result->objects.size(); ++k) {
        const Recognition& r = result->objects[k];
        if (used[k] || r.model != o.model) continue;
        const double dp = (r.world_T_object.translation - o.world_T_object.translation).norm();
        const double da = SymmetricRotationAngle(m, r.world_T_object, o.world_T_object);
        if (dp > dev::kMatchPositionM || da > dev::kMatchRotationRad) continue;
        used[k] = true;
        ++bin.found;
        unoccluded.found += whole ? 1 : 0;
        const Eigen::Vector3d axis = (o.world_T_object.translation - camera->world_T_camera().translation).normalized();
        const Eigen::Vector3d err = r.world_T_object.translation - o.world_T_object.translation;
        position_errors_mm.push_back(1000 * (err - axis * axis.dot(err)).norm());
        depth_errors_mm.push_back(1000 * std::abs(axis.dot(err)));
        raw_position_mm.push_back(1000 * (r.raw_world_T_object.translation - o.world_T_object.translation).norm());
        rotation_errors_deg.push_back(da * 180 / M_PI);
        rms_px.push_back(r.reprojection_rms_px);
        if (da * 180 / M_PI > 0.5) {
          std::printf("  %s: %s off by %.2f deg (reprojection RMS %.2f px, matched %.2f)\n", c.image_path.c_str(),
                      r.model.c_str(), da * 180 / M_PI, r.reprojection_rms_px, r.matched_edge_fraction);
        }
        break;
      }
    }
    for (size_t k = 0; k < used.size(); ++k) {
      if (used[k]) continue;
      ++false_positives;
      const Recognition& r = result->objects[k];
      std::printf("  false positive in %s: %s at (%.1f, %.1f, %.1f) mm, score %.2f, matched %.2f\n",
                  c.image_path.c_str(), r.model.c_str(), 1000 * r.world_T_object.translation.x(),
                  1000 * r.world_T_object.translation.y(), 1000 * r.world_T_object.translation.z(), r.score,
                  r.matched_edge_fraction);
    }
    if (debug_dir != nullptr) {
      cv::Mat overlay;
      cv::cvtColor(image, overlay, cv::COLOR_GRAY2BGR);
      for (const Recognition& r : result->objects) {
        const Model& m = *std::find_if(models.models.begin(), models.models.end(),
                                       [&](const Model& x) { return x.name == r.model; });
        for (int e = 0; e < 12; ++e) {
          const auto a = camera->Project(r.world_T_object * BoxVertex(m.box_size_m, kBoxEdges[e][0]));
          const auto b = camera->Project(r.world_T_object * BoxVertex(m.box_size_m, kBoxEdges[e][1]));
          if (a && b) cv::line(overlay, {int(a->x()), int(a->y())}, {int(b->x()), int(b->y())}, {0, 0, 255}, 1);
        }
      }
      const std::string name = c.image_path.substr(c.image_path.rfind('/') + 1);
      cv::imwrite(std::string(debug_dir) + "/" + name, overlay);
    }
  }
  auto median = [](std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  auto percentile = [](std::vector<double> v, double q) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[static_cast<size_t>(q * static_cast<double>(v.size() - 1))];
  };
  auto max = [](const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); };
  const char* names[3] = {">=0.7", "0.4-0.7", "<0.4"};
  for (int b = 0; b < 3; ++b) {
    std::printf("visible %-8s %2d of %2d found\n", names[b], bins[b].found, bins[b].objects);
  }
  std::printf("unoccluded        %2d of %2d found\n", unoccluded.found, unoccluded.objects);
  std::printf("false positives: %d in %d images\n", false_positives, images);
  std::printf("position across the view: median %.2f mm, max %.2f mm; along the camera axis: median %.2f, max %.2f mm\n",
              median(position_errors_mm), max(position_errors_mm), median(depth_errors_mm), max(depth_errors_mm));
  std::printf("raw (before the editor) position error: median %.2f mm, max %.2f mm\n", median(raw_position_mm),
              max(raw_position_mm));
  std::printf("rotation: median %.2f deg, p90 %.2f deg, max %.2f deg; reprojection RMS median %.2f px, max %.2f px\n",
              median(rotation_errors_deg), percentile(rotation_errors_deg, 0.9), max(rotation_errors_deg),
              median(rms_px), max(rms_px));
  std::printf("time per image: median %.1f ms, max %.1f ms\n", median(times_ms), max(times_ms));

  // Thresholds met on this set (see the report; the goals are higher in places).
  // Recall, against the goals of 98 % of the unoccluded blocks and 90 % with up to 30 %
  // hidden (the >= 0.7 bin): the support-plane hypotheses raised the >= 0.7 bin from 21 to 27 of 38
  // (the index alone fails this threshold), the robust fits to 33, the evidence score to 35 and it
  // took the last false positive away, the lower Canny thresholds to 36. Of the 27 unoccluded blocks
  // 26 are found: case_009's slab, in full view, is missed (its right face is lit like the table;
  // docs/benchmarks.md, sessions 30-31), one block short of 98 % on this set. False positives,
  // accuracy in the median and time meet the goals. Since
  // the lower thresholds a few found blocks were 0.6-1.0 deg off in yaw, most the same way: the
  // edge points were placed on the gamma-encoded grey levels. Told the set's gamma (2.2), the
  // editor's fit places them on the linear light: p90 0.69 -> 0.30 deg, the largest 1.01 -> 0.43
  // (session 29). The goal, 0.5 deg, holds the p90.
  EXPECT_GE(bins[0].found, static_cast<int>(0.92 * bins[0].objects));
  // Half hidden (0.4-0.7 visible), against the goal of 70 %: 4 of the 6. Until session 41 this test
  // built the table 1.2 x 1.0 m where the benchmark builds it 1.2 x 1.2 m (FixedWorldScene), and
  // case_007's tall block, 0.63 visible, was found by the benchmark and missed here.
  EXPECT_GE(bins[1].found, 4);
  EXPECT_EQ(unoccluded.objects, 27);
  EXPECT_GE(unoccluded.found, unoccluded.objects - 1);
  EXPECT_EQ(false_positives, 0);
  EXPECT_LT(median(rotation_errors_deg), 0.5);
  EXPECT_LT(percentile(rotation_errors_deg, 0.9), 0.5);
  EXPECT_LT(max(rotation_errors_deg), 0.75);
  EXPECT_LT(median(position_errors_mm), 1.0);
  EXPECT_LT(median(depth_errors_mm), 1.0);
  EXPECT_LT(median(rms_px), 0.5);
}

// The matched-share rescue (RecognizerOptions::matched_share_rescue_score): in case_002 the tall block
// half behind the cylinder (0.46 visible) has too few of its edges as image lines for the matched
// share, while its outline's edge points are there. Found with the rescue, missed without it; and no
// other recognition in the image either way.
TEST(DevSetTest, AHalfHiddenBlockShortOfMatchedLinesIsTakenOnItsEvidence) {
  const json::Json truth = dev::Truth();
  const ModelLibrary models = dev::Models(truth);
  const std::vector<dev::Case> cases = dev::Cases(truth);
  const auto c = std::find_if(cases.begin(), cases.end(), [](const dev::Case& x) {
    return x.image_path.find("case_002") != std::string::npos;
  });
  ASSERT_NE(c, cases.end());
  const auto tall = std::find_if(c->objects.begin(), c->objects.end(),
                                 [](const dev::TrueObject& o) { return o.model == "tall135"; });
  ASSERT_NE(tall, c->objects.end());
  ASSERT_GE(tall->visible_fraction, 0.4);
  ASSERT_LT(tall->visible_fraction, 0.7);
  const cv::Mat image = cv::imread(c->image_path, cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(image.empty());
  auto camera = Camera::FromSpec(c->camera);
  ASSERT_TRUE(camera.ok());
  const Model& model = *std::find_if(models.models.begin(), models.models.end(),
                                     [](const Model& m) { return m.name == "tall135"; });
  auto found = [&](bool rescue) {
    RecognizerOptions options;
    options.matched_share_rescue = rescue;
    auto recognizer = Recognizer::Create(models, options, ::testing::TempDir() + "/teachsim-devset-index");
    EXPECT_TRUE(recognizer.ok()) << recognizer.status().message();
    if (!recognizer.ok()) return -1;
    auto result = recognizer->Recognize(image, *camera, &c->fixed_world);
    EXPECT_TRUE(result.ok());
    if (!result.ok()) return -1;
    int near_truth = 0;
    for (const Recognition& r : result->objects) {
      near_truth += r.model == "tall135" &&
                            (r.world_T_object.translation - tall->world_T_object.translation).norm() <=
                                dev::kMatchPositionM &&
                            SymmetricRotationAngle(model, r.world_T_object, tall->world_T_object) <=
                                dev::kMatchRotationRad
                        ? 1
                        : 0;
    }
    EXPECT_EQ(static_cast<int>(result->objects.size()), near_truth) << "rescue " << rescue;
    return near_truth;
  };
  EXPECT_EQ(found(true), 1);
  EXPECT_EQ(found(false), 0);
}

}  // namespace
}  // namespace teachsim::vision
