// Hamiltonians, the Legendre transform with its regularity check, and the Hamiltonian
// step of Eq. 5.1: closed-form special cases, measured symplecticity (and a method
// that must fail the measurement), discrete Noether for Kepler, and the partitioned
// Runge-Kutta methods composed from theta-map steps (Sec. 6.2).
#define BOOST_TEST_MODULE hamiltonian
#include <boost/test/unit_test.hpp>

#include "mechanics/hamiltonian.h"
#include "mechanics/systems.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/integrate.h"
#include "solvers/partitioned_dirk.h"
#include "solvers/position_momentum_step.h"
#include "solvers/runtime/run.h"

using namespace dvm;
using V1 = Vec<double, 1>;
using V2 = Vec<double, 2>;

namespace {

// A Lagrangian with no closed forms, nonlinear in v: the Legendre map is inverted by
// Newton. d2L/dv2 = 1 + v^2 > 0, so it is regular everywhere.
struct QuarticKinetic {
  static constexpr int dim = 1;
  std::string name() const { return "quartic-kinetic"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    return 0.5 * v[0] * v[0] + v[0] * v[0] * v[0] * v[0] / 12.0 - 0.5 * q[0] * q[0];
  }
};

// Degenerate: L = v1 q2 - q1 v2 - (q1^2 + q2^2)/2 is linear in v (d2L/dv2 = 0).
struct LinearInVelocity {
  static constexpr int dim = 2;
  std::string name() const { return "linear-in-velocity"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    return v[0] * q[1] - q[0] * v[1] - 0.5 * (q[0] * q[0] + q[1] * q[1]);
  }
};

// Degenerate in one direction only: L = v1^2/2 + q1 v2 (d2L/dv2 = diag(1, 0)).
struct HalfDegenerate {
  static constexpr int dim = 2;
  std::string name() const { return "half-degenerate"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    return 0.5 * v[0] * v[0] + q[0] * v[1];
  }
};

// A non-separable Hamiltonian: H = p^2 (1 + q^2)/2 + q^4/4 - q^2/2.
struct NonSeparable {
  static constexpr int dim = 1;
  std::string name() const { return "non-separable"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& p) const {
    return 0.5 * p[0] * p[0] * (1.0 + q[0] * q[0]) + 0.25 * q[0] * q[0] * q[0] * q[0] - 0.5 * q[0] * q[0];
  }
};

using PendulumH = LegendreHamiltonian<Pendulum>;
using KeplerH = LegendreHamiltonian<Kepler>;

}  // namespace

BOOST_AUTO_TEST_CASE(legendre_hamiltonians_match_closed_forms) {
  // harmonic: H = p^2/2 + w^2 q^2/2;  pendulum: H = p^2/(2 m l^2) - m g l cos q;
  // Kepler: H = |p|^2/2 - mu/|q|.
  const LegendreHamiltonian<HarmonicOscillator> Hh(HarmonicOscillator(1.5));
  const PendulumH Hp(Pendulum(2.0, 0.5, 9.81));
  const KeplerH Hk(Kepler(1.3));
  BOOST_TEST(std::fabs(Hh(V1(0.3), V1(-0.7)) - (0.5 * 0.49 + 0.5 * 2.25 * 0.09)) <= 1e-15);
  BOOST_TEST(std::fabs(Hp(V1(0.3), V1(-0.7)) - (0.49 / (2 * 2.0 * 0.25) - 2.0 * 9.81 * 0.5 * std::cos(0.3))) <= 1e-14);
  BOOST_TEST(std::fabs(Hk(V2(0.6, -0.8), V2(0.1, 1.2)) - (0.5 * 1.45 - 1.3)) <= 1e-15);
  // gradients through Jets (the scalar-generic path): X_H of the pendulum
  V1 qd, pd;
  hamiltonian_vector_field(Hp, V1(0.3), V1(-0.7), qd, pd);
  BOOST_TEST(std::fabs(qd[0] - (-0.7 / 0.5)) <= 1e-14);
  BOOST_TEST(std::fabs(pd[0] + 2.0 * 9.81 * 0.5 * std::sin(0.3)) <= 1e-14);
}

