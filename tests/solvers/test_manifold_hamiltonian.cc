// The Hamiltonian step of Eq. 5.1 on S^2 and SO(3) (solvers/manifold_hamiltonian_step.h):
// symplectic in a chart to round-off (and a non-symplectic variant that the check
// catches), independent of the chart it is solved in, on the manifold, conserving
// the momentum maps of the symmetries (discrete Noether), with measured orders; its
// derivative in canonical coordinates (solvers/manifold_hamiltonian_step_derivative.h).
#define BOOST_TEST_MODULE manifold_hamiltonian
#include <boost/test/unit_test.hpp>

#include <array>

#include "solvers/manifold_hamiltonian_step.h"
#include "solvers/manifold_hamiltonian_step_derivative.h"
#include "tests/verification/common.h"

using namespace dvm;

namespace {

using V2 = Vec<double, 2>;
using V3 = Vec<double, 3>;
using M3 = Mat<double, 3, 3>;

const SphereMap sphere_maps[] = {
    SphereMap(RetractionKind::exp, 0.5, "sphere-exp"),
    SphereMap(RetractionKind::projection, 0.5, "sphere-projection"),
    SphereMap(RetractionKind::exp, 0.0, "sphere-exp-fixed"),
    SphereMap(RetractionKind::projection, 0.0, "sphere-projection-fixed"),
};
const SO3Map so3_maps[] = {
    SO3Map(RetractionKind::exp, 0.5, "so3-exp"),
    SO3Map(RetractionKind::cayley, 0.5, "so3-cayley"),
    SO3Map(RetractionKind::exp, 0.0, "so3-exp-fixed"),
    SO3Map(RetractionKind::cayley, 0.0, "so3-cayley-fixed"),
};

// A pendulum state: a point off the axes and a tangent momentum.
V3 pendulum_point() { return V3(0.48, -0.6, 0.64); }
V3 pendulum_momentum() {
  const V3 x = pendulum_point();
  V3 p(0.7, 0.9, -0.2);
  return p - x.dot(p) * x;
}

// The largest symplectic defect |M^T J M - J| of single steps from a few states, M the
// Jacobian of the step in the chart centred at the starting point.
template <class Step>
double chart_defect(const Step& S, const std::vector<std::pair<typename Step::Point, typename Step::Covector>>& states,
                    double h) {
  double d = 0.0;
  for (const auto& [q0, p0] : states) {
    const auto local = S.local_step(q0);
    using V = typename Step::V;
    const V pi0 = Step::M::covector_to_local(q0, p0);
    V dq = V::Zero(), dp = V::Zero();
    const StepSummary s = local.step(0.0, V::Zero(), pi0, dq, dp);
    BOOST_REQUIRE(s.converged);
    BOOST_REQUIRE(max_abs(dq) > 0.1 * h * max_abs(pi0));  // the step moved
    d = std::fmax(d, symplectic_defect<Step::n>(local.jacobian(V::Zero(), pi0, dq, dp)));
  }
  return d;
}

}  // namespace

BOOST_AUTO_TEST_CASE(sphere_hamiltonian_step_is_symplectic_in_a_chart) {
  const SphericalPendulum P(1.0, 1.0, 9.81);
  const double h = 0.1;
  std::vector<std::pair<V3, V3>> states = {{pendulum_point(), pendulum_momentum()}};
  const V3 x2 = V3(0.1, 0.2, -1.0).normalized();
  states.push_back({x2, V3(1.5, -0.4, 0.0) - x2.dot(V3(1.5, -0.4, 0.0)) * x2});
  for (const SphereMap& R : sphere_maps) {
    BOOST_TEST_CONTEXT(R.name()) {
      const ManifoldHamiltonianStep<SphericalPendulumHamiltonian, SphereMap> S(hamiltonian_of(P), R, h);
      const double d = chart_defect(S, states, h);
      BOOST_TEST_MESSAGE(R.name() << ": symplectic defect " << d);
      BOOST_TEST(d <= 1e-13);
      // The same map with X_H averaged over the end points (not Eq. 5.1): the metric
      // of the chart makes H non-quadratic in (eta, pi), and the check sees it.
      const ManifoldHamiltonianStep<SphericalPendulumHamiltonian, SphereMap> T(hamiltonian_of(P), R, h, {},
                                                                               VectorFieldSample::trapezoidal);
      const double dt = chart_defect(T, states, h);
      BOOST_TEST_MESSAGE(R.name() << ": trapezoidal variant defect " << dt);
      BOOST_TEST(dt >= 1e-5);
    }
  }
}

