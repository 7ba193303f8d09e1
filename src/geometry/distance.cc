// GJK (Gilbert, Johnson, Keerthi 1988; van den Bergen's termination) on the Minkowski difference
// C = B - A, in A's frame. Every iterate v is a convex combination of points of C, so |v| is an
// upper bound on the distance; every support point w gives the separating-plane lower bound
// v.w/|v|. We stop when the two agree within kDistanceTolerance and report the lower bound, so
// the result never over-estimates whatever the conditioning of the simplex (near-parallel faces
// give flat simplices: they only cost iterations here, never safety).
#include "teachsim/geometry/distance.h"

#include <Eigen/Dense>

#include <algorithm>
#include <bit>
#include <cmath>
#include <initializer_list>
#include <limits>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace teachsim::geometry {

namespace {

double ClosestPointsBruteForce(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                               const Pose3& world_T_b, Eigen::Vector3d* point_a, Eigen::Vector3d* point_b);

constexpr int kMaxIterations = 64;
constexpr int kTryFeaturesAt = 2;  // GJK iteration at which two boxes try their features
constexpr double kTouching = 1e-12;  // m: |v| below this counts as intersecting

// A point of C = B - A (A's frame) and the support vertices it came from. The points on A and B
// are rebuilt from the indices once at the end, so the simplex moves 32 bytes per vertex.
struct Vertex {
  Eigen::Vector3d w;
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

inline void Apply(Simplex& s, const Candidate& c) {
  Vertex v[3];
  for (int k = 0; k < c.n; ++k) v[k] = s.v[c.index[k]];
  for (int k = 0; k < c.n; ++k) {
    s.v[k] = v[k];
    s.lambda[k] = c.weight[k];
  }
  s.n = c.n;
}

inline Candidate One(const Simplex& s, int i) {
  Candidate c;
  c.index[0] = i;
  c.point = s.v[i].w;
  return c;
}

inline Candidate Two(const Simplex& s, int i, int j, double t) {
  Candidate c;
  c.n = 2;
  c.index[0] = i;
  c.index[1] = j;
  c.weight[0] = 1.0 - t;
  c.weight[1] = t;
  c.point = s.v[i].w + t * (s.v[j].w - s.v[i].w);
  return c;
}

inline Candidate SegmentCandidate(const Simplex& s, int i, int j) {
  const Eigen::Vector3d& a = s.v[i].w;
  const Eigen::Vector3d ab = s.v[j].w - a;
  const double denom = ab.squaredNorm();
  const double t = denom > 0.0 ? -a.dot(ab) / denom : 0.0;
  if (t <= 0.0) return One(s, i);
  if (t >= 1.0) return One(s, j);
  return Two(s, i, j, t);
}

// Triangle s.v[i], s.v[j], s.v[k].
inline Candidate TriangleCandidate(const Simplex& s, int i, int j, int k) {
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

// Returns true when the origin lies inside the tetrahedron. Vertex 3 is the newest: it was found
// beyond the previous triangle (0 1 2) along -v, so in exact arithmetic the origin is on the inner
// side of that face and the closest feature holds vertex 3. That face is therefore tested last,
// and only when the other three leave the origin inside or the tetrahedron is flat (then every
// face counts, as before); a wrong guess costs an iteration, never safety (the certificate).
bool SolveTetrahedron(Simplex& s, Eigen::Vector3d* closest) {
  static constexpr int kFaces[4][4] = {{0, 2, 3, 1}, {0, 3, 1, 2}, {1, 3, 2, 0}, {0, 1, 2, 3}};  // i j k, opposite
  Candidate best;
  double best_norm = std::numeric_limits<double>::infinity();
  bool any_outside = false, any_flat = false;
  const double scale = (s.v[1].w - s.v[0].w).squaredNorm() + (s.v[2].w - s.v[0].w).squaredNorm() +
                       (s.v[3].w - s.v[0].w).squaredNorm();
  const double flat_limit = 1e-14 * scale * std::sqrt(scale);
  for (const auto& f : kFaces) {
    if (f[3] == 3 && any_outside && !any_flat) break;
    const Eigen::Vector3d& a = s.v[f[0]].w;
    const Eigen::Vector3d n = (s.v[f[1]].w - a).cross(s.v[f[2]].w - a);
    const double side_origin = -n.dot(a);
    const double side_other = n.dot(s.v[f[3]].w - a);
    // Flat tetrahedra (|side_other| tiny) are treated as open on every face.
    const bool flat = std::abs(side_other) <= flat_limit;
    any_flat = any_flat || flat;
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

inline bool SolveSimplex(Simplex& s, Eigen::Vector3d* closest) {
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

// The feature spanned by a set of vertex indices of p (count <= 4, duplicates allowed): a
// vertex, the edge joining two, else the face holding them all (else the lowest vertex).
Feature FeatureOf(const ConvexPolyhedron& p, const int* indices, int count) {
  if (p.is_box()) {
    // Box vertex numbering (bit k: sign of coordinate k): an edge joins two vertices differing in
    // one bit, a face holds the vertices that agree in one bit (face 2k + that bit).
    int all_set = 7, any_set = 0;
    for (int i = 0; i < count; ++i) {
      all_set &= indices[i];
      any_set |= indices[i];
    }
    const int differ = all_set ^ any_set;
    if (differ == 0) return {Feature::Type::kVertex, indices[0]};
    if ((differ & (differ - 1)) == 0) {
      if (const int e = p.EdgeBetween(all_set, any_set); e >= 0) return {Feature::Type::kEdge, e};
    }
    const int agree = ~differ & 7;
    if (agree != 0) {
      const int k = std::countr_zero(static_cast<unsigned>(agree));
      return {Feature::Type::kFace, 2 * k + ((all_set >> k) & 1)};
    }
    return {Feature::Type::kVertex, *std::min_element(indices, indices + count)};
  }
  if (p.vertices().size() <= 64) {
    // As a bit set: duplicates merge, the lowest index is the first set bit.
    std::uint64_t wanted = 0;
    for (int i = 0; i < count; ++i) wanted |= std::uint64_t{1} << indices[i];
    const int lowest = std::countr_zero(wanted);
    const std::uint64_t rest = wanted & (wanted - 1);  // without the lowest
    if (rest == 0) return {Feature::Type::kVertex, lowest};
    if ((rest & (rest - 1)) == 0) {
      if (const int e = p.EdgeBetween(lowest, std::countr_zero(rest)); e >= 0) return {Feature::Type::kEdge, e};
    }
    for (int f : p.vertex_faces(lowest)) {
      if ((p.face_vertex_mask(f) & wanted) == wanted) return {Feature::Type::kFace, f};
    }
    return {Feature::Type::kVertex, lowest};
  }
  int sorted[4] = {indices[0], 0, 0, 0};
  int unique = 0;
  for (int i = 0; i < count; ++i) {  // insertion without duplicates
    int j = unique;
    bool duplicate = false;
    for (int k = 0; k < unique; ++k) duplicate = duplicate || sorted[k] == indices[i];
    if (duplicate) continue;
    for (; j > 0 && sorted[j - 1] > indices[i]; --j) sorted[j] = sorted[j - 1];
    sorted[j] = indices[i];
    ++unique;
  }
  count = unique;
  if (count == 1) return {Feature::Type::kVertex, sorted[0]};
  if (count == 2) {
    if (const int e = p.EdgeBetween(sorted[0], sorted[1]); e >= 0) return {Feature::Type::kEdge, e};
  }
  for (int f : p.vertex_faces(sorted[0])) {
    const std::vector<int>& fv = p.faces()[f].vertices;
    bool all = true;
    for (int i = 1; i < count && all; ++i) all = std::find(fv.begin(), fv.end(), sorted[i]) != fv.end();
    if (all) return {Feature::Type::kFace, f};
  }
  return {Feature::Type::kVertex, sorted[0]};
}

// Index of a box's support vertex: bit k set when the direction's k-th component is positive
// (ConvexPolyhedron::Box numbers its vertices that way).
inline int BoxSupport(double dx, double dy, double dz) {
  return (dx > 0.0 ? 1 : 0) | (dy > 0.0 ? 2 : 0) | (dz > 0.0 ? 4 : 0);
}

// A hull's vertices as three columns (x, y, z), padded to a multiple of four with copies of the
// last vertex, for the support scan of cold queries. A cold query scans every vertex at each of
// its support queries (convex-convex bench, 8-40 vertices: about six per polyhedron), so one
// copy per query pays for itself: the scan then needs no shuffles and runs four vertices per step.
struct VertexColumns {
  static constexpr int kCapacity = (ConvexPolyhedron::kMaxHullPoints + 3) / 4 * 4;
  alignas(16) double x[kCapacity];
  alignas(16) double y[kCapacity];
  alignas(16) double z[kCapacity];
  int n = 0;       // vertices
  int padded = 0;  // n rounded up to a multiple of 4

  // False (and nothing copied) when p has more vertices than fit. With r and t, each vertex x is
  // stored as r x + t (B's columns placed in A's frame, once per query: then each support query
  // needs neither the direction turned into B's frame nor its vertex turned back, two matrix
  // products off the chain of dependent steps that a GJK iteration is).
  bool Fill(const ConvexPolyhedron& p, const Eigen::Matrix3d* r = nullptr,
            const Eigen::Vector3d* t = nullptr) {
    n = static_cast<int>(p.vertices().size());
    if (n < 1 || n > kCapacity) return false;
    padded = (n + 3) & ~3;
    const double* v = p.vertices().front().data();  // x y z per vertex (Eigen::Vector3d is packed)
    static_assert(sizeof(Eigen::Vector3d) == 3 * sizeof(double));
    int i = 0;
#if defined(__SSE2__)
    // Two vertices from three loads, (x0 y0) (z0 x1) (y1 z1), into (x0 x1) (y0 y1) (z0 z1).
    auto columns = [&](int at, __m128d* cx, __m128d* cy, __m128d* cz) {
      const __m128d m0 = _mm_loadu_pd(v + 3 * at), m1 = _mm_loadu_pd(v + 3 * at + 2),
                    m2 = _mm_loadu_pd(v + 3 * at + 4);
      *cx = _mm_shuffle_pd(m0, m1, 0b10);
      *cy = _mm_shuffle_pd(m0, m2, 0b01);
      *cz = _mm_shuffle_pd(m1, m2, 0b10);
    };
    if (r == nullptr) {
      for (; i + 2 <= n; i += 2) {
        __m128d cx, cy, cz;
        columns(i, &cx, &cy, &cz);
        _mm_store_pd(x + i, cx);
        _mm_store_pd(y + i, cy);
        _mm_store_pd(z + i, cz);
      }
    } else {
      const Eigen::Matrix3d& m = *r;
      auto row = [&](int k, __m128d cx, __m128d cy, __m128d cz) {
        return _mm_add_pd(
            _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_set1_pd(m(k, 0)), cx), _mm_mul_pd(_mm_set1_pd(m(k, 1)), cy)),
                       _mm_mul_pd(_mm_set1_pd(m(k, 2)), cz)),
            _mm_set1_pd((*t)[k]));
      };
      for (; i + 2 <= n; i += 2) {
        __m128d cx, cy, cz;
        columns(i, &cx, &cy, &cz);
        _mm_store_pd(x + i, row(0, cx, cy, cz));
        _mm_store_pd(y + i, row(1, cx, cy, cz));
        _mm_store_pd(z + i, row(2, cx, cy, cz));
      }
    }
#endif
    for (; i < n; ++i) {
      const double px = v[3 * i], py = v[3 * i + 1], pz = v[3 * i + 2];
      if (r == nullptr) {
        x[i] = px;
        y[i] = py;
        z[i] = pz;
      } else {
        const Eigen::Matrix3d& m = *r;
        x[i] = m(0, 0) * px + m(0, 1) * py + m(0, 2) * pz + t->x();
        y[i] = m(1, 0) * px + m(1, 1) * py + m(1, 2) * pz + t->y();
        z[i] = m(2, 0) * px + m(2, 1) * py + m(2, 2) * pz + t->z();
      }
    }
    for (i = n; i < padded; ++i) {
      x[i] = x[n - 1];
      y[i] = y[n - 1];
      z[i] = z[n - 1];
    }
    return true;
  }

  Eigen::Vector3d Point(int i) const { return {x[i], y[i], z[i]}; }

  // The vertex with the largest dot product with d, the first one on ties (as
  // ConvexPolyhedron::Support: each dot product is summed as (x dx + y dy) + z dz).
  int Support(const Eigen::Vector3d& d) const {
#if defined(__SSE2__)
    // Two vertices per SSE2 register (the baseline x86-64 ISA), two registers in flight: four
    // short dependency chains for the running maxima instead of one long one; the lanes merge
    // with selects, no data-dependent branch (the maximum's position is unpredictable).
    const __m128d dx = _mm_set1_pd(d.x()), dy = _mm_set1_pd(d.y()), dz = _mm_set1_pd(d.z());
    __m128d best0 = _mm_set1_pd(-std::numeric_limits<double>::infinity()), best1 = best0;
    // Per lane, the first index of the group of four where the lane's maximum was last raised:
    // groups only increase, so max(group, better & next group) keeps it without a select.
    __m128d group0 = _mm_setzero_pd(), group1 = group0;
    __m128d at = _mm_setzero_pd();
    const __m128d step = _mm_set1_pd(4.0);
    for (int i = 0; i < padded; i += 4) {
      const __m128d d0 =
          _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_load_pd(x + i), dx), _mm_mul_pd(_mm_load_pd(y + i), dy)),
                     _mm_mul_pd(_mm_load_pd(z + i), dz));
      const __m128d d1 = _mm_add_pd(
          _mm_add_pd(_mm_mul_pd(_mm_load_pd(x + i + 2), dx), _mm_mul_pd(_mm_load_pd(y + i + 2), dy)),
          _mm_mul_pd(_mm_load_pd(z + i + 2), dz));
      const __m128d better0 = _mm_cmpgt_pd(d0, best0), better1 = _mm_cmpgt_pd(d1, best1);
      best0 = _mm_max_pd(d0, best0);  // d where d > best, as `better` says
      best1 = _mm_max_pd(d1, best1);
      group0 = _mm_max_pd(group0, _mm_and_pd(better0, at));
      group1 = _mm_max_pd(group1, _mm_and_pd(better1, at));
      at = _mm_add_pd(at, step);
    }
    // Lane l of register r holds vertex 4 group + 2 r + l.
    __m128d index0 = _mm_add_pd(group0, _mm_set_pd(1.0, 0.0));
    const __m128d index1 = _mm_add_pd(group1, _mm_set_pd(3.0, 2.0));
    auto select = [](__m128d mask, __m128d yes, __m128d no) {
      return _mm_or_pd(_mm_and_pd(mask, yes), _mm_andnot_pd(mask, no));
    };
    // Merge the lanes: the larger dot product, the lower index on ties.
    auto take = [](__m128d dot, __m128d index, __m128d best, __m128d best_index) {
      return _mm_or_pd(_mm_cmpgt_pd(dot, best),
                       _mm_and_pd(_mm_cmpeq_pd(dot, best), _mm_cmplt_pd(index, best_index)));
    };
    const __m128d take1 = take(best1, index1, best0, index0);
    best0 = select(take1, best1, best0);
    index0 = select(take1, index1, index0);
    const __m128d best_high = _mm_unpackhi_pd(best0, best0), index_high = _mm_unpackhi_pd(index0, index0);
    index0 = select(take(best_high, index_high, best0, index0), index_high, index0);
    // A padding copy of the last vertex never beats the lower index it copies; min() says so.
    return std::min(static_cast<int>(_mm_cvtsd_f64(index0)), n - 1);
#else
    int best = 0;
    double best_dot = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) {
      const double dot = x[i] * d.x() + y[i] * d.y() + z[i] * d.z();
      const bool better = dot > best_dot;
      best_dot = better ? dot : best_dot;
      best = better ? i : best;
    }
    return best;
#endif
  }
};

