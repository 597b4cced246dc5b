// The map R_d^L = (FL^{-1}, FL^{-1}) o R_d^{T*} o TFL on TQ induced by a map on Q and a
// regular Lagrangian (paper Prop. 5.3, Cor. 5.4, Eq. 5.2): it is a discretization map,
// it is the tangent lift of the midpoint map exactly when the mass matrix is constant,
// and the Lagrangian method it defines is the Hamiltonian method of the cotangent lift
// seen through the Legendre map, on the double pendulum (mass matrix depending on q).
#define BOOST_TEST_MODULE legendre_lift
#include <boost/test/unit_test.hpp>

#include <random>

#include "mechanics/legendre_lift.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/sode_step.h"

using namespace dvm;
using V2 = Vec<double, 2>;
using V4 = Vec<double, 4>;

namespace {

const DoublePendulum kPendulum2(1.0, 0.7, 1.2, 0.9, 9.81);

struct Samples {
  std::mt19937 rng{53};
  template <int N>
  Vec<double, N> draw(double a) {
    std::uniform_real_distribution<double> U(-a, a);
    Vec<double, N> x;
    for (int i = 0; i < N; ++i) x[i] = U(rng);
    return x;
  }
};

}  // namespace

BOOST_AUTO_TEST_CASE(legendre_lift_is_a_discretization_map) {
  // Prop. 5.3 (b): R^L(X, 0) = (X, X), d/dW (R^L_2 - R^L_1)(X, 0) = Id (Def. 2.2), and the
  // inverse undoes the map, for a non-symmetric and a symmetric theta map.
  Samples rnd;
  for (double theta : {0.3, 0.5}) {
    const LegendreLiftedMap<DoublePendulum, ThetaMap> R(kPendulum2, ThetaMap(theta));
    double zero = 0.0, ident = 0.0, trip = 0.0;
    for (int k = 0; k < 8; ++k) {
      const V4 X = rnd.draw<4>(1.0), W = rnd.draw<4>(0.3);
      const auto z = R(X, V4(V4::Zero()));
      zero = std::fmax(zero, std::fmax(max_abs(V4(z.q0 - X)), max_abs(V4(z.q1 - X))));
      Mat<double, 8, 8> J;
      map_with_jacobian(R, X, V4(V4::Zero()), J);
      const Mat<double, 4, 4> D = J.block<4, 4>(4, 4) - J.block<4, 4>(0, 4);
      ident = std::fmax(ident, max_abs(Mat<double, 4, 4>(D - Mat<double, 4, 4>::Identity())));
      const auto r = R(X, W);
      const auto t = R.inverse(r.q0, r.q1);
      trip = std::fmax(trip, std::fmax(max_abs(V4(t.x - X)), max_abs(V4(t.v - W))));
    }
    BOOST_TEST_CONTEXT("theta " << theta) {
      BOOST_TEST(zero <= 1e-14);
      BOOST_TEST(ident <= 1e-13);
      BOOST_TEST(trip <= 1e-13);
    }
  }
}

BOOST_AUTO_TEST_CASE(legendre_lift_is_the_tangent_lift_only_for_constant_mass_and_the_midpoint) {
  // Cor. 5.4: L = m l^2 v^2 / 2 + m g l cos q (constant mass m l^2) with the midpoint map:
  // R^L = R^T. With theta = 0.3 the cotangent lift puts the momenta's weights the other
  // way round, (p - (1 - theta) pdot, p + theta pdot), so R^L differs from R^T; with the
  // double pendulum's mass matrix M(q) it differs even for the midpoint.
  Samples rnd;
  const Pendulum P(2.0, 1.5, 9.81);
  double mid = 0.0, theta = 0.0, coupled = 0.0;
  for (int k = 0; k < 8; ++k) {
    const V2 X = rnd.draw<2>(1.0), W = rnd.draw<2>(0.5);
    auto gap = [&](const auto& a, const auto& b) { return std::fmax(max_abs(V2(a.q0 - b.q0)), max_abs(V2(a.q1 - b.q1))); };
    mid = std::fmax(mid, gap(LegendreLiftedMap<Pendulum, ThetaMap>(P, ThetaMap::midpoint())(X, W),
                             tangent_lift(ThetaMap::midpoint())(X, W)));
    theta = std::fmax(theta, gap(LegendreLiftedMap<Pendulum, ThetaMap>(P, ThetaMap(0.3))(X, W),
                                 tangent_lift(ThetaMap(0.3))(X, W)));
    const V4 Y = rnd.draw<4>(1.0), U = rnd.draw<4>(0.5);
    const auto a = LegendreLiftedMap<DoublePendulum, ThetaMap>(kPendulum2, ThetaMap::midpoint())(Y, U);
    const auto b = tangent_lift(ThetaMap::midpoint())(Y, U);
    coupled = std::fmax(coupled, std::fmax(max_abs(V4(a.q0 - b.q0)), max_abs(V4(a.q1 - b.q1))));
  }
  BOOST_TEST(mid <= 1e-14);
  BOOST_TEST(theta > 1e-2);
  BOOST_TEST(coupled > 1e-2);
}

BOOST_AUTO_TEST_CASE(lagrangian_method_of_the_legendre_lift_is_the_hamiltonian_method) {
  // Prop. 5.3 (a) and Eq. 5.2: the Lagrangian method of R^L (sode2: W = h Gamma_L(X),
  // (X, W) = (R^L)^{-1}(Y0, Y1)), solved by Newton in (q, v), and the Hamiltonian method of
  // Eq. 5.1 for the cotangent lift of R_d with H the Legendre transform of L, solved in
  // (q, p), give the same trajectory through p = dL/dv(q, v): 40 steps of the double
  // pendulum, to round-off (both solves stop at residuals near 1e-15).
  const double h = 0.02;
  for (double theta : {0.3, 0.5}) {
    const ThetaMap R(theta);
    using Lift = LegendreLiftedMap<DoublePendulum, ThetaMap>;
    const SodeStep<DoublePendulum, Lift> Lag(kPendulum2, Lift(kPendulum2, R), h, SodeForm::sode2);
    const HamiltonianStep<LegendreHamiltonian<DoublePendulum>, ThetaMap> Ham(LegendreHamiltonian<DoublePendulum>(kPendulum2),
                                                                             R, h);
    V2 q(0.9, -0.4), v(0.3, 1.1);
    V2 Q = q, P = legendre(kPendulum2, q, v);
    double dq_max = 0.0, dp_max = 0.0, p_size = 0.0;
    for (int k = 0; k < 40; ++k) {
      V2 dq = h * v, dv = V2::Zero();
      BOOST_REQUIRE(Lag.step_qv(0.0, q, v, dq, dv).converged);
      q += dq;
      v += dv;
      V2 dQ = dq, dP = V2::Zero();
      BOOST_REQUIRE(Ham.step(0.0, Q, P, dQ, dP).converged);
      Q += dQ;
      P += dP;
      const V2 p = legendre(kPendulum2, q, v);
      dq_max = std::fmax(dq_max, max_abs(V2(q - Q)));
      dp_max = std::fmax(dp_max, max_abs(V2(p - P)));
      p_size = std::fmax(p_size, max_abs(P));
    }
    BOOST_TEST_MESSAGE("theta " << theta << ": |q - Q| " << dq_max << ", |FL(q, v) - P| " << dp_max << " (|P| "
                                << p_size << ")");
    BOOST_TEST_CONTEXT("theta " << theta) {
      BOOST_TEST(dq_max <= 1e-13);
      BOOST_TEST(dp_max <= 1e-13 * p_size);
    }
  }
}
