#include "teachsim/vision/camera.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace teachsim::vision {

namespace {
bool Finite(double v) { return std::isfinite(v); }
}  // namespace

Result<Camera> Camera::FromSpec(const scene::CameraSpec& spec) {
  const std::string where = "camera '" + spec.name + "'";
  for (double v : {spec.fx, spec.fy, spec.cx, spec.cy, spec.k1, spec.k2, spec.p1, spec.p2, spec.k3}) {
    if (!Finite(v)) return Status::InvalidInput(where + ": intrinsics and distortion must be finite");
  }
  if (spec.fx <= 0 || spec.fy <= 0) {
    return Status::InvalidInput(where + ": fx and fy must be > 0, got " + json::FormatNumber(spec.fx) + ", " +
                                json::FormatNumber(spec.fy));
  }
  if (spec.width <= 0 || spec.height <= 0) {
    return Status::InvalidInput(where + ": width and height must be > 0, got " + std::to_string(spec.width) +
                                "x" + std::to_string(spec.height));
  }
  if (!spec.world_T_camera.IsValid()) {
    return Status::InvalidInput(where + ": pose must be finite with a unit quaternion");
  }
  if (!(spec.gamma >= kMinGamma && spec.gamma <= kMaxGamma)) {
    return Status::InvalidInput(where + ": gamma must be in [" + json::FormatNumber(kMinGamma) + ", " +
                                json::FormatNumber(kMaxGamma) + "], got " + json::FormatNumber(spec.gamma));
  }
  Camera camera({spec.fx, spec.fy, spec.cx, spec.cy}, {spec.k1, spec.k2, spec.p1, spec.p2, spec.k3},
                spec.world_T_camera, spec.width, spec.height);
  camera.set_gamma(spec.gamma);
  return camera;
}

Camera Camera::WithPose(const geometry::Pose3& world_T_camera) const {
  Camera moved(intrinsics_, distortion_, world_T_camera, width_, height_);
  moved.gamma_ = gamma_;
  return moved;
}

void Camera::set_gamma(double gamma) {
  TEACHSIM_CHECK(gamma >= kMinGamma && gamma <= kMaxGamma);
  gamma_ = gamma;
}

Camera::Camera(const Intrinsics& intrinsics, const Distortion& distortion,
               const geometry::Pose3& world_T_camera, int width, int height)
    : intrinsics_(intrinsics),
      distortion_(distortion),
      world_T_camera_(world_T_camera),
      camera_T_world_(world_T_camera.Inverse()),
      width_(width),
      height_(height) {
  TEACHSIM_CHECK(intrinsics.fx > 0 && intrinsics.fy > 0 && width > 0 && height > 0);
  // The view (SegmentInView): the picture [-0.5, width - 0.5) x [-0.5, height - 0.5) in distorted
  // normalized coordinates, grown by half its size on every side (undistortion moves the picture's
  // border outwards under barrel distortion: by a tenth in its corners at k1 = -0.25).
  const Eigen::Vector2d lo((-0.5 - intrinsics.cx) / intrinsics.fx, (-0.5 - intrinsics.cy) / intrinsics.fy);
  const Eigen::Vector2d hi((width - 0.5 - intrinsics.cx) / intrinsics.fx,
                           (height - 0.5 - intrinsics.cy) / intrinsics.fy);
  view_lo_ = lo - 0.5 * (hi - lo);
  view_hi_ = hi + 0.5 * (hi - lo);
  // The first radius at which the radial term r (1 + k1 r^2 + k2 r^4 + k3 r^6) stops growing (its
  // derivative 1 + 3 k1 r^2 + 5 k2 r^4 + 7 k3 r^6 reaches 0), looked for out to r = 10 in steps of
  // 0.001; the view keeps within 0.98 of it.
  const Distortion& d = distortion_;
  view_radius_ = std::numeric_limits<double>::infinity();
  for (int i = 1; i <= 10000; ++i) {
    const double r2 = 1e-6 * i * i;
    if (1 + r2 * (3 * d.k1 + r2 * (5 * d.k2 + r2 * 7 * d.k3)) <= 0) {
      view_radius_ = 0.98 * std::sqrt(r2);
      break;
    }
  }
}

scene::CameraSpec Camera::ToSpec(const std::string& name) const {
  scene::CameraSpec spec;
  spec.name = name;
  spec.width = width_;
  spec.height = height_;
  spec.fx = intrinsics_.fx;
  spec.fy = intrinsics_.fy;
  spec.cx = intrinsics_.cx;
  spec.cy = intrinsics_.cy;
  spec.k1 = distortion_.k1;
  spec.k2 = distortion_.k2;
  spec.p1 = distortion_.p1;
  spec.p2 = distortion_.p2;
  spec.k3 = distortion_.k3;
  spec.gamma = gamma_;
  spec.world_T_camera = world_T_camera_;
  return spec;
}

