// teachsim bench plan: deformation + simplification per demonstration, against OMPL's
// PathSimplifier (shortcutting, B-spline smoothing, vertex reduction) on the same initial path in
// an SE(3) space whose validity checker is our collision test (issue 4).
#include <ompl/base/SpaceInformation.h>
#include <ompl/base/spaces/SE3StateSpace.h>
#include <ompl/geometric/PathGeometric.h>
#include <ompl/geometric/PathSimplifier.h>
#include <ompl/util/Console.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "teachsim/base/bench_registry.h"
#include "teachsim/plan/planner.h"
#include "teachsim/sim/demos.h"

namespace teachsim::plan {
namespace {

namespace ob = ompl::base;
namespace og = ompl::geometric;

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// The figures both methods are judged by, on a densely sampled output path.
struct Judged {
  double length_m = 0.0;
  double min_clearance_m = 0.0;  // to anything not required, away from the ends and required stretches
  bool required_kept = true;
};

Judged Judge(const sim::SimWorld& world, int workpiece, const std::vector<geometry::Pose3>& poses,
             const sim::WorkpiecePath& demonstrated) {
  Judged j;
  j.length_m = PathLength(poses);
  std::vector<geometry::Pose3> dense;
  for (std::size_t i = 0; i + 1 < poses.size(); ++i) {
    for (int s = 0; s < 8; ++s) dense.push_back(geometry::Interpolate(poses[i], poses[i + 1], s / 8.0));
  }
  dense.push_back(poses.back());
  // Required poses: where the demonstration was captured (and its end).
  std::vector<std::pair<Eigen::Vector3d, std::vector<int>>> required;
  for (const sim::PathNode& n : demonstrated.nodes) {
    std::vector<int> objects;
    for (const std::string& name : n.captured) objects.push_back(world.scene.FindObject(name));
    if (!objects.empty()) required.emplace_back(n.world_T_workpiece.translation, objects);
  }
  const double away = 0.02 + world.scene.objects[static_cast<std::size_t>(workpiece)].shape.bounding_radius();
  std::vector<double> arc{0.0};
  for (std::size_t i = 1; i < dense.size(); ++i) arc.push_back(arc.back() + (dense[i].translation - dense[i - 1].translation).norm());
  j.min_clearance_m = 1e300;
  for (std::size_t i = 0; i < dense.size(); ++i) {
    if (arc[i] < away || arc.back() - arc[i] < away) continue;
    bool near = false;
    for (const auto& r : required) near = near || (dense[i].translation - r.first).norm() < away;
    if (near) continue;
    j.min_clearance_m = std::min(j.min_clearance_m, Clearance(world, workpiece, dense[i], {}, 0.05));
  }
  // Kept: between the output samples nearest to the first and the last captured pose of the
  // demonstration, every sample stays within eps_o of the objects captured at both ends.
  if (!required.empty()) {
    auto nearest = [&](const Eigen::Vector3d& p) {
      std::size_t best = 0;
      for (std::size_t i = 1; i < dense.size(); ++i) {
        if ((dense[i].translation - p).norm() < (dense[best].translation - p).norm()) best = i;
      }
      return best;
    };
    const std::size_t from = nearest(required.front().first), to = nearest(required.back().first);
    std::vector<int> both;
    for (int o : required.front().second) {
      if (std::find(required.back().second.begin(), required.back().second.end(), o) != required.back().second.end()) both.push_back(o);
    }
    for (std::size_t i = std::min(from, to); i <= std::max(from, to); ++i) {
      for (int o : both) {
        if (ObjectDistance(world, workpiece, dense[i], o) > world.options.capture_distance_m) j.required_kept = false;
      }
    }
  }
  return j;
}

int Run(const BenchArgs& args) {
  ompl::msg::setLogLevel(ompl::msg::LOG_NONE);
  auto scene = scene::LoadScene(std::string(TEACHSIM_BENCH_SOURCE_DIR) + "/scenes/puzzle.json");
  if (!scene.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", scene.status().message().c_str());
    return 2;
  }
  const sim::SimWorld world = sim::SimWorld::Build(*scene, {}).value();
  struct Case {
    std::string name;
    sim::DragScript script;
  };
  sim::CorneringVariation wander;
  wander.wander = true;
  std::vector<Case> cases = {{"cornering", sim::CorneringScript(*scene, {}).value()},
                             {"cornering_wandering", sim::CorneringScript(*scene, wander).value()},
                             {"around_corner", sim::AroundCornerScript(*scene).value()}};
  const int repeats = args.quick ? 1 : 5;
  json::Json out = json::Json::array();
  for (const Case& c : cases) {
    const sim::WorkpiecePath path = sim::RunScript(world, c.script, {}, nullptr).value();
    const int workpiece = scene->FindObject(c.script.workpiece);
    // Ours.
    std::vector<double> ours_ms;
    Result<PlanResult> ours = Status::Internal("not run");
    for (int r = 0; r < repeats; ++r) {
      ours = GenerateProgram(*scene, path);
      if (!ours.ok()) {
        std::fprintf(stderr, "teachsim: error: %s: %s\n", c.name.c_str(), ours.status().message().c_str());
        return 1;
      }
      ours_ms.push_back(ours->metrics.deform_ms + ours->metrics.simplify_ms);
    }
    std::vector<geometry::Pose3> ours_poses;
    for (const auto& n : ours->simplified.nodes) ours_poses.push_back(n.world_T_workpiece);
    const Judged ours_j = Judge(world, workpiece, ours_poses, path);

    // OMPL on the same initial path.
    auto space = std::make_shared<ob::SE3StateSpace>();
    ob::RealVectorBounds bounds(3);
    bounds.setLow(0, -0.4);
    bounds.setHigh(0, 0.4);
    bounds.setLow(1, -0.3);
    bounds.setHigh(1, 0.3);
    bounds.setLow(2, 0.0);
    bounds.setHigh(2, 0.3);
    space->setBounds(bounds);
    auto si = std::make_shared<ob::SpaceInformation>(space);
    si->setStateValidityChecker([&](const ob::State* state) {
      const auto* s = state->as<ob::SE3StateSpace::StateType>();
      const geometry::Pose3 pose(Eigen::Quaterniond(s->rotation().w, s->rotation().x, s->rotation().y, s->rotation().z),
                                 Eigen::Vector3d(s->getX(), s->getY(), s->getZ()));
      return Clearance(world, workpiece, pose, {}, 0.001) > 0.0;
    });
    si->setStateValidityCheckingResolution(0.002);  // of the space's extent: about 2 mm
    si->setup();
    // OMPL's simplifier on poses [from, to) of the demonstration; returns the simplified poses and
    // adds its time to *ms.
    auto ompl_simplify = [&](std::size_t from, std::size_t to, double* ms) {
      og::PathGeometric geometric(si);
      for (std::size_t i = from; i < to; ++i) {
        const sim::PathNode& n = path.nodes[i];
        ob::ScopedState<ob::SE3StateSpace> st(space);
        st->setXYZ(n.world_T_workpiece.translation.x(), n.world_T_workpiece.translation.y(),
                   n.world_T_workpiece.translation.z());
        const Eigen::Quaterniond& q = n.world_T_workpiece.rotation;
        st->rotation().w = q.w();
        st->rotation().x = q.x();
        st->rotation().y = q.y();
        st->rotation().z = q.z();
        geometric.append(st.get());
      }
      og::PathSimplifier simplifier(si);
      const auto start = std::chrono::steady_clock::now();
      if (geometric.getStateCount() > 2) {
        simplifier.shortcutPath(geometric);
        simplifier.smoothBSpline(geometric);
        simplifier.reduceVertices(geometric);
      }
      *ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      std::vector<geometry::Pose3> poses;
      for (std::size_t i = 0; i < geometric.getStateCount(); ++i) {
        const auto* s = geometric.getState(i)->as<ob::SE3StateSpace::StateType>();
        poses.emplace_back(Eigen::Quaterniond(s->rotation().w, s->rotation().x, s->rotation().y, s->rotation().z),
                           Eigen::Vector3d(s->getX(), s->getY(), s->getZ()));
      }
      return poses;
    };
    std::vector<double> ompl_ms;
    std::vector<geometry::Pose3> ompl_poses;
    for (int r = 0; r < repeats; ++r) {
      double ms = 0.0;
      ompl_poses = ompl_simplify(0, path.nodes.size(), &ms);
      ompl_ms.push_back(ms);
    }
    // A second peer that keeps the required contacts as ours must: OMPL simplifies only the free
    // stretches between captured ones, which stay as demonstrated (the fair length comparison
    // where the demonstration captured objects).
    std::vector<double> kept_ms;
    std::vector<geometry::Pose3> kept_poses;
    for (int r = 0; r < repeats; ++r) {
      double ms = 0.0;
      kept_poses.clear();
      std::size_t i = 0;
      while (i < path.nodes.size()) {
        const bool captured = !path.nodes[i].captured.empty();
        std::size_t j = i;
        while (j < path.nodes.size() && path.nodes[j].captured.empty() != captured) ++j;
        if (captured) {
          for (std::size_t k = i; k < j; ++k) kept_poses.push_back(path.nodes[k].world_T_workpiece);
        } else {
          // The free stretch runs from the last captured pose before it to the first after it.
          const std::size_t from = i > 0 ? i - 1 : i, to = j < path.nodes.size() ? j + 1 : j;
          std::vector<geometry::Pose3> piece = ompl_simplify(from, to, &ms);
          const std::size_t skip_front = i > 0 ? 1 : 0, skip_back = j < path.nodes.size() ? 1 : 0;
          for (std::size_t k = skip_front; k + skip_back < piece.size(); ++k) kept_poses.push_back(piece[k]);
        }
        i = j;
      }
      kept_ms.push_back(ms);
    }
    const Judged kept_j = Judge(world, workpiece, kept_poses, path);
    const Judged ompl_j = Judge(world, workpiece, ompl_poses, path);
    auto finite = [](double v) { return v > 1e299 ? json::Json(nullptr) : json::Json(v); };
    out.push_back({{"name", c.name},
                   {"initial_length_m", PathLength([&] {
                      std::vector<geometry::Pose3> p;
                      for (const auto& n : path.nodes) p.push_back(n.world_T_workpiece);
                      return p;
                    }())},
                   {"ours_ms", Median(ours_ms)},
                   {"ompl_ms", Median(ompl_ms)},
                   {"ours_length_m", ours_j.length_m},
                   {"ompl_length_m", ompl_j.length_m},
                   {"ours_min_clearance_m", finite(ours_j.min_clearance_m)},
                   {"ompl_min_clearance_m", finite(ompl_j.min_clearance_m)},
                   {"ours_required_contacts_kept", ours_j.required_kept},
                   {"ompl_required_contacts_kept", ompl_j.required_kept},
                   {"ompl_contacts_kept_ms", Median(kept_ms)},
                   {"ompl_contacts_kept_length_m", kept_j.length_m},
                   {"ompl_contacts_kept_min_clearance_m", finite(kept_j.min_clearance_m)},
                   {"ompl_contacts_kept_required_contacts_kept", kept_j.required_kept},
                   {"ours_iterations", ours->metrics.iterations},
                   {"ours_band_converged", ours->metrics.band_converged},
                   {"ours_motion_commands", ours->metrics.motion_commands}});
  }
  if (args.json) {
    std::printf("%s\n", json::Json{{"benchmark", "plan"}, {"cases", out}}.dump(2).c_str());
  } else {
    std::printf("%-22s %9s %9s %10s %10s %10s %11s %11s %6s %6s %6s\n", "case", "ours ms", "ompl ms", "ours mm",
                "ompl mm", "ompl+c mm", "ours clr mm", "ompl clr mm", "ours", "ompl", "ompl+c");
    for (const auto& row : out) {
      auto clr = [](const json::Json& v) { return v.is_null() ? -1.0 : v.get<double>() * 1e3; };
      std::printf("%-22s %9.1f %9.1f %10.1f %10.1f %10.1f %11.1f %11.1f %6s %6s %6s\n",
                  row["name"].get<std::string>().c_str(), row["ours_ms"].get<double>(), row["ompl_ms"].get<double>(),
                  row["ours_length_m"].get<double>() * 1e3, row["ompl_length_m"].get<double>() * 1e3,
                  row["ompl_contacts_kept_length_m"].get<double>() * 1e3, clr(row["ours_min_clearance_m"]),
                  clr(row["ompl_min_clearance_m"]), row["ours_required_contacts_kept"].get<bool>() ? "kept" : "lost",
                  row["ompl_required_contacts_kept"].get<bool>() ? "kept" : "lost",
                  row["ompl_contacts_kept_required_contacts_kept"].get<bool>() ? "kept" : "lost");
    }
    std::printf("(clearance -1: no point of the path lies away from the ends and required stretches;\n"
                " ompl+c: OMPL simplifies only the stretches outside the captured ones)\n");
  }
  return 0;
}

}  // namespace

TEACHSIM_BENCH("plan", "path deformation + simplification per demonstration, against OMPL's PathSimplifier", Run);

}  // namespace teachsim::plan
