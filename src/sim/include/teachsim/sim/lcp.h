// Contact forces for the first-order model (paper §5.1, Baraff 1994).
//
// The workpiece's spatial velocity is V = D (F + J^T f), D = diag(d_t I3, d_r I3). Row i of J is
// [n_i^T, (r_i x n_i)^T]: the wrench of a unit force along contact normal n_i (pointing from the
// obstacle toward the workpiece) at lever r_i from the workpiece origin. The normal velocities are
// a = J V = A f + b with A = J D J^T (PSD, rank <= 6: a face-face contact gives > 6 rows) and
// b = J D F. Baraff's conditions a >= 0, f >= 0, f.a = 0 are exactly the KKT conditions of
//     min_f 1/2 |D^1/2 (F + J^T f)|^2  subject to f >= 0,
// a non-negative least-squares problem, which Lawson and Hanson's active-set method solves
// exactly in finitely many steps, rank-deficient or not (the velocity is unique, f may not be).
// Bilateral rows (contacts with capture objects) have free f and a = 0.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace teachsim::sim {

using Matrix6X = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using Vector6 = Eigen::Matrix<double, 6, 1>;

struct LcpProblem {
  Matrix6X jt;                // J^T: column i is contact i's unit wrench
  Vector6 d_diag;             // D's diagonal (d_t x3, d_r x3)
  Vector6 applied;            // F: applied force and moment on the workpiece
  std::vector<bool> bilateral;  // per contact; empty means all unilateral
};

struct LcpSolution {
  Eigen::VectorXd force;      // f, one per contact (N)
  Vector6 velocity;           // V = D (F + J^T f)
  Eigen::VectorXd normal_velocity;  // a = J V
  int iterations = 0;
  bool converged = true;
};

LcpSolution SolveContactLcp(const LcpProblem& problem);

// Reference: enumerates every active set (2^n, n <= 16) and returns the first that satisfies
// the conditions to `tolerance`; for tests.
bool SolveContactLcpBruteForce(const LcpProblem& problem, double tolerance, LcpSolution* out);

// Largest violation of a >= 0 (unilateral), a = 0 (bilateral), f >= 0 and |f_i a_i|, scaled to
// the problem (forces in N, velocities in m/s).
double ComplementarityError(const LcpProblem& problem, const LcpSolution& solution);

}  // namespace teachsim::sim
