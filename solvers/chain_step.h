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
// multiply-adds per particle per iteration and is exact Newton
// (examples/bench/bench_chain.cc times the same step as a reused ceres::Problem
// against it). The elimination has
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
#include "solvers/newton_driver.h"

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
    dx_.resize(n);
    diag_.resize(n);
    off_.resize(std::max(n - 1, 0));
    c_.resize(n);
    d_.resize(n);
  }

  double step_size() const { return h_; }
  const FPUChain& chain() const { return chain_; }
  const ThetaMap& map() const { return map_; }

  // One step from (q0, p0); dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0. Newton's method by the driver (solvers/newton_driver.h), the
  // tridiagonal Jacobian formed and factored at every iteration.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    const double th = map_.theta();
    Equation eq{*this, q0, p0, h_ * (1.0 - th), h_ * th * (1.0 - th), max_abs(p0), max_abs(q0)};
    Tridiagonal la{*this, chain_.m / h_, eq.b};
    DriverState state;  // (nothing is kept between steps: a Jacobian at every iteration)
    StepSummary s = newton_drive(eq, la, Refresh::every_iteration, options_, dq, r_, dx_, unused_, state, unused_guess_);
    if (!s.converged) return s;
    x_ = q0 + th * dq;
    chain_.gradient(x_, g_);
    dp = -h_ * g_;
    return s;
  }

 private:
  // The equation for the driver, with dq = q1 - q0 and x = q0 + theta dq:
  //   F(dq) = p0 - (m/h) dq - a grad V(x),   dF/ddq = -((m/h) I + b Hess V(x)),
  // a = h (1 - theta), b = h theta (1 - theta). The Jacobian lives in the step's diag_
  // and off_ (Hess V's diagonals), not in the driver's matrix.
  struct Equation {
    using Vector = V;
    using Matrix = Eigen::MatrixXd;
    const ChainStep& st;
    const V& q0;
    const V& p0;
    double a, b, pscale, x0;
    // (each sets gradient_scale_, the chain's gradient_scale at the iterate, for scale())
    void residual(const V& dq, V& r) {
      st.x_ = q0 + st.map_.theta() * dq;
      st.chain_.gradient(st.x_, st.g_);
      r = p0 - (st.chain_.m / st.h_) * dq - a * st.g_;
      gradient_scale_ = st.chain_.gradient_scale(st.x_);
    }
    // J = -((m/h) I + b T), T = tridiag(off_, diag_, off_), formed: Hess V into diag_
    // and off_, in the pass over the bonds that forms grad V (FPUChain::derivatives; the
    // separate gradient, Hessian and gradient scale would each form every bond length).
    // Returns |m/h| + |b| max(|diag_|, |off_|), which bounds max|J_ij| and is within a
    // factor 6 of it (|diag_i| <= 2 max|off_|), measured by two passes that do not wait
    // on each other's comparisons; it only sets the round-off floor of the stopping rule
    // (the chain's scale is its own). bench_chain times the step.
    double jacobian(const V& dq, V& r, Matrix&) {
      st.x_ = q0 + st.map_.theta() * dq;
      double force_max, stiffness_max;
      st.chain_.derivatives(st.x_, st.g_, st.diag_, st.off_, force_max, stiffness_max);
      r = p0 - (st.chain_.m / st.h_) * dq - a * st.g_;
      gradient_scale_ = force_max + stiffness_max * max_abs(st.x_);
      const double m = std::fabs(st.chain_.m / st.h_) + std::fabs(b) * std::max(inf_norm(st.diag_), inf_norm(st.off_));
      return m < INFINITY ? m : INFINITY;  // (NaN too)
    }
    // the size of F's terms at dq (the gradient's own terms, not only their sum), at the
    // iterate of the last residual() or jacobian(), where the driver asks for it
    double scale(double dqn, double) const {
      return pscale + std::fabs(st.chain_.m / st.h_) * dqn + std::fabs(a) * gradient_scale_;
    }
    double offset() const { return x0; }
    double gradient_scale_ = 0.0;
  };

  // The driver's linear algebra: -J = d0 I + b T eliminated without pivoting (Thomas)
  // together with the right-hand side, in solve(), as one pass: its two recurrences (the
  // pivots, the right-hand side) then overlap, where a factorisation first and a solve
  // after would run one after the other (bench_chain times the step). So factor() has
  // nothing to do, and a non-positive pivot leaves a non-finite correction, which the
  // driver reports as a singular Jacobian. A backward substep (h < 0) has d0 < 0 and
  // b <= 0: it is solved as (-d0 I - b T) y = -r, positive definite where V is convex.
  struct Tridiagonal {
    const ChainStep& st;
    double d0, b;
    bool factor(const Eigen::MatrixXd&, double) { return true; }
    // dx = J^{-1} r = -(d0 I + b T)^{-1} r
    void solve(const V& r, V& dx) const {
      const int n = st.chain_.n;
      const bool neg = d0 < 0.0;
      const double e0 = neg ? -d0 : d0, eb = neg ? -b : b;
      V& c = st.c_;
      V& y = st.d_;
      double piv = e0 + eb * st.diag_[0];
      if (!(piv > 0.0)) {
        dx.setConstant(NAN);
        return;
      }
      c[0] = n > 1 ? eb * st.off_[0] / piv : 0.0;
      y[0] = (neg ? -r[0] : r[0]) / piv;
      for (int i = 1; i < n; ++i) {
        const double lower = eb * st.off_[i - 1];
        piv = e0 + eb * st.diag_[i] - lower * c[i - 1];
        if (!(piv > 0.0)) {
          dx.setConstant(NAN);
          return;
        }
        c[i] = i + 1 < n ? eb * st.off_[i] / piv : 0.0;
        y[i] = ((neg ? -r[i] : r[i]) - lower * y[i - 1]) / piv;
      }
      dx[n - 1] = -y[n - 1];
      for (int i = n - 2; i >= 0; --i) {
        y[i] = y[i] - c[i] * y[i + 1];
        dx[i] = -y[i];
      }
    }
    const char* name() const { return "tridiagonal elimination without pivoting"; }
  };

  FPUChain chain_;
  ThetaMap map_;
  double h_;
  StepOptions options_;
  mutable V x_, g_, r_, dx_, diag_, off_, c_, d_;
  // (the driver's matrix and kept guess, which a step solved by Newton's method at every
  // iteration never touches: the Jacobian lives in diag_ and off_)
  mutable Eigen::MatrixXd unused_;
  mutable V unused_guess_;
};

}  // namespace dvm
