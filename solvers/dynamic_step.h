// Steps of the theta discretization maps for run-time-sized systems
// (mechanics/dynamic_system.h): the step equations assembled from the derivative
// blocks the system provides, solved by Newton's method in storage sized once.
//
// The theta map R_d(x, v) = (x - theta v, x + (1 - theta) v), theta in [0, 1]
// (explicit Euler 0, midpoint 1/2, adjoint Euler 1; core/discretization_map.h).
//
// 1. Position-momentum step (discrete Legendre form; solvers/position_momentum_step.h).
//    The discrete Lagrangian L_d(q0, q1) = h L(x, v) at R_d^{-1}(q0, q1) / h, i.e.
//    x = q0 + theta dq, v = dq / h with dq = q1 - q0 (paper Sec. 5.3), has
//      D1 L_d = h (1 - theta) L_q(x, v) - L_v(x, v),   (D1 + D2) L_d = h L_q(x, v).
//    Given (q0, p0), the increment dq solves
//      F(dq) = p0 + h (1 - theta) L_q(x, v) - L_v(x, v) = 0,
//    then dp = p1 - p0 = h L_q(x, v) (the common shift of q0 and q1 leaves v unchanged:
//    no cancellation). With dx/ddq = theta I and dv/ddq = I / h, the Jacobian is
//      dF/ddq = h theta (1 - theta) L_qq + (1 - theta) L_qv - theta L_qv^T - L_vv / h,
//    built from one call of the system's hessian() per Newton iteration.
//
// 2. Hamiltonian step (paper Sec. 5.1, Eq. 5.1; solvers/hamiltonian_step.h). The
//    inverse of the cotangent lift of the theta map sends (q0, p0; q1, p1) to the base
//    point x = (1 - theta) q0 + theta q1 = q0 + theta dq,
//          p = theta p0 + (1 - theta) p1 = p0 + (1 - theta) dp,
//    and the tangent vector (dq, dp); Eq. 5.1 asks it to be h X_H(x, p):
//      F(dq, dp) = (dq - h H_p(x, p),  dp + h H_q(x, p)) = 0,
//    with the Jacobian (H_pq = H_qp^T)
//      [ I - h theta H_pq      -h (1 - theta) H_pp   ]
//      [ h theta H_qq           I + h (1 - theta) H_qp ].
//    The map is symplectic for any H (the lift is a symplectomorphism, Prop. 5.1 of the
//    paper); with theta = 1/2 it is the implicit midpoint rule.
//
// Adjoints. The theta map's adjoint is the (1 - theta) map (Prop. 2.4), and the method
// of the adjoint map is the adjoint method, so adjoint() of either step is the same
// type with 1 - theta: ComposedStep<DynamicThetaStep<Sys>> composes one type.
//
// Solving: Newton's method with the stopping rule newton_verdict (solvers/newton.h), the
// correction of the accepted residual applied as solve_newton does, and the scale
// conventions of the fixed-size steps: |p0| + |J| |dq| for the position-momentum step
// (stall measured against |dq| + |q0|), |h| max(|H_p|, |H_q|)(q0, p0) + |J| |(dq, dp)|
// for the Hamiltonian step (against |(dq, dp)| + max(|q0|, |p0|)). The linear solves use
// DenseLU (a pivot not above 1e-14 max|J| is singular, as solve_dense; the fixed-size
// Newton of dimension <= 4 refuses only an exactly singular matrix). The
// position-momentum step may instead keep its Jacobian across steps (keep_jacobian:
// simplified Newton, solvers/kept_newton.h), where a step then costs gradients of L and
// triangular solves, and L's Hessian only where the iteration stops converging fourfold.
// Compiled for a number of coordinates K known in advance (DynamicThetaStep<Sys, K>),
// it keeps the first iteration's Jacobian within each step by the same rule and forms dp
// from the last gradient (newton() below). Non-convergence,
// singular Jacobians, non-finite values and std::domain_error from the system (e.g. a
// degenerate Legendre transform) are reported in the StepSummary, never thrown. Only
// Newton's method is offered: StepOptions::solver = tiny is refused at construction.
//
// Workspace is allocated at construction for the system's dimension; a step allocates
// nothing (checked with Eigen's EIGEN_RUNTIME_NO_MALLOC and a count of operator new in
// tests/solvers/test_dynamic.cc). One object must not be used from two threads at once,
// nor copies of a step that keeps its Jacobian (they share its factorisation).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/discretization_map.h"
#include "mechanics/dynamic_system.h"
#include "solvers/kept_newton.h"
#include "solvers/newton.h"

