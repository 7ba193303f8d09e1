// What the wrist force says about each contact's normal force when the contacts have friction
// (issue 5: "friction at the other contacts skews the force read along each normal"). The sensor
// reads the sum over the contacts j of N_j n_j + t_j, with t_j tangential and |t_j| <= mu N_j
// (Coulomb). The component along one normal mixes that contact's push with the other contacts'
// friction, so the monitor asks instead: what is the SMALLEST normal force N_i that any contact
// forces within the friction cones could have, given the measured sum? That is a small convex
// program; its dual gives a certificate: any lambda with
//   lambda . n_j + mu |P_j lambda| <= 0 (j != i),  lambda . n_i + mu |P_i lambda| <= 1
// (P_j: projection onto n_j's tangent plane) proves N_i >= lambda . f. The bound is found by
// searching lambda's direction; every candidate is checked exactly, so the reported bound never
// exceeds the true minimum (an imperfect search only makes it more cautious).
#pragma once

#include <Eigen/Core>

namespace teachsim::robot {

struct NormalForceBound {
  // Certified lower bound on N_i for the part of the force the contacts can explain (0 when
  // nothing better is certified).
  double min_n = 0;
  // The distance from the measured force to the sum of the friction cones: the part that no
  // contact forces within the cones explain (0 when consistent; an unexpected contact, or
  // friction above mu, makes it grow).
  double outside_n = 0;
};

// normals: unit columns (from the obstacle toward the workpiece); force_n: their sum as measured;
// mu >= 0. For mu = 0 and orthonormal normals the bound is force . n_i (when the force lies in
// their span and has no negative component).
NormalForceBound MinNormalForce(const Eigen::Vector3d& force_n, const Eigen::Matrix3Xd& normals, double mu,
                                long i);

}  // namespace teachsim::robot
