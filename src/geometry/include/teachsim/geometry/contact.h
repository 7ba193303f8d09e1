// Contact sets: a finite set of points with normals that models the contact between two convex
// polyhedra closer than a threshold (paper §5.1, footnote 2). As Box2D/Jolt do it: the separating
// axis, preferring face axes over edge axes by an absolute slack (so parallel faces give a face
// contact, never a spurious edge-edge one), a reference and an incident face, Sutherland-Hodgman
// clipping, and the clipped points within the threshold (at most kMaxContactPoints, well spread).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "teachsim/geometry/convex.h"
#include "teachsim/geometry/distance.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::geometry {

inline constexpr int kMaxContactPoints = 8;
// A face axis wins over an edge axis unless the edge axis separates by more than this.
inline constexpr double kFaceAxisSlack = 1e-5;  // m
// ... and a face whose normal is within this angle of the separating direction is a face contact.
inline constexpr double kFaceAngle = 1.0 * 3.14159265358979323846 / 180.0;  // rad

struct ContactPoint {
  Eigen::Vector3d point_a;  // world, on A's surface
  Eigen::Vector3d point_b;  // world, on B's surface
  Eigen::Vector3d normal;   // world, unit, from A toward B (a force pushing A away from B is -normal)
  double distance = 0.0;    // m, along the normal
  std::uint32_t id = 0;     // feature key, stable while the same features touch (warm starts)
};

enum class ContactKind : std::uint8_t { kNone, kFaceFace, kEdgeFace, kVertexFace, kEdgeEdge, kVertexVertex };

struct ContactSet {
  ContactKind kind = ContactKind::kNone;
  std::vector<ContactPoint> points;
};

// The contact set of A and B when their distance is at most `threshold` (empty otherwise).
// `distance` is the result of Distance() for this pair at these poses.
ContactSet ComputeContacts(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                           const Pose3& world_T_b, const DistanceResult& distance, double threshold);

const char* ToString(ContactKind kind);

}  // namespace teachsim::geometry
