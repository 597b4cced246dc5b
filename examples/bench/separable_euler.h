// Closed-form position-momentum steps of the two Euler maps on a separable Lagrangian
// L(q, v) = v^T M v / 2 - V(q) with constant M, written here to measure what a
// closed-form path in the library would save on Stormer-Verlet by composition
// (the generic step solves the same equations by Newton's method with automatic
// differentiation). With F = -grad V = dL/dq:
//
//   explicit Euler, R_d(x, v) = (x, x + v):  L_d = h L(q0, (q1 - q0)/h),
//     p0 = -D1 L_d = M v - h F(q0)  =>  dp = h F(q0),  dq = h M^{-1} (p0 + dp);
//   adjoint Euler, R_d(x, v) = (x - v, x):   L_d = h L(q1, (q1 - q0)/h),
//     p0 = -D1 L_d = M v            =>  dq = h M^{-1} p0,  dp = h F(q0 + dq).
//
// Both satisfy the `integrate` contract, so ComposedStep composes them exactly as it
// composes the generic steps; bench_ratios checks the two routes agree.
#pragma once

#include "examples/bench/hand_written.h"
#include "solvers/newton.h"

namespace dvm::bench {

template <class System, bool AdjointMap>
class SeparableEulerStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  SeparableEulerStep(System L, double h) : L_(std::move(L)), h_(h) {}
  double step_size() const { return h_; }
  StepSummary step(const V& q0, const V& p0, V& dq, V& dp) const {
    if (AdjointMap) {
      dq = h_ * L_.velocity(q0, p0);
      dp = h_ * force(L_, V(q0 + dq));
    } else {
      dp = h_ * force(L_, q0);
      dq = h_ * L_.velocity(q0, V(p0 + dp));
    }
    StepSummary s;
    s.converged = true;
    s.iterations = 0;
    s.residual = 0.0;
    s.scale = 1.0;
    return s;
  }

 private:
  System L_;
  double h_;
};

}  // namespace dvm::bench
