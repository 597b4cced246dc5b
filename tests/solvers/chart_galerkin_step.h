// ChartGalerkinStep: the Galerkin step taken in the chart centred at the current point
// and mapped back, construction 1 of solvers/manifold_galerkin_step.h. It is not a
// variational integrator (its generating function depends on the moving centre); the
// tests keep it to show what the variational construction ManifoldGalerkinStep gains.
#pragma once

#include <stdexcept>
#include <string>
#include <utility>

#include "solvers/manifold_galerkin_step.h"

namespace dvm {

// L_c(eta, nu) = L(chart(c, eta), D chart(c, eta) nu): a manifold Lagrangian written in
// the chart centred at *centre, as an R^dim system. The centre is owned by the stepper
// that re-bases it before each step.
template <class System>
struct ChartLagrangian {
  using M = typename System::Manifold;
  static constexpr int dim = M::dim;
  using Point = typename M::template Point<double>;
  System system;
  const Point* centre;
  std::string name() const { return system.name(); }
  template <class T>
  T operator()(const Vec<T, dim>& eta, const Vec<T, dim>& nu) const {
    const auto xv = M::chart_and_tangent(*centre, eta, nu);
    return system(xv.first, xv.second);
  }
};

// The Galerkin method of S stages (1..6 at compile time; 0 at run time) on the
// manifold of System, in the chart centred at the current point. Not copyable: the
// chart Lagrangian inside the R^n step refers to this object's centre.
template <class System, int S = 0>
class ChartGalerkinStep {
 public:
  using M = typename System::Manifold;
  static constexpr int n = M::dim;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  using V = Vec<double, n>;
  using Local = GalerkinStep<ChartLagrangian<System>, S>;

  ChartGalerkinStep(System L, QuadratureKind kind, int stages, double h, StepOptions options = {})
      : centre_(M::sample_point()), local_(ChartLagrangian<System>{std::move(L), &centre_}, kind, stages, h, options) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
  }
  ChartGalerkinStep(const ChartGalerkinStep&) = delete;
  ChartGalerkinStep& operator=(const ChartGalerkinStep&) = delete;

  double step_size() const { return local_.step_size(); }
  int stages() const { return local_.stages(); }
  int order() const { return local_.order(); }
  const System& lagrangian() const { return local_.lagrangian().system; }
  long jacobian_updates() const { return local_.jacobian_updates(); }
  // The R^n step in the chart centred at the last step's starting point.
  const Local& local_step() const { return local_; }

  // One step: xi holds a guess of the chart coordinates of q1 on entry (the R^n step
  // spreads it linearly over its control points) and them on return; dpi (optional)
  // returns the change of the chart momentum pi_1 - pi_k.
  StepSummary step(double t, const Point& q0, const Covector& p0, V& xi, Point& q1, Covector& p1, V* dpi = nullptr) const {
    centre_ = q0;
    const V pi0 = M::covector_to_local(q0, p0);
    V dq = xi, dp = V::Zero();
    StepSummary s = local_.step(t, V::Zero(), pi0, dq, dp);
    if (!s.converged) return s;
    xi = dq;
    if (dpi) *dpi = dp;
    leave_chart<M>(q0, xi, V(pi0 + dp), s, q1, p1);
    return s;
  }

  // d(eta_1, pi_1)/d(eta_0, pi_0) of the chart step just taken from (q0, p0) (centre
  // held at q0), through the solve: symplectic exactly when M^T J M = J.
  Mat<double, 2 * n, 2 * n> chart_jacobian(const Point& q0, const Covector& p0) const {
    return local_.map_jacobian(V::Zero(), M::covector_to_local(q0, p0));
  }

 private:
  mutable Point centre_;
  Local local_;
};

}  // namespace dvm
