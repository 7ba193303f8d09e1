// The paper's two demonstrations as drag scripts on the default scene (scenes/puzzle.json):
// Figure 1, a block placed into an inside corner of the frame from a misaligned start, and
// Figure 2, a block dragged around an outside corner of the frame, keeping contact with the
// frame and the table (capture on both).
#pragma once

#include <cstdint>

#include "teachsim/sim/script.h"

namespace teachsim::sim {

struct CorneringVariation {
  double start_x_m = 0.03, start_y_m = 0.02;  // the cube's start, inside the frame
  double start_yaw_rad = 20.0 * 3.14159265358979323846 / 180.0;
  bool wander = false;  // the operator feels their way: detours, touches the far wall first
};

// Needs objects "cube", "frame" and "table" as in scenes/puzzle.json.
[[nodiscard]] Result<DragScript> CorneringScript(const scene::Scene& scene, const CorneringVariation& variation = {});
// Needs objects "plate", "frame" and "table" as in scenes/puzzle.json.
[[nodiscard]] Result<DragScript> AroundCornerScript(const scene::Scene& scene);

// A random cornering start (position inside the frame, yaw +-20 deg) from a seed.
CorneringVariation RandomCornering(std::uint64_t seed);

}  // namespace teachsim::sim
