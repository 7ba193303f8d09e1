// teachsim inspect --scene FILE: validate a scene and print its objects and the clearances
// between them (a quick check after editing a scene by hand).
#include <cmath>
#include <memory>

#include "commands.h"
#include "teachsim/geometry/toi.h"
#include "teachsim/scene/scene.h"

namespace teachsim::app {

namespace {
int RunInspect(const std::string& path) {
  auto scene = scene::LoadScene(path);
  if (!scene.ok()) return ReportError(scene.status());
  std::printf("%s: %zu objects, %zu cameras%s\n", path.c_str(), scene->objects.size(), scene->cameras.size(),
              scene->robot ? (", robot " + scene->robot->model).c_str() : "");
  for (const scene::SceneObject& o : scene->objects) {
    const Eigen::Vector3d& p = o.world_T_object.translation;
    std::printf("  %-14s %-7s parts %zu  at (%.1f, %.1f, %.1f) mm  thinnest %.1f mm\n", o.name.c_str(),
                o.fixed ? "fixed" : "movable", o.shape.parts().size(), p.x() * 1e3, p.y() * 1e3, p.z() * 1e3,
                o.shape.min_thickness() * 1e3);
  }
  std::printf("clearances of movable objects (mm, closest first):\n");
  int touching = 0;
  for (const scene::SceneObject& a : scene->objects) {
    if (a.fixed) continue;
    for (const scene::SceneObject& b : scene->objects) {
      if (&a == &b || (!b.fixed && &b < &a)) continue;
      geometry::DistanceResult d = geometry::ShapeDistance(a.shape, a.world_T_object, b.shape, b.world_T_object, 0.01);
      if (!std::isfinite(d.distance)) continue;
      if (d.intersecting) ++touching;
      std::printf("  %-14s %-14s %8.3f%s\n", a.name.c_str(), b.name.c_str(), d.distance * 1e3,
                  d.intersecting ? "  TOUCHING OR INTERSECTING" : "");
    }
  }
  if (touching > 0) {
    return ReportError(Status::InvalidInput(path + ": " + std::to_string(touching) + " pairs of objects touch or intersect (movable objects must be apart)"));
  }
  return 0;
}
}  // namespace

void AddSceneCommand(CLI::App& app, Runner* run) {
  auto path = std::make_shared<std::string>();
  CLI::App* sub = app.add_subcommand("inspect", "validate a scene file; print its objects and clearances");
  sub->add_option("--scene", *path, "scene file (JSON, docs/formats.md)")->required();
  sub->callback([path, run] { *run = [path] { return RunInspect(*path); }; });
}

}  // namespace teachsim::app
