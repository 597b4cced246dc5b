// Galerkin discrete Lagrangians on S^2 and SO(3), solved in the chart centred at the
// current point: two constructions, one of which is a variational integrator.
//
// Let phi_c(eta) = chart(c, eta) (core/manifolds.h: the central projection
// (c + B eta)/|c + B eta| on S^2, c exp(eta) on SO(3)) and D_c(eta) its differential,
// mapping chart velocities nu to stored tangent vectors. The Lagrangian pulled back by
// the chart, L_c(eta, nu) = L(phi_c(eta), D_c(eta) nu), is a smooth Lagrangian on
// T R^dim near eta = 0. F(c; q0, q1) denotes the Galerkin action (solvers/
// galerkin_step.h: degree-s curves, Gauss or Lobatto quadrature) of L_c between the
// coordinates of q0 and q1.
//
// 1. ChartGalerkinStep (a wrapper of the R^n step; tests/solvers/chart_galerkin_step.h,
//    kept beside the tests that compare it with 2): from (q_k, p_k), take one Galerkin
//    step of L_c with c = q_k from (0, pi_k), pi_k = D_c(0)^T p_k, and map back,
//    q_{k+1} = phi_c(eta_1), p_{k+1} = D (D^T D)^{-1} pi_1 (D = D_c(eta_1)), as
//    solvers/manifold_hamiltonian_step.h does. For a fixed centre this map is
//    symplectic in the canonical coordinates (eta, pi) and has local error
//    O(h^{2s+1}), so the order is 2s. But the Galerkin curves are polynomials in the
//    chart's coordinates, and charts with different centres differ by nonlinear maps
//    (projective maps of the tangent planes on S^2, Baker-Campbell-Hausdorff on
//    SO(3)), so the step depends on its centre, which moves with the state: the
//    one-step map z -> psi_{c(z)}(z) is not symplectic and the momentum maps drift.
//    Measured (tests/solvers/test_galerkin_manifold.cc): symplecticity defect about
//    h^3 (s = 1), h^5.5 (s = 2); momentum errors about h^{2s} at a fixed time. Its
//    generating function is F(c; q0, q1) differentiated with c = q0 held fixed, not a
//    function of (q0, q1) alone.
//
// 2. ManifoldGalerkinStep (the variational integrator): the discrete Lagrangian
//       L_d(q0, q1) = F(q0; q0, q1),  p0 = -D1 L_d(q0, q1),  p1 = D2 L_d(q0, q1),
//    the derivative in q0 moving the chart's centre with q0 (on Lie groups with the
//    chart q0 exp(e), the construction behind the symplectic Runge-Kutta-Munthe-Kaas
//    methods of Bogfjellmo and Marthinsen, "High order symplectic partitioned Lie
//    group methods", Found. Comput. Math. 16, 2016, arXiv:1303.5654; here the same
//    with the central-projection charts of S^2 too; the chart approach in
//    general: Leok and Shingel, "General techniques for constructing variational
//    integrators", Front. Math. China 7, 2012). L_d is a function of the two points,
//    so the step is exactly symplectic (a type-1 generating function); if the chart
//    family is equivariant under a symmetry of L (g phi_c(eta) = phi_{gc}(A eta), A
//    linear: rotations on S^2, left multiplication on SO(3)), L_d is invariant (the
//    Galerkin action is invariant under linear changes of the chart coordinates) and
//    the momentum map is conserved exactly (discrete Noether). The local error is
//    still O(h^{2s+1}): order 2s. Measured: symplecticity defect at the level of the
//    finite-difference check, momentum maps to round-off.
//
// Every point is produced by the chart, so it lies on the manifold to round-off.
// Both keep a factored Jacobian across steps (simplified Newton: refreshed when the
// iteration contracts poorly) and allocate nothing per step.
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "mechanics/manifold_hamiltonian.h"
#include "mechanics/manifold_systems.h"
#include "solvers/galerkin_step.h"
#include "solvers/manifold_step.h"
#include "solvers/newton_driver.h"

