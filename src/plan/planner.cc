#include "teachsim/plan/planner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>

#include "teachsim/geometry/toi.h"
#include "teachsim/robot/controller.h"
#include "teachsim/robot/kinematics.h"
#include "teachsim/robot/safety.h"

namespace teachsim::plan {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

double Elapsed(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since).count();
}

const scene::SceneObject& Object(const sim::SimWorld& world, int index) {
  return world.scene.objects[static_cast<std::size_t>(index)];
}

// Rotation from a to b as an axis * angle vector (shortest way).
Eigen::Vector3d RotationVector(const Eigen::Quaterniond& from, const Eigen::Quaterniond& to) {
  Eigen::Quaterniond delta = to * from.conjugate();
  if (delta.w() < 0) delta.coeffs() = -delta.coeffs();
  const Eigen::AngleAxisd aa(delta);
  return aa.angle() * aa.axis();
}

}  // namespace

Status PlanOptions::Validate() const {
  for (auto [field, value] :
       {std::pair{"tension_n", tension_n}, {"min_spacing_m", min_spacing_m}, {"rotation_tension_nm", rotation_tension_nm},
        {"repulsion_range_m", repulsion_range_m}, {"repulsion_n_per_m", repulsion_n_per_m}, {"converged_m", converged_m},
        {"position_tolerance_m", position_tolerance_m}, {"angle_tolerance_rad", angle_tolerance_rad},
        {"clearance_target_m", clearance_target_m},
        {"grip_depth_m", grip_depth_m}, {"free_speed_mps", free_speed_mps}, {"contact_speed_mps", contact_speed_mps},
        {"bias_depth_m", bias_depth_m}, {"max_bias_m", max_bias_m},
        {"contact_stiffness_n_per_m", contact_stiffness_n_per_m},
        {"contact_damping_n_s_per_m", contact_damping_n_s_per_m}, {"threshold_fraction", threshold_fraction},
        {"retreat_m", retreat_m}, {"gripper_clearance_m", gripper_clearance_m},
        {"min_wrist_measure", min_wrist_measure}, {"min_elbow_measure", min_elbow_measure},
        {"min_shoulder_m", min_shoulder_m}, {"check_step_m", check_step_m}, {"check_step_rad", check_step_rad}}) {
    if (!(std::isfinite(value) && value > 0.0)) {
      return Status::InvalidInput(std::string("PlanOptions::") + field + " = " + json::FormatNumber(value) + " must be > 0");
    }
  }
  if (max_iterations < 0 || max_iterations > 100000) {
    return Status::InvalidInput("PlanOptions::max_iterations = " + std::to_string(max_iterations) + " must be in [0, 100000]");
  }
  if (!(max_spacing_m >= 0.0)) return Status::InvalidInput("PlanOptions::max_spacing_m must be >= 0 (0: automatic)");
  return Status::Ok();
}

double PathLength(const std::vector<geometry::Pose3>& poses) {
  double length = 0.0;
  for (std::size_t i = 1; i < poses.size(); ++i) length += (poses[i].translation - poses[i - 1].translation).norm();
  return length;
}

bool MotionClear(const sim::SimWorld& world, int workpiece, const geometry::Pose3& a, const geometry::Pose3& b,
                 double clearance_m) {
  const scene::SceneObject& wp = Object(world, workpiece);
  const geometry::ToiOptions options{.target_distance_m = clearance_m, .tolerance_m = 1e-6, .max_iterations = 64};
  for (int o = 0; o < static_cast<int>(world.scene.objects.size()); ++o) {
    if (o == workpiece) continue;
    const scene::SceneObject& obstacle = Object(world, o);
    const geometry::ToiResult r = geometry::TimeOfImpact(wp.shape, a, b, obstacle.shape, obstacle.world_T_object, options);
    if (r.hit) return false;
  }
  return true;
}

double Clearance(const sim::SimWorld& world, int workpiece, const geometry::Pose3& pose, const std::set<int>& skip,
                 double range_m) {
  const scene::SceneObject& wp = Object(world, workpiece);
  double best = kInf;
  for (int o = 0; o < static_cast<int>(world.scene.objects.size()); ++o) {
    if (o == workpiece || skip.count(o)) continue;
    const scene::SceneObject& obstacle = Object(world, o);
    const geometry::DistanceResult d = geometry::ShapeDistance(wp.shape, pose, obstacle.shape, obstacle.world_T_object, range_m);
    best = std::min(best, d.intersecting ? 0.0 : d.distance);
  }
  return best;
}

double ObjectDistance(const sim::SimWorld& world, int workpiece, const geometry::Pose3& pose, int object) {
  const scene::SceneObject& obstacle = Object(world, object);
  const geometry::DistanceResult d =
      geometry::ShapeDistance(Object(world, workpiece).shape, pose, obstacle.shape, obstacle.world_T_object);
  return d.intersecting ? 0.0 : d.distance;
}

