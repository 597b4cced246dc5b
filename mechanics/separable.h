// The two parts of a separable Lagrangian that its fast steps need.
//
// For L(q, v) = v^T M v / 2 - V(q) with M constant, symmetric and positive definite
// (mechanics/structure.h),
//   the force         F(q) = -grad V(q) = dL/dq(q, 0),
//   the inverse mass  M^{-1} p, which is the inverse Legendre map v(q, p) at any q.
// The force is the system's gradient at v = 0 (closed form or automatic
// differentiation, fixed size or run-time size: gradient_of). M^{-1} is the system's
// closed-form velocity where it has one; otherwise M is read off column by column,
// dL/dv(q_ref, e_j) (dL/dv is linear in v and independent of q), and factored once
// (Cholesky), so that applying M^{-1} is two triangular solves.
//
// SeparableParts serves Gauss collocation on the stage forces (solvers/collocation_step.h);
// the explicit kicks and drifts of the Euler maps (solvers/splitting_step.h) keep their
// own force and velocity calls (the same code held in this class made Stormer-Verlet
// markedly slower against Odeint's velocity_verlet in bench_ratios: GCC inlines the
// loop differently) and share factor_mass_matrix.
#pragma once

#include <Eigen/Cholesky>
#include <stdexcept>
#include <string>
#include <utility>

#include "mechanics/dynamic_system.h"
#include "mechanics/structure.h"

namespace dvm {

// The constant mass matrix M of a separable S, read off at q_ref column by column,
// M e_j = dL/dv(q_ref, e_j) (dL/dv is linear in v).
template <class S, int N = state_size<S>::value>
Mat<double, N, N> mass_matrix(const S& L, const Vec<double, N>& q_ref) {
  const Eigen::Index n = q_ref.size();
  Mat<double, N, N> M = Mat<double, N, N>::Zero(n, n);
  Vec<double, N> e = Vec<double, N>::Zero(n), a = e, b = e;
  for (Eigen::Index j = 0; j < n; ++j) {
    e.setZero();
    e[j] = 1.0;
    gradient_of(L, q_ref, e, a, b);
    M.col(j) = b;
  }
  return M;
}

// Its Cholesky factor. Throws std::invalid_argument when M is not positive definite.
template <class S, int N = state_size<S>::value>
Eigen::LLT<Mat<double, N, N>> factor_mass_matrix(const S& L, const Vec<double, N>& q_ref) {
  const Mat<double, N, N> M = mass_matrix(L, q_ref);
  Eigen::LLT<Mat<double, N, N>> llt(M);
  if (llt.info() != Eigen::Success || !M.allFinite())
    throw std::invalid_argument(L.name() + ": the mass matrix is not positive definite");
  return llt;
}

template <class S>
class SeparableParts {
  static_assert(is_separable_v<S>, "SeparableParts needs a system that declares a separable structure");

 public:
  static constexpr int N = state_size<S>::value;  // S::dim, or Eigen::Dynamic
  using V = Vec<double, N>;
  // Whether M^{-1} p is the system's closed form (no factorisation).
  static constexpr bool closed_velocity =
      N == Eigen::Dynamic ? has_dynamic_velocity<S>::value : has_velocity<S>::value;

  // q_ref: a point where L is defined (where M is read off when S has no closed-form
  // velocity). Throws std::invalid_argument when that M is not positive definite.
  SeparableParts(S L, const V& q_ref) : L_(std::move(L)), n_(system_dim(L_)) {
    if (q_ref.size() != n_) throw std::invalid_argument("separable parts: q_ref has the wrong size");
    zero_ = dLdv_ = V::Zero(n_);
    if constexpr (!closed_velocity) llt_ = factor_mass_matrix(L_, q_ref);
  }

  const S& system() const { return L_; }
  Eigen::Index dim() const { return n_; }

  // F = -grad V(q) (F sized n).
  void force(const V& q, V& F) const {
    if constexpr (N == Eigen::Dynamic) {
      gradient_of(L_, q, zero_, F, dLdv_);
    } else {
      V dLdv;  // (fixed size: in registers, not in the object)
      gradient_of(L_, q, zero_, F, dLdv);
    }
  }

  // v = M^{-1} p; q is any point (M is constant), passed to the closed form.
  void velocity(const V& q, const V& p, V& v) const {
    if constexpr (!closed_velocity)
      v = llt_.solve(p);
    else if constexpr (N == Eigen::Dynamic)
      L_.velocity(q, p, v);
    else
      v = L_.velocity(q, p);
  }

 private:
  S L_;
  Eigen::Index n_;
  Eigen::LLT<Mat<double, N, N>> llt_;
  V zero_;
  mutable V dLdv_;  // run-time size: the discarded dL/dv(q, 0) of a force evaluation
};

}  // namespace dvm
