// Explicit steps of the two Euler maps on a separable Lagrangian, alone or composed.
//
// For L(q, v) = v^T M v / 2 - V(q) with constant M (mechanics/structure.h) and the theta
// map R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), the discrete
// Lagrangian of Sec. 5.3 is
//   L_d(q0, q1) = (q1 - q0)^T M (q1 - q0) / (2h) - h V((1 - theta) q0 + theta q1).
// With F = -grad V = dL/dq, the discrete Legendre equations p0 = -D1 L_d(q0, q1),
// p1 = D2 L_d(q0, q1) are explicit at the two ends of the family:
//   theta = 0 (explicit Euler, R_d(x, v) = (x, x + v)):
//     p0 = M dq/h - h F(q0)   =>  kick  p1 = p0 + h F(q0),  then drift  q1 = q0 + h M^{-1} p1;
//   theta = 1 (its adjoint, R_d(x, v) = (x - v, x)):
//     p0 = M dq/h             =>  drift q1 = q0 + h M^{-1} p0,  then kick  p1 = p0 + h F(q1).
// These are the two symplectic Euler methods. A composition (paper Sec. 6; the substeps
// of solvers/composition_methods.h, an adjoint substep being the other end of the
// family by Prop. 2.4) is then a sequence of kicks and drifts; two kicks in a row act
// at the same point and are one kick with the summed coefficient (one force), two
// drifts likewise. Stormer-Verlet, Phi_{h/2} o Phi^*_{h/2} of either Euler map, is
// drift-kick-drift or kick-drift-kick with one force per step.
//
// First same as last: when a step ends with a kick and the next starts with one, the
// force at the end of a step is the force at the start of the next. The integrate loop
// adds the increments with compensated sums, so the point it passes in may differ
// from q0 + dq of the previous step in the last bit; the force is reused when the two
// agree to 4 units of round-off in the max norm of q (the kick then differs from one
// at the loop's point by round-off), and evaluated afresh otherwise.
//
// The step solves the same equations as PositionMomentumStep<S, ThetaMap> and its
// compositions (ComposedStep), without Newton's method or derivatives of L_d; the
// two agree to round-off (tests/solvers/test_splitting.cc). It has the contract of
// `integrate` (N, step_size(), step(q, p, dq, dp)).
#pragma once

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Cholesky>

#include "mechanics/dynamic_system.h"
#include "mechanics/separable.h"
#include "mechanics/structure.h"
#include "solvers/composition_methods.h"
#include "solvers/newton.h"

namespace dvm {

// Whether S gives its force dL/dq at v = 0 alone, force(q, F) (the written separable
// systems: no dL/dv formed, no zero velocity read, on a chain of 25000 particles five
// passes over arrays of n saved a step).
template <class S, class V, class = void>
struct has_force : std::false_type {};
template <class S, class V>
struct has_force<S, V, std::void_t<decltype(std::declval<const S&>().force(std::declval<const V&>(), std::declval<V&>()))>>
    : std::true_type {};

// One operation of an explicit splitting step: kick p += c F(q), or drift q += c M^{-1} p.
struct SplittingOp {
  bool kick;
  double c;
};

// The kicks and drifts of the Euler map theta (0: kick then drift; 1: drift then kick)
// composed by `substeps` at step h, two of a kind in a row merged into one (one force).
// Throws std::invalid_argument for another theta, no substeps or a zero or non-finite
// weight.
inline std::vector<SplittingOp> splitting_sequence(double theta, const std::vector<Substep>& substeps, double h) {
  if (!(theta == 0.0 || theta == 1.0))
    throw std::invalid_argument("explicit splitting steps exist for theta = 0 and theta = 1 only");
  if (substeps.empty()) throw std::invalid_argument("a composition needs at least one substep");
  std::vector<SplittingOp> ops;
  auto push = [&ops](bool kick, double c) {
    if (!ops.empty() && ops.back().kick == kick)
      ops.back().c += c;
    else
      ops.push_back({kick, c});
  };
  for (const Substep& s : substeps) {
    if (!(s.weight != 0.0) || !std::isfinite(s.weight))
      throw std::invalid_argument("composition substeps must have nonzero finite weights");
    const double th = s.adjoint ? 1.0 - theta : theta;
    const double c = s.weight * h;
    push(th == 0.0, c);  // explicit Euler (theta 0) kicks first, its adjoint drifts first
    push(th != 0.0, c);
  }
  return ops;
}

// The forces a step of the sequence evaluates in a long run: its kicks, less the first
// where a step starts and ends with a kick (the last force of a step serves the next).
inline int splitting_forces_per_step(const std::vector<SplittingOp>& ops) {
  int kicks = 0;
  for (const SplittingOp& o : ops) kicks += o.kick;
  return kicks - (ops.size() > 1 && ops.front().kick && ops.back().kick ? 1 : 0);
}

template <class S>
class ExplicitSplittingStep {
  static_assert(is_separable_v<S>, "explicit splitting steps need a system that declares a separable structure");