// Closest-feature tracking for two boxes (I-COLLIDE, paper §5.1): when the previous query's
// closest features still bound the answer, the distance costs one feature-pair distance and no
// GJK iteration. A pair is accepted only with the separating-plane certificate GJK uses (each
// box's extreme vertices along the normal are on its feature, and the closest points lie inside
// both features), so the answer is exact: the plane's gap is a lower bound, the two points an
// upper bound, and they agree. Work happens in A's frame, where A's faces are axis-aligned.
struct BoxPair {
  const ConvexPolyhedron& a;
  const ConvexPolyhedron& b;
  const Eigen::Matrix3d& r_ab;  // B's directions and points in A's frame
  const Eigen::Vector3d& t_ab;
  Eigen::Vector3d half_a, half_b;
};

struct FeatureAnswer {
  Feature feature_a, feature_b;
  Eigen::Vector3d point_a, point_b;  // A's frame
  Eigen::Vector3d normal;            // A's frame, unit, from A toward B
  double distance = 0.0;             // the certified plane gap
  int simplex_a[3] = {0, 0, 0}, simplex_b[3] = {0, 0, 0};  // a GJK simplex spanning the features
  int simplex_n = 0;
};

// True when box vertex v (bit k: sign of coordinate k) is extreme along d: bit k set where
// d_k > 0 and clear where d_k < 0; axis `skip` (along the feature) is not checked.
inline bool BoxVertexExtreme(int v, const Eigen::Vector3d& d, int skip = -1) {
  for (int k = 0; k < 3; ++k) {
    if (k == skip) continue;
    if ((v >> k) & 1 ? d[k] < 0.0 : d[k] > 0.0) return false;
  }
  return true;
}

