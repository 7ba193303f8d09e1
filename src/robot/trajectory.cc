#include "teachsim/robot/trajectory.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace teachsim::robot {

Status MotionLimits::Validate() const {
  const std::pair<const char*, double> fields[] = {{"speed_mps", speed_mps},
                                                   {"angular_speed_rad_s", angular_speed_rad_s},
                                                   {"accel_mps2", accel_mps2},
                                                   {"angular_accel_rad_s2", angular_accel_rad_s2}};
  for (const auto& [name, value] : fields) {
    if (!(std::isfinite(value) && value > 0)) {
      return Status::InvalidInput(std::string("MotionLimits::") + name + " = " + json::FormatNumber(value) +
                                  " must be > 0");
    }
  }
  return Status::Ok();
}

CartesianLine::CartesianLine(const geometry::Pose3& start, const geometry::Pose3& goal,
                             const MotionLimits& limits)
    : start_(start), goal_(goal) {
  TEACHSIM_CHECK(limits.Validate().ok());
  length_m_ = geometry::TranslationDistance(start, goal);
  angle_rad_ = geometry::RotationAngle(start, goal);
  if (length_m_ < 1e-12 && angle_rad_ < 1e-12) return;  // nothing to do: duration 0
  // The slower of translation and rotation sets the pace of s.
  double rate = std::numeric_limits<double>::infinity(), accel = std::numeric_limits<double>::infinity();
  if (length_m_ > 0) {
    rate = std::min(rate, limits.speed_mps / length_m_);
    accel = std::min(accel, limits.accel_mps2 / length_m_);
  }
  if (angle_rad_ > 0) {
    rate = std::min(rate, limits.angular_speed_rad_s / angle_rad_);
    accel = std::min(accel, limits.angular_accel_rad_s2 / angle_rad_);
  }
  accel_s_ = accel;
  if (rate * rate / accel >= 1) {  // triangular: never reaches cruise
    ramp_s_ = std::sqrt(1 / accel);
    peak_s_rate_ = accel * ramp_s_;
    duration_s_ = 2 * ramp_s_;
  } else {
    peak_s_rate_ = rate;
    ramp_s_ = rate / accel;
    duration_s_ = 1 / rate + ramp_s_;
  }
}

CartesianLine::Sample CartesianLine::At(double t_s) const {
  Sample out;
  if (duration_s_ <= 0) {
    out.pose = goal_;
    out.s = 1;
    return out;
  }
  const double t = std::clamp(t_s, 0.0, duration_s_);
  double s, rate;
  if (t < ramp_s_) {
    s = 0.5 * accel_s_ * t * t;
    rate = accel_s_ * t;
  } else if (t <= duration_s_ - ramp_s_) {
    s = 0.5 * accel_s_ * ramp_s_ * ramp_s_ + peak_s_rate_ * (t - ramp_s_);
    rate = peak_s_rate_;
  } else {
    double left = duration_s_ - t;
    s = 1 - 0.5 * accel_s_ * left * left;
    rate = accel_s_ * left;
  }
  out.s = std::clamp(s, 0.0, 1.0);
  out.pose = geometry::Interpolate(start_, goal_, out.s);
  out.speed_mps = rate * length_m_;
  out.angular_speed_rad_s = rate * angle_rad_;
  return out;
}

}  // namespace teachsim::robot