Result<Band> MakeBand(const sim::SimWorld& world, const sim::WorkpiecePath& path, const PlanOptions& options) {
  Band band;
  band.workpiece = world.scene.FindObject(path.workpiece);
  if (band.workpiece < 0) return Status::NotFound("path: workpiece '" + path.workpiece + "' is not in the scene");
  if (Object(world, band.workpiece).fixed) {
    return Status::InvalidInput("path: workpiece '" + path.workpiece + "' is a fixed object in the scene");
  }
  if (path.nodes.size() < 2) return Status::InvalidInput("path: needs at least two nodes to plan a motion");
  std::set<int> forced;
  for (const std::string& name : options.required_objects) {
    const int o = world.scene.FindObject(name);
    if (o < 0) return Status::NotFound("PlanOptions::required_objects: '" + name + "' is not in the scene");
    forced.insert(o);
  }
  // Required objects per node (PlanOptions: destination, capture stretches, overrides).
  std::vector<PlanNode> raw;
  for (std::size_t i = 0; i < path.nodes.size(); ++i) {
    const sim::PathNode& n = path.nodes[i];
    PlanNode node;
    node.pose = n.world_T_workpiece;
    node.contacts = n.contacts;
    const bool last = i + 1 == path.nodes.size();
    for (const sim::PathContact& c : n.contacts) {
      const int o = world.scene.FindObject(c.object);
      if (o < 0) return Status::NotFound("path: nodes[" + std::to_string(i) + "]: contact object '" + c.object + "' is not in the scene");
      if ((c.capture && options.capture_required) || (last && options.destination_required) || forced.count(o)) {
        node.required.insert(o);
      }
    }
    if (options.capture_required) {
      for (const std::string& name : n.captured) {
        const int o = world.scene.FindObject(name);
        if (o < 0) return Status::NotFound("path: nodes[" + std::to_string(i) + "]: captured object '" + name + "' is not in the scene");
        node.required.insert(o);
      }
    }
    raw.push_back(std::move(node));
  }
  // Drop the nodes where nothing moved (settling), keeping changes of the required set.
  std::vector<PlanNode> kept;
  for (std::size_t i = 0; i < raw.size(); ++i) {
    const bool edge = i == 0 || i + 1 == raw.size();
    if (!edge && !kept.empty()) {
      const PlanNode& prev = kept.back();
      const bool still = (raw[i].pose.translation - prev.pose.translation).norm() < 2e-4 &&
                         geometry::RotationAngle(raw[i].pose, prev.pose) < 0.2 * M_PI / 180;
      if (still && raw[i].required == prev.required && raw[i + 1].required == raw[i].required) continue;
    }
    kept.push_back(raw[i]);
  }
  // The band's spacing stays below half the thinnest part of the scene (the paper's open
  // problem: a band with coarse nodes could pass through a thin lip between two of them).
  double max_spacing = options.max_spacing_m;
  if (max_spacing <= 0.0) {
    double thinnest = kInf;
    for (const auto& o : world.scene.objects) thinnest = std::min(thinnest, o.shape.min_thickness());
    max_spacing = std::clamp(0.5 * thinnest, 1e-3, 0.01);
  }
  // Resample: interpolated nodes lie on the simulator's own (collision-free) motion.
  for (std::size_t i = 0; i < kept.size(); ++i) {
    if (i > 0) {
      const PlanNode& a = kept[i - 1];
      const PlanNode& b = kept[i];
      const double gap = (b.pose.translation - a.pose.translation).norm();
      const int pieces = static_cast<int>(std::ceil(gap / max_spacing));
      for (int k = 1; k < pieces; ++k) {
        PlanNode mid;
        mid.pose = geometry::Interpolate(a.pose, b.pose, static_cast<double>(k) / pieces);
        if (a.required == b.required) mid.required = a.required;
        band.nodes.push_back(mid);
      }
    }
    band.nodes.push_back(kept[i]);
  }
  // Fixed: the ends, and the ends of every required stretch.
  const std::size_t n = band.nodes.size();
  for (std::size_t i = 0; i < n; ++i) {
    PlanNode& node = band.nodes[i];
    if (i == 0 || i + 1 == n) node.fixed = true;
    if (!node.required.empty()) {
      const bool starts = band.nodes[i - (i > 0 ? 1 : 0)].required != node.required || i == 0;
      const bool ends = i + 1 == n || band.nodes[i + 1].required != node.required;
      if (starts || ends) node.fixed = true;
    }
  }
  return band;
}

namespace {

struct NodeForce {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  Eigen::Vector3d torque = Eigen::Vector3d::Zero();
};

NodeForce BandForce(const sim::SimWorld& world, const Band& band, std::size_t i, const PlanOptions& o) {
  const PlanNode& node = band.nodes[i];
  const PlanNode& prev = band.nodes[i - 1];
  const PlanNode& next = band.nodes[i + 1];
  NodeForce f;
  // Constant tension toward each neighbour, proportional below the minimum spacing (paper §6.1).
  for (const PlanNode* nb : {&prev, &next}) {
    const Eigen::Vector3d delta = nb->pose.translation - node.pose.translation;
    const double length = delta.norm();
    if (length > 1e-12) f.force += o.tension_n * std::min(1.0, length / o.min_spacing_m) * delta / length;
    const Eigen::Vector3d turn = RotationVector(node.pose.rotation, nb->pose.rotation);
    const double angle = turn.norm();
    if (angle > 1e-12) f.torque += o.rotation_tension_nm * std::min(1.0, angle / (M_PI / 180)) * turn / angle;
  }
  // Repulsion from unwanted obstacles, translation only, without its component along the path.
  const scene::SceneObject& wp = Object(world, band.workpiece);
  Eigen::Vector3d repulsion = Eigen::Vector3d::Zero();
  for (int ob = 0; ob < static_cast<int>(world.scene.objects.size()); ++ob) {
    if (ob == band.workpiece || node.required.count(ob)) continue;
    const scene::SceneObject& obstacle = Object(world, ob);
    const geometry::DistanceResult d =
        geometry::ShapeDistance(wp.shape, node.pose, obstacle.shape, obstacle.world_T_object, o.repulsion_range_m);
    if (!(d.distance < o.repulsion_range_m)) continue;
    repulsion += o.repulsion_n_per_m * (o.repulsion_range_m - d.distance) * (-d.normal);
  }
  const Eigen::Vector3d along = next.pose.translation - prev.pose.translation;
  if (along.norm() > 1e-12) {
    const Eigen::Vector3d t = along.normalized();
    repulsion -= repulsion.dot(t) * t;
  }
  f.force += repulsion;
  return f;
}

}  // namespace

