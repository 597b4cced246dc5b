// Symplectic partitioned Runge-Kutta methods built from two diagonally implicit ones
// (paper Sec. 6.2, the remark after the DIRK composition: "similar argument also holds
// for partitioned Runge-Kutta methods based on two diagonally implicit methods").
//
// The Hamiltonian step (Eq. 5.1) of the theta map R_d(q, v) = (q - theta v,
// q + (1 - theta) v) is the one-stage partitioned method
//   q1 - q0 = h dH/dp(Q, P),  p1 - p0 = -h dH/dq(Q, P),
//   Q = q0 + theta (q1 - q0),  P = p0 + (1 - theta) (p1 - p0),
// i.e. the pair of tableaux a = theta (for q) and a^ = 1 - theta (for p), weight 1.
// Composing such steps of sizes b_1 h, ..., b_s h with thetas theta_1, ..., theta_s
// gives the s-stage partitioned method with common weights b and
//   a_ij = a^_ij = b_j   (j < i),     a_ii = theta_i b_i,     a^_ii = (1 - theta_i) b_i,
// two diagonally implicit tableaux. They satisfy the symplecticity conditions of
// partitioned methods, b_i a^_ij + b_j a_ji = b_i b_j (Hairer, Lubich, Wanner,
// Geometric Numerical Integration, Thm. VI.4.6), and every diagonally implicit pair
// that does, with the same weights and nonzero b_i, is of this form: the conditions
// force a_ji = b_i below the diagonal and a_ii + a^_ii = b_i on it. So the pair is
// given by b and the diagonal of the q-tableau, theta_i = a_ii / b_i. All thetas 1/2
// give the symplectic DIRK of weights b (dirk_scheme).
//
// Order: 1 always; 2 exactly when sum_i b_i c_i = 1/2 with c_i = sum_j a_ij, which is
// sum_i (theta_i - 1/2) b_i^2 = 0. Reversed weights with theta_{s+1-i} = 1 - theta_i
// make the composition its own adjoint (the adjoint of the theta map is the map of
// 1 - theta, Prop. 2.4), so a symmetric method of even order. `order` states what is
// proved here: the DIRK's order when every theta is 1/2, else 1 or 2; the third-order
// conditions of partitioned methods are not checked, so a pair may exceed it.
//
// PartitionedDirk (b, the thetas, symmetry, order) and its constructors
// partitioned_dirk(b, a_diagonal) and partitioned_dirk_thetas(b, theta) are in
// solvers/composition_methods.h, with the other composition schemes; a scene names the
// pair by composition = "dirk", integrator.weights and integrator.thetas, in any form
// and with any map that takes a theta (stage i then takes the map at theta_i).
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/discretization_map.h"
#include "solvers/composition.h"
#include "solvers/composition_methods.h"
#include "solvers/hamiltonian_step.h"

namespace dvm {

// The method as a composition of Hamiltonian steps of theta maps: stage i is the step
// of ThetaMap(theta_i) and size b_i h.
template <class Ham>
ComposedStep<HamiltonianStep<Ham, ThetaMap>> partitioned_dirk_step(const Ham& H, const PartitionedDirk& m, double h,
                                                                   StepOptions options = {}) {
  std::vector<Substep> subs;
  for (double b : m.weight) subs.push_back({b, false});
  // ComposedStep builds the steps of its substeps in order, all plain here, so the
  // counter walks the stages
  std::size_t stage = 0;
  auto make = [&](double hk) {
    return HamiltonianStep<Ham, ThetaMap>(H, ThetaMap(m.theta.at(stage++)), hk, options);
  };
  return ComposedStep<HamiltonianStep<Ham, ThetaMap>>(h, subs, make, make);
}

}  // namespace dvm
