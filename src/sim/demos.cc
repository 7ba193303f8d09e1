#include "teachsim/sim/demos.h"

#include <cmath>
#include <optional>
#include <random>

namespace teachsim::sim {

namespace {
Status Require(const scene::Scene& scene, std::initializer_list<const char*> names) {
  for (const char* name : names) {
    if (scene.FindObject(name) < 0) {
      return Status::InvalidInput(std::string("the demonstration needs an object named '") + name +
                                  "' (as in scenes/puzzle.json)");
    }
  }
  return Status::Ok();
}
}  // namespace

// The puzzle scene's frame: inside x in [-0.10, 0.10], y in [-0.08, 0.08]; outside x in [-0.12,
// 0.12], y in [-0.10, 0.10]; walls 60 mm high; the lip over the south-west inside corner.
Result<DragScript> CorneringScript(const scene::Scene& scene, const CorneringVariation& v) {
  TEACHSIM_RETURN_IF_ERROR(Require(scene, {"cube", "frame", "table"}));
  const scene::SceneObject& cube = scene.objects[static_cast<std::size_t>(scene.FindObject("cube"))];
  DragScript script;
  script.workpiece = "cube";
  const double z = cube.world_T_object.translation.z();
  script.start_pose = geometry::Pose3(Eigen::Quaterniond(Eigen::AngleAxisd(v.start_yaw_rad, Eigen::Vector3d::UnitZ())),
                                      Eigen::Vector3d(v.start_x_m, v.start_y_m, z));
  // The corner pose of the cube's centre: 22.5 mm from both inside walls, under the lip.
  const Eigen::Vector3d corner(-0.1 + 0.0225, -0.08 + 0.0225, z);
  const Eigen::Vector3d start = script.start_pose->translation;
  script.keyframes.push_back({0.0, start, std::nullopt});
  double t = 0.0;
  if (v.wander) {
    // Feel the way: over to the east wall, along to the north wall, across to the west wall,
    // and only then into the corner.
    script.keyframes.push_back({t += 1.5, Eigen::Vector3d(0.085, 0.0, z), std::nullopt});
    script.keyframes.push_back({t += 1.5, Eigen::Vector3d(0.07, 0.066, z), std::nullopt});
    script.keyframes.push_back({t += 2.0, Eigen::Vector3d(-0.02, 0.066, z), std::nullopt});
    script.keyframes.push_back({t += 1.5, Eigen::Vector3d(-0.085, 0.03, z), std::nullopt});
    script.keyframes.push_back({t += 1.5, Eigen::Vector3d(-0.03, -0.02, z), std::nullopt});  // back into the open
  }
  // Aim 10 mm beyond the corner on the diagonal: the walls and the table do the aligning.
  script.keyframes.push_back({t += 3.0, corner + Eigen::Vector3d(-0.007, -0.007, 0.0), std::nullopt});
  script.settle_s = 3.0;
  return script;
}

Result<DragScript> AroundCornerScript(const scene::Scene& scene) {
  TEACHSIM_RETURN_IF_ERROR(Require(scene, {"plate", "frame", "table"}));
  const scene::SceneObject& plate = scene.objects[static_cast<std::size_t>(scene.FindObject("plate"))];
  DragScript script;
  script.workpiece = "plate";
  // Capture on for the stretch along the frame (Figure 12 bottom): from when the plate meets the
  // east wall (squared to it as it arrives) to the end; the approach before it is free motion.
  script.capture = {{"frame", 1.8, 1e300}, {"table", 1.8, 1e300}};
  const Eigen::Vector3d start = plate.world_T_object.translation;
  const double z = start.z();
  const double half = 0.03;    // the plate's half side
  const double press = 0.008;  // the dragger runs 8 mm inside the frame: about 0.8 N of contact force
  const Eigen::Vector3d corner(0.12, -0.10, z);  // the frame's south-east outside corner
  auto yaw = [](double deg) {
    return std::optional<Eigen::Quaterniond>(Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitZ()));
  };
  // Around the corner the plate pivots -90 degrees about the corner's edge, its north-west corner
  // on it, as a person turns a part around a post. A plate slid around the corner without turning
  // cannot be held by any robot: the jaws that grip it along the east wall close across the south
  // wall afterwards (a finger would be inside the wall), and jaws turned the other way put the palm
  // over the east wall. Turned with the plate, the jaws stay parallel to the wall they slide along.
  // Half way round: the plate centre straight below the corner edge (corner + R(-45 deg) (half, -half)),
  // the dragger pressed into both walls' directions.
  const Eigen::Vector3d halfway =
      corner + Eigen::Vector3d(0, -half * std::sqrt(2.0), 0) + press * Eigen::Vector3d(-1, 1, 0).normalized();
  script.keyframes = {
      {0.0, start, std::nullopt},
      {2.0, Eigen::Vector3d(0.12 + half - press, -0.05, z), yaw(0)},              // to the east wall, square to it
      {5.0, Eigen::Vector3d(0.12 + half - press, -0.10 - half, z), yaw(0)},       // south along it, to the corner
      {6.5, halfway, yaw(-45)},                                                   // pivoting about the corner edge
      {8.0, Eigen::Vector3d(0.12 - half, -0.1 - half + press, z), yaw(-90)},      // on the south wall
      {10.0, Eigen::Vector3d(0.0, -0.1 - half + press, z), yaw(-90)},             // west along the south wall
  };
  script.settle_s = 2.0;
  return script;
}

CorneringVariation RandomCornering(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(-0.02, 0.06), y(-0.02, 0.045), sign(-1.0, 1.0);
  CorneringVariation v;
  v.start_x_m = x(rng);
  v.start_y_m = y(rng);
  v.start_yaw_rad = (sign(rng) < 0 ? -1.0 : 1.0) * 20.0 * 3.14159265358979323846 / 180.0;
  return v;
}

}  // namespace teachsim::sim