Eigen::Matrix3d Camera::K() const {
  Eigen::Matrix3d k;
  k << intrinsics_.fx, 0, intrinsics_.cx, 0, intrinsics_.fy, intrinsics_.cy, 0, 0, 1;
  return k;
}

namespace {

// Brown-Conrady distortion of normalized coordinates n and, where `jacobian` is given, its
// derivative there: one evaluation of the shared terms for Newton's steps.
Eigen::Vector2d DistortAt(const Distortion& d, const Eigen::Vector2d& n, Eigen::Matrix2d* jacobian) {
  const double x = n.x(), y = n.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  if (jacobian != nullptr) {
    const double dradial_dr2 = d.k1 + r2 * (2 * d.k2 + 3 * r2 * d.k3);
    // d(r2)/dx = 2x, d(r2)/dy = 2y
    Eigen::Matrix2d& j = *jacobian;
    j(0, 0) = radial + x * dradial_dr2 * 2 * x + 2 * d.p1 * y + d.p2 * (2 * x + 4 * x);
    j(0, 1) = x * dradial_dr2 * 2 * y + 2 * d.p1 * x + d.p2 * 2 * y;
    j(1, 0) = y * dradial_dr2 * 2 * x + d.p1 * 2 * x + 2 * d.p2 * y;
    j(1, 1) = radial + y * dradial_dr2 * 2 * y + d.p1 * (2 * y + 4 * y) + 2 * d.p2 * x;
  }
  return {x * radial + 2 * d.p1 * x * y + d.p2 * (r2 + 2 * x * x),
          y * radial + d.p1 * (r2 + 2 * y * y) + 2 * d.p2 * x * y};
}

}  // namespace

Eigen::Vector2d Camera::Distort(const Eigen::Vector2d& n) const { return DistortAt(distortion_, n, nullptr); }

Eigen::Matrix2d Camera::DistortJacobian(const Eigen::Vector2d& n) const {
  Eigen::Matrix2d j;
  DistortAt(distortion_, n, &j);
  return j;
}

namespace {

// A lens without tangential terms moves each point along its own radius: undistorting is then the
// root r of the radius' map f(r) = r (1 + k1 r^2 + k2 r^4 + k3 r^6) = |distorted|, found by Newton
// from r_start, and a scaling. The same answer and the same checks as the 2-D Newton below (the
// residual |f(r) - |distorted|| is the 2-D residual's size; the 2-D Jacobian's determinant is
// radial * f'(r)) for less than half the time (docs/benchmarks.md, `bench render`): the renderer
// undistorts every sample of every image, the line stage every edge point.
// `rd`: |distorted|, which both callers have already.
std::optional<Eigen::Vector2d> UndistortRadial(const Distortion& d, const Eigen::Vector2d& distorted,
                                               double rd, double r_start) {
  if (rd == 0) return distorted;
  double r = std::isfinite(r_start) ? r_start : rd;
  double radial = 1, slope = 1;
  auto residual_at = [&](double at) {
    const double r2 = at * at;
    radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
    slope = radial + 2 * r2 * (d.k1 + r2 * (2 * d.k2 + 3 * r2 * d.k3));
    return at * radial - rd;
  };
  double residual = residual_at(r);
  for (int i = 0; i < 30 && !(std::abs(residual) < 1e-14 * (1 + rd)); ++i) {
    if (!(std::abs(radial * slope) > 1e-12)) return std::nullopt;
    r -= residual / slope;
    if (!std::isfinite(r)) return std::nullopt;
    residual = residual_at(r);
  }
  if (std::abs(residual) > 1e-9 * (1 + rd)) return std::nullopt;
  if (radial * slope <= 0) return std::nullopt;
  return Eigen::Vector2d(distorted * (r / rd));
}

}  // namespace

