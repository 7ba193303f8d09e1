// teachsim bench simulate: microseconds per simulator step (median, p99) and distance queries
// per step on the puzzle scene under the two demonstrations and random drags, and in the same run
// MuJoCo's mj_step on the same boxes (table, frame parts, free blocks) as a peer (issue 3).
#include <mujoco/mujoco.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <sstream>

#include "teachsim/base/bench_registry.h"
#include "teachsim/base/json.h"
#include "teachsim/sim/demos.h"
#include "teachsim/sim/script.h"

namespace teachsim::sim {
namespace {

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5));
  return v[i];
}

// The scene's boxes as MJCF: fixed objects as world geoms, movable ones as free bodies.
std::string SceneToMjcf(const scene::Scene& scene) {
  std::ostringstream x;
  x.precision(9);
  x << "<mujoco model=\"puzzle\"><option timestep=\"0.002\"/><worldbody>\n";
  auto geom = [&](const scene::ShapeSpec& spec, const geometry::Pose3& pose, auto&& self) -> void {
    if (spec.kind == scene::ShapeSpec::Kind::kBox) {
      const Eigen::Quaterniond& q = pose.rotation;
      x << "<geom type=\"box\" size=\"" << spec.box_size.x() / 2 << " " << spec.box_size.y() / 2 << " "
        << spec.box_size.z() / 2 << "\" pos=\"" << pose.translation.x() << " " << pose.translation.y() << " "
        << pose.translation.z() << "\" quat=\"" << q.w() << " " << q.x() << " " << q.y() << " " << q.z()
        << "\" density=\"600\"/>\n";
    } else if (spec.kind == scene::ShapeSpec::Kind::kParts) {
      for (const auto& part : spec.parts) self(part.shape, pose * part.pose, self);
    }
  };
  for (const scene::SceneObject& o : scene.objects) {
    if (o.fixed) {
      geom(o.shape_spec, o.world_T_object, geom);
    } else {
      const auto& p = o.world_T_object;
      x << "<body name=\"" << o.name << "\" pos=\"" << p.translation.x() << " " << p.translation.y() << " "
        << p.translation.z() << "\" quat=\"" << p.rotation.w() << " " << p.rotation.x() << " " << p.rotation.y()
        << " " << p.rotation.z() << "\"><freejoint/>\n";
      geom(o.shape_spec, geometry::Pose3::Identity(), geom);
      x << "</body>\n";
    }
  }
  x << "</worldbody></mujoco>\n";
  return x.str();
}

struct MujocoFigures {
  double median_us = 0.0, p99_us = 0.0;
  int steps = 0;
  std::string error;
};

MujocoFigures TimeMujoco(const scene::Scene& scene, int steps) {
  MujocoFigures out;
  const std::string xml = SceneToMjcf(scene);
  mjVFS vfs;
  mj_defaultVFS(&vfs);
  mj_makeEmptyFileVFS(&vfs, "puzzle.xml", static_cast<int>(xml.size()));
  const int index = mj_findFileVFS(&vfs, "puzzle.xml");
  std::copy(xml.begin(), xml.end(), static_cast<char*>(vfs.filedata[index]));
  char error[1000] = "";
  mjModel* m = mj_loadXML("puzzle.xml", &vfs, error, sizeof(error));
  mj_deleteVFS(&vfs);
  if (m == nullptr) {
    out.error = error;
    return out;
  }
  mjData* d = mj_makeData(m);
  // Push the first block sideways so that contacts slide, as in a drag.
  std::vector<double> times;
  for (int i = 0; i < steps; ++i) {
    if (m->nbody > 1) d->xfrc_applied[6 * 1 + 0] = 2.0;
    const auto t0 = std::chrono::steady_clock::now();
    mj_step(m, d);
    times.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
  }
  out.median_us = Percentile(times, 0.5);
  out.p99_us = Percentile(times, 0.99);
  out.steps = steps;
  mj_deleteData(d);
  mj_deleteModel(m);
  return out;
}

