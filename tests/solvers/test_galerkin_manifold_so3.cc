// Galerkin discrete Lagrangians on SO(3) (see test_galerkin_manifold.cc): orders of
// the generating step on the heavy top, symplecticity in a fixed chart, the spatial
// angular momentum of the free rigid body, bounded energy error.
#include "tests/solvers/galerkin_manifold_common.h"

using namespace gm;

namespace {

template <int S>
void check_so3_order(double T, const std::vector<int>& ns, const M3& qr, const V3& pr) {
  BOOST_TEST_CONTEXT("s=" << S) {
    const double p = fitted_order<HeavyTop, S>(top(), T, ns, body_point(), body_momentum(), qr, pr);
    BOOST_TEST(std::fabs(p - 2 * S) <= 0.3);
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(so3_orders_are_2s_for_s_1_to_4) {
  const double T = 2.0;
  const SO3Map map(RetractionKind::exp, 0.5, "so3-exp");
  M3 qr = body_point(), qc = qr;
  V3 pr = body_momentum(), pc = pr;
  reference(top(), map, T, 800, qr, pr);
  reference(top(), map, T, 1600, qc, pc);
  const double ref_err = std::fmax(SO3::distance(qr, qc), max_abs(V3(pr - pc)));
  BOOST_TEST_MESSAGE("reference (kahan-li8, 800 vs 1600 steps) agrees to " << ref_err);
  BOOST_TEST(ref_err <= 1e-13);
  check_so3_order<1>(T, {40, 57, 80, 113, 160, 226, 320}, qr, pr);
  check_so3_order<2>(T, {20, 28, 40, 57, 80, 113, 160}, qr, pr);
  // s = 3 and 4 from h = 0.2 and 0.25 down (local slopes 6.5 and 8.2 there, 9.1 for
  // s = 4 at h = 0.33)
  check_so3_order<3>(T, {10, 13, 16, 20, 25, 32, 40}, qr, pr);
  check_so3_order<4>(T, {8, 9, 10, 11, 13, 14, 16}, qr, pr);
}

BOOST_AUTO_TEST_CASE(so3_action_gradient_is_that_of_the_action) {
  auto check = [](auto stages, QuadratureKind kind) {
    constexpr int S = decltype(stages)::value;
    const ManifoldGalerkinStep<HeavyTop> G(top(), kind, S, 0.3);
    const double d = gradient_against_jets<S>(G, body_point());
    BOOST_TEST_MESSAGE("s=" << S << ": relative difference " << d);
    BOOST_TEST(d <= 1e-13, "s=" << S);
  };
  check(std::integral_constant<int, 1>(), QuadratureKind::gauss);
  check(std::integral_constant<int, 2>(), QuadratureKind::lobatto);
  check(std::integral_constant<int, 4>(), QuadratureKind::gauss);
}

BOOST_AUTO_TEST_CASE(so3_generating_step_is_symplectic_and_the_chart_step_is_not) {
  const M3 c = body_point();
  const V3 e0(0.05, -0.03, 0.02);
  const double h = 0.2;
  auto check = [&](auto stages) {
    constexpr int S = decltype(stages)::value;
    const ManifoldGalerkinStep<HeavyTop> E(top(), QuadratureKind::gauss, S, h);
    const ChartGalerkinStep<HeavyTop, S> G(top(), QuadratureKind::gauss, S, h);
    const double de = defect_in_chart(E, c, e0, body_momentum());
    const double dg = defect_in_chart(G, c, e0, body_momentum());
    BOOST_TEST_MESSAGE("heavy top s=" << S << " h=" << h << ": symplecticity defect in a fixed chart, generating "
                                      << "function " << de << ", chart step " << dg);
    BOOST_TEST(de <= 1e-9);
    BOOST_TEST(dg >= 1e-6);
    V3 xi = V3::Zero(), p1;
    M3 q1;
    BOOST_REQUIRE(G.step(0.0, c, body_momentum(), xi, q1, p1).converged);
    const double dc = symplectic_defect<3>(G.chart_jacobian(c, body_momentum()));
    BOOST_TEST_MESSAGE("heavy top s=" << S << ": chart step in its own chart, defect " << dc);
    BOOST_TEST(dc <= 1e-13);
  };
  check(std::integral_constant<int, 1>{});
  check(std::integral_constant<int, 2>{});
}

BOOST_AUTO_TEST_CASE(rigid_body_spatial_momentum_is_conserved_by_the_generating_step_only) {
  const double h = 0.05;
  const int n = 2000;
  const V3 m0 = RigidBody::spatial_momentum(body_point(), body_momentum());
  const ManifoldGalerkinStep<RigidBody> E(body(), QuadratureKind::gauss, 2, h);
  const ChartGalerkinStep<RigidBody, 2> G(body(), QuadratureKind::gauss, 2, h);
  M3 q = body_point(), qg = q;
  V3 p = body_momentum(), pg = p;
  BOOST_REQUIRE(run(E, body(), q, p, n));
  BOOST_REQUIRE(run(G, body(), qg, pg, n));
  const double me = max_abs(V3(RigidBody::spatial_momentum(q, p) - m0));
  const double mg = max_abs(V3(RigidBody::spatial_momentum(qg, pg) - m0));
  BOOST_TEST_MESSAGE("spatial angular momentum error after " << n << " steps of h = " << h
                                                             << " (s = 2): generating function " << me
                                                             << ", chart step " << mg);
  BOOST_TEST(me <= 1e-12);  // round-off, about 1e-16 a step
  BOOST_TEST(mg >= 1e-9);
}

BOOST_AUTO_TEST_CASE(heavy_top_energy_error_is_bounded_over_a_long_run) {
  const double h = 0.05;
  const int N = 40000;
  const ManifoldGalerkinStep<HeavyTop> E(top(), QuadratureKind::gauss, 2, h);
  M3 q = body_point();
  V3 p = body_momentum();
  auto energy = [&](const M3& x, const V3& y) {
    return manifold_energy(top(), x, manifold_legendre_inverse(top(), x, y));
  };
  const double E0 = energy(q, p), J0 = HeavyTop::vertical_momentum(q, p);
  double emax[4] = {0, 0, 0, 0}, jmax = 0.0, defect = 0.0;
  const RunSummary r = integrate(E, 0.0, q, p, manifold_legendre_inverse(top(), q, p), N,
                                          [&](std::int64_t k, double, const M3& x, const V3& y, const StepSummary&) {
                                            const int b = static_cast<int>((k - 1) * 4 / N);
                                            emax[b] = std::fmax(emax[b], std::fabs(energy(x, y) - E0));
                                            jmax = std::fmax(jmax, std::fabs(HeavyTop::vertical_momentum(x, y) - J0));
                                            defect = std::fmax(defect, SO3::point_defect(x));
                                          });
  BOOST_REQUIRE(!r.failed);
  BOOST_TEST_MESSAGE("heavy top energy error by quarter of " << N << " steps: " << emax[0] << " " << emax[1] << " "
                                                             << emax[2] << " " << emax[3] << "; vertical momentum "
                                                             << jmax << "; largest orthogonality defect " << defect);
  BOOST_TEST(emax[0] <= 1e-4);
  BOOST_TEST(emax[3] <= 1.5 * emax[0]);
  BOOST_TEST(jmax <= 2e-11);  // round-off over 40000 steps, about 5e-16 a step
  BOOST_TEST(defect <= 1e-14);
}
