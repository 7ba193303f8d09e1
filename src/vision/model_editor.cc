// The model editor's rules (issue 7, item 6; paper §4.3) and the world geometry the recognizer's
// verification and selection share with them (model_editor.h).
#include "model_editor.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

namespace teachsim::vision::internal {

namespace {

// A length in metres as the adjustments' text gives it: "12.3 mm".
std::string Mm(double m) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f mm", m * 1000);
  return buf;
}

// The ladder check (RecognizerOptions::ladder_search_m) of a recognition resting on the table: a thin
// block beside its shadow shows several parallel edges a thickness apart, and a fit can settle with
// its outline one rung off (a plate's far edge on a grain line of its top, its near edge on its
// shadow's). Only a pose whose outline is short of edges (coverage under ladder_max_coverage) is
// looked at. Moves along each horizontal side on the table, ranked by NetSupportPx at the moved pose;
// the best, fitted again there, replaces the pose when it beats it by ladder_margin and its
// evidence score by ladder_score_gain.
void LadderCheck(const Model& model, const Camera& camera, const LineDetection& detection,
                 const std::vector<Occluder>& others, const RecognizerOptions& options, Recognition* r) {
  auto net = [&](const geometry::Pose3& world_T_object) {
    return NetSupportPx(
        EvaluateOutline(model, camera, camera.camera_T_world() * world_T_object, detection, options));
  };
  const PoseEvidence here =
      EvaluateOutline(model, camera, camera.camera_T_world() * r->world_T_object, detection, options);
  if (!(here.coverage < options.ladder_max_coverage)) return;
  const double current = NetSupportPx(here);
  double best = current;
  geometry::Pose3 best_pose = r->world_T_object;
  const Eigen::Matrix3d rot = r->world_T_object.RotationMatrix();
  for (int a = 0; a < 3; ++a) {
    Eigen::Vector3d side = rot.col(a);
    if (std::abs(side.z()) > 0.5) continue;  // the vertical axis
    side.z() = 0;
    side.normalize();
    for (double sign : {-1.0, 1.0}) {
      for (double d = options.ladder_step_m; d <= options.ladder_search_m + 1e-9;
           d += options.ladder_step_m) {
        geometry::Pose3 moved = r->world_T_object;
        moved.translation += sign * d * side;
        const double v = net(moved);
        if (v > best) best = v, best_pose = moved;
      }
    }
  }
  if (!(best > current * (1 + options.ladder_margin))) return;
  const PolishResult polished = PolishPose(
      model, camera, camera.camera_T_world() * best_pose, detection.edge_map, true, 3,
      [&](const Eigen::Vector3d& point) { return HiddenByAny(others, point); },
      /*weigh_above=*/2 * options.canny_high);
  if (!polished.ok) return;
  const geometry::Pose3 fitted = camera.world_T_camera() * polished.fit.camera_T_object;
  const double after = net(fitted);
  if (!(after > current * (1 + options.ladder_margin))) return;
  auto score = [&](const geometry::Pose3& world_T_object) {
    return EvidenceScore(
        EvaluatePose(model, camera, camera.camera_T_world() * world_T_object, detection, options));
  };
  const double score_before = score(r->world_T_object), score_after = score(fitted);
  if (!(score_after >= score_before + options.ladder_score_gain)) return;
  char buf[200];
  std::snprintf(buf, sizeof(buf),
                "moved %.1f mm along its side on the table, where its outline has more edge support (%.0f -> "
                "%.0f px, score %.3f -> %.3f)",
                1000 * (fitted.translation - r->world_T_object.translation).norm(), current, after,
                score_before, score_after);
  r->world_T_object = fitted;
  r->reprojection_rms_px = polished.rms_px;
  r->adjustments.push_back(buf);
}

}  // namespace

// ---------------------------------------------------------------- the fixed world and boxes

