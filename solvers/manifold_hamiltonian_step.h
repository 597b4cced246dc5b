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
// The local map is inverted through the manifold map's closed-form inverse
// (ClosedFormChartMap), with the relative position of the two points formed in the
// chart without cancellation; maps without one use Newton's method in the chart.
#pragma once

#include <memory>
#include <type_traits>

#include "mechanics/manifold_hamiltonian.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/manifold_step.h"

namespace dvm {

// The relative position (Sphere::relative, SO3::relative) of chart(c, e0 + de) from
// chart(c, e0), formed without cancellation when de is small:
//   S^2 (central projection, chart(c, e) = (c + B e)/n(e), n = sqrt(1 + |e|^2)):
//     d = c k + B (de/n1 + e0 k),   k = 1/n1 - 1/n0 = -(de.(2 e0 + de))/(n0 n1 (n0 + n1));
//   SO(3): chart(c, e0)^T chart(c, e0 + de) = exp(e0)^T exp(e0 + de) (c cancels).
template <class T>
Vec<T, 3> chart_relative(const Sphere&, const Vec<double, 3>& c, const Vec<T, 2>& e0, const Vec<T, 2>& de) {
  using std::sqrt;
  const Vec<T, 2> e1(e0[0] + de[0], e0[1] + de[1]);
  const T n0 = sqrt(1.0 + detail::dot(e0, e0)), n1 = sqrt(1.0 + detail::dot(e1, e1));
  const T k = -(de[0] * (2.0 * e0[0] + de[0]) + de[1] * (2.0 * e0[1] + de[1])) / (n0 * n1 * (n0 + n1));
  const Vec<T, 2> u(de[0] / n1 + e0[0] * k, de[1] / n1 + e0[1] * k);
  const Vec<T, 3> Bu = Sphere::tangent(c, u);
  return Vec<T, 3>(c[0] * k + Bu[0], c[1] * k + Bu[1], c[2] * k + Bu[2]);
}
template <class T>
Mat<T, 3, 3> chart_relative(const SO3&, const Mat<double, 3, 3>&, const Vec<T, 3>& e0, const Vec<T, 3>& de) {
  return SO3::transpose_mul(SO3::exp(e0), SO3::exp(Vec<T, 3>(e0 + de)));
}

// The map in the chart centred at c (as LocalRepresentation), inverted through the
// manifold map's closed-form inverse when it has one: (x, v) = R_d^{-1}(q0, q1) with
// the relative position from chart_relative, eta = chart^{-1}(x), and nu the chart
// velocity with D(eta) nu = v, i.e. nu = (D^T D)^{-1} D^T v. Maps without a closed
// form fall back to Newton's method on the local representation.
template <class Map>
class ClosedFormChartMap {
 public:
  using M = typename Map::Manifold;
  static constexpr int n = M::dim;
  static constexpr int S = M::template Tangent<double>::RowsAtCompileTime;
  static constexpr bool provides_inverse = true;
  using Point = typename M::template Point<double>;
  ClosedFormChartMap(const Map* map, const Point& c) : local_(MapView<Map>{map}, c), map_(map), c_(c) {}
  std::string name() const { return local_.name(); }
  bool symmetric() const { return local_.symmetric(); }
  int order() const { return local_.order(); }

  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& eta, const Vec<T, N>& nu) const {
    return local_(eta, nu);
  }
  template <class T, int N>
  TangentPoint<T, N> inverse(const Vec<T, N>& e0, const Vec<T, N>& e1) const {
    return inverse_increment(e0, Vec<T, N>(e1 - e0));
  }
  template <class T, int N>
  TangentPoint<T, N> inverse_increment(const Vec<T, N>& e0, const Vec<T, N>& de) const {
    static_assert(N == n, "a local representation lives in R^dim");
    if (!map_->closed_form_inverse()) return dvm::inverse(local_, e0, Vec<T, N>(e0 + de));
    const ManifoldTangent<M, T> t = map_->inverse_relative(M::chart(c_, e0), chart_relative(M{}, c_, e0, de));
    const Vec<T, n> eta = M::chart_inverse(c_, t.x);
    Mat<T, S, n> D;
    chart_with_differential<M, T>(c_, eta, D);
    Mat<T, n, n> G;
    Vec<T, n> b;
    for (int i = 0; i < n; ++i) {
      T bi = constant<T>(0.0);
      for (int k = 0; k < S; ++k) bi = bi + D(k, i) * t.v[k];
      b[i] = bi;
      for (int j = 0; j < n; ++j) {
        T g = constant<T>(0.0);
        for (int k = 0; k < S; ++k) g = g + D(k, i) * D(k, j);
        G(i, j) = g;
      }
    }
    return {eta, solve_dense<T, n, n>(G, b)};
  }

 private:
  LocalRepresentation<MapView<Map>> local_;
  const Map* map_;
  Point c_;
};