// Three corners of face f of a box that span the triangle holding `point` (box frame, over the
// face): the quad less its corner farthest from the point, whose in-plane signs are the point's
// opposites (Box numbers vertices by their signs). A warm GJK restarted from the simplex of a
// vertex-face pair then starts at the answer.
inline void FaceTriangle(int f, const Eigen::Vector3d& point, int* corners) {
  const int k = f >> 1, i = (k + 1) % 3, j = (k + 2) % 3;
  const int far = ((f & 1) << k) | (point[i] < 0.0 ? 1 << i : 0) | (point[j] < 0.0 ? 1 << j : 0);
  corners[0] = far ^ (1 << i);
  corners[1] = far ^ (1 << j);
  corners[2] = far ^ ((1 << i) | (1 << j));
}

// Vertex ib of B against face f of A. On a failed support check, *better is B's extreme vertex.
bool VertexOfBFaceOfA(const BoxPair& p, int ib, int f, FeatureAnswer* out, int* better) {
  const int k = f >> 1;
  const double s = (f & 1) ? 1.0 : -1.0;
  const Eigen::Vector3d q = p.r_ab * p.b.vertices()[ib] + p.t_ab;
  const double gap = s * q[k] - p.half_a[k];
  if (!(gap > kTouching)) return false;
  const Eigen::Vector3d toward_a = -s * p.r_ab.row(k).transpose();  // B's frame
  if (!BoxVertexExtreme(ib, toward_a)) {
    *better = BoxSupport(toward_a.x(), toward_a.y(), toward_a.z());
    return false;
  }
  const int i = (k + 1) % 3, j = (k + 2) % 3;
  if (std::abs(q[i]) > p.half_a[i] || std::abs(q[j]) > p.half_a[j]) return false;
  out->feature_a = {Feature::Type::kFace, f};
  out->feature_b = {Feature::Type::kVertex, ib};
  out->point_b = q;
  out->point_a = q;
  out->point_a[k] = s * p.half_a[k];
  out->normal = Eigen::Vector3d::Zero();
  out->normal[k] = s;
  out->distance = gap;
  FaceTriangle(f, q, out->simplex_a);
  for (int m = 0; m < 3; ++m) out->simplex_b[m] = ib;
  out->simplex_n = 3;
  return true;
}

// Face f of B against vertex ia of A. On a failed support check, *better is A's extreme vertex.
bool FaceOfBVertexOfA(const BoxPair& p, int f, int ia, FeatureAnswer* out, int* better) {
  const int k = f >> 1;
  const double s = (f & 1) ? 1.0 : -1.0;
  const Eigen::Vector3d& x = p.a.vertices()[ia];
  const Eigen::Vector3d x_in_b = p.r_ab.transpose() * (x - p.t_ab);
  const double gap = s * x_in_b[k] - p.half_b[k];
  if (!(gap > kTouching)) return false;
  const Eigen::Vector3d n_b = s * p.r_ab.col(k);  // B's face normal in A's frame, toward A
  const Eigen::Vector3d toward_b = -n_b;
  if (!BoxVertexExtreme(ia, toward_b)) {
    *better = BoxSupport(toward_b.x(), toward_b.y(), toward_b.z());
    return false;
  }
  const int i = (k + 1) % 3, j = (k + 2) % 3;
  if (std::abs(x_in_b[i]) > p.half_b[i] || std::abs(x_in_b[j]) > p.half_b[j]) return false;
  out->feature_a = {Feature::Type::kVertex, ia};
  out->feature_b = {Feature::Type::kFace, f};
  out->point_a = x;
  out->point_b = x - gap * n_b;
  out->normal = toward_b;
  out->distance = gap;
  FaceTriangle(f, x_in_b, out->simplex_b);
  for (int m = 0; m < 3; ++m) out->simplex_a[m] = ia;
  out->simplex_n = 3;
  return true;
}

