#include "linemod_peer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "teachsim/base/binary_io.h"
#include "teachsim/base/json.h"
#include "teachsim/worksite/render.h"

namespace teachsim::worksite {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr char kCacheMagic[] = "teachsim-linemod-templates-1";

// FNV-1a: a hash that is the same in every build (std::hash need not be).
std::uint64_t Fnv1a(const std::string& text) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

// Viewing directions (object to camera, object frame) on the quarter sphere y >= 0, z >= 0: a box
// seen from any other direction looks as from one of these after a half turn about one of its axes.
std::vector<Eigen::Vector3d> QuarterSphereViews(double step_deg) {
  const double step = step_deg * kPi / 180;
  const int n_full = std::max(8, static_cast<int>(std::lround(4 * kPi / (step * step))));
  const double golden = kPi * (3 - std::sqrt(5.0));
  std::vector<Eigen::Vector3d> views;
  for (int i = 0; i < n_full; ++i) {
    const double z = 1 - (2.0 * i + 1) / n_full;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const Eigen::Vector3d v(r * std::cos(golden * i), r * std::sin(golden * i), z);
    if (v.y() >= 0 && v.z() >= 0) views.push_back(v);
  }
  return views;
}

// camera_R_object for a camera on `view` (object frame) looking at the object's centre.
Eigen::Quaterniond LookAtObject(const Eigen::Vector3d& view) {
  const Eigen::Vector3d z = -view.normalized();
  const Eigen::Vector3d hint = std::abs(z.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d x = hint.cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d object_R_camera;
  object_R_camera << x, y, z;
  return Eigen::Quaterniond(object_R_camera.transpose());
}

using binary::Get;
using binary::Put;

}  // namespace

Status LinemodOptions::Validate() const {
  if (!(template_focal_px > 0)) return Status::InvalidInput("LinemodOptions::template_focal_px must be > 0");
  if (distances_m.empty()) return Status::InvalidInput("LinemodOptions::distances_m must not be empty");
  for (double d : distances_m) {
    if (!(d > 0.2)) return Status::InvalidInput("LinemodOptions::distances_m: " + json::FormatNumber(d) + " must be > 0.2");
  }
  if (!(view_step_deg >= 2 && view_step_deg <= 90)) {
    return Status::InvalidInput("LinemodOptions::view_step_deg must be in [2, 90]");
  }
  if (!(in_plane_step_deg >= 1 && in_plane_step_deg <= 360)) {
    return Status::InvalidInput("LinemodOptions::in_plane_step_deg must be in [1, 360]");
  }
  if (num_features < 8 || num_features > 63) {
    return Status::InvalidInput(
        "LinemodOptions::num_features must be in [8, 63] (LINE-MOD matches 63 at most)");
  }
  if (pyramid_t.empty()) return Status::InvalidInput("LinemodOptions::pyramid_t must not be empty");
  if (!(match_threshold > 0 && match_threshold <= 100)) {
    return Status::InvalidInput("LinemodOptions::match_threshold must be in (0, 100]");
  }
  if (max_detections < 1) return Status::InvalidInput("LinemodOptions::max_detections must be >= 1");
  return Status::Ok();
}

std::string LinemodOptions::TemplateKey() const {
  std::ostringstream key;
  key.precision(17);
  key << "f" << template_focal_px << " d";
  for (double d : distances_m) key << d << ",";
  key << " v" << view_step_deg << " r" << in_plane_step_deg << " w" << weak_threshold << " s" << strong_threshold
      << " n" << num_features << " t";
  for (int t : pyramid_t) key << t << ",";
  return key.str();
}

cv::Mat UndistortImage(const cv::Mat& image, const vision::Camera& camera) {
  if (camera.distortion().IsZero()) return image;
  cv::Mat map_x(image.rows, image.cols, CV_32FC1), map_y(image.rows, image.cols, CV_32FC1);
  for (int v = 0; v < image.rows; ++v) {
    float* mx = map_x.ptr<float>(v);
    float* my = map_y.ptr<float>(v);
    for (int u = 0; u < image.cols; ++u) {
      const Eigen::Vector2d pixel = camera.DistortPixel(Eigen::Vector2d(u, v));
      mx[u] = static_cast<float>(pixel.x());
      my[u] = static_cast<float>(pixel.y());
    }
  }
  cv::Mat out;
  cv::remap(image, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return out;
}

Result<LinemodPeer> LinemodPeer::Create(const std::map<std::string, Eigen::Vector3d>& model_sizes_m,
                                        const LinemodOptions& options, const std::string& cache_dir) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  const auto t0 = std::chrono::steady_clock::now();
  LinemodPeer peer;
  peer.options_ = options;
  std::vector<cv::Ptr<cv::linemod::Modality>> modalities = {cv::linemod::ColorGradient::create(
      options.weak_threshold, static_cast<size_t>(options.num_features), options.strong_threshold)};
  peer.detector_ = cv::makePtr<cv::linemod::Detector>(modalities, options.pyramid_t);

  std::ostringstream models_key;
  models_key.precision(17);
  for (const auto& [name, size] : model_sizes_m) models_key << name << ":" << size.transpose() << ";";
  const std::string key = options.TemplateKey() + " | " + models_key.str();
  std::string cache_path;
  if (!cache_dir.empty()) {
    char name[64];
    std::snprintf(name, sizeof(name), "linemod_%016llx.bin", static_cast<unsigned long long>(Fnv1a(key)));
    cache_path = (std::filesystem::path(cache_dir) / name).string();
  }

  // --- From the cache. A file is used only as far as it holds together: the key, the library's
  // model names, unit rotations and finite numbers, the detector's pyramid levels, template sizes
  // and feature counts in bounds, each feature inside its template with one of the 8 orientation
  // labels. Anything else (a damaged file) and the templates are made afresh.
  if (!cache_path.empty() && std::filesystem::exists(cache_path)) {
    // LINE-MOD matches a template of at most 63 features (cv::linemod's similarity asserts it).
    constexpr std::int32_t kMaxTemplateSide = 4096, kMaxFeatures = 63;
    constexpr std::uint32_t kMaxTemplates = 1u << 20;
    std::ifstream in(cache_path, std::ios::binary);
    std::string magic(sizeof(kCacheMagic), '\0'), stored_key;
    std::uint32_t key_size = 0, classes = 0;
    bool ok = in.read(magic.data(), static_cast<std::streamsize>(magic.size())) &&
              std::memcmp(magic.data(), kCacheMagic, sizeof(kCacheMagic)) == 0 && Get(in, &key_size) &&
              key_size == key.size();
    if (ok) {
      stored_key.resize(key_size);
      ok = in.read(stored_key.data(), key_size) && stored_key == key && Get(in, &classes) &&
           classes == model_sizes_m.size();  // every model has its templates (the writer writes all)
    }
    for (std::uint32_t c = 0; ok && c < classes; ++c) {
      std::uint32_t name_size = 0, count = 0;
      ok = Get(in, &name_size) && name_size <= 256;
      std::string class_id(ok ? name_size : 0, '\0');
      ok = ok && in.read(class_id.data(), name_size) && model_sizes_m.count(class_id) > 0 &&
           peer.info_.count(class_id) == 0 && Get(in, &count) && count <= kMaxTemplates;
      for (std::uint32_t t = 0; ok && t < count; ++t) {
        TemplateInfo info;
        double v[10];
        ok = in.read(reinterpret_cast<char*>(v), sizeof(v)).good() &&
             Eigen::Map<Eigen::Matrix<double, 10, 1>>(v).allFinite();
        const Eigen::Quaterniond rotation(v[0], v[1], v[2], v[3]);
        ok = ok && std::abs(rotation.norm() - 1) < 1e-9 && v[9] > 0;
        info.camera_T_object = geometry::Pose3(rotation, {v[4], v[5], v[6]});
        info.centre_offset_px = {v[7], v[8]};
        info.size_px = v[9];
        std::uint32_t levels = 0;
        ok = ok && Get(in, &levels) && levels == options.pyramid_t.size();
        std::vector<cv::linemod::Template> pyramid(ok ? levels : 0);
        for (std::size_t l = 0; l < pyramid.size() && ok; ++l) {
          cv::linemod::Template& level = pyramid[l];
          std::int32_t header[4];
          ok = in.read(reinterpret_cast<char*>(header), sizeof(header)).good() && header[0] >= 0 &&
               header[0] <= kMaxTemplateSide && header[1] >= 0 && header[1] <= kMaxTemplateSide &&
               header[2] == static_cast<std::int32_t>(l) && header[3] >= 0 && header[3] <= kMaxFeatures;
          if (!ok) break;
          level.width = header[0];
          level.height = header[1];
          level.pyramid_level = header[2];
          level.features.resize(static_cast<std::size_t>(header[3]));
          for (cv::linemod::Feature& f : level.features) {
            std::int32_t xyl[3];
            ok = ok && in.read(reinterpret_cast<char*>(xyl), sizeof(xyl)) && xyl[0] >= 0 &&
                 xyl[0] <= level.width && xyl[1] >= 0 && xyl[1] <= level.height && xyl[2] >= 0 && xyl[2] < 8;
            f = cv::linemod::Feature(xyl[0], xyl[1], xyl[2]);
          }
        }
        if (!ok) break;
        const int id = peer.detector_->addSyntheticTemplate(pyramid, class_id);
        ok = id == static_cast<int>(peer.info_[class_id].size());
        peer.info_[class_id].push_back(info);
      }
    }
    if (ok) {
      peer.loaded_from_cache_ = true;
      peer.build_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      return peer;
    }
    // A stale or damaged cache: build afresh.
    peer.detector_ = cv::makePtr<cv::linemod::Detector>(modalities, options.pyramid_t);
    peer.info_.clear();
  }

  // --- Render and extract.
  double max_radius = 0;
  for (const auto& [name, size] : model_sizes_m) max_radius = std::max(max_radius, size.norm() / 2);
  const double nearest = *std::min_element(options.distances_m.begin(), options.distances_m.end());
  if (nearest <= 1.5 * max_radius) return Status::InvalidInput("LinemodOptions::distances_m: too near for the models");
  const int half = static_cast<int>(std::ceil(options.template_focal_px * max_radius / (nearest - max_radius))) + 12;
  const int side = 2 * half + 1;  // odd: the principal point is a pixel centre
  scene::CameraSpec spec;
  spec.width = spec.height = side;
  spec.fx = spec.fy = options.template_focal_px;
  spec.cx = spec.cy = half;
  TEACHSIM_ASSIGN_OR_RETURN(const vision::Camera camera, vision::Camera::FromSpec(spec));
  RenderOptions render;
  render.noise_sigma = 0;
  render.shadows = false;  // the object alone: nothing to cast on
  render.light_direction_in_world = Eigen::Vector3d(0.3, -0.4, -0.87).normalized();  // from the camera's side
  TEACHSIM_ASSIGN_OR_RETURN(const Renderer renderer, Renderer::Create(camera, render));

  const std::vector<Eigen::Vector3d> views = QuarterSphereViews(options.view_step_deg);
  const int in_plane_steps = std::max(1, static_cast<int>(std::lround(360.0 / options.in_plane_step_deg)));
  for (const auto& [name, size] : model_sizes_m) {
    auto box = geometry::ConvexPolyhedron::Box(size);
    if (!box.ok()) return box.status();
    RenderObject object;
    object.name = name;
    object.model = name;
    object.parts.push_back({std::make_shared<const geometry::ConvexPolyhedron>(std::move(*box)), {}});
    object.texture_seed = static_cast<std::uint32_t>(Fnv1a(name));
    std::vector<TemplateInfo>& infos = peer.info_[name];
    for (const Eigen::Vector3d& view : views) {
      const Eigen::Quaterniond camera_R_object = LookAtObject(view);
      for (double distance : options.distances_m) {
        object.world_T_object = geometry::Pose3(camera_R_object, {0, 0, distance});  // world = template camera
        const RenderResult rendered = renderer.Render({object}, 0);
        const cv::Mat mask = rendered.labels == 0;
        // A square window about the object centre (the principal point) that holds it at any rotation.
        double reach = 0;
        for (int v = 0; v < side; ++v) {
          const std::uint8_t* row = mask.ptr<std::uint8_t>(v);
          for (int u = 0; u < side; ++u) {
            if (row[u] != 0) reach = std::max(reach, std::hypot(u - half, v - half));
          }
        }
        if (reach == 0) continue;
        const int w = std::min(half, static_cast<int>(std::ceil(reach)) + 8);
        const cv::Rect window(half - w, half - w, 2 * w + 1, 2 * w + 1);
        const cv::Mat crop = rendered.image(window), crop_mask = mask(window);
        for (int step = 0; step < in_plane_steps; ++step) {
          const double angle_deg = step * 360.0 / in_plane_steps;
          // OpenCV's rotation by +a (image y down) is the camera turned by -a about its optical axis.
          const cv::Mat rotation = cv::getRotationMatrix2D(cv::Point2f(static_cast<float>(w), static_cast<float>(w)),
                                                           angle_deg, 1.0);
          cv::Mat turned, turned_mask, bgr;
          cv::warpAffine(crop, turned, rotation, crop.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
          cv::warpAffine(crop_mask, turned_mask, rotation, crop.size(), cv::INTER_NEAREST, cv::BORDER_CONSTANT, 0);
          cv::cvtColor(turned, bgr, cv::COLOR_GRAY2BGR);
          cv::Rect bounds;
          const int id = peer.detector_->addTemplate({bgr}, name, turned_mask, &bounds);
          if (id < 0) continue;
          TEACHSIM_CHECK(id == static_cast<int>(infos.size()));
          TemplateInfo info;
          const Eigen::Quaterniond turn(Eigen::AngleAxisd(-angle_deg * kPi / 180, Eigen::Vector3d::UnitZ()));
          info.camera_T_object = geometry::Pose3(turn * camera_R_object, {0, 0, distance});
          info.centre_offset_px = Eigen::Vector2d(w - bounds.x, w - bounds.y);
          info.size_px = std::min(bounds.width, bounds.height);
          infos.push_back(info);
        }
      }
    }
  }
  peer.build_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  // --- To the cache.
  if (!cache_path.empty()) {
    std::string out(kCacheMagic, sizeof(kCacheMagic));
    Put(&out, static_cast<std::uint32_t>(key.size()));
    out += key;
    Put(&out, static_cast<std::uint32_t>(peer.info_.size()));
    for (const auto& [class_id, infos] : peer.info_) {
      Put(&out, static_cast<std::uint32_t>(class_id.size()));
      out += class_id;
      Put(&out, static_cast<std::uint32_t>(infos.size()));
      for (std::size_t t = 0; t < infos.size(); ++t) {
        const TemplateInfo& info = infos[t];
        const Eigen::Quaterniond& q = info.camera_T_object.rotation;
        const Eigen::Vector3d& p = info.camera_T_object.translation;
        for (double v : {q.w(), q.x(), q.y(), q.z(), p.x(), p.y(), p.z(), info.centre_offset_px.x(),
                         info.centre_offset_px.y(), info.size_px}) {
          Put(&out, v);
        }
        const std::vector<cv::linemod::Template>& pyramid = peer.detector_->getTemplates(class_id, static_cast<int>(t));
        Put(&out, static_cast<std::uint32_t>(pyramid.size()));
        for (const cv::linemod::Template& level : pyramid) {
          for (std::int32_t v : {level.width, level.height, level.pyramid_level,
                                 static_cast<std::int32_t>(level.features.size())}) {
            Put(&out, v);
          }
          for (const cv::linemod::Feature& f : level.features) {
            for (std::int32_t v : {f.x, f.y, f.label}) Put(&out, v);
          }
        }
      }
    }
    std::error_code ec;
    std::filesystem::create_directories(cache_dir, ec);
    // A cache that cannot be written only costs the next run its set-up time.
    (void)json::WriteFileAtomic(cache_path, out);
  }
  return peer;
}

int LinemodPeer::num_templates() const { return detector_->numTemplates(); }

std::vector<LinemodDetection> LinemodPeer::Detect(const cv::Mat& image_gray8, const vision::Camera& camera) const {
  const cv::Mat ideal = UndistortImage(image_gray8, camera);
  cv::Mat bgr;
  cv::cvtColor(ideal, bgr, cv::COLOR_GRAY2BGR);
  std::vector<cv::linemod::Match> matches;
  detector_->match({bgr}, options_.match_threshold, matches);
  std::sort(matches.begin(), matches.end());  // by falling similarity

  const vision::Intrinsics& k = camera.intrinsics();
  const double focal_ratio = std::sqrt(k.fx * k.fy) / options_.template_focal_px;
  std::vector<LinemodDetection> out;
  std::vector<std::pair<Eigen::Vector2d, double>> kept;  // centre, size
  for (const cv::linemod::Match& m : matches) {
    if (static_cast<int>(out.size()) >= options_.max_detections) break;
    const auto infos = info_.find(m.class_id);
    if (infos == info_.end() || m.template_id < 0 ||
        m.template_id >= static_cast<int>(infos->second.size())) {
      continue;
    }
    const TemplateInfo& info = infos->second[static_cast<std::size_t>(m.template_id)];
    const Eigen::Vector2d centre = Eigen::Vector2d(m.x, m.y) + info.centre_offset_px;
    // Non-maximum suppression: one object per place, whatever its model.
    bool suppressed = false;
    for (const auto& [c, size] : kept) {
      if ((c - centre).norm() < options_.suppression_radius * std::min(size, info.size_px)) suppressed = true;
    }
    if (suppressed) continue;
    kept.emplace_back(centre, info.size_px);
    const Eigen::Vector3d ray =
        Eigen::Vector3d((centre.x() - k.cx) / k.fx, (centre.y() - k.cy) / k.fy, 1.0).normalized();
    const Eigen::Quaterniond onto_ray = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), ray);
    LinemodDetection d;
    d.template_id = m.template_id;
    d.camera_T_object = geometry::Pose3(onto_ray * info.camera_T_object.rotation,
                                        ray * info.camera_T_object.translation.z() * focal_ratio);
    d.detection.model = m.class_id;
    d.detection.world_T_object = camera.world_T_camera() * d.camera_T_object;
    d.detection.score = m.similarity / 100.0;
    out.push_back(std::move(d));
  }
  return out;
}

}  // namespace teachsim::worksite