DeformStats Deform(const sim::SimWorld& world, Band& band, const PlanOptions& o) {
  const scene::SceneObject& wp = Object(world, band.workpiece);
  sim::SimState state;
  state.workpiece = band.workpiece;
  state.caches.assign(wp.shape.parts().size() * world.parts.size(), geometry::DistanceCache{});
  const double clearance = 0.05 * world.options.barrier_distance_m;  // never closer than 5 um
  const double radius = wp.shape.bounding_radius();
  // Each node's distance to everything (up to 50 mm). A motion between two poses moves no point
  // farther than L = |dp| + angle * radius, and the distance is 1-Lipschitz in that, so it stays
  // above (c_a + c_b - L) / 2: most band motions need no conservative advancement at all.
  auto clear_of = [&](const geometry::Pose3& pose) { return Clearance(world, band.workpiece, pose, {}, 0.05); };
  std::vector<double> clear;
  for (const PlanNode& node : band.nodes) clear.push_back(clear_of(node.pose));
  auto motion_clear = [&](const geometry::Pose3& a, double ca, const geometry::Pose3& b, double cb) {
    const double reach = (b.translation - a.translation).norm() + geometry::RotationAngle(a, b) * radius;
    if (ca + cb > reach + 2.0 * clearance) return true;
    return MotionClear(world, band.workpiece, a, b, clearance);
  };
  double final_spacing = o.max_spacing_m;
  if (final_spacing <= 0.0) {
    double thinnest = kInf;
    for (const auto& obj : world.scene.objects) thinnest = std::min(thinnest, obj.shape.min_thickness());
    final_spacing = std::clamp(0.5 * thinnest, 1e-3, 0.01);
  }
  final_spacing = std::max(final_spacing, 2.0 * o.min_spacing_m);

  // Removes unfixed nodes closer than `spacing` to the last kept one, where the motion that
  // replaces them is clear; inserts midpoints (on motions already proven clear) where farther.
  auto respace = [&](double spacing) {
    std::vector<PlanNode> nodes{band.nodes.front()};
    std::vector<double> c{clear.front()};
    for (std::size_t i = 1; i < band.nodes.size(); ++i) {
      const bool last = i + 1 == band.nodes.size();
      const PlanNode& node = band.nodes[i];
      const bool close = (node.pose.translation - nodes.back().pose.translation).norm() < 0.75 * spacing &&
                         node.required == nodes.back().required;
      if (!last && !node.fixed && close &&
          motion_clear(nodes.back().pose, c.back(), band.nodes[i + 1].pose, clear[i + 1])) {
        continue;
      }
      nodes.push_back(node);
      c.push_back(clear[i]);
    }
    band.nodes.clear();
    clear.clear();
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      if (i > 0) {
        const PlanNode& a = nodes[i - 1];
        const PlanNode& b = nodes[i];
        const int pieces = static_cast<int>(std::ceil((b.pose.translation - a.pose.translation).norm() / spacing));
        for (int k = 1; k < pieces; ++k) {
          PlanNode mid;
          mid.pose = geometry::Interpolate(a.pose, b.pose, static_cast<double>(k) / pieces);
          if (a.required == b.required) mid.required = a.required;
          band.nodes.push_back(mid);
          clear.push_back(clear_of(mid.pose));
        }
      }
      band.nodes.push_back(nodes[i]);
      clear.push_back(c[i]);
    }
  };

  // Coarse to fine: a band of n nodes straightens in O(n^2) sweeps (tension diffuses one node
  // per sweep), so most of the work happens on a coarse band, whose links conservative
  // advancement checks however long they are; the last level keeps the spacing below half the
  // thinnest part (the paper's open problem) for the simplifier and the program.
  std::vector<double> levels;
  for (double spacing = 0.016; spacing > final_spacing * 1.5; spacing *= 0.5) levels.push_back(spacing);
  levels.push_back(final_spacing);
  DeformStats stats;
  for (std::size_t level = 0; level < levels.size(); ++level) {
    respace(levels[level]);
    // Larger nodes move farther per sweep: the force scales with the spacing.
    const double gain = levels[level] / final_spacing;
    // The tension is constant above the minimum spacing, so a node near its balance would hop to
    // and fro by a whole step for ever (measured: 1-2 mm hops through all 200 sweeps). Each node
    // therefore has its own step scale, halved whenever its move turns back on the previous one
    // and regrown while the moves agree (as in Rprop): the band settles instead of circling.
    std::vector<double> scale(band.nodes.size(), 1.0);
    std::vector<Eigen::Vector3d> last_move(band.nodes.size(), Eigen::Vector3d::Zero());
    // What a coarser level left of its share carries over to the finer ones.
    const int budget = std::max(1, (o.max_iterations - stats.iterations) / static_cast<int>(levels.size() - level));
    bool settled = false;
    for (int iteration = 0; iteration < budget && !settled; ++iteration) {
      ++stats.iterations;
      double sum_move = 0.0;
      // Gauss-Seidel: each node sees its neighbours' new poses (paper: "in succession").
      for (std::size_t i = 1; i + 1 < band.nodes.size(); ++i) {
        PlanNode& node = band.nodes[i];
        if (node.fixed) continue;
        const NodeForce f = BandForce(world, band, i, o);
        state.world_T_workpiece = node.pose;
        state.capture.assign(node.required.begin(), node.required.end());
        state.engaged = state.capture;
        const double k = gain * scale[i];
        sim::Step(world, state, sim::StepInput{k * f.force, k * f.torque});
        const geometry::Pose3 moved = state.world_T_workpiece;
        const Eigen::Vector3d move = moved.translation - node.pose.translation;
        const double step = move.norm();
        if (step < 1e-9 && geometry::RotationAngle(moved, node.pose) < 1e-9) continue;
        // The moves to and from the neighbours stay collision-free over their continuous motion.
        const double c_moved = clear_of(moved);
        if (!motion_clear(band.nodes[i - 1].pose, clear[i - 1], moved, c_moved) ||
            !motion_clear(moved, c_moved, band.nodes[i + 1].pose, clear[i + 1])) {
          continue;
        }
        bool keeps = true;
        for (int r : node.required) {
          keeps = keeps && ObjectDistance(world, band.workpiece, moved, r) <= world.options.capture_distance_m;
        }
        if (!keeps) continue;
        if (move.dot(last_move[i]) < 0.0) {
          scale[i] *= 0.5;
        } else {
          scale[i] = std::min(1.0, scale[i] * 1.25);
        }
        last_move[i] = move;
        node.pose = moved;
        clear[i] = c_moved;
        sum_move += step;
      }
      // Settled: the band as a whole stands still. A single node pressed against an obstacle
      // may still hop by a step now and then (its scale regrows while the pushes agree), which
      // would keep a max-norm test from ever passing.
      settled = sum_move / static_cast<double>(band.nodes.size()) < o.converged_m * gain;
    }
    // A coarse level only speeds the fine one up; it hands over when its share runs out. The
    // band has converged when the final level settles.
    stats.converged = settled;
  }
  return stats;
}