FixedWorld ReadFixedWorld(const scene::Scene* fixed_world) {
  FixedWorld out;
  if (fixed_world == nullptr) return out;
  for (const scene::SceneObject& o : fixed_world->objects) {
    if (!o.fixed) continue;
    if (o.name == "table") {
      out.table_top_z = o.shape.WorldBounds(o.world_T_object).max.z();
      continue;
    }
    for (const geometry::ShapePart& part : o.shape.parts()) {
      const geometry::Pose3 world_T_part = o.world_T_object * part.shape_T_part;
      FixedPart f;
      f.name = o.name;
      for (const Eigen::Vector3d& v : part.convex->vertices()) f.vertices.push_back(world_T_part * v);
      for (const geometry::Face& face : part.convex->faces())
        f.normals.push_back(world_T_part.Rotate(face.normal));
      for (const geometry::Edge& e : part.convex->edges()) {
        f.edge_dirs.push_back(world_T_part
                                  .Rotate(part.convex->vertices()[static_cast<size_t>(e.v1)] -
                                          part.convex->vertices()[static_cast<size_t>(e.v0)])
                                  .normalized());
      }
      if (f.vertices.size() > 0) out.parts.push_back(std::move(f));
    }
  }
  return out;
}

std::vector<Eigen::Vector3d> BoxWorldVertices(const Model& model, const geometry::Pose3& world_T_object) {
  std::vector<Eigen::Vector3d> v;
  for (int i = 0; i < 8; ++i) v.push_back(world_T_object * BoxVertex(model.box_size_m, i));
  return v;
}

double LowestZ(const Model& model, const geometry::Pose3& world_T_object) {
  double z = 1e9;
  for (const Eigen::Vector3d& v : BoxWorldVertices(model, world_T_object)) z = std::min(z, v.z());
  return z;
}

Penetration PartPenetration(const Model& model, const geometry::Pose3& world_T_object, const FixedPart& part,
                            bool horizontal_only) {
  std::vector<Eigen::Vector3d> axes = part.normals;
  const Eigen::Matrix3d r = world_T_object.RotationMatrix();
  for (int i = 0; i < 3; ++i) {
    axes.push_back(r.col(i));
    for (const Eigen::Vector3d& d : part.edge_dirs) axes.push_back(r.col(i).cross(d));
  }
  if (horizontal_only) {
    for (Eigen::Vector3d& a : axes) a.z() = 0;
  }
  return VertexSetPenetration(BoxWorldVertices(model, world_T_object), part.vertices, axes);
}

// ---------------------------------------------------------------- the model editor's rules

