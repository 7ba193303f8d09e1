// Convex polyhedra: vertices, faces with outward normals, edges and adjacency, in the body frame.
// Built once and then shared read-only (model apart from state, STYLE.md).
#pragma once

#include <Eigen/Core>
#include <array>
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

  const Aabb& local_bounds() const { return local_bounds_; }
  double bounding_radius() const { return bounding_radius_; }  // max |vertex| about the body origin
  Eigen::Vector3d centroid() const { return centroid_; }       // of the vertices
  double min_thickness() const { return min_thickness_; }      // smallest width over face normals
  double Volume() const;

  // The vertex farthest along `direction` (body frame); `hint` starts a hill climb over the
  // adjacency (temporal coherence), otherwise a scan.
  int Support(const Eigen::Vector3d& direction, int hint = -1) const;

  Aabb WorldBounds(const Pose3& world_T_body) const;

 private:
  ConvexPolyhedron() = default;
  void BuildTopology();  // edges, neighbors, bounds from faces_

  std::vector<Eigen::Vector3d> vertices_;
  std::vector<Face> faces_;
  std::vector<Edge> edges_;
  std::vector<std::vector<int>> neighbors_;
  std::vector<std::vector<int>> vertex_faces_;
  Aabb local_bounds_;
  double bounding_radius_ = 0.0;
  double min_thickness_ = 0.0;
  Eigen::Vector3d centroid_ = Eigen::Vector3d::Zero();
};

}  // namespace teachsim::geometry