// Edge ea of A against edge eb of B.
bool EdgeEdge(const BoxPair& p, int ea, int eb, FeatureAnswer* out) {
  const Edge& edge_a = p.a.edges()[ea];
  const Edge& edge_b = p.b.edges()[eb];
  const Eigen::Vector3d& p0 = p.a.vertices()[edge_a.v0];
  const Eigen::Vector3d da = p.a.vertices()[edge_a.v1] - p0;  // along one axis of A exactly
  const Eigen::Vector3d q0 = p.r_ab * p.b.vertices()[edge_b.v0] + p.t_ab;
  const Eigen::Vector3d db = p.r_ab * p.b.vertices()[edge_b.v1] + p.t_ab - q0;
  const Eigen::Vector3d n = da.cross(db);
  const double aa = da.squaredNorm(), bb = db.squaredNorm(), ab = da.dot(db);
  const double denom = aa * bb - ab * ab;  // = |n|^2
  if (!(denom > 1e-6 * aa * bb)) return false;  // near-parallel edges: GJK decides
  const Eigen::Vector3d r = q0 - p0;
  const double ra = da.dot(r), rb = db.dot(r);
  const double sa = (ra * bb - ab * rb) / denom;  // parameter on A's edge
  const double sb = (ab * ra - aa * rb) / denom;  // parameter on B's edge
  if (!(sa > 0.0 && sa < 1.0 && sb > 0.0 && sb < 1.0)) return false;
  const double side = n.dot(r);
  if (!(std::abs(side) > 0.0)) return false;
  const Eigen::Vector3d m = side > 0.0 ? n : Eigen::Vector3d(-n);  // from A toward B
  const int axis_a = std::countr_zero(static_cast<unsigned>(edge_a.v0 ^ edge_a.v1));
  const int axis_b = std::countr_zero(static_cast<unsigned>(edge_b.v0 ^ edge_b.v1));
  if (!BoxVertexExtreme(edge_a.v0, m, axis_a)) return false;
  if (!BoxVertexExtreme(edge_b.v0, -(p.r_ab.transpose() * m), axis_b)) return false;
  const double norm = std::sqrt(denom);
  const double gap = std::abs(side) / norm;
  if (!(gap > kTouching)) return false;
  out->feature_a = {Feature::Type::kEdge, ea};
  out->feature_b = {Feature::Type::kEdge, eb};
  out->point_a = p0 + sa * da;
  out->point_b = q0 + sb * db;
  out->normal = m / norm;
  out->distance = gap;
  // The simplex spans b0 - a0 + t (b1 - b0) - s (a1 - a0) over one of the two triangles of that
  // parallelogram: the one that holds (sa, sb), so a warm GJK restarted from it starts at the answer.
  const bool far_half = sa + sb > 1.0;
  out->simplex_a[0] = far_half ? edge_a.v1 : edge_a.v0;
  out->simplex_b[0] = far_half ? edge_b.v1 : edge_b.v0;
  out->simplex_a[1] = edge_a.v1;
  out->simplex_b[1] = edge_b.v0;
  out->simplex_a[2] = edge_a.v0;
  out->simplex_b[2] = edge_b.v1;
  out->simplex_n = 3;
  return true;
}

// Vertex ia of A against edge eb of B, or (a_edge) edge ea of A against vertex ib of B: the
// closest point on the edge's segment, certified along the joining direction.
bool VertexEdge(const BoxPair& p, int ia, int eb, FeatureAnswer* out) {
  const Edge& edge = p.b.edges()[eb];
  const Eigen::Vector3d& x = p.a.vertices()[ia];
  const Eigen::Vector3d q0 = p.r_ab * p.b.vertices()[edge.v0] + p.t_ab;
  const Eigen::Vector3d db = p.r_ab * p.b.vertices()[edge.v1] + p.t_ab - q0;
  const double t = (x - q0).dot(db) / db.squaredNorm();
  if (!(t > 0.0 && t < 1.0)) return false;
  const Eigen::Vector3d q = q0 + t * db;
  const Eigen::Vector3d v = q - x;  // from A toward B
  const int axis_b = std::countr_zero(static_cast<unsigned>(edge.v0 ^ edge.v1));
  if (!BoxVertexExtreme(ia, v) || !BoxVertexExtreme(edge.v0, -(p.r_ab.transpose() * v), axis_b)) return false;
  const double gap = v.norm();
  if (!(gap > kTouching)) return false;
  out->feature_a = {Feature::Type::kVertex, ia};
  out->feature_b = {Feature::Type::kEdge, eb};
  out->point_a = x;
  out->point_b = q;
  out->normal = v / gap;
  out->distance = gap;
  out->simplex_a[0] = out->simplex_a[1] = ia;
  out->simplex_b[0] = edge.v0;
  out->simplex_b[1] = edge.v1;
  out->simplex_n = 2;
  return true;
}

bool EdgeVertex(const BoxPair& p, int ea, int ib, FeatureAnswer* out) {
  const Edge& edge = p.a.edges()[ea];
  const Eigen::Vector3d y = p.r_ab * p.b.vertices()[ib] + p.t_ab;
  const Eigen::Vector3d& p0 = p.a.vertices()[edge.v0];
  const Eigen::Vector3d da = p.a.vertices()[edge.v1] - p0;
  const double t = (y - p0).dot(da) / da.squaredNorm();
  if (!(t > 0.0 && t < 1.0)) return false;
  const Eigen::Vector3d x = p0 + t * da;
  const Eigen::Vector3d v = y - x;
  const int axis_a = std::countr_zero(static_cast<unsigned>(edge.v0 ^ edge.v1));
  if (!BoxVertexExtreme(edge.v0, v, axis_a) || !BoxVertexExtreme(ib, -(p.r_ab.transpose() * v))) return false;
  const double gap = v.norm();
  if (!(gap > kTouching)) return false;
  out->feature_a = {Feature::Type::kEdge, ea};
  out->feature_b = {Feature::Type::kVertex, ib};
  out->point_a = x;
  out->point_b = y;
  out->normal = v / gap;
  out->distance = gap;
  out->simplex_a[0] = edge.v0;
  out->simplex_a[1] = edge.v1;
  out->simplex_b[0] = out->simplex_b[1] = ib;
  out->simplex_n = 2;
  return true;
}

bool VertexVertex(const BoxPair& p, int ia, int ib, FeatureAnswer* out) {
  const Eigen::Vector3d& x = p.a.vertices()[ia];
  const Eigen::Vector3d y = p.r_ab * p.b.vertices()[ib] + p.t_ab;
  const Eigen::Vector3d v = y - x;
  if (!BoxVertexExtreme(ia, v) || !BoxVertexExtreme(ib, -(p.r_ab.transpose() * v))) return false;
  const double gap = v.norm();
  if (!(gap > kTouching)) return false;
  out->feature_a = {Feature::Type::kVertex, ia};
  out->feature_b = {Feature::Type::kVertex, ib};
  out->point_a = x;
  out->point_b = y;
  out->normal = v / gap;
  out->distance = gap;
  out->simplex_a[0] = ia;
  out->simplex_b[0] = ib;
  out->simplex_n = 1;
  return true;
}

