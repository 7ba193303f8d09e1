#include "teachsim/geometry/contact.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace teachsim::geometry {

namespace {

// Largest separation of `other` (vertices given in ref's frame) along ref's face normals.
double BestFaceAxis(const ConvexPolyhedron& ref, const std::vector<Eigen::Vector3d>& other_in_ref, int* face) {
  double best = -std::numeric_limits<double>::infinity();
  for (int f = 0; f < static_cast<int>(ref.faces().size()); ++f) {
    const Face& fc = ref.faces()[f];
    double lowest = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& v : other_in_ref) lowest = std::min(lowest, fc.normal.dot(v) - fc.offset);
    if (lowest > best) {
      best = lowest;
      *face = f;
    }
  }
  return best;
}

struct ClipVertex {
  Eigen::Vector3d p;
  std::uint32_t tag;  // incident vertex (< 1024) or 1024 + incident edge * 32 + reference side
};

// Sutherland-Hodgman: keep the part of `poly` with plane_n.(p - plane_p) <= 0.
void ClipAgainst(const std::vector<ClipVertex>& poly, const Eigen::Vector3d& plane_n, const Eigen::Vector3d& plane_p,
                 std::uint32_t side, std::vector<ClipVertex>* out) {
  out->clear();
  const std::size_t m = poly.size();
  for (std::size_t i = 0; i < m; ++i) {
    const ClipVertex& a = poly[i];
    const ClipVertex& b = poly[(i + 1) % m];
    const double da = plane_n.dot(a.p - plane_p), db = plane_n.dot(b.p - plane_p);
    if (da <= 0.0) out->push_back(a);
    if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
      const double s = da / (da - db);
      out->push_back({a.p + s * (b.p - a.p), 1024u + static_cast<std::uint32_t>(i) * 32u + side});
    }
  }
}

// Keeps at most kMaxContactPoints: the closest, then repeatedly the point farthest from those kept.
void Reduce(std::vector<ContactPoint>* points) {
  if (points->size() <= static_cast<std::size_t>(kMaxContactPoints)) return;
  std::vector<ContactPoint> kept;
  auto closest = std::min_element(points->begin(), points->end(),
                                  [](const ContactPoint& a, const ContactPoint& b) { return a.distance < b.distance; });
  kept.push_back(*closest);
  std::vector<bool> used(points->size(), false);
  used[static_cast<std::size_t>(closest - points->begin())] = true;
  while (kept.size() < static_cast<std::size_t>(kMaxContactPoints)) {
    double best = -1.0;
    std::size_t pick = 0;
    for (std::size_t i = 0; i < points->size(); ++i) {
      if (used[i]) continue;
      double nearest = std::numeric_limits<double>::infinity();
      for (const ContactPoint& k : kept) nearest = std::min(nearest, ((*points)[i].point_b - k.point_b).norm());
      if (nearest > best) {
        best = nearest;
        pick = i;
      }
    }
    used[pick] = true;
    kept.push_back((*points)[pick]);
  }
  *points = std::move(kept);
}

}  // namespace