// A force on the manifold (ManifoldForce, mechanics/written_manifold.h) in the chart
// centred at c, at time t: the chart components of the force at chart velocity nu,
//   F_c(eta, nu) = D(eta)^T F(t, phi(eta), D(eta) nu),
// the force pulled back by the chart as a stored covector p is (pi = D^T p). It pairs the
// force with the virtual displacement as the lagrangian form does (ManifoldForce::
// displacement): on S^2 the displacement of the embedded point, D delta-eta; on SO(3)
// the body rotation vee(R^T delta R), which is again D delta-eta, since D maps chart
// velocities to body angular velocities there.
template <class Fo, class M>
struct ChartForce {
  static constexpr int n = M::dim;
  static constexpr int S = M::template Tangent<double>::RowsAtCompileTime;
  static_assert(Fo::size == S, "the force has the components of a stored covector");
  const Fo* force = nullptr;
  typename M::template Point<double> centre;
  double t = 0.0;
  template <class T>
  Vec<T, n> operator()(const Vec<T, n>& eta, const Vec<T, n>& nu) const {
    Mat<T, S, n> D;
    const auto x = chart_with_differential<M, T>(centre, eta, D);
    typename M::template Tangent<T> v;
    for (int k = 0; k < S; ++k) {
      T s = constant<T>(0.0);
      for (int j = 0; j < n; ++j) s = s + D(k, j) * nu[j];
      v[k] = s;
    }
    Vec<T, S> F;
    force->value(t, x, v, F);
    Vec<T, n> out;
    for (int j = 0; j < n; ++j) {
      T s = constant<T>(0.0);
      for (int k = 0; k < S; ++k) s = s + D(k, j) * F[k];
      out[j] = s;
    }
    return out;
  }
};

// Force: NoForce, or a force on the manifold (ManifoldForce<M>): the chart step then
// samples the forced Hamilton equations (solvers/hamiltonian_step.h) with the force in
// the chart (ChartForce) at the time of the map's base point, t0 + theta h (as the
// lagrangian form's ManifoldStep evaluates it at its node), and reports its work.
template <class Ham, class Map, class Force = NoForce>
class ManifoldHamiltonianStep {
 public:
  using M = typename Map::Manifold;
  static constexpr int n = M::dim;
  static constexpr bool kForced = is_force_v<Force>;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  using V = Vec<double, n>;
  using LocalH = decltype(chart_hamiltonian(std::declval<const Ham&>(), std::declval<const Point&>()));
  using LocalMap = ClosedFormChartMap<Map>;
  using LocalForce = std::conditional_t<kForced, ChartForce<Force, M>, NoForce>;
  using Local = HamiltonianStep<LocalH, LocalMap, LocalForce>;
  static_assert(std::is_same_v<typename Ham::Manifold, M>, "Hamiltonian and map live on different manifolds");

  ManifoldHamiltonianStep(Ham H, Map R, double h, StepOptions options = {},
                          VectorFieldSample sample = VectorFieldSample::base_point,
                          std::shared_ptr<const Force> force = nullptr)
      : H_(std::move(H)), R_(std::move(R)), h_(h), options_(options), sample_(sample), force_(std::move(force)) {
    // negative sizes are the backward substeps of compositions (solvers/manifold_composition.h)
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    if (kForced && !force_) throw std::invalid_argument("ManifoldHamiltonianStep: a forced step needs its force");
  }
  double step_size() const { return h_; }
  const Ham& hamiltonian() const { return H_; }
  const Map& map() const { return R_; }
  // The controls the force reads (0 without a force).
  int controls() const {
    if constexpr (kForced)
      return force_->controls();
    else
      return 0;
  }

  // The R^dim Hamiltonian step in the chart centred at c, for the step that starts at
  // time t (it refers to this object's map and force, so it must not outlive it).
  Local local_step(const Point& c, double t = 0.0) const {
    LocalForce f{};
    if constexpr (kForced)
      f = LocalForce{force_.get(), c, t + R_.theta() * h_};
    else
      (void)t;
    Local local(chart_hamiltonian(H_, c), LocalMap(&R_, c), h_, options_, sample_, f);
    local.keep_jacobian_within_step(true);  // (its Jacobian: the map's and H_c's in nested Jets)
    return local;
  }

  // The derivative of the step (q0, p0) -> (q1, p1) at its solution, in the canonical
  // coordinates (eta, pi) around q0 before the step and around q1 after it (those of
  // ManifoldStep::derivatives, solvers/manifold_step.h): A (2 dim x 2 dim), by the
  // implicit function theorem through the chart step's solve (in the chart centred at
  // q0, solved again from (q0, p0)) followed by the change of
  // canonical coordinates from the chart at q0 to the chart at q1 at the end point.
  // Unforced steps only (a forced step's derivative is not written: validate refuses
  // --linearize there); B, where given, is 2 dim x 0. Defined in
  // solvers/manifold_hamiltonian_step_derivative.h, which only the files that
  // differentiate include (the runtime's kernels_sphere.cc and kernels_rotation.cc, where
  // the step is compiled too, instantiate it). False where the solve fails or a Jacobian
  // is singular.
  bool derivatives(double t, const Point& q0, const Covector& p0, const Point& q1, Eigen::MatrixXd& A,
                   Eigen::MatrixXd* B) const;

  // One step: xi holds the guess of the chart coordinates of q1 on entry and them on
  // return; dp (optional) returns the change of the chart momentum.
  StepSummary step(double t, const Point& q0, const Covector& p0, V& xi, Point& q1, Covector& p1, V* dp_out = nullptr) const {
    const Local local = local_step(q0, t);
    const V pi0 = M::covector_to_local(q0, p0);
    V dq = xi, dp = V::Zero();
    StepSummary s = local.step(t, V::Zero(), pi0, dq, dp);
    if (!s.converged) return s;
    xi = dq;
    if (dp_out) *dp_out = dp;
    leave_chart<M>(q0, xi, V(pi0 + dp), s, q1, p1);
    return s;
  }

 private:
  Ham H_;
  Map R_;
  double h_;
  StepOptions options_;
  VectorFieldSample sample_;
  std::shared_ptr<const Force> force_;
};

}  // namespace dvm