namespace dvm {

namespace detail {

// The chart centred at c(eps) = chart(q0, eps), as a function of eps (any scalar): the
// data that the generating function of ManifoldGalerkinStep differentiates in eps.
//   point_tangent(eta, nu)  the point with coordinates eta and the tangent vector with
//                           chart velocity nu there
//   end_coordinates(xs)     the coordinates of q1 = chart(q0, xs) in this chart
template <class M, class T>
struct MovingChart;

// SO(3): c(eps) = q0 exp(eps), chart(c, eta) = c exp(eta), body velocity J_r(eta) nu;
// q1 = q0 exp(xs) has coordinates log(exp(-eps) exp(xs)).
template <class T>
struct MovingChart<SO3, T> {
  Mat<T, 3, 3> C, E;
  MovingChart(const Mat<double, 3, 3>& q0, const Vec<T, 3>& eps)
      : C(SO3::mul(SO3::constants3<T>(q0), SO3::exp(eps))), E(SO3::exp(eps)) {}
  std::pair<Mat<T, 3, 3>, Vec<T, 3>> point_tangent(const Vec<T, 3>& eta, const Vec<T, 3>& nu) const {
    return {SO3::mul(C, SO3::exp(eta)), SO3::right_jacobian_times(eta, nu)};
  }
  Vec<T, 3> end_coordinates(const Mat<double, 3, 3>&, const Vec<T, 3>& xs) const {
    return SO3::log(SO3::transpose_mul(E, SO3::exp(xs)));
  }
};

// S^2: c(eps) = chart(q0, eps) and the tangent basis B' = (I - c c^T) B(q0) of T_c S^2
// (any basis serves: the Galerkin action is invariant under linear changes of the
// chart coordinates), chart(c, eta) = (c + B' eta)/|c + B' eta|; q1 has coordinates
// eta with B' eta = q1/(c.q1) - c.
template <class T>
struct MovingChart<Sphere, T> {
  Vec<T, 3> c;
  Mat<T, 3, 2> B;
  MovingChart(const Vec<double, 3>& q0, const Vec<T, 2>& eps) : c(Sphere::chart(q0, eps)) {
    const Mat<double, 3, 2> B0 = Sphere::basis(q0);
    for (int j = 0; j < 2; ++j) {
      const T cb = c[0] * B0(0, j) + c[1] * B0(1, j) + c[2] * B0(2, j);
      for (int i = 0; i < 3; ++i) B(i, j) = B0(i, j) - cb * c[i];
    }
  }
  std::pair<Vec<T, 3>, Vec<T, 3>> point_tangent(const Vec<T, 2>& eta, const Vec<T, 2>& nu) const {
    using std::sqrt;
    Vec<T, 3> y, w;
    for (int i = 0; i < 3; ++i) {
      y[i] = c[i] + B(i, 0) * eta[0] + B(i, 1) * eta[1];
      w[i] = B(i, 0) * nu[0] + B(i, 1) * nu[1];
    }
    const T n2 = detail::dot(y, y);
    const T n = sqrt(n2);
    const T k = detail::dot(y, w) / (n2 * n);
    Vec<T, 3> x, v;
    for (int i = 0; i < 3; ++i) {
      x[i] = y[i] / n;
      v[i] = w[i] / n - k * y[i];
    }
    return {x, v};
  }
  Vec<T, 2> end_coordinates(const Vec<double, 3>& q0, const Vec<T, 2>& xs) const {
    const Vec<T, 3> q1 = Sphere::chart(q0, xs);
    const T d = detail::dot(c, q1);
    Vec<T, 3> y;
    for (int i = 0; i < 3; ++i) y[i] = q1[i] / d - c[i];
    Mat<T, 2, 2> G;
    Vec<T, 2> b;
    for (int a = 0; a < 2; ++a) {
      b[a] = B(0, a) * y[0] + B(1, a) * y[1] + B(2, a) * y[2];
      for (int e = 0; e < 2; ++e) G(a, e) = B(0, a) * B(0, e) + B(1, a) * B(1, e) + B(2, a) * B(2, e);
    }
    const T det = G(0, 0) * G(1, 1) - G(0, 1) * G(1, 0);
    return Vec<T, 2>((G(1, 1) * b[0] - G(0, 1) * b[1]) / det, (G(0, 0) * b[1] - G(1, 0) * b[0]) / det);
  }
};

// The moving chart centred at q0, eps seeded as the first dim directions of a Jet at
// eps = 0, in the two Jet types that ManifoldGalerkinStep's gradient uses: 2 dim
// directions (eps, xs) for the end coordinates, 3 dim (eps, eta, nu) at the nodes. It
// depends on q0 alone, so a step builds it once for all its residuals.
template <class M>
struct SeededCharts {
  static constexpr int n = M::dim;
  using J2 = ceres::Jet<double, 2 * n>;
  using J3 = ceres::Jet<double, 3 * n>;
  typename M::template Point<double> q0;
  MovingChart<M, J2> end;
  MovingChart<M, J3> node;
  explicit SeededCharts(const typename M::template Point<double>& c)
      : q0(c), end(c, seeded_zero<J2>()), node(c, seeded_zero<J3>()) {}