ContactSet ComputeContacts(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                           const Pose3& world_T_b, const DistanceResult& distance, double threshold) {
  ContactSet set;
  if (distance.distance > threshold) return set;

  const Pose3 a_T_b = world_T_a.Inverse() * world_T_b;
  const Pose3 b_T_a = a_T_b.Inverse();
  std::vector<Eigen::Vector3d> b_in_a, a_in_b;
  b_in_a.reserve(b.vertices().size());
  a_in_b.reserve(a.vertices().size());
  for (const auto& v : b.vertices()) b_in_a.push_back(a_T_b * v);
  for (const auto& v : a.vertices()) a_in_b.push_back(b_T_a * v);
  int face_a = 0, face_b = 0;
  const double sep_a = BestFaceAxis(a, b_in_a, &face_a);
  const double sep_b = BestFaceAxis(b, a_in_b, &face_b);
  // The faces best aligned with the exact separating direction.
  const Eigen::Vector3d n_in_a = world_T_a.rotation.conjugate() * distance.normal;
  const Eigen::Vector3d n_in_b = world_T_b.rotation.conjugate() * distance.normal;
  int align_a = 0, align_b = 0;
  double cos_a = -2.0, cos_b = -2.0;
  for (int f = 0; f < static_cast<int>(a.faces().size()); ++f) {
    if (double c = a.faces()[f].normal.dot(n_in_a); c > cos_a) cos_a = c, align_a = f;
  }
  for (int f = 0; f < static_cast<int>(b.faces().size()); ++f) {
    if (double c = -b.faces()[f].normal.dot(n_in_b); c > cos_b) cos_b = c, align_b = f;
  }

  // A face axis wins when its separation is within the slack of the exact distance (SAT with an
  // absolute tie-break), or when the separating direction is within kFaceAngle of a face normal:
  // tilted near-parallel faces whose closest features are two boundary edges (SAT alone called
  // 0.4 % of such poses edge-edge) are face contacts.
  const bool sat_face = std::max(sep_a, sep_b) >= distance.distance - kFaceAxisSlack;
  const bool aligned_face = std::max(cos_a, cos_b) >= std::cos(kFaceAngle);
  if (!distance.intersecting && !sat_face && !aligned_face) {
    ContactPoint cp{distance.point_a, distance.point_b, distance.normal, distance.distance, 0};
    const bool edges = distance.feature_a.type == Feature::Type::kEdge && distance.feature_b.type == Feature::Type::kEdge;
    cp.id = (1u << 31) | (static_cast<std::uint32_t>(distance.feature_a.index) << 12) |
            static_cast<std::uint32_t>(distance.feature_b.index);
    set.kind = edges ? ContactKind::kEdgeEdge : ContactKind::kVertexVertex;
    set.points.push_back(cp);
    return set;
  }

  // Reference face: A's unless B's is clearly better (deterministic tie-break to A).
  bool ref_is_a;
  int ref_face;
  if (sat_face) {
    ref_is_a = !(sep_b > sep_a + 0.1 * kFaceAxisSlack);
    ref_face = ref_is_a ? face_a : face_b;
  } else {
    ref_is_a = !(cos_b > cos_a + 1e-9);
    ref_face = ref_is_a ? align_a : align_b;
  }
  const ConvexPolyhedron& ref = ref_is_a ? a : b;
  const ConvexPolyhedron& inc = ref_is_a ? b : a;
  const Pose3& world_T_ref = ref_is_a ? world_T_a : world_T_b;
  const Pose3& world_T_inc = ref_is_a ? world_T_b : world_T_a;
  const Face& rf = ref.faces()[ref_face];
  const Eigen::Vector3d n_ref = world_T_ref.Rotate(rf.normal);

  // Incident face: the most anti-parallel face of the other body.
  int inc_face = 0;
  double most = std::numeric_limits<double>::infinity();
  for (int f = 0; f < static_cast<int>(inc.faces().size()); ++f) {
    double c = world_T_inc.Rotate(inc.faces()[f].normal).dot(n_ref);
    if (c < most) {
      most = c;
      inc_face = f;
    }
  }
  std::vector<ClipVertex> poly, next;
  for (int vi : inc.faces()[inc_face].vertices) {
    poly.push_back({world_T_inc * inc.vertices()[vi], static_cast<std::uint32_t>(vi)});
  }
  const int m = static_cast<int>(rf.vertices.size());
  for (int i = 0; i < m && !poly.empty(); ++i) {
    const Eigen::Vector3d p0 = world_T_ref * ref.vertices()[rf.vertices[i]];
    const Eigen::Vector3d p1 = world_T_ref * ref.vertices()[rf.vertices[(i + 1) % m]];
    const Eigen::Vector3d side_n = (p1 - p0).cross(n_ref);
    ClipAgainst(poly, side_n, p0, static_cast<std::uint32_t>(i), &next);
    poly.swap(next);
  }
  const Eigen::Vector3d on_ref = world_T_ref * ref.vertices()[rf.vertices[0]];
  const std::uint32_t base = (ref_is_a ? 0u : (1u << 30)) | (static_cast<std::uint32_t>(ref_face) << 20) |
                             (static_cast<std::uint32_t>(inc_face) << 12);
  for (const ClipVertex& cv : poly) {
    const double sep = n_ref.dot(cv.p - on_ref);
    if (sep > threshold) continue;
    ContactPoint cp;
    const Eigen::Vector3d projected = cv.p - sep * n_ref;
    if (ref_is_a) {
      cp.point_a = projected;
      cp.point_b = cv.p;
      cp.normal = n_ref;
    } else {
      cp.point_b = projected;
      cp.point_a = cv.p;
      cp.normal = -n_ref;
    }
    cp.distance = sep;
    cp.id = base | (cv.tag & 0xfffu);
    set.points.push_back(cp);
  }
  if (set.points.empty()) {
    // The clip left nothing within the threshold (a slack case at a face boundary): fall back
    // to the single closest-point contact, which is always right.
    set.points.push_back({distance.point_a, distance.point_b, distance.normal, distance.distance, 1u << 31});
    set.kind = ContactKind::kVertexVertex;
    return set;
  }
  Reduce(&set.points);
  set.kind = set.points.size() >= 3   ? ContactKind::kFaceFace
             : set.points.size() == 2 ? ContactKind::kEdgeFace
                                      : ContactKind::kVertexFace;
  return set;
}

const char* ToString(ContactKind kind) {
  switch (kind) {
    case ContactKind::kNone: return "none";
    case ContactKind::kFaceFace: return "face-face";
    case ContactKind::kEdgeFace: return "edge-face";
    case ContactKind::kVertexFace: return "vertex-face";
    case ContactKind::kEdgeEdge: return "edge-edge";
    case ContactKind::kVertexVertex: return "vertex-vertex";
  }
  return "?";
}

}  // namespace teachsim::geometry