std::vector<int> Simplify(const sim::SimWorld& world, const Band& band, const PlanOptions& o) {
  const int n = static_cast<int>(band.nodes.size());
  const double clearance = 0.05 * world.options.barrier_distance_m;
  auto valid = [&](int a, int b) {
    const geometry::Pose3& pa = band.nodes[static_cast<std::size_t>(a)].pose;
    const geometry::Pose3& pb = band.nodes[static_cast<std::size_t>(b)].pose;
    if (!MotionClear(world, band.workpiece, pa, pb, clearance)) return false;
    // Required stretches stay contact moves; elsewhere the shortcut may not come nearer to
    // unwanted obstacles than the band it replaces (less 1 mm).
    std::set<int> required = band.nodes[static_cast<std::size_t>(a)].required;
    for (int k = a + 1; k <= b; ++k) {
      std::set<int> both;
      const auto& r = band.nodes[static_cast<std::size_t>(k)].required;
      std::set_intersection(required.begin(), required.end(), r.begin(), r.end(), std::inserter(both, both.begin()));
      required = both;
    }
    // Pointwise: at each fraction of the way, the shortcut keeps the clearance of the band node
    // at the same fraction of its length (less 1 mm, up to the repulsion range).
    std::vector<double> arc{0.0};
    for (int k = a + 1; k <= b; ++k) {
      arc.push_back(arc.back() + (band.nodes[static_cast<std::size_t>(k)].pose.translation -
                                  band.nodes[static_cast<std::size_t>(k - 1)].pose.translation).norm());
    }
    std::set<int> skip = required;
    skip.insert(band.nodes[static_cast<std::size_t>(a)].required.begin(), band.nodes[static_cast<std::size_t>(a)].required.end());
    skip.insert(band.nodes[static_cast<std::size_t>(b)].required.begin(), band.nodes[static_cast<std::size_t>(b)].required.end());
    for (int s = 1; s < 8; ++s) {
      const geometry::Pose3 p = geometry::Interpolate(pa, pb, s / 8.0);
      for (int r : required) {
        if (ObjectDistance(world, band.workpiece, p, r) > world.options.capture_distance_m) return false;
      }
      const double target = arc.back() * s / 8.0;
      const std::size_t j = std::min<std::size_t>(
          std::max<std::ptrdiff_t>(1, std::lower_bound(arc.begin(), arc.end(), target) - arc.begin()), arc.size() - 1);
      const double u = arc[j] > arc[j - 1] ? (target - arc[j - 1]) / (arc[j] - arc[j - 1]) : 1.0;
      auto node_clearance = [&](std::size_t index) {
        return std::min(Clearance(world, band.workpiece, band.nodes[static_cast<std::size_t>(a) + index].pose, skip,
                                  o.repulsion_range_m),
                        o.clearance_target_m);
      };
      const double band_clearance = (1.0 - u) * node_clearance(j - 1) + u * node_clearance(j);
      if (Clearance(world, band.workpiece, p, skip, o.repulsion_range_m) < band_clearance - 1e-3) return false;
    }
    return true;
  };
  std::vector<int> knots;
  // Ramer-Douglas-Peucker in SE(3) between consecutive fixed nodes.
  std::function<void(int, int)> rdp = [&](int a, int b) {
    if (b - a < 2) {
      knots.push_back(b);
      return;
    }
    const geometry::Pose3& pa = band.nodes[static_cast<std::size_t>(a)].pose;
    const geometry::Pose3& pb = band.nodes[static_cast<std::size_t>(b)].pose;
    const Eigen::Vector3d ab = pb.translation - pa.translation;
    double worst = 0.0;
    int worst_k = (a + b) / 2;
    for (int k = a + 1; k < b; ++k) {
      const geometry::Pose3& pk = band.nodes[static_cast<std::size_t>(k)].pose;
      double u = ab.squaredNorm() > 1e-12 ? std::clamp((pk.translation - pa.translation).dot(ab) / ab.squaredNorm(), 0.0, 1.0)
                                          : static_cast<double>(k - a) / (b - a);
      const geometry::Pose3 on = geometry::Interpolate(pa, pb, u);
      const double error = std::max((pk.translation - on.translation).norm() / o.position_tolerance_m,
                                    geometry::RotationAngle(pk, on) / o.angle_tolerance_rad);
      if (error > worst) {
        worst = error;
        worst_k = k;
      }
    }
    if (worst <= 1.0 && valid(a, b)) {
      knots.push_back(b);
      return;
    }
    rdp(a, worst_k);
    rdp(worst_k, b);
  };
  knots.push_back(0);
  int start = 0;
  for (int i = 1; i < n; ++i) {
    if (band.nodes[static_cast<std::size_t>(i)].fixed) {
      rdp(start, i);
      start = i;
    }
  }
  // Then drop every knot whose neighbours' shortcut is itself valid (collision-free, clearance
  // kept, required contacts kept): RDP follows the band's bends more closely than the program
  // needs (the cornering program fell from 8 to 4-6 motions here).
  for (bool removed = true; removed;) {
    removed = false;
    for (std::size_t k = 1; k + 1 < knots.size(); ++k) {
      if (band.nodes[static_cast<std::size_t>(knots[k])].fixed) continue;
      if (valid(knots[k - 1], knots[k + 1])) {
        knots.erase(knots.begin() + static_cast<std::ptrdiff_t>(k));
        removed = true;
        break;
      }
    }
  }
  return knots;
}

