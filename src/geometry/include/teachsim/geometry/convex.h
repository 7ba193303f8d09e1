// Convex polyhedra: vertices, faces with outward normals, edges and adjacency, in the body frame.
// Built once and then shared read-only (model apart from state, STYLE.md).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "teachsim/base/status.h"
#include "teachsim/geometry/aabb.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::geometry {

struct Face {
  Eigen::Vector3d normal;     // outward, unit
  double offset = 0.0;        // plane: normal . x = offset
  std::vector<int> vertices;  // counter-clockwise seen from outside
  std::vector<int> edges;     // edges[i] joins vertices[i] and vertices[i+1]
};

struct Edge {
  int v0 = 0, v1 = 0;        // vertex indices
  int f0 = 0, f1 = 0;        // the two faces that share it
};

class ConvexPolyhedron {
 public:
  // A box of full side lengths `size` centred on the origin (the scene's {"box": [sx, sy, sz]}).
  static Result<ConvexPolyhedron> Box(const Eigen::Vector3d& size);
  // The convex hull of the points; coplanar hull facets merge into one polygonal face. Fails on
  // fewer than 4 points, points that span no volume, non-finite or too many points (> kMaxHullPoints).
  static Result<ConvexPolyhedron> Hull(const std::vector<Eigen::Vector3d>& points);
  static constexpr int kMaxHullPoints = 256;

  const std::vector<Eigen::Vector3d>& vertices() const { return vertices_; }
  const std::vector<Face>& faces() const { return faces_; }
  const std::vector<Edge>& edges() const { return edges_; }
  // The vertices joined to vertex i by an edge.
  const std::vector<int>& neighbors(int i) const { return neighbors_[static_cast<std::size_t>(i)]; }
  // The faces that contain vertex i.
  const std::vector<int>& vertex_faces(int i) const { return vertex_faces_[static_cast<std::size_t>(i)]; }
  // The edge joining vertices v0 and v1, or -1.
  int EdgeBetween(int v0, int v1) const;
  // The vertices of face f as a bit set (bit i: vertex i), for polyhedra of at most 64 vertices
  // (0 otherwise): feature look-ups after a distance query without searching vertex lists.
  std::uint64_t face_vertex_mask(int f) const { return face_masks_[static_cast<std::size_t>(f)]; }

  // Built by Box(): vertex i is (+-hx, +-hy, +-hz) with bit 0/1/2 of i giving the sign of x/y/z,
  // so the support vertex follows from the direction's sign pattern (no scan).
  bool is_box() const { return is_box_; }

  const Aabb& local_bounds() const { return local_bounds_; }
  double bounding_radius() const { return bounding_radius_; }  // max |vertex| about the body origin
  Eigen::Vector3d centroid() const { return centroid_; }       // of the vertices
  double min_thickness() const { return min_thickness_; }      // smallest width over face normals
  double Volume() const;

  // The vertex farthest along `direction` (body frame); `hint` starts a hill climb over the
  // adjacency (temporal coherence), otherwise a scan.
  int Support(const Eigen::Vector3d& direction, int hint = -1) const;
  // Up to this many vertices Support() scans even with a hint (on the distance benchmark's 8-40
  // vertex hulls, 8 and 16 cost the same instructions within 1 %).
  static constexpr int kScanVertices = 16;

  Aabb WorldBounds(const Pose3& world_T_body) const;

 private:
  ConvexPolyhedron() = default;
  void BuildTopology();  // edges, neighbors, bounds from faces_

  std::vector<Eigen::Vector3d> vertices_;
  std::vector<Face> faces_;
  std::vector<Edge> edges_;
  std::vector<std::vector<int>> neighbors_;
  std::vector<std::vector<int>> vertex_faces_;
  // Adjacency flattened for the support hill climb: vertex i's neighbours are
  // adjacency_[adjacency_begin_[i] .. adjacency_begin_[i + 1]), the joining edges alongside.
  std::vector<int> adjacency_begin_;
  std::vector<int> adjacency_;
  std::vector<int> adjacency_edge_;
  std::vector<std::uint64_t> face_masks_;
  bool is_box_ = false;
  Aabb local_bounds_;
  double bounding_radius_ = 0.0;
  double min_thickness_ = 0.0;
  Eigen::Vector3d centroid_ = Eigen::Vector3d::Zero();
};

}  // namespace teachsim::geometry
