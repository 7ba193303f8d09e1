#include "teachsim/geometry/convex.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

namespace teachsim::geometry {

namespace {

// 2D convex hull (Andrew's monotone chain) of points given as indices into `p2`; collinear points
// are dropped. Returns indices counter-clockwise.
std::vector<int> ConvexHull2d(const std::vector<Eigen::Vector2d>& p2, std::vector<int> idx, double eps) {
  std::sort(idx.begin(), idx.end(), [&](int a, int b) {
    return p2[a].x() < p2[b].x() || (p2[a].x() == p2[b].x() && p2[a].y() < p2[b].y());
  });
  auto cross = [&](int o, int a, int b) {
    Eigen::Vector2d u = p2[a] - p2[o], v = p2[b] - p2[o];
    return u.x() * v.y() - u.y() * v.x();
  };
  std::vector<int> hull(2 * idx.size());
  std::size_t k = 0;
  for (int i : idx) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], i) <= eps) --k;
    hull[k++] = i;
  }
  for (std::size_t n = idx.size(), t = k + 1, j = n - 1; j-- > 0;) {
    int i = idx[j];
    while (k >= t && cross(hull[k - 2], hull[k - 1], i) <= eps) --k;
    hull[k++] = i;
  }
  hull.resize(k > 0 ? k - 1 : 0);
  return hull;
}

}  // namespace

Result<ConvexPolyhedron> ConvexPolyhedron::Box(const Eigen::Vector3d& size) {
  if (!size.allFinite() || (size.array() <= 0.0).any()) {
    return Status::InvalidInput("box size must be finite and > 0");
  }
  ConvexPolyhedron p;
  Eigen::Vector3d h = 0.5 * size;
  for (int i = 0; i < 8; ++i) {
    p.vertices_.emplace_back((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  }
  // Faces counter-clockwise seen from outside: -x, +x, -y, +y, -z, +z.
  const int loops[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (int f = 0; f < 6; ++f) {
    Face face;
    int axis = f / 2;
    double sign = (f % 2) ? 1.0 : -1.0;
    face.normal = Eigen::Vector3d::Zero();
    face.normal[axis] = sign;
    face.offset = h[axis];
    face.vertices.assign(loops[f], loops[f] + 4);
    p.faces_.push_back(face);
  }
  p.BuildTopology();
  p.is_box_ = true;
  return p;
}

Result<ConvexPolyhedron> ConvexPolyhedron::Hull(const std::vector<Eigen::Vector3d>& points) {
  const int n = static_cast<int>(points.size());
  if (n < 4) return Status::InvalidInput("a convex shape needs at least 4 vertices, got " + std::to_string(n));
  if (n > kMaxHullPoints) {
    return Status::InvalidInput("a convex shape may have at most " + std::to_string(kMaxHullPoints) +
                                " vertices, got " + std::to_string(n));
  }
  Aabb bounds;
  for (int i = 0; i < n; ++i) {
    if (!points[i].allFinite()) return Status::InvalidInput("vertex " + std::to_string(i) + " is not finite");
    bounds.Extend(points[i]);
  }
  const double extent = bounds.Size().maxCoeff();
  if (!(extent > 0.0)) return Status::InvalidInput("the vertices span no volume");
  const double eps = 1e-9 * extent;

  // Supporting planes from triples of points (small hulls only: blocks, frames, wedges).
  struct Plane {
    Eigen::Vector3d normal;
    double offset;
  };
  std::vector<Plane> planes;
  auto on_known_plane = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    for (const Plane& pl : planes) {
      if (std::abs(pl.normal.dot(a) - pl.offset) <= eps && std::abs(pl.normal.dot(b) - pl.offset) <= eps &&
          std::abs(pl.normal.dot(c) - pl.offset) <= eps) {
        return true;
      }
    }
    return false;
  };
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      for (int k = j + 1; k < n; ++k) {
        Eigen::Vector3d normal = (points[j] - points[i]).cross(points[k] - points[i]);
        double len = normal.norm();
        if (len <= 1e-9 * extent * extent) continue;  // collinear
        normal /= len;
        double offset = normal.dot(points[i]);
        bool above = false, below = false;
        for (int m = 0; m < n && !(above && below); ++m) {
          double s = normal.dot(points[m]) - offset;
          if (s > eps) above = true;
          if (s < -eps) below = true;
        }
        if (above && below) continue;
        if (!above && !below) return Status::InvalidInput("the vertices are coplanar: they span no volume");
        if (above) {
          normal = -normal;
          offset = -offset;
        }
        if (on_known_plane(points[i], points[j], points[k])) continue;
        planes.push_back({normal, offset});
      }
    }
  }
  if (planes.size() < 4) return Status::InvalidInput("the vertices span no volume");

  ConvexPolyhedron p;
  std::map<int, int> remap;  // input point index -> vertex index
  for (const Plane& pl : planes) {
    // Orthonormal basis of the plane, then the 2D hull of the points on it.
    Eigen::Vector3d u = pl.normal.unitOrthogonal();
    Eigen::Vector3d v = pl.normal.cross(u);
    std::vector<Eigen::Vector2d> p2(static_cast<std::size_t>(n));
    std::vector<int> on;
    for (int m = 0; m < n; ++m) {
      p2[m] = {u.dot(points[m]), v.dot(points[m])};
      if (std::abs(pl.normal.dot(points[m]) - pl.offset) <= eps) on.push_back(m);
    }
    // Drop duplicates before the 2D hull.
    std::vector<int> unique;
    for (int m : on) {
      bool dup = false;
      for (int q : unique) dup = dup || (points[m] - points[q]).norm() <= eps;
      if (!dup) unique.push_back(m);
    }
    std::vector<int> loop = ConvexHull2d(p2, unique, eps * extent);
    if (loop.size() < 3) continue;
    Face face;
    face.normal = pl.normal;
    for (int m : loop) {
      auto [it, inserted] = remap.emplace(m, static_cast<int>(p.vertices_.size()));
      if (inserted) p.vertices_.push_back(points[m]);
      face.vertices.push_back(it->second);
    }
    // Average offset over the face's vertices for a plane that fits them all.
    face.offset = 0.0;
    for (int vi : face.vertices) face.offset += face.normal.dot(p.vertices_[vi]);
    face.offset /= static_cast<double>(face.vertices.size());
    p.faces_.push_back(std::move(face));
  }
  // A point that sits on several faces is shared through remap; duplicates of the same position
  // with different indices are merged by position.
  p.BuildTopology();
  for (const Edge& e : p.edges_) {
    if (e.f0 < 0 || e.f1 < 0) return Status::InvalidInput("the hull is not closed (degenerate vertices)");
  }
  return p;
}