int Run(const BenchArgs& args) {
  auto scene = scene::LoadScene(std::string(TEACHSIM_BENCH_SOURCE_DIR) + "/scenes/puzzle.json");
  if (!scene.ok()) {
    std::fprintf(stderr, "teachsim: error: %s\n", scene.status().message().c_str());
    return 2;
  }
  auto world = SimWorld::Build(*scene, {}).value();
  // The paper's line search (golden section over the whole bracket, no end-point test), for the
  // same scripts in the same run.
  SimOptions golden_options;
  golden_options.line_search_golden = true;
  auto golden_world = SimWorld::Build(*scene, golden_options).value();
  struct Case {
    std::string name;
    std::vector<DragScript> scripts;
  };
  std::vector<Case> cases;
  cases.push_back({"cornering", {CorneringScript(*scene, {}).value()}});
  cases.push_back({"around_corner", {AroundCornerScript(*scene).value()}});
  Case random{"random_drags", {}};
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const std::vector<std::string> movable = {"cube", "bar", "tall", "plate", "slab"};
  for (int i = 0; i < (args.quick ? 20 : 200); ++i) {
    DragScript s;
    s.workpiece = movable[static_cast<std::size_t>(i) % movable.size()];
    const Eigen::Vector3d start = scene->objects[static_cast<std::size_t>(scene->FindObject(s.workpiece))].world_T_object.translation;
    s.keyframes = {{0.0, start, std::nullopt}, {1.0, start + Eigen::Vector3d(u(rng), u(rng), 0.2 * u(rng)) * 0.2, std::nullopt}};
    s.settle_s = 0.5;
    random.scripts.push_back(s);
  }
  cases.push_back(random);

  const int repeats = args.quick ? 1 : 5;
  const MujocoFigures mujoco = TimeMujoco(*scene, args.quick ? 500 : 5000);
  json::Json out = json::Json::array();
  for (const Case& c : cases) {
    std::vector<double> step_us;
    long steps = 0;
    double queries = 0.0;
    for (int r = 0; r < repeats; ++r) {
      for (const DragScript& s : c.scripts) {
        RunSummary summary;
        auto path = RunScript(world, s, {}, &summary);
        if (!path.ok()) {
          std::fprintf(stderr, "teachsim: error: %s\n", path.status().message().c_str());
          return 1;
        }
        step_us.insert(step_us.end(), summary.step_us.begin(), summary.step_us.end());
        steps += summary.steps;
        queries += summary.queries_per_step * static_cast<double>(summary.steps);
      }
    }
    std::vector<double> golden_us;
    long golden_steps = 0;
    double golden_queries = 0.0;
    for (const DragScript& s : c.scripts) {
      RunSummary summary;
      auto path = RunScript(golden_world, s, {}, &summary);
      if (!path.ok()) continue;
      golden_us.insert(golden_us.end(), summary.step_us.begin(), summary.step_us.end());
      golden_steps += summary.steps;
      golden_queries += summary.queries_per_step * static_cast<double>(summary.steps);
    }
    const double median = Percentile(step_us, 0.5);
    out.push_back({{"name", c.name},
                   {"steps", steps},
                   {"ours_step_us_median", median},
                   {"ours_step_us_p99", Percentile(step_us, 0.99)},
                   {"queries_per_step", steps > 0 ? queries / static_cast<double>(steps) : 0.0},
                   {"mujoco_step_us_median", mujoco.median_us},
                   {"mujoco_step_us_p99", mujoco.p99_us},
                   {"ratio_to_mujoco", mujoco.median_us > 0 ? median / mujoco.median_us : 0.0},
                   {"real_time_factor", median > 0 ? 0.05e6 / median : 0.0},
                   {"golden_step_us_median", Percentile(golden_us, 0.5)},
                   {"golden_queries_per_step", golden_steps > 0 ? golden_queries / static_cast<double>(golden_steps) : 0.0}});
  }
  if (args.json) {
    json::Json doc{{"benchmark", "simulate"}, {"step_s", 0.05}, {"cases", out}};
    if (!mujoco.error.empty()) doc["mujoco_error"] = mujoco.error;
    std::printf("%s\n", doc.dump(2).c_str());
  } else {
    std::printf("%-14s %8s %12s %12s %10s %14s %8s %12s %10s\n", "case", "steps", "median us", "p99 us", "queries",
                "mujoco us", "ratio", "golden us", "golden q");
    for (const auto& row : out) {
      std::printf("%-14s %8ld %12.1f %12.1f %10.1f %14.2f %8.2f %12.1f %10.1f\n", row["name"].get<std::string>().c_str(),
                  row["steps"].get<long>(), row["ours_step_us_median"].get<double>(), row["ours_step_us_p99"].get<double>(),
                  row["queries_per_step"].get<double>(), row["mujoco_step_us_median"].get<double>(),
                  row["ratio_to_mujoco"].get<double>(), row["golden_step_us_median"].get<double>(),
                  row["golden_queries_per_step"].get<double>());
    }
    if (!mujoco.error.empty()) std::printf("mujoco: %s\n", mujoco.error.c_str());
  }
  return 0;
}

}  // namespace

TEACHSIM_BENCH("simulate", "simulator step time on the demonstrations and random drags, against MuJoCo's mj_step", Run);

}  // namespace teachsim::sim