namespace dvm {

namespace dynamic_detail {

inline void require_newton(const StepOptions& options) {
  if (options.solver != SolverKind::newton)
    throw std::invalid_argument("run-time-sized steps solve by Newton's method only (solver = \"newton\")");
}
inline void require_step(double h) {
  // negative sizes are the backward substeps of compositions (solvers/composition.h)
  if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
}
// A summary for a state whose size is not the system's.
inline bool sizes_match(int n, const Eigen::VectorXd& q0, const Eigen::VectorXd& p0, const Eigen::VectorXd& dq,
                        StepSummary& s) {
  if (q0.size() == n && p0.size() == n && dq.size() == n) return true;
  s.message = "the state has " + std::to_string(q0.size()) + " coordinates (p " + std::to_string(p0.size()) +
              ", dq " + std::to_string(dq.size()) + "); the system has " + std::to_string(n);
  return false;
}

}  // namespace dynamic_detail

// The position-momentum step of the theta map for a run-time-sized Lagrangian Sys.
// K: the number of coordinates where it is known when the step is compiled (the runtime
// makes K = 1 and 2 for a written Lagrangian of so few): the same step, its workspace and
// its loops of fixed size; the state stays run-time sized. Sys::dim() must equal K.
template <class Sys, int K = Eigen::Dynamic>
class DynamicThetaStep {
  static_assert(is_dynamic_system_v<Sys>, "DynamicThetaStep needs a run-time-sized system (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  // keep_jacobian: simplified Newton across steps (solvers/kept_newton.h), the
  // factorisation of an earlier step kept while it serves; otherwise Newton's method with
  // a Jacobian at every iteration.
  DynamicThetaStep(Sys L, ThetaMap R, double h, StepOptions options = {}, bool keep_jacobian = false)
      : L_(std::move(L)), R_(std::move(R)), h_(h), options_(options) {
    if (keep_jacobian) kept_ = std::make_shared<Kept>();
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    const int n = L_.dim();
    if (K != Eigen::Dynamic && n != K)
      throw std::invalid_argument("DynamicThetaStep<" + std::to_string(K) + ">: a system of " + std::to_string(n) +
                                  " coordinates");
    x_.resize(n);
    v_.resize(n);
    Lq_.resize(n);
    Lv_.resize(n);
    r_.resize(n);
    Lqq_.resize(n, n);
    Lqv_.resize(n, n);
    Lvv_.resize(n, n);
    J_.resize(n, n);
    if (kept_) {
      kept_->lu.resize(n);
      work_.resize(n);
    } else {
      lu_.resize(n);
    }
  }

  double step_size() const { return h_; }
  bool keeps_jacobian() const { return kept_ != nullptr; }
  // Forgets the kept factorisation (keep_jacobian): the next step forms one.
  void reset() const {
    if (kept_) kept_->valid = false;
  }
  const Sys& lagrangian() const { return L_; }
  const ThetaMap& map() const { return R_; }
  const StepOptions& options() const { return options_; }
  int dim() const { return L_.dim(); }

  // The step of the adjoint map (1 - theta), of the same size.
  DynamicThetaStep adjoint() const { return DynamicThetaStep(L_, R_.adjoint(), h_, options_, keeps_jacobian()); }

  // One step from (q0, p0); dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0.
  StepSummary step(const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = K == Eigen::Dynamic ? L_.dim() : K;
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.resize(n);
    try {
      if (kept_) {
        kept_jacobian_newton(KeptOps{*this}, *kept_, options_, q0, p0, dq, dp, work_, s);
      } else if constexpr (K == Eigen::Dynamic) {
        newton(q0, p0, dq, dp, s);
      } else {  // the state in storage of fixed size: every loop and norm below of length K
        const SV a = q0, b = p0;
        SV d = dq, e = dp;
        newton(a, b, d, e, s);
        dq = d;
        dp = e;
      }
    } catch (const std::domain_error& e) {
      s.converged = false;
      s.message = e.what();
    }
    return s;
  }

 private:
  using SV = Eigen::Matrix<double, K, 1>;
  static constexpr bool kChord = K != Eigen::Dynamic;

  // Newton's method on vectors of type W (V, or SV where K is known). Where K is known
  // (kChord), the Jacobian of the first iteration serves the next ones while each
  // shrinks the residual fourfold (the rule of solvers/kept_newton.h, within a step): a
  // step that converges in two iterations costs one Hessian of L and two gradients
  // instead of two Hessians and a gradient. Otherwise a Jacobian at every iteration.
  template <class W>
  void newton(const W& q0, const W& p0, W& dq, W& dp, StepSummary& s) const {
    const int n = static_cast<int>(x_.size());
    const double th = R_.theta(), inv_h = 1.0 / h_;
    const double a = h_ * th * (1.0 - th), b = 1.0 - th;
    const double pscale = dynamic_detail::inf_norm(p0), q0size = dynamic_detail::inf_norm(q0);
    // F = p0 + D1 L_d, written as PositionMomentumStep evaluates it
    auto residual = [&] {
      for (int i = 0; i < n; ++i) r_[i] = p0[i] + ((h_ * Lq_[i]) * b - Lv_[i]);
      s.residual = dynamic_detail::inf_norm(r_);
    };
    double dxn = INFINITY, last = INFINITY, Jmax = 0.0;
    bool factored = false, done = false, corrected = false;
    for (int it = 0; it < options_.max_iterations && !done; ++it) {
      at(q0, dq);
      const double dqn = dynamic_detail::inf_norm(dq);
      corrected = false;
      bool fresh = !factored;
      if (factored) {  // (kChord) the residual alone; a Jacobian where the kept one no longer serves
        L_.gradient(x_, v_, Lq_, Lv_);
        residual();
        fresh = !kept_jacobian_serves(s, last, it, pscale + Jmax * dqn + options_.absolute_floor, options_,
                                      [&](StepSummary& probe) {
                                        return newton_verdict(probe, dxn, dqn + q0size, options_);
                                      });
      }
      if (fresh) {
        L_.hessian(x_, v_, Lq_, Lv_, Lqq_, Lqv_, Lvv_);
        residual();
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i)
            J_(i, j) = a * Lqq_(i, j) + b * Lqv_(i, j) - th * Lqv_(j, i) - inv_h * Lvv_(i, j);
        Jmax = dynamic_detail::inf_norm(J_);
        ++s.iterations;
      }
      s.scale = pscale + Jmax * dqn + options_.absolute_floor;
      if (!std::isfinite(s.residual) || !std::isfinite(Jmax)) {
        s.message = "non-finite residual or Jacobian";
        return;
      }
      const NewtonVerdict verdict = newton_verdict(s, dxn, dqn + q0size, options_);
      if (verdict == NewtonVerdict::failed) return;
      if (fresh) {
        if (!lu_.factor(J_, Jmax)) {
          if (verdict == NewtonVerdict::converged) break;  // nothing more to apply
          s.message = "singular step Jacobian";
          return;
        }
        factored = kChord;
      }
      lu_.solve(r_, r_);  // r_ is now the Newton correction
      dq -= r_;
      corrected = true;
      dxn = dynamic_detail::inf_norm(r_);
      last = s.residual;
      // on convergence the correction already paid for is applied (see solve_newton)
      done = verdict == NewtonVerdict::converged;
    }
    if (!s.converged) {
      s.message = "no convergence within " + std::to_string(options_.max_iterations) + " iterations";
      return;
    }
    // (the correction is at round-off where the residual met its tolerance; where the
    // iteration was accepted as stalled above it, the gradient at the solution instead)
    if (kChord && s.residual <= options_.residual_tolerance * s.scale) {
      // dp = h L_q at the solution, from L_q at the last iterate and the correction c
      // applied since (x moved by -theta c, v by -c / h): L_q + L_qq (-theta c) + L_qv (-c / h),
      // with the blocks of the Jacobian's Hessian. The correction is the converged one, at
      // the residual's tolerance, so what this leaves out (c times the change of the
      // Hessian, and c^2) lies below the round-off of dp: one gradient less a step.
      // (Where the loop ended at a singular Jacobian no correction was applied: c = 0.)
      for (int i = 0; i < n; ++i) {
        double d = Lq_[i];
        if (corrected)
          for (int j = 0; j < n; ++j) d -= (th * Lqq_(i, j) + inv_h * Lqv_(i, j)) * r_[j];
        dp[i] = h_ * d;
      }
    } else {
      at(q0, dq);
      L_.gradient(x_, v_, Lq_, Lv_);
      for (int i = 0; i < n; ++i) dp[i] = h_ * Lq_[i];
    }
    if (!std::isfinite(dynamic_detail::inf_norm(dp))) {
      s.converged = false;
      s.message = "non-finite momentum";
    }
  }

