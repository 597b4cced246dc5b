// The integrate loop for one-step methods in (q, p) form, on R^n and on manifolds.
//
// A step on R^n provides `static constexpr int N`, `double step_size() const` and
//   StepSummary step(double /*t*/, const V& q, const V& p, V& dq, V& dp) const
// returning the increments; dq carries the starting guess on entry. A step on a
// manifold M (solvers/manifold_step.h) provides `M`, `n`, `Point`, `Covector`,
// step_size() and
//   StepSummary step(double /*t*/, const Point& q0, const Covector& p0, Vec<double, n>& xi, Point& q1, Covector& p1) const
// with xi the guess of q1's chart coordinates around q0. The loop
//   - starts the first step from dq = h v with v from the inverse Legendre map
//     (passed in by the caller), later steps from the linear extrapolation
//     2 dq_{k-1} - dq_{k-2} of the previous increments (error O(h^3));
//   - accumulates q and p with compensated (Kahan) summation, so that round-off
//     does not grow with the number of steps;
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
#include <type_traits>
#include <utility>

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
  std::int64_t solver_iterations = 0;  // Newton (or fixed-point) iterations, summed over the steps
  std::int64_t jacobians = 0;          // Jacobians formed, summed over the steps
  int max_step_iterations = 0;

  // Books the summary of step k (from t0 + k h); returns false, recording the
  // failure, if the step did not converge.
  bool record(const StepSummary& s, std::int64_t k, double t0, double h) {
    solver_iterations += s.iterations;
    jacobians += s.jacobians;
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

// How the loop holds the state of a stepper's space: steps on R^n return increments,
// added with compensated sums; steps on a manifold return the new point and momentum
// (each produced by a chart, so on the manifold to round-off). The starting guess of
// a step continues the previous steps: on R^n the linear extrapolation
// 2 dq_{k-1} - dq_{k-2} of the increments, on a manifold the chart coordinates of the
// previous step's end seen from its start (M::next_guess).
template <class S, class = void>
struct is_point_stepper : std::false_type {};
template <class S>
struct is_point_stepper<S, std::void_t<typename S::Point, typename S::M>> : std::true_type {};

// Whether a step on R^n reads the starting guess in dq (an explicit step does not:
// `static constexpr bool takes_guess = false`, and the loop keeps no previous increments).
template <class S, class = void>
struct takes_guess : std::true_type {};
template <class S>
struct takes_guess<S, std::void_t<decltype(S::takes_guess)>> : std::bool_constant<S::takes_guess> {};

template <class S, bool = is_point_stepper<S>::value>
class LoopState;

// R^n: (q, p) as compensated sums of the increments.
template <class S>
class LoopState<S, false> {
 public:
  static constexpr int N = S::N;
  using Point = Vec<double, N>;
  using Covector = Vec<double, N>;
  LoopState(const Point& q, const Covector& p, const Covector& v0, double h)
      : Q_(q), P_(p), dq_(h * v0), dq_prev_(dq_), dq_prev2_(dq_), dp_(Covector::Zero(q.rows())) {}
  StepSummary step(const S& stepper, std::int64_t k, double t) {
    if constexpr (takes_guess<S>::value) {
      if (k >= 2)
        dq_ = 2.0 * dq_prev_ - dq_prev2_;
      else if (k == 1)
        dq_ = dq_prev_;
    }
    return stepper.step(t, Q_.sum, P_.sum, dq_, dp_);
  }
  // (an expression: no temporary vector, no allocation for dynamic sizes)
  bool finite() const { return (Q_.sum + dq_).allFinite() && (P_.sum + dp_).allFinite(); }
  void commit() {
    Q_.add(dq_);
    P_.add(dp_);
    if constexpr (takes_guess<S>::value) {
      dq_prev2_ = dq_prev_;
      dq_prev_ = dq_;
    }
  }
  const Point& q() const { return Q_.sum; }
  const Covector& p() const { return P_.sum; }

 private:
  CompensatedVector<N> Q_, P_;
  Point dq_, dq_prev_, dq_prev2_;
  Covector dp_;
};

// A manifold M: the points themselves.
template <class S>
class LoopState<S, true> {
 public:
  using M = typename S::M;
  using Point = typename S::Point;
  using Covector = typename S::Covector;
  LoopState(const Point& q, const Covector& p, const Covector& v0, double h)
      : q_(q), q_prev_(q), q1_(q), p_(p), p1_(p), xi0_(h * M::tangent_coordinates(q, v0)) {}
  StepSummary step(const S& stepper, std::int64_t k, double t) {
    Vec<double, S::n> xi = k == 0 ? xi0_ : Vec<double, S::n>(M::next_guess(q_prev_, q_));
    return stepper.step(t, q_, p_, xi, q1_, p1_);
  }
  bool finite() const { return q1_.allFinite() && p1_.allFinite(); }
  void commit() {
    q_prev_ = q_;
    q_ = q1_;
    p_ = p1_;
  }
  const Point& q() const { return q_; }
  const Covector& p() const { return p_; }

 private:
  Point q_, q_prev_, q1_;
  Covector p_, p1_;
  Vec<double, S::n> xi0_;
};

// The loop, for steps on R^n and on manifolds alike: q and p hold the initial state
// on entry and the last completed state on return; v0 is the initial velocity (the
// first step's guess).
template <class S, class Observer>
RunSummary integrate(const S& stepper, double t0, typename LoopState<S>::Point& q,
                     typename LoopState<S>::Covector& p, const typename LoopState<S>::Covector& v0,
                     std::int64_t steps, Observer&& observer) {
  const double h = stepper.step_size();
  LoopState<S> state(q, p, v0, h);
  RunSummary run;
  for (std::int64_t k = 0; k < steps; ++k) {
    // The step's summary is initialized by the step itself, not default-constructed and
    // then assigned: on the cheapest steps (a splitting into kicks and drifts) that
    // assignment is a visible share of the step (bench_ratios, "Stormer-Verlet by
    // composition").
    bool thrown = false;
    std::string why;
    const StepSummary s = [&]() -> StepSummary {
      try {
        return state.step(stepper, k, t0 + static_cast<double>(k) * h);
      } catch (const std::domain_error& e) {
        thrown = true;
        why = e.what();
        return StepSummary();
      }
    }();
    if (thrown) {
      run.fail(step_fault(why), k, t0, h);
      break;
    }
    if (!run.record(s, k, t0, h)) break;
    if (!state.finite()) {
      run.fail(step_fault("the step gave a non-finite state (q or p is inf or NaN)", s.residual, s.iterations), k, t0,
               h);
      break;
    }
    state.commit();
    run.steps_done = k + 1;
    try {
      observer(k + 1, t0 + static_cast<double>(k + 1) * h, state.q(), state.p(), s);
    } catch (const std::domain_error& e) {
      // the state of step k + 1 exists but cannot be evaluated (e.g. its Legendre
      // transform is degenerate): the run stops there
      run.fail(step_fault(std::string("at the state the step reached: ") + e.what()), k, t0, h);
      break;
    }
  }
  q = state.q();
  p = state.p();
  return run;
}

}  // namespace dvm