Result<robot::Program> MakeProgram(const sim::SimWorld& world, const Band& band, const std::vector<int>& knots,
                                   const PlanOptions& o, double grasp_yaw_rad) {
  const scene::SceneObject& wp = Object(world, band.workpiece);
  const geometry::Aabb box = wp.shape.WorldBounds(geometry::Pose3::Identity());
  robot::Program program;
  program.workpiece = wp.name;
  // The fingers hold the top grip_depth of the block from above: tool z points down, the jaws
  // close along the block's y axis.
  // On a thin block, a biased target must not drive the fingertips into what the block rests on:
  // they stay at least d (plus 1 mm) above its bottom.
  const double grip = std::min(o.grip_depth_m, std::max(0.003, box.Size().z() - o.bias_depth_m - 0.001));
  // A grasp turned by grasp_yaw_rad about the tool axis (multiples of 90 degrees for a box) closes
  // the jaws across the block's extent along the turned tool y.
  program.workpiece_T_tool =
      geometry::Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())),
                      Eigen::Vector3d(box.Center().x(), box.Center().y(), box.max.z() - grip));
  if (grasp_yaw_rad != 0.0) {
    program.workpiece_T_tool = program.workpiece_T_tool *
                               geometry::Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(grasp_yaw_rad, Eigen::Vector3d::UnitZ())),
                                               Eigen::Vector3d::Zero());
  }
  const Eigen::Vector3d jaw_axis = program.workpiece_T_tool.rotation * Eigen::Vector3d::UnitY();
  const double width = std::abs(jaw_axis.x()) * box.Size().x() + std::abs(jaw_axis.y()) * box.Size().y() +
                       std::abs(jaw_axis.z()) * box.Size().z();
  auto tool = [&](const geometry::Pose3& world_T_workpiece) { return world_T_workpiece * program.workpiece_T_tool; };

  robot::GraspCommand grasp;
  grasp.world_T_tool = tool(band.nodes.front().pose);
  grasp.width_m = width;
  grasp.open_width_m = width + 0.015;  // 7.5 mm each side; within the 80 mm jaws for 60 mm blocks
  program.commands.push_back(grasp);

  sim::SimState state;
  state.workpiece = band.workpiece;
  state.caches.assign(wp.shape.parts().size() * world.parts.size(), geometry::DistanceCache{});
  for (std::size_t k = 1; k < knots.size(); ++k) {
    const PlanNode& knot = band.nodes[static_cast<std::size_t>(knots[k])];
    if (knot.required.empty()) {
      program.commands.push_back(robot::MoveCommand{tool(knot.pose), o.free_speed_mps});
      continue;
    }
    // The knot's contact normals with the required objects, merged when within 5 degrees.
    state.world_T_workpiece = knot.pose;
    std::vector<Eigen::Vector3d> normals;
    for (const sim::Contact& c : sim::CurrentContacts(world, state)) {
      if (!knot.required.count(c.object)) continue;
      bool merged = false;
      for (Eigen::Vector3d& n : normals) {
        if (n.normalized().dot(c.normal) > std::cos(5.0 * M_PI / 180)) {
          n += c.normal;
          merged = true;
        }
      }
      if (!merged) normals.push_back(c.normal);
    }
    if (normals.empty()) {
      return Status::Failed("knot " + std::to_string(k) + " must keep contact with " +
                            world.name(*knot.required.begin()) + " but touches nothing there");
    }
    robot::ContactMoveCommand move;
    move.world_T_tool = tool(knot.pose);
    move.normals.resize(3, static_cast<Eigen::Index>(normals.size()));
    for (std::size_t i = 0; i < normals.size(); ++i) move.normals.col(static_cast<Eigen::Index>(i)) = normals[i].normalized();
    auto bias = robot::ContactBias(move.normals, o.bias_depth_m, o.max_bias_m);
    if (!bias.ok()) {
      return Status::Failed("knot " + std::to_string(k) + ": no contact bias: " + bias.status().message() +
                            " (a tight fit: the paper's open case)");
    }
    move.bias_m = *bias;
    move.force_thresholds_n.assign(normals.size(), o.threshold_fraction * o.contact_stiffness_n_per_m * o.bias_depth_m);
    move.stiffness_n_per_m = o.contact_stiffness_n_per_m;
    move.damping_n_s_per_m = o.contact_damping_n_s_per_m;
    move.speed_mps = o.contact_speed_mps;
    program.commands.push_back(move);
  }
  program.commands.push_back(robot::ReleaseCommand{grasp.open_width_m});
  program.commands.push_back(robot::RetreatCommand{o.retreat_m, o.free_speed_mps});
  TEACHSIM_RETURN_IF_ERROR(program.Validate());
  return program;
}

