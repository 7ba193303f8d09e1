#include "teachsim/sim/simulator.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "teachsim/sim/lcp.h"

namespace teachsim::sim {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kGolden = 0.6180339887498949;
constexpr int kMaxAdvance = 64;  // conservative-advancement iterations per pair and step

Status Positive(const char* field, double value) {
  if (std::isfinite(value) && value > 0.0) return Status::Ok();
  return Status::InvalidInput(std::string("SimOptions::") + field + " = " + json::FormatNumber(value) + " must be > 0");
}

}  // namespace

Status SimOptions::Validate() const {
  for (auto [field, value] : {std::pair{"step_s", step_s}, {"contact_distance_m", contact_distance_m},
                              {"barrier_distance_m", barrier_distance_m}, {"capture_distance_m", capture_distance_m},
                              {"translation_gain", translation_gain}, {"rotation_gain", rotation_gain},
                              {"barrier_constant_j", barrier_constant_j}, {"max_speed_mps", max_speed_mps},
                              {"max_angular_speed_radps", max_angular_speed_radps},
                              {"search_tolerance", search_tolerance}}) {
    TEACHSIM_RETURN_IF_ERROR(Positive(field, value));
  }
  if (!(barrier_distance_m < contact_distance_m && contact_distance_m < capture_distance_m)) {
    return Status::InvalidInput("SimOptions: barrier_distance_m < contact_distance_m < capture_distance_m must hold, got " +
                                json::FormatNumber(barrier_distance_m) + ", " + json::FormatNumber(contact_distance_m) +
                                ", " + json::FormatNumber(capture_distance_m));
  }
  if (!(settle_force_n >= 0.0) || !std::isfinite(settle_force_n)) {
    return Status::InvalidInput("SimOptions::settle_force_n = " + json::FormatNumber(settle_force_n) + " must be >= 0");
  }
  return Status::Ok();
}

Result<SimWorld> SimWorld::Build(scene::Scene scene, const SimOptions& options) {
  TEACHSIM_RETURN_IF_ERROR(options.Validate());
  SimWorld world;
  world.scene = std::move(scene);
  world.options = options;
  for (std::size_t i = 0; i < world.scene.objects.size(); ++i) {
    const scene::SceneObject& o = world.scene.objects[i];
    for (const geometry::ShapePart& part : o.shape.parts()) {
      ObstaclePart p;
      p.object = static_cast<int>(i);
      p.convex = part.convex.get();
      p.world_T_part = o.world_T_object * part.shape_T_part;
      p.bounds = p.convex->WorldBounds(p.world_T_part);
      world.parts.push_back(p);
    }
  }
  return world;
}

namespace {

// Everything one step needs about the workpiece and the obstacles near it.
class StepContext {
 public:
  StepContext(const SimWorld& world, SimState& state) : world_(world), state_(state), o_(world.options) {
    const scene::SceneObject& wp = world.scene.objects[static_cast<std::size_t>(state.workpiece)];
    for (const geometry::ShapePart& part : wp.shape.parts()) {
      wp_parts_.push_back(&part);
      double r = 0.0;
      for (const Eigen::Vector3d& v : part.convex->vertices()) r = std::max(r, (part.shape_T_part * v).norm());
      radius_.push_back(r);
    }
    radius_max_ = *std::max_element(radius_.begin(), radius_.end());
  }

  // Obstacle parts that the workpiece can reach this step (or must stay near, for capture).
  void GatherCandidates(double reach) {
    candidates_.clear();
    const geometry::Aabb box = world_.scene.objects[static_cast<std::size_t>(state_.workpiece)]
                                   .shape.WorldBounds(state_.world_T_workpiece)
                                   .Inflated(reach);
    for (int j = 0; j < static_cast<int>(world_.parts.size()); ++j) {
      const ObstaclePart& p = world_.parts[static_cast<std::size_t>(j)];
      if (p.object == state_.workpiece) continue;
      if (box.Overlaps(p.bounds) || IsEngaged(p.object)) candidates_.push_back(j);
    }
  }

  bool IsCapture(int object) const {
    return std::find(state_.capture.begin(), state_.capture.end(), object) != state_.capture.end();
  }
  bool IsEngaged(int object) const {
    return std::find(state_.engaged.begin(), state_.engaged.end(), object) != state_.engaged.end();
  }

