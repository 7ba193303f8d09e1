// The default scene and arm, loaded for the work-site tests.
#pragma once

#include <string>

#include "teachsim/base/status.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"

namespace teachsim::worksite::testing {

inline scene::Scene Puzzle() {
  auto scene = scene::LoadScene(std::string(TEACHSIM_SOURCE_DIR) + "/scenes/puzzle.json");
  TEACHSIM_CHECK(scene.ok());
  return *scene;
}

inline robot::RobotModel Arm() {
  auto model = robot::LoadRobotModel(std::string(TEACHSIM_SOURCE_DIR) + "/robots/crs_a465.json");
  TEACHSIM_CHECK(model.ok());
  return *model;
}

}  // namespace teachsim::worksite::testing