  // x = q0 + theta dq, v = dq / h (as ThetaMap::inverse_increment and DiscreteLagrangian)
  template <class W>
  void at(const W& q0, const W& dq) const {
    const double th = R_.theta(), inv_h = 1.0 / h_;
    for (Eigen::Index i = 0; i < x_.size(); ++i) {
      x_[i] = q0[i] + th * dq[i];
      v_[i] = dq[i] * inv_h;
    }
  }

  // The equation in the terms of kept_jacobian_newton: r as above, J = -dF/ddq.
  struct KeptOps {
    const DynamicThetaStep& s;
    void residual(const V& q0, const V& p0, const V& dq, V& r) const {
      s.at(q0, dq);
      s.L_.gradient(s.x_, s.v_, s.Lq_, s.Lv_);
      const double b = 1.0 - s.R_.theta();
      for (Eigen::Index i = 0; i < r.size(); ++i) r[i] = p0[i] + ((s.h_ * s.Lq_[i]) * b - s.Lv_[i]);
    }
    double jacobian(const V& q0, const V& dq) const {
      s.at(q0, dq);
      s.L_.hessian(s.x_, s.v_, s.Lq_, s.Lv_, s.Lqq_, s.Lqv_, s.Lvv_);
      const double th = s.R_.theta(), inv_h = 1.0 / s.h_, a = s.h_ * th * (1.0 - th), b = 1.0 - th;
      const Eigen::Index n = s.J_.rows();
      for (Eigen::Index j = 0; j < n; ++j)
        for (Eigen::Index i = 0; i < n; ++i)
          s.J_(i, j) = -(a * s.Lqq_(i, j) + b * s.Lqv_(i, j) - th * s.Lqv_(j, i) - inv_h * s.Lvv_(i, j));
      const double m = dynamic_detail::inf_norm(s.J_);
      return std::isfinite(m) ? m : INFINITY;
    }
    bool factor() const { return s.kept_->lu.factor(s.J_); }
    void solve(const V& r, V& dx) const { s.kept_->lu.solve(r, dx); }
    void increment(const V& q0, const V& dq, V& dp) const {
      s.at(q0, dq);
      s.L_.gradient(s.x_, s.v_, s.Lq_, s.Lv_);
      for (Eigen::Index i = 0; i < dp.size(); ++i) dp[i] = s.h_ * s.Lq_[i];
    }
    const char* factorisation() const { return "dense LU factorisation"; }
  };
  // The factorisation kept across steps, shared by copies of the step.
  struct Kept : KeptJacobian {
    DenseLUOf<K> lu;
  };