  geometry::Pose3 PartPose(const geometry::Pose3& world_T_wp, int k) const {
    return world_T_wp * wp_parts_[static_cast<std::size_t>(k)]->shape_T_part;
  }

  geometry::DistanceResult Distance(const geometry::Pose3& world_T_wp, int k, int j) {
    const ObstaclePart& p = world_.parts[static_cast<std::size_t>(j)];
    ++queries_;
    ++state_.stats.distance_queries;
    geometry::DistanceCache& cache = state_.caches[static_cast<std::size_t>(k) * world_.parts.size() + j];
    return geometry::Distance(*wp_parts_[static_cast<std::size_t>(k)]->convex, PartPose(world_T_wp, k), *p.convex,
                              p.world_T_part, &cache);
  }

  // Per-object smallest distance at a pose, over the candidates whose boxes are within `range`.
  struct Closest {
    int object = -1;
    double distance = kInf;
    Eigen::Vector3d normal_push = Eigen::Vector3d::Zero();  // from the obstacle toward the workpiece
    Eigen::Vector3d point_on_wp = Eigen::Vector3d::Zero();
    bool intersecting = false;
  };
  void Distances(const geometry::Pose3& world_T_wp, double range, std::vector<Closest>* out) {
    out->clear();
    for (int k = 0; k < static_cast<int>(wp_parts_.size()); ++k) {
      const geometry::Aabb box = wp_parts_[static_cast<std::size_t>(k)]->convex->WorldBounds(PartPose(world_T_wp, k));
      for (int j : candidates_) {
        const ObstaclePart& p = world_.parts[static_cast<std::size_t>(j)];
        const bool engaged = IsEngaged(p.object);
        if (!engaged && box.Distance(p.bounds) > range) continue;
        const geometry::DistanceResult d = Distance(world_T_wp, k, j);
        auto it = std::find_if(out->begin(), out->end(), [&](const Closest& c) { return c.object == p.object; });
        if (it == out->end()) {
          out->push_back({});
          it = out->end() - 1;
          it->object = p.object;
        }
        if (d.distance < it->distance || d.intersecting) {
          it->distance = d.distance;
          it->normal_push = -d.normal;
          it->point_on_wp = d.point_a;
          it->intersecting = d.intersecting;
        }
      }
    }
  }

  std::vector<Contact> Contacts(const geometry::Pose3& world_T_wp, std::vector<Eigen::Vector3d>* levers) {
    std::vector<Contact> contacts;
    for (int k = 0; k < static_cast<int>(wp_parts_.size()); ++k) {
      const geometry::Pose3 pose_k = PartPose(world_T_wp, k);
      const geometry::Aabb box = wp_parts_[static_cast<std::size_t>(k)]->convex->WorldBounds(pose_k);
      for (int j : candidates_) {
        const ObstaclePart& p = world_.parts[static_cast<std::size_t>(j)];
        if (box.Distance(p.bounds) > o_.contact_distance_m) continue;
        const geometry::DistanceResult d = Distance(world_T_wp, k, j);
        if (d.distance > o_.contact_distance_m) continue;
        const geometry::ContactSet set = geometry::ComputeContacts(
            *wp_parts_[static_cast<std::size_t>(k)]->convex, pose_k, *p.convex, p.world_T_part, d, o_.contact_distance_m);
        for (const geometry::ContactPoint& cp : set.points) {
          contacts.push_back({p.object, cp.point_b, -cp.normal, cp.distance, IsCapture(p.object)});
          if (levers != nullptr) levers->push_back(cp.point_a - world_T_wp.translation);
        }
      }
    }
    return contacts;
  }

