#include "teachsim/worksite/render.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "texture.h"

namespace teachsim::worksite {

namespace {

constexpr int kTile = 16;                // px, culling tiles
constexpr float kNearDepth = 1e-3f;      // m, rays start this far in front of the camera
constexpr float kShadowEpsilon = 2e-5f;  // m, shadow rays start this far off the surface
constexpr float kInf = std::numeric_limits<float>::infinity();

struct Plane {  // n . p = d, camera frame
  float nx, ny, nz, d;
};

struct Part {
  int object = 0;
  int first_face = 0, face_count = 0;
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();  // bounding sphere, camera frame
  float radius = 0;
  int x0 = 0, y0 = 0, x1 = -1, y1 = -1;  // pixel bounds (inclusive)
  // Texture frame: the part's own frame (part_T_camera), so each piece of a frame has its own grain
  // along its longest side.
  Eigen::Matrix3f part_R_camera = Eigen::Matrix3f::Identity();
  Eigen::Vector3f part_t_camera = Eigen::Vector3f::Zero();
  int grain_axis = 0;
  float ring_u = 0, ring_v = 0;
  std::uint32_t seed = 0;
};

struct Object {
  Eigen::Matrix3f object_R_camera;
  Eigen::Vector3f object_t_camera;  // object_T_camera
  Material material = Material::kWood;
  float albedo = 0.6f;
  vision::ChessboardSpec board;
  bool near_border = false;  // its projection reaches the image border or beyond
  bool behind_camera = false;
};

struct Prepared {
  std::vector<Plane> planes;
  std::vector<Part> parts;
  std::vector<Object> objects;
  int tiles_x = 0;
  std::vector<std::vector<int>> tile_parts;  // per kTile x kTile tile, row-major
};

// SplitMix64: a small, fully specified generator, so the noise is the same on every platform.
struct SplitMix64 {
  std::uint64_t state;
  std::uint64_t Next() {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double Uniform() { return (static_cast<double>(Next() >> 11) + 0.5) * (1.0 / 9007199254740992.0); }
};

std::uint32_t NameSeed(const std::string& name) {
  std::uint32_t h = 2166136261u;  // FNV-1a
  for (unsigned char c : name) h = (h ^ c) * 16777619u;
  return h;
}

// Nearest entry into a convex part along p = t (x, y, 1); t is the depth. -1 when missed.
inline int EnterFace(const Plane* planes, int count, float x, float y, float* t_enter, float* t_exit_out) {
  float t_in = kNearDepth, t_out = kInf;
  int face = -1;
  for (int f = 0; f < count; ++f) {
    const Plane& p = planes[f];
    const float nd = p.nx * x + p.ny * y + p.nz;
    if (nd < 0) {
      const float t = p.d / nd;
      if (t > t_in) {
        t_in = t;
        face = f;
      }
    } else if (nd > 0) {
      const float t = p.d / nd;
      if (t < t_out) t_out = t;
    } else if (p.d < 0) {
      return -1;
    }
    if (t_in > t_out) return -1;
  }
  *t_enter = t_in;
  *t_exit_out = t_out;
  return face;
}

// Does the ray from `o` along unit `l` pass through the part?
inline bool Blocks(const Plane* planes, int count, const Eigen::Vector3f& o, const Eigen::Vector3f& l) {
  float t_in = kShadowEpsilon, t_out = kInf;
  for (int f = 0; f < count; ++f) {
    const Plane& p = planes[f];
    const float nd = p.nx * l.x() + p.ny * l.y() + p.nz * l.z();
    const float num = p.d - (p.nx * o.x() + p.ny * o.y() + p.nz * o.z());
    if (nd < 0) {
      t_in = std::max(t_in, num / nd);
    } else if (nd > 0) {
      t_out = std::min(t_out, num / nd);
    } else if (num < 0) {
      return false;
    }
    if (t_in >= t_out) return false;
  }
  return true;
}

float ChessboardAlbedo(const vision::ChessboardSpec& board, float x, float y) {
  const float s = static_cast<float>(board.square_m);
  // Squares span [-s, cols s] x [-s, rows s]; the margin beyond is white.
  if (x < -s || y < -s || x > board.cols * s || y > board.rows * s) return 0.85f;
  const int i = static_cast<int>(std::floor(x / s)) + 1, j = static_cast<int>(std::floor(y / s)) + 1;
  return ((i + j) % 2 == 0) ? 0.06f : 0.85f;
}

// Planes, bounding spheres, pixel bounds and texture frames of every part, in the camera frame;
// the parts that may cover each tile.
Prepared Prepare(const std::vector<RenderObject>& objects, const vision::Camera& camera,
                 double max_ideal_radius2) {
  const int w = camera.width(), h = camera.height();
  const geometry::Pose3& camera_T_world = camera.camera_T_world();
  Prepared prep;
  for (std::size_t oi = 0; oi < objects.size(); ++oi) {
    const RenderObject& ro = objects[oi];
    const geometry::Pose3 camera_T_object = camera_T_world * ro.world_T_object;
    const geometry::Pose3 object_T_camera = camera_T_object.Inverse();
    Object obj;
    obj.object_R_camera = object_T_camera.RotationMatrix().cast<float>();
    obj.object_t_camera = object_T_camera.translation.cast<float>();
    obj.material = ro.material;
    obj.albedo = static_cast<float>(ro.albedo);
    obj.board = ro.board;

    for (const geometry::ShapePart& part : ro.parts) {
      const geometry::Pose3 camera_T_part = camera_T_object * part.shape_T_part;
      Part p;
      p.object = static_cast<int>(oi);
      p.first_face = static_cast<int>(prep.planes.size());
      const Eigen::Matrix3d r = camera_T_part.RotationMatrix();
      for (const geometry::Face& face : part.convex->faces()) {
        const Eigen::Vector3d n = r * face.normal;
        const double d = face.offset + n.dot(camera_T_part.translation);
        prep.planes.push_back({static_cast<float>(n.x()), static_cast<float>(n.y()),
                               static_cast<float>(n.z()), static_cast<float>(d)});
      }
      p.face_count = static_cast<int>(part.convex->faces().size());
      // The grain runs along the part's longest side; ring centres sit off the piece, per piece.
      const geometry::Pose3 part_T_camera = camera_T_part.Inverse();
      p.part_R_camera = part_T_camera.RotationMatrix().cast<float>();
      p.part_t_camera = part_T_camera.translation.cast<float>();
      part.convex->local_bounds().Size().maxCoeff(&p.grain_axis);
      p.seed = ro.texture_seed + 977u * static_cast<std::uint32_t>(prep.parts.size());
      p.ring_u = (internal::HashUnit(1, 2, 3, p.seed) - 0.5f) * 0.09f;
      p.ring_v = (internal::HashUnit(4, 5, 6, p.seed) - 0.5f) * 0.09f;
      // Bounds: vertices and points along the edges (edges curve under distortion).
      std::vector<Eigen::Vector3d> points;
      for (const Eigen::Vector3d& v : part.convex->vertices()) points.push_back(camera_T_part * v);
      Eigen::Vector3d centre = Eigen::Vector3d::Zero();
      for (const Eigen::Vector3d& q : points) centre += q;
      centre /= static_cast<double>(points.size());
      double radius = 0;
      for (const Eigen::Vector3d& q : points) radius = std::max(radius, (q - centre).norm());
      p.centre = centre.cast<float>();
      p.radius = static_cast<float>(radius * 1.0001 + 1e-6);
      for (const geometry::Edge& e : part.convex->edges()) {
        for (int i = 1; i < 8; ++i)
          points.push_back(points[e.v0] + (points[e.v1] - points[e.v0]) * (i / 8.0));
      }
      bool full = false;
      double umin = 1e18, umax = -1e18, vmin = 1e18, vmax = -1e18;
      for (const Eigen::Vector3d& q : points) {
        if (q.z() <= kNearDepth) {
          full = true;
          obj.behind_camera = true;
          break;
        }
        const Eigen::Vector2d n = q.head<2>() / q.z();
        if (n.squaredNorm() > max_ideal_radius2) {
          full = true;  // outside the field of view, where the lens polynomial may fold back
          break;
        }
        const Eigen::Vector2d px = camera.NormalizedToPixel(n);
        umin = std::min(umin, px.x());
        umax = std::max(umax, px.x());
        vmin = std::min(vmin, px.y());
        vmax = std::max(vmax, px.y());
      }
      if (full) {
        p.x0 = 0;
        p.y0 = 0;
        p.x1 = w - 1;
        p.y1 = h - 1;
        obj.near_border = true;
      } else {
        const double margin = 2.0;
        if (umin - margin < 0 || vmin - margin < 0 || umax + margin > w - 1 || vmax + margin > h - 1) {
          obj.near_border = true;
        }
        p.x0 = std::max(0, static_cast<int>(std::floor(umin - margin)));
        p.y0 = std::max(0, static_cast<int>(std::floor(vmin - margin)));
        p.x1 = std::min(w - 1, static_cast<int>(std::ceil(umax + margin)));
        p.y1 = std::min(h - 1, static_cast<int>(std::ceil(vmax + margin)));
      }
      prep.parts.push_back(p);
    }
    prep.objects.push_back(obj);
  }

  // Tiles: which parts may cover each 16x16 block of pixels.
  prep.tiles_x = (w + kTile - 1) / kTile;
  const int tiles_y = (h + kTile - 1) / kTile;
  prep.tile_parts.resize(static_cast<std::size_t>(prep.tiles_x * tiles_y));
  for (std::size_t pi = 0; pi < prep.parts.size(); ++pi) {
    const Part& p = prep.parts[pi];
    if (p.x1 < p.x0 || p.y1 < p.y0) continue;
    for (int ty = p.y0 / kTile; ty <= p.y1 / kTile; ++ty) {
      for (int tx = p.x0 / kTile; tx <= p.x1 / kTile; ++tx) {
        prep.tile_parts[static_cast<std::size_t>(ty * prep.tiles_x + tx)].push_back(static_cast<int>(pi));
      }
    }
  }

  return prep;
}

// Optics and sensor: gain, blur, Gaussian noise from the seed, rounding to 8 bits.
// `gamma` is the camera's response (vision::Camera::gamma): the light, blended and blurred
// linearly, is encoded as 255 (E / 255)^(1 / gamma) before the sensor noise.
cv::Mat Expose(const cv::Mat& radiance, const RenderOptions& options, double gamma, std::uint64_t seed) {
  cv::Mat gray = radiance * options.gain;
  if (options.blur_sigma_px > 0) {
    cv::GaussianBlur(gray, gray, cv::Size(0, 0), options.blur_sigma_px, options.blur_sigma_px,
                     cv::BORDER_REFLECT);
  }
  if (gamma != 1.0) {
    const float exponent = static_cast<float>(1.0 / gamma);
    for (int v = 0; v < gray.rows; ++v) {
      float* row = gray.ptr<float>(v);
      for (int u = 0; u < gray.cols; ++u)
        row[u] = 255.0f * std::pow(std::clamp(row[u] / 255.0f, 0.0f, 1.0f), exponent);
    }
  }
  cv::Mat image(radiance.rows, radiance.cols, CV_8UC1);
  SplitMix64 rng{seed};
  const double sigma = options.noise_sigma;
  for (int v = 0; v < radiance.rows; ++v) {
    const float* in = gray.ptr<float>(v);
    std::uint8_t* out = image.ptr<std::uint8_t>(v);
    for (int u = 0; u < radiance.cols; u += 2) {
      double n0 = 0, n1 = 0;
      if (sigma > 0) {
        // Box-Muller: two normal deviates per pair of uniforms.
        const double r = std::sqrt(-2.0 * std::log(rng.Uniform())), a = 6.283185307179586 * rng.Uniform();
        n0 = sigma * r * std::cos(a);
        n1 = sigma * r * std::sin(a);
      }
      out[u] = static_cast<std::uint8_t>(std::clamp(std::lround(in[u] + n0), 0L, 255L));
      if (u + 1 < radiance.cols)
        out[u + 1] = static_cast<std::uint8_t>(std::clamp(std::lround(in[u + 1] + n1), 0L, 255L));
    }
  }

  return image;
}

// The share of an object's silhouette, alone, that falls on the image: sampled on the ideal
// (undistorted) image plane at about one sample per pixel.
double ShareInImage(const Prepared& prep, int object, const RenderObject& ro, const vision::Camera& camera,
                    double max_ideal_radius2) {
  const geometry::Pose3& camera_T_world = camera.camera_T_world();
  // Sample the object's silhouette alone on the ideal (undistorted) image plane, at about one
  // sample per pixel, and count the samples that fall on the real image.
  double xmin = 1e18, xmax = -1e18, ymin = 1e18, ymax = -1e18;
  std::vector<const Part*> own;
  for (const Part& part : prep.parts) {
    if (part.object != object) continue;
    own.push_back(&part);
  }
  const geometry::Pose3 camera_T_object = camera_T_world * ro.world_T_object;
  for (const geometry::ShapePart& sp : ro.parts) {
    for (const Eigen::Vector3d& vtx : sp.convex->vertices()) {
      const Eigen::Vector3d q = camera_T_object * (sp.shape_T_part * vtx);
      xmin = std::min(xmin, q.x() / q.z());
      xmax = std::max(xmax, q.x() / q.z());
      ymin = std::min(ymin, q.y() / q.z());
      ymax = std::max(ymax, q.y() / q.z());
    }
  }
  double step_x = 1.0 / camera.intrinsics().fx, step_y = 1.0 / camera.intrinsics().fy;
  const double cells = ((xmax - xmin) / step_x) * ((ymax - ymin) / step_y);
  if (cells > 1e5) {
    const double grow = std::sqrt(cells / 1e5);
    step_x *= grow;
    step_y *= grow;
  }
  long long total = 0, inside = 0;
  for (double y = ymin + step_y / 2; y < ymax; y += step_y) {
    for (double x = xmin + step_x / 2; x < xmax; x += step_x) {
      bool hit = false;
      for (const Part* part : own) {
        float t_in = 0, t_out = 0;
        if (EnterFace(&prep.planes[static_cast<std::size_t>(part->first_face)], part->face_count,
                      static_cast<float>(x), static_cast<float>(y), &t_in, &t_out) >= 0) {
          hit = true;
          break;
        }
      }
      if (!hit) continue;
      ++total;
      if (x * x + y * y <= max_ideal_radius2 && camera.InImage(camera.NormalizedToPixel({x, y}))) ++inside;
    }
  }
  return total > 0 && inside > 0 ? static_cast<double>(inside) / static_cast<double>(total) : 1.0;
}

}  // namespace

RenderOptions RenderOptions::HighContrast() {
  RenderOptions o;
  o.textures = false;
  o.shadows = false;
  o.blur_sigma_px = 0;
  o.noise_sigma = 0;
  o.ambient = 0.3;
  o.diffuse = 0.9;
  o.background = 0.0;
  return o;
}

Status RenderOptions::Validate() const {
  auto bad = [](const std::string& field, double value, const std::string& expected) {
    return Status::InvalidInput("RenderOptions::" + field + " = " + json::FormatNumber(value) + " must be " +
                                expected);
  };
  if (supersample < 1 || supersample > 8) return bad("supersample", supersample, "in [1, 8]");
  if (!light_direction_in_world.allFinite() || light_direction_in_world.norm() < 1e-9) {
    return Status::InvalidInput("RenderOptions::light_direction_in_world must be a finite non-zero vector");
  }
  if (!(light_angular_radius_rad >= 0 && light_angular_radius_rad < 0.5)) {
    return bad("light_angular_radius_rad", light_angular_radius_rad, "in [0, 0.5)");
  }
  if (!(ambient >= 0 && ambient <= 2)) return bad("ambient", ambient, "in [0, 2]");
  if (!(diffuse >= 0 && diffuse <= 2)) return bad("diffuse", diffuse, "in [0, 2]");
  if (!(background >= 0 && background <= 1)) return bad("background", background, "in [0, 1]");
  if (!(gain > 0 && gain < 1e4)) return bad("gain", gain, "in (0, 1e4)");
  if (!(blur_sigma_px >= 0 && blur_sigma_px <= 10)) return bad("blur_sigma_px", blur_sigma_px, "in [0, 10]");
  if (!(noise_sigma >= 0 && noise_sigma <= 100)) return bad("noise_sigma", noise_sigma, "in [0, 100]");
  return Status::Ok();
}

Result<Renderer> Renderer::Create(const vision::Camera& camera, const RenderOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  Renderer renderer(camera, options);
  const int ss = options.supersample, w = camera.width(), h = camera.height();
  auto rays = std::make_shared<std::vector<Eigen::Vector2f>>(static_cast<std::size_t>(w) * h * ss * ss);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const vision::Intrinsics& intrinsics = camera.intrinsics();
  // Along each row of samples (equally spaced), Newton starts from the line through the two answers
  // before: off by the curvature of the lens model only, it converges in one step where the
  // previous answer alone took three (the same root to 1e-14; bench render setup at 2x2 samples
  // 136 -> 105 ms).
  for (int v = 0; v < h; ++v) {
    for (int sy = 0; sy < ss; ++sy) {
      Eigen::Vector2d previous = Eigen::Vector2d::Zero(), before = Eigen::Vector2d::Zero();
      int answered = 0;  // answers in a row just before this sample (0, 1, or 2 for both)
      for (int u = 0; u < w; ++u) {
        for (int sx = 0; sx < ss; ++sx) {
          // Sample offsets (i + 0.5) / ss - 0.5 about the pixel centre (pixel centres at integers).
          const Eigen::Vector2d pixel(u + (sx + 0.5) / ss - 0.5, v + (sy + 0.5) / ss - 0.5);
          const Eigen::Vector2d distorted((pixel.x() - intrinsics.cx) / intrinsics.fx,
                                          (pixel.y() - intrinsics.cy) / intrinsics.fy);
          const std::optional<Eigen::Vector2d> n =
              answered == 2   ? camera.Undistort(distorted, 2 * previous - before)
              : answered == 1 ? camera.Undistort(distorted, previous)
                              : camera.Undistort(distorted);
          if (n) {
            before = previous;
            previous = *n;
            answered = std::min(answered + 1, 2);
          } else {
            answered = 0;
          }
          const std::size_t k = ((static_cast<std::size_t>(v) * w + u) * ss + sy) * ss + sx;
          (*rays)[k] = n ? n->cast<float>() : Eigen::Vector2f(nan, nan);
        }
      }
    }
  }
  renderer.rays_ = std::move(rays);
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(w - 0.5, -0.5),
                                        Eigen::Vector2d(-0.5, h - 0.5), Eigen::Vector2d(w - 0.5, h - 0.5)}) {
    if (auto n = camera.PixelToNormalized(corner)) {
      renderer.max_ideal_radius2_ = std::max(renderer.max_ideal_radius2_, n->squaredNorm());
    } else {
      return Status::InvalidInput("camera: the lens model has no inverse at the image corner (" +
                                  json::FormatNumber(corner.x()) + ", " + json::FormatNumber(corner.y()) +
                                  "); check k1 k2 k3");
    }
  }
  return renderer;
}

