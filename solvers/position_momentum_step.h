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

#include <Eigen/LU>

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

  // The derivative of the step (q0, p0) -> (q1, p1) at the dq that step() solved for,
  // by the implicit function theorem on its equation (no finite differences): with
  // F(q0, dq) = D1 L_d(q0, q0 + dq) and G(q0, dq) = D2 L_d(q0, q0 + dq) (= p1), their
  // derivatives in (q0, dq) by one Jet level over the slopes,
  //   d dq = -F_dq^{-1} (F_q0 dq0 + dp0),   dp1 = G_q0 dq0 + G_dq d dq.
  // A (2N x 2N, the coordinates then the momenta, for rows and columns) receives
  // [dq1/dq0  dq1/dp0; dp1/dq0  dp1/dp0]: for any map, the flow of a discrete
  // Lagrangian, so A^T J A = J (Marsden and West, Acta Numerica 2001) up to round-off
  // and the tolerance dq was solved to. A does not depend on p0. Returns false where
  // F_dq is singular (or A not finite) at dq; a map's domain error is thrown.
  bool derivative(const V& q0, const V& dq, Mat<double, 2 * N, 2 * N>& A) const {
    using D = ceres::Jet<double, 2 * N>;
    using M = Mat<double, N, N>;
    Vec<D, N> a, b;
    for (int i = 0; i < N; ++i) {
      a[i] = seed<double, 2 * N>(q0[i], i);
      b[i] = seed<double, 2 * N>(dq[i], N + i);
    }
    const Vec<D, N> F = dl_.D1Ld_increment(a, b), G = dl_.D2Ld_increment(a, b);
    M Fq, Fd, Gq, Gd;
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) {
        Fq(i, j) = F[i].v[j];
        Fd(i, j) = F[i].v[N + j];
        Gq(i, j) = G[i].v[j];
        Gd(i, j) = G[i].v[N + j];
      }
    const Eigen::FullPivLU<M> lu(Fd);
    if (!Fd.allFinite() || !lu.isInvertible()) return false;
    const M Dq = -lu.solve(Fq);  // d dq / d q0
    const M Dp = -lu.inverse();  // d dq / d p0
    A.template topLeftCorner<N, N>() = M::Identity() + Dq;
    A.template topRightCorner<N, N>() = Dp;
    A.template bottomLeftCorner<N, N>() = Gq + Gd * Dq;
    A.template bottomRightCorner<N, N>() = Gd * Dp;
    return A.allFinite();
  }

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
        if (!std::isfinite(max_abs(dp))) s.fail("non-finite momentum");
      }
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    return s;
  }

 private:
  DL dl_;
  StepOptions options_;
};

}  // namespace dvm