  // Conservative advancement of the whole workpiece along start->end from s0 until some candidate
  // part comes within `target`; returns the first such s (1 when none does).
  double AdvanceToward(const geometry::Pose3& start, const geometry::Pose3& end, double s0, double target,
                       double* min_seen) {
    const Eigen::Vector3d dp = end.translation - start.translation;
    const double theta = start.rotation.angularDistance(end.rotation);
    double s_first = 1.0;
    for (int k = 0; k < static_cast<int>(wp_parts_.size()); ++k) {
      const double radius = radius_[static_cast<std::size_t>(k)];
      geometry::Aabb swept = wp_parts_[static_cast<std::size_t>(k)]->convex->WorldBounds(PartPose(start, k));
      swept.Extend(wp_parts_[static_cast<std::size_t>(k)]->convex->WorldBounds(PartPose(end, k)));
      swept = swept.Inflated(theta * radius + target);
      for (int j : candidates_) {
        const ObstaclePart& p = world_.parts[static_cast<std::size_t>(j)];
        if (!swept.Overlaps(p.bounds)) continue;
        double s = s0;
        int it = 0;
        for (; it < kMaxAdvance && s < s_first; ++it) {
          const geometry::DistanceResult d = Distance(geometry::Interpolate(start, end, s), k, j);
          *min_seen = std::min(*min_seen, d.distance);
          const double gap = d.distance - target;
          if (d.intersecting || gap <= 1e-7) {
            s_first = std::min(s_first, s);
            break;
          }
          // d.normal points from the workpiece toward the obstacle: the approach speed along the
          // certified separating plane is at most normal . dp + theta * r (per unit s).
          const double approach = std::max(0.0, d.normal.dot(dp)) + theta * radius;
          if (approach <= 0.0) break;
          s += gap / approach;
        }
        // Out of iterations (a slow, grazing approach): the distance is proven >= target only up
        // to s, so the motion stops there.
        if (it == kMaxAdvance) s_first = std::min(s_first, s);
      }
    }
    return s_first;
  }

  // Smallest distance from the workpiece to one object (its candidate parts).
  double ObjectDistance(const geometry::Pose3& world_T_wp, int object) {
    double best = kInf;
    for (int k = 0; k < static_cast<int>(wp_parts_.size()); ++k) {
      for (int j : candidates_) {
        if (world_.parts[static_cast<std::size_t>(j)].object != object) continue;
        best = std::min(best, Distance(world_T_wp, k, j).distance);
      }
    }
    return best;
  }

  // For engaged capture objects: the largest s at which the distance is still within `limit`
  // (bisection on the exact distance; the poses the step ends on always keep the contact, and
  // contact is a matter of the recorded poses, while safety rests on AdvanceToward). Starting
  // beyond the limit (drift), the distance may not grow further.
  double AdvanceAway(const geometry::Pose3& start, const geometry::Pose3& end, double limit) {
    double s_first = 1.0;
    for (int object : state_.engaged) {
      const double bound = std::max(limit, ObjectDistance(start, object) + 1e-9);
      auto within = [&](double s) { return ObjectDistance(geometry::Interpolate(start, end, s), object) <= bound; };
      if (within(s_first)) continue;
      double lo = 0.0, hi = s_first;
      for (int i = 0; i < 12; ++i) {
        const double mid = 0.5 * (lo + hi);
        (within(mid) ? lo : hi) = mid;
      }
      s_first = lo;
    }
    return s_first;
  }

  // The net potential along the motion (paper eq. 2 and U_v), with U_i = +inf below zero.
  double Potential(const geometry::Pose3& world_T_wp, double s, double work) {
    const double eb = o_.barrier_distance_m, eo = o_.capture_distance_m, k = o_.barrier_constant_j;
    Distances(world_T_wp, eb, &scratch_);
    double u = -work * s;
    for (const Closest& c : scratch_) {
      if (c.intersecting || c.distance <= 0.0) return kInf;
      const double delta = c.distance / eb;
      if (delta < 1.0) u += k * (delta - 1.0 - std::log(delta));
      if (IsEngaged(c.object)) {
        const double outer = (eo - c.distance) / eb;
        if (outer <= 0.0) return kInf;
        if (outer < 1.0) u += k * (outer - 1.0 - std::log(outer));
      }
    }
    return u;
  }

  int queries() const { return queries_; }
  double radius_max() const { return radius_max_; }
  int part_count() const { return static_cast<int>(wp_parts_.size()); }

