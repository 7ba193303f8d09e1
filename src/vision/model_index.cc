// The recognizer's model-view index (issue 7, item 3): see model_index.h.
#include "model_index.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <system_error>
#include <vector>

#include "teachsim/base/binary_io.h"
#include "teachsim/base/json.h"

namespace teachsim::vision {

namespace {

uint64_t Fnv(uint64_t h, const void* data, size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ULL;
  return h;
}

// Bump when the index's contents or file layout change.
constexpr uint32_t kIndexFormat = 3;

}  // namespace

uint64_t HashModelLibrary(const ModelLibrary& models) {
  uint64_t h = 14695981039346656037ULL;
  for (const Model& m : models.models) {
    h = Fnv(h, m.name.data(), m.name.size() + 1);
    h = Fnv(h, m.box_size_m.data(), sizeof(double) * 3);
  }
  return h;
}

namespace {

constexpr double kNominalFocalPx = 800;  // for the model views' 2D geometry (scale drops out)
constexpr double kMinViewAngleDeg =
    20;  // junction angles below this are not indexed (the image side accepts 15)

geometry::Pose3 LookAt(const Eigen::Vector3d& direction_from_object, double distance_m) {
  const Eigen::Vector3d z = -direction_from_object.normalized();
  Eigen::Vector3d helper = std::abs(z.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d x = helper.cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d object_R_camera;
  object_R_camera << x, y, z;
  const Eigen::Matrix3d camera_R_object = object_R_camera.transpose();
  return {Eigen::Quaterniond(camera_R_object), Eigen::Vector3d(0, 0, distance_m)};
}

void AddViewGroups(const Model& model, uint16_t model_index, uint16_t view_index,
                   const geometry::Pose3& camera_T_object, RecognizerIndex* index,
                   std::vector<float> vectors[kGroupKinds]) {
  const Eigen::Vector3d camera_in_object = camera_T_object.Inverse().translation;
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_in_object);
  Eigen::Vector2d px[8];
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d p = camera_T_object * BoxVertex(model.box_size_m, i);
    px[i] = kNominalFocalPx * p.head<2>() / p.z();
  }
  double longest = 0;
  for (int e = 0; e < 12; ++e) {
    if (visible >> e & 1) longest = std::max(longest, (px[kBoxEdges[e][0]] - px[kBoxEdges[e][1]]).norm());
  }
  // Usable edges: visible and not seen nearly end-on (the image would not show them as segments).
  bool adjacent[8][8] = {};
  for (int e = 0; e < 12; ++e) {
    const int a = kBoxEdges[e][0], b = kBoxEdges[e][1];
    if ((visible >> e & 1) && (px[a] - px[b]).norm() >= 0.15 * longest)
      adjacent[a][b] = adjacent[b][a] = true;
  }
  const double min_sin = std::sin(kMinViewAngleDeg * M_PI / 180);
  auto good_corner = [&](int a, int b, int c) {  // lines a-b and b-c meet at an angle
    const Eigen::Vector2d u = (px[a] - px[b]).normalized(), v = (px[c] - px[b]).normalized();
    return std::abs(u.x() * v.y() - u.y() * v.x()) >= min_sin;
  };
  auto add = [&](GroupKind kind, const int* verts, int count) {
    Group g;
    g.kind = kind;
    IndexEntry entry;
    entry.model = model_index;
    entry.view = view_index;
    for (int k = 0; k < count; ++k) {
      g.points[static_cast<size_t>(k)] = px[verts[k]];
      entry.vertices[k] = static_cast<uint8_t>(verts[k]);
    }
    const std::vector<float> v = IndexVector(g);
    const int ki = static_cast<int>(kind);
    vectors[ki].insert(vectors[ki].end(), v.begin(), v.end());
    index->entries[ki].push_back(entry);
  };
  // Chains of 3 and 4 edges: simple paths in the visible-edge graph, both directions.
  int path[5];
  auto dfs = [&](auto&& self, int depth) -> void {
    if (depth == 4) add(GroupKind::kChain3, path, 4);
    if (depth == 5) {
      add(GroupKind::kChain4, path, 5);
      return;
    }
    const int last = path[depth - 1];
    for (int next = 0; next < 8; ++next) {
      if (!adjacent[last][next]) continue;
      bool used = false;
      for (int k = 0; k < depth; ++k) used = used || path[k] == next;
      if (used) continue;
      if (depth >= 2 && !good_corner(path[depth - 2], last, next)) continue;
      path[depth] = next;
      self(self, depth + 1);
    }
  };
  for (int v = 0; v < 8; ++v) {
    path[0] = v;
    dfs(dfs, 1);
  }
  // Forks: vertices with three usable edges, arms ordered by image angle, every cyclic start.
  for (int v = 0; v < 8; ++v) {
    std::vector<std::pair<double, int>> arms;
    for (int w = 0; w < 8; ++w) {
      if (adjacent[v][w]) arms.push_back({std::atan2((px[w] - px[v]).y(), (px[w] - px[v]).x()), w});
    }
    if (arms.size() != 3) continue;
    if (!good_corner(arms[0].second, v, arms[1].second) || !good_corner(arms[1].second, v, arms[2].second) ||
        !good_corner(arms[0].second, v, arms[2].second)) {
      continue;
    }
    std::sort(arms.begin(), arms.end());
    for (int start = 0; start < 3; ++start) {
      const int verts[4] = {v, arms[static_cast<size_t>(start)].second,
                            arms[static_cast<size_t>((start + 1) % 3)].second,
                            arms[static_cast<size_t>((start + 2) % 3)].second};
      add(GroupKind::kFork3, verts, 4);
    }
  }
}

std::shared_ptr<RecognizerIndex> BuildIndex(const ModelLibrary& library, const RecognizerOptions& options) {
  auto index = std::make_shared<RecognizerIndex>();
  std::vector<float> vectors[kGroupKinds];
  // Directions over the sphere (Fibonacci lattice). The box's symmetry (pi about each axis) makes
  // views from the quarter x >= 0, z >= 0 enough; the others give the same images.
  const int n = options.view_sphere_samples;
  std::vector<Eigen::Vector3d> directions;
  for (int i = 0; i < n; ++i) {
    const double z = 1 - (i + 0.5) * 2.0 / n;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const double phi = i * M_PI * (3 - std::sqrt(5.0));
    const Eigen::Vector3d d(r * std::cos(phi), r * std::sin(phi), z);
    if (d.x() >= 0 && d.z() >= 0) directions.push_back(d);
  }
  for (size_t m = 0; m < library.models.size(); ++m) {
    for (double distance : options.view_distances_m) {
      for (const Eigen::Vector3d& d : directions) {
        const geometry::Pose3 camera_T_object = LookAt(d, distance);
        const auto view = static_cast<uint16_t>(index->views.size());
        index->views.push_back(camera_T_object);
        AddViewGroups(library.models[m], static_cast<uint16_t>(m), view, camera_T_object, index.get(),
                      vectors);
      }
    }
  }
  for (int k = 0; k < kGroupKinds; ++k) {
    const int dim = GroupDimension(static_cast<GroupKind>(k));
    index->vectors[k] = cv::Mat(static_cast<int>(index->entries[k].size()), dim, CV_32F);
    if (!vectors[k].empty())
      std::memcpy(index->vectors[k].data, vectors[k].data(), vectors[k].size() * sizeof(float));
  }
  return index;
}

void BuildTrees(RecognizerIndex* index) {
  // A kd-tree per kind, searched approximately (each neighbour within 1 + eps of the true one's
  // distance), as Beis & Lowe's best-bin-first search is; FLANN, its descendant, took 25 us per
  // query here against nanoflann's 3-5 (docs/benchmarks.md, session 13). The kinds' trees are
  // independent: built side by side, the first on this thread (each the same tree as built alone).
  auto build = [index](int k) {
    if (index->vectors[k].rows > 0) index->trees[k] = std::make_shared<const KindTree>(index->vectors[k]);
  };
  std::vector<std::future<void>> others;
  for (int k = 1; k < kGroupKinds; ++k) {
    try {
      others.push_back(std::async(std::launch::async, build, k));
    } catch (const std::system_error&) {  // no thread to be had: built here instead
      build(k);
    }
  }
  build(0);
  for (std::future<void>& f : others) f.get();  // rethrows what a builder threw
}

uint64_t IndexKey(const ModelLibrary& library, const RecognizerOptions& options) {
  uint64_t h = HashModelLibrary(library);
  h = Fnv(h, &kIndexFormat, sizeof(kIndexFormat));
  h = Fnv(h, &options.view_sphere_samples, sizeof(int));
  for (double d : options.view_distances_m) h = Fnv(h, &d, sizeof(double));
  return h;
}

using binary::Get;
using binary::Put;

constexpr char kMagic[8] = {'T', 'S', 'R', 'I', 'N', 'D', 'E', 'X'};

Status SaveIndex(const RecognizerIndex& index, uint64_t key, const std::string& path) {
  std::string out;
  out.append(kMagic, 8);
  Put(&out, key);
  Put(&out, static_cast<uint64_t>(index.views.size()));
  for (const geometry::Pose3& v : index.views) {
    const double q[7] = {v.rotation.w(),    v.rotation.x(),    v.rotation.y(),   v.rotation.z(),
                         v.translation.x(), v.translation.y(), v.translation.z()};
    out.append(reinterpret_cast<const char*>(q), sizeof(q));
  }
  for (int k = 0; k < kGroupKinds; ++k) {
    Put(&out, static_cast<uint64_t>(index.entries[k].size()));
    // Entry by entry, the padding byte zeroed: the same index writes the same bytes.
    for (const IndexEntry& e : index.entries[k]) {
      char bytes[sizeof(IndexEntry)] = {};
      std::memcpy(bytes + offsetof(IndexEntry, model), &e.model, sizeof(e.model));
      std::memcpy(bytes + offsetof(IndexEntry, view), &e.view, sizeof(e.view));
      std::memcpy(bytes + offsetof(IndexEntry, vertices), e.vertices, sizeof(e.vertices));
      out.append(bytes, sizeof(bytes));
    }
    out.append(reinterpret_cast<const char*>(index.vectors[k].data),
               index.vectors[k].total() * index.vectors[k].elemSize());
  }
  return json::WriteFileAtomic(path, out);
}

// Whether a cached index holds together: unit rotations and finite positions for the views, entries
// naming a model of the library (`models` of them), a view of the index and box vertices, finite
// index vectors. A file with the right key can still be damaged; one that fails is rebuilt.
bool HoldsTogether(const RecognizerIndex& index, size_t models) {
  for (const geometry::Pose3& v : index.views) {
    if (!v.rotation.coeffs().allFinite() || !(std::abs(v.rotation.norm() - 1) < 1e-9) ||
        !v.translation.allFinite()) {
      return false;
    }
  }
  for (int k = 0; k < kGroupKinds; ++k) {
    const auto kind = static_cast<GroupKind>(k);
    for (const IndexEntry& e : index.entries[k]) {
      if (e.model >= models || e.view >= index.views.size()) return false;
      for (uint8_t vertex : e.vertices) {
        if (vertex >= 8) return false;
      }
      // Each of the group's segments on a box edge, as the fit takes them (FitIndexHypotheses).
      for (int s = 0; s < GroupSegments(kind); ++s) {
        if (EntrySegmentEdge(e, kind, s) < 0) return false;
      }
    }
    if (!index.vectors[k].empty() && !cv::checkRange(index.vectors[k], true)) return false;
  }
  return true;
}

std::shared_ptr<RecognizerIndex> LoadIndex(const std::string& path, uint64_t key, size_t models) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return nullptr;
  // The bytes left after the read position: no count is allocated that the file cannot fill.
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  in.seekg(0, std::ios::beg);
  if (size < 0) return nullptr;
  auto left = [&] {
    const std::streamoff at = in.tellg();
    return at < 0 || at > size ? uint64_t{0} : static_cast<uint64_t>(size - at);
  };
  char magic[8];
  uint64_t stored_key = 0, views = 0;
  if (!in.read(magic, 8) || std::memcmp(magic, kMagic, 8) != 0 || !Get(in, &stored_key) ||
      stored_key != key || !Get(in, &views) || views > 1000000 || views * 7 * sizeof(double) > left()) {
    return nullptr;
  }
  auto index = std::make_shared<RecognizerIndex>();
  for (uint64_t i = 0; i < views; ++i) {
    double q[7];
    if (!in.read(reinterpret_cast<char*>(q), sizeof(q))) return nullptr;
    index->views.emplace_back(Eigen::Quaterniond(q[0], q[1], q[2], q[3]), Eigen::Vector3d(q[4], q[5], q[6]));
  }
  for (int k = 0; k < kGroupKinds; ++k) {
    uint64_t n = 0;
    const int dim = GroupDimension(static_cast<GroupKind>(k));
    if (!Get(in, &n) || n > 100000000 || n * (sizeof(IndexEntry) + dim * sizeof(float)) > left())
      return nullptr;
    index->entries[k].resize(n);
    if (!in.read(reinterpret_cast<char*>(index->entries[k].data()),
                 static_cast<std::streamsize>(n * sizeof(IndexEntry)))) {
      return nullptr;
    }
    index->vectors[k] = cv::Mat(static_cast<int>(n), dim, CV_32F);
    if (!in.read(reinterpret_cast<char*>(index->vectors[k].data),
                 static_cast<std::streamsize>(n * dim * sizeof(float)))) {
      return nullptr;
    }
  }
  return HoldsTogether(*index, models) ? index : nullptr;
}

}  // namespace

