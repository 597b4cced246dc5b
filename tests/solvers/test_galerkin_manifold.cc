// Galerkin discrete Lagrangians on S^2 (this file) and SO(3)
// (test_galerkin_manifold_so3.cc), solvers/manifold_galerkin_step.h:
//  - ManifoldGalerkinStep (the discrete Lagrangian F(q0; q0, q1) as a generating
//    function): orders 2s for s = 1..4 at a fixed time against an order-8 composition
//    of the midpoint map; symplectic to the resolution of a finite-difference check in
//    a fixed chart; momentum maps (J3 of the spherical pendulum, the spatial angular
//    momentum of the free rigid body) conserved to round-off; energy error bounded
//    over long runs; every point on the manifold to round-off.
//  - ChartGalerkinStep (the R^n step of the chart Lagrangian, centre re-based at each
//    step): symplectic in its chart through the solve, but the centre moves with the
//    state, and the same checks measure a symplecticity defect and momentum drifts of
//    the method's order: the checks can fail.
#define BOOST_TEST_MODULE galerkin_manifold
#include "tests/solvers/galerkin_manifold_common.h"

using namespace gm;

namespace {

template <int S>
void check_sphere_order(double T, const std::vector<int>& ns, const V3& qr, const V3& pr) {
  BOOST_TEST_CONTEXT("s=" << S) {
    const double p = fitted_order<SphericalPendulum, S>(pendulum(), T, ns, pendulum_point(), pendulum_momentum(), qr, pr);
    BOOST_TEST(std::fabs(p - 2 * S) <= 0.3);
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(sphere_orders_are_2s_for_s_1_to_4) {
  const double T = 2.0;
  const SphereMap map(RetractionKind::exp, 0.5, "sphere-exp");
  V3 qr = pendulum_point(), pr = pendulum_momentum(), qc = qr, pc = pr;
  reference(pendulum(), map, T, 400, qr, pr);
  reference(pendulum(), map, T, 800, qc, pc);
  const double ref_err = std::fmax(max_abs(V3(qr - qc)), max_abs(V3(pr - pc)));
  BOOST_TEST_MESSAGE("reference (kahan-li8, 400 vs 800 steps) agrees to " << ref_err);
  BOOST_TEST(ref_err <= 1e-13);
  check_sphere_order<1>(T, {20, 28, 40, 57, 80, 113, 160}, qr, pr);
  check_sphere_order<2>(T, {10, 14, 20, 28, 40, 57, 80}, qr, pr);
  // s = 3 and 4 from h = 0.1 and 0.08 down: at larger steps the local slopes are
  // still above 2s (9.5 at h = 0.2 for s = 4, falling to 8.1 at h = 0.05)
  check_sphere_order<3>(T, {20, 23, 28, 32, 40, 45, 64}, qr, pr);
  check_sphere_order<4>(T, {25, 28, 32, 36, 40, 45}, qr, pr);
}

BOOST_AUTO_TEST_CASE(sphere_action_gradient_is_that_of_the_action) {
  auto check = [](auto stages, QuadratureKind kind) {
    constexpr int S = decltype(stages)::value;
    const ManifoldGalerkinStep<SphericalPendulum> G(pendulum(), kind, S, 0.3);
    const double d = gradient_against_jets<S>(G, pendulum_point());
    BOOST_TEST_MESSAGE("s=" << S << ": relative difference " << d);
    BOOST_TEST(d <= 1e-13, "s=" << S);
  };
  check(std::integral_constant<int, 1>(), QuadratureKind::gauss);
  check(std::integral_constant<int, 2>(), QuadratureKind::gauss);
  check(std::integral_constant<int, 3>(), QuadratureKind::lobatto);
  check(std::integral_constant<int, 6>(), QuadratureKind::gauss);
}

BOOST_AUTO_TEST_CASE(sphere_generating_step_is_symplectic_and_the_chart_step_is_not) {
  const V3 c = pendulum_point();
  const V2 e0(0.05, -0.03);
  const double h = 0.2;
  auto check = [&](auto stages) {
    constexpr int S = decltype(stages)::value;
    const ManifoldGalerkinStep<SphericalPendulum> E(pendulum(), QuadratureKind::gauss, S, h);
    const ChartGalerkinStep<SphericalPendulum, S> G(pendulum(), QuadratureKind::gauss, S, h);
    const double de = defect_in_chart(E, c, e0, pendulum_momentum());
    const double dg = defect_in_chart(G, c, e0, pendulum_momentum());
    BOOST_TEST_MESSAGE("s=" << S << " h=" << h << ": symplecticity defect in a fixed chart, generating function "
                            << de << ", chart step " << dg);
    BOOST_TEST(de <= 1e-9);
    BOOST_TEST(dg >= 1e-6);
    // the chart step in its own chart (centre fixed), Jacobian through the solve
    V2 xi = V2::Zero();
    V3 q1, p1;
    BOOST_REQUIRE(G.step(0.0, c, pendulum_momentum(), xi, q1, p1).converged);
    const double dc = symplectic_defect<2>(G.chart_jacobian(c, pendulum_momentum()));
    BOOST_TEST_MESSAGE("s=" << S << ": chart step in its own chart, defect " << dc);
    BOOST_TEST(dc <= 1e-13);
  };
  check(std::integral_constant<int, 1>{});
  check(std::integral_constant<int, 2>{});
}

BOOST_AUTO_TEST_CASE(sphere_vertical_momentum_is_conserved_by_the_generating_step_only) {
  const double h = 0.05;
  const int n = 2000;
  const double J0 = SphericalPendulum::vertical_momentum(pendulum_point(), pendulum_momentum());
  const ManifoldGalerkinStep<SphericalPendulum> E(pendulum(), QuadratureKind::gauss, 2, h);
  const ChartGalerkinStep<SphericalPendulum, 2> G(pendulum(), QuadratureKind::gauss, 2, h);
  V3 q = pendulum_point(), p = pendulum_momentum(), qg = q, pg = p;
  BOOST_REQUIRE(run(E, pendulum(), q, p, n));
  BOOST_REQUIRE(run(G, pendulum(), qg, pg, n));
  const double je = std::fabs(SphericalPendulum::vertical_momentum(q, p) - J0);
  const double jg = std::fabs(SphericalPendulum::vertical_momentum(qg, pg) - J0);
  BOOST_TEST_MESSAGE("J3 error after " << n << " steps of h = " << h << " (s = 2): generating function " << je
                                       << ", chart step " << jg);
  BOOST_TEST(je <= 1e-12);  // round-off, about 1e-16 a step
  BOOST_TEST(jg >= 1e-9);
}

BOOST_AUTO_TEST_CASE(sphere_energy_error_is_bounded_over_a_long_run) {
  // 10^5 steps of h = 0.1 (s = 2): the largest energy error of the last quarter is
  // no larger than that of the first (no drift), and |x| = 1 to round-off throughout
  const double h = 0.1;
  const int N = 100000;
  const ManifoldGalerkinStep<SphericalPendulum> E(pendulum(), QuadratureKind::gauss, 2, h);
  V3 q = pendulum_point(), p = pendulum_momentum();
  auto energy = [&](const V3& x, const V3& y) {
    return manifold_energy(pendulum(), x, manifold_legendre_inverse(pendulum(), x, y));
  };
  const double E0 = energy(q, p);
  double emax[4] = {0, 0, 0, 0}, defect = 0.0;
  const RunSummary r = integrate(E, 0.0, q, p, manifold_legendre_inverse(pendulum(), q, p), N,
                                          [&](std::int64_t k, double, const V3& x, const V3& y, const StepSummary&) {
                                            const int b = static_cast<int>((k - 1) * 4 / N);
                                            emax[b] = std::fmax(emax[b], std::fabs(energy(x, y) - E0));
                                            defect = std::fmax(defect, Sphere::point_defect(x));
                                          });
  BOOST_REQUIRE(!r.failed);
  BOOST_TEST_MESSAGE("energy error by quarter of 10^5 steps: " << emax[0] << " " << emax[1] << " " << emax[2] << " "
                                                              << emax[3] << "; largest | |x| - 1 | " << defect
                                                              << "; Jacobian updates " << E.jacobian_updates()
                                                              << ", solver iterations " << r.solver_iterations);
  BOOST_TEST(emax[0] <= 1e-4);
  BOOST_TEST(emax[3] <= 1.5 * emax[0]);
  BOOST_TEST(defect <= 1e-15);
}
