// The Newton iteration of a theta map on a separable Lagrangian of run-time size, shared
// by the step that factors a sparse Jacobian (solvers/sparse_separable_step.h) and the
// one that factors a dense one (solvers/dense_separable_step.h).
//
// For L(q, v) = v^T M v / 2 + U(q) with M constant, the theta map
// R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), D = q1 - q0 and
// q_theta = q0 + theta D, the discrete Legendre equations of Sec. 5.3 are
//   p0 = M D / h - h (1 - theta) F(q_theta),   p1 - p0 = h F(q_theta),   F = grad U,
// (solvers/separable_theta_step.h derives them). The first is solved for D with the
// Jacobian of its residual, -(M / h - h theta (1 - theta) Hess U), by simplified Newton
// across steps: the factorisation made by an earlier step of the same step object is
// kept while the iteration shrinks the residual fourfold an iteration or has reached
// the stopping rule, and is made again at the current iterate where neither holds (or
// where there is none yet). The equation, the stopping rule and the final correction are
// solve_newton's (solvers/newton.h), so a kept Jacobian changes the iterations, not the
// solution.
//
// SeparableThetaNewton<Step> holds that loop; Step (which derives from it) supplies the
// linear algebra:
//   void force(const V& x, V& F) const           F = grad U(x)
//   void mass_times(const V& v, V& out) const    out = M v
//   double jacobian(const V& x) const            J = M / h - h theta (1 - theta) Hess U(x)
//                                                formed; its largest entry (or INFINITY)
//   bool factor() const                          J factored; false where singular
//   void solve(const V& r, V& dx) const          J dx = r
//   KeptJacobian& kept() const                   the state of the kept factorisation,
//                                                shared by copies of a step
//   static const char* factorisation()           named in the singular-Jacobian message
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>
#include <string>

#include "solvers/dynamic_step.h"
#include "solvers/newton.h"

namespace dvm {

// What a step keeps of its factored Jacobian between steps.
struct KeptJacobian {
  bool valid = false;  // factored, and not singular
  double Jmax = 0.0;   // the largest entry of the Jacobian factored
};

template <class Step>
class SeparableThetaNewton {
 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  double step_size() const { return h_; }
  double theta() const { return theta_; }
  int dim() const { return n_; }

  // One step from (q0, p0): dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0 = h F(q_theta) (the contract of `integrate`).
  StepSummary step(const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const Step& self = static_cast<const Step&>(*this);
    if (!dynamic_detail::sizes_match(n_, q0, p0, dq, s)) return s;
    if (dp.size() != n_) dp.resize(n_);
    const StepOptions& opt = options_;
    const double pscale = dynamic_detail::inf_norm(p0), x0 = dynamic_detail::inf_norm(q0);
    KeptJacobian& f = self.kept();
    double dxn = INFINITY, last = INFINITY;
    for (int it = 0; it < opt.max_iterations; ++it) {
      x_ = q0 + theta_ * dq;
      self.force(x_, F_);
      self.mass_times(dq, r_);
      r_ = p0 - r_ / h_ + (h_ * (1.0 - theta_)) * F_;
      s.residual = dynamic_detail::inf_norm(r_);
      bool refresh = !f.valid;
      if (!refresh && !(s.residual <= 0.25 * last)) {
        // not shrinking fourfold: a new Jacobian, unless the residual is already where
        // the stopping rule accepts it (at round-off it shrinks no more, whatever J is)
        StepSummary probe = s;
        probe.scale = pscale + f.Jmax * dynamic_detail::inf_norm(dq) + opt.absolute_floor;
        refresh = newton_verdict_floored(probe, dxn, dynamic_detail::inf_norm(dq) + x0, opt, f.Jmax) !=
                  NewtonVerdict::converged;
      }
      if (refresh) {
        f.Jmax = self.jacobian(x_);
        ++s.iterations;  // (Jacobian evaluations, as solve_newton counts them)
        f.valid = std::isfinite(f.Jmax) && self.factor();
        if (std::isfinite(f.Jmax) && !f.valid) {
          s.message = std::string("singular step Jacobian (") + Step::factorisation() + " failed)";
          return s;
        }
      }
      const double Jmax = f.Jmax;
      last = s.residual;
      s.scale = pscale + Jmax * dynamic_detail::inf_norm(dq) + opt.absolute_floor;
      if (!std::isfinite(s.residual) || !std::isfinite(Jmax)) {
        s.message = "non-finite residual or Jacobian";
        return s;
      }
      const NewtonVerdict verdict = newton_verdict_floored(s, dxn, dynamic_detail::inf_norm(dq) + x0, opt, Jmax);
      if (verdict == NewtonVerdict::failed) return s;
      self.solve(r_, dx_);  // J dx = r; the Jacobian of r is -J
      if (!std::isfinite(dynamic_detail::inf_norm(dx_))) {
        s.converged = false;
        s.message = "singular step Jacobian";
        return s;
      }
      dq += dx_;
      if (verdict == NewtonVerdict::converged) break;  // (the correction already paid for, applied)
      dxn = dynamic_detail::inf_norm(dx_);
    }
    if (!s.converged) {
      s.message = "no convergence within " + std::to_string(opt.max_iterations) + " iterations";
      return s;
    }
    x_ = q0 + theta_ * dq;
    self.force(x_, F_);
    dp = h_ * F_;
    if (!std::isfinite(dynamic_detail::inf_norm(dp))) {
      s.converged = false;
      s.message = "non-finite momentum";
    }
    return s;
  }

 protected:
  SeparableThetaNewton(int n, double theta, double h, StepOptions options)
      : theta_(theta), h_(h), options_(options), n_(n) {
    if (!(theta >= 0.0 && theta <= 1.0)) throw std::invalid_argument("theta must lie in [0, 1]");
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    x_.resize(n);
    F_.resize(n);
    r_.resize(n);
    dx_.resize(n);
  }

  double theta_, h_;
  StepOptions options_;
  int n_;

 private:
  mutable V x_, F_, r_, dx_;
};

}  // namespace dvm