int EntrySegmentEdge(const IndexEntry& entry, GroupKind kind, int s) {
  const int a = kind == GroupKind::kFork3 ? entry.vertices[0] : entry.vertices[s];
  const int b = entry.vertices[s + 1];
  for (int e = 0; e < 12; ++e) {
    const auto& ends = kBoxEdges[static_cast<size_t>(e)];
    if ((ends[0] == a && ends[1] == b) || (ends[0] == b && ends[1] == a)) return e;
  }
  return -1;
}

namespace internal {

Result<std::shared_ptr<RecognizerIndex>> LoadOrBuildIndex(const ModelLibrary& library,
                                                          const RecognizerOptions& options,
                                                          const std::string& cache_dir,
                                                          bool* loaded_from_cache) {
  *loaded_from_cache = false;
  const uint64_t key = IndexKey(library, options);
  std::string path;
  std::shared_ptr<RecognizerIndex> index;
  if (!cache_dir.empty()) {
    char name[64];
    std::snprintf(name, sizeof(name), "recognizer-index-%016llx.bin", static_cast<unsigned long long>(key));
    path = (std::filesystem::path(cache_dir) / name).string();
    index = LoadIndex(path, key, library.models.size());
    *loaded_from_cache = index != nullptr;
  }
  if (!index) {
    index = BuildIndex(library, options);
    if (!path.empty()) {
      std::error_code ec;
      std::filesystem::create_directories(cache_dir, ec);
      if (ec) return Status::IoError(cache_dir + ": cannot create the index cache folder: " + ec.message());
      TEACHSIM_RETURN_IF_ERROR(SaveIndex(*index, key, path));
    }
  }
  BuildTrees(index.get());
  return index;
}

// 3. indexing: the k nearest model-view vectors of each group; their votes give p(model | group)
// (Beis & Lowe). The hypotheses, most probable first.
std::vector<Hypothesis> IndexHypotheses(const RecognizerIndex& index, const std::vector<Group>& groups,
                                        const std::vector<ImageLine>& lines,
                                        const RecognizerOptions& options) {
  std::vector<Hypothesis> hypotheses;
  constexpr double kSigma = 0.12;              // spread of an index vector's error (rad / weighted log ratio)
  constexpr double kBackgroundDistance = 0.3;  // a neighbour this far is as likely as clutter
  const double background = std::exp(-kBackgroundDistance * kBackgroundDistance / (2 * kSigma * kSigma));
  for (int k = 0; k < kGroupKinds; ++k) {
    if (!index.trees[k]) continue;
    std::vector<int> members;
    for (size_t g = 0; g < groups.size(); ++g) {
      if (static_cast<int>(groups[g].kind) == k) members.push_back(static_cast<int>(g));
    }
    if (members.empty()) continue;
    // The most salient groups (longest segments in all) when there are more than the search can
    // afford: only the best max_hypotheses hypotheses are fitted, and on wood grain or clutter
    // most groups are short texture lines.
    if (static_cast<int>(members.size()) > options.max_index_queries) {
      std::vector<double> length(groups.size(), 0.0);  // of each group's segments, px
      for (int g : members) {
        const Group& group = groups[static_cast<size_t>(g)];
        for (int s = 0; s < GroupSegments(group.kind); ++s) {
          length[static_cast<size_t>(g)] +=
              lines[static_cast<size_t>(group.segments[static_cast<size_t>(s)])].Length();
        }
      }
      const auto keep = members.begin() + options.max_index_queries;
      std::partial_sort(members.begin(), keep, members.end(), [&](int a, int b) {
        const double la = length[static_cast<size_t>(a)], lb = length[static_cast<size_t>(b)];
        return la != lb ? la > lb : a < b;
      });
      members.erase(keep, members.end());
    }
    const size_t knn = static_cast<size_t>(std::min(options.neighbours, index.vectors[k].rows));
    const nanoflann::SearchParams search(0, static_cast<float>(options.index_search_eps));
    std::vector<uint32_t> found(knn);
    std::vector<float> d2(knn);
    std::vector<double> w(knn);
    for (int g : members) {
      const std::vector<float> query = IndexVector(groups[static_cast<size_t>(g)]);
      nanoflann::KNNResultSet<float, uint32_t> neighbours(knn);
      neighbours.init(found.data(), d2.data());
      index.trees[k]->tree.findNeighbors(neighbours, query.data(), search);
      const size_t count = neighbours.size();  // nearest first
      double total = background;
      std::map<int, double> per_model;
      for (size_t j = 0; j < count; ++j) {
        w[j] = std::exp(-d2[j] / (2 * kSigma * kSigma));
        total += w[j];
        per_model[index.entries[k][found[j]].model] += w[j];
      }
      for (size_t j = 0; j < count; ++j) {
        const double p_model = per_model[index.entries[k][found[j]].model] / total;
        // The neighbour's own weight orders the views within a model.
        const double p = p_model * w[j] / std::max(w[0], 1e-300);
        if (p < 1e-3) continue;
        // Larger groups are more specific (paper §7.1): ties go to them.
        hypotheses.push_back(
            {p * (k == static_cast<int>(GroupKind::kChain4) ? 1.2 : 1.0), g, k, static_cast<int>(found[j])});
      }
    }
  }
  std::stable_sort(hypotheses.begin(), hypotheses.end(),
                   [](const Hypothesis& a, const Hypothesis& b) { return a.probability > b.probability; });
  return hypotheses;
}

// The initial pose of a hypothesis: the model view's pose turned and scaled by the 2D similarity
// that maps the view's group onto the image group (weak perspective), then re-aimed at the group.
geometry::Pose3 InitialPose(const RecognizerIndex& index, const Model& model, const IndexEntry& entry,
                            const Group& group, const Eigen::Matrix3d& K) {
  const geometry::Pose3& view = index.views[entry.view];
  const int count = group.kind == GroupKind::kChain4 ? 5 : 4;
  std::complex<double> q[5], p[5];
  double w[5];
  for (int k = 0; k < count; ++k) {
    const Eigen::Vector3d v = view * BoxVertex(model.box_size_m, entry.vertices[k]);
    q[k] = {v.x() / v.z(), v.y() / v.z()};
    const Eigen::Vector2d& g = group.points[static_cast<size_t>(k)];
    p[k] = {(g.x() - K(0, 2)) / K(0, 0), (g.y() - K(1, 2)) / K(1, 1)};
    // Junctions are reliable, free ends less so.
    const bool junction = group.kind == GroupKind::kFork3 ? k == 0 : (k > 0 && k < count - 1);
    w[k] = junction ? 1.0 : 0.5;
  }
  std::complex<double> qm = 0, pm = 0;
  double ws = 0;
  for (int k = 0; k < count; ++k) qm += w[k] * q[k], pm += w[k] * p[k], ws += w[k];
  qm /= ws;
  pm /= ws;
  std::complex<double> num = 0;
  double den = 0;
  for (int k = 0; k < count; ++k) {
    num += w[k] * std::conj(q[k] - qm) * (p[k] - pm);
    den += w[k] * std::norm(q[k] - qm);
  }
  const std::complex<double> z = den > 0 ? num / den : std::complex<double>(1, 0);
  const std::complex<double> t = pm - z * qm;  // where the view's centre (0, 0) goes
  const double scale = std::max(std::abs(z), 1e-6), theta = std::arg(z);
  const Eigen::Vector3d ray = Eigen::Vector3d(t.real(), t.imag(), 1).normalized();
  const Eigen::Quaterniond align = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), ray);
  const Eigen::Quaterniond roll(Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()));
  return {(align * roll * view.rotation).normalized(), ray * (view.translation.z() / scale)};
}

}  // namespace internal

}  // namespace teachsim::vision
