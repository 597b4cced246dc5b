// The classic built-in systems (mechanics/systems_classic.h): their closed-form
// derivatives and velocities against automatic differentiation, their exact solutions
// against the equations of motion, and the adiabatic invariant of the FPU chain.
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <cstdint>
#include <random>
#include <type_traits>

#include "mechanics/hamiltonian.h"
#include "mechanics/systems_classic.h"
#include "tests/verification/common.h"

using namespace dvm;

BOOST_AUTO_TEST_CASE(classic_systems_closed_forms_match_autodiff) {
  auto check = [](const auto& S, double shift) {
    using Sys = std::decay_t<decltype(S)>;
    constexpr int N = Sys::dim;
    const GenericOnly<Sys> G{S};
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    for (int s = 0; s < 5; ++s) {
      Vec<double, N> q, v;
      for (int i = 0; i < N; ++i) {
        q[i] = U(rng) + shift * i;
        v[i] = U(rng);
      }
      Vec<double, N> a1, b1, a2, b2;
      lagrangian_gradient(S, q, v, a1, b1);
      lagrangian_gradient(G, q, v, a2, b2);
      BOOST_TEST(max_abs(a1 - a2) <= 1e-13 * std::fmax(1.0, max_abs(a2)), S.name());
      BOOST_TEST(max_abs(b1 - b2) <= 1e-13 * std::fmax(1.0, max_abs(b2)), S.name());
      const Vec<double, N> p = legendre(S, q, v);
      BOOST_TEST(max_abs(S.velocity(q, p) - v) <= 1e-13, S.name());
      BOOST_TEST(max_abs(legendre_inverse(G, q, p) - v) <= 1e-12, S.name());
    }
  };
  check(DoublePendulum(1.0, 2.0, 1.5, 0.5, 9.8), 0.0);
  check(HenonHeiles(1.0), 0.0);
  check(FermiPastaUlam(50.0), 0.0);
  check(Duffing(1.0, 2.0), 0.0);
  check(ChargedParticle(2.0, -1.5, 0.8, 0.3), 0.0);
  check(NBody<3>(1.5, {1.0, 0.5, 0.25}), 1.0);  // bodies kept apart by the shift
}

// The exact solutions satisfy Hamilton's equations (central differences in t) and
// keep the energy (and, for the charged particle, the angular momentum).
BOOST_AUTO_TEST_CASE(exact_solutions_solve_the_equations) {
  auto check = [](const auto& S, const auto& q0, const auto& p0) {
    using Sys = std::decay_t<decltype(S)>;
    constexpr int N = Sys::dim;
    using V = Vec<double, N>;
    const double E0 = energy(S, q0, S.velocity(q0, p0));
    for (double t : {0.0, 0.3, 1.7, 5.2, 23.9}) {
      const double d = 1e-4;
      V q, p, qa, pa, qb, pb;
      S.exact(t, q0, p0, q, p);
      S.exact(t + d, q0, p0, qa, pa);
      S.exact(t - d, q0, p0, qb, pb);
      const V v = S.velocity(q, p);
      V dLdq, dLdv;
      lagrangian_gradient(S, q, v, dLdq, dLdv);
      BOOST_TEST(max_abs((qa - qb) / (2 * d) - v) <= 1e-7, S.name() << " t=" << t);
      BOOST_TEST(max_abs((pa - pb) / (2 * d) - dLdq) <= 1e-7, S.name() << " t=" << t);
      BOOST_TEST(std::fabs(energy(S, q, v) - E0) <= 1e-13 * std::fmax(1.0, std::fabs(E0)), S.name());
      if (t == 0.0) BOOST_TEST(max_abs(q - q0) + max_abs(p - p0) <= 1e-14, S.name());
    }
  };
  check(Duffing(1.0, 2.0), Vec<double, 1>(1.2), Vec<double, 1>(0.0));
  check(Duffing(1.0, 2.0), Vec<double, 1>(-0.3), Vec<double, 1>(0.9));
  check(Duffing(0.5, 0.0), Vec<double, 1>(0.4), Vec<double, 1>(-0.2));
  check(ChargedParticle(1.0, 1.0, 2.0, 0.0), Vec<double, 2>(1.0, 0.0), Vec<double, 2>(0.0, 1.0));
  check(ChargedParticle(2.0, -1.5, 0.8, 0.3), Vec<double, 2>(0.5, -0.2), Vec<double, 2>(0.1, 0.7));
  // Duffing's period 4K/w: one full period returns the start
  const Duffing D(1.0, 2.0);
  const double A = 1.2, w = std::sqrt(1.0 + 2.0 * A * A), k = std::sqrt(2.0 * A * A / (2 * w * w));
  const double K = detail::carlson_rf(0.0, 1.0 - k * k, 1.0);
  Vec<double, 1> q, p;
  D.exact(4.0 * K / w, Vec<double, 1>(A), Vec<double, 1>(0.0), q, p);
  BOOST_TEST(std::fabs(q[0] - A) <= 1e-13);
  BOOST_TEST(std::fabs(p[0]) <= 1e-12);
}

BOOST_AUTO_TEST_CASE(fpu_oscillatory_energy_is_an_adiabatic_invariant) {
  // GNI Sec. I.5.1: initial x_{0,1} = 1, y_{0,1} = 1, x_{1,1} = 1/omega, y_{1,1} = 1,
  // so I(0) = 1. The total oscillatory energy stays within O(1/omega) of its start
  // while energy flows between the stiff springs: doubling omega halves the deviation.
  auto deviation = [](double w) {
    const FermiPastaUlam F(w);
    Vec<double, 6> q = Vec<double, 6>::Zero(), p = Vec<double, 6>::Zero();
    const double s = std::sqrt(0.5);
    q[0] = s * (1.0 - 1.0 / w);
    q[1] = s * (1.0 + 1.0 / w);
    p[1] = std::sqrt(2.0);
    const double I0 = F.oscillatory_energy(q, p);
    BOOST_TEST(std::fabs(I0 - 1.0) <= 1e-14);
    const double h = 0.1 / w;  // omega h = 0.1
    const PositionMomentumStep<FermiPastaUlam, ThetaMap> S(F, ThetaMap::midpoint(), h);
    double maxdev = 0.0;
    const auto r = integrate(S, 0.0, q, p, p, static_cast<std::int64_t>(std::llround(20.0 / h)),
                             [&](std::int64_t, double, const auto& qk, const auto& pk, const auto&) {
                               maxdev = std::fmax(maxdev, std::fabs(F.oscillatory_energy(qk, pk) - I0));
                             });
    BOOST_REQUIRE(!r.failed);
    return maxdev;
  };
  const double d50 = deviation(50.0), d100 = deviation(100.0);
  BOOST_TEST_MESSAGE("FPU max |I - I0| to t = 20: omega 50: " << d50 << ", omega 100: " << d100);
  BOOST_TEST(d50 < 0.1);
  BOOST_TEST(d50 > 1e-3);  // not an exact invariant
  BOOST_TEST(d50 / d100 > 1.6);
  BOOST_TEST(d50 / d100 < 2.5);
}