  // The point and tangent vector at chart coordinates (eta, nu), in the Jet of the
  // directions (eps, eta, nu).
  auto node_point_tangent(const Vec<double, n>& eta, const Vec<double, n>& nu) const {
    Vec<J3, n> e, v;
    for (int a = 0; a < n; ++a) {
      e[a] = J3(eta[a], n + a);
      v[a] = J3(nu[a], 2 * n + a);
    }
    return node.point_tangent(e, v);
  }

 private:
  template <class J>
  static Vec<J, n> seeded_zero() {
    Vec<J, n> e;
    for (int a = 0; a < n; ++a) e[a] = J(0.0, a);
    return e;
  }
};

// The derivatives of L along the moving chart at eps = 0, for `points` chart points and
// velocities (eta_i, nu_i): out[i] holds dL/d(eps, eta, nu) there. Not inlined, and
// independent of the Galerkin stage count: compiled once per system, whatever S is.
template <class System>
[[gnu::noinline]] void chart_lagrangian_gradients(const System& L,
                                                  const SeededCharts<typename System::Manifold>& charts, int points,
                                                  const Vec<double, System::Manifold::dim>* eta,
                                                  const Vec<double, System::Manifold::dim>* nu,
                                                  Vec<double, 3 * System::Manifold::dim>* out) {
  for (int i = 0; i < points; ++i) {
    const auto xv = charts.node_point_tangent(eta[i], nu[i]);
    out[i] = L(xv.first, xv.second).v;
  }
}

// The virtual work of a force at the same nodes (the discrete Lagrange-d'Alembert
// principle, as solvers/dynamic_galerkin_step.h on R^n): the force F_i = F(t_i, x_i, v_i)
// evaluated at node i and held there, paired with the node's virtual displacement
// (ManifoldForce::displacement) along the moving chart, is added to out[i], which then
// holds dL/d(eps, eta, nu) + <F_i, d disp/d(eps, eta)>. Returns the force's power
// sum_i b_i <F_i, v_i> (the step's work is h times it).
template <class M, class Force>
[[gnu::noinline]] double chart_force_work(const Force& force, const SeededCharts<M>& charts, int points,
                                          const double* times, const double* b, const Vec<double, M::dim>* eta,
                                          const Vec<double, M::dim>* nu, Vec<double, 3 * M::dim>* out) {
  using J3 = typename SeededCharts<M>::J3;
  double power = 0.0;
  for (int i = 0; i < points; ++i) {
    // (the node again, as chart_lagrangian_gradients formed it: its chart costs little
    // beside L, and the unforced step's function stays one per system)
    const auto xv = charts.node_point_tangent(eta[i], nu[i]);
    const typename M::template Point<double> x = xv.first.unaryExpr([](const J3& j) { return j.a; });
    const typename M::template Tangent<double> w = xv.second.unaryExpr([](const J3& j) { return j.a; });
    Vec<double, Force::size> F;
    force.value(times[i], x, w, F);
    const Vec<J3, Force::size> d = Force::displacement(x, xv.first);
    for (int k = 0; k < Force::size; ++k) out[i] += F[k] * d[k].v;
    power += b[i] * F.dot(w);
  }
  return power;
}

// The Jacobian of the end coordinates Y_S(eps, xs) (MovingChart::end_coordinates) at
// eps = 0: columns 0..dim-1 in eps, dim..2 dim-1 in xs.
template <class M>
[[gnu::noinline]] Mat<double, M::dim, 2 * M::dim> end_coordinates_jacobian(const SeededCharts<M>& charts,
                                                                          const Vec<double, M::dim>& xs) {
  constexpr int n = M::dim;
  using J2 = ceres::Jet<double, 2 * n>;
  Vec<J2, n> x;
  for (int a = 0; a < n; ++a) x[a] = J2(xs[a], n + a);
  const Vec<J2, n> ys = charts.end.end_coordinates(charts.q0, x);
  Mat<double, n, 2 * n> J;
  for (int a = 0; a < n; ++a) J.row(a) = ys[a].v.transpose();
  return J;
}

// Replace the double at the bottom of a (possibly nested) Jet.
template <class T>
void set_bottom_value(T& t, double v) {
  if constexpr (is_jet_v<T>)
    set_bottom_value(t.a, v);
  else
    t = v;
}

}  // namespace detail

// The Galerkin discrete Lagrangian on S^2 or SO(3) as a generating function (the
// second construction above). With F(c; q0, q1) the Galerkin action (degree-s
// curves, the quadrature of `kind`) in the chart centred at c,
//
//   L_d(q0, q1) = F(q0; q0, q1),   p0 = -D1 L_d(q0, q1),   p1 = D2 L_d(q0, q1),
//
// the derivative in q0 moving the chart's centre with q0. L_d is a function of the
// two points alone, so the step (q0, p0) -> (q1, p1) is exactly symplectic (a
// type-1 generating function); if the chart family is equivariant under a symmetry of
// L (g chart(c, eta) = chart(g c, A eta) with A linear: rotations on S^2, left
// multiplication on SO(3)), L_d is invariant and the momentum map is conserved
// exactly (discrete Noether). The local error is that of the Galerkin action,
// O(h^{2s+1}), so the order is 2s.
//
// The step, in the chart centred at q0 with unknowns X_1..X_s (coordinates of the
// control points; X_s those of q1): with A(eps, X) the quadrature of the action along
// the curve whose control points are, in the chart centred at chart(q0, eps), 0,
// X_1, .., X_{s-1} and the coordinates of chart(q0, X_s),
//   p0 + dA/deps = 0,   dA/dX_j = 0 (j = 1..s-1)   at eps = 0,   p1 = dA/dX_s
// (internal control points are stationary, so how they move with eps does not
// matter). The chain rule gives all of them from derivatives of L at the quadrature
// nodes (action_gradient); the Jacobian in X (central differences of them) is factored
// and reused across iterations and steps while the corrections contract, by the one
// driver with Refresh::contracting, as in solvers/galerkin_step.h.
//
// The stage count s (1..kGalerkinMaxStages) is a run-time argument: the vectors and
// matrices of the stage system have run-time sizes in storage of the largest size
// (no allocation), so that a system compiles one step for every s. The arithmetic that
// costs (L and its derivatives at the nodes, the chart) has fixed sizes either way.
//
// Force: a force on the manifold (ManifoldForce<M>: an embedded force on S^2, a body
// torque on SO(3)) or NoForce. A forced step adds the discrete forces of the Lagrange-
// d'Alembert principle by the same quadrature: at node i, time t + c_i h, the force is
// held and paired with the node's virtual displacement (detail::chart_force_work), in
// the equations for eps, the internal control points and p1 alike; the step reports
// the force's work h sum_i b_i <F_i, v_i> at its last evaluation (StepSummary::work).
// The step is then no longer symplectic, and the momentum maps change by the forces'
// impulse.
template <class System, class Force = NoForce>
class ManifoldGalerkinStep {
 public:
  static constexpr bool kForced = is_force_v<Force>;
  using M = typename System::Manifold;
  static constexpr int n = M::dim;
  static constexpr int max_SN = kGalerkinMaxStages * n;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  using V = Vec<double, n>;
  // the control points X (s n), the action's gradient (n + s n), the Jacobian (s n)^2
  using XV = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, max_SN, 1>;
  using GV = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, max_SN + n, 1>;
  using JM = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, max_SN, max_SN>;

