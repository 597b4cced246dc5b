// Long-time behaviour: quadratic invariants kept to round-off by the midpoint map,
// angular momentum kept by every rotation-invariant discrete Lagrangian (discrete
// Noether), and a control showing the checks can fail.
#include <boost/test/unit_test.hpp>

#include "tests/verification/common.h"

using namespace dvm;
using namespace dvm::verification;

BOOST_AUTO_TEST_CASE(midpoint_keeps_harmonic_energy_to_round_off) {
  // The midpoint rule conserves quadratic invariants exactly; the energy of the
  // harmonic oscillator drifts only by round-off over 10^5 steps.
  const HarmonicOscillator L(1.0);
  const PositionMomentumStep<HarmonicOscillator, ThetaMap> S(L, ThetaMap::midpoint(), 0.1);
  Vec<double, 1> q(1.0), p(0.5);
  const double E0 = 0.5 * (p[0] * p[0] + q[0] * q[0]);
  double worst = 0;
  const RunSummary r = integrate(S, 0.0, q, p, p, 100000, [&](std::int64_t, double, const auto& qk, const auto& pk, const auto&) {
    worst = std::fmax(worst, std::fabs(0.5 * (pk[0] * pk[0] + qk[0] * qk[0]) - E0));
  });
  BOOST_TEST(!r.failed);
  BOOST_TEST_MESSAGE("harmonic midpoint, 1e5 steps: max |E - E0| = " << worst);
  BOOST_TEST(worst <= 1e-13);
}

BOOST_AUTO_TEST_CASE(symplectic_euler_energy_is_bounded_not_conserved) {
  // Control: explicit Euler's map is symplectic but not energy-conserving; its energy
  // error is O(h) and oscillates without drift.
  const HarmonicOscillator L(1.0);
  const PositionMomentumStep<HarmonicOscillator, ThetaMap> S(L, ThetaMap::explicit_euler(), 0.1);
  Vec<double, 1> q(1.0), p(0.5);
  const double E0 = 0.5 * (p[0] * p[0] + q[0] * q[0]);
  double first = 0, second = 0;
  const std::int64_t n = 100000;
  integrate(S, 0.0, q, p, p, n, [&](std::int64_t k, double, const auto& qk, const auto& pk, const auto&) {
    const double e = std::fabs(0.5 * (pk[0] * pk[0] + qk[0] * qk[0]) - E0);
    (k <= n / 2 ? first : second) = std::fmax(k <= n / 2 ? first : second, e);
  });
  BOOST_TEST(first > 1e-3);                     // the check would see a non-conserving method
  BOOST_TEST(std::fabs(second - first) <= 1e-3 * first);  // and no drift
}

BOOST_AUTO_TEST_CASE(angular_momentum_is_kept_by_every_theta_map) {
  // L_d of the theta maps is invariant under rotations of the plane, so the discrete
  // momentum map q x p is conserved exactly (to round-off), whatever the order.
  Vec<double, 2> q0, p0;
  kepler_initial(0.6, q0, p0);
  const double L0 = Kepler::angular_momentum(q0, p0);
  for (double theta : {0.5, 0.0, 0.3, 1.0}) {
    const PositionMomentumStep<Kepler, ThetaMap> S(Kepler(), ThetaMap(theta), 0.01);
    Vec<double, 2> q = q0, p = p0;
    double worst = 0;
    const RunSummary r = integrate(S, 0.0, q, p, p0, 100000, [&](std::int64_t, double, const auto& qk, const auto& pk, const auto&) {
      worst = std::fmax(worst, std::fabs(Kepler::angular_momentum(qk, pk) - L0));
    });
    BOOST_TEST(!r.failed);
    BOOST_TEST_MESSAGE("kepler theta=" << theta << ", 1e5 steps: max |L - L0| = " << worst);
    BOOST_TEST(worst <= 1e-14, "theta " << theta << ": " << worst);
  }
}