BOOST_AUTO_TEST_CASE(so3_hamiltonian_step_is_symplectic_in_a_chart) {
  const HeavyTop top(V3(1.0, 1.2, 0.5), 1.0, 9.81, V3(0.1, 0.0, 0.5));
  const RigidBody body(V3(1.0, 2.0, 2.5));
  const double h = 0.05;
  const std::vector<std::pair<M3, V3>> states = {{SO3::exp(V3(0.3, -0.7, 1.1)), V3(0.4, -1.0, 2.0)},
                                                 {SO3::exp(V3(-1.2, 0.2, 0.4)), V3(2.0, 0.5, -0.3)}};
  for (const SO3Map& R : so3_maps) {
    BOOST_TEST_CONTEXT(R.name()) {
      const double dt = chart_defect(ManifoldHamiltonianStep<HeavyTopHamiltonian, SO3Map>(hamiltonian_of(top), R, h),
                                     states, h);
      const double db =
          chart_defect(ManifoldHamiltonianStep<RigidBodyHamiltonian, SO3Map>(hamiltonian_of(body), R, h), states, h);
      BOOST_TEST_MESSAGE(R.name() << ": symplectic defect heavy top " << dt << ", rigid body " << db);
      BOOST_TEST(dt <= 1e-13);
      BOOST_TEST(db <= 1e-13);
      const double dtr = chart_defect(ManifoldHamiltonianStep<HeavyTopHamiltonian, SO3Map>(
                                          hamiltonian_of(top), R, h, {}, VectorFieldSample::trapezoidal),
                                      states, h);
      BOOST_TEST_MESSAGE(R.name() << ": trapezoidal variant defect " << dtr);
      BOOST_TEST(dtr >= 1e-6);
    }
  }
}

BOOST_AUTO_TEST_CASE(the_step_does_not_depend_on_the_chart) {
  // Eq. 5.1 is natural: the same step solved in a chart centred at another point c
  // (q0 then has coordinates eta0 != 0) gives the same (q1, p1).
  const SphericalPendulum P(1.0, 1.0, 9.81);
  const double h = 0.1;
  const V3 q0 = pendulum_point(), p0 = pendulum_momentum();
  const V3 c = Sphere::chart(q0, V2(0.15, -0.1));
  for (const SphereMap& R : sphere_maps) {
    BOOST_TEST_CONTEXT(R.name()) {
      const ManifoldHamiltonianStep<SphericalPendulumHamiltonian, SphereMap> S(hamiltonian_of(P), R, h);
      V2 xi = V2::Zero();
      V3 q1, p1;
      BOOST_REQUIRE(S.step(0.0, q0, p0, xi, q1, p1).converged);
      // in the chart centred at c
      const V2 eta0 = Sphere::chart_inverse(c, q0);
      Mat<double, 3, 2> D;
      chart_with_differential<Sphere, double>(c, eta0, D);
      const V2 pi0 = D.transpose() * p0;
      const auto local = S.local_step(c);
      V2 dq = V2::Zero(), dp = V2::Zero();
      BOOST_REQUIRE(local.step(0.0, eta0, pi0, dq, dp).converged);
      const V3 q1c = Sphere::chart(c, V2(eta0 + dq));
      const V3 p1c = covector_from_chart_at<Sphere>(c, V2(eta0 + dq), V2(pi0 + dp));
      BOOST_TEST_MESSAGE(R.name() << ": chart difference q " << max_abs(V3(q1c - q1)) << ", p "
                                  << max_abs(V3(p1c - p1)));
      BOOST_TEST(max_abs(V3(q1c - q1)) <= 1e-13);
      BOOST_TEST(max_abs(V3(p1c - p1)) <= 1e-12);
      BOOST_TEST(std::fabs(q1.dot(p1)) <= 1e-14);  // p1 tangent at q1
    }
  }
}

