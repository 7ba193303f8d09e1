// teachsim bench distance: our GJK (cold and warm-started) against FCL 0.7's libccd GJK on the
// same pose sets, plus each one's largest error against the exhaustive oracle (issue 2).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <fcl/narrowphase/distance.h>
#include <map>
#include <memory>

#include "teachsim/base/bench_registry.h"
#include "teachsim/base/json.h"
#include "teachsim/geometry/distance.h"
#include "tests/random_poses.h"

namespace teachsim::geometry {
namespace {

// FCL's libccd GJK stops when its simplex improves by less than this; the default (1e-6 m) is
// what users get, 1e-9 m is as tight as it converges reliably (measured here).
constexpr double kFclTolerance = 1e-9;

struct Case {
  std::string name;
  std::vector<std::shared_ptr<const ConvexPolyhedron>> a, b;  // one shape pair per pose (or shared)
  std::vector<testing::PosePair> poses;
  std::vector<testing::PosePair> previous;  // the pose 0.1 mm / 0.05 deg before each, for warm starts
  bool sequence = false;                    // poses form a motion: warm start from the previous query
};

std::shared_ptr<fcl::CollisionGeometryd> ToFcl(const ConvexPolyhedron& p) {
  const Eigen::Vector3d size = p.local_bounds().Size();
  if (p.vertices().size() == 8 && p.faces().size() == 6 &&
      std::abs(p.Volume() - size.prod()) < 1e-12 * size.prod()) {
    return std::make_shared<fcl::Boxd>(size.x(), size.y(), size.z());
  }
  auto vertices = std::make_shared<std::vector<Eigen::Vector3d>>(p.vertices());
  auto faces = std::make_shared<std::vector<int>>();
  for (const Face& f : p.faces()) {
    faces->push_back(static_cast<int>(f.vertices.size()));
    faces->insert(faces->end(), f.vertices.begin(), f.vertices.end());
  }
  return std::make_shared<fcl::Convexd>(vertices, static_cast<int>(p.faces().size()), faces);
}

fcl::Transform3d ToFcl(const Pose3& pose) {
  fcl::Transform3d t = fcl::Transform3d::Identity();
  t.linear() = pose.RotationMatrix();
  t.translation() = pose.translation;
  return t;
}

Pose3 Nudge(const Pose3& pose, std::mt19937_64& rng) {
  return Integrate(pose, Twist{testing::RandomUnit(rng) * 1e-4, testing::RandomUnit(rng) * (0.05 * M_PI / 180)}, 1.0);
}

std::vector<Case> MakeCases(int count) {
  std::vector<Case> cases;
  auto cube = std::make_shared<const ConvexPolyhedron>(ConvexPolyhedron::Box({0.045, 0.045, 0.045}).value());
  auto bar = std::make_shared<const ConvexPolyhedron>(ConvexPolyhedron::Box({0.09, 0.045, 0.045}).value());
  std::mt19937_64 rng(42);
  auto add = [&](std::string name, std::shared_ptr<const ConvexPolyhedron> a, std::shared_ptr<const ConvexPolyhedron> b,
                 std::vector<testing::PosePair> poses) {
    Case c;
    c.name = std::move(name);
    for (const auto& p : poses) {
      c.a.push_back(a);
      c.b.push_back(b);
      c.previous.push_back({p.a, Nudge(p.b, rng)});
    }
    c.poses = std::move(poses);
    return c;
  };
  cases.push_back(add("box_box_random", cube, bar, testing::MakePoses(*cube, *bar, testing::PoseSet::kRandom, count, 1)));
  cases.push_back(
      add("box_box_near_parallel", cube, bar, testing::MakePoses(*cube, *bar, testing::PoseSet::kNearParallel, count, 2)));
  // Convex-convex, 8 to 40 vertices: a fresh pair of hulls every 10 poses.
  Case convex;
  convex.name = "convex_convex_8_40";
  std::uniform_int_distribution<int> vertex_count(8, 40);
  while (static_cast<int>(convex.poses.size()) < count) {
    auto a = std::make_shared<const ConvexPolyhedron>(
        ConvexPolyhedron::Hull(testing::RandomConvexPoints(rng, vertex_count(rng), 0.03)).value());
    auto b = std::make_shared<const ConvexPolyhedron>(
        ConvexPolyhedron::Hull(testing::RandomConvexPoints(rng, vertex_count(rng), 0.03)).value());
    for (const auto& p : testing::MakePoses(*a, *b, testing::PoseSet::kRandom, 10, rng())) {
      convex.a.push_back(a);
      convex.b.push_back(b);
      convex.poses.push_back(p);
      convex.previous.push_back({p.a, Nudge(p.b, rng)});
    }
  }
  cases.push_back(std::move(convex));
  Case motion = add("box_box_small_motion", cube, bar, testing::MakeMotion(*cube, *bar, count, 3));
  motion.sequence = true;
  cases.push_back(std::move(motion));
  return cases;
}

struct Figures {
  double ours_cold_ns = 0, ours_warm_ns = 0, fcl_ns = 0;
  double ours_max_error_m = 0, fcl_max_error_m = 0, ours_max_over_m = 0, fcl_max_over_m = 0;
  std::size_t queries = 0;
};

class Collector : public benchmark::BenchmarkReporter {
 public:
  bool ReportContext(const Context&) override { return true; }
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& run : runs) {
      if (run.run_type == Run::RT_Aggregate && run.aggregate_name == "median") {
        // Each benchmark iteration is one query; time in ns. CPU time of the benchmark thread
        // is the figure: on a machine shared with other builds, wall-clock time also counts the
        // time the thread waited for a core.
        median_ns[run.run_name.function_name] = run.GetAdjustedCPUTime();
        median_real_ns[run.run_name.function_name] = run.GetAdjustedRealTime();
      }
    }
  }
  std::map<std::string, double> median_ns;
  std::map<std::string, double> median_real_ns;
};