// Nearly parallel faces (I-COLLIDE's failure case): face fa of A and face fb of B, facing each
// other. The gap along A's face normal is affine over B's face, so its minimum over the overlap
// of the two faces (seen along A's normal) is at a vertex of that overlap: a vertex of B inside
// A's face, a corner of A's face inside B's, or a crossing of their edges. That vertex names the
// feature pair to try (clipping the faces' projections, without building the polygon); the
// certificate in the pair functions decides, and GJK takes over when it does not hold.
bool FaceFace(const BoxPair& p, int fa, int fb, FeatureAnswer* out) {
  const int k = fa >> 1, i = (k + 1) % 3, j = (k + 2) % 3;
  const double s = (fa & 1) ? 1.0 : -1.0;
  const double hi = p.half_a[i], hj = p.half_a[j];
  const Face& face_b = p.b.faces()[fb];
  Eigen::Vector3d q[4];
  for (int m = 0; m < 4; ++m) q[m] = p.r_ab * p.b.vertices()[face_b.vertices[m]] + p.t_ab;
  // B's face plane in A's frame, to lift A's corners onto it: n . x = c.
  const Eigen::Vector3d n_b = ((fb & 1) ? 1.0 : -1.0) * p.r_ab.col(fb >> 1);
  if (!(std::abs(n_b[k]) > 0.5)) return false;  // not facing
  const double c = n_b.dot(q[0]);
  enum class Kind { kVertexB, kCornerA, kCrossing } kind = Kind::kVertexB;
  double best = std::numeric_limits<double>::infinity();
  int best_b = -1, best_corner = 0, cross_edge_b = -1, cross_axis = 0, cross_sign = 0;
  for (int m = 0; m < 4; ++m) {
    if (std::abs(q[m][i]) <= hi && std::abs(q[m][j]) <= hj && s * q[m][k] < best) {
      best = s * q[m][k];
      kind = Kind::kVertexB;
      best_b = m;
    }
  }
  // Corners of A's face inside B's face (seen along A's normal): inside all four edge lines.
  for (int corner = 0; corner < 4; ++corner) {
    const double ci = (corner & 1) ? hi : -hi, cj = (corner & 2) ? hj : -hj;
    // Lift onto B's plane along A's normal.
    const double ck = (c - n_b[i] * ci - n_b[j] * cj) / n_b[k];
    if (!(s * ck < best)) continue;
    bool inside = true;
    for (int m = 0; m < 4 && inside; ++m) {
      const Eigen::Vector3d& u = q[m];
      const Eigen::Vector3d& w = q[(m + 1) & 3];
      const double cross = (w[i] - u[i]) * (cj - u[j]) - (w[j] - u[j]) * (ci - u[i]);
      inside = cross * n_b[k] >= 0.0;  // B's loop turns counter-clockwise about n_b
    }
    if (inside) {
      best = s * ck;
      kind = Kind::kCornerA;
      best_corner = corner;
    }
  }
  // B's edges crossing the lines of A's face edges.
  for (int m = 0; m < 4; ++m) {
    const Eigen::Vector3d& u = q[m];
    const Eigen::Vector3d& w = q[(m + 1) & 3];
    for (int line = 0; line < 4; ++line) {
      const int along = line < 2 ? i : j, other = line < 2 ? j : i;
      const double bound = (line & 1) ? (along == i ? hi : hj) : -(along == i ? hi : hj);
      const double du = u[along] - bound, dw = w[along] - bound;
      if (!(du * dw < 0.0)) continue;
      const double t = du / (du - dw);
      const Eigen::Vector3d x = u + t * (w - u);
      if (std::abs(x[other]) > (other == i ? hi : hj) || !(s * x[k] < best)) continue;
      best = s * x[k];
      kind = Kind::kCrossing;
      cross_edge_b = face_b.edges[m];
      cross_axis = along;
      cross_sign = (line & 1) ? 1 : 0;
    }
  }
  if (!std::isfinite(best)) return false;
  int better = -1;
  const int top = (fa & 1) << k;  // bit k of the vertices of A's face
  switch (kind) {
    case Kind::kVertexB:
      return VertexOfBFaceOfA(p, face_b.vertices[best_b], fa, out, &better);
    case Kind::kCornerA: {
      const int ia = top | ((best_corner & 1) << i) | (((best_corner >> 1) & 1) << j);
      return FaceOfBVertexOfA(p, fb, ia, out, &better);
    }
    case Kind::kCrossing: {
      // A's edge lies on the line: bit cross_axis fixed, running along the third axis.
      const int run = cross_axis == i ? j : i;
      const int v0 = top | (cross_sign << cross_axis);
      const int ea = p.a.EdgeBetween(v0, v0 | (1 << run));
      return ea >= 0 && EdgeEdge(p, ea, cross_edge_b, out);
    }
  }
  return false;
}

// The faces of A and B that face each other most nearly head-on, when their normals are within
// ~5 degrees of opposite (A's frame: B's axis l against A's axis k).
bool FacingFaces(const BoxPair& p, int* fa, int* fb) {
  int k = 0, l = 0;
  double most = 0.0;
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) {
      if (std::abs(p.r_ab(r, col)) > most) {
        most = std::abs(p.r_ab(r, col));
        k = r;
        l = col;
      }
    }
  }
  if (most < 0.996) return false;
  const bool up = p.t_ab[k] > 0.0;  // B beyond A's +k face
  *fa = 2 * k + (up ? 1 : 0);
  // B's face whose outward normal points back toward A.
  const bool b_positive = (p.r_ab(k, l) > 0.0) != up;
  *fb = 2 * l + (b_positive ? 1 : 0);
  return true;
}

// The cached feature pair, or (vertex-face pairs) the same face with the other box's new extreme
// vertex: the step I-COLLIDE takes when a vertex leaves its Voronoi region across the face.
bool TrackPair(const BoxPair& p, const Feature& fa, const Feature& fb, FeatureAnswer* out) {
  int better = -1;
  if (fa.type == Feature::Type::kFace && fb.type == Feature::Type::kVertex) {
    if (VertexOfBFaceOfA(p, fb.index, fa.index, out, &better)) return true;
    return better >= 0 && VertexOfBFaceOfA(p, better, fa.index, out, &better);
  }
  if (fa.type == Feature::Type::kVertex && fb.type == Feature::Type::kFace) {
    if (FaceOfBVertexOfA(p, fb.index, fa.index, out, &better)) return true;
    return better >= 0 && FaceOfBVertexOfA(p, fb.index, better, out, &better);
  }
  if (fa.type == Feature::Type::kEdge && fb.type == Feature::Type::kEdge) return EdgeEdge(p, fa.index, fb.index, out);
  if (fa.type == Feature::Type::kVertex && fb.type == Feature::Type::kEdge) return VertexEdge(p, fa.index, fb.index, out);
  if (fa.type == Feature::Type::kEdge && fb.type == Feature::Type::kVertex) return EdgeVertex(p, fa.index, fb.index, out);
  if (fa.type == Feature::Type::kVertex && fb.type == Feature::Type::kVertex) {
    return VertexVertex(p, fa.index, fb.index, out);
  }
  return false;
}