BOOST_AUTO_TEST_CASE(hamiltonian_of_a_lagrangian_without_closed_forms) {
  // For any regular L: dH/dp = v and dH/dq = -dL/dq at v = FL^{-1}(q, p).
  const QuarticKinetic L;
  const LegendreHamiltonian<QuarticKinetic> H(L);
  for (double q : {-0.8, 0.1, 1.3})
    for (double p : {-2.0, 0.0, 0.4, 3.0}) {
      const V1 v = legendre_inverse_checked(L, V1(q), V1(p));
      BOOST_TEST(std::fabs(v[0] + v[0] * v[0] * v[0] / 3.0 - p) <= 1e-14 * std::fmax(1.0, std::fabs(p)));
      BOOST_TEST(std::fabs(legendre_checked(L, V1(q), v)[0] - p) <= 1e-14 * std::fmax(1.0, std::fabs(p)));
      V1 dHdq, dHdp;
      hamiltonian_gradient(H, V1(q), V1(p), dHdq, dHdp);
      BOOST_TEST(std::fabs(dHdp[0] - v[0]) <= 1e-14);
      BOOST_TEST(std::fabs(dHdq[0] - q) <= 1e-14);
      // second derivative through the nested Jet: d2H/dp2 = 1 / (d2L/dv2) = 1/(1 + v^2)
      using D = ceres::Jet<double, 1>;
      Vec<D, 1> qq, pp;
      qq[0] = D(q);
      pp[0] = D(p, 0);
      Vec<D, 1> gq, gp;
      hamiltonian_gradient(H, qq, pp, gq, gp);
      BOOST_TEST(std::fabs(gp[0].v[0] - 1.0 / (1.0 + v[0] * v[0])) <= 1e-13);
    }
}

BOOST_AUTO_TEST_CASE(singular_lagrangians_are_rejected_with_a_clear_message) {
  auto check = [](auto L, int dim) {
    using S = decltype(L);
    const Vec<double, S::dim> q = Vec<double, S::dim>::Constant(0.3), p = Vec<double, S::dim>::Constant(0.2);
    BOOST_TEST(velocity_hessian_rcond(L, q, p) <= 1e-12);
    try {
      legendre_inverse_checked(L, q, p);
      BOOST_FAIL("a degenerate Lagrangian was accepted");
    } catch (const DegenerateLagrangianError& e) {
      const std::string msg = e.what();
      BOOST_TEST(msg.find(L.name()) != std::string::npos, msg);
      BOOST_TEST(msg.find("singular") != std::string::npos, msg);
    }
    const LegendreHamiltonian<S> H(L);
    BOOST_CHECK_THROW(H(q, p), DegenerateLagrangianError);
    // and through Jets, as the Hamiltonian step evaluates H (the check runs once per
    // evaluation, on the Hessian the Jet sweeps use)
    Vec<double, S::dim> fq, fp;
    BOOST_CHECK_THROW(hamiltonian_vector_field(H, q, p, fq, fp), DegenerateLagrangianError);
    BOOST_CHECK_THROW(legendre_checked(L, q, p), DegenerateLagrangianError);
    (void)dim;
  };
  check(LinearInVelocity{}, 2);
  check(HalfDegenerate{}, 2);
  // and a regular one passes, with a condition number that is sane
  BOOST_TEST(velocity_hessian_rcond(Kepler(1.0), V2(1, 0), V2(0, 1)) == 1.0);
}

