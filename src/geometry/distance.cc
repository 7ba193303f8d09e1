// GJK (Gilbert, Johnson, Keerthi 1988; van den Bergen's termination) on the Minkowski difference
// C = B - A, in A's frame. Every iterate v is a convex combination of points of C, so |v| is an
// upper bound on the distance; every support point w gives the separating-plane lower bound
// v.w/|v|. We stop when the two agree within kDistanceTolerance and report the lower bound, so
// the result never over-estimates whatever the conditioning of the simplex (near-parallel faces
// give flat simplices: they only cost iterations here, never safety).
#include "teachsim/geometry/distance.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <utility>

namespace teachsim::geometry {

namespace {

double ClosestPointsBruteForce(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                               const Pose3& world_T_b, Eigen::Vector3d* point_a, Eigen::Vector3d* point_b);

constexpr int kMaxIterations = 64;
constexpr double kTouching = 1e-12;  // m: |v| below this counts as intersecting

struct Vertex {
  Eigen::Vector3d w;  // b - a, in A's frame
  Eigen::Vector3d a;  // on A, A's frame
  Eigen::Vector3d b;  // on B, A's frame
  int ia = 0, ib = 0;
};

struct Simplex {
  Vertex v[4];
  double lambda[4] = {1, 0, 0, 0};
  int n = 0;
};

// Closest point to the origin on a segment, triangle or tetrahedron by Voronoi regions
// (Ericson, Real-Time Collision Detection 5.1), reducing the simplex to the supporting subset
// with its barycentric weights. Degenerate (collinear, flat) cases fall back to their faces. The
// result is always a convex combination of the simplex's points, hence a point of C: its norm
// stays an upper bound whatever the rounding, and the certificate in Distance() does the rest.
// A sub-simplex (indices into s.v) with barycentric weights and its point: computed without
// touching the simplex, so the tetrahedron step can compare its faces without copying it.
struct Candidate {
  int index[3] = {0, 0, 0};
  double weight[3] = {1.0, 0.0, 0.0};
  int n = 1;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
};

void Apply(Simplex& s, const Candidate& c) {
  Vertex v[3];
  for (int k = 0; k < c.n; ++k) v[k] = s.v[c.index[k]];
  for (int k = 0; k < c.n; ++k) {
    s.v[k] = v[k];
    s.lambda[k] = c.weight[k];
  }
  s.n = c.n;
}

Candidate One(const Simplex& s, int i) {
  Candidate c;
  c.index[0] = i;
  c.point = s.v[i].w;
  return c;
}

Candidate Two(const Simplex& s, int i, int j, double t) {
  Candidate c;
  c.n = 2;
  c.index[0] = i;
  c.index[1] = j;
  c.weight[0] = 1.0 - t;
  c.weight[1] = t;
  c.point = s.v[i].w + t * (s.v[j].w - s.v[i].w);
  return c;
}

Candidate SegmentCandidate(const Simplex& s, int i, int j) {
  const Eigen::Vector3d& a = s.v[i].w;
  const Eigen::Vector3d ab = s.v[j].w - a;
  const double denom = ab.squaredNorm();
  const double t = denom > 0.0 ? -a.dot(ab) / denom : 0.0;
  if (t <= 0.0) return One(s, i);
  if (t >= 1.0) return One(s, j);
  return Two(s, i, j, t);
}

// Triangle s.v[i], s.v[j], s.v[k].
Candidate TriangleCandidate(const Simplex& s, int i, int j, int k) {
  const Eigen::Vector3d& a = s.v[i].w;
  const Eigen::Vector3d& b = s.v[j].w;
  const Eigen::Vector3d& c = s.v[k].w;
  const Eigen::Vector3d ab = b - a, ac = c - a;
  const double d1 = -ab.dot(a), d2 = -ac.dot(a);
  if (d1 <= 0.0 && d2 <= 0.0) return One(s, i);
  const double d3 = -ab.dot(b), d4 = -ac.dot(b);
  if (d3 >= 0.0 && d4 <= d3) return One(s, j);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return Two(s, i, j, d1 / (d1 - d3));
  const double d5 = -ab.dot(c), d6 = -ac.dot(c);
  if (d6 >= 0.0 && d5 <= d6) return One(s, k);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return Two(s, i, k, d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return Two(s, j, k, (d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double sum = va + vb + vc;
  if (!(sum > 0.0)) {
    // Collinear: the best of the three edges.
    Candidate best = SegmentCandidate(s, i, j);
    for (const Candidate& e : {SegmentCandidate(s, i, k), SegmentCandidate(s, j, k)}) {
      if (e.point.squaredNorm() < best.point.squaredNorm()) best = e;
    }
    return best;
  }
  Candidate out;
  out.n = 3;
  out.index[0] = i;
  out.index[1] = j;
  out.index[2] = k;
  const double v = vb / sum, w = vc / sum;
  out.weight[0] = 1.0 - v - w;
  out.weight[1] = v;
  out.weight[2] = w;
  out.point = a + v * ab + w * ac;
  return out;
}

// Returns true when the origin lies inside the tetrahedron.
bool SolveTetrahedron(Simplex& s, Eigen::Vector3d* closest) {
  static constexpr int kFaces[4][4] = {{0, 1, 2, 3}, {0, 2, 3, 1}, {0, 3, 1, 2}, {1, 3, 2, 0}};  // i j k, opposite
  Candidate best;
  double best_norm = std::numeric_limits<double>::infinity();
  bool any_outside = false;
  const double scale = (s.v[1].w - s.v[0].w).squaredNorm() + (s.v[2].w - s.v[0].w).squaredNorm() +
                       (s.v[3].w - s.v[0].w).squaredNorm();
  for (const auto& f : kFaces) {
    const Eigen::Vector3d& a = s.v[f[0]].w;
    const Eigen::Vector3d n = (s.v[f[1]].w - a).cross(s.v[f[2]].w - a);
    const double side_origin = -n.dot(a);
    const double side_other = n.dot(s.v[f[3]].w - a);
    // Flat tetrahedra (|side_other| tiny) are treated as open on every face.
    const bool flat = std::abs(side_other) <= 1e-14 * scale * std::sqrt(scale);
    if (!flat && side_origin * side_other >= 0.0) continue;  // origin on the inner side of this face
    any_outside = true;
    const Candidate c = TriangleCandidate(s, f[0], f[1], f[2]);
    if (const double norm = c.point.squaredNorm(); norm < best_norm) {
      best_norm = norm;
      best = c;
    }
  }
  if (!any_outside) {
    closest->setZero();
    return true;
  }
  *closest = best.point;
  Apply(s, best);
  return false;
}

bool SolveSimplex(Simplex& s, Eigen::Vector3d* closest) {
  switch (s.n) {
    case 1:
      s.lambda[0] = 1.0;
      *closest = s.v[0].w;
      return false;
    case 2: {
      const Candidate c = SegmentCandidate(s, 0, 1);
      *closest = c.point;
      Apply(s, c);
      return false;
    }
    case 3: {
      const Candidate c = TriangleCandidate(s, 0, 1, 2);
      *closest = c.point;
      Apply(s, c);
      return false;
    }
    default:
      return SolveTetrahedron(s, closest);
  }
}

// The slow, careful solver used once the fast one stalls (flat simplices near parallel faces).
// Closest point to the origin of the hull of s: the least-norm point over all sub-simplices
// whose affine projection of the origin has non-negative barycentric coordinates (at most 15
// subsets). Reduces s to that subset. Returns true when the origin is inside a full tetrahedron.
bool SolveSimplexRobust(Simplex& s, Eigen::Vector3d* closest) {
  const int n = s.n;
  double best_norm = std::numeric_limits<double>::infinity();
  int best_mask = 1;
  double best_lambda[4] = {1, 0, 0, 0};
  Eigen::Vector3d best_point = s.v[0].w;
  bool inside = false;
  for (int mask = 1; mask < (1 << n); ++mask) {
    int idx[4], k = 0;
    for (int i = 0; i < n; ++i) {
      if (mask & (1 << i)) idx[k++] = i;
    }
    double lam[4] = {1, 0, 0, 0};
    Eigen::Vector3d p;
    if (k == 1) {
      p = s.v[idx[0]].w;
    } else {
      const Eigen::Vector3d& p0 = s.v[idx[0]].w;
      Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, 3> e(3, k - 1);
      for (int j = 1; j < k; ++j) e.col(j - 1) = s.v[idx[j]].w - p0;
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3> g = e.transpose() * e;
      Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 3, 1> rhs = -(e.transpose() * p0);
      Eigen::LDLT<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3>> ldlt(g);
      if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > 1e-14)) continue;  // degenerate subset
      Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 3, 1> mu = ldlt.solve(rhs);
      if (!mu.allFinite()) continue;
      double sum = 0.0;
      bool valid = true;
      for (int j = 1; j < k; ++j) {
        lam[j] = mu(j - 1);
        sum += lam[j];
        if (lam[j] < 0.0) valid = false;
      }
      lam[0] = 1.0 - sum;
      if (!valid || lam[0] < 0.0) continue;
      p.setZero();
      for (int j = 0; j < k; ++j) p += lam[j] * s.v[idx[j]].w;
      if (k == 4) {
        inside = true;
        p.setZero();
      }
    }
    double norm = p.squaredNorm();
    if (norm < best_norm) {
      best_norm = norm;
      best_mask = mask;
      best_point = p;
      std::copy(lam, lam + 4, best_lambda);
    }
    if (inside) break;
  }
  Simplex reduced;
  int k = 0;
  for (int i = 0; i < n; ++i) {
    if (best_mask & (1 << i)) {
      reduced.v[k] = s.v[i];
      reduced.lambda[k] = best_lambda[k];
      ++k;
    }
  }
  reduced.n = k;
  s = reduced;
  *closest = best_point;
  return inside;
}

// The feature spanned by a set of distinct vertex indices of p.
Feature FeatureOf(const ConvexPolyhedron& p, int* indices, int count) {
  std::sort(indices, indices + count);
  count = static_cast<int>(std::unique(indices, indices + count) - indices);
  if (count == 1) return {Feature::Type::kVertex, indices[0]};
  if (count == 2) {
    for (int f : p.vertex_faces(indices[0])) {
      for (int e : p.faces()[f].edges) {
        const Edge& edge = p.edges()[e];
        if ((edge.v0 == indices[0] && edge.v1 == indices[1]) || (edge.v0 == indices[1] && edge.v1 == indices[0])) {
          return {Feature::Type::kEdge, e};
        }
      }
    }
  }
  for (int f : p.vertex_faces(indices[0])) {
    const std::vector<int>& fv = p.faces()[f].vertices;
    bool all = true;
    for (int i = 1; i < count && all; ++i) all = std::find(fv.begin(), fv.end(), indices[i]) != fv.end();
    if (all) return {Feature::Type::kFace, f};
  }
  return {Feature::Type::kVertex, indices[0]};
}

}  // namespace

DistanceResult Distance(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                        const Pose3& world_T_b, DistanceCache* cache) {
  const Pose3 a_T_b = world_T_a.Inverse() * world_T_b;
  const Eigen::Matrix3d r_ab = a_T_b.RotationMatrix();
  const Eigen::Vector3d t_ab = a_T_b.translation;
  const auto& va = a.vertices();
  const auto& vb = b.vertices();

  auto make_vertex = [&](int ia, int ib) {
    Vertex v;
    v.ia = ia;
    v.ib = ib;
    v.a = va[ia];
    v.b = r_ab * vb[ib] + t_ab;
    v.w = v.b - v.a;
    return v;
  };
  int hint_a = -1, hint_b = -1;
  // Support of C = B - A in direction d: max over B of d.b, min over A of d.a.
  auto support = [&](const Eigen::Vector3d& d) {
    int ib = b.Support(r_ab.transpose() * d, hint_b);
    int ia = a.Support(-d, hint_a);
    hint_a = ia;
    hint_b = ib;
    return make_vertex(ia, ib);
  };

  Simplex s;
  if (cache != nullptr && cache->count > 0) {
    for (int i = 0; i < cache->count; ++i) {
      int ia = cache->index_a[i], ib = cache->index_b[i];
      if (ia < 0 || ib < 0 || ia >= static_cast<int>(va.size()) || ib >= static_cast<int>(vb.size())) {
        s.n = 0;
        break;
      }
      s.v[s.n++] = make_vertex(ia, ib);
    }
    if (s.n > 0) {
      hint_a = s.v[0].ia;
      hint_b = s.v[0].ib;
    }
  }
  if (s.n == 0) {
    // Start from the direction between the centres.
    Eigen::Vector3d d = (r_ab * b.centroid() + t_ab) - a.centroid();
    if (d.squaredNorm() < 1e-30) d = Eigen::Vector3d::UnitX();
    s.v[0] = support(-d);
    s.n = 1;
  }

  Eigen::Vector3d v;
  bool inside = SolveSimplex(s, &v);
  double lower = 0.0;
  int iterations = 0;
  bool robust = false;  // switched to the careful sub-solver after a stall
  double previous_norm = std::numeric_limits<double>::infinity();
  while (!inside && iterations < kMaxIterations) {
    ++iterations;
    const double vnorm = v.norm();
    if (vnorm <= kTouching) break;
    Vertex w = support(-v);
    lower = std::max(lower, v.dot(w.w) / vnorm);
    if (vnorm - lower <= kDistanceTolerance) break;
    bool repeated = false;
    for (int i = 0; i < s.n; ++i) repeated = repeated || (s.v[i].ia == w.ia && s.v[i].ib == w.ib);
    if (repeated) {
      // No new support point, yet the gap is open: the fast sub-solver lost precision.
      if (robust) break;
      robust = true;
      inside = SolveSimplexRobust(s, &v);
      continue;
    }
    s.v[s.n++] = w;
    inside = robust ? SolveSimplexRobust(s, &v) : SolveSimplex(s, &v);
    const double norm = v.norm();
    if (norm >= previous_norm && norm >= vnorm) {
      if (robust) break;  // no progress
      robust = true;
    }
    previous_norm = std::min(previous_norm, vnorm);
  }
  // Certificate gap still open (never seen on 1e5 test poses): fall back to the exhaustive
  // feature-pair distance, which is exact.
  bool exhaustive = false;
  if (!inside && v.norm() > kTouching && v.norm() - lower > kDistanceTolerance) exhaustive = true;

  DistanceResult result;
  result.iterations = iterations;
  result.exhaustive = exhaustive;
  Eigen::Vector3d pa_world, pb_world;
  if (exhaustive) {
    lower = ClosestPointsBruteForce(a, world_T_a, b, world_T_b, &pa_world, &pb_world);
    v = world_T_a.rotation.conjugate() * (pb_world - pa_world);
  }
  const double upper = v.norm();
  result.intersecting = inside || upper <= kTouching;
  result.upper_bound = result.intersecting ? 0.0 : upper;
  result.distance = result.intersecting ? 0.0 : std::max(0.0, std::min(lower, upper));
  Eigen::Vector3d pa = Eigen::Vector3d::Zero(), pb = Eigen::Vector3d::Zero();
  int ia[4], ib[4];
  for (int i = 0; i < s.n; ++i) {
    pa += s.lambda[i] * s.v[i].a;
    pb += s.lambda[i] * s.v[i].b;
    ia[i] = s.v[i].ia;
    ib[i] = s.v[i].ib;
  }
  result.point_a = exhaustive ? pa_world : world_T_a * pa;
  result.point_b = exhaustive ? pb_world : world_T_a * pb;
  Eigen::Vector3d n_in_a = upper > kTouching ? Eigen::Vector3d(v / upper) : Eigen::Vector3d::UnitZ();
  result.normal = world_T_a.Rotate(n_in_a);
  result.feature_a = FeatureOf(a, ia, s.n);
  result.feature_b = FeatureOf(b, ib, s.n);
  if (cache != nullptr) {
    cache->count = static_cast<std::int8_t>(s.n);
    for (int i = 0; i < s.n; ++i) {
      cache->index_a[i] = static_cast<std::int16_t>(s.v[i].ia);
      cache->index_b[i] = static_cast<std::int16_t>(s.v[i].ib);
    }
  }
  return result;
}

double SegmentSegmentDistance(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& q0,
                              const Eigen::Vector3d& q1, Eigen::Vector3d* closest_p, Eigen::Vector3d* closest_q) {
  // Ericson, Real-Time Collision Detection, 5.1.9, with clamping in both parameters.
  const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  double s = 0.0, t = 0.0;
  if (a <= 1e-30 && e <= 1e-30) {
    s = t = 0.0;
  } else if (a <= 1e-30) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= 1e-30) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;
      s = denom > 0.0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  Eigen::Vector3d cp = p0 + s * d1, cq = q0 + t * d2;
  if (closest_p != nullptr) *closest_p = cp;
  if (closest_q != nullptr) *closest_q = cq;
  return (cp - cq).norm();
}

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c) {
  // Ericson 5.1.5 (Voronoi regions).
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

namespace {
// Distance from p to a convex polygon face when p projects inside it, on its outer side; +inf
// otherwise (the boundary cases are covered by the edge-edge pairs). *foot is the projection.
double PointFaceDistance(const Eigen::Vector3d& p, const std::vector<Eigen::Vector3d>& verts, const Face& face,
                         const Eigen::Matrix3d& r, const Eigen::Vector3d& t, Eigen::Vector3d* foot) {
  const Eigen::Vector3d n = r * face.normal;
  const int m = static_cast<int>(face.vertices.size());
  for (int i = 0; i < m; ++i) {
    Eigen::Vector3d u = r * verts[face.vertices[i]] + t;
    Eigen::Vector3d w = r * verts[face.vertices[(i + 1) % m]] + t;
    if ((w - u).cross(p - u).dot(n) < 0.0) return std::numeric_limits<double>::infinity();
  }
  Eigen::Vector3d on = r * verts[face.vertices[0]] + t;
  const double height = n.dot(p - on);
  if (height < 0.0) return std::numeric_limits<double>::infinity();  // behind the face: not closest
  *foot = p - height * n;
  return height;
}

double ClosestPointsBruteForce(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                               const Pose3& world_T_b, Eigen::Vector3d* point_a, Eigen::Vector3d* point_b) {
  const Eigen::Matrix3d ra = world_T_a.RotationMatrix(), rb = world_T_b.RotationMatrix();
  const Eigen::Vector3d ta = world_T_a.translation, tb = world_T_b.translation;
  std::vector<Eigen::Vector3d> wa, wb;
  for (const auto& v : a.vertices()) wa.push_back(ra * v + ta);
  for (const auto& v : b.vertices()) wb.push_back(rb * v + tb);
  double best = std::numeric_limits<double>::infinity();
  Eigen::Vector3d foot;
  for (const auto& p : wa) {
    for (const Face& f : b.faces()) {
      if (double d = PointFaceDistance(p, b.vertices(), f, rb, tb, &foot); d < best) {
        best = d;
        *point_a = p;
        *point_b = foot;
      }
    }
  }
  for (const auto& p : wb) {
    for (const Face& f : a.faces()) {
      if (double d = PointFaceDistance(p, a.vertices(), f, ra, ta, &foot); d < best) {
        best = d;
        *point_a = foot;
        *point_b = p;
      }
    }
  }
  Eigen::Vector3d cp, cq;
  for (const Edge& ea : a.edges()) {
    for (const Edge& eb : b.edges()) {
      if (double d = SegmentSegmentDistance(wa[ea.v0], wa[ea.v1], wb[eb.v0], wb[eb.v1], &cp, &cq); d < best) {
        best = d;
        *point_a = cp;
        *point_b = cq;
      }
    }
  }
  return best;
}
}  // namespace

double DistanceBruteForce(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                          const Pose3& world_T_b) {
  Eigen::Vector3d pa, pb;
  return ClosestPointsBruteForce(a, world_T_a, b, world_T_b, &pa, &pb);
}

}  // namespace teachsim::geometry
