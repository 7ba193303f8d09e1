// teachsim recognize: the blocks in one camera image, by model-based recognition (paper §4; issue 7).
//
//   teachsim recognize --image IMG.png --camera CAMERA.json --models MODELS.json [--out RESULT.json]
//                      [--scene SCENE.json] [--cache DIR] [--overlay OVERLAY.png]
//
// RESULT.json is described in docs/formats/recognize.md. Exit status 0 done (even when nothing is
// recognized: that is an outcome, reported), 2 bad input.
#include <cstdio>
#include <memory>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "commands.h"
#include "teachsim/base/json.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/camera.h"
#include "teachsim/vision/overlay.h"
#include "teachsim/vision/recognizer.h"
#include "teachsim/worksite/render.h"

namespace teachsim::app {

namespace {

struct RecognizeArgs {
  std::string image, camera, models, out, scene, cache, overlay;
};

json::Json PoseJson(const geometry::Pose3& pose) { return geometry::WritePose(pose); }

int RunRecognize(const RecognizeArgs& a) {
  auto spec = scene::LoadCamera(a.camera);
  if (!spec.ok()) return ReportError(spec.status());
  auto camera = vision::Camera::FromSpec(*spec);
  if (!camera.ok()) return ReportError(camera.status().WithPrefix(a.camera));
  auto models = vision::LoadModels(a.models);
  if (!models.ok()) return ReportError(models.status());
  std::unique_ptr<scene::Scene> fixed_world;
  if (!a.scene.empty()) {
    auto scene = scene::LoadScene(a.scene);
    if (!scene.ok()) return ReportError(scene.status());
    fixed_world = std::make_unique<scene::Scene>();
    for (const scene::SceneObject& o : scene->objects) {
      if (o.fixed) fixed_world->objects.push_back(o);
    }
  }
  const cv::Mat image = cv::imread(a.image, cv::IMREAD_GRAYSCALE);
  if (image.empty()) {
    return ReportError(Status::InvalidInput(a.image + ": cannot read the image (missing or not an image)"));
  }
  if (image.cols != camera->width() || image.rows != camera->height()) {
    return ReportError(Status::InvalidInput(a.image + ": image is " + std::to_string(image.cols) + "x" +
                                            std::to_string(image.rows) + " but " + a.camera + " (width, height) is " +
                                            std::to_string(camera->width()) + "x" + std::to_string(camera->height())));
  }
  // The recognizer works on one core (issue 7's time goal; `bench recognize` measures it so). Left
  // to itself, OpenCV would start its pool of worker threads at the first filter of the image's line
  // stage: 4-9 ms of this process's one recognition on our 2-core VM, for no gain.
  cv::setNumThreads(1);
  auto recognizer = vision::Recognizer::Create(*models, vision::RecognizerOptions(), a.cache);
  if (!recognizer.ok()) return ReportError(recognizer.status().WithPrefix(a.models));
  auto result = recognizer->Recognize(image, *camera, fixed_world.get());
  if (!result.ok()) return ReportError(result.status().WithPrefix(a.image));

  json::Json objects = json::Json::array();
  for (const vision::Recognition& r : result->objects) {
    json::Json o = PoseJson(r.world_T_object);  // position, quaternion_wxyz
    o["model"] = r.model;
    o["raw"] = PoseJson(r.raw_world_T_object);
    o["score"] = r.score;
    o["matched_edge_fraction"] = r.matched_edge_fraction;
    o["reprojection_rms_px"] = r.reprojection_rms_px;
    json::Json cov = json::Json::array();
    for (int i = 0; i < 6; ++i) {
      json::Json row = json::Json::array();
      for (int j = 0; j < 6; ++j) row.push_back(r.covariance(i, j));
      cov.push_back(row);
    }
    o["covariance"] = cov;
    o["adjustments"] = r.adjustments;
    objects.push_back(o);
    const Eigen::Vector3d& p = r.world_T_object.translation;
    std::printf("%-10s at (%7.1f, %7.1f, %7.1f) mm  score %.2f  matched %.2f  rms %.2f px\n", r.model.c_str(),
                p.x() * 1e3, p.y() * 1e3, p.z() * 1e3, r.score, r.matched_edge_fraction, r.reprojection_rms_px);
    for (const std::string& adj : r.adjustments) std::printf("           %s\n", adj.c_str());
  }
  json::Json timing = json::Json::object();
  for (const auto& [stage, ms] : result->timing_ms) timing[stage] = ms;
  std::printf("%zu objects; %.1f ms (index %s)\n", result->objects.size(), result->timing_ms.back().second,
              recognizer->loaded_from_cache() ? "from the cache" : "built");
  if (!a.out.empty()) {
    json::Json document = {{"objects", objects}, {"timing_ms", timing}};
    if (Status s = json::WriteJsonFile(a.out, document); !s.ok()) return ReportError(s);
  }
  if (!a.overlay.empty()) {
    auto drawn = vision::DrawRecognitions(image, *camera, *models, result->objects);
    if (!drawn.ok()) return ReportError(drawn.status().WithPrefix(a.overlay));
    if (Status s = worksite::WritePng(a.overlay, *drawn); !s.ok()) return ReportError(s);
  }
  return 0;
}

}  // namespace

void AddRecognizeCommand(CLI::App& app, Runner* run) {
  auto args = std::make_shared<RecognizeArgs>();
  CLI::App* sub = app.add_subcommand("recognize", "recognize the blocks in a camera image (model-based vision)");
  sub->add_option("--image", args->image, "the camera image (PNG, any depth: read as grey)")->required();
  sub->add_option("--camera", args->camera, "CAMERA.json: one camera entry of the scene format")->required();
  sub->add_option("--models", args->models, "MODELS.json: a scene (its movable boxes) or {\"models\": [...]}")
      ->required();
  sub->add_option("--out", args->out, "RESULT.json to write (docs/formats/recognize.md)");
  sub->add_option("--scene", args->scene, "a scene whose fixed objects (table, frame) the model editor uses");
  sub->add_option("--cache", args->cache, "folder for the model-view index (rebuilt when the models change)");
  sub->add_option("--overlay", args->overlay,
                  "OVERLAY.png to write: the image with each recognition's outline and \"#i model score\"");
  sub->callback([args, run] { *run = [args] { return RunRecognize(*args); }; });
}

}  // namespace teachsim::app