 public:
  static constexpr int N = state_size<S>::value;  // S::dim, or Eigen::Dynamic for a run-time-sized system
  using V = Vec<double, N>;
  static constexpr bool takes_guess = false;  // explicit: the integrate loop keeps no guess

  // theta: 0 or 1, the basic map; substeps: its composition ({{1, false}} for none).
  // q_ref: a point where L is defined (where M is read off when S has no closed-form
  // velocity; M is constant).
  ExplicitSplittingStep(S L, double theta, double h, const std::vector<Substep>& substeps, const V& q_ref)
      : L_(std::move(L)), h_(h), n_(system_dim(L_)) {
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    if (q_ref.size() != n_) throw std::invalid_argument("explicit splitting step: q_ref has the wrong size");
    ops_ = splitting_sequence(theta, substeps, h);
    fsal_ = ops_.front().kick && ops_.back().kick;
    q_ = force_ = dLdv_ = zero_ = vel_ = p_ = V::Zero(n_);
    end_q_ = V::Constant(n_, std::numeric_limits<double>::quiet_NaN());
    if constexpr (!closed_velocity) llt_ = factor_mass_matrix(L_, q_ref);  // M is constant
  }

  double step_size() const { return h_; }
  // The number of force evaluations of a step (before first-same-as-last reuse).
  int forces_per_step() const {
    int n = 0;
    for (const Op& o : ops_) n += o.kick;
    return n;
  }
  bool first_same_as_last() const { return fsal_; }

  // At a fixed size of 3 coordinates or more the step is flattened: everything it
  // calls is inlined into it (the system's gradient, Eigen's fixed-size assignments), so
  // the workspace stays in registers. In a large translation unit (the benchmark suite)
  // GCC may leave those calls out of line, several times slower for FPU (6 dof); with 1
  // or 2 coordinates they are inlined already and flattening made Kepler's step slower.
  // The run-time-sized step is left as it is.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    if constexpr (N != Eigen::Dynamic && N >= 3)
      return step_flattened(q0, p0, dq, dp);
    else
      return step_impl(q0, p0, dq, dp);
  }