BOOST_AUTO_TEST_CASE(long_runs_stay_on_the_manifold_and_conserve_momentum_maps) {
  // 4000 steps: |x| = 1 and R^T R = I to round-off; the vertical angular momentum of
  // the pendulum and the spatial angular momentum of the free rigid body (every map
  // here commutes with the symmetry) conserved to a few ulp per step; the energy error
  // bounded with no drift (the second half of the run no worse than the first) and of
  // the method's order p: a symplectic method of order p keeps |E - E0| at O(h^p) over
  // the whole run (backward error analysis: it follows a modified Hamiltonian
  // H + h^p H_p + ..., GNI IX.8), so the pendulum's run to t = 40 is repeated at h/2 and
  // the largest error must fall by 2^p: to within the next term's relative O(h) (log2
  // of the ratio within 0.1; measured 0.003 and 0.06) for the first-order maps, O(h^2)
  // for the symmetric ones, whose error expansion is even (within 0.01; measured 1e-5
  // and 7e-4).
  const int steps = 4000;
  const SphericalPendulum P(1.0, 1.0, 9.81);
  for (const SphereMap& R : sphere_maps) {
    std::array<double, 2> dE_at{0, 0};  // max |E - E0| at h = 0.01 and at h/2
    for (int refine = 0; refine < 2; ++refine) {
      const int n = steps << refine;
      const ManifoldHamiltonianStep<SphericalPendulumHamiltonian, SphereMap> S(hamiltonian_of(P), R,
                                                                             0.01 / (1 << refine));
      V3 q = pendulum_point(), p = pendulum_momentum();
      const V3 v0 = p;
      const double J0 = SphericalPendulum::vertical_momentum(q, p), E0 = S.hamiltonian()(q, p);
      double dJ = 0, defect = 0;
      std::array<double, 2> dE{0, 0};
      const RunSummary run = integrate(S, 0.0, q, p, v0, n, [&](std::int64_t k, double, const V3& x,
                                                                         const V3& y, const StepSummary&) {
        dJ = std::fmax(dJ, std::fabs(SphericalPendulum::vertical_momentum(x, y) - J0));
        double& e = dE[2 * k > n ? 1 : 0];
        e = std::fmax(e, std::fabs(S.hamiltonian()(x, y) - E0));
        defect = std::fmax(defect, Sphere::point_defect(x));
      });
      dE_at[refine] = std::fmax(dE[0], dE[1]);
      BOOST_TEST_CONTEXT(R.name() << ", " << n << " steps") {
        BOOST_TEST(!run.failed);
        BOOST_TEST_MESSAGE(R.name() << ": " << n << " steps, max |J3 - J3(0)| " << dJ << ", max |E - E0| "
                                    << dE[0] << " (first half), " << dE[1] << " (second half), max ||x| - 1| "
                                    << defect);
        BOOST_TEST(defect <= 1e-15);
        BOOST_TEST(dJ <= 1e-12);
        BOOST_TEST(dE[1] <= 1.5 * dE[0]);
      }
    }
    const double measured = std::log2(dE_at[0] / dE_at[1]);
    BOOST_TEST_MESSAGE(R.name() << ": energy error h -> h/2 falls by 2^" << measured << " (order " << R.order()
                                << ")");
    BOOST_TEST_CONTEXT(R.name()) { BOOST_TEST(std::fabs(measured - R.order()) <= (R.symmetric() ? 0.01 : 0.1)); }
  }
  const RigidBody body(V3(1.0, 2.0, 2.5));
  for (const SO3Map& R : so3_maps) {
    const ManifoldHamiltonianStep<RigidBodyHamiltonian, SO3Map> S(hamiltonian_of(body), R, 0.01);
    M3 q = SO3::exp(V3(0.3, -0.7, 1.1));
    V3 p(0.4, -1.0, 2.0);
    const V3 m0 = q * p;
    const V3 v0 = p.cwiseQuotient(body.inertia);
    double dm = 0, defect = 0;
    const RunSummary run = integrate(S, 0.0, q, p, v0, steps, [&](std::int64_t, double, const M3& x,
                                                                           const V3& y, const StepSummary&) {
      dm = std::fmax(dm, max_abs(V3(x * y - m0)));
      defect = std::fmax(defect, SO3::point_defect(x));
    });
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(!run.failed);
      BOOST_TEST_MESSAGE(R.name() << ": " << steps << " steps, max |R Pi - m0| " << dm << " ("
                                  << dm / (steps * 2.2e-16 * m0.norm()) << " ulp of |m| per step), max |R^T R - I| "
                                  << defect);
      BOOST_TEST(defect <= 1e-14);
      BOOST_TEST(dm <= 4.0 * steps * 2.2e-16 * m0.norm());  // a few ulp per step
    }
  }
}