std::optional<Eigen::Vector2d> Camera::Undistort(const Eigen::Vector2d& distorted) const {
  if (distortion_.IsZero()) return distorted;
  const Distortion& d = distortion_;
  if (d.IsRadial()) {
    // OpenCV's fixed-point iteration, as below, on the radius alone.
    const double rd = distorted.norm();
    double r = rd;
    for (int i = 0; i < 5; ++i) {
      const double r2 = r * r;
      const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
      if (!(radial > 0)) break;
      r = rd / radial;
    }
    return UndistortRadial(d, distorted, rd, r);
  }
  // OpenCV's fixed-point iteration (cvUndistortPointsInternal) for a start near the right branch.
  Eigen::Vector2d n = distorted;
  for (int i = 0; i < 5; ++i) {
    const double r2 = n.squaredNorm();
    const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
    if (!(radial > 0)) break;
    const double dx = 2 * d.p1 * n.x() * n.y() + d.p2 * (r2 + 2 * n.x() * n.x());
    const double dy = d.p1 * (r2 + 2 * n.y() * n.y()) + 2 * d.p2 * n.x() * n.y();
    n = Eigen::Vector2d((distorted.x() - dx) / radial, (distorted.y() - dy) / radial);
  }
  if (!n.allFinite()) n = distorted;
  return Undistort(distorted, n);
}

std::optional<Eigen::Vector2d> Camera::Undistort(const Eigen::Vector2d& distorted,
                                                 const Eigen::Vector2d& start) const {
  if (distortion_.IsZero()) return distorted;
  if (distortion_.IsRadial()) {
    const double rd = distorted.norm();
    return UndistortRadial(distortion_, distorted, rd, rd > 0 ? start.dot(distorted) / rd : 0);
  }
  Eigen::Vector2d n = start.allFinite() ? start : distorted;
  // Gauss-Newton (a square system: Newton) to full precision. The residual and derivative at the
  // last point serve the checks below.
  Eigen::Matrix2d j;
  Eigen::Vector2d residual = DistortAt(distortion_, n, &j) - distorted;
  for (int i = 0; i < 30 && !(residual.norm() < 1e-14 * (1 + distorted.norm())); ++i) {
    const double det = j.determinant();
    if (!(std::abs(det) > 1e-12)) return std::nullopt;
    n -= j.inverse() * residual;
    if (!n.allFinite()) return std::nullopt;
    residual = DistortAt(distortion_, n, &j) - distorted;
  }
  // Reject a root beyond the fold of the polynomial (the map is not orientation preserving there)
  // and a non-converged one.
  if (residual.norm() > 1e-9 * (1 + distorted.norm())) return std::nullopt;
  if (j.determinant() <= 0) return std::nullopt;
  return n;
}

Eigen::Vector2d Camera::NormalizedToPixel(const Eigen::Vector2d& normalized) const {
  const Eigen::Vector2d dn = Distort(normalized);
  return {intrinsics_.fx * dn.x() + intrinsics_.cx, intrinsics_.fy * dn.y() + intrinsics_.cy};
}

std::optional<Eigen::Vector2d> Camera::PixelToNormalized(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d distorted((pixel.x() - intrinsics_.cx) / intrinsics_.fx,
                                  (pixel.y() - intrinsics_.cy) / intrinsics_.fy);
  return Undistort(distorted);
}

std::optional<Eigen::Vector2d> Camera::UndistortPixel(const Eigen::Vector2d& pixel) const {
  auto n = PixelToNormalized(pixel);
  if (!n) return std::nullopt;
  return Eigen::Vector2d(intrinsics_.fx * n->x() + intrinsics_.cx, intrinsics_.fy * n->y() + intrinsics_.cy);
}

Eigen::Vector2d Camera::DistortPixel(const Eigen::Vector2d& undistorted) const {
  return NormalizedToPixel({(undistorted.x() - intrinsics_.cx) / intrinsics_.fx,
                            (undistorted.y() - intrinsics_.cy) / intrinsics_.fy});
}

std::optional<Eigen::Vector2d> Camera::ProjectFromCamera(const Eigen::Vector3d& p_in_camera,
                                                         double min_depth_m) const {
  if (!(p_in_camera.z() > min_depth_m)) return std::nullopt;
  return NormalizedToPixel(p_in_camera.head<2>() / p_in_camera.z());
}

std::optional<Eigen::Vector2d> Camera::Project(const Eigen::Vector3d& p_in_world, double min_depth_m) const {
  return ProjectFromCamera(camera_T_world_ * p_in_world, min_depth_m);
}

