// Simplified Newton across steps for the position-momentum steps of a theta map on a
// Lagrangian of run-time size: the loop shared by the separable steps that factor a
// sparse or a dense Jacobian (solvers/sparse_separable_step.h,
// solvers/dense_separable_step.h) and by DynamicThetaStep when it keeps its Jacobian
// (solvers/dynamic_step.h, mechanical and general Lagrangians).
//
// Each step solves r(D) = 0 for the increment D = q1 - q0 (the discrete Legendre
// equation p0 = -D1 L_d(q0, q0 + D), paper Sec. 5.3), then p1 - p0 follows from D. The
// factorisation of the Jacobian J = -dr/dD made by an earlier step of the same step
// object is kept while the iteration shrinks the residual fourfold an iteration or has
// reached the stopping rule, and is made again at the current iterate where neither
// holds (or where there is none yet). The stopping rule and the final correction are
// solve_newton's (solvers/newton.h), so a kept Jacobian changes the iterations, not the
// solution. StepSummary::iterations counts the Jacobians formed, as solve_newton does.
// Copies of a step that share its kept factorisation must not run on two threads at once.
//
// kept_jacobian_newton(ops, kept, options, q0, p0, dq, dp, work, summary) runs the loop;
// `ops` supplies
//   void residual(const V& q0, const V& p0, const V& dq, V& r) const
//   double jacobian(const V& q0, const V& dq) const   J formed at q0, dq; its largest
//                                                     entry (or INFINITY)
//   bool factor() const                               J factored; false where singular
//   void solve(const V& r, V& dx) const               J dx = r
//   void increment(const V& q0, const V& dq, V& dp) const   dp = p1 - p0
//   const char* factorisation() const                 named when J is singular
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <utility>

#include "mechanics/dynamic_system.h"
#include "solvers/newton.h"

namespace dvm {

// What a step keeps of its factored Jacobian between steps.
struct KeptJacobian {
  bool valid = false;  // factored, and not singular
  double Jmax = 0.0;   // the largest entry of the Jacobian factored
};

// Workspace of the loop, sized n.
struct KeptNewtonWork {
  void resize(int n) {
    r.resize(n);
    dx.resize(n);
    start.resize(n);
  }
  Eigen::VectorXd r, dx, start;  // the residual, the correction, the starting guess
};

// Whether a factorisation formed at an earlier iterate still serves at this one: the
// residual shrank fourfold since the last iterate, within the first half of the
// iteration budget (Newton's method from there on), or it already meets the stopping
// rule (a residual at round-off shrinks no more, whatever J is). scale: the residual's
// scale with that Jacobian; verdict(probe): the caller's stopping rule on a copy of s.
template <class Verdict>
bool kept_jacobian_serves(const StepSummary& s, double last, int it, double scale, const StepOptions& opt,
                          Verdict&& verdict) {
  if (s.residual <= 0.25 * last && 2 * (it + 1) <= opt.max_iterations) return true;
  StepSummary probe = s;
  probe.scale = scale;
  return verdict(probe) == NewtonVerdict::converged;
}

// The loop. f: the state of the kept factorisation (valid, Jmax), updated here; s: the
// step's summary, filled as the loop goes (so that a caller catching an exception from
// the system keeps what it holds). Beyond solve_newton's rule, a Jacobian is also formed
//   - at every iteration of the second half of the iteration budget (Newton's method
//     there, so that a small budget converges where Newton's method does);
//   - at the starting guess, where an update by a kept Jacobian left the domain of the
//     equation (a non-finite residual): the iteration starts again from there.
// A singular Jacobian at an iterate the stopping rule accepts ends the step there, as in
// the Newton loops that form a Jacobian at every iteration. On a failed step
// s.iterations is at least 1.
template <class Ops>
void kept_jacobian_newton(const Ops& ops, KeptJacobian& f, const StepOptions& opt, const Eigen::VectorXd& q0,
                          const Eigen::VectorXd& p0, Eigen::VectorXd& dq, Eigen::VectorXd& dp, KeptNewtonWork& w,
                          StepSummary& s) {
  s = StepSummary{};
  const double pscale = dynamic_detail::inf_norm(p0), x0 = dynamic_detail::inf_norm(q0);
  double dxn = INFINITY, last = INFINITY;
  bool formed = false;  // a Jacobian formed in this step
  w.start = dq;
  auto fail = [&](std::string message) {
    s.converged = false;
    s.message = std::move(message);
    if (s.iterations == 0) s.iterations = 1;
  };
  for (int it = 0; it < opt.max_iterations; ++it) {
    ops.residual(q0, p0, dq, w.r);
    s.residual = dynamic_detail::inf_norm(w.r);
    if (!std::isfinite(s.residual) && !formed && it > 0) {
      dq = w.start;
      f.valid = false;
      dxn = last = INFINITY;
      ops.residual(q0, p0, dq, w.r);
      s.residual = dynamic_detail::inf_norm(w.r);
    }
    const double dqn = dynamic_detail::inf_norm(dq);  // (dq is this until the correction below)
    const bool refresh =
        !f.valid || !kept_jacobian_serves(s, last, it, pscale + f.Jmax * dqn + opt.absolute_floor, opt,
                                          [&](StepSummary& probe) {
                                            return newton_verdict_floored(probe, dxn, dqn + x0, opt, f.Jmax);
                                          });
    if (refresh) {
      f.Jmax = ops.jacobian(q0, dq);
      ++s.iterations;
      formed = true;
      f.valid = std::isfinite(f.Jmax) && ops.factor();  // (factor() may read f.Jmax, set above)
      if (std::isfinite(f.Jmax) && !f.valid) {
        s.scale = pscale + f.Jmax * dqn + opt.absolute_floor;
        if (std::isfinite(s.residual) &&
            newton_verdict_floored(s, dxn, dqn + x0, opt, f.Jmax) == NewtonVerdict::converged)
          break;  // nothing more to apply
        fail(std::string("singular step Jacobian (") + ops.factorisation() + " failed)");
        return;
      }
    }
    const double Jmax = f.Jmax;
    last = s.residual;
    s.scale = pscale + Jmax * dqn + opt.absolute_floor;
    if (!std::isfinite(s.residual) || !std::isfinite(Jmax)) {
      fail("non-finite residual or Jacobian");
      return;
    }
    const NewtonVerdict verdict = newton_verdict_floored(s, dxn, dqn + x0, opt, Jmax);
    if (verdict == NewtonVerdict::failed) {
      if (s.iterations == 0) s.iterations = 1;
      return;
    }
    ops.solve(w.r, w.dx);  // J dx = r, J = -dr/dD
    const double dx_norm = dynamic_detail::inf_norm(w.dx);
    if (!std::isfinite(dx_norm)) {
      fail("singular step Jacobian");
      return;
    }
    dq += w.dx;
    if (verdict == NewtonVerdict::converged) break;  // (the correction already paid for, applied)
    dxn = dx_norm;
  }
  if (!s.converged) {
    fail("no convergence within " + std::to_string(opt.max_iterations) + " iterations (" +
         std::to_string(s.iterations) + " Jacobians formed)");
    return;
  }
  ops.increment(q0, dq, dp);
  if (!std::isfinite(dynamic_detail::inf_norm(dp))) fail("non-finite momentum");
}

}  // namespace dvm