// The cached pair or its neighbour; else, for nearly parallel faces (edge-face and face-face
// pairs, or a pair that left its region between them), the face-face step.
bool TrackFeatures(const BoxPair& p, const Feature& fa, const Feature& fb, FeatureAnswer* out) {
  if (TrackPair(p, fa, fb, out)) return true;
  int face_a = 0, face_b = 0;
  return FacingFaces(p, &face_a, &face_b) && FaceFace(p, face_a, face_b, out);
}

// Where a point lies against a box's slabs (box frame, half sizes `half`): bit k of *outside is set
// when coordinate k is beyond a slab, bit k of *bits when beyond the + side (a vertex index's bit).
void SlabRegion(const Eigen::Vector3d& point, const Eigen::Vector3d& half, int* outside, int* bits) {
  *outside = 0;
  *bits = 0;
  for (int k = 0; k < 3; ++k) {
    if (point[k] > half[k]) {
      *outside |= 1 << k;
      *bits |= 1 << k;
    } else if (point[k] < -half[k]) {
      *outside |= 1 << k;
    }
  }
}

// B's vertex ib against box A: the feature of A nearest to it (clamping in A's frame: a vertex,
// an edge or a face by how many coordinates lie outside A's slabs), certified as a tracked pair.
bool VertexOfBAgainstA(const BoxPair& p, int ib, FeatureAnswer* out) {
  int outside = 0, bits = 0;
  SlabRegion(p.r_ab * p.b.vertices()[ib] + p.t_ab, p.half_a, &outside, &bits);
  int better = -1;
  switch (std::popcount(static_cast<unsigned>(outside))) {
    case 3:
      return VertexVertex(p, bits, ib, out);
    case 2: {
      const int free_axis = std::countr_zero(static_cast<unsigned>(~outside & 7));
      const int ea = p.a.EdgeBetween(bits, bits | (1 << free_axis));
      return ea >= 0 && EdgeVertex(p, ea, ib, out);
    }
    case 1: {
      const int k = std::countr_zero(static_cast<unsigned>(outside));
      return VertexOfBFaceOfA(p, ib, 2 * k + ((bits >> k) & 1), out, &better);
    }
    default:
      return false;  // inside A
  }
}

// A's vertex ia against box B, as above in B's frame.
bool VertexOfAAgainstB(const BoxPair& p, int ia, FeatureAnswer* out) {
  int outside = 0, bits = 0;
  SlabRegion(p.r_ab.transpose() * (p.a.vertices()[ia] - p.t_ab), p.half_b, &outside, &bits);
  int better = -1;
  switch (std::popcount(static_cast<unsigned>(outside))) {
    case 3:
      return VertexVertex(p, ia, bits, out);
    case 2: {
      const int free_axis = std::countr_zero(static_cast<unsigned>(~outside & 7));
      const int eb = p.b.EdgeBetween(bits, bits | (1 << free_axis));
      return eb >= 0 && VertexEdge(p, ia, eb, out);
    }
    case 1: {
      const int l = std::countr_zero(static_cast<unsigned>(outside));
      return FaceOfBVertexOfA(p, 2 * l + ((bits >> l) & 1), ia, out, &better);
    }
    default:
      return false;  // inside B
  }
}

// Cold queries on two boxes: the separating axis theorem's 15 axes (A's 3 face normals, B's 3,
// and the 9 cross products of their edge directions) in A's frame. The axis of largest separation
// names a feature pair: a face of one box and the other box's extreme vertex along its normal, or
// an edge of each along their cross product. When the closest features are such a pair (vertex-face
// and edge-edge, the common cases), that separation is the distance, and the pair functions
// certify it as they certify tracked features (GJK's separating-plane certificate: exact, never an
// over-estimate); otherwise (vertex-vertex, vertex-edge) they refuse and GJK decides, starting from
// the axis. *axis (A's frame, from A toward B) is set whenever the boxes are separated along it.
bool SeparatingAxisFeatures(const BoxPair& p, int kind, int best_k, int best_l, FeatureAnswer* out,
                            Eigen::Vector3d* axis);

bool SeparatingAxisPair(const BoxPair& p, FeatureAnswer* out, Eigen::Vector3d* axis) {
  const Eigen::Matrix3d& r = p.r_ab;
  const Eigen::Vector3d& t = p.t_ab;
  const Eigen::Vector3d& ha = p.half_a;
  const Eigen::Vector3d& hb = p.half_b;
  const Eigen::Matrix3d abs_r = r.cwiseAbs();
  enum class Kind { kFaceA, kFaceB, kEdges } kind = Kind::kFaceA;
  double best = -std::numeric_limits<double>::infinity();
  int best_k = 0, best_l = 0;
  for (int k = 0; k < 3; ++k) {
    const double sep = std::abs(t[k]) - ha[k] - abs_r.row(k).dot(hb);
    if (sep > best) {
      best = sep;
      kind = Kind::kFaceA;
      best_k = k;
    }
  }
  const Eigen::Vector3d t_in_b = r.transpose() * t;
  for (int l = 0; l < 3; ++l) {
    const double sep = std::abs(t_in_b[l]) - hb[l] - abs_r.col(l).dot(ha);
    if (sep > best) {
      best = sep;
      kind = Kind::kFaceB;
      best_l = l;
    }
  }
  // Edge k of A against edge l of B: n = e_k x r.col(l), |n|^2 = 1 - r(k,l)^2 (Gottschalk's OBB
  // terms); nearly parallel edges are left to the face axes.
  for (int k = 0; k < 3; ++k) {
    const int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
    for (int l = 0; l < 3; ++l) {
      const double norm2 = 1.0 - r(k, l) * r(k, l);
      if (!(norm2 > 1e-6)) continue;
      const int l1 = (l + 1) % 3, l2 = (l + 2) % 3;
      const double along = t[k2] * r(k1, l) - t[k1] * r(k2, l);
      const double radii =
          ha[k1] * abs_r(k2, l) + ha[k2] * abs_r(k1, l) + hb[l1] * abs_r(k, l2) + hb[l2] * abs_r(k, l1);
      const double sep = (std::abs(along) - radii) / std::sqrt(norm2);
      if (sep > best) {
        best = sep;
        kind = Kind::kEdges;
        best_k = k;
        best_l = l;
      }
    }
  }
  if (!(best > kTouching)) return false;  // touching or overlapping: GJK says which
  if (SeparatingAxisFeatures(p,
                             kind == Kind::kFaceA   ? 0
                             : kind == Kind::kFaceB ? 1
                                                    : 2,
                             best_k, best_l, out, axis)) {
    return true;
  }
  // Not a face or edge-edge pair: most often a vertex of one box against a vertex or an edge of
  // the other. Each box's extreme vertex along the axis, against the other box's nearest feature.
  const Eigen::Vector3d toward_a = -(r.transpose() * *axis);  // B's frame
  if (VertexOfBAgainstA(p, BoxSupport(toward_a.x(), toward_a.y(), toward_a.z()), out)) return true;
  return VertexOfAAgainstB(p, BoxSupport(axis->x(), axis->y(), axis->z()), out);
}

