// Helpers shared by the two translation units of test_galerkin_manifold: the systems
// and states, running a stepper to a fixed time, a fixed-time order fit against a
// reference from an independent method (an order-8 composition of the midpoint map,
// solvers/manifold_composition.h), and the symplecticity defect of a manifold step
// read in a fixed chart, by central differences.
#pragma once

#include <boost/test/unit_test.hpp>

#include <cmath>
#include <sstream>
#include <vector>

#include "solvers/hamiltonian_step.h"
#include "solvers/manifold_composition.h"
#include "solvers/manifold_galerkin_step.h"
#include "tests/composed_steps.h"
#include "tests/solvers/chart_galerkin_step.h"
#include "tests/verification/common.h"

namespace gm {

using namespace dvm;
using V2 = Vec<double, 2>;
using V3 = Vec<double, 3>;
using M3 = Mat<double, 3, 3>;

inline const SphericalPendulum& pendulum() {
  static const SphericalPendulum P(1.0, 1.0, 1.0);
  return P;
}
inline const RigidBody& body() {
  static const RigidBody B(V3(1.0, 2.0, 3.0));
  return B;
}
inline const HeavyTop& top() {
  static const HeavyTop T(V3(1.0, 1.2, 0.5), 1.0, 1.0, V3(0.1, 0.0, 0.5));
  return T;
}

inline V3 pendulum_point() { return V3(0.48, -0.6, 0.64); }
inline V3 pendulum_momentum() {
  const V3 x = pendulum_point();
  const V3 p(0.7, 0.9, -0.2);
  return p - x.dot(p) * x;
}
inline M3 body_point() { return SO3::exp(V3(0.3, -0.7, 1.1)); }
inline V3 body_momentum() { return V3(0.4, -1.0, 2.0); }

template <class Step, class System>
bool run(const Step& S, const System& L, typename Step::Point& q, typename Step::Covector& p, std::int64_t steps) {
  const RunSummary r = integrate(S, 0.0, q, p, manifold_legendre_inverse(L, q, p), steps, [](auto&&...) {});
  return !r.failed;
}

// (q, p) at time T by kahan-li8 composed from the midpoint map of the exponential
// retraction with n steps.
template <class System, class Map>
void reference(const System& L, const Map& R, double T, int n, typename Map::Manifold::template Point<double>& q,
               typename Map::Manifold::template Tangent<double>& p) {
  const ComposedManifoldStep<System, Map> C(L, R, T / n, substeps(find_composition("kahan-li8"), true));
  BOOST_REQUIRE(run(C, L, q, p, n));
}

// The fitted order of Galerkin with S stages at time T over the step counts ns,
// against (qr, pr); errors below 1e-12 are left out of the fit (round-off).
template <class System, int S>
double fitted_order(const System& L, double T, const std::vector<int>& ns,
                    const typename System::Manifold::template Point<double>& q0,
                    const typename System::Manifold::template Tangent<double>& p0,
                    const typename System::Manifold::template Point<double>& qr,
                    const typename System::Manifold::template Tangent<double>& pr) {
  using M = typename System::Manifold;
  std::vector<double> hs, errs;
  for (int n : ns) {
    const ManifoldGalerkinStep<System> G(L, QuadratureKind::gauss, S, T / n);
    auto q = q0;
    auto p = p0;
    BOOST_REQUIRE(run(G, L, q, p, n));
    hs.push_back(T / n);
    errs.push_back(std::fmax(M::distance(q, qr), max_abs(p - pr)));
  }
  const double order = verification::fit_order(hs, errs, 1e-12);
  std::ostringstream all;
  for (double e : errs) all << " " << e;
  BOOST_TEST_MESSAGE(L.name() << " galerkin gauss s=" << S << " to t=" << T << ": h " << hs.front() << " .. "
                              << hs.back() << ", errors" << all.str() << ", fitted order " << order);
  return order;
}

// Central-difference Jacobian of a map of R^{N2}.
template <int N2, class F>
Mat<double, N2, N2> fd_jacobian(const F& f, const Vec<double, N2>& z, double d) {
  Mat<double, N2, N2> J;
  for (int k = 0; k < N2; ++k) {
    Vec<double, N2> a = z, b = z;
    a[k] += d;
    b[k] -= d;
    J.col(k) = (f(a) - f(b)) / (2 * d);
  }
  return J;
}

// A manifold step read in the fixed chart centred at c: (eta, pi) -> (eta', pi'),
// pi the chart components D^T p of the momentum.
template <class Step>
struct InChart {
  using M = typename Step::M;
  static constexpr int n = Step::n;
  using Z = Vec<double, 2 * n>;
  const Step* step;
  typename Step::Point c;
  Z operator()(const Z& z) const {
    const Vec<double, n> e = z.template head<n>(), pi = z.template tail<n>();
    const auto q = M::chart(c, e);
    const auto p = covector_from_chart_at<M>(c, e, pi);
    Vec<double, n> xi =
        step->step_size() * M::tangent_coordinates(q, manifold_legendre_inverse(step->lagrangian(), q, p));
    typename Step::Point q1 = q;
    typename Step::Covector p1 = p;
    const StepSummary s = step->step(0.0, q, p, xi, q1, p1);
    BOOST_TEST_REQUIRE(s.converged, s.message);
    const Vec<double, n> e1 = M::chart_inverse(c, q1);
    Mat<double, M::template Tangent<double>::RowsAtCompileTime, n> D;
    chart_with_differential<M, double>(c, e1, D);
    Z out;
    out << e1, D.transpose() * p1;
    return out;
  }
};

// max |M^T J M - J| of the step from chart(c, e0) with momentum p (chart components
// taken at that point), M by central differences of step 1e-5: the difference
// quotients carry about 1e-10 of truncation and solver round-off.
template <class Step>
double defect_in_chart(const Step& G, const typename Step::Point& c, const Vec<double, Step::n>& e0,
                       const typename Step::Covector& p) {
  constexpr int n = Step::n;
  const InChart<Step> f{&G, c};
  Vec<double, 2 * n> z0;
  z0 << e0, Step::M::covector_to_local(c, p);
  return symplectic_defect<n>(fd_jacobian<2 * n>(f, z0, 1e-5));
}

// max over the components of |g - g_ref| / max|g_ref|, where g is the step's gradient
// of the action A(eps, X) at eps = 0 (the chain rule, node by node) and g_ref the
// gradient of action() in one Jet of all its arguments, at control points X spread
// about a step of chart length ~0.1 from q0 (each component perturbed by a fixed
// pattern so that the curve is not a straight line).
template <int S, class Step>
double gradient_against_jets(const Step& G, const typename Step::Point& q0) {
  constexpr int n = Step::n, SN = S * n, K = n + SN;
  BOOST_REQUIRE_EQUAL(G.stages(), S);
  using J = ceres::Jet<double, K>;
  Vec<double, SN> X;
  for (int k = 0; k < SN; ++k) X[k] = 0.1 * (k / n + 1) / (SN / n) + 0.013 * std::sin(1.7 * k + 0.4);
  Vec<J, n> eps;
  Vec<J, SN> XJ;
  for (int a = 0; a < n; ++a) eps[a] = seed<double, K>(0.0, a);
  for (int k = 0; k < SN; ++k) XJ[k] = seed<double, K>(X[k], n + k);
  const Vec<double, K> ref = G.template action<J>(q0, eps, XJ).v;
  Vec<double, K> g;
  G.action_gradient(q0, X, g);
  return max_abs(Vec<double, K>(g - ref)) / max_abs(ref);
}

}  // namespace gm
