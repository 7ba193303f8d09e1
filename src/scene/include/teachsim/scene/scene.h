// The world model: named objects (fixed or movable) with shapes and poses, cameras, and the
// robot's placement; JSON I/O with validation (docs/formats.md, "Scene").
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/geometry/shape.h"

namespace teachsim::scene {

// A shape as written in a file, kept for saving it back unchanged.
struct ShapeSpec {
  enum class Kind { kBox, kConvex, kParts };
  struct Part;
  Kind kind = Kind::kBox;
  Eigen::Vector3d box_size = Eigen::Vector3d::Zero();  // m, full side lengths, centred
  std::vector<Eigen::Vector3d> vertices;               // m, kConvex
  std::vector<Part> parts;                             // kParts
};
struct ShapeSpec::Part {
  ShapeSpec shape;
  geometry::Pose3 pose;  // shape_T_part
};

struct SceneObject {
  std::string name;
  bool fixed = true;
  std::string model;  // optional: the library model this object is an instance of
  ShapeSpec shape_spec;
  geometry::Shape shape;  // built from shape_spec
  geometry::Pose3 world_T_object;
};

// A pin-hole camera with OpenCV's distortion model and axes (x right, y down, z forward).
struct CameraSpec {
  std::string name;
  int width = 640, height = 480;            // px
  double fx = 600, fy = 600, cx = 319.5, cy = 239.5;  // px
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  // The response: a pixel's grey level is 255 E^(1 / gamma) for the light E in [0, 1] it gathered.
  // 1: linear (teachsim's renderer); about 2.2 for an sRGB camera or a POV-Ray PNG.
  double gamma = 1.0;
  geometry::Pose3 world_T_camera;
};

struct RobotPlacement {
  std::string model = "crs_a465";  // a table in robots/
  geometry::Pose3 world_T_base;
};

struct Scene {
  std::vector<SceneObject> objects;
  std::vector<CameraSpec> cameras;
  std::optional<RobotPlacement> robot;

  // Index of the object or camera named `name`, or -1.
  int FindObject(const std::string& name) const;
  int FindCamera(const std::string& name) const;
};

// Loading: every error names the file, the JSON path and the problem
// ("scenes/x.json: objects[3].shape.box[1]: must be > 0, got -0.02").
[[nodiscard]] Result<Scene> LoadScene(const std::string& path);
[[nodiscard]] Result<Scene> ParseScene(const json::Json& document, const std::string& name);
[[nodiscard]] Status SaveScene(const Scene& scene, const std::string& path);  // atomic
json::Json SceneToJson(const Scene& scene);

// Pieces, for other formats that embed them (camera files, model libraries, messages).
// These throw json::ParseError; use them inside json::Decode().
ShapeSpec ReadShapeSpec(const json::Reader& reader);
json::Json WriteShapeSpec(const ShapeSpec& spec);
CameraSpec ReadCamera(const json::Reader& reader);
json::Json WriteCamera(const CameraSpec& camera);
[[nodiscard]] Result<CameraSpec> LoadCamera(const std::string& path);  // a file holding one camera entry

// A box-shaped object (full side lengths size_m, centred), for scenes built in code.
SceneObject BoxObject(const std::string& name, bool fixed, const Eigen::Vector3d& size_m,
                      const geometry::Pose3& world_T_object);

// Builds the geometry of a validated spec.
[[nodiscard]] Result<geometry::Shape> BuildShape(const ShapeSpec& spec);

}  // namespace teachsim::scene