RenderResult Renderer::Render(const std::vector<RenderObject>& objects, std::uint64_t seed) const {
  const int w = camera_.width(), h = camera_.height(), ss = options_.supersample;
  const int samples_per_pixel = ss * ss;
  const geometry::Pose3& camera_T_world = camera_.camera_T_world();

  const Prepared prep = Prepare(objects, camera_, max_ideal_radius2_);
  const int num_objects = static_cast<int>(prep.objects.size());
  const int tiles_x = prep.tiles_x;
  const std::vector<std::vector<int>>& tile_parts = prep.tile_parts;

  // --- Light: direction in the camera frame and a basis across it for the disc's samples.
  const Eigen::Vector3f light =
      camera_T_world.Rotate(options_.light_direction_in_world.normalized()).cast<float>();
  const Eigen::Vector3f e1 = light.unitOrthogonal();
  const Eigen::Vector3f e2 = light.cross(e1);
  const float light_radius = static_cast<float>(std::tan(options_.light_angular_radius_rad));
  // Points on the light's disc: per pixel one of kPatterns rotations of a golden-angle spiral with
  // one point per sample (stratified over the pixel's samples), directions precomputed.
  constexpr int kPatterns = 32;
  std::vector<Eigen::Vector3f> light_samples(static_cast<std::size_t>(kPatterns * samples_per_pixel));
  for (int k = 0; k < kPatterns; ++k) {
    for (int s = 0; s < samples_per_pixel; ++s) {
      const float radial = light_radius * std::sqrt((static_cast<float>(s) + 0.5f) / samples_per_pixel);
      const float angle =
          6.2831853f * static_cast<float>(k) / kPatterns + 2.39996323f * static_cast<float>(s);
      light_samples[static_cast<std::size_t>(k * samples_per_pixel + s)] =
          (light + radial * (std::cos(angle) * e1 + std::sin(angle) * e2)).normalized();
    }
  }
  const float ambient = static_cast<float>(options_.ambient), diffuse = static_cast<float>(options_.diffuse);
  const float background = static_cast<float>(options_.background);

  // --- Cast.
  cv::Mat radiance(h, w, CV_32FC1);
  RenderResult result;
  result.labels = cv::Mat(h, w, CV_16SC1);
  std::vector<int> unoccluded_pixels(static_cast<std::size_t>(num_objects), 0);
  std::vector<int> label_count(static_cast<std::size_t>(num_objects) + 1);
  std::vector<int> any_count(static_cast<std::size_t>(num_objects));
  std::vector<std::uint64_t> any_stamp(static_cast<std::size_t>(num_objects), 0);
  const Eigen::Vector2f* rays = rays_->data();
  std::uint64_t stamp = 0;
  const float inv_samples = 1.0f / static_cast<float>(samples_per_pixel);
  for (int v = 0; v < h; ++v) {
    float* out_row = radiance.ptr<float>(v);
    std::int16_t* label_row = result.labels.ptr<std::int16_t>(v);
    for (int u = 0; u < w; ++u) {
      const std::vector<int>& candidates =
          tile_parts[static_cast<std::size_t>((v / kTile) * tiles_x + u / kTile)];
      std::fill(label_count.begin(), label_count.end(), 0);
      for (int part_index : candidates)
        any_count[static_cast<std::size_t>(prep.parts[part_index].object)] = 0;
      const Eigen::Vector3f* pixel_light =
          &light_samples[static_cast<std::size_t>((internal::Hash3(u, v, 0, 0x5EEDu) >> 8) % kPatterns) *
                         static_cast<std::size_t>(samples_per_pixel)];
      float sum = 0;
      int cached_part = -1;
      float cached_albedo = 0;
      const Eigen::Vector2f* ray = rays + (static_cast<std::size_t>(v) * w + u) * samples_per_pixel;
      for (int s = 0; s < samples_per_pixel; ++s, ++ray) {
        ++stamp;
        const float x = ray->x(), y = ray->y();
        float best_t = kInf;
        int best_part = -1, best_face = -1;
        if (!std::isnan(x)) {
          for (int part_index : candidates) {
            const Part& part = prep.parts[static_cast<std::size_t>(part_index)];
            float t_in = 0, t_out = 0;
            const int face = EnterFace(&prep.planes[static_cast<std::size_t>(part.first_face)],
                                       part.face_count, x, y, &t_in, &t_out);
            if (face < 0) continue;
            auto& st = any_stamp[static_cast<std::size_t>(part.object)];
            if (st != stamp) {
              st = stamp;
              ++any_count[static_cast<std::size_t>(part.object)];
            }
            if (t_in < best_t) {
              best_t = t_in;
              best_part = part_index;
              best_face = part.first_face + face;
            }
          }
        }
        if (best_part < 0) {
          sum += background;
          ++label_count[0];
          continue;
        }
        const Part& part = prep.parts[static_cast<std::size_t>(best_part)];
        const Object& obj = prep.objects[static_cast<std::size_t>(part.object)];
        ++label_count[static_cast<std::size_t>(part.object) + 1];
        const Plane& plane = prep.planes[static_cast<std::size_t>(best_face)];
        const Eigen::Vector3f normal(plane.nx, plane.ny, plane.nz);
        const Eigen::Vector3f p = best_t * Eigen::Vector3f(x, y, 1.0f);
        float lambert = std::max(0.0f, normal.dot(light));
        if (lambert > 0 && options_.shadows) {
          const Eigen::Vector3f& l = pixel_light[s];
          const Eigen::Vector3f origin = p + normal * kShadowEpsilon;
          for (std::size_t qi = 0; qi < prep.parts.size(); ++qi) {
            if (static_cast<int>(qi) == best_part) continue;
            const Part& q = prep.parts[qi];
            const Eigen::Vector3f to_centre = q.centre - origin;
            const float along = to_centre.dot(l);
            if (along < -q.radius) continue;
            if (to_centre.squaredNorm() - along * along > q.radius * q.radius) continue;
            if (Blocks(&prep.planes[static_cast<std::size_t>(q.first_face)], q.face_count, origin, l)) {
              lambert = 0;
              break;
            }
          }
        }
        float albedo = obj.albedo;
        if (obj.material != Material::kChessboard && best_part == cached_part) {
          albedo = cached_albedo;  // wood and table vary little within a pixel: one look-up per pixel
        } else if (options_.textures || obj.material == Material::kChessboard) {
          const Eigen::Vector3f p_obj = obj.object_R_camera * p + obj.object_t_camera;
          switch (obj.material) {
            case Material::kWood: {
              const Eigen::Vector3f p_part = part.part_R_camera * p + part.part_t_camera;
              const int a = part.grain_axis, b = (a + 1) % 3, c = (a + 2) % 3;
              albedo *=
                  internal::WoodFactor(p_part[a], p_part[b], p_part[c], part.ring_u, part.ring_v, part.seed);
              break;
            }
            case Material::kTable:
              albedo *= internal::TableFactor(p_obj.x(), p_obj.y(), part.seed);
              break;
            case Material::kChessboard: {
              const Eigen::Vector3f n_obj = obj.object_R_camera * normal;
              albedo = n_obj.z() < -0.5f ? ChessboardAlbedo(obj.board, p_obj.x(), p_obj.y()) : 0.5f;
              break;
            }
            case Material::kFlat:
              break;
          }
          cached_part = best_part;
          cached_albedo = albedo;
        }
        sum += albedo * (ambient + diffuse * lambert);
      }
      out_row[u] = sum * inv_samples;
      // The pixel's label: the majority of its samples (ties to the lower index).
      int best_label = 0;
      for (std::size_t l = 1; l < label_count.size(); ++l) {
        if (label_count[l] > label_count[static_cast<std::size_t>(best_label)])
          best_label = static_cast<int>(l);
      }
      label_row[u] = static_cast<std::int16_t>(best_label - 1);
      for (int part_index : candidates) {
        const int o = prep.parts[static_cast<std::size_t>(part_index)].object;
        if (any_count[static_cast<std::size_t>(o)] * 2 > samples_per_pixel) {
          ++unoccluded_pixels[static_cast<std::size_t>(o)];
          any_count[static_cast<std::size_t>(o)] = 0;  // count each object once per pixel
        }
      }
    }
  }

  result.image = Expose(radiance, options_, camera_.gamma(), seed);

  // --- Truth: visible pixels and visible fraction per object.
  std::vector<int> visible(static_cast<std::size_t>(num_objects), 0);
  for (int v = 0; v < h; ++v) {
    const std::int16_t* row = result.labels.ptr<std::int16_t>(v);
    for (int u = 0; u < w; ++u) {
      if (row[u] >= 0) ++visible[static_cast<std::size_t>(row[u])];
    }
  }
  for (int oi = 0; oi < num_objects; ++oi) {
    const Object& obj = prep.objects[static_cast<std::size_t>(oi)];
    ObjectTruth truth;
    truth.name = objects[static_cast<std::size_t>(oi)].name;
    truth.model = objects[static_cast<std::size_t>(oi)].model;
    truth.world_T_object = objects[static_cast<std::size_t>(oi)].world_T_object;
    truth.visible_pixels = visible[static_cast<std::size_t>(oi)];
    const int in_image = unoccluded_pixels[static_cast<std::size_t>(oi)];
    double share_in_image = 1.0;  // of the object's silhouette, measured in the ideal image plane
    if (obj.near_border && !obj.behind_camera && in_image > 0) {
      share_in_image =
          ShareInImage(prep, oi, objects[static_cast<std::size_t>(oi)], camera_, max_ideal_radius2_);
    }
    truth.visible_fraction =
        in_image > 0 ? std::min(1.0, truth.visible_pixels * share_in_image / static_cast<double>(in_image))
                     : 0.0;
    result.objects.push_back(std::move(truth));
  }
  return result;
}

