// Position-based impedance (admittance) control on a position-controlled robot (Pelletier & Doyon
// 1994; paper §6.2): the measured contact force drives a low, uniform spring–damper
//   K x + B dx/dt = f
// whose displacement x offsets the trajectory's setpoint. Its output velocity is clipped to the
// robot's current speed against contact-transition instability (paper §6.2: "large enough to
// remove observed forces within one control cycle"); the controller passes the command's speed,
// so the compliance never moves the setpoint faster than the trajectory itself does.
#pragma once

#include <Eigen/Core>

#include "teachsim/base/status.h"

namespace teachsim::robot {

struct AdmittanceOptions {
  bool clip_velocity = true;      // paper §6.2; off only for the ablation
  double min_clip_speed_mps = 0;  // floor of the clip speed
  double max_offset_m = 0.03;     // the compliance never moves the setpoint farther than this
  [[nodiscard]] Status Validate() const;
};

struct AdmittanceState {
  Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();      // x, world frame
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();  // dx/dt over the last cycle
  bool clipped = false;                                    // the last cycle hit the clip
};

// One control cycle, exact for f held over the cycle: x+ = f/K + (x - f/K) exp(-K dt / B); then
// |dx/dt| is clipped to clip_speed_mps. force_n: on the tool, world frame.
void AdmittanceStep(double stiffness_n_per_m, double damping_n_s_per_m, const AdmittanceOptions& options,
                    const Eigen::Vector3d& force_n, double clip_speed_mps, double dt_s,
                    AdmittanceState* state);

}  // namespace teachsim::robot
