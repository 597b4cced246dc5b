// The position-momentum step of a theta discretization map for the FPU chain, for any
// number of particles (dynamic size), at O(n) cost per step.
//
// For L = m |v|^2/2 - V(q) and R_d(x, v) = (x - theta v, x + (1 - theta) v) the discrete
// Lagrangian is L_d(q0, q1) = m |q1 - q0|^2 / (2h) - h V(q0 + theta (q1 - q0)), and the
// discrete Legendre equations (see mechanics/discrete_lagrangian.h) read, with
// dq = q1 - q0 and x = q0 + theta dq,
//   F(dq) = p0 - m dq / h - h (1 - theta) grad V(x) = 0,      p1 - p0 = -h grad V(x).
// They are what the generic PositionMomentumStep solves for a FixedChain<N>; the tests
// check that both give the same steps.
//
// The step Jacobian dF/ddq = -(m/h) I - h theta (1 - theta) Hess V(x) is tridiagonal
// (nearest-neighbour springs), so each Newton iteration is one tridiagonal solve
// (Thomas algorithm, O(n), no fill-in). Why not a ceres::Problem with a sparse linear
// solver: the sparsity here is known and banded, a sparse Cholesky of a tridiagonal
// matrix does the same elimination plus symbolic analysis, permutation and, in Ceres,
// the normal equations J^T J (pentadiagonal, squared condition number) and per-solve
// setup of the trust-region machinery; the direct tridiagonal Newton costs a few
// multiply-adds per particle per iteration and is exact Newton. Measured in
// examples/bench/bench_chain.cc: the same step as a reused ceres::Problem costs 44x,
// 121x and 174x more at n = 1e2, 1e3, 1e4. The elimination has
// no pivoting: it is stable when the Jacobian is diagonally dominant or definite,
// which holds when every spring is convex where it is used (Hess V positive
// semi-definite, so -J is positive definite) and also when h^2 |V''| stays below
// about m/(h theta (1 - theta)); a non-positive pivot is reported as a failed step.
//
// Workspace is allocated at construction; a step allocates nothing. One ChainStep
// must not be used from two threads at once.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>

#include "core/discretization_map.h"
#include "mechanics/chain.h"
#include "solvers/newton.h"

namespace dvm {

class ChainStep {
 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  ChainStep(FPUChain chain, ThetaMap map, double h, StepOptions options = {})
      : chain_(std::move(chain)), map_(std::move(map)), h_(h), options_(options) {
    // negative sizes are the backward substeps of compositions (solvers/composition.h)
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    const int n = chain_.n;
    x_.resize(n);
    g_.resize(n);
    r_.resize(n);
    diag_.resize(n);
    off_.resize(std::max(n - 1, 0));
    c_.resize(n);
    d_.resize(n);
  }

  double step_size() const { return h_; }
  const FPUChain& chain() const { return chain_; }
  const ThetaMap& map() const { return map_; }

  // One step from (q0, p0); dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    const int n = chain_.n;
    const double th = map_.theta(), m = chain_.m;
    const double a = h_ * (1.0 - th);    // weight of grad V in F
    const double b = h_ * th * (1.0 - th);  // weight of Hess V in dF/ddq
    const double pscale = max_abs(p0);
    StepSummary s;
    double dxn = INFINITY;
    for (int it = 0; it < options_.max_iterations; ++it) {
      x_ = q0 + th * dq;
      chain_.gradient(x_, g_);
      r_ = p0 - (m / h_) * dq - a * g_;
      s.iterations = s.jacobians = it + 1;
      s.residual = max_abs(r_);
      s.scale = pscale + std::fabs(m / h_) * max_abs(dq) + std::fabs(a) * chain_.gradient_scale(x_) +
                options_.absolute_floor;
      if (!std::isfinite(s.residual)) {
        s.message = "non-finite residual";
        return s;
      }
      if (newton_verdict(s, dxn, max_abs(dq) + max_abs(q0), options_) != NewtonVerdict::iterate) break;
      // Solve (-J) delta = r with -J = (m/h) I + b Hess V(x), then dq += delta.
      chain_.hessian(x_, diag_, off_);
      if (!solve_tridiagonal(m / h_, b)) {
        s.message = "non-positive pivot in the tridiagonal step Jacobian (a strongly non-convex spring)";
        return s;
      }
      dq += r_;  // r_ now holds delta
      dxn = max_abs(r_);
    }
    if (!s.converged) {
      if (s.message.empty())
        s.message = "no convergence within " + std::to_string(options_.max_iterations) + " iterations";
      return s;
    }
    // As solve_newton does (solvers/newton.h): apply the correction of the accepted
    // residual, which takes it from the tolerance down to round-off (the reported
    // residual is the one measured before it).
    chain_.hessian(x_, diag_, off_);
    if (solve_tridiagonal(m / h_, b)) dq += r_;
    x_ = q0 + th * dq;
    chain_.gradient(x_, g_);
    dp = -h_ * g_;
    (void)n;
    return s;
  }

 private:
  // Solves (d0 I + b T) y = r_ in place, T = tridiag(off_, diag_, off_). Returns false on a
  // non-positive pivot. A backward substep (h < 0) has d0 < 0 and b <= 0: the system is
  // solved as (-d0 I - b T) y = -r_, positive definite where V is convex.
  bool solve_tridiagonal(double d0, double b) const {
    const int n = chain_.n;
    if (d0 < 0.0) {
      d0 = -d0;
      b = -b;
      r_ = -r_;
    }
    // forward elimination (Thomas): c_ = modified super-diagonal, d_ = modified rhs
    double piv = d0 + b * diag_[0];
    if (!(piv > 0.0)) return false;
    c_[0] = n > 1 ? b * off_[0] / piv : 0.0;
    d_[0] = r_[0] / piv;
    for (int i = 1; i < n; ++i) {
      const double lower = b * off_[i - 1];
      piv = d0 + b * diag_[i] - lower * c_[i - 1];
      if (!(piv > 0.0)) return false;
      c_[i] = i + 1 < n ? b * off_[i] / piv : 0.0;
      d_[i] = (r_[i] - lower * d_[i - 1]) / piv;
    }
    r_[n - 1] = d_[n - 1];
    for (int i = n - 2; i >= 0; --i) r_[i] = d_[i] - c_[i] * r_[i + 1];
    return true;
  }

  FPUChain chain_;
  ThetaMap map_;
  double h_;
  StepOptions options_;
  mutable V x_, g_, r_, diag_, off_, c_, d_;
};

}  // namespace dvm