 private:
  const SimWorld& world_;
  SimState& state_;
  const SimOptions& o_;
  std::vector<const geometry::ShapePart*> wp_parts_;
  std::vector<double> radius_;
  double radius_max_ = 0.0;
  std::vector<int> candidates_;
  std::vector<Closest> scratch_;
  int queries_ = 0;
};

// Contact rows are unilateral. Each engaged capture object adds one bilateral row at its closest
// point: its distance stays constant to first order, which still lets the workpiece slide along
// it, turn about the contact and go around its corners (making every contact point bilateral
// locked a misaligned block against a wall here).
LcpProblem MakeProblem(const SimOptions& o, const std::vector<Contact>& contacts,
                       const std::vector<Eigen::Vector3d>& levers, const Vector6& applied,
                       const std::vector<StepContext::Closest>& captured, const Eigen::Vector3d& origin) {
  LcpProblem p;
  p.d_diag << o.translation_gain, o.translation_gain, o.translation_gain, o.rotation_gain, o.rotation_gain,
      o.rotation_gain;
  p.applied = applied;
  p.jt.resize(6, static_cast<Eigen::Index>(contacts.size() + captured.size()));
  Eigen::Index col = 0;
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    p.jt.col(col++) << contacts[i].normal, levers[i].cross(contacts[i].normal);
    p.bilateral.push_back(false);
  }
  for (const StepContext::Closest& c : captured) {
    p.jt.col(col++) << c.normal_push, (c.point_on_wp - origin).cross(c.normal_push);
    p.bilateral.push_back(true);
  }
  return p;
}

}  // namespace

Result<SimState> StartDrag(const SimWorld& world, const std::string& workpiece) {
  const int index = world.scene.FindObject(workpiece);
  if (index < 0) return Status::NotFound("no object named '" + workpiece + "' in the scene");
  const scene::SceneObject& o = world.scene.objects[static_cast<std::size_t>(index)];
  if (o.fixed) return Status::InvalidInput("object '" + workpiece + "' is fixed; only movable objects can be dragged");
  SimState state;
  state.workpiece = index;
  state.world_T_workpiece = o.world_T_object;
  state.caches.assign(o.shape.parts().size() * world.parts.size(), geometry::DistanceCache{});
  StepContext ctx(world, state);
  ctx.GatherCandidates(world.options.capture_distance_m);
  std::vector<StepContext::Closest> closest;
  ctx.Distances(state.world_T_workpiece, kInf, &closest);
  for (const auto& c : closest) {
    if (c.intersecting || c.distance <= 0.0) {
      return Status::InvalidInput("workpiece '" + workpiece + "' touches or intersects '" + world.name(c.object) +
                                  "' at its start pose; movable objects must start apart (at least " +
                                  json::FormatNumber(world.options.barrier_distance_m * 1e3) + " mm)");
    }
    state.stats.min_distance_m = std::min(state.stats.min_distance_m, c.distance);
  }
  return state;
}

std::vector<Contact> CurrentContacts(const SimWorld& world, SimState& state) {
  StepContext ctx(world, state);
  ctx.GatherCandidates(world.options.contact_distance_m);
  return ctx.Contacts(state.world_T_workpiece, nullptr);
}