int Run(const BenchArgs& args) {
  const int count = args.quick ? 200 : 2000;
  std::vector<Case> cases = MakeCases(count);
  std::map<std::string, Figures> figures;
  std::vector<std::shared_ptr<fcl::CollisionGeometryd>> keep_alive;

  for (const Case& c : cases) {
    Figures& f = figures[c.name];
    f.queries = c.poses.size();
    // Accuracy against the oracle, and FCL geometry for each pose's shapes.
    std::map<const ConvexPolyhedron*, std::shared_ptr<fcl::CollisionGeometryd>> fcl_shapes;
    for (std::size_t i = 0; i < c.poses.size(); ++i) {
      for (const auto* p : {c.a[i].get(), c.b[i].get()}) {
        if (!fcl_shapes.count(p)) fcl_shapes[p] = ToFcl(*p);
      }
    }
    fcl::DistanceRequestd request;
    request.gjk_solver_type = fcl::GST_LIBCCD;
    request.distance_tolerance = kFclTolerance;
    DistanceCache cache;
    for (std::size_t i = 0; i < c.poses.size(); ++i) {
      const auto& p = c.poses[i];
      const double oracle = DistanceBruteForce(*c.a[i], p.a, *c.b[i], p.b);
      const double ours = Distance(*c.a[i], p.a, *c.b[i], p.b, c.sequence ? &cache : nullptr).distance;
      fcl::DistanceResultd result;
      fcl::distance(fcl_shapes[c.a[i].get()].get(), ToFcl(p.a), fcl_shapes[c.b[i].get()].get(), ToFcl(p.b), request,
                    result);
      f.ours_max_error_m = std::max(f.ours_max_error_m, std::abs(ours - oracle));
      f.fcl_max_error_m = std::max(f.fcl_max_error_m, std::abs(result.min_distance - oracle));
      f.ours_max_over_m = std::max(f.ours_max_over_m, ours - oracle);
      f.fcl_max_over_m = std::max(f.fcl_max_over_m, result.min_distance - oracle);
    }
    for (auto& [ptr, shape] : fcl_shapes) keep_alive.push_back(shape);

    // Timing: one benchmark iteration is one query, cycling through the pose set.
    const Case* cp = &c;
    benchmark::RegisterBenchmark((c.name + "/ours_cold").c_str(), [cp](benchmark::State& state) {
      std::size_t i = 0;
      for (auto _ : state) {
        const auto& p = cp->poses[i];
        benchmark::DoNotOptimize(Distance(*cp->a[i], p.a, *cp->b[i], p.b).distance);
        if (++i == cp->poses.size()) i = 0;
      }
    })->Repetitions(args.quick ? 2 : 7)->ReportAggregatesOnly();
    benchmark::RegisterBenchmark((c.name + "/ours_warm").c_str(), [cp](benchmark::State& state) {
      // Warm: each query starts from the cache of a query 0.1 mm / 0.05 deg away (the previous
      // simulator step), or, for a motion sequence, from the previous query itself.
      std::vector<DistanceCache> caches(cp->poses.size());
      for (std::size_t k = 0; k < cp->poses.size(); ++k) {
        Distance(*cp->a[k], cp->previous[k].a, *cp->b[k], cp->previous[k].b, &caches[k]);
      }
      DistanceCache running = caches[0];
      std::size_t i = 0;
      for (auto _ : state) {
        const auto& p = cp->poses[i];
        DistanceCache* start = cp->sequence ? &running : &caches[i];
        DistanceCache copy = *start;
        benchmark::DoNotOptimize(Distance(*cp->a[i], p.a, *cp->b[i], p.b, &copy).distance);
        if (cp->sequence) running = copy;
        if (++i == cp->poses.size()) i = 0;
      }
    })->Repetitions(args.quick ? 2 : 7)->ReportAggregatesOnly();
    std::vector<std::pair<fcl::CollisionGeometryd*, fcl::CollisionGeometryd*>> pairs;
    for (std::size_t i = 0; i < c.poses.size(); ++i) {
      pairs.emplace_back(fcl_shapes[c.a[i].get()].get(), fcl_shapes[c.b[i].get()].get());
    }
    std::vector<std::pair<fcl::Transform3d, fcl::Transform3d>> transforms;
    for (const auto& p : c.poses) transforms.emplace_back(ToFcl(p.a), ToFcl(p.b));
    benchmark::RegisterBenchmark((c.name + "/fcl").c_str(), [pairs, transforms, request](benchmark::State& state) {
      std::size_t i = 0;
      for (auto _ : state) {
        fcl::DistanceResultd result;
        fcl::distance(pairs[i].first, transforms[i].first, pairs[i].second, transforms[i].second, request, result);
        benchmark::DoNotOptimize(result.min_distance);
        if (++i == pairs.size()) i = 0;
      }
    })->Repetitions(args.quick ? 2 : 7)->ReportAggregatesOnly();
  }

  std::vector<std::string> argv_storage = {"teachsim-bench-distance"};
  if (args.quick) argv_storage.push_back("--benchmark_min_time=0.01");
  for (const std::string& e : args.extra) argv_storage.push_back(e);
  std::vector<char*> argv;
  for (std::string& s : argv_storage) argv.push_back(s.data());
  int argc = static_cast<int>(argv.size());
  benchmark::Initialize(&argc, argv.data());
  Collector collector;
  benchmark::RunSpecifiedBenchmarks(&collector);
  benchmark::ClearRegisteredBenchmarks();

  json::Json out = json::Json::array();
  for (const Case& c : cases) {
    Figures& f = figures[c.name];
    f.ours_cold_ns = collector.median_ns[c.name + "/ours_cold"];
    f.ours_warm_ns = collector.median_ns[c.name + "/ours_warm"];
    f.fcl_ns = collector.median_ns[c.name + "/fcl"];
    out.push_back({{"name", c.name},
                   {"queries", f.queries},
                   {"ours_cold_ns", f.ours_cold_ns},
                   {"ours_warm_ns", f.ours_warm_ns},
                   {"fcl_ns", f.fcl_ns},
                   {"ours_max_error_m", f.ours_max_error_m},
                   {"fcl_max_error_m", f.fcl_max_error_m},
                   {"ours_max_overestimate_m", f.ours_max_over_m},
                   {"fcl_max_overestimate_m", f.fcl_max_over_m},
                   {"ours_cold_wall_ns", collector.median_real_ns[c.name + "/ours_cold"]},
                   {"ours_warm_wall_ns", collector.median_real_ns[c.name + "/ours_warm"]},
                   {"fcl_wall_ns", collector.median_real_ns[c.name + "/fcl"]},
                   {"cold_speedup_vs_fcl", f.ours_cold_ns > 0 ? f.fcl_ns / f.ours_cold_ns : 0.0},
                   {"warm_speedup_vs_fcl", f.ours_warm_ns > 0 ? f.fcl_ns / f.ours_warm_ns : 0.0}});
  }
  if (args.json) {
    std::printf("%s\n", json::Json{{"benchmark", "distance"},
                                   {"fcl_distance_tolerance_m", kFclTolerance},
                                   {"time", "median CPU time of the benchmark thread per query; *_wall_ns: wall clock"},
                                   {"cases", out}}.dump(2).c_str());
  } else {
    std::printf("%-24s %10s %10s %10s %8s %8s %12s %12s\n", "case", "cold ns", "warm ns", "fcl ns", "cold x",
                "warm x", "ours err m", "fcl err m");
    for (const auto& row : out) {
      std::printf("%-24s %10.0f %10.0f %10.0f %8.1f %8.1f %12.2e %12.2e\n", row["name"].get<std::string>().c_str(),
                  row["ours_cold_ns"].get<double>(), row["ours_warm_ns"].get<double>(), row["fcl_ns"].get<double>(),
                  row["cold_speedup_vs_fcl"].get<double>(), row["warm_speedup_vs_fcl"].get<double>(),
                  row["ours_max_error_m"].get<double>(), row["fcl_max_error_m"].get<double>());
    }
  }
  return 0;
}

}  // namespace

TEACHSIM_BENCH("distance", "GJK distance, cold and warm, against FCL 0.7 (libccd) with errors vs the oracle", Run);

}  // namespace teachsim::geometry
