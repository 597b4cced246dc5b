// The integrate loop for one-step methods in (q, p) form.
//
// A step type S provides `static constexpr int N`, `double step_size() const` and
//   StepSummary step(const V& q, const V& p, V& dq, V& dp) const
// returning the increments; dq carries the starting guess on entry. The loop
//   - starts the first step from dq = h v with v from the inverse Legendre map
//     (passed in by the caller), later steps from the linear extrapolation
//     2 dq_{k-1} - dq_{k-2} of the previous increments (error O(h^3));
//   - accumulates q and p with compensated (Kahan) summation, so that round-off
//     does not grow with the number of steps (DESIGN.md, "Speed");
//   - computes t_k = t_0 + k h by multiplication, never by summation;
//   - stops at the first step that fails and reports it, never passing a failed
//     step on. A step fails when its solve does not converge, when it would make q
//     or p non-finite (inf or NaN), or when the step or the observer throws
//     std::domain_error (a map or Legendre transform evaluated outside its domain,
//     e.g. DegenerateLagrangianError); the failure records the step index k, the
//     time t_k, the residual and a message saying which.
// The observer is called as observer(k, t_k, q_k, p_k, summary_of_step_k) after
// every completed step (k >= 1); it is a template parameter, so the loop has no
// virtual call per step.
#pragma once

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "solvers/newton.h"

namespace dvm {

// Compensated sum of vectors (Kahan-Babuska): sum + c carries the exact total to
// about twice working precision.
template <int N>
struct CompensatedVector {
  Vec<double, N> sum, c;
  explicit CompensatedVector(const Vec<double, N>& start) : sum(start), c(Vec<double, N>::Zero(start.rows())) {}
  void add(const Vec<double, N>& x) {
    for (int i = 0; i < sum.rows(); ++i) {
      const double y = x[i] - c[i];
      const double t = sum[i] + y;
      c[i] = (t - sum[i]) - y;
      sum[i] = t;
    }
  }
};

struct RunSummary {
  std::int64_t steps_done = 0;
  bool failed = false;
  std::int64_t failed_step = -1;  // index k of the step k -> k+1 that failed
  double failed_time = NAN;       // t_k at the start of that step
  StepSummary failure;            // the failed step's summary
  std::int64_t solver_iterations = 0;
  int max_step_iterations = 0;

  // Books the summary of step k (from t0 + k h); returns false, recording the
  // failure, if the step did not converge.
  bool record(const StepSummary& s, std::int64_t k, double t0, double h) {
    solver_iterations += s.iterations;
    if (s.iterations > max_step_iterations) max_step_iterations = s.iterations;
    if (s.converged) return true;
    fail(s, k, t0, h);
    if (!std::isfinite(failure.residual) && failure.iterations > 0)
      failure.message = "the step equation is not finite (residual " + std::to_string(failure.residual) +
                        "): the iterate left the domain of the Lagrangian or the map; " + failure.message;
    return false;
  }
  // Records a failure of step k with the summary s (its message saying why).
  void fail(const StepSummary& s, std::int64_t k, double t0, double h) {
    failed = true;
    failed_step = k;
    failed_time = t0 + static_cast<double>(k) * h;
    failure = s;
    failure.converged = false;
  }
};

// A failure that is not a solve's: the message, and the residual where there is one.
inline StepSummary step_fault(const std::string& message, double residual = NAN, int iterations = 0) {
  StepSummary s;
  s.message = message;
  s.residual = residual;
  s.iterations = iterations;
  return s;
}

template <class S, class Observer>
RunSummary integrate(const S& stepper, double t0, Vec<double, S::N>& q, Vec<double, S::N>& p,
                     const Vec<double, S::N>& v0, std::int64_t steps, Observer&& observer) {
  constexpr int N = S::N;
  using V = Vec<double, N>;
  const double h = stepper.step_size();
  CompensatedVector<N> Q(q), P(p);
  V dq = h * v0, dq_prev = dq, dq_prev2 = dq, dp = V::Zero(q.rows());
  RunSummary run;
  for (std::int64_t k = 0; k < steps; ++k) {
    if (k >= 2)
      dq = 2.0 * dq_prev - dq_prev2;
    else if (k == 1)
      dq = dq_prev;
    StepSummary s;
    try {
      s = stepper.step(Q.sum, P.sum, dq, dp);
    } catch (const std::domain_error& e) {
      run.fail(step_fault(e.what()), k, t0, h);
      break;
    }
    if (!run.record(s, k, t0, h)) break;
    // (an expression: no temporary vector, no allocation for dynamic sizes)
    if (!((Q.sum + dq).allFinite() && (P.sum + dp).allFinite())) {
      run.fail(step_fault("the step gave a non-finite state (q or p is inf or NaN)", s.residual, s.iterations), k, t0,
               h);
      break;
    }
    Q.add(dq);
    P.add(dp);
    dq_prev2 = dq_prev;
    dq_prev = dq;
    run.steps_done = k + 1;
    try {
      observer(k + 1, t0 + static_cast<double>(k + 1) * h, Q.sum, P.sum, s);
    } catch (const std::domain_error& e) {
      // the state of step k + 1 exists but cannot be evaluated (e.g. its Legendre
      // transform is degenerate): the run stops there
      run.fail(step_fault(std::string("at the state the step reached: ") + e.what()), k, t0, h);
      break;
    }
  }
  q = Q.sum;
  p = P.sum;
  return run;
}

}  // namespace dvm