std::vector<std::vector<Eigen::Vector2d>> PixelsInView(const RenderResult& result) {
  std::vector<std::vector<Eigen::Vector2d>> out(result.objects.size());
  for (int v = 0; v < result.labels.rows; ++v) {
    const std::int16_t* row = result.labels.ptr<std::int16_t>(v);
    for (int u = 0; u < result.labels.cols; ++u) {
      if (row[u] >= 0 && static_cast<std::size_t>(row[u]) < out.size())
        out[static_cast<std::size_t>(row[u])].emplace_back(u, v);
    }
  }
  return out;
}

std::vector<std::vector<Eigen::Vector2d>> OutlinePixelsInView(const RenderResult& result) {
  std::vector<std::vector<Eigen::Vector2d>> out(result.objects.size());
  const cv::Mat& labels = result.labels;
  auto label = [&](int u, int v) -> int {
    return u < 0 || v < 0 || u >= labels.cols || v >= labels.rows ? -1 : labels.at<std::int16_t>(v, u);
  };
  for (int v = 0; v < labels.rows; ++v) {
    for (int u = 0; u < labels.cols; ++u) {
      const int own = label(u, v);
      if (own < 0 || static_cast<std::size_t>(own) >= out.size()) continue;
      if (label(u - 1, v) != own || label(u + 1, v) != own || label(u, v - 1) != own ||
          label(u, v + 1) != own)
        out[static_cast<std::size_t>(own)].emplace_back(u, v);
    }
  }
  return out;
}

