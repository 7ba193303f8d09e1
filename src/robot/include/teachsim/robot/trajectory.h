// Straight-line Cartesian trajectories for the 100 Hz task controller (paper §3.1): the tool's
// origin moves on a line and its orientation by slerp, both driven by one path parameter s in
// [0, 1] with a trapezoidal speed profile (continuous speed, bounded acceleration).
#pragma once

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"

namespace teachsim::robot {

struct MotionLimits {
  double speed_mps = 0.25;  // tool origin; ISO 10218-1 reduced speed by default
  double angular_speed_rad_s = 1.0;
  double accel_mps2 = 0.5;
  double angular_accel_rad_s2 = 4.0;
  [[nodiscard]] Status Validate() const;
};

class CartesianLine {
 public:
  struct Sample {
    geometry::Pose3 pose;
    double s = 0;          // path parameter in [0, 1]
    double speed_mps = 0;  // of the tool origin
    double angular_speed_rad_s = 0;
  };

  CartesianLine() = default;
  // limits must be valid (TEACHSIM_CHECK).
  CartesianLine(const geometry::Pose3& start, const geometry::Pose3& goal, const MotionLimits& limits);

  Sample At(double t_s) const;  // clamped to [0, duration]
  double duration_s() const { return duration_s_; }
  double length_m() const { return length_m_; }
  double angle_rad() const { return angle_rad_; }
  double peak_speed_mps() const { return peak_s_rate_ * length_m_; }
  const geometry::Pose3& start() const { return start_; }
  const geometry::Pose3& goal() const { return goal_; }

 private:
  geometry::Pose3 start_, goal_;
  double length_m_ = 0, angle_rad_ = 0;
  double peak_s_rate_ = 0;  // ds/dt at cruise (1/s)
  double accel_s_ = 0;      // d2s/dt2 (1/s^2)
  double ramp_s_ = 0;       // duration of the acceleration ramp (s)
  double duration_s_ = 0;
};

}  // namespace teachsim::robot