  // force: required where Force is not NoForce (shared by the step's copies).
  ManifoldGalerkinStep(System L, QuadratureKind kind, int stages, double h, StepOptions options = {},
                       std::shared_ptr<const Force> force = nullptr)
      : L_(std::move(L)),
        quad_(kind, checked_stages(stages)),
        S_(stages),
        SN_(stages * n),
        h_(h),
        options_(options),
        force_(std::move(force)) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
    if (kForced && !force_) throw std::invalid_argument("ManifoldGalerkinStep: a forced step needs its force");
    const int S = S_;
    for (int i = 0; i < quad_.points; ++i) {
      b_[i] = static_cast<double>(quad_.b[i]);
      for (int j = 0; j <= S; ++j) {
        // Lagrange basis on the control points d_k = k/S and its derivative at c_i
        long double l = 1.0L, dl = 0.0L;
        for (int k = 0; k <= S; ++k) {
          if (k == j) continue;
          const long double dj = static_cast<long double>(j) / S, dk = static_cast<long double>(k) / S;
          const long double f = (quad_.c[i] - dk) / (dj - dk);
          dl = dl * f + l / (dj - dk);
          l *= f;
        }
        A_[i][j] = static_cast<double>(l);
        B_[i][j] = static_cast<double>(dl);
      }
    }
    // extrapolation of the previous step's curve to tau = 1 + j/S (control points of
    // the next step, in the previous chart)
    for (int j = 1; j <= S; ++j)
      for (int k = 1; k <= S; ++k) {
        long double l = 1.0L;
        const long double t = 1.0L + static_cast<long double>(j) / S;
        for (int m = 0; m <= S; ++m)
          if (m != k) l *= (t - static_cast<long double>(m) / S) / (static_cast<long double>(k - m) / S);
        E_[j][k] = static_cast<double>(l);
      }
    Xprev_ = X_ = R_ = delta_ = start_ = XV::Zero(SN_);
    G_ = GV::Zero(n + SN_);
    J_ = lu_.inv = JM::Zero(SN_, SN_);
  }