namespace {

// Spherical pendulum (m = l = 1) by long-double RK4 on x'' = -g (e3 - x3 x) - |x'|^2 x.
void pendulum_reference(double g, double t_end, const V3& x0, const V3& v0, V3& x, V3& v) {
  using LD = long double;
  std::array<LD, 6> y{x0[0], x0[1], x0[2], v0[0], v0[1], v0[2]};
  auto f = [&](const std::array<LD, 6>& s) {
    const LD u2 = s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
    std::array<LD, 6> d{s[3], s[4], s[5], 0, 0, 0};
    for (int i = 0; i < 3; ++i) d[3 + i] = -(LD)g * ((i == 2 ? 1 : 0) - s[2] * s[i]) - u2 * s[i];
    return d;
  };
  verification::rk4(f, y, t_end, 20000);
  x = V3((double)y[0], (double)y[1], (double)y[2]);
  v = V3((double)y[3], (double)y[4], (double)y[5]);
}

}  // namespace

BOOST_AUTO_TEST_CASE(measured_orders_on_the_spherical_pendulum) {
  // Error at t = 1 against the reference, steps 1/40 ... 1/320, log-log fit: 2 for the
  // midpoint maps, 1 for the fixed-first-point maps.
  const double g = 9.81;
  const SphericalPendulum P(1.0, 1.0, g);
  const V3 x0 = pendulum_point(), v0 = pendulum_momentum();  // m = l = 1: p = v
  V3 xr, vr;
  pendulum_reference(g, 1.0, x0, v0, xr, vr);
  for (const SphereMap& R : sphere_maps) {
    std::vector<double> hs, errs;
    for (int steps : {40, 80, 160, 320}) {
      const double h = 1.0 / steps;
      const ManifoldHamiltonianStep<SphericalPendulumHamiltonian, SphereMap> S(hamiltonian_of(P), R, h);
      V3 q = x0, p = v0;
      const RunSummary run = integrate(S, 0.0, q, p, v0, steps, [](auto&&...) {});
      BOOST_REQUIRE(!run.failed);
      hs.push_back(h);
      errs.push_back(std::fmax(max_abs(V3(q - xr)), max_abs(V3(p - vr))));
    }
    const double order = verification::fit_order(hs, errs);
    BOOST_TEST_MESSAGE(R.name() << ": order " << order << " (errors " << errs[0] << " ... " << errs.back() << ")");
    BOOST_TEST_CONTEXT(R.name()) { BOOST_TEST(std::fabs(order - R.order()) <= 0.1); }
  }
}