 private:
  [[gnu::flatten]] StepSummary step_flattened(const V& q0, const V& p0, V& dq, V& dp) const {
    return step_impl(q0, p0, dq, dp);
  }
  StepSummary step_impl(const V& q0, const V& p0, V& dq, V& dp) const {
    if constexpr (N == Eigen::Dynamic) {
      run_ops(q0, p0, dq, dp, q_, p_, vel_, force_, dLdv_);
    } else {
      // fixed size: the intermediate vectors live in registers, not in the object
      V q, p, v, F = force_, dLdv;
      run_ops(q0, p0, dq, dp, q, p, v, F, dLdv);
      if (fsal_) force_ = F;
    }
    StepSummary s;
    s.converged = true;
    s.iterations = 0;
    s.residual = 0.0;
    s.scale = 1.0;
    return s;
  }
  static constexpr bool closed_velocity = N == Eigen::Dynamic ? has_dynamic_velocity<S>::value : has_velocity<S>::value;
  using Op = SplittingOp;
  // The kicks and drifts from (q0, p0), the increments into dq, dp; q, p, v, F, dLdv are
  // workspace (F holds the previous step's last force on entry).
  void run_ops(const V& q0, const V& p0, V& dq, V& dp, V& q, V& p, V& v, V& F, V& dLdv) const {
    if (ops_.size() == 3) {
      // Stormer-Verlet, written out (the general loop below keeps F and dp in memory
      // across its branches; straight-line code keeps them in registers)
      const double a = ops_[0].c, b = ops_[1].c, c = ops_[2].c;
      if (fsal_) {  // kick, drift, kick
        if (!(have_force_ && reusable(q0))) force_at(q0, F, dLdv);
        dp.noalias() = a * F;
        p.noalias() = p0 + dp;
        velocity(q0, p, v);
        dq.noalias() = b * v;
        q.noalias() = q0 + dq;
        force_at(q, F, dLdv);
        dp.noalias() += c * F;
        end_q_ = q;
      } else {  // drift, kick, drift
        velocity(q0, p0, v);
        dq.noalias() = a * v;
        q.noalias() = q0 + dq;
        force_at(q, F, dLdv);
        dp.noalias() = b * F;
        p.noalias() = p0 + dp;
        velocity(q0, p, v);
        dq.noalias() += c * v;
      }
      return;
    }
    dq.setZero();
    dp.setZero();
    for (std::size_t k = 0; k < ops_.size(); ++k) {
      const Op& o = ops_[k];
      if (o.kick) {
        if (k == 0) {
          // first same as last: F is the force at the previous step's end
          if (!(fsal_ && have_force_ && reusable(q0))) force_at(q0, F, dLdv);
        } else {
          q.noalias() = q0 + dq;
          force_at(q, F, dLdv);
        }
        dp.noalias() += o.c * F;
      } else {
        p.noalias() = p0 + dp;
        velocity(q0, p, v);
        dq.noalias() += o.c * v;
      }
    }
    if (fsal_) end_q_.noalias() = q0 + dq;  // where F was taken (ops_ merged: the last kick follows a drift)
  }
  // v = M^{-1} p: the system's closed form (separable: the same at every q), or the
  // factored M
  void velocity(const V& q, const V& p, V& v) const {
    if constexpr (!closed_velocity)
      v = llt_.solve(p);
    else if constexpr (N == Eigen::Dynamic)
      L_.velocity(q, p, v);
    else
      v = L_.velocity(q, p);
  }
  void force_at(const V& q, V& F, V& dLdv) const {
    if constexpr (has_force<S, V>::value)
      L_.force(q, F);
    else
      gradient_of(L_, q, zero_, F, dLdv);
    have_force_ = true;
  }
  bool reusable(const V& q0) const {
    const double tol = 4.0 * std::numeric_limits<double>::epsilon() * max_abs(q0);
    return max_abs(q0 - end_q_) <= tol;
  }

  S L_;
  double h_;
  Eigen::Index n_;
  std::vector<Op> ops_;
  bool fsal_ = false;
  // the factored M, only where S has no closed-form velocity (an LLT that is never
  // computed holds unset members, which copying the step would read)
  struct NoFactor {};
  std::conditional_t<closed_velocity, NoFactor, Eigen::LLT<Mat<double, N, N>>> llt_;
  // workspace, and the last force with, when the step ends with a kick, the point of
  // the step's end
  mutable V q_, p_, vel_, force_, dLdv_, zero_, end_q_;
  mutable bool have_force_ = false;
};

}  // namespace dvm