std::vector<RenderObject> ObjectsFromScene(const scene::Scene& scene) {
  std::vector<RenderObject> out;
  for (const scene::SceneObject& o : scene.objects) {
    RenderObject ro;
    ro.name = o.name;
    ro.model = o.model;
    ro.parts = o.shape.parts();
    ro.world_T_object = o.world_T_object;
    ro.texture_seed = NameSeed(o.name);
    const geometry::Aabb bounds = o.shape.WorldBounds(o.world_T_object);
    if (o.fixed && bounds.max.z() <= 1e-3) {
      ro.material = Material::kTable;
      ro.albedo = 0.78;
    } else {
      ro.material = Material::kWood;
      ro.albedo = 0.62;
    }
    out.push_back(std::move(ro));
  }
  return out;
}

RenderObject ChessboardObject(const vision::ChessboardSpec& board, const geometry::Pose3& world_T_board) {
  const double s = board.square_m, thickness = 0.003;
  // Squares span [-s, cols s] x [-s, rows s]; one more square of white margin around them.
  const Eigen::Vector3d size((board.cols + 3) * s, (board.rows + 3) * s, thickness);
  const Eigen::Vector3d centre((board.cols - 1) * s / 2, (board.rows - 1) * s / 2, thickness / 2);
  auto box = geometry::ConvexPolyhedron::Box(size);
  TEACHSIM_CHECK_MSG(box.ok(), "chessboard size must be positive");
  RenderObject ro;
  ro.name = "chessboard";
  ro.model = "chessboard";
  ro.parts.push_back({std::make_shared<const geometry::ConvexPolyhedron>(std::move(*box)),
                      geometry::Pose3::Translation(centre)});
  ro.world_T_object = world_T_board;
  ro.material = Material::kChessboard;
  ro.board = board;
  return ro;
}

json::Json TruthToJson(const RenderResult& result, const scene::CameraSpec& camera, std::uint64_t seed) {
  json::Json objects = json::Json::array();
  for (const ObjectTruth& o : result.objects) {
    const json::Json pose = geometry::WritePose(o.world_T_object);
    json::Json entry{{"name", o.name}};
    if (!o.model.empty()) entry["model"] = o.model;
    entry["position"] = pose["position"];
    entry["quaternion_wxyz"] = pose["quaternion_wxyz"];
    entry["visible_fraction"] = o.visible_fraction;
    entry["visible_pixels"] = o.visible_pixels;
    objects.push_back(std::move(entry));
  }
  return {{"camera", scene::WriteCamera(camera)}, {"seed", seed}, {"objects", objects}};
}

Status WritePng(const std::string& path, const cv::Mat& image) {
  std::vector<std::uint8_t> bytes;
  try {
    if (!cv::imencode(".png", image, bytes)) return Status::IoError(path + ": PNG encoding failed");
  } catch (const cv::Exception& e) {
    return Status::IoError(path + ": PNG encoding failed: " + e.what());
  }
  return json::WriteFileAtomic(path,
                               std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

}  // namespace teachsim::worksite