// ManifoldHamiltonianStep::derivatives against central differences of the step itself
// in the canonical coordinates (eta, pi) around q0 before it and around q1 after it
// (canonical_state, canonical_coordinates: solvers/manifold_step.h), relative 1e-7,
// and symplectic (1e-12), for every map of S^2 and SO(3) on the spherical pendulum and
// the heavy top. The end's change of charts matters: the derivative in the chart
// centred at q0 alone (the chart step's Jacobian) is asserted to differ.
namespace {
template <class Step>
void check_manifold_hamiltonian_derivative(const Step& S, const typename Step::Point& q0,
                                           const typename Step::Covector& p0) {
  using M = typename Step::M;
  constexpr int n = Step::n;
  using V = Vec<double, n>;
  auto one_step = [&](const typename Step::Point& q, const typename Step::Covector& p, typename Step::Point& q1,
                      typename Step::Covector& p1) {
    V xi = V::Zero();
    const StepSummary s = S.step(0.0, q, p, xi, q1, p1);
    BOOST_REQUIRE_MESSAGE(s.converged, s.message);
  };
  typename Step::Point c1;
  typename Step::Covector p1;
  one_step(q0, p0, c1, p1);
  Eigen::MatrixXd A, B;
  BOOST_REQUIRE(S.derivatives(0.0, q0, p0, c1, A, &B));
  BOOST_TEST(A.rows() == 2 * n);
  BOOST_TEST(B.cols() == 0);
  V eta0, pi0;
  canonical_coordinates<M>(q0, q0, p0, eta0, pi0);
  const double eps = 1e-6;
  Eigen::MatrixXd C(2 * n, 2 * n);
  for (int j = 0; j < 2 * n; ++j) {
    Vec<double, 2 * n> end[2];
    for (int side = 0; side < 2; ++side) {
      V eta = eta0, pi = pi0;
      (j < n ? eta : pi)[j % n] += side == 0 ? eps : -eps;
      typename Step::Point q, qe;
      typename Step::Covector p, pe;
      canonical_state<M>(q0, eta, pi, q, p);
      one_step(q, p, qe, pe);
      V zeta, pie;
      canonical_coordinates<M>(c1, qe, pe, zeta, pie);
      end[side] << zeta, pie;
    }
    C.col(j) = (end[0] - end[1]) / (2 * eps);
  }
  const double size = std::fmax(1.0, A.cwiseAbs().maxCoeff());
  const double err = (A - C).cwiseAbs().maxCoeff() / size;
  BOOST_TEST_MESSAGE("against central differences " << err);
  BOOST_TEST(err <= 1e-7);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  J.topRightCorner(n, n) = Eigen::MatrixXd::Identity(n, n);
  J.bottomLeftCorner(n, n) = -Eigen::MatrixXd::Identity(n, n);
  BOOST_TEST((A.transpose() * J * A - J).cwiseAbs().maxCoeff() <= 1e-12 * size * size);
  // the chart step's Jacobian (both ends around q0) is not the derivative
  const auto local = S.local_step(q0);
  V dq = M::chart_inverse(q0, c1), dp = V::Zero();
  BOOST_REQUIRE(local.step(0.0, V::Zero(), pi0, dq, dp).converged);
  BOOST_TEST((Eigen::MatrixXd(local.jacobian(V::Zero(), pi0, dq, dp)) - C).cwiseAbs().maxCoeff() > 1e-4 * size);
}
}  // namespace

BOOST_AUTO_TEST_CASE(the_derivative_in_canonical_coordinates_is_the_linearisation) {
  const SphericalPendulum P(1.0, 1.0, 9.81);
  for (const SphereMap& R : sphere_maps)
    BOOST_TEST_CONTEXT(R.name()) {
      check_manifold_hamiltonian_derivative(
          ManifoldHamiltonianStep<SphericalPendulumHamiltonian, SphereMap>(hamiltonian_of(P), R, 0.1), pendulum_point(),
          pendulum_momentum());
    }
  const HeavyTop top(V3(1.0, 1.2, 0.5), 1.0, 9.81, V3(0.1, 0.0, 0.5));
  for (const SO3Map& R : so3_maps)
    BOOST_TEST_CONTEXT(R.name()) {
      check_manifold_hamiltonian_derivative(
          ManifoldHamiltonianStep<HeavyTopHamiltonian, SO3Map>(hamiltonian_of(top), R, 0.05),
          M3(SO3::exp(V3(0.3, -0.7, 1.1))), V3(0.4, -1.0, 2.0));
    }
}