std::vector<ToolSample> SampleProgram(const robot::Program& program, const geometry::Pose3& start, double start_width_m,
                                      double step_m, double step_rad) {
  std::vector<ToolSample> out;
  geometry::Pose3 pose = start;
  double width = start_width_m;
  out.push_back({pose, width, "start"});
  auto line = [&](const geometry::Pose3& goal, const std::string& what) {
    const double length = (goal.translation - pose.translation).norm();
    const double angle = geometry::RotationAngle(pose, goal);
    const int steps = std::max(1, static_cast<int>(std::ceil(std::max(length / step_m, angle / step_rad))));
    for (int k = 1; k <= steps; ++k) {
      const double u = static_cast<double>(k) / steps;
      out.push_back({geometry::Interpolate(pose, goal, u), width, what + " at " + std::to_string(std::lround(100 * u)) + "%"});
    }
    pose = goal;
  };
  for (std::size_t i = 0; i < program.commands.size(); ++i) {
    const robot::Command& command = program.commands[i];
    const std::string what = "commands[" + std::to_string(i) + "] (" + robot::CommandType(command) + ")";
    if (const auto* g = std::get_if<robot::GraspCommand>(&command)) {
      width = g->open_width_m;
      line(g->ApproachPose(), what + " approach");
      line(g->world_T_tool, what + " descent");
      width = g->width_m;
      out.push_back({pose, width, what + " closed"});
    } else if (const auto* m = std::get_if<robot::MoveCommand>(&command)) {
      line(m->world_T_tool, what);
    } else if (const auto* c = std::get_if<robot::ContactMoveCommand>(&command)) {
      line(c->world_T_tool, what);  // the nominal target: the bias only presses the workpiece into its contacts
    } else if (const auto* r = std::get_if<robot::ReleaseCommand>(&command)) {
      width = r->width_m;
      out.push_back({pose, width, what});
    } else if (const auto* t = std::get_if<robot::RetreatCommand>(&command)) {
      geometry::Pose3 up = pose;
      up.translation.z() += t->distance_m;
      line(up, what);
    }
  }
  return out;
}