std::optional<std::pair<double, double>> Camera::SegmentInView(const Eigen::Vector3d& p,
                                                               const Eigen::Vector3d& q,
                                                               double min_depth_m) const {
  // Liang-Barsky: each bound is a half-space f(point) <= 0, linear in t along the segment.
  double t0 = 0, t1 = 1;
  auto clip = [&](double fp, double fq) {
    if (fp <= 0 && fq <= 0) return true;
    if (fp > 0 && fq > 0) return false;
    const double t = fp / (fp - fq);
    if (fp > 0) {
      t0 = std::max(t0, t);
    } else {
      t1 = std::min(t1, t);
    }
    return t0 <= t1;
  };
  // z > min_depth_m (at the clipped end z equals it up to rounding: a hair inside is asked for).
  const double depth = min_depth_m * (1 + 1e-9) + 1e-12;
  if (!(clip(depth - p.z(), depth - q.z()) &&
        clip(p.x() - view_hi_.x() * p.z(), q.x() - view_hi_.x() * q.z()) &&
        clip(view_lo_.x() * p.z() - p.x(), view_lo_.x() * q.z() - q.x()) &&
        clip(p.y() - view_hi_.y() * p.z(), q.y() - view_hi_.y() * q.z()) &&
        clip(view_lo_.y() * p.z() - p.y(), view_lo_.y() * q.z() - q.y()))) {
    return std::nullopt;
  }
  if (!std::isfinite(view_radius_)) return std::make_pair(t0, t1);
  // Within the fold radius: x^2 + y^2 <= R^2 z^2, the cone in front of the camera, quadratic in t:
  // f(t) = a t^2 + b t + c <= 0. Its intersection with [t0, t1] (where z > 0) is one interval.
  const Eigen::Vector3d v = q - p;
  const double r2 = view_radius_ * view_radius_;
  const double a = v.x() * v.x() + v.y() * v.y() - r2 * v.z() * v.z();
  const double b = 2 * (p.x() * v.x() + p.y() * v.y() - r2 * p.z() * v.z());
  const double c = p.x() * p.x() + p.y() * p.y() - r2 * p.z() * p.z();
  const auto f = [&](double t) { return (a * t + b) * t + c; };
  const bool in0 = f(t0) <= 0, in1 = f(t1) <= 0;
  if (in0 && in1) return std::make_pair(t0, t1);
  const double disc = b * b - 4 * a * c;
  if (!(disc >= 0) || a == 0) {
    if (a != 0 || b == 0 || (!in0 && !in1)) return std::nullopt;
    const double t = -c / b;  // f linear: one end in, one out
    return in0 ? std::make_pair(t0, std::min(t1, t)) : std::make_pair(std::max(t0, t), t1);
  }
  // The roots, the smaller first; with one end in, the root between the ends is the boundary.
  const double sq = std::sqrt(disc);
  const double h = -0.5 * (b + (b >= 0 ? sq : -sq));
  double r_lo = h / a, r_hi = h != 0 ? c / h : r_lo;
  if (r_lo > r_hi) std::swap(r_lo, r_hi);
  const auto between = [&](double t) { return t > t0 && t < t1; };
  if (in0) return std::make_pair(t0, between(r_lo) ? r_lo : r_hi);
  if (in1) return std::make_pair(between(r_hi) ? r_hi : r_lo, t1);
  if (a > 0 && r_lo >= t0 && r_hi <= t1) return std::make_pair(r_lo, r_hi);
  return std::nullopt;
}

std::optional<Eigen::Vector3d> Camera::UnprojectToCamera(const Eigen::Vector2d& pixel) const {
  auto n = PixelToNormalized(pixel);
  if (!n) return std::nullopt;
  return Eigen::Vector3d(n->x(), n->y(), 1.0);
}

std::optional<Ray> Camera::Unproject(const Eigen::Vector2d& pixel) const {
  auto d = UnprojectToCamera(pixel);
  if (!d) return std::nullopt;
  return Ray{world_T_camera_.translation, world_T_camera_.Rotate(d->normalized())};
}

std::optional<Segment2> Camera::SegmentToNormalized(const Segment2& pixel_segment) const {
  auto a = PixelToNormalized(pixel_segment.a);
  auto b = PixelToNormalized(pixel_segment.b);
  if (!a || !b) return std::nullopt;
  return Segment2{*a, *b};
}

std::optional<Eigen::Vector3d> Camera::InterpretationPlaneNormal(const Segment2& pixel_segment) const {
  auto s = SegmentToNormalized(pixel_segment);
  if (!s) return std::nullopt;
  const Eigen::Vector3d n =
      Eigen::Vector3d(s->a.x(), s->a.y(), 1).cross(Eigen::Vector3d(s->b.x(), s->b.y(), 1));
  if (n.norm() < 1e-15) return std::nullopt;  // a degenerate segment spans no plane
  return n.normalized();
}

Eigen::Vector3d LineThrough(const Eigen::Vector2d& p, const Eigen::Vector2d& q) {
  const Eigen::Vector2d dir = q - p;
  TEACHSIM_CHECK_MSG(dir.norm() > 0, "LineThrough needs two distinct points");
  const Eigen::Vector2d normal = Eigen::Vector2d(-dir.y(), dir.x()).normalized();
  return {normal.x(), normal.y(), -normal.dot(p)};
}

}  // namespace teachsim::vision