BOOST_AUTO_TEST_CASE(midpoint_map_gives_the_implicit_midpoint_rule) {
  // Harmonic oscillator: the implicit midpoint rule is the Cayley transform.
  const double w = 2.0, h = 0.1;
  const HamiltonianStep<LegendreHamiltonian<HarmonicOscillator>, ThetaMap> S(
      LegendreHamiltonian<HarmonicOscillator>(HarmonicOscillator(w)), ThetaMap::midpoint(), h);
  Mat<double, 2, 2> A;
  A << 0, 1, -w * w, 0;
  const Mat<double, 2, 2> I = Mat<double, 2, 2>::Identity();
  const Mat<double, 2, 2> C = (I - 0.5 * h * A).inverse() * (I + 0.5 * h * A);
  V1 dq = V1::Zero(), dp = V1::Zero();
  const StepSummary s = S.step(0.0, V1(0.7), V1(-0.3), dq, dp);
  BOOST_TEST(s.converged);
  const V2 z1 = C * V2(0.7, -0.3);
  BOOST_TEST(std::fabs(0.7 + dq[0] - z1[0]) <= 1e-15);
  BOOST_TEST(std::fabs(-0.3 + dp[0] - z1[1]) <= 1e-15);

  // Non-separable H: the result satisfies the midpoint equations themselves.
  const NonSeparable H;
  const HamiltonianStep<NonSeparable, ThetaMap> M(H, ThetaMap::midpoint(), 0.2);
  const V1 q0(0.4), p0(0.9);
  dq.setZero();
  dp.setZero();
  BOOST_TEST(M.step(0.0, q0, p0, dq, dp).converged);
  V1 fq, fp;
  hamiltonian_vector_field(H, V1(q0 + 0.5 * dq), V1(p0 + 0.5 * dp), fq, fp);
  BOOST_TEST(std::fabs(dq[0] - 0.2 * fq[0]) <= 1e-15);
  BOOST_TEST(std::fabs(dp[0] - 0.2 * fp[0]) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(map_q_minus_v_q_is_explicit_for_separable_hamiltonians) {
  // R_d(q, v) = (q - v, q): q1 = q0 + h dH/dp(p0), p1 = p0 - h dH/dq(q1).
  const Pendulum P(1.0, 1.0, 1.0);
  const double h = 0.05;
  const HamiltonianStep<PendulumH, ThetaMap> S(PendulumH(P), ThetaMap::adjoint_euler(), h);
  const V1 q0(1.1), p0(0.4);
  V1 dq = V1::Zero(), dp = V1::Zero();
  const StepSummary s = S.step(0.0, q0, p0, dq, dp);
  BOOST_TEST(s.converged);
  const double q1 = q0[0] + h * p0[0];
  BOOST_TEST(std::fabs(q0[0] + dq[0] - q1) <= 1e-15);
  BOOST_TEST(std::fabs(p0[0] + dp[0] - (p0[0] - h * std::sin(q1))) <= 1e-15);
  // explicit: the step Jacobian is triangular, so Newton is exact after resolving the
  // one nonlinear substitution (at most 3 Jacobian evaluations including the check)
  BOOST_TEST(s.iterations <= 3);
}

BOOST_AUTO_TEST_CASE(step_residual_is_the_cotangent_lift_inverse_minus_h_XH) {
  // The step writes (R_d^{T*})^{-1} in increment form (no q1 - q0 cancellation); it
  // must be the generic cotangent_lift_inverse of core/map_operations.h.
  const double h = 0.1;
  const KeplerH K(Kepler(1.0));
  const V2 q0(0.9, 0.6), p0(-0.5, 0.7), dq(0.03, -0.02), dp(0.01, 0.04);
  auto check = [&](const auto& R) {
    using Map = std::decay_t<decltype(R)>;
    const HamiltonianStep<KeplerH, Map> S(K, R, h);
    const Vec<double, 4> F = S.residual(q0, p0, dq, dp);
    const CotangentVelocity<double, 2> c = cotangent_lift_inverse(R, q0, p0, V2(q0 + dq), V2(p0 + dp));
    V2 fq, fp;
    hamiltonian_vector_field(K, c.q, c.p, fq, fp);
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(max_abs(V2(F.head<2>() - (c.qdot - h * fq))) <= 1e-15);
      BOOST_TEST(max_abs(V2(F.tail<2>() - (c.pdot - h * fp))) <= 1e-15);
    }
  };
  check(ThetaMap::midpoint());
  check(ThetaMap(0.3));
  check(RetractionMap<EuclideanRetraction>({}, 0.7));
}

namespace {

template <class Step>
double max_defect(const Step& S, const std::vector<std::pair<Vec<double, Step::N>, Vec<double, Step::N>>>& points) {
  double d = 0.0;
  for (const auto& [q0, p0] : points) {
    Vec<double, Step::N> dq = Vec<double, Step::N>::Zero(), dp = Vec<double, Step::N>::Zero();
    const StepSummary s = S.step(0.0, q0, p0, dq, dp);
    BOOST_REQUIRE(s.converged);
    d = std::fmax(d, symplectic_defect<Step::N>(S.jacobian(q0, p0, dq, dp)));
  }
  return d;
}

}  // namespace

BOOST_AUTO_TEST_CASE(hamiltonian_steps_are_symplectic_to_round_off) {
  const double h = 0.1;
  const std::vector<std::pair<V1, V1>> pts1 = {{V1(0.3), V1(0.5)}, {V1(2.0), V1(0.0)}, {V1(-1.2), V1(1.4)}};
  const std::vector<std::pair<V2, V2>> pts2 = {{V2(0.4, 0.0), V2(0.0, 2.0)}, {V2(0.9, 0.6), V2(-0.5, 0.7)}};
  const PendulumH P(Pendulum(1.0, 1.0, 1.0));
  const KeplerH K(Kepler(1.0));
  const RetractionMap<EuclideanRetraction> retr({}, 0.3);  // generic Newton inverse
  const double tol = 1e-13;
  double d;
  d = max_defect(HamiltonianStep<PendulumH, ThetaMap>(P, ThetaMap::midpoint(), h), pts1);
  BOOST_TEST_MESSAGE("pendulum midpoint defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<PendulumH, ThetaMap>(P, ThetaMap::adjoint_euler(), h), pts1);
  BOOST_TEST_MESSAGE("pendulum adjoint-euler defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<PendulumH, ThetaMap>(P, ThetaMap::explicit_euler(), h), pts1);
  BOOST_TEST_MESSAGE("pendulum explicit-euler defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<PendulumH, ThetaMap>(P, ThetaMap(0.3), h), pts1);
  BOOST_TEST_MESSAGE("pendulum theta 0.3 defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<PendulumH, RetractionMap<EuclideanRetraction>>(P, retr, h), pts1);
  BOOST_TEST_MESSAGE("pendulum retraction-theta 0.3 (Newton inverse) defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<NonSeparable, ThetaMap>(NonSeparable{}, ThetaMap(0.3), h), pts1);
  BOOST_TEST_MESSAGE("non-separable H, theta 0.3 defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<KeplerH, ThetaMap>(K, ThetaMap::midpoint(), 0.05), pts2);
  BOOST_TEST_MESSAGE("kepler midpoint defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<KeplerH, ThetaMap>(K, ThetaMap(0.7), 0.05), pts2);
  BOOST_TEST_MESSAGE("kepler theta 0.7 defect " << d);
  BOOST_TEST(d <= tol);
  d = max_defect(HamiltonianStep<KeplerH, RetractionMap<EuclideanRetraction>>(K, retr, 0.05), pts2);
  BOOST_TEST_MESSAGE("kepler retraction-theta 0.3 defect " << d);
  BOOST_TEST(d <= tol);
  // the trapezoidal counter-example on Kepler
  d = max_defect(HamiltonianStep<KeplerH, ThetaMap>(K, ThetaMap::midpoint(), 0.05, {}, VectorFieldSample::trapezoidal),
                 pts2);
  BOOST_TEST_MESSAGE("kepler trapezoidal defect " << d);
  BOOST_TEST(d >= 1e-5);
}

BOOST_AUTO_TEST_CASE(maps_given_directly_on_the_cotangent_bundle) {
  // Eq. 5.1 with a discretization map on T*Q that is not a cotangent lift: the theta map
  // of R^2 = T*R, i.e. the theta method z1 - z0 = h X_H(z0 + theta (z1 - z0)). Its step
  // solves that equation (checked by evaluating X_H directly); at theta = 1/2 it is the
  // implicit midpoint rule, equal to the cotangent lift of the midpoint map; at 0.3 it is
  // not symplectic (Prop. 5.1 needs a cotangent lift), while the cotangent lift of the
  // same theta map is (above).
  const double h = 0.1;
  const std::vector<std::pair<V1, V1>> pts1 = {{V1(0.3), V1(0.5)}, {V1(2.0), V1(0.0)}, {V1(-1.2), V1(1.4)}};
  const PendulumH P(Pendulum(1.0, 1.0, 1.0));
  using Direct = HamiltonianStep<PendulumH, OnCotangentBundle<ThetaMap>>;
  double worst = 0.0, mid = 0.0;
  for (const auto& [q0, p0] : pts1) {
    const Direct D(P, OnCotangentBundle<ThetaMap>{ThetaMap(0.3)}, h);
    V1 dq = V1::Zero(), dp = V1::Zero();
    BOOST_REQUIRE(D.step(0.0, q0, p0, dq, dp).converged);
    V1 fq, fp;
    hamiltonian_vector_field(P, V1(q0 + 0.3 * dq), V1(p0 + 0.3 * dp), fq, fp);
    worst = std::fmax(worst, std::fmax(std::fabs(dq[0] - h * fq[0]), std::fabs(dp[0] - h * fp[0])));
    const Direct M(P, OnCotangentBundle<ThetaMap>{ThetaMap::midpoint()}, h);
    const HamiltonianStep<PendulumH, ThetaMap> C(P, ThetaMap::midpoint(), h);
    V1 a = V1::Zero(), b = V1::Zero(), c = V1::Zero(), d = V1::Zero();
    BOOST_REQUIRE(M.step(0.0, q0, p0, a, b).converged);
    BOOST_REQUIRE(C.step(0.0, q0, p0, c, d).converged);
    mid = std::fmax(mid, std::fmax(std::fabs(a[0] - c[0]), std::fabs(b[0] - d[0])));
  }
  BOOST_TEST(worst <= 1e-15);
  BOOST_TEST(mid <= 1e-15);
  const double d_theta = max_defect(Direct(P, OnCotangentBundle<ThetaMap>{ThetaMap(0.3)}, h), pts1);
  const double d_mid = max_defect(Direct(P, OnCotangentBundle<ThetaMap>{ThetaMap::midpoint()}, h), pts1);
  BOOST_TEST_MESSAGE("theta method on T*Q: symplectic defect " << d_theta << " at theta 0.3, " << d_mid << " at 1/2");
  BOOST_TEST(d_theta >= 1e-3);
  BOOST_TEST(d_mid <= 1e-13);
}

BOOST_AUTO_TEST_CASE(trapezoidal_averaging_is_not_symplectic) {
  // The same midpoint map with X_H averaged over the end points: the trapezoidal rule.
  // Its defect is O(h^3) for a non-quadratic H; at h = 0.1 it is far above round-off.
  const double h = 0.1;
  const std::vector<std::pair<V1, V1>> pts1 = {{V1(0.3), V1(0.5)}, {V1(2.0), V1(0.0)}, {V1(-1.2), V1(1.4)}};
  const PendulumH P(Pendulum(1.0, 1.0, 1.0));
  const HamiltonianStep<PendulumH, ThetaMap> T(P, ThetaMap::midpoint(), h, {}, VectorFieldSample::trapezoidal);
  const double d = max_defect(T, pts1);
  BOOST_TEST_MESSAGE("pendulum trapezoidal defect " << d);
  BOOST_TEST(d >= 1e-5);
  // and it shrinks like h^3 (a consistent method, so only the structure is missing)
  const HamiltonianStep<PendulumH, ThetaMap> T2(P, ThetaMap::midpoint(), h / 2, {}, VectorFieldSample::trapezoidal);
  const double d2 = max_defect(T2, pts1);
  BOOST_TEST(std::log2(d / d2) >= 2.8);
  BOOST_TEST(std::log2(d / d2) <= 3.2);
  // For a quadratic H the trapezoidal rule coincides with the midpoint rule and is
  // symplectic: the check distinguishes structure, not the averaging as such.
  const LegendreHamiltonian<HarmonicOscillator> Hh(HarmonicOscillator(1.0));
  const HamiltonianStep<LegendreHamiltonian<HarmonicOscillator>, ThetaMap> Th(Hh, ThetaMap::midpoint(), h, {},
                                                                             VectorFieldSample::trapezoidal);
  BOOST_TEST(max_defect(Th, pts1) <= 1e-14);
}

BOOST_AUTO_TEST_CASE(kepler_angular_momentum_is_conserved_by_hamiltonian_steps) {
  // Discrete Noether: every theta map commutes with rotations, so its cotangent lift
  // and the step of Eq. 5.1 preserve q x p.
  const KeplerH K(Kepler(1.0));
  for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap::adjoint_euler(), ThetaMap(0.3)}) {
    const HamiltonianStep<KeplerH, ThetaMap> S(K, R, 0.01);
    V2 q(0.4, 0.0), p(0.0, 2.0);
    const double L0 = Kepler::angular_momentum(q, p);
    double worst = 0.0;
    const RunSummary run = integrate(S, 0.0, q, p, p, 5000, [&](std::int64_t, double, const V2& qk, const V2& pk,
                                                                   const StepSummary&) {
      worst = std::fmax(worst, std::fabs(Kepler::angular_momentum(qk, pk) - L0));
    });
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(!run.failed);
      BOOST_TEST_MESSAGE(R.name() << " max |L - L0| = " << worst);
      BOOST_TEST(worst <= 1e-13);
    }
  }
}

BOOST_AUTO_TEST_CASE(orders_of_hamiltonian_steps) {
  // Error at t = 1 against the exact harmonic flow: midpoint order 2, theta 0.3 order 1.
  const LegendreHamiltonian<HarmonicOscillator> H(HarmonicOscillator(1.0));
  const HarmonicOscillator ho(1.0);
  for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap(0.3)}) {
    std::vector<double> err;
    for (int k = 0; k < 4; ++k) {
      const int n = 10 << k;
      const HamiltonianStep<LegendreHamiltonian<HarmonicOscillator>, ThetaMap> S(H, R, 1.0 / n);
      V1 q(1.0), p(0.5), qe, pe;
      integrate(S, 0.0, q, p, p, n, [](auto&&...) {});
      ho.exact(1.0, V1(1.0), V1(0.5), qe, pe);
      err.push_back(std::fmax(std::fabs(q[0] - qe[0]), std::fabs(p[0] - pe[0])));
    }
    const double order = std::log2(err[2] / err[3]);
    BOOST_TEST_CONTEXT(R.name()) { BOOST_TEST(std::fabs(order - R.order()) <= 0.05); }
  }
}

namespace {

// The one-step Jacobian of the Lagrangian position-momentum step by the implicit
// function theorem: F(q0, p0, dq) = p0 + D1 L_d(q0, q0 + dq) = 0 defines dq, and
// p1 = D2 L_d(q0, q0 + dq).
template <class System, class Map>
double lagrangian_step_defect(const System& L, const Map& R, double h, const Vec<double, System::dim>& q0,
                              const Vec<double, System::dim>& p0) {
  constexpr int N = System::dim, K = 3 * N;
  const PositionMomentumStep<System, Map> S(L, R, h);
  Vec<double, N> dq = Vec<double, N>::Zero(), dp = Vec<double, N>::Zero();
  BOOST_REQUIRE(S.step(0.0, q0, p0, dq, dp).converged);
  using D = ceres::Jet<double, K>;
  Vec<D, N> a, b, c;
  for (int i = 0; i < N; ++i) {
    a[i] = seed<double, K>(q0[i], i);
    b[i] = seed<double, K>(p0[i], N + i);
    c[i] = seed<double, K>(dq[i], 2 * N + i);
  }
  const auto& dl = S.discrete_lagrangian();
  const Vec<D, N> F = b + dl.D1Ld_increment(a, c);
  const Vec<D, N> p1 = dl.D2Ld(a, Vec<D, N>(a + c));
  Mat<double, N, 2 * N> Fy, Py;
  Mat<double, N, N> Fx, Px;
  for (int i = 0; i < N; ++i) {
    Fy.row(i) = F[i].v.template head<2 * N>().transpose();
    Fx.row(i) = F[i].v.template tail<N>().transpose();
    Py.row(i) = p1[i].v.template head<2 * N>().transpose();
    Px.row(i) = p1[i].v.template tail<N>().transpose();
  }
  const Mat<double, N, 2 * N> dxdy = -Fx.partialPivLu().solve(Fy);
  Mat<double, 2 * N, 2 * N> M;
  M.template topRows<N>() = dxdy;
  M.template topLeftCorner<N, N>() += Mat<double, N, N>::Identity();
  M.template bottomRows<N>() = Py + Px * dxdy;
  return symplectic_defect<N>(M);
}

}  // namespace

BOOST_AUTO_TEST_CASE(lagrangian_position_momentum_steps_are_symplectic_too) {
  // The same measurement on the discrete Legendre (position-momentum) step of
  // L_d(q0, q1) = h L(R_d^{-1}(q0, q1)/h), for symmetric and non-symmetric maps.
  const Pendulum P;
  const Kepler K(1.0);
  const RetractionMap<EuclideanRetraction> retr({}, 0.3);
  double d = 0.0;
  for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap(0.3), ThetaMap::adjoint_euler()}) {
    d = std::fmax(d, lagrangian_step_defect(P, R, 0.1, V1(2.0), V1(0.3)));
    d = std::fmax(d, lagrangian_step_defect(K, R, 0.05, V2(0.9, 0.6), V2(-0.5, 0.7)));
  }
  d = std::fmax(d, lagrangian_step_defect(P, retr, 0.1, V1(2.0), V1(0.3)));
  d = std::fmax(d, lagrangian_step_defect(K, retr, 0.05, V2(0.9, 0.6), V2(-0.5, 0.7)));
  BOOST_TEST_MESSAGE("largest defect of the Lagrangian steps: " << d);
  BOOST_TEST(d <= 1e-13);
}

namespace {

// `steps` steps of the partitioned Runge-Kutta method (a, a^, b) on H = NonSeparable,
// solved as such: stage by stage (both tableaux are lower triangular), each stage's
// (K_i, L_i) = (dH/dp, -dH/dq)(Q_i, P_i) by fixed-point iteration to a repeated
// iterate, with Q_i = q0 + h sum_j a_ij K_j and P_i = p0 + h sum_j a^_ij L_j.
std::pair<double, double> prk_non_separable(const PartitionedDirk& m, double h, int steps, double q, double p) {
  const auto a = m.tableau(false), ah = m.tableau(true);
  const std::size_t s = m.weight.size();
  for (int n = 0; n < steps; ++n) {
    std::vector<double> K(s), L(s);
    for (std::size_t i = 0; i < s; ++i) {
      double Q0 = q, P0 = p;
      for (std::size_t j = 0; j < i; ++j) {
        Q0 += h * a[i][j] * K[j];
        P0 += h * ah[i][j] * L[j];
      }
      double k = 0.0, l = 0.0;
      for (int it = 0; it < 500; ++it) {
        const double Q = Q0 + h * a[i][i] * k, P = P0 + h * ah[i][i] * l;
        const double nk = P * (1.0 + Q * Q), nl = -(P * P * Q + Q * Q * Q - Q);
        const bool done = nk == k && nl == l;
        k = nk;
        l = nl;
        if (done) break;
      }
      K[i] = k;
      L[i] = l;
    }
    for (std::size_t i = 0; i < s; ++i) {
      q += h * m.weight[i] * K[i];
      p += h * m.weight[i] * L[i];
    }
  }
  return {q, p};
}

std::pair<double, double> composed_non_separable(const PartitionedDirk& m, double h, int steps, double q, double p) {
  const auto S = partitioned_dirk_step(NonSeparable(), m, h);
  V1 Q(q), P(p);
  BOOST_TEST_REQUIRE(!integrate(S, 0.0, Q, P, P, steps, [](auto&&...) {}).failed);
  return {Q[0], P[0]};
}

}  // namespace

BOOST_AUTO_TEST_CASE(theta_map_compositions_are_symplectic_partitioned_runge_kutta_methods) {
  // Sec. 6.2: a pair of diagonally implicit tableaux with common weights b,
  // a_ij = a^_ij = b_j below the diagonal and a_ii + a^_ii = b_i on it (the symplectic
  // pairs) is the composition of Hamiltonian steps of the theta maps theta_i = a_ii/b_i
  // with sizes b_i h. Compared on a non-separable H over 30 steps, for pairs whose q and
  // p tableaux differ (theta != 1/2), weights that are not palindromes, a negative
  // weight, and the explicit ends theta = 0 and 1.
  const double h = 0.1;
  const int steps = 30;
  const std::vector<double> tj = TripleJump4::gamma();
  struct Case {
    std::vector<double> b, theta;
  };
  for (const Case& c : std::vector<Case>{{tj, {0.3, 0.5, 0.7}},
                                         {{0.3, 0.7}, {0.0, 1.0}},
                                         {{0.25, 0.5, -0.1, 0.35}, {0.2, 0.9, 0.5, 0.4}}}) {
    std::vector<double> diag;
    for (std::size_t i = 0; i < c.b.size(); ++i) diag.push_back(c.theta[i] * c.b[i]);
    const PartitionedDirk m = partitioned_dirk(c.b, diag);
    const auto [y0, y1] = prk_non_separable(m, h, steps, 0.8, 0.3);
    const auto [z0, z1] = composed_non_separable(m, h, steps, 0.8, 0.3);
    const double err = std::fmax(std::fabs(y0 - z0), std::fabs(y1 - z1));
    BOOST_TEST_MESSAGE("partitioned DIRK (" << c.b.size() << " stages) vs composed theta-map steps: " << err);
    BOOST_TEST(err <= 1e-13);
  }
  // exchanging the two tableaux is another method: the comparison above can fail
  const PartitionedDirk m = partitioned_dirk({0.3, 0.7}, {0.0, 0.7});
  const PartitionedDirk swapped = partitioned_dirk({0.3, 0.7}, {0.3, 0.0});
  const auto [y0, y1] = prk_non_separable(m, h, steps, 0.8, 0.3);
  const auto [z0, z1] = composed_non_separable(swapped, h, steps, 0.8, 0.3);
  BOOST_TEST(std::fmax(std::fabs(y0 - z0), std::fabs(y1 - z1)) > 1e-6);
  // the symplecticity conditions b_i a^_ij + b_j a_ji = b_i b_j hold for every pair built
  const PartitionedDirk w = partitioned_dirk({0.25, 0.5, -0.1, 0.35}, {0.05, 0.45, -0.05, 0.14});
  const auto a = w.tableau(false), ah = w.tableau(true);
  for (std::size_t i = 0; i < 4; ++i)
    for (std::size_t j = 0; j < 4; ++j)
      BOOST_TEST(std::fabs(w.weight[i] * ah[i][j] + w.weight[j] * a[j][i] - w.weight[i] * w.weight[j]) <= 1e-16);
  // what partitioned_dirk states and refuses
  BOOST_TEST(partitioned_dirk(tj, {0.3 * tj[0], 0.5 * tj[1], 0.7 * tj[2]}).symmetric);
  BOOST_TEST(partitioned_dirk(tj, {0.3 * tj[0], 0.5 * tj[1], 0.7 * tj[2]}).order == 2);
  BOOST_TEST(partitioned_dirk(tj, {0.5 * tj[0], 0.5 * tj[1], 0.5 * tj[2]}).order == 4);  // the DIRK
  BOOST_TEST(partitioned_dirk({0.3, 0.7}, {0.0, 0.7}).order == 1);
  BOOST_TEST(partitioned_dirk({0.5, 0.5}, {0.0, 0.5}).order == 2);  // symplectic Euler and its adjoint
  BOOST_CHECK_THROW(partitioned_dirk({0.3, 0.7}, {0.0}), std::invalid_argument);
  BOOST_CHECK_THROW(partitioned_dirk({0.3, 0.7}, {0.4, 0.0}), std::invalid_argument);  // theta_1 > 1
  BOOST_CHECK_THROW(partitioned_dirk({0.3, 0.6}, {0.1, 0.1}), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(orders_of_partitioned_dirk_methods) {
  // Measured orders on the non-separable H to t = 1 against a run with h/32: first order
  // when sum (theta_i - 1/2) b_i^2 != 0, second when it vanishes, and the symmetric pair
  // on the triple-jump weights.
  const std::vector<double> tj = TripleJump4::gamma();
  struct Case {
    std::vector<double> b, theta;
  };
  for (const Case& c : std::vector<Case>{{{0.3, 0.7}, {0.0, 1.0}},
                                         {{0.5, 0.5}, {0.0, 1.0}},
                                         {{0.3, 0.7}, {0.2, 0.5 + 0.3 * 0.3 * 0.3 / (0.7 * 0.7)}},
                                         {tj, {0.3, 0.5, 0.7}}}) {
    std::vector<double> diag;
    for (std::size_t i = 0; i < c.b.size(); ++i) diag.push_back(c.theta[i] * c.b[i]);
    const PartitionedDirk m = partitioned_dirk(c.b, diag);
    const auto ref = composed_non_separable(m, 1.0 / 2560, 2560, 0.8, 0.3);
    std::vector<double> errs;
    for (int n : {20, 40, 80}) {
      const auto y = composed_non_separable(m, 1.0 / n, n, 0.8, 0.3);
      errs.push_back(std::fmax(std::fabs(y.first - ref.first), std::fabs(y.second - ref.second)));
    }
    const double o1 = std::log2(errs[0] / errs[1]), o2 = std::log2(errs[1] / errs[2]);
    BOOST_TEST_MESSAGE("partitioned DIRK, " << c.b.size() << " stages, stated order " << m.order
                                            << ": measured " << o1 << ", " << o2);
    BOOST_TEST(std::fabs(o2 - m.order) <= 0.15, o2);
  }
}

BOOST_AUTO_TEST_CASE(the_runtime_runs_the_partitioned_pair_the_method_names) {
  // composition = "dirk", integrator.weights and integrator.thetas with the hamiltonian
  // form and map = "theta" (what a scene writes, through make_run) take the steps of
  // partitioned_dirk_step, checked above against the tableaux: the same trajectory, to
  // round-off, on the pendulum (H = p^2/2 - cos q) over 200 steps
  const std::vector<double> b = {0.25, 0.5, -0.1, 0.35}, theta = {0.2, 0.9, 0.5, 0.4};
  Problem pr;
  pr.system = &find_system_entry("pendulum", "test");
  for (const ParamEntry& e : pr.system->params) pr.params[e.name] = e.default_value;
  pr.dim = 1;
  pr.q = {2.0};
  pr.p = {0.3};
  pr.momentum_given = true;
  pr.step = 0.05;
  pr.steps = 200;
  Method me;
  me.form = Form::hamiltonian;
  me.map = &find_map_entry("theta", "test");
  me.composition = "dirk";
  me.weights = b;
  me.thetas = theta;
  const RunReport r = make_run(pr, me)->execute(nullptr);
  BOOST_TEST_REQUIRE(!r.failed);
  BOOST_TEST(me.order() == 1);
  const Pendulum P(pr.params.at("m"), pr.params.at("l"), pr.params.at("g"));
  const auto S = partitioned_dirk_step(LegendreHamiltonian<Pendulum>(P), partitioned_dirk_thetas(b, theta), pr.step);
  V1 q(2.0), p(0.3), v = V1::Zero();
  BOOST_TEST_REQUIRE(!integrate(S, 0.0, q, p, v, pr.steps, [](auto&&...) {}).failed);
  BOOST_TEST_MESSAGE("runtime vs partitioned_dirk_step: " << std::fabs(r.q_final.at(0) - q[0]) << ", "
                                                           << std::fabs(r.p_final.at(0) - p[0]));
  BOOST_TEST(std::fabs(r.q_final.at(0) - q[0]) <= 1e-13);
  BOOST_TEST(std::fabs(r.p_final.at(0) - p[0]) <= 1e-13);
  // a pair whose second-order condition holds is stated as order 2
  me.weights = {0.5, 0.5};
  me.thetas = {0.0, 1.0};
  BOOST_TEST(me.order() == 2);
}