// The feature pair that SeparatingAxisPair's best axis names (kind 0: A's face axis k, 1: B's face
// axis l, 2: edge k of A and edge l of B), certified; *axis is set to that axis.
bool SeparatingAxisFeatures(const BoxPair& p, int kind, int best_k, int best_l, FeatureAnswer* out,
                            Eigen::Vector3d* axis) {
  const Eigen::Matrix3d& r = p.r_ab;
  const Eigen::Vector3d& t = p.t_ab;
  int better = -1;
  switch (kind) {
    case 0: {
      const int k = best_k;
      const double s = t[k] > 0.0 ? 1.0 : -1.0;  // B beyond A's +k face
      *axis = Eigen::Vector3d::Zero();
      (*axis)[k] = s;
      const Eigen::Vector3d toward_a = -s * r.row(k).transpose();  // B's frame
      const int ib = BoxSupport(toward_a.x(), toward_a.y(), toward_a.z());
      return VertexOfBFaceOfA(p, ib, 2 * k + (t[k] > 0.0 ? 1 : 0), out, &better);
    }
    case 1: {
      const int l = best_l;
      // B's face whose outward normal points back toward A.
      const double s = r.col(l).dot(t) < 0.0 ? 1.0 : -1.0;
      const Eigen::Vector3d toward_b = -s * r.col(l);  // A's frame
      *axis = toward_b;
      const int ia = BoxSupport(toward_b.x(), toward_b.y(), toward_b.z());
      return FaceOfBVertexOfA(p, 2 * l + (s > 0.0 ? 1 : 0), ia, out, &better);
    }
    default: {
      const int k = best_k, l = best_l;
      Eigen::Vector3d n = Eigen::Vector3d::Unit(k).cross(r.col(l));
      if (n.dot(t) < 0.0) n = -n;  // from A toward B
      *axis = n.normalized();
      // Each box's edge along its axis k (l) that is extreme along n (-n for B).
      const int v0 = BoxSupport(n.x(), n.y(), n.z()) & ~(1 << k);
      const Eigen::Vector3d m = -(r.transpose() * n);
      const int w0 = BoxSupport(m.x(), m.y(), m.z()) & ~(1 << l);
      const int ea = p.a.EdgeBetween(v0, v0 | (1 << k));
      const int eb = p.b.EdgeBetween(w0, w0 | (1 << l));
      return ea >= 0 && eb >= 0 && EdgeEdge(p, ea, eb, out);
    }
  }
  return false;
}

// A result from a certified feature pair; the cache then holds a simplex spanning that pair.
DistanceResult FeatureResult(const Pose3& world_T_a, const FeatureAnswer& answer, DistanceCache* cache) {
  DistanceResult result;
  const Eigen::Matrix3d r_world_a = world_T_a.rotation.toRotationMatrix();
  result.point_a = r_world_a * answer.point_a + world_T_a.translation;
  result.point_b = r_world_a * answer.point_b + world_T_a.translation;
  result.normal = r_world_a * answer.normal;
  result.upper_bound = (answer.point_b - answer.point_a).norm();
  result.distance = std::min(answer.distance, result.upper_bound);
  result.feature_a = answer.feature_a;
  result.feature_b = answer.feature_b;
  if (cache != nullptr && (cache->count == 0 || cache->feature_a != answer.feature_a ||
                           cache->feature_b != answer.feature_b)) {
    cache->count = static_cast<std::int8_t>(answer.simplex_n);
    for (int i = 0; i < answer.simplex_n; ++i) {
      cache->index_a[i] = static_cast<std::int16_t>(answer.simplex_a[i]);
      cache->index_b[i] = static_cast<std::int16_t>(answer.simplex_b[i]);
    }
    cache->feature_a = answer.feature_a;
    cache->feature_b = answer.feature_b;
  }
  return result;
}

}  // namespace

