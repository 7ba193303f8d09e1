#include "teachsim/robot/kinematics.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>

namespace teachsim::robot {

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
constexpr double kPi = std::numbers::pi;

Matrix3d RotX(double a) {
  double c = std::cos(a), s = std::sin(a);
  Matrix3d R;
  R << 1, 0, 0, 0, c, -s, 0, s, c;
  return R;
}

Matrix3d RotY(double a) {
  double c = std::cos(a), s = std::sin(a);
  Matrix3d R;
  R << c, 0, s, 0, 1, 0, -s, 0, c;
  return R;
}

Matrix3d RotZ(double a) {
  double c = std::cos(a), s = std::sin(a);
  Matrix3d R;
  R << c, -s, 0, s, c, 0, 0, 0, 1;
  return R;
}

struct Frame {
  Matrix3d R = Matrix3d::Identity();
  Vector3d p = Vector3d::Zero();
};

// One modified-DH step: RotX(alpha) TransX(a) RotZ(theta) TransZ(d).
Frame Step(const Frame& f, const DhJoint& j, double theta) {
  Frame out;
  out.R = f.R * RotX(j.alpha_rad) * RotZ(theta);
  out.p = f.p + f.R.col(0) * j.a_m + out.R.col(2) * j.d_m;
  return out;
}

geometry::Pose3 ToPose(const Frame& f) { return {Eigen::Quaterniond(f.R).normalized(), f.p}; }

Frame FlangeFrame(const RobotModel& m, const Joints& q) {
  Frame f;
  for (int i = 0; i < kNumJoints; ++i) f = Step(f, m.joints[i], q[i] + m.joints[i].theta_offset_rad);
  return f;
}

// The joint value equivalent (mod 2 pi) to q that lies within [lower, upper] and is nearest
// `near`; returns false when no equivalent lies within the limits.
bool Representative(double q, double lower, double upper, double near, double* out) {
  bool found = false;
  double best = 0;
  for (int k = -2; k <= 2; ++k) {
    double v = q + 2 * kPi * k;
    if (v < lower || v > upper) continue;
    if (!found || std::abs(v - near) < std::abs(best - near)) best = v;
    found = true;
  }
  if (found) *out = best;
  return found;
}

// Elbow and shoulder measures from theta2, theta3 (DH angles), see DetectSingularities.
void ArmMeasures(const RobotModel& m, double theta2, double theta3, double* elbow, double* rho) {
  double a2 = m.upper_arm_m(), a3 = m.elbow_offset_m(), d4 = m.forearm_m();
  double c3 = std::cos(theta3), s3 = std::sin(theta3);
  double X = a2 + a3 * c3 - d4 * s3, Y = a3 * s3 + d4 * c3;
  *elbow = std::abs(Y) / std::hypot(a3, d4);
  *rho = std::cos(theta2) * X - std::sin(theta2) * Y;
}

Singularities MakeSingularities(double wrist, double elbow, double rho, const SingularityOptions& o) {
  Singularities s;
  s.wrist_measure = wrist;
  s.elbow_measure = elbow;
  s.shoulder_measure_m = std::abs(rho);
  s.wrist = wrist < o.wrist_tolerance;
  s.elbow = elbow < o.elbow_tolerance;
  s.shoulder = std::abs(rho) < o.shoulder_tolerance_m;
  return s;
}

std::string Mm(const Vector3d& p) {
  char buffer[96];
  std::snprintf(buffer, sizeof buffer, "(%.1f, %.1f, %.1f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return buffer;
}

}  // namespace

double WrapAngle(double a) {
  a = std::remainder(a, 2 * kPi);  // [-pi, pi]
  return a <= -kPi ? a + 2 * kPi : a;
}

std::string IkBranch::Name() const {
  return std::string(shoulder_right ? "right" : "left") + "/" + (elbow_up ? "up" : "down") + "/" +
         (wrist_flip ? "flip" : "noflip");
}

const char* IkStatusName(IkStatus status) {
  switch (status) {
    case IkStatus::kOk:
      return "ok";
    case IkStatus::kInvalidPose:
      return "invalid pose";
    case IkStatus::kOutOfReach:
      return "out of reach";
    case IkStatus::kInsideReach:
      return "too close to the shoulder";
    case IkStatus::kBeyondLimits:
      return "beyond the joint limits";
  }
  return "?";
}

std::string Singularities::Describe() const {
  if (!any()) return "regular";
  std::string out;
  char buffer[96];
  if (wrist) {
    std::snprintf(buffer, sizeof buffer, "wrist singular (|sin theta5| = %.2g)", wrist_measure);
    out += buffer;
  }
  if (elbow) {
    std::snprintf(buffer, sizeof buffer, "%selbow singular (arm stretched or folded, |sin| = %.2g)",
                  out.empty() ? "" : ", ", elbow_measure);
    out += buffer;
  }
  if (shoulder) {
    std::snprintf(buffer, sizeof buffer, "%sshoulder singular (wrist centre %.2g mm from joint 1's axis)",
                  out.empty() ? "" : ", ", shoulder_measure_m * 1e3);
    out += buffer;
  }
  return out;
}

std::array<geometry::Pose3, kNumJoints + 1> LinkFrames(const RobotModel& m, const Joints& q) {
  std::array<geometry::Pose3, kNumJoints + 1> frames;
  Frame f;
  frames[0] = ToPose(f);
  for (int i = 0; i < kNumJoints; ++i) {
    f = Step(f, m.joints[i], q[i] + m.joints[i].theta_offset_rad);
    frames[i + 1] = ToPose(f);
  }
  return frames;
}

geometry::Pose3 FlangePose(const RobotModel& m, const Joints& q) { return ToPose(FlangeFrame(m, q)); }

geometry::Pose3 ToolPose(const RobotModel& m, const Joints& q) { return FlangePose(m, q) * m.flange_T_tool; }

Jacobian ToolJacobian(const RobotModel& m, const Joints& q) {
  Jacobian J;
  Frame f;
  std::array<Frame, kNumJoints> frames;
  for (int i = 0; i < kNumJoints; ++i) {
    f = Step(f, m.joints[i], q[i] + m.joints[i].theta_offset_rad);
    frames[i] = f;
  }
  Vector3d tool = f.p + f.R * m.flange_T_tool.translation;
  for (int i = 0; i < kNumJoints; ++i) {
    Vector3d z = frames[i].R.col(2);  // joint i turns about z_i through the origin of frame i
    J.block<3, 1>(0, i) = z.cross(tool - frames[i].p);
    J.block<3, 1>(3, i) = z;
  }
  return J;
}

Singularities DetectSingularities(const RobotModel& m, const Joints& q, const SingularityOptions& options) {
  double elbow = 0, rho = 0;
  ArmMeasures(m, q[1] + m.joints[1].theta_offset_rad, q[2] + m.joints[2].theta_offset_rad, &elbow, &rho);
  double wrist = std::abs(std::sin(q[4] + m.joints[4].theta_offset_rad));
  return MakeSingularities(wrist, elbow, rho, options);
}

IkSolutions SolveFlangeIk(const RobotModel& m, const geometry::Pose3& base_T_flange, const Joints& hint,
                          const SingularityOptions& options) {
  IkSolutions out;
  if (!base_T_flange.IsValid()) {
    out.status = IkStatus::kInvalidPose;
    return out;
  }
  const Matrix3d R = base_T_flange.rotation.normalized().toRotationMatrix();
  const double a2 = m.upper_arm_m(), a3 = m.elbow_offset_m(), d4 = m.forearm_m();
  const double D = m.shoulder_offset_m();
  const Vector3d wc = base_T_flange.translation - m.flange_m() * R.col(2);  // the wrist centre
  const double px = wc.x(), py = wc.y(), h = -(wc.z() - m.base_height_m());
  const double scale = a2 + std::hypot(a3, d4) + std::abs(D);

  // Shoulder: (px, py) = RotZ(theta1) (rho, D), rho = +-sqrt(px^2 + py^2 - D^2).
  const double r2 = px * px + py * py;
  const double rho_sq = r2 - D * D;
  if (rho_sq < -1e-12 * scale * scale) {
    out.status = IkStatus::kInsideReach;
    return out;
  }
  const double rho_abs = std::sqrt(std::max(rho_sq, 0.0));

  // Elbow: in the arm's plane (rho, h) = Rot(theta2) (X, Y), with X = a2 + a3 c3 - d4 s3 and
  // Y = a3 s3 + d4 c3, so rho^2 + h^2 = a2^2 + a3^2 + d4^2 + 2 a2 (a3 c3 - d4 s3).
  const double Rf = std::hypot(a3, d4), phi = std::atan2(d4, a3);
  double K = (rho_abs * rho_abs + h * h - a2 * a2 - Rf * Rf) / (2 * a2);
  if (K > Rf * (1 + 1e-12)) {
    out.status = IkStatus::kOutOfReach;
    return out;
  }
  if (K < -Rf * (1 + 1e-12)) {
    out.status = IkStatus::kInsideReach;
    return out;
  }
  const double c = std::clamp(K / Rf, -1.0, 1.0);
  const double s_abs = std::sqrt(std::max(0.0, 1 - c * c));

  const double hint_theta1 = hint[0] + m.joints[0].theta_offset_rad;
  const double hint_theta4 = hint[3] + m.joints[3].theta_offset_rad;
  bool any_within = false;
  for (int shoulder = 0; shoulder < 2; ++shoulder) {
    const double rho = shoulder == 0 ? rho_abs : -rho_abs;
    double theta1;
    if (r2 < 1e-24 * scale * scale) {
      theta1 = hint_theta1 + (shoulder == 0 ? 0 : kPi);  // on joint 1's axis: theta1 is free
    } else {
      theta1 = std::atan2(py, px) - std::atan2(D, rho);
    }
    for (int elbow = 0; elbow < 2; ++elbow) {
      const double theta3 = std::atan2(elbow == 0 ? s_abs : -s_abs, c) - phi;
      const double c3 = std::cos(theta3), s3 = std::sin(theta3);
      const double X = a2 + a3 * c3 - d4 * s3, Y = a3 * s3 + d4 * c3;
      const double theta2 = std::atan2(h, rho) - std::atan2(Y, X);
      // Elbow above the shoulder–wrist line (physical z), whichever way the arm reaches.
      const double rho_e = a2 * std::cos(theta2), z_e = -a2 * std::sin(theta2);
      const double cross = rho * z_e + h * rho_e;
      const bool elbow_up = (shoulder == 0 ? cross : -cross) > 0;

      Frame f;
      f = Step(f, m.joints[0], theta1);
      f = Step(f, m.joints[1], theta2);
      f = Step(f, m.joints[2], theta3);
      // R36 = RotX(-90) Rz(t4) RotX(90) Rz(t5) RotX(-90) Rz(t6) = Ry(t4) Rz(t5) Ry(t6) RotX(-90).
      const Matrix3d M = f.R.transpose() * R * RotX(kPi / 2);
      const double s5_abs = std::hypot(M(0, 1), M(2, 1));
      double elbow_measure = 0, rho_check = 0;
      ArmMeasures(m, theta2, theta3, &elbow_measure, &rho_check);
      for (int flip = 0; flip < 2; ++flip) {
        double theta4 = s5_abs < 1e-12 ? hint_theta4 : std::atan2(M(2, 1), -M(0, 1));
        if (flip == 1) theta4 += kPi;
        // Given theta4, theta5 and theta6 follow exactly from N = Ry(-t4) M = Rz(t5) Ry(t6): this
        // keeps the round trip exact near the wrist singularity.
        const Matrix3d N = RotY(-theta4) * M;
        const double theta5 = std::atan2(-N(0, 1), N(1, 1));
        const double theta6 = std::atan2(-N(2, 0), N(2, 2));
        const double theta[kNumJoints] = {theta1, theta2, theta3, theta4, theta5, theta6};

        IkSolution& sol = out.solutions[out.count++];
        sol.branch = {shoulder == 0, elbow_up, flip == 1};
        sol.within_limits = true;
        for (int i = 0; i < kNumJoints; ++i) {
          const DhJoint& j = m.joints[i];
          double q = WrapAngle(theta[i] - j.theta_offset_rad);
          double within;
          if (Representative(q, j.lower_rad, j.upper_rad, q, &within)) {
            q = within;
          } else {
            sol.within_limits = false;
          }
          sol.q[i] = q;
        }
        sol.singularities = MakeSingularities(std::abs(std::sin(theta5)), elbow_measure, rho, options);
        any_within = any_within || sol.within_limits;
      }
    }
  }
  out.status = any_within ? IkStatus::kOk : IkStatus::kBeyondLimits;
  return out;
}

IkSolutions SolveToolIk(const RobotModel& m, const geometry::Pose3& base_T_tool, const Joints& hint,
                        const SingularityOptions& options) {
  return SolveFlangeIk(m, base_T_tool * m.flange_T_tool.Inverse(), hint, options);
}

Result<IkSolution> NearestToolIk(const RobotModel& m, const geometry::Pose3& base_T_tool,
                                 const Joints& current, const SingularityOptions& options) {
  IkSolutions all = SolveToolIk(m, base_T_tool, current, options);
  // Messages are built only on failure: this runs every control cycle and must not allocate.
  auto where = [&] { return "tool pose at " + Mm(base_T_tool.translation) + " in the base frame"; };
  auto wc_distance = [&] {
    const Vector3d wc = (base_T_tool * m.flange_T_tool.Inverse()) * Vector3d(0, 0, -m.flange_m());
    return std::hypot(std::hypot(wc.x(), wc.y()), wc.z() - m.base_height_m());  // from the shoulder
  };
  char buffer[200];
  switch (all.status) {
    case IkStatus::kInvalidPose:
      return Status::InvalidInput(where() + " is not a valid rigid transform");
    case IkStatus::kOutOfReach:
      std::snprintf(
          buffer, sizeof buffer,
          " is out of reach: the wrist centre would be %.1f mm from the shoulder, the arm reaches %.1f mm",
          wc_distance() * 1e3,
          std::hypot(m.upper_arm_m() + std::hypot(m.elbow_offset_m(), m.forearm_m()), m.shoulder_offset_m()) *
              1e3);
      return Status::InvalidInput(where() + buffer);
    case IkStatus::kInsideReach:
      std::snprintf(buffer, sizeof buffer, " is too close to the shoulder: wrist centre %.1f mm from it",
                    wc_distance() * 1e3);
      return Status::InvalidInput(where() + buffer);
    case IkStatus::kBeyondLimits:
    case IkStatus::kOk:
      break;
  }
  const Joints speeds = m.MaxSpeeds();
  int best = -1;
  double best_cost = std::numeric_limits<double>::infinity();
  Joints best_q = Joints::Zero();
  for (int s = 0; s < all.count; ++s) {
    const IkSolution& sol = all.solutions[s];
    if (!sol.within_limits) continue;
    Joints q;
    double cost = 0;
    for (int i = 0; i < kNumJoints; ++i) {
      const DhJoint& j = m.joints[i];
      bool ok = Representative(sol.q[i], j.lower_rad, j.upper_rad, current[i], &q[i]);
      TEACHSIM_CHECK(ok);
      double t = (q[i] - current[i]) / speeds[i];
      cost += t * t;
    }
    if (cost < best_cost) {
      best_cost = cost;
      best = s;
      best_q = q;
    }
  }
  if (best < 0) {
    // Name the joint that blocks the branch nearest to the current one.
    const IkSolution* nearest = nullptr;
    double nearest_distance = std::numeric_limits<double>::infinity();
    for (int s = 0; s < all.count; ++s) {
      double d = (all.solutions[s].q - current).cwiseAbs().maxCoeff();
      if (d < nearest_distance) {
        nearest_distance = d;
        nearest = &all.solutions[s];
      }
    }
    std::string detail;
    for (int i = 0; nearest != nullptr && i < kNumJoints; ++i) {
      const DhJoint& j = m.joints[i];
      if (nearest->q[i] < j.lower_rad || nearest->q[i] > j.upper_rad) {
        std::snprintf(buffer, sizeof buffer, "%s%s at %.3f rad, limits [%.3f, %.3f]",
                      detail.empty() ? "" : "; ", j.name.c_str(), nearest->q[i], j.lower_rad, j.upper_rad);
        detail += buffer;
      }
    }
    return Status::InvalidInput(where() + " is reachable only beyond the joint limits (nearest branch " +
                                nearest->branch.Name() + ": " + detail + ")");
  }
  IkSolution result = all.solutions[best];
  result.q = best_q;
  return result;
}

}  // namespace teachsim::robot
