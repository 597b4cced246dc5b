// Lagrangians, their derived quantities, and discrete Lagrangians of maps.
#define BOOST_TEST_MODULE mechanics
#include <boost/test/unit_test.hpp>

#include <random>

#include "mechanics/discrete_lagrangian.h"
#include "mechanics/systems.h"

using namespace dvm;

namespace {

// L = q v: linear in the velocity, so its velocity Hessian vanishes everywhere.
struct Degenerate {
  static constexpr int dim = 1;
  std::string name() const { return "degenerate"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    return q[0] * v[0];
  }
};

// A Lagrangian with a position-dependent mass and no closed forms, written with
// plain double literals: it must compile and differentiate at any Jet depth.
struct VariableMass {
  static constexpr int dim = 2;
  std::string name() const { return "variable-mass"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    using std::cos;
    using std::exp;
    const T m = 2.0 + cos(q[0]) * 0.5;
    return 0.5 * m * v[0] * v[0] + 0.75 * v[1] * v[1] + 0.1 * v[0] * v[1] - exp(-q[1] * q[1]) / 3.0;
  }
};

template <class S>
void gradients_match_autodiff(const S& system, int dim_samples = 8) {
  constexpr int N = S::dim;
  const GenericOnly<S> generic{system};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1.5, 1.5);
  for (int s = 0; s < dim_samples; ++s) {
    Vec<double, N> q, v;
    for (int i = 0; i < N; ++i) {
      q[i] = U(rng) + (S::dim == 2 ? 2.0 : 0.0);  // keep Kepler away from the origin
      v[i] = U(rng);
    }
    Vec<double, N> a1, b1, a2, b2;
    lagrangian_gradient(system, q, v, a1, b1);
    lagrangian_gradient(generic, q, v, a2, b2);
    BOOST_TEST(max_abs(a1 - a2) <= 1e-14 * std::fmax(1.0, max_abs(a2)));
    BOOST_TEST(max_abs(b1 - b2) <= 1e-14 * std::fmax(1.0, max_abs(b2)));
    const Vec<double, N> p = legendre(system, q, v);
    BOOST_TEST(max_abs(legendre_inverse(system, q, p) - v) <= 1e-14);
    BOOST_TEST(max_abs(legendre_inverse(generic, q, p) - v) <= 1e-13);
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(closed_forms_match_automatic_differentiation) {
  gradients_match_autodiff(HarmonicOscillator(1.7));
  gradients_match_autodiff(Pendulum(1.3, 0.8, 9.81));
  gradients_match_autodiff(Kepler(1.2));
}

BOOST_AUTO_TEST_CASE(energy_of_the_pendulum) {
  const Pendulum P(2.0, 0.5, 9.81);
  Vec<double, 1> q(0.4), v(1.3);
  const double expected = 0.5 * 2.0 * 0.25 * 1.3 * 1.3 - 2.0 * 9.81 * 0.5 * std::cos(0.4);
  BOOST_TEST(energy(P, q, v) == expected, boost::test_tools::tolerance(1e-15));
}

BOOST_AUTO_TEST_CASE(nested_jets_with_double_literals) {
  // Second derivatives of a Lagrangian written with double literals, by Jet<Jet>,
  // against central differences of the first derivatives.
  const VariableMass L;
  Vec<double, 2> q(0.3, -0.4), v(0.7, 0.2);
  const Mat<double, 2, 2> H = velocity_hessian(L, q, v);
  const double eps = 1e-6;
  for (int j = 0; j < 2; ++j) {
    Vec<double, 2> vp = v, vm = v;
    vp[j] += eps;
    vm[j] -= eps;
    const Vec<double, 2> col = (legendre(L, q, vp) - legendre(L, q, vm)) / (2 * eps);
    BOOST_TEST(max_abs(H.col(j) - col) <= 1e-8);
  }
  using J1 = ceres::Jet<double, 2>;
  using J2 = ceres::Jet<J1, 2>;
  Vec<J2, 2> qq, vv;
  for (int i = 0; i < 2; ++i) {
    qq[i] = J2(constant<J1>(q[i]));
    vv[i] = J2(J1(v[i], i), i);
  }
  const J2 l = L(qq, vv);
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) BOOST_TEST(std::fabs(l.v[i].v[j] - H(i, j)) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(degenerate_lagrangian_is_rejected) {
  const Degenerate L;
  BOOST_CHECK_THROW(legendre_inverse(L, Vec<double, 1>(0.5), Vec<double, 1>(1.0), Vec<double, 1>(0.1)),
                    DegenerateLagrangianError);
}

BOOST_AUTO_TEST_CASE(discrete_lagrangian_of_the_theta_map) {
  // L_d(q0, q1) = h L((1-theta) q0 + theta q1, (q1 - q0)/h) and, for the harmonic
  // oscillator, D1 L_d = -h (1-theta) w^2 x - (q1-q0)/h,  D2 L_d = -h theta w^2 x + (q1-q0)/h.
  const double w = 1.3, h = 0.1;
  for (double theta : {0.0, 0.3, 0.5, 1.0}) {
    const DiscreteLagrangian<HarmonicOscillator, ThetaMap> Ld(HarmonicOscillator(w), ThetaMap(theta), h);
    const DiscreteLagrangian<GenericOnly<HarmonicOscillator>, RetractionMap<EuclideanRetraction>> Lg(
        GenericOnly<HarmonicOscillator>{HarmonicOscillator(w)}, RetractionMap<EuclideanRetraction>({}, theta), h);
    Vec<double, 1> q0(0.4), q1(0.47);
    const double x = (1 - theta) * q0[0] + theta * q1[0], u = (q1[0] - q0[0]) / h;
    BOOST_TEST(Ld(q0, q1) == h * (0.5 * u * u - 0.5 * w * w * x * x), boost::test_tools::tolerance(1e-14));
    const double d1 = -h * (1 - theta) * w * w * x - u, d2 = -h * theta * w * w * x + u;
    BOOST_TEST(Ld.D1Ld(q0, q1)[0] == d1, boost::test_tools::tolerance(1e-14));
    BOOST_TEST(Ld.D2Ld(q0, q1)[0] == d2, boost::test_tools::tolerance(1e-14));
    BOOST_TEST(Lg.D1Ld(q0, q1)[0] == d1, boost::test_tools::tolerance(1e-13));
    BOOST_TEST(Lg.D2Ld(q0, q1)[0] == d2, boost::test_tools::tolerance(1e-13));
    Vec<double, 1> a, s;
    Ld.D2Ld_and_shift(q0, Vec<double, 1>(q1 - q0), a, s);
    BOOST_TEST(a[0] == d2, boost::test_tools::tolerance(1e-14));
    BOOST_TEST(s[0] == -h * w * w * x, boost::test_tools::tolerance(1e-14));
  }
}

BOOST_AUTO_TEST_CASE(discrete_lagrangian_slopes_agree_across_paths) {
  // Kepler with closed-form gradient vs automatic differentiation, for a
  // non-symmetric map: the chain-rule path and the full Jet path must agree.
  const double h = 0.05;
  const DiscreteLagrangian<Kepler, ThetaMap> A(Kepler(1.0), ThetaMap(0.2), h);
  const DiscreteLagrangian<GenericOnly<Kepler>, ThetaMap> B(GenericOnly<Kepler>{Kepler(1.0)}, ThetaMap(0.2), h);
  Vec<double, 2> q0(0.9, 0.2), q1(0.88, 0.26);
  BOOST_TEST(max_abs(A.D1Ld(q0, q1) - B.D1Ld(q0, q1)) <= 1e-14);
  BOOST_TEST(max_abs(A.D2Ld(q0, q1) - B.D2Ld(q0, q1)) <= 1e-14);
  // central differences of L_d itself
  const double eps = 1e-6;
  for (int i = 0; i < 2; ++i) {
    Vec<double, 2> e = Vec<double, 2>::Zero();
    e[i] = eps;
    const double fd1 = (A(Vec<double, 2>(q0 + e), q1) - A(Vec<double, 2>(q0 - e), q1)) / (2 * eps);
    const double fd2 = (A(q0, Vec<double, 2>(q1 + e)) - A(q0, Vec<double, 2>(q1 - e))) / (2 * eps);
    BOOST_TEST(std::fabs(A.D1Ld(q0, q1)[i] - fd1) <= 1e-7);
    BOOST_TEST(std::fabs(A.D2Ld(q0, q1)[i] - fd2) <= 1e-7);
  }
}

BOOST_AUTO_TEST_CASE(invalid_parameters_are_rejected) {
  BOOST_CHECK_THROW(HarmonicOscillator(0.0), std::invalid_argument);
  BOOST_CHECK_THROW(Pendulum(-1.0, 1.0, 1.0), std::invalid_argument);
  BOOST_CHECK_THROW(Kepler(NAN), std::invalid_argument);
  BOOST_CHECK_THROW((DiscreteLagrangian<Kepler, ThetaMap>(Kepler(1.0), ThetaMap(0.5), 0.0)), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(kepler_exact_solution_conserves_invariants) {
  const Kepler K(1.0);
  const double e = 0.6;
  Vec<double, 2> q0(1 - e, 0.0), p0(0.0, std::sqrt((1 + e) / (1 - e))), q, p;
  const double E0 = 0.5 * p0.squaredNorm() - 1.0 / q0.norm();
  for (double t : {0.3, 1.0, 2 * M_PI, 17.5}) {
    K.exact(t, q0, p0, q, p);
    BOOST_TEST(std::fabs(0.5 * p.squaredNorm() - 1.0 / q.norm() - E0) <= 1e-14);
    BOOST_TEST(std::fabs(Kepler::angular_momentum(q, p) - Kepler::angular_momentum(q0, p0)) <= 1e-14);
  }
  K.exact(2 * M_PI, q0, p0, q, p);  // period 2 pi for a = 1
  BOOST_TEST(max_abs(q - q0) <= 1e-13);
  // derivative check: dq/dt = p by central differences
  Vec<double, 2> qa, qb, pa, pb;
  K.exact(1.0 + 1e-5, q0, p0, qa, pa);
  K.exact(1.0 - 1e-5, q0, p0, qb, pb);
  K.exact(1.0, q0, p0, q, p);
  BOOST_TEST(max_abs((qa - qb) / 2e-5 - p) <= 1e-8);
  BOOST_TEST(max_abs((pa - pb) / 2e-5 + q / std::pow(q.norm(), 3)) <= 1e-8);
}