StepResult Step(const SimWorld& world, SimState& state, const StepInput& input) {
  const SimOptions& o = world.options;
  StepContext ctx(world, state);
  const double dt = o.step_s;
  const double reach = o.max_speed_mps * dt + o.max_angular_speed_radps * dt * ctx.radius_max() + o.capture_distance_m;
  ctx.GatherCandidates(reach);

  StepResult result;
  std::vector<Eigen::Vector3d> levers;
  result.contacts = ctx.Contacts(state.world_T_workpiece, &levers);
  std::vector<StepContext::Closest> closest;
  ctx.Distances(state.world_T_workpiece, o.capture_distance_m, &closest);
  // Capture: contact, once made, is kept (paper §5.2, last paragraph).
  for (const auto& c : closest) {
    if (c.distance <= o.contact_distance_m && ctx.IsCapture(c.object) && !ctx.IsEngaged(c.object)) {
      state.engaged.push_back(c.object);
    }
  }
  for (Contact& c : result.contacts) c.capture = ctx.IsCapture(c.object) && ctx.IsEngaged(c.object);

  Vector6 applied;
  applied << input.force_n + Eigen::Vector3d(0, 0, -o.settle_force_n), input.torque_nm;
  // The paper's method first: capture acts through the barrier alone (bilateral rows only when a
  // step sticks, below).
  // Capture keeps contact (paper §5.2): an engaged capture object in contact holds the workpiece
  // against the part of the applied force that pulls away from it, along its mean contact
  // normal, which leaves the tangential part to slide along it and around its corners. (Turning
  // every capture contact point, or the closest point, into a bilateral LCP row wedged blocks at
  // the junction of two frame parts here.)
  for (int object : state.engaged) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const Contact& c : result.contacts) {
      if (c.object == object) mean += c.normal;
    }
    if (mean.norm() < 1e-9) {
      // Out of contact but still captured (eps_c < d <= eps_o): hold along the closest direction.
      for (const auto& c : closest) {
        if (c.object == object) mean = c.normal_push;
      }
      if (mean.norm() < 1e-9) continue;
    }
    mean.normalize();
    const double pull = applied.head<3>().dot(mean);
    if (pull > 0.0) applied.head<3>() -= pull * mean;
  }
  LcpProblem problem = MakeProblem(o, result.contacts, levers, applied, {}, state.world_T_workpiece.translation);
  LcpSolution lcp = SolveContactLcp(problem);
  Eigen::Vector3d v = lcp.velocity.head<3>();
  Eigen::Vector3d w = lcp.velocity.tail<3>();

  // Barrier gradients (paper §5.2): repel below eps_b; for engaged capture objects, attract
  // within eps_b of eps_o. The raw gradient d_t K/eps_b (1/delta - 1) reaches metres per second
  // near zero distance (it threw blocks 20 mm back from a wall here); it is limited to the speed
  // that restores the barrier distance in one step, which is all it is for.
  const double eb = o.barrier_distance_m, k = o.barrier_constant_j;
  for (const auto& c : closest) {
    if (c.distance < eb) {
      const double gradient = o.translation_gain * (k / eb) * (eb / std::max(c.distance, 1e-3 * eb) - 1.0);
      v += std::min(gradient, (eb - c.distance) / dt) * c.normal_push;
    }
    if (ctx.IsEngaged(c.object) && c.distance > o.contact_distance_m) {
      // Drifted out of contact with a captured object (second-order effects of turning about
      // it): return to the middle of the contact band within one step.
      v -= ((c.distance - 0.5 * o.contact_distance_m) / dt) * c.normal_push;
    }
  }
  if (v.norm() > o.max_speed_mps) v *= o.max_speed_mps / v.norm();
  if (w.norm() > o.max_angular_speed_radps) w *= o.max_angular_speed_radps / w.norm();

  auto search = [&](const Eigen::Vector3d& lin, const Eigen::Vector3d& ang, double* fraction, double* min_seen) {
    const geometry::Pose3 start = state.world_T_workpiece;
    const geometry::Pose3 end = geometry::Integrate(start, geometry::Twist{lin, ang}, dt);
    const double requested = lin.norm() * dt + ang.norm() * dt * ctx.radius_max();
    if (requested < 1e-9) {
      *fraction = 0.0;
      return start;
    }
    // The bracket: [s_b, s_hi]. Below s_b nothing is within eps_b (U is linear, falling); s_hi
    // is where conservative advancement proves the distance still >= eps_b / 10 (and, for
    // engaged capture objects, <= eps_o). Only that stretch is searched, so every pose tried and
    // every motion between them is collision-free.
    const double floor = 0.1 * eb;
    const double s_b = ctx.AdvanceToward(start, end, 0.0, eb, min_seen);
    double s_hi = s_b < 1.0 ? ctx.AdvanceToward(start, end, s_b, floor, min_seen) : 1.0;
    if (!state.engaged.empty()) s_hi = std::min(s_hi, ctx.AdvanceAway(start, end, o.capture_distance_m - 0.1 * eb));
    const bool capture_near = !state.engaged.empty();
    if (s_b >= 1.0 && s_hi >= 1.0 && !capture_near) {
      *fraction = 1.0;
      return end;
    }
    const double work = (lin.squaredNorm() / o.translation_gain + ang.squaredNorm() / o.rotation_gain) * dt;
    auto u = [&](double s) { return ctx.Potential(geometry::Interpolate(start, end, s), s, work); };
    double lo = o.line_search_golden ? 0.0 : std::min(s_b, s_hi);
    double hi = s_hi;
    if (hi <= 0.0) {
      *fraction = 0.0;
      return start;
    }
    if (!o.line_search_golden) {
      // Most steps slide along contacts: U still falls at the end of the bracket.
      const double h = std::max(o.search_tolerance, 1e-6);
      if (hi - h > lo && u(hi) <= u(hi - h)) {
        *fraction = hi;
        return geometry::Interpolate(start, end, hi);
      }
    }
    // Golden section on [lo, hi] (paper §5.2).
    double x1 = hi - kGolden * (hi - lo), x2 = lo + kGolden * (hi - lo);
    double f1 = u(x1), f2 = u(x2);
    while (hi - lo > o.search_tolerance) {
      if (f1 <= f2) {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - kGolden * (hi - lo);
        f1 = u(x1);
      } else {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + kGolden * (hi - lo);
        f2 = u(x2);
      }
    }
    double s = f1 <= f2 ? x1 : x2;
    if (u(0.0) < std::min(f1, f2)) s = 0.0;
    *fraction = s;
    return geometry::Interpolate(start, end, s);
  };

  double fraction = 0.0;
  double min_seen = kInf;
  geometry::Pose3 next = search(v, w, &fraction, &min_seen);
  const double requested = v.norm() * dt + w.norm() * dt * ctx.radius_max();
  const bool could_move = requested > 1e-5;
  if (could_move && fraction * requested < 1e-6) {
    // Sticking (paper §5.2): the force could move the workpiece, yet no finite step is free.
    // Re-project: add the limiting obstacles' closest points at the blocked pose as contacts and
    // move along what is left of the velocity, without the rotation that second-order effects spoil.
    std::vector<StepContext::Closest> near;
    ctx.Distances(state.world_T_workpiece, o.capture_distance_m, &near);
    std::vector<Contact> extra = result.contacts;
    std::vector<Eigen::Vector3d> extra_levers = levers;
    std::vector<StepContext::Closest> held;
    for (const auto& c : near) {
      if (ctx.IsEngaged(c.object)) {
        held.push_back(c);
      } else if (c.distance <= o.contact_distance_m) {
        extra.push_back({c.object, c.point_on_wp, c.normal_push, c.distance, false});
        extra_levers.push_back(c.point_on_wp - state.world_T_workpiece.translation);
      }
    }
    LcpProblem retry = MakeProblem(o, extra, extra_levers, applied, held, state.world_T_workpiece.translation);
    LcpSolution again = SolveContactLcp(retry);
    Eigen::Vector3d v2 = again.velocity.head<3>();
    Eigen::Vector3d w2 = again.velocity.tail<3>();
    if (v2.norm() > o.max_speed_mps) v2 *= o.max_speed_mps / v2.norm();
    if (w2.norm() > o.max_angular_speed_radps) w2 *= o.max_angular_speed_radps / w2.norm();
    // Only a force with a component along the feasible (tangent) motions can stick; one that pulls
    // straight off a captured contact is simply held.
    const bool feasible = (v2.norm() + w2.norm() * ctx.radius_max()) * dt > 1e-5;
    bool moved = false;
    for (int attempt = 0; attempt < 2 && !moved && feasible; ++attempt) {
      if (attempt == 1) w2.setZero();  // then without the rotation that second-order effects spoil
      double fraction2 = 0.0;
      geometry::Pose3 next2 = search(v2, w2, &fraction2, &min_seen);
      if (fraction2 * (v2.norm() + w2.norm() * ctx.radius_max()) * dt >= 1e-6) {
        next = next2;
        fraction = fraction2;
        v = v2;
        w = w2;
        moved = true;
      }
    }
    if (moved) {
      ++state.stats.sticking_resolved;
    } else if (feasible) {
      ++state.stats.sticking_events;
      result.blocked = true;
    }
  }

  state.world_T_workpiece = next;
  state.time_s += dt;
  ++state.stats.steps;
  result.velocity = {v, w};
  result.fraction = fraction;
  for (const auto& c : closest) min_seen = std::min(min_seen, c.distance);
  result.min_distance_m = min_seen;
  state.stats.min_distance_m = std::min(state.stats.min_distance_m, min_seen);
  result.distance_queries = ctx.queries();
  return result;
}

}  // namespace teachsim::sim