namespace {

std::string Mm(const Eigen::Vector3d& p) {
  char text[96];
  std::snprintf(text, sizeof text, "(%.1f, %.1f, %.1f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return text;
}

}  // namespace

GraspReport CheckWithRobot(const sim::SimWorld& world, const robot::RobotModel& model,
                           const geometry::Pose3& world_T_base, const robot::Program& program, const PlanOptions& o) {
  GraspReport report;
  report.min_gripper_clearance_m = kInf;
  report.min_wrist_measure = report.min_elbow_measure = kInf;
  report.min_shoulder_m = kInf;
  // What the work site's controller checks before any motion (reach, limits, joint speeds, widths).
  const robot::ControllerOptions controller;
  if (Status s = robot::CheckProgram(model, world_T_base, program, model.ready_rad, controller.limits, controller.safety);
      !s.ok()) {
    report.problem = s.message();
  }
  const int workpiece = world.scene.FindObject(program.workpiece);
  const geometry::Pose3 base_T_world = world_T_base.Inverse();
  // The arm starts at its ready joints with the jaws open (as the work site starts it).
  const std::vector<ToolSample> samples =
      SampleProgram(program, world_T_base * robot::ToolPose(model, model.ready_rad), 0.9 * model.gripper.max_width_m,
                    o.check_step_m, o.check_step_rad);
  std::vector<geometry::Shape> shapes;
  const std::vector<robot::GripperBox> layout = robot::GripperBoxes(model.gripper, 0.0);
  for (const robot::GripperBox& b : layout) {
    auto box = geometry::ConvexPolyhedron::Box(b.size_m);
    TEACHSIM_CHECK(box.ok());
    shapes.push_back(geometry::Shape::Single(std::move(box).value()));
  }
  robot::Joints q = model.ready_rad;
  std::string singular_problem, gripper_problem;
  char text[400];
  for (const ToolSample& sample : samples) {
    // The joints the controller will take there: the IK solution nearest the previous one.
    auto ik = robot::NearestToolIk(model, base_T_world * sample.world_T_tool, q);
    if (!ik.ok()) {
      if (report.problem.empty()) report.problem = sample.what + ": " + ik.status().message();
    } else {
      q = ik->q;
      const robot::Singularities s = robot::DetectSingularities(model, q);
      report.min_wrist_measure = std::min(report.min_wrist_measure, s.wrist_measure);
      report.min_elbow_measure = std::min(report.min_elbow_measure, s.elbow_measure);
      report.min_shoulder_m = std::min(report.min_shoulder_m, s.shoulder_measure_m);
      if (singular_problem.empty() && (s.wrist_measure < o.min_wrist_measure || s.elbow_measure < o.min_elbow_measure ||
                                       s.shoulder_measure_m < o.min_shoulder_m)) {
        std::snprintf(text, sizeof text,
                      "%s: the arm comes near a singularity with the tool at %s (|sin theta5| = %.3f, elbow %.3f, "
                      "shoulder %.1f mm; the program asks for at least %.2f, %.2f, %.1f mm)",
                      sample.what.c_str(), Mm(sample.world_T_tool.translation).c_str(), s.wrist_measure,
                      s.elbow_measure, s.shoulder_measure_m * 1e3, o.min_wrist_measure, o.min_elbow_measure,
                      o.min_shoulder_m * 1e3);
        singular_problem = text;
      }
    }
    // Palm and fingers against everything but the workpiece (which the pads hold or are about to).
    const std::vector<robot::GripperBox> boxes = robot::GripperBoxes(model.gripper, sample.width_m);
    for (std::size_t b = 0; b < boxes.size(); ++b) {
      const geometry::Pose3 world_T_box = sample.world_T_tool * boxes[b].tool_T_box;
      for (int obj = 0; obj < static_cast<int>(world.scene.objects.size()); ++obj) {
        if (obj == workpiece) continue;
        const scene::SceneObject& obstacle = Object(world, obj);
        const geometry::DistanceResult d =
            geometry::ShapeDistance(shapes[b], world_T_box, obstacle.shape, obstacle.world_T_object, 0.05);
        const double distance = d.intersecting ? 0.0 : d.distance;
        if (distance < report.min_gripper_clearance_m) {
          report.min_gripper_clearance_m = distance;
          std::snprintf(text, sizeof text, "the %s %s %.1f mm %s %s at %s, the tool at %s", boxes[b].name.c_str(),
                        d.intersecting ? "overlaps" : "comes", distance * 1e3, d.intersecting ? "into" : "from",
                        obstacle.name.c_str(), sample.what.c_str(), Mm(sample.world_T_tool.translation).c_str());
          report.closest = text;
          if (distance < o.gripper_clearance_m && gripper_problem.empty()) {
            gripper_problem = report.closest + " (the gripper must keep " +
                              json::FormatNumber(o.gripper_clearance_m * 1e3) + " mm)";
          }
        }
      }
    }
  }
  if (report.problem.empty()) report.problem = gripper_problem;
  if (report.problem.empty()) report.problem = singular_problem;
  report.feasible = report.problem.empty();
  return report;
}

namespace {

sim::WorkpiecePath ToPath(const sim::WorkpiecePath& like, const std::vector<geometry::Pose3>& poses) {
  sim::WorkpiecePath out;
  out.workpiece = like.workpiece;
  out.step_s = like.step_s;
  out.capture_objects = like.capture_objects;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    sim::PathNode node;
    node.time_s = static_cast<double>(i);
    node.world_T_workpiece = poses[i];
    out.nodes.push_back(node);
  }
  return out;
}

}  // namespace