  double step_size() const { return h_; }
  int stages() const { return S_; }
  int order() const { return 2 * S_; }
  const System& lagrangian() const { return L_; }
  long jacobian_updates() const { return jacobian_updates_; }
  // The controls the force reads (0 without a force).
  int controls() const {
    if constexpr (kForced)
      return force_->controls();
    else
      return 0;
  }

  // The quadrature of the action, A(eps, X), for any scalar (X: s n control-point
  // coordinates, of fixed or run-time size).
  template <class T, int R>
  T action(const Point& q0, const Vec<T, n>& eps, const Vec<T, R>& X) const {
    if (X.size() != SN_) throw std::invalid_argument("ManifoldGalerkinStep::action: X has the wrong size");
    const int S = S_;
    const detail::MovingChart<M, T> chart(q0, eps);
    std::array<Vec<T, n>, kGalerkinMaxStages + 1> Y;
    for (int j = 1; j < S; ++j) Y[j] = X.template segment<n>((j - 1) * n);
    const Vec<T, n> xs = X.template segment<n>((S - 1) * n);
    Y[S] = chart.end_coordinates(q0, xs);
    // at eps = 0 the end coordinates are xs: keep its value exactly (the formula's
    // round-off is relative to |xs| ~ h); the derivatives come from the formula
    for (int a = 0; a < n; ++a) detail::set_bottom_value(Y[S][a], value(xs[a]));
    T sum = constant<T>(0.0);
    for (int i = 0; i < quad_.points; ++i) {
      Vec<T, n> eta, nu;
      for (int a = 0; a < n; ++a) {
        T e = constant<T>(0.0), v = constant<T>(0.0);
        for (int j = 1; j <= S; ++j) {
          e = e + A_[i][j] * Y[j][a];
          v = v + (B_[i][j] / h_) * Y[j][a];
        }
        eta[a] = e;
        nu[a] = v;
      }
      const auto xv = chart.point_tangent(eta, nu);
      sum = sum + (h_ * b_[i]) * L_(xv.first, xv.second);
    }
    return sum;
  }