void ApplyModelEditorRules(const ModelLibrary& models, const Camera& camera, const LineDetection& detection,
                           const FixedWorld& fixed, const RecognizerOptions& options,
                           std::vector<Recognition>* objects_io) {
  const EdgeMap& edge_map = detection.edge_map;
  std::vector<Recognition>& objects = *objects_io;
  std::vector<bool> resting(objects.size(), false);
  const Eigen::Vector3d camera_centre = camera.world_T_camera().translation;
  auto model_of = [&](const Recognition& r) -> const Model& {
    return *std::find_if(models.models.begin(), models.models.end(),
                         [&](const Model& m) { return m.name == r.model; });
  };
  for (size_t k = 0; k < objects.size(); ++k) {
    Recognition& r = objects[k];
    const Model& model = model_of(r);
    auto lowest = [&]() { return LowestZ(model, r.world_T_object); };
    if (lowest() - fixed.table_top_z > options.table_snap_distance_m) continue;
    // Level a nearly flat face (the object cannot rest on the table tilted by a few degrees).
    const Eigen::Matrix3d rot = r.world_T_object.RotationMatrix();
    int axis = 0;
    for (int a = 1; a < 3; ++a) {
      if (std::abs(rot(2, a)) > std::abs(rot(2, axis))) axis = a;
    }
    const Eigen::Vector3d up_axis = rot.col(axis) * (rot(2, axis) >= 0 ? 1.0 : -1.0);
    const double tilt = std::acos(std::clamp(up_axis.z(), -1.0, 1.0));
    if (tilt <= options.table_snap_max_tilt_deg * M_PI / 180) {
      if (tilt > 1e-9) {
        const Eigen::Quaterniond level =
            Eigen::Quaterniond::FromTwoVectors(up_axis, Eigen::Vector3d::UnitZ());
        r.world_T_object.rotation = (level * r.world_T_object.rotation).normalized();
        char buf[96];
        std::snprintf(buf, sizeof(buf), "levelled onto the table: turned %.2f deg", tilt * 180 / M_PI);
        r.adjustments.push_back(buf);
      }
      // Along the camera ray (the monocular system's weak direction, §4.2-4.3).
      const Eigen::Vector3d ray = (r.world_T_object.translation - camera_centre).normalized();
      const double dz = fixed.table_top_z - lowest();
      const Eigen::Vector3d move =
          std::abs(ray.z()) > 0.1 ? Eigen::Vector3d(ray * (dz / ray.z())) : Eigen::Vector3d(0, 0, dz);
      r.world_T_object.translation += move;
      resting[k] = true;
      r.adjustments.push_back("rested on the table: moved " + Mm(move.norm()) +
                              (std::abs(ray.z()) > 0.1 ? " along the camera ray" : " vertically"));
    }
  }
  // Fitted again where it now rests (x, y and yaw on the table) to the image's edge points along its
  // outline (PolishPose): lines beside an edge no longer pull it. The outline the other recognitions,
  // where they now rest, hide (each box shrunk by 1 mm, as in the occlusion pass) is left out: there
  // the front block's own edges would pull it.
  if (options.polish_pose) {
    std::vector<std::optional<Occluder>> occluders;
    for (const Recognition& o : objects) {
      occluders.push_back(
          MakeOccluder(model_of(o), camera.camera_T_world() * o.world_T_object, kOccluderMarginM));
    }
    for (size_t k = 0; k < objects.size(); ++k) {
      if (!resting[k]) continue;
      Recognition& r = objects[k];
      const Model& model = model_of(r);
      std::vector<Occluder> others;
      for (size_t j = 0; j < occluders.size(); ++j) {
        if (j != k && occluders[j]) others.push_back(*occluders[j]);
      }
      const geometry::Pose3 camera_T_object = camera.camera_T_world() * r.world_T_object;
      const PolishResult polished = PolishPose(
          model, camera, camera_T_object, edge_map, true, 3,
          [&](const Eigen::Vector3d& point) { return HiddenByAny(others, point); },
          /*weigh_above=*/2 * options.canny_high);
      if (polished.ok) {
        const geometry::Pose3 before = r.world_T_object;
        r.world_T_object = camera.world_T_camera() * polished.fit.camera_T_object;
        r.reprojection_rms_px = polished.rms_px;
        char buf[128];
        std::snprintf(buf, sizeof(buf),
                      "fitted on the table to %d edge points: moved %.2f mm, turned %.2f deg",
                      polished.points, 1000 * (r.world_T_object.translation - before.translation).norm(),
                      r.world_T_object.rotation.angularDistance(before.rotation) * 180 / M_PI);
        r.adjustments.push_back(buf);
      }
      if (options.ladder_search_m > 0) LadderCheck(model, camera, detection, others, options, &r);
    }
  }
  // Interpenetrating recognitions: the less certain one moves by the smallest separating move
  // (horizontal only when it rests on the table); then out of fixed objects.
  for (int pass = 0; pass < 3; ++pass) {
    bool moved = false;
    for (size_t i = 0; i < objects.size(); ++i) {
      for (size_t j = 0; j < objects.size(); ++j) {
        if (i == j || objects[i].score > objects[j].score ||
            (objects[i].score == objects[j].score && i < j)) {
          continue;  // i moves when it scores lower
        }
        Recognition& ri = objects[i];
        const Recognition& rj = objects[j];
        const Penetration pen = BoxBoxPenetration(model_of(ri).box_size_m, ri.world_T_object,
                                                  model_of(rj).box_size_m, rj.world_T_object, resting[i]);
        if (pen.depth_m <= 1e-5) continue;
        ri.world_T_object.translation += pen.direction * (pen.depth_m + 1e-5);
        ri.adjustments.push_back("separated from the " + rj.model + " recognized at (" +
                                 Mm(rj.world_T_object.translation.x()) + ", " +
                                 Mm(rj.world_T_object.translation.y()) + "): moved " + Mm(pen.depth_m));
        moved = true;
      }
      for (const FixedPart& part : fixed.parts) {
        Recognition& ri = objects[i];
        const Penetration pen = PartPenetration(model_of(ri), ri.world_T_object, part, resting[i]);
        if (pen.depth_m <= 1e-5) continue;
        ri.world_T_object.translation += pen.direction * (pen.depth_m + 1e-5);
        ri.adjustments.push_back("pushed out of " + part.name + ": moved " + Mm(pen.depth_m));
        moved = true;
      }
    }
    if (!moved) break;
  }
}

}  // namespace teachsim::vision::internal