  Sys L_;
  ThetaMap R_;
  double h_;
  StepOptions options_;
  mutable Eigen::Matrix<double, K, 1> x_, v_, Lq_, Lv_, r_;
  mutable KeptNewtonWork work_;  // (keep_jacobian)
  mutable Eigen::Matrix<double, K, K> Lqq_, Lqv_, Lvv_, J_;
  mutable DenseLUOf<K> lu_;
  std::shared_ptr<Kept> kept_;
};

// The Hamiltonian step (Eq. 5.1) of the theta map for a run-time-sized Hamiltonian Ham
// (WrittenDynamicHamiltonian, LegendreDynamicHamiltonian<Sys>, or any type of the
// concept with (q, p) as its blocks):
//   q1 - q0 = h dH/dp(Q, P),  p1 - p0 = -h dH/dq(Q, P),  Q = q0 + theta dq,
// with P = p0 + (1 - theta) dp for the cotangent lift of the theta map on Q, and
// P = p0 + theta dp for the theta map given directly on T*Q (`on_bundle`, the map of
// OnCotangentBundle<ThetaMap> in solvers/hamiltonian_step.h: the theta method, not
// symplectic unless theta = 1/2).
template <class Ham>
class DynamicHamiltonianThetaStep {
  static_assert(is_dynamic_system_v<Ham>,
                "DynamicHamiltonianThetaStep needs a run-time-sized Hamiltonian (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  DynamicHamiltonianThetaStep(Ham H, ThetaMap R, double h, StepOptions options = {}, bool on_bundle = false)
      : H_(std::move(H)), R_(std::move(R)), h_(h), options_(options), on_bundle_(on_bundle) {
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    const int n = H_.dim();
    x_.resize(n);
    p_.resize(n);
    Hq_.resize(n);
    Hp_.resize(n);
    y_.resize(2 * n);
    r_.resize(2 * n);
    Hqq_.resize(n, n);
    Hqp_.resize(n, n);
    Hpp_.resize(n, n);
    J_.resize(2 * n, 2 * n);
    lu_.resize(2 * n);
  }

  double step_size() const { return h_; }
  const Ham& hamiltonian() const { return H_; }
  const ThetaMap& map() const { return R_; }
  const StepOptions& options() const { return options_; }
  int dim() const { return H_.dim(); }

  // The step of the adjoint map (1 - theta), of the same size.
  DynamicHamiltonianThetaStep adjoint() const {
    return DynamicHamiltonianThetaStep(H_, R_.adjoint(), h_, options_, on_bundle_);
  }

  // One step from (q0, p0); (dq, dp) hold the starting guess on entry and the
  // increments on return.
  StepSummary step(const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = H_.dim();
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.setZero(n);
    const double th = R_.theta(), b = on_bundle_ ? th : 1.0 - th;
    y_.head(n) = dq;
    y_.tail(n) = dp;
    try {
      H_.gradient(q0, p0, Hq_, Hp_);
      const double s0 = std::fabs(h_) * std::fmax(dynamic_detail::inf_norm(Hp_), dynamic_detail::inf_norm(Hq_));
      const double x0 = std::fmax(dynamic_detail::inf_norm(q0), dynamic_detail::inf_norm(p0));
      double dxn = INFINITY;
      bool done = false;
      for (int it = 0; it < options_.max_iterations && !done; ++it) {
        for (int i = 0; i < n; ++i) {
          x_[i] = q0[i] + th * y_[i];
          p_[i] = p0[i] + b * y_[n + i];
        }
        H_.hessian(x_, p_, Hq_, Hp_, Hqq_, Hqp_, Hpp_);
        for (int i = 0; i < n; ++i) {
          r_[i] = y_[i] - h_ * Hp_[i];
          r_[n + i] = y_[n + i] + h_ * Hq_[i];
        }
        const double ht = h_ * th, hb = h_ * b;
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i) {
            J_(i, j) = (i == j ? 1.0 : 0.0) - ht * Hqp_(j, i);
            J_(i, n + j) = -hb * Hpp_(i, j);
            J_(n + i, j) = ht * Hqq_(i, j);
            J_(n + i, n + j) = (i == j ? 1.0 : 0.0) + hb * Hqp_(i, j);
          }
        s.iterations = it + 1;
        s.residual = dynamic_detail::inf_norm(r_);
        const double Jmax = dynamic_detail::inf_norm(J_);
        s.scale = s0 + Jmax * dynamic_detail::inf_norm(y_) + options_.absolute_floor;
        if (!std::isfinite(s.residual) || !std::isfinite(Jmax)) {
          s.message = "non-finite residual or Jacobian";
          break;
        }
        const NewtonVerdict verdict = newton_verdict(s, dxn, dynamic_detail::inf_norm(y_) + x0, options_);
        if (verdict == NewtonVerdict::failed) break;
        if (!lu_.factor(J_)) {
          if (verdict != NewtonVerdict::converged) s.message = "singular step Jacobian";
          break;
        }
        lu_.solve(r_, r_);
        y_ -= r_;
        dxn = dynamic_detail::inf_norm(r_);
        done = verdict == NewtonVerdict::converged;
      }
      if (!s.converged && s.message.empty())
        s.message = "no convergence within " + std::to_string(options_.max_iterations) + " iterations";
    } catch (const std::domain_error& e) {
      s.converged = false;
      s.message = e.what();
    }
    dq = y_.head(n);
    dp = y_.tail(n);
    return s;
  }

 private:
  Ham H_;
  ThetaMap R_;
  double h_;
  StepOptions options_;
  bool on_bundle_;
  mutable V x_, p_, Hq_, Hp_, y_, r_;
  mutable Eigen::MatrixXd Hqq_, Hqp_, Hpp_, J_;
  mutable DenseLU lu_;
};

}  // namespace dvm
