// The photoreal dev set (../shared/data/vision-dev/, issue 7): cases with cameras, the fixed world
// (table and frame) and the true object poses, and the matching of recognitions to the truth.
#pragma once

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/evaluate.h"
#include "teachsim/vision/recognizer.h"

namespace teachsim::vision::dev {

inline std::string Folder() { return std::string(TEACHSIM_SHARED_DIR) + "/data/vision-dev"; }

struct TrueObject {
  std::string model;
  geometry::Pose3 world_T_object;  // the box's centre (checked against the images in the tests)
  double visible_fraction = 1;
};

struct Case {
  std::string image_path;
  scene::CameraSpec camera;
  scene::Scene fixed_world;  // the table (top at z = 0) and the frame's four walls (FixedWorldScene)
  std::vector<TrueObject> objects;
};

inline geometry::Pose3 PoseOf(const json::Json& j) {
  const auto& p = j.at("position");
  const auto& q = j.at("quaternion_wxyz");
  return {Eigen::Quaterniond(q[0].get<double>(), q[1].get<double>(), q[2].get<double>(), q[3].get<double>()).normalized(),
          Eigen::Vector3d(p[0].get<double>(), p[1].get<double>(), p[2].get<double>())};
}

inline ModelLibrary Models(const json::Json& truth) {
  ModelLibrary library;
  for (const auto& [name, dims] : truth.at("models").items()) {
    library.models.push_back({name, Eigen::Vector3d(dims[0].get<double>(), dims[1].get<double>(), dims[2].get<double>())});
  }
  return library;
}

inline json::Json Truth() {
  auto truth = json::ReadFile(Folder() + "/truth.json");
  EXPECT_TRUE(truth.ok()) << truth.status().message();
  return truth.ok() ? *truth : json::Json();
}

inline std::vector<Case> Cases(const json::Json& truth) {
  std::vector<Case> cases;
  for (const auto& c : truth.at("cases")) {
    Case out;
    out.image_path = Folder() + "/" + c.at("image").get<std::string>();
    const auto& cam = c.at("camera");
    out.camera.name = "dev";
    out.camera.width = cam.at("width").get<int>();
    out.camera.height = cam.at("height").get<int>();
    out.camera.fx = cam.at("fx").get<double>();
    out.camera.fy = cam.at("fy").get<double>();
    out.camera.cx = cam.at("cx").get<double>();
    out.camera.cy = cam.at("cy").get<double>();
    out.camera.k1 = cam.at("k1").get<double>();
    out.camera.k2 = cam.at("k2").get<double>();
    out.camera.p1 = cam.at("p1").get<double>();
    out.camera.p2 = cam.at("p2").get<double>();
    out.camera.k3 = cam.at("k3").get<double>();
    out.camera.gamma = kDevSetGamma;
    out.camera.world_T_camera = PoseOf(cam);
    // The fixed world as the benchmark builds it (FixedWorldScene), so that the test and
    // `teachsim bench recognize` judge the same recognitions.
    const auto& f = c.at("frame");
    FrameTruth frame;
    frame.world_T_frame = PoseOf(f);
    frame.inner_m = Eigen::Vector2d(f.at("inner")[0].get<double>(), f.at("inner")[1].get<double>());
    frame.wall_m = f.at("wall").get<double>();
    frame.height_m = f.at("height").get<double>();
    out.fixed_world = FixedWorldScene(frame);
    for (const auto& o : c.at("objects")) {
      out.objects.push_back({o.at("model").get<std::string>(), PoseOf(o), o.at("visible_fraction").get<double>()});
    }
    cases.push_back(std::move(out));
  }
  return cases;
}

// A recognition matches a true object of the same model within these (generous: the figures
// below measure the accuracy; this only decides found / not found / false).
inline constexpr double kMatchPositionM = 0.015;
inline constexpr double kMatchRotationRad = 10 * M_PI / 180;

}  // namespace teachsim::vision::dev