void ConvexPolyhedron::BuildTopology() {
  std::map<std::pair<int, int>, int> edge_index;
  edges_.clear();
  for (int f = 0; f < static_cast<int>(faces_.size()); ++f) {
    Face& face = faces_[f];
    face.edges.clear();
    const int m = static_cast<int>(face.vertices.size());
    for (int i = 0; i < m; ++i) {
      int a = face.vertices[i], b = face.vertices[(i + 1) % m];
      auto key = std::minmax(a, b);
      auto it = edge_index.find(key);
      if (it == edge_index.end()) {
        it = edge_index.emplace(key, static_cast<int>(edges_.size())).first;
        edges_.push_back({key.first, key.second, f, -1});
      } else {
        edges_[it->second].f1 = f;
      }
      face.edges.push_back(it->second);
    }
  }
  const std::size_t nv = vertices_.size();
  neighbors_.assign(nv, {});
  vertex_faces_.assign(nv, {});
  for (const Edge& e : edges_) {
    neighbors_[e.v0].push_back(e.v1);
    neighbors_[e.v1].push_back(e.v0);
  }
  for (int f = 0; f < static_cast<int>(faces_.size()); ++f) {
    for (int v : faces_[f].vertices) vertex_faces_[v].push_back(f);
  }
  adjacency_begin_.assign(nv + 1, 0);
  for (const Edge& e : edges_) {
    ++adjacency_begin_[e.v0 + 1];
    ++adjacency_begin_[e.v1 + 1];
  }
  for (std::size_t i = 0; i < nv; ++i) adjacency_begin_[i + 1] += adjacency_begin_[i];
  adjacency_.assign(edges_.size() * 2, 0);
  adjacency_edge_.assign(edges_.size() * 2, 0);
  {
    std::vector<int> fill(adjacency_begin_.begin(), adjacency_begin_.end() - 1);
    for (int k = 0; k < static_cast<int>(edges_.size()); ++k) {
      const Edge& e = edges_[k];
      adjacency_[fill[e.v0]] = e.v1;
      adjacency_edge_[fill[e.v0]++] = k;
      adjacency_[fill[e.v1]] = e.v0;
      adjacency_edge_[fill[e.v1]++] = k;
    }
  }
  face_masks_.assign(faces_.size(), 0);
  if (nv <= 64) {
    for (std::size_t f = 0; f < faces_.size(); ++f) {
      for (int v : faces_[f].vertices) face_masks_[f] |= std::uint64_t{1} << v;
    }
  }
  local_bounds_ = Aabb();
  bounding_radius_ = 0.0;
  centroid_.setZero();
  for (const Eigen::Vector3d& v : vertices_) {
    local_bounds_.Extend(v);
    bounding_radius_ = std::max(bounding_radius_, v.norm());
    centroid_ += v;
  }
  if (nv > 0) centroid_ /= static_cast<double>(nv);
  min_thickness_ = std::numeric_limits<double>::infinity();
  for (const Face& face : faces_) {
    double lowest = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& v : vertices_) lowest = std::min(lowest, face.normal.dot(v));
    min_thickness_ = std::min(min_thickness_, face.offset - lowest);
  }
}