  // One step: xi holds a guess of the chart coordinates of q1 on entry (spread
  // linearly over the control points) and them on return.
  StepSummary step(double t, const Point& q0, const Covector& p0, V& xi, Point& q1, Covector& p1) const {
    const int S = S_;
    const V pi0 = M::covector_to_local(q0, p0);
    // starting guess: the previous step's curve extrapolated (error O(h^{S+1})) and
    // read in the chart centred at q0, when this step continues that one; otherwise
    // xi spread linearly over the control points
    if (have_prev_ && M::distance(q0, prev_end_) <= 1e-14) {
      for (int j = 1; j <= S; ++j) {
        V z = V::Zero();
        for (int k = 1; k <= S; ++k) z += E_[j][k] * Xprev_.template segment<n>((k - 1) * n);
        X_.template segment<n>((j - 1) * n) = M::chart_inverse(q0, M::chart(prev_centre_, z));
      }
    } else {
      for (int j = 1; j <= S; ++j) X_.template segment<n>((j - 1) * n) = (static_cast<double>(j) / S) * xi;
    }
    have_prev_ = false;
    Equation eq{*this, t, q0, pi0, max_abs(pi0)};
    StepSummary sum;
    try {
      sum = newton_drive(eq, lu_, Refresh::contracting, options_, X_, R_, delta_, J_, kept_, start_);
      jacobian_updates_ += sum.jacobians;
      if (!sum.converged) return sum;
      V pi1;
      sum.work = residual(t, q0, pi0, X_, R_, pi1);  // p1 at the corrected nodes
      xi = X_.template segment<n>((S - 1) * n);
      leave_chart<M>(q0, xi, pi1, sum, q1, p1);
      if (!sum.converged) return sum;
      Xprev_ = X_;
      prev_centre_ = q0;
      prev_end_ = q1;
      have_prev_ = true;
    } catch (const std::domain_error& e) {  // L or the chart undefined at a node
      sum.fail(e.what());
      kept_.valid = false;
    }
    return sum;
  }

 private:
  static int checked_stages(int s) {
    if (s < 1 || s > kGalerkinMaxStages)
      throw std::invalid_argument("Galerkin stages must be 1.." + std::to_string(kGalerkinMaxStages) + ", got " +
                                  std::to_string(s));
    return s;
  }

  // R = (p0 + dA/deps, dA/dX_1, .., dA/dX_{s-1}) at eps = 0 and pi1 = dA/dX_s, at the
  // control points X, with the forces' virtual work in each where the step has a force;
  // returns the forces' work over the step (0 without).
  double residual(double t, const Point& q0, const V& pi0, const XV& X, XV& R, V& pi1) const {
    const double work = gradient(t, q0, X, G_);
    R = G_.head(SN_);
    R.template head<n>() += pi0;
    pi1 = G_.template tail<n>();
    return work;
  }

