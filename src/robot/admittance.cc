#include "teachsim/robot/admittance.h"

#include <cmath>

#include "teachsim/base/json.h"

namespace teachsim::robot {

Status AdmittanceOptions::Validate() const {
  if (!(min_clip_speed_mps >= 0 && std::isfinite(min_clip_speed_mps))) {
    return Status::InvalidInput("AdmittanceOptions::min_clip_speed_mps = " +
                                json::FormatNumber(min_clip_speed_mps) + " must be >= 0");
  }
  if (!(max_offset_m > 0 && std::isfinite(max_offset_m))) {
    return Status::InvalidInput("AdmittanceOptions::max_offset_m = " + json::FormatNumber(max_offset_m) +
                                " must be > 0");
  }
  return Status::Ok();
}

void AdmittanceStep(double stiffness, double damping, const AdmittanceOptions& options,
                    const Eigen::Vector3d& force, double clip_speed_mps, double dt_s,
                    AdmittanceState* state) {
  TEACHSIM_CHECK(stiffness > 0 && damping > 0 && dt_s > 0);
  const Eigen::Vector3d rest = force / stiffness;
  const double decay = std::exp(-stiffness * dt_s / damping);
  Eigen::Vector3d next = rest + (state->offset_m - rest) * decay;
  Eigen::Vector3d velocity = (next - state->offset_m) / dt_s;
  state->clipped = false;
  if (options.clip_velocity) {
    const double clip = std::max(clip_speed_mps, options.min_clip_speed_mps);
    const double speed = velocity.norm();
    if (speed > clip) {
      velocity *= clip / speed;
      state->clipped = true;
    }
  }
  next = state->offset_m + velocity * dt_s;
  const double norm = next.norm();
  if (norm > options.max_offset_m) next *= options.max_offset_m / norm;
  state->velocity_mps = (next - state->offset_m) / dt_s;
  state->offset_m = next;
}

}  // namespace teachsim::robot