double ConvexPolyhedron::Volume() const {
  // Sum of pyramids from the centroid over each face's fan.
  double volume = 0.0;
  for (const Face& face : faces_) {
    const Eigen::Vector3d& a = vertices_[face.vertices[0]];
    for (std::size_t i = 1; i + 1 < face.vertices.size(); ++i) {
      const Eigen::Vector3d& b = vertices_[face.vertices[i]];
      const Eigen::Vector3d& c = vertices_[face.vertices[i + 1]];
      volume += (a - centroid_).dot((b - centroid_).cross(c - centroid_)) / 6.0;
    }
  }
  return volume;
}

int ConvexPolyhedron::Support(const Eigen::Vector3d& direction, int hint) const {
  const int n = static_cast<int>(vertices_.size());
  const double dx = direction.x(), dy = direction.y(), dz = direction.z();
  const Eigen::Vector3d* v = vertices_.data();
  if (hint < 0 || hint >= n || n <= kScanVertices) {
    // Branch-free (selects, not jumps): the maximum's position is unpredictable.
    int best = 0;
    double best_dot = v[0].x() * dx + v[0].y() * dy + v[0].z() * dz;
    for (int i = 1; i < n; ++i) {
      const double d = v[i].x() * dx + v[i].y() * dy + v[i].z() * dz;
      const bool better = d > best_dot;
      best_dot = better ? d : best_dot;
      best = better ? i : best;
    }
    return best;
  }
  // Hill climb: on a convex polyhedron a vertex with no better neighbour is a global maximum.
  int best = hint;
  double best_dot = v[hint].x() * dx + v[hint].y() * dy + v[hint].z() * dz;
  const int* begin = adjacency_begin_.data();
  const int* adjacent = adjacency_.data();
  for (bool improved = true; improved;) {
    improved = false;
    const int from = best;
    for (int k = begin[from]; k < begin[from + 1]; ++k) {
      const int nb = adjacent[k];
      const double d = v[nb].x() * dx + v[nb].y() * dy + v[nb].z() * dz;
      if (d > best_dot) {
        best_dot = d;
        best = nb;
        improved = true;
      }
    }
  }
  return best;
}

int ConvexPolyhedron::EdgeBetween(int v0, int v1) const {
  for (int k = adjacency_begin_[v0]; k < adjacency_begin_[v0 + 1]; ++k) {
    if (adjacency_[k] == v1) return adjacency_edge_[k];
  }
  return -1;
}

Aabb ConvexPolyhedron::WorldBounds(const Pose3& world_T_body) const {
  // Exact box of the rotated vertices (few vertices; tighter than rotating the local box).
  Aabb box;
  Eigen::Matrix3d r = world_T_body.RotationMatrix();
  for (const Eigen::Vector3d& v : vertices_) box.Extend(r * v + world_T_body.translation);
  return box;
}

}  // namespace teachsim::geometry
