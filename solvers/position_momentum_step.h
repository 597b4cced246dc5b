// The position-momentum step of a discrete Lagrangian (discrete Legendre form):
//
//   given (q_k, p_k), solve   p_k + D1 L_d(q_k, q_{k+1}) = 0   for q_{k+1},
//   then                      p_{k+1} = D2 L_d(q_k, q_{k+1}).
//
// The unknown is the increment dq = q_{k+1} - q_k, whose size is O(h), so the
// relative tolerances of the solver act on the quantity that matters. The momentum
// increment is returned as dp = (D1 + D2) L_d(q_k, q_{k+1}) (equal to
// p_{k+1} - p_k at the solution), computed without cancellation (see
// discrete_lagrangian.h). The caller accumulates q and p with compensated sums.
//
// The residual is judged against the size of its terms, |p_k| + |J| |dq|, where J
// is the step Jacobian (about M/h for a mass matrix M, so |J||dq| is the size of the
// momentum carried by dq).
#pragma once

#include "mechanics/discrete_lagrangian.h"
#include "solvers/newton_driver.h"

namespace dvm {

// Tiny: whether StepOptions::solver may choose ceres::TinySolver (else Newton's method
// alone is compiled, and a step that asks for TinySolver throws at construction).
template <class System, class Map, bool Tiny = true>
class PositionMomentumStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using DL = DiscreteLagrangian<System, Map>;

  PositionMomentumStep(System L, Map R, double h, StepOptions options = {})
      : dl_(std::move(L), std::move(R), h), options_(options) {
    if (!Tiny && options_.solver != SolverKind::newton)
      throw std::invalid_argument("this position-momentum step is compiled for Newton's method only");
  }

  const DL& discrete_lagrangian() const { return dl_; }
  const StepOptions& options() const { return options_; }
  double step_size() const { return dl_.step(); }

  // The residual p_k + D1 L_d(q_k, q_k + dq) as a functor of dq.
  struct Residual {
    const DL* dl;
    V q0, p0;
    template <class T>
    bool operator()(const T* dq, T* r) const {
      Vec<T, N> a, b;
      for (int i = 0; i < N; ++i) {
        a[i] = constant<T>(q0[i]);
        b[i] = dq[i];
      }
      const Vec<T, N> d1 = dl->D1Ld_increment(a, b);
      for (int i = 0; i < N; ++i) r[i] = p0[i] + d1[i];
      return true;
    }
  };

  // One step from (q0, p0). `dq` holds the starting guess on entry and the
  // increment q1 - q0 on return; `dp` receives p1 - p0. Map domain errors met in
  // the solve are reported in the summary, not thrown.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    Residual f{&dl_, q0, p0};
    const double pscale = max_abs(p0);
    StepSummary s;
    try {
      if constexpr (Tiny)
        s = solve_step_system<N>(f, dq, max_abs(q0), options_, pscale);
      else
        s = solve_newton<N>(f, dq, max_abs(q0), options_, pscale);
      if (s.converged) {
        V d2;
        dl_.D2Ld_and_shift(q0, dq, d2, dp);
        if (!std::isfinite(max_abs(dp))) {
          s.converged = false;
          s.message = "non-finite momentum";
        }
      }
    } catch (const std::domain_error& e) {
      s.converged = false;
      s.message = e.what();
    }
    return s;
  }

 private:
  DL dl_;
  StepOptions options_;
};

}  // namespace dvm
