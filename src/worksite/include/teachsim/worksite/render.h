// The work site's simulated camera (paper §3.1: a single monochrome camera): an 8-bit image of the
// scene as the camera model sees it. The recognizer must cope with light, occlusion and noise
// (§7.1), so the image carries shading, soft cast shadows, wood grain and a mottled table, lens
// distortion, anti-aliasing, blur and sensor noise.
//
// A CPU ray caster of our own: every sub-pixel sample's ray comes from the camera model's exact
// unprojection (so corners land where vision::Camera projects them, distortion included), the
// nearest convex part is found per ray (parts culled per 16x16 tile), and shadow rays go to a
// disc-shaped light (soft shadow edges). Formats: docs/formats/render.md.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "teachsim/base/json.h"
#include "teachsim/base/status.h"
#include "teachsim/geometry/shape.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/calibration.h"
#include "teachsim/vision/camera.h"

namespace teachsim::worksite {

enum class Material {
  kWood,        // blocks and frame: growth rings about the object's longest axis, fine streaks
  kTable,       // mottled light surface
  kChessboard,  // the printed face (board z = 0) carries the chessboard, with a white margin
  kFlat,        // uniform albedo
};

struct RenderObject {
  std::string name;
  std::string model;                       // copied to the truth file
  std::vector<geometry::ShapePart> parts;  // convex parts, shape_T_part
  geometry::Pose3 world_T_object;
  Material material = Material::kWood;
  double albedo = 0.62;            // mean reflectance in [0, 1]
  std::uint32_t texture_seed = 0;  // the grain is the object's own: it moves with the object
  vision::ChessboardSpec board;    // kChessboard only
};

struct RenderOptions {
  int supersample = 2;  // samples per pixel along each axis (anti-aliasing)
  // Towards the light, world frame; the light is a disc of this angular radius (soft shadow edges).
  Eigen::Vector3d light_direction_in_world = Eigen::Vector3d(0.55, -0.2, 0.81);
  double light_angular_radius_rad = 0.035;
  double ambient = 0.5;     // share of radiance that reaches shadowed and back-facing surfaces
  double diffuse = 0.55;    // Lambertian term of the light
  double background = 0.1;  // radiance where a ray hits nothing
  double gain = 255.0;      // gray level per unit radiance
  double blur_sigma_px = 0.85;
  double noise_sigma = 3.0;  // sensor noise, gray levels (Gaussian, per pixel)
  bool textures = true;
  bool shadows = true;
  // Flat shading, no texture, shadow, blur or noise: edges at full contrast, for geometry checks.
  static RenderOptions HighContrast();
  [[nodiscard]] Status Validate() const;
};

struct ObjectTruth {
  std::string name, model;
  geometry::Pose3 world_T_object;
  int visible_pixels = 0;       // pixels showing the object (majority of their samples)
  double visible_fraction = 0;  // visible share of the pixels it would cover alone on an unbounded image
};

struct RenderResult {
  cv::Mat image;   // CV_8UC1
  cv::Mat labels;  // CV_16SC1: index into the rendered objects, -1 for background
  std::vector<ObjectTruth> objects;
};

// Built once per camera (the rays of every sample are precomputed); Render() is then const and
// may be called for every frame of a stream.
class Renderer {
 public:
  [[nodiscard]] static Result<Renderer> Create(const vision::Camera& camera, const RenderOptions& options);

  // The same inputs and seed give a byte-identical image.
  RenderResult Render(const std::vector<RenderObject>& objects, std::uint64_t seed) const;

  const vision::Camera& camera() const { return camera_; }
  const RenderOptions& options() const { return options_; }

 private:
  Renderer(const vision::Camera& camera, const RenderOptions& options) : camera_(camera), options_(options) {}
  vision::Camera camera_;
  RenderOptions options_;
  // Per sample (row-major pixels, then ss x ss samples): normalized ray (x, y); NaN where the lens
  // model has no inverse.
  std::shared_ptr<const std::vector<Eigen::Vector2f>> rays_;
  double max_ideal_radius2_ = 0;  // squared normalized radius of the farthest image corner
};

// Each rendered object's pixels in view: the centres (u, v) of the pixels `result.labels` gives it,
// row by row, indexed as result.objects.
std::vector<std::vector<Eigen::Vector2d>> PixelsInView(const RenderResult& result);
// Of those, the pixels on the outline of each object's region: those with a 4-neighbour that is not
// the object's (or outside the image). A point set lies in a convex region when its outline does,
// also after a continuous one-to-one map such as undoing the lens: vision::ShorterModelsInView
// gives the same answer for these as for all the pixels, and undistorts far fewer.
std::vector<std::vector<Eigen::Vector2d>> OutlinePixelsInView(const RenderResult& result);

// The scene's objects: fixed objects whose top is at the table plane (z <= 1 mm) get the table's
// material, all others wood; each gets a texture seed from its name.
std::vector<RenderObject> ObjectsFromScene(const scene::Scene& scene);

// A board of `board` (inner corners) with a one-square white margin, 3 mm thick, its printed face
// on the board frame's z = 0 plane (vision::ChessboardSpec describes the frame).
RenderObject ChessboardObject(const vision::ChessboardSpec& board, const geometry::Pose3& world_T_board);

// The truth file (docs/formats/render.md).
json::Json TruthToJson(const RenderResult& result, const scene::CameraSpec& camera, std::uint64_t seed);

// PNG through OpenCV's encoder, written atomically.
[[nodiscard]] Status WritePng(const std::string& path, const cv::Mat& image);

}  // namespace teachsim::worksite