  // The step equation for the driver: R(X) = 0, its scale |p0| + max|J| max|X|; the
  // coordinates X are those of points near the chart's centre (offset 0).
  struct Equation {
    using Vector = XV;
    using Matrix = JM;
    const ManifoldGalerkinStep& step;
    double t;
    const Point& q0;
    const V& pi0;
    double pscale;
    void residual(const Vector& x, Vector& r) const {
      V pi1;
      step.residual(t, q0, pi0, x, r, pi1);
    }
    double jacobian(const Vector& x, Vector& r, Matrix& J) const {
      const double Jmax = step.form_jacobian(t, q0, pi0, x, J);
      residual(x, r);
      return Jmax;
    }
    double scale(double xn, double Jmax) const { return pscale + Jmax * xn; }
    double offset() const { return 0.0; }
  };

  // The Jacobian's factorisation, kept as its inverse; singular where Eigen's estimate
  // of its reciprocal condition is not above 1e-13.
  struct InverseLU {
    JM inv;
    bool factor(const JM& J, double /*Jmax*/) {
      const Eigen::PartialPivLU<JM> lu(J);
      if (!(lu.rcond() > 1e-13)) return false;
      inv = lu.inverse();
      return true;
    }
    void solve(const XV& r, XV& dx) const { dx.noalias() = inv.lazyProduct(r); }
    const char* name() const { return "LU with reciprocal condition above 1e-13"; }
  };

 public:
  // The gradient of the action A(eps, X) at eps = 0, in the order (eps, X_1, .., X_s)
  // (X: s n values; G: n + s n). By the chain rule, node by node: L along the moving
  // chart is differentiated at each quadrature node in one Jet of 3 dim directions
  // (eps, eta, nu), and the end coordinates Y_s(eps, X_s) in one of 2 dim, both in
  // functions that do not depend on s (differentiating action() in a Jet of
  // dim + s dim directions would compile L's derivatives once per stage count). Equal
  // to the gradient of action() to round-off (tests/solvers/test_galerkin_manifold.cc).
  void action_gradient(const Point& q0, const Eigen::Ref<const Eigen::VectorXd>& X, Eigen::Ref<Eigen::VectorXd> G) const {
    if (X.size() != SN_ || G.size() != n + SN_)
      throw std::invalid_argument("ManifoldGalerkinStep::action_gradient: X or G has the wrong size");
    gradient_with<NoForce>(nullptr, 0.0, q0, X, G);
  }

 private:
  // action_gradient with the forces' virtual work where the step has a force (their
  // nodes at t + c_i h); returns their work over the step (0 without).
  double gradient(double t, const Point& q0, const Eigen::Ref<const Eigen::VectorXd>& X,
                  Eigen::Ref<Eigen::VectorXd> G) const {
    if constexpr (kForced)
      return gradient_with(force_.get(), t, q0, X, G);
    else
      return gradient_with<NoForce>(nullptr, t, q0, X, G);
  }
  template <class Fo>
  double gradient_with(const Fo* force, double t, const Point& q0, const Eigen::Ref<const Eigen::VectorXd>& X,
                       Eigen::Ref<Eigen::VectorXd> G) const {
    const int S = S_;
    if (!charts_ || !(charts_->q0 == q0)) charts_.emplace(q0);
    std::array<V, kGalerkinMaxStages + 2> eta, nu;
    for (int i = 0; i < quad_.points; ++i) {
      eta[i].setZero();
      nu[i].setZero();
      for (int j = 1; j <= S; ++j) {
        const V Yj = X.template segment<n>((j - 1) * n);
        eta[i] += A_[i][j] * Yj;
        nu[i] += (B_[i][j] / h_) * Yj;
      }
    }
    std::array<Vec<double, 3 * n>, kGalerkinMaxStages + 2> dl;
    detail::chart_lagrangian_gradients(L_, *charts_, quad_.points, eta.data(), nu.data(), dl.data());
    double work = 0.0;
    if constexpr (is_force_v<Fo>) {
      if (force) {
        std::array<double, kGalerkinMaxStages + 2> times;
        for (int i = 0; i < quad_.points; ++i) times[i] = t + static_cast<double>(quad_.c[i]) * h_;
        work = h_ * detail::chart_force_work<M>(*force, *charts_, quad_.points, times.data(), b_.data(), eta.data(),
                                                nu.data(), dl.data());
      }
    } else {
      (void)force;
      (void)t;
    }
    // dA/deps through the chart (G's head) and dA/dY_j as if the Y_j were free
    G.setZero();
    for (int i = 0; i < quad_.points; ++i) {
      const double w = h_ * b_[i];
      G.template head<n>() += w * dl[i].template head<n>();
      for (int j = 1; j <= S; ++j)
        G.template segment<n>(j * n) +=
            (w * A_[i][j]) * dl[i].template segment<n>(n) + (w * B_[i][j] / h_) * dl[i].template segment<n>(2 * n);
    }
    // Y_s = Y_s(eps, X_s): dA/deps += (dY_s/deps)^T dA/dY_s, dA/dX_s = (dY_s/dX_s)^T dA/dY_s
    const Mat<double, n, 2 * n> J = detail::end_coordinates_jacobian(*charts_, V(X.template tail<n>()));
    const V gS = G.template tail<n>();
    G.template head<n>() += J.template leftCols<n>().transpose() * gS;
    G.template tail<n>() = J.template rightCols<n>().transpose() * gS;
    return work;
  }

