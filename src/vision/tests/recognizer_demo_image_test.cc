// The recognizer on one of the work site's own camera images (issue 7, "end-to-end"): the image
// that `teachsim demo --seed 2` renders of its MuJoCo world, with the world it rendered (the true
// poses, the camera, the table and the frame), kept in tests/data. The five blocks are all found
// where they are and nothing else is: in session 10 the first version of the edge-point refit let a
// refitted bar outrank the slab there (a refitted pose's score, judged on edge points, is higher
// than one judged on lines; the selection now ranks it by its lines' score like any other pose).
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <string>

#include "teachsim/scene/scene.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::vision {
namespace {

const std::string kData = std::string(TEACHSIM_SOURCE_DIR) + "/src/vision/tests/data/";

TEST(DemoImageTest, FindsEveryBlockOfTheDemoWorldAndNothingElse) {
  auto world = scene::LoadScene(kData + "demo_seed2_world.scene.json");
  ASSERT_TRUE(world.ok()) << world.status().message();
  auto models = LoadModels(kData + "demo_seed2_world.scene.json");
  ASSERT_TRUE(models.ok()) << models.status().message();
  ASSERT_EQ(models->models.size(), 5u);
  ASSERT_FALSE(world->cameras.empty());
  auto camera = Camera::FromSpec(world->cameras.front());
  ASSERT_TRUE(camera.ok()) << camera.status().message();
  scene::Scene fixed_world;
  for (const scene::SceneObject& o : world->objects) {
    if (o.fixed) fixed_world.objects.push_back(o);
  }
  const cv::Mat image = cv::imread(kData + "demo_seed2_camera.png", cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(image.empty());

  auto recognizer =
      Recognizer::Create(*models, RecognizerOptions(), ::testing::TempDir() + "/teachsim-demo-index");
  ASSERT_TRUE(recognizer.ok()) << recognizer.status().message();
  auto result = recognizer->Recognize(image, *camera, &fixed_world);
  ASSERT_TRUE(result.ok()) << result.status().message();

  std::string found;
  for (const Recognition& r : result->objects) found += " " + r.model;
  int matched = 0;
  for (const scene::SceneObject& o : world->objects) {
    if (o.fixed) continue;
    const Model& model = *std::find_if(models->models.begin(), models->models.end(),
                                       [&](const Model& m) { return m.name == o.model; });
    bool here = false;
    for (const Recognition& r : result->objects) {
      here = here || (r.model == o.model &&
                      (r.world_T_object.translation - o.world_T_object.translation).norm() < 0.003 &&
                      SymmetricRotationAngle(model, r.world_T_object, o.world_T_object) < 1.0 * M_PI / 180);
    }
    EXPECT_TRUE(here) << o.name << " (" << o.model << ") not found within 3 mm and 1 deg; found:" << found;
    matched += here ? 1 : 0;
  }
  EXPECT_EQ(matched, 5);
  EXPECT_EQ(result->objects.size(), 5u) << "found:" << found;
}

}  // namespace
}  // namespace teachsim::vision
