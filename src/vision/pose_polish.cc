// The accepted pose polished on the image's own edge points (see PolishPose in
// recognition_stages.h): the line fit's matches can include a grain line or a shadow beside an
// edge; the Canny points nearest the predicted outline do not. Each point counts once, however the
// edge's lines are fragmented, weighed by its contrast only (PolishPointWeight).
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <optional>
#include <vector>

#include "sampling.h"
#include "teachsim/vision/recognition_stages.h"

namespace teachsim::vision {

namespace {

constexpr double kSpacingPx = 2;        // between samples along a predicted edge
constexpr double kCornerMargin = 0.08;  // of the edge's length left out at each end (corners are rounded)
constexpr int kMinPointsPerEdge = 4, kMinEdges = 3, kRounds = 2, kIterations = 10;
constexpr double kTukeyPx = 2, kMaxMovePx = 2;

// The edge points near the predicted visible edges at a pose, as zero-length segments for the line
// fit, weighed by PolishPointWeight.
std::vector<LineMatch> EdgePoints(const Model& model, const Camera& camera,
                                  const geometry::Pose3& camera_T_object, const EdgeMap& edge_map,
                                  double search_px, const HiddenTest& hidden, double weigh_above,
                                  int* edges_with_points) {
  const Eigen::Matrix3d K = camera.K();
  const Intrinsics& k = camera.intrinsics();
  const uint16_t visible = VisibleBoxEdges(model.box_size_m, camera_T_object.Inverse().translation);
  std::vector<LineMatch> out;
  *edges_with_points = 0;
  const int steps = static_cast<int>(std::ceil(search_px));
  auto linear_magnitude_at = [&edge_map](int x, int y) { return LinearMagnitude(edge_map, x, y); };
  for (int e = 0; e < 12; ++e) {
    if (!(visible >> e & 1)) continue;
    const Eigen::Vector3d a = camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[static_cast<size_t>(e)][0]);
    const Eigen::Vector3d b = camera_T_object * BoxVertex(model.box_size_m, kBoxEdges[static_cast<size_t>(e)][1]);
    if (a.z() <= 0.05 || b.z() <= 0.05) continue;
    const double length_px = ((K * a).hnormalized() - (K * b).hnormalized()).norm();
    const int n = static_cast<int>(length_px / kSpacingPx);
    if (n < kMinPointsPerEdge) continue;
    int found = 0;
    // Beyond the camera's view the lens model may fold a point into the picture.
    const auto in_view = camera.SegmentInView(a, b);
    if (!in_view) continue;
    for (int i = 0; i < n; ++i) {
      const double t = kCornerMargin + (1 - 2 * kCornerMargin) * (i + 0.5) / n;
      if (t < in_view->first || t > in_view->second) continue;
      const Eigen::Vector3d x = a + t * (b - a);
      if (hidden && hidden(x)) continue;
      const auto here = camera.ProjectFromCamera(x, 0.05);
      const auto ahead = camera.ProjectFromCamera(x + 0.01 * (b - a), 0.05);
      if (!here || !ahead || !camera.InImage(*here)) continue;
      const Eigen::Vector2d along = (*ahead - *here).normalized(), normal(-along.y(), along.x());
      const std::optional<EdgePixel> edge = EdgePixelAcross(edge_map, *here, normal, steps);
      if (!edge) continue;
      const Eigen::Vector2d distorted =
          Eigen::Vector2d(edge->x, edge->y) +
          Eigen::Vector2d(edge->gx, edge->gy) *
              internal::SubPixelEdgeOffsetAt(linear_magnitude_at, edge_map.dx.cols, edge_map.dx.rows, edge->x,
                                             edge->y, edge->gx, edge->gy);
      // Undistorted, starting from the predicted point's ideal coordinates.
      const auto ideal = camera.Undistort(
          Eigen::Vector2d((distorted.x() - k.cx) / k.fx, (distorted.y() - k.cy) / k.fy), x.head<2>() / x.z());
      if (!ideal) continue;
      const Eigen::Vector2d p(k.fx * ideal->x() + k.cx, k.fy * ideal->y() + k.cy);
      out.push_back({e, p, p, PolishPointWeight(GradientMagnitude(edge_map, edge->x, edge->y), weigh_above)});
      ++found;
    }
    if (found >= kMinPointsPerEdge) ++*edges_with_points;
  }
  return out;
}

}  // namespace

double PolishPointWeight(double magnitude, double weigh_above) {
  constexpr double kMaxWeight = 4;
  if (!(weigh_above > 0) || !(magnitude > weigh_above)) return 1;
  const double r = magnitude / weigh_above;
  return std::min(r * r, kMaxWeight);
}

PolishResult PolishPose(const Model& model, const Camera& camera, const geometry::Pose3& camera_T_object,
                        const EdgeMap& edge_map, bool on_plane, double search_px, const HiddenTest& hidden,
                        double weigh_above) {
  PolishResult out;
  const Eigen::Matrix3d K = camera.K();
  geometry::Pose3 pose = camera_T_object;
  std::vector<LineMatch> points;
  for (int round = 0; round < kRounds; ++round) {
    int edges = 0;
    points = EdgePoints(model, camera, pose, edge_map, search_px, hidden, weigh_above, &edges);
    if (edges < kMinEdges) return out;
    const RobustLoss loss{RobustLoss::Kind::kTukey, kTukeyPx};
    out.fit = on_plane ? FitPoseOnPlane(model.box_size_m, K, camera.camera_T_world(), pose, points, kIterations, loss)
                       : FitPoseToLines(model.box_size_m, K, pose, points, kIterations, loss);
    pose = out.fit.camera_T_object;
    if (!(pose.translation.z() > 0.05) || !pose.translation.allFinite()) return out;
  }
  // How far the polish moved the projected vertices, px.
  double moved = 0;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d before = camera_T_object * BoxVertex(model.box_size_m, i);
    const Eigen::Vector3d after = pose * BoxVertex(model.box_size_m, i);
    moved += ((K * before).hnormalized() - (K * after).hnormalized()).norm() / 8;
  }
  if (moved > kMaxMovePx) return out;
  // The residual of the points within Tukey's scale (the rest are not the block's edge).
  std::array<Eigen::Vector2d, 8> vertex_px;
  for (int i = 0; i < 8; ++i) vertex_px[static_cast<size_t>(i)] = (K * (pose * BoxVertex(model.box_size_m, i))).hnormalized();
  double sum = 0;
  int count = 0;
  for (const LineMatch& m : points) {
    const Eigen::Vector2d& a = vertex_px[static_cast<size_t>(kBoxEdges[static_cast<size_t>(m.edge)][0])];
    const Eigen::Vector2d& b = vertex_px[static_cast<size_t>(kBoxEdges[static_cast<size_t>(m.edge)][1])];
    const Eigen::Vector2d d = (b - a).normalized();
    const double r = std::abs(d.x() * (m.a.y() - a.y()) - d.y() * (m.a.x() - a.x()));
    if (r <= kTukeyPx) sum += r * r, ++count;
  }
  out.points = count;
  out.rms_px = count > 0 ? std::sqrt(sum / count) : 0;
  out.ok = true;
  return out;
}

}  // namespace teachsim::vision