  // The Jacobian dR/dX at the current X_, inverted, by central differences of the
  // residual (each column from two residuals in Jets of the first order). The Jacobian
  // only steers the iteration: its error (relative ~1e-10) slows the contraction to a
  // rate near that, and the solution is the zero of the residual, which is exact, to the
  // iteration's tolerance. (Nested Jets would give it exactly, at the price of L's
  // second derivatives compiled in a Jet type of its own.)
  // (Into J at the control points X; returns max|J_ij|, not finite where an entry is not.)
  // The differences are relative to the control points' size, but not below 1e-8 (the
  // chart coordinates are angles or of that scale): a step from rest under a force starts
  // from X = 0, where relative differences would vanish.
  double form_jacobian(double t, const Point& q0, const V& pi0, const XV& X, JM& J) const {
    const double size = std::fmax(max_abs(X), 1e-8);
    XV Xk = X, Rp, Rm;
    V pi1;
    for (int k = 0; k < SN_; ++k) {
      const double dk = 6e-6 * std::fmax(std::fabs(X[k]), size);  // ~ cbrt(machine epsilon)
      Xk[k] = X[k] + dk;
      residual(t, q0, pi0, Xk, Rp, pi1);
      Xk[k] = X[k] - dk;
      residual(t, q0, pi0, Xk, Rm, pi1);
      Xk[k] = X[k];
      J.col(k) = (Rp - Rm) / (2.0 * dk);
    }
    return max_abs(J);
  }

  System L_;
  Quadrature quad_;
  int S_, SN_;
  double h_;
  StepOptions options_;
  std::shared_ptr<const Force> force_;
  std::array<double, kGalerkinMaxStages + 2> b_{};
  std::array<std::array<double, kGalerkinMaxStages + 1>, kGalerkinMaxStages + 2> A_{}, B_{};
  std::array<std::array<double, kGalerkinMaxStages + 1>, kGalerkinMaxStages + 1> E_{};
  mutable XV Xprev_;
  mutable Point prev_centre_ = M::sample_point(), prev_end_ = M::sample_point();
  mutable bool have_prev_ = false;
  mutable XV X_, R_, delta_, start_;
  mutable GV G_;
  mutable std::optional<detail::SeededCharts<M>> charts_;  // at the centre of the last gradient
  mutable JM J_;
  mutable InverseLU lu_;
  mutable DriverState kept_;  // whether lu_ holds a Jacobian kept across steps
  mutable long jacobian_updates_ = 0;
};

}  // namespace dvm
