// The Hamiltonian step of a discretization map on a curved space (paper Sec. 5.1,
// Eq. 5.1, on S^2, SO(3) and (S^2)^K), solved in the chart centred at the current
// point:
//
//   given (q_k, p_k), write the map and the Hamiltonian in the chart centred at q_k
//   (LocalRepresentation, ChartHamiltonian; q_k has coordinates eta = 0 and p_k
//   components pi_k = D(0)^T p_k), take one step of Eq. 5.1 there,
//       (R_c^{T*})^{-1}(0, pi_k; eta, pi) = h X_{H_c}(tau((R_c^{T*})^{-1}(0, pi_k; eta, pi))),
//   with solvers/hamiltonian_step.h, and map back:
//       q_{k+1} = chart(q_k, eta),   p_{k+1} = D (D^T D)^{-1} pi  (D = D chart(q_k, eta)).
//
// Why this is the manifold method and not a chart artefact: the cotangent lift is
// natural (Prop. 3.4: for a diffeomorphism phi, the lift of phi^{-1} o R_d o T phi is
// the lift of R_d conjugated by the cotangent maps of phi), and the Hamiltonian vector
// field is natural under symplectomorphisms, so Eq. 5.1 in any chart containing q_k
// and q_{k+1} gives the same (q_{k+1}, p_{k+1}); a test checks this by solving the
// same step in a chart centred elsewhere. Since (eta, pi) are canonical coordinates of
// T*M, the step is symplectic exactly when its Jacobian in the chart satisfies
// M^T J M = J, which `jacobian` of the chart step measures (implicit function theorem
// through the solve). VectorFieldSample::trapezoidal gives the non-symplectic variant
// used to show that the measurement can fail.
//
// Every iterate is produced by the chart, so it lies on the manifold to round-off (a
// chart result off by more than 1e-12 fails the step, as in solvers/manifold_step.h).
// The local map has no closed-form inverse: HamiltonianStep inverts it by Newton's
// method in doubles and differentiates the inverse by the implicit function theorem.
#pragma once

#include "mechanics/manifold_hamiltonian.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/manifold_step.h"

namespace dvm {

template <class Ham, class Map>
class ManifoldHamiltonianStep {
 public:
  using M = typename Map::Manifold;
  static constexpr int n = M::dim;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  using V = Vec<double, n>;
  using LocalH = decltype(chart_hamiltonian(std::declval<const Ham&>(), std::declval<const Point&>()));
  using LocalMap = LocalRepresentation<MapView<Map>>;
  using Local = HamiltonianStep<LocalH, LocalMap>;
  static_assert(std::is_same_v<typename Ham::Manifold, M>, "Hamiltonian and map live on different manifolds");

  ManifoldHamiltonianStep(Ham H, Map R, double h, StepOptions options = {},
                          VectorFieldSample sample = VectorFieldSample::base_point)
      : H_(std::move(H)), R_(std::move(R)), h_(h), options_(options), sample_(sample) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
  }
  double step_size() const { return h_; }
  const Ham& hamiltonian() const { return H_; }
  const Map& map() const { return R_; }

  // The R^dim Hamiltonian step in the chart centred at c (it refers to this object's
  // map, so it must not outlive it).
  Local local_step(const Point& c) const {
    return Local(chart_hamiltonian(H_, c), LocalMap(MapView<Map>{&R_}, c), h_, options_, sample_);
  }

  // One step: xi holds the guess of the chart coordinates of q1 on entry and them on
  // return; dp (optional) returns the change of the chart momentum.
  StepSummary step(const Point& q0, const Covector& p0, V& xi, Point& q1, Covector& p1, V* dp_out = nullptr) const {
    const Local local = local_step(q0);
    const V pi0 = M::covector_to_local(q0, p0);
    V dq = xi, dp = V::Zero();
    StepSummary s = local.step(V::Zero(), pi0, dq, dp);
    if (!s.converged) return s;
    xi = dq;
    if (dp_out) *dp_out = dp;
    const Point raw = M::chart(q0, xi);
    const double defect = M::point_defect(raw);
    if (!(defect <= 1e-12)) {
      s.converged = false;
      s.message = "the chart left the manifold by " + std::to_string(defect) + " (more than round-off)";
      return s;
    }
    p1 = covector_from_chart_at<M>(q0, xi, V(pi0 + dp));
    q1 = M::clean(raw);
    if (!std::isfinite(max_abs(p1))) {
      s.converged = false;
      s.message = "non-finite momentum";
    }
    return s;
  }

 private:
  Ham H_;
  Map R_;
  double h_;
  StepOptions options_;
  VectorFieldSample sample_;
};

}  // namespace dvm