Result<PlanResult> GenerateProgram(const scene::Scene& scene, const sim::WorkpiecePath& path, const PlanOptions& options,
                                   const robot::RobotModel* robot) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  if (robot && !scene.robot) return Status::InvalidInput("the scene places no robot (its \"robot\" entry) to plan for");
  const auto start = std::chrono::steady_clock::now();
  sim::SimOptions sim_options;
  sim_options.settle_force_n = 0.0;  // the band floats: only its own forces move it
  // One band iteration moves a node d_t * f * step: 0.1 m/s/N * 1 N * 10 ms = 1 mm, small against
  // the node spacing, so the Gauss-Seidel sweep does not oscillate (50 ms made nodes jitter by mm).
  sim_options.step_s = 0.01;
  auto built = sim::SimWorld::Build(scene, sim_options);
  if (!built.ok()) return built.status();
  const sim::SimWorld& world = *built;
  auto band = MakeBand(world, path, options);
  if (!band.ok()) return band.status();

  PlanResult result;
  result.initial = path;
  PlanMetrics& m = result.metrics;
  std::vector<geometry::Pose3> initial;
  for (const sim::PathNode& n : path.nodes) initial.push_back(n.world_T_workpiece);
  m.length_before_m = PathLength(initial);
  m.nodes_before = static_cast<int>(path.nodes.size());

  // Clearance to unwanted obstacles away from the ends and required stretches: farther along the
  // path than the repulsion range plus the workpiece's own radius (closer than that, the block
  // cannot be clear of what it is about to touch or has just left).
  const double away = options.repulsion_range_m + world.scene.objects[static_cast<std::size_t>(band->workpiece)].shape.bounding_radius();
  auto clearance_away = [&](const Band& b) {
    std::vector<double> arc(b.nodes.size(), 0.0);
    for (std::size_t i = 1; i < b.nodes.size(); ++i) {
      arc[i] = arc[i - 1] + (b.nodes[i].pose.translation - b.nodes[i - 1].pose.translation).norm();
    }
    double best = kInf;
    for (std::size_t i = 0; i < b.nodes.size(); ++i) {
      bool near_required = arc[i] < away || arc.back() - arc[i] < away;
      for (std::size_t j = 0; j < b.nodes.size() && !near_required; ++j) {
        near_required = !b.nodes[j].required.empty() && std::abs(arc[i] - arc[j]) < away;
      }
      if (near_required) continue;
      best = std::min(best, Clearance(world, b.workpiece, b.nodes[i].pose, {}, 1.0));
    }
    return best;
  };
  m.min_clearance_before_m = clearance_away(*band);

  const auto deform_start = std::chrono::steady_clock::now();
  const DeformStats deform = Deform(world, *band, options);
  m.iterations = deform.iterations;
  m.band_converged = deform.converged;
  m.deform_ms = Elapsed(deform_start);
  m.nodes_deformed = static_cast<int>(band->nodes.size());
  std::vector<geometry::Pose3> deformed;
  for (const PlanNode& n : band->nodes) deformed.push_back(n.pose);
  result.deformed = ToPath(path, deformed);

  const auto simplify_start = std::chrono::steady_clock::now();
  const std::vector<int> knots = Simplify(world, *band, options);
  m.simplify_ms = Elapsed(simplify_start);
  std::vector<geometry::Pose3> simplified;
  Band knot_band;
  knot_band.workpiece = band->workpiece;
  for (int k : knots) {
    simplified.push_back(band->nodes[static_cast<std::size_t>(k)].pose);
    knot_band.nodes.push_back(band->nodes[static_cast<std::size_t>(k)]);
  }
  result.simplified = ToPath(path, simplified);
  m.knots = static_cast<int>(knots.size());
  m.length_after_m = PathLength(simplified);

  // Clearance of the simplified path over its continuous motion, away from required stretches.
  {
    Band dense;
    dense.workpiece = band->workpiece;
    for (std::size_t k = 0; k + 1 < knot_band.nodes.size(); ++k) {
      for (int s = 0; s < 16; ++s) {
        PlanNode node;
        node.pose = geometry::Interpolate(knot_band.nodes[k].pose, knot_band.nodes[k + 1].pose, s / 16.0);
        if (s == 0) node.required = knot_band.nodes[k].required;
        dense.nodes.push_back(node);
      }
    }
    dense.nodes.push_back(knot_band.nodes.back());
    m.min_clearance_after_m = clearance_away(dense);
  }
  // Required contacts kept: every required node of the deformed band within eps_o of its objects.
  for (const PlanNode& n : band->nodes) {
    if (n.required.empty()) continue;
    ++m.required_nodes;
    for (int r : n.required) {
      if (ObjectDistance(world, band->workpiece, n.pose, r) > world.options.capture_distance_m) m.required_contacts_kept = false;
    }
  }

  if (!robot) {
    auto program = MakeProgram(world, *band, knots, options);
    if (!program.ok()) return program.status();
    result.program = std::move(program).value();
  } else {
    // The grasp (paper §6.2 leaves it to the programmer): from above, turned about the tool axis;
    // the feasible candidate farthest from the singularities (relative to the required margins).
    const geometry::Pose3& world_T_base = scene.robot->world_T_base;
    double best_score = -kInf;
    for (int k = 0; k < 4; ++k) {
      const double yaw = k * M_PI / 2;
      auto program = MakeProgram(world, *band, knots, options, yaw);
      if (!program.ok()) return program.status();  // the contacts' bias: the same for every grasp
      GraspReport report = CheckWithRobot(world, *robot, world_T_base, *program, options);
      report.yaw_deg = k * 90.0;
      report.width_m = std::get<robot::GraspCommand>(program->commands.front()).width_m;
      if (report.feasible) {
        const double score = std::min({report.min_wrist_measure / options.min_wrist_measure,
                                       report.min_elbow_measure / options.min_elbow_measure,
                                       report.min_shoulder_m / options.min_shoulder_m});
        if (score > best_score) {
          best_score = score;
          result.program = std::move(program).value();
          m.robot_checked = true;
          m.grasp_yaw_deg = report.yaw_deg;
          m.min_gripper_clearance_m = report.min_gripper_clearance_m;
          m.min_wrist_measure = report.min_wrist_measure;
          m.min_elbow_measure = report.min_elbow_measure;
          m.min_shoulder_m = report.min_shoulder_m;
        }
      }
      result.grasps.push_back(std::move(report));
    }
    if (!m.robot_checked) {
      std::string why = "no grasp of '" + path.workpiece + "' lets " + robot->name + " run the program:";
      for (const GraspReport& g : result.grasps) {
        why += "\n  grasp turned " + json::FormatNumber(g.yaw_deg) + " deg: " + g.problem;
      }
      return Status::Failed(why);
    }
  }
  m.commands = static_cast<int>(result.program.commands.size());
  for (const robot::Command& c : result.program.commands) {
    if (std::holds_alternative<robot::MoveCommand>(c) || std::holds_alternative<robot::ContactMoveCommand>(c)) {
      ++m.motion_commands;
    }
  }
  m.total_ms = Elapsed(start);
  return result;
}

}  // namespace teachsim::plan
