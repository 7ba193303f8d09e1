// Stage 2 of the demo: the recognizer (src/vision) on the work site's camera image. Only the image,
// the calibrated camera, the model library and the fixed world go in; nothing of the simulator.
#include "demo_pipeline.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::app {

Result<RecognitionOutput> RecognizeBlocks(const std::string& models_path, const cv::Mat& image,
                                          const vision::Camera& camera, const scene::Scene& fixed_world,
                                          const std::string& cache_dir) {
  auto models = vision::LoadModels(models_path);
  if (!models.ok()) return models.status();
  auto recognizer = vision::Recognizer::Create(*models, vision::RecognizerOptions{}, cache_dir);
  if (!recognizer.ok()) return recognizer.status();
  auto recognized = recognizer->Recognize(image, camera, &fixed_world);
  if (!recognized.ok()) return recognized.status();
  RecognitionOutput out;
  out.from_cache = recognizer->loaded_from_cache();
  out.timing_ms = recognized->timing_ms;
  for (const vision::Recognition& r : recognized->objects) {
    DemoRecognition d;
    d.model = r.model;
    for (const vision::Model& m : models->models) {
      if (m.name == r.model) d.box_size_m = m.box_size_m;
    }
    d.world_T_object = r.world_T_object;
    d.score = r.score;
    d.matched_edge_fraction = r.matched_edge_fraction;
    d.reprojection_rms_px = r.reprojection_rms_px;
    d.adjustments = r.adjustments;
    out.objects.push_back(std::move(d));
  }
  return out;
}

}  // namespace teachsim::app