DistanceResult Distance(const ConvexPolyhedron& a, const Pose3& world_T_a, const ConvexPolyhedron& b,
                        const Pose3& world_T_b, DistanceCache* cache) {
  // B's placement in A's frame, once per query: GJK runs in A's frame, so A's support points are
  // its own vertices and B's are one rotation away (r_ab maps B's directions and points).
  const Eigen::Quaterniond q_a_world = world_T_a.rotation.conjugate();
  const Eigen::Matrix3d r_ab = (q_a_world * world_T_b.rotation).toRotationMatrix();
  const Eigen::Vector3d t_ab = q_a_world * (world_T_b.translation - world_T_a.translation);
  const Eigen::Vector3d* va = a.vertices().data();
  const Eigen::Vector3d* vb = b.vertices().data();
  const int na = static_cast<int>(a.vertices().size());
  const int nb = static_cast<int>(b.vertices().size());
  const bool box_a = a.is_box(), box_b = b.is_box();

  // GJK's first direction (A's frame, from A toward B) when a cold box-box query found one.
  Eigen::Vector3d start_axis = Eigen::Vector3d::Zero();
  if (box_a && box_b) {
    const BoxPair pair{a, b, r_ab, t_ab, a.local_bounds().max, b.local_bounds().max};
    FeatureAnswer answer;
    if (cache != nullptr && cache->count > 0) {
      if (TrackFeatures(pair, cache->feature_a, cache->feature_b, &answer)) {
        return FeatureResult(world_T_a, answer, cache);
      }
    } else if (int face_a = 0, face_b = 0;
               FacingFaces(pair, &face_a, &face_b) && FaceFace(pair, face_a, face_b, &answer)) {
      // Cold, nearly parallel faces: where GJK would walk across the flat simplices.
      return FeatureResult(world_T_a, answer, cache);
    } else if (SeparatingAxisPair(pair, &answer, &start_axis)) {
      return FeatureResult(world_T_a, answer, cache);
    }
  }

  auto point_b = [&](int ib) -> Eigen::Vector3d { return r_ab * vb[ib] + t_ab; };
  // Hill-climbing hints only on warm queries: a cold query's first directions jump across the
  // polyhedron, where a climb from the last support vertex takes many dependent steps and the
  // scan is faster (convex-convex bench, 8-40 vertices: about 2x).
  int hint_a = -1, hint_b = -1;
  bool climb = false;
  // Cold queries scan column copies of the hulls' vertices (see VertexColumns); warm ones climb
  // from the cached support vertices or scan the few vertices in place.
  const bool warm = cache != nullptr && cache->count > 0;
  VertexColumns columns_a, columns_b;
  const bool scan_a = !box_a && !warm && columns_a.Fill(a);
  const bool scan_b = !box_b && !warm && columns_b.Fill(b, &r_ab, &t_ab);  // B's columns in A's frame
  // Support of C = B - A in direction d (A's frame): max over B of d.b, min over A of d.a.
  auto support = [&](const Eigen::Vector3d& d) {
    Vertex out;
    out.ia = box_a    ? BoxSupport(-d.x(), -d.y(), -d.z())
             : scan_a ? columns_a.Support(-d)
                      : a.Support(-d, hint_a);
    if (scan_b) {
      out.ib = columns_b.Support(d);
      out.w = columns_b.Point(out.ib) - va[out.ia];
      return out;
    }
    const Eigen::Vector3d d_in_b = r_ab.transpose() * d;
    out.ib = box_b ? BoxSupport(d_in_b.x(), d_in_b.y(), d_in_b.z()) : b.Support(d_in_b, hint_b);
    if (climb) {
      hint_a = out.ia;
      hint_b = out.ib;
    }
    out.w = point_b(out.ib) - va[out.ia];
    return out;
  };

  Simplex s;
  if (cache != nullptr && cache->count > 0) {
    for (int i = 0; i < cache->count; ++i) {
      const int ia = cache->index_a[i], ib = cache->index_b[i];
      if (ia < 0 || ib < 0 || ia >= na || ib >= nb) {
        s.n = 0;
        break;
      }
      Vertex& x = s.v[s.n++];
      x.ia = ia;
      x.ib = ib;
      x.w = point_b(ib) - va[ia];
    }
    if (s.n > 0) {
      hint_a = s.v[0].ia;
      hint_b = s.v[0].ib;
      climb = true;
    }
  }
  if (s.n == 0) {
    // Start from the separating axis, else the direction between the centres.
    Eigen::Vector3d d = start_axis.squaredNorm() > 0.0
                            ? start_axis
                            : Eigen::Vector3d((r_ab * b.centroid() + t_ab) - a.centroid());
    if (d.squaredNorm() < 1e-30) d = Eigen::Vector3d::UnitX();
    s.v[0] = support(-d);
    s.n = 1;
  }

  // The warm path is the first pass of this loop: the cached simplex, re-posed, gives v, one
  // support query tests its separating plane, and a still-valid certificate ends the query.
  Eigen::Vector3d v;
  bool inside = SolveSimplex(s, &v);
  double lower = 0.0;
  int iterations = 0;
  bool robust = false;  // switched to the careful sub-solver after a stall
  double previous_norm2 = std::numeric_limits<double>::infinity();
  while (!inside && iterations < kMaxIterations) {
    ++iterations;
    const double vnorm2 = v.squaredNorm();
    if (vnorm2 <= kTouching * kTouching) break;
    const Vertex w = support(-v);
    const double vw = v.dot(w.w);
    // The bound itself needs |v| (a square root and a division); the stopping test, written as
    // |v|^2 - v.w <= tol |v| (the same up to rounding, which only moves the stop), waits for
    // neither, and the loop runs ahead of them.
    const double vnorm = std::sqrt(vnorm2);
    lower = std::max(lower, vw / vnorm);
    if (vnorm2 - vw <= kDistanceTolerance * vnorm && vnorm - lower <= kDistanceTolerance) break;
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
    if (box_a && box_b && iterations == kTryFeaturesAt && !inside && s.n < 4) {
      // Two boxes: once the simplex has settled, its features usually are the closest pair, and
      // certifying them costs less than the iterations GJK needs to close its gap.
      int fa_idx[4], fb_idx[4];
      for (int i = 0; i < s.n; ++i) {
        fa_idx[i] = s.v[i].ia;
        fb_idx[i] = s.v[i].ib;
      }
      const BoxPair pair{a, b, r_ab, t_ab, a.local_bounds().max, b.local_bounds().max};
      FeatureAnswer answer;
      if (TrackPair(pair, FeatureOf(a, fa_idx, s.n), FeatureOf(b, fb_idx, s.n), &answer)) {
        DistanceResult r = FeatureResult(world_T_a, answer, cache);
        r.iterations = iterations;
        return r;
      }
    }
    const double norm2 = v.squaredNorm();
    if (norm2 >= previous_norm2 && norm2 >= vnorm2) {
      if (robust) break;  // no progress
      robust = true;
    }
    previous_norm2 = std::min(previous_norm2, vnorm2);
  }
  // Certificate gap still open (never seen on 1e5 test poses): fall back to the exhaustive
  // feature-pair distance, which is exact.
  bool exhaustive = false;
  if (!inside && v.norm() > kTouching && v.norm() - lower > kDistanceTolerance) exhaustive = true;

  DistanceResult result;
  result.iterations = iterations;
  result.exhaustive = exhaustive;
  const Eigen::Matrix3d r_world_a = world_T_a.rotation.toRotationMatrix();
  Eigen::Vector3d pa_world, pb_world;
  if (exhaustive) {
    lower = ClosestPointsBruteForce(a, world_T_a, b, world_T_b, &pa_world, &pb_world);
    v = r_world_a.transpose() * (pb_world - pa_world);
  }
  const double upper = v.norm();
  result.intersecting = inside || upper <= kTouching;
  result.upper_bound = result.intersecting ? 0.0 : upper;
  result.distance = result.intersecting ? 0.0 : std::max(0.0, std::min(lower, upper));
  // v = sum lambda_i (b_i - a_i) = point_b - point_a in A's frame, so only A's point is rebuilt.
  const Eigen::Vector3d v_world = r_world_a * v;
  if (exhaustive) {
    result.point_a = pa_world;
    result.point_b = pb_world;
  } else {
    Eigen::Vector3d pa = s.lambda[0] * va[s.v[0].ia];
    for (int i = 1; i < s.n; ++i) pa += s.lambda[i] * va[s.v[i].ia];
    result.point_a = r_world_a * pa + world_T_a.translation;
    result.point_b = result.point_a + v_world;
  }
  result.normal = upper > kTouching ? Eigen::Vector3d(v_world / upper) : Eigen::Vector3d(r_world_a.col(2));
  int ia[4] = {0, 0, 0, 0}, ib[4] = {0, 0, 0, 0};
  for (int i = 0; i < s.n; ++i) {
    ia[i] = s.v[i].ia;
    ib[i] = s.v[i].ib;
  }
  // The same support vertices as the cached simplex span the same features (the common case of
  // a warm query: the closest features did not change, as I-COLLIDE's feature tracking).
  bool same = cache != nullptr && cache->count == s.n;
  for (int i = 0; same && i < s.n; ++i) same = cache->index_a[i] == ia[i] && cache->index_b[i] == ib[i];
  if (same) {
    result.feature_a = cache->feature_a;
    result.feature_b = cache->feature_b;
  } else {
    result.feature_a = FeatureOf(a, ia, s.n);
    result.feature_b = FeatureOf(b, ib, s.n);
  }
  if (cache != nullptr && !same) {
    cache->count = static_cast<std::int8_t>(s.n);
    for (int i = 0; i < s.n; ++i) {
      cache->index_a[i] = static_cast<std::int16_t>(s.v[i].ia);
      cache->index_b[i] = static_cast<std::int16_t>(s.v[i].ib);
    }
    cache->feature_a = result.feature_a;
    cache->feature_b = result.feature_b;
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
