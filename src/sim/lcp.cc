#include "teachsim/sim/lcp.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace teachsim::sim {

namespace {

// Least squares on the passive columns of m; minimum-norm solution when they are dependent.
Eigen::VectorXd SolvePassive(const Eigen::MatrixXd& m, const Eigen::VectorXd& y, const std::vector<int>& passive) {
  Eigen::MatrixXd mp(m.rows(), static_cast<Eigen::Index>(passive.size()));
  for (std::size_t k = 0; k < passive.size(); ++k) mp.col(static_cast<Eigen::Index>(k)) = m.col(passive[k]);
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(mp);
  cod.setThreshold(1e-12);
  return cod.solve(y);
}

}  // namespace

LcpSolution SolveContactLcp(const LcpProblem& p) {
  const Eigen::Index n = p.jt.cols();
  LcpSolution out;
  out.force = Eigen::VectorXd::Zero(n);
  // NNLS form: min |M f - y|^2, M = D^1/2 J^T, y = -D^1/2 F.
  const Vector6 sqrt_d = p.d_diag.cwiseSqrt();
  const Eigen::MatrixXd m = sqrt_d.asDiagonal() * p.jt;
  const Eigen::VectorXd y = -(sqrt_d.cwiseProduct(p.applied));
  auto is_bilateral = [&](Eigen::Index i) {
    return !p.bilateral.empty() && p.bilateral[static_cast<std::size_t>(i)];
  };
  std::vector<int> passive;
  std::vector<bool> in_passive(static_cast<std::size_t>(n), false);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (is_bilateral(i)) {
      passive.push_back(static_cast<int>(i));
      in_passive[static_cast<std::size_t>(i)] = true;
    }
  }
  Eigen::VectorXd f = Eigen::VectorXd::Zero(n);
  if (!passive.empty()) {
    Eigen::VectorXd z = SolvePassive(m, y, passive);
    for (std::size_t k = 0; k < passive.size(); ++k) f(passive[k]) = z(static_cast<Eigen::Index>(k));
  }
  const double scale = std::max(1e-300, m.norm() * (y.norm() + 1e-300));
  const double tol = 1e-13 * scale;
  const int max_iterations = 3 * static_cast<int>(n) + 30;
  int iterations = 0;
  while (iterations < max_iterations) {
    // Gradient of -1/2|Mf - y|^2: w = M^T (y - M f). A positive w_i means raising f_i helps.
    const Eigen::VectorXd w = m.transpose() * (y - m * f);
    Eigen::Index best = -1;
    double best_w = tol;
    for (Eigen::Index i = 0; i < n; ++i) {
      if (!in_passive[static_cast<std::size_t>(i)] && w(i) > best_w) {
        best_w = w(i);
        best = i;
      }
    }
    if (best < 0) break;
    passive.push_back(static_cast<int>(best));
    in_passive[static_cast<std::size_t>(best)] = true;
    // Inner loop: keep unilateral passive forces non-negative.
    while (iterations < max_iterations) {
      ++iterations;
      Eigen::VectorXd z = SolvePassive(m, y, passive);
      double alpha = 1.0;
      int leaving = -1;
      for (std::size_t k = 0; k < passive.size(); ++k) {
        const int i = passive[k];
        if (is_bilateral(i)) continue;
        const double zi = z(static_cast<Eigen::Index>(k));
        if (zi <= 0.0) {
          const double step = f(i) / (f(i) - zi);
          if (step < alpha) {
            alpha = step;
            leaving = i;
          }
        }
      }
      if (leaving < 0) {
        f.setZero();
        for (std::size_t k = 0; k < passive.size(); ++k) f(passive[k]) = z(static_cast<Eigen::Index>(k));
        break;
      }
      for (std::size_t k = 0; k < passive.size(); ++k) {
        const int i = passive[k];
        f(i) += alpha * (z(static_cast<Eigen::Index>(k)) - f(i));
      }
      // Remove every unilateral passive variable that reached zero.
      std::vector<int> kept;
      for (int i : passive) {
        if (!is_bilateral(i) && (i == leaving || f(i) <= 0.0)) {
          f(i) = 0.0;
          in_passive[static_cast<std::size_t>(i)] = false;
        } else {
          kept.push_back(i);
        }
      }
      passive.swap(kept);
    }
  }
  out.iterations = iterations;
  out.converged = iterations < max_iterations;
  out.force = f;
  out.velocity = p.d_diag.cwiseProduct(p.applied + p.jt * f);
  out.normal_velocity = p.jt.transpose() * out.velocity;
  return out;
}

double ComplementarityError(const LcpProblem& p, const LcpSolution& s) {
  const double f_scale = std::max(1.0, p.applied.norm());
  const double v_scale = std::max(1e-6, p.d_diag.maxCoeff() * f_scale);
  double err = 0.0;
  for (Eigen::Index i = 0; i < s.force.size(); ++i) {
    const double f = s.force(i) / f_scale, a = s.normal_velocity(i) / v_scale;
    const bool bilateral = !p.bilateral.empty() && p.bilateral[static_cast<std::size_t>(i)];
    if (bilateral) {
      err = std::max(err, std::abs(a));
    } else {
      err = std::max({err, -a, -f, std::abs(f * a)});
    }
  }
  return err;
}

bool SolveContactLcpBruteForce(const LcpProblem& p, double tolerance, LcpSolution* out) {
  const Eigen::Index n = p.jt.cols();
  if (n > 16) return false;
  const Eigen::MatrixXd a = p.jt.transpose() * p.d_diag.asDiagonal() * p.jt;
  const Eigen::VectorXd b = p.jt.transpose() * p.d_diag.cwiseProduct(p.applied);
  for (long mask = 0; mask < (1L << n); ++mask) {
    std::vector<int> active;
    bool skip = false;
    for (Eigen::Index i = 0; i < n; ++i) {
      const bool on = (mask >> i) & 1;
      const bool bilateral = !p.bilateral.empty() && p.bilateral[static_cast<std::size_t>(i)];
      if (bilateral && !on) skip = true;
      if (on) active.push_back(static_cast<int>(i));
    }
    if (skip) continue;
    LcpSolution s;
    s.force = Eigen::VectorXd::Zero(n);
    if (!active.empty()) {
      Eigen::MatrixXd aa(active.size(), active.size());
      Eigen::VectorXd bb(active.size());
      for (std::size_t r = 0; r < active.size(); ++r) {
        bb(static_cast<Eigen::Index>(r)) = -b(active[r]);
        for (std::size_t c = 0; c < active.size(); ++c) {
          aa(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = a(active[r], active[c]);
        }
      }
      Eigen::VectorXd fa = aa.completeOrthogonalDecomposition().solve(bb);
      for (std::size_t r = 0; r < active.size(); ++r) s.force(active[r]) = fa(static_cast<Eigen::Index>(r));
    }
    s.velocity = p.d_diag.cwiseProduct(p.applied + p.jt * s.force);
    s.normal_velocity = p.jt.transpose() * s.velocity;
    if (ComplementarityError(p, s) <= tolerance) {
      *out = s;
      return true;
    }
  }
  return false;
}

}  // namespace teachsim::sim
