// Discretization maps on R^n: the identities of Def. 2.2, Prop. 2.4, 3.2, 3.4 and the
// paper's closed forms (Ex. 3.4, Eqs. 3.8-3.9, Sec. 5.1).
#define BOOST_TEST_MODULE core_maps
#include <boost/test/unit_test.hpp>

#include "core/map_checks.h"

using namespace dvm;

namespace {

// A retraction of R^n that is not the flat one: R_x(v) = x + v + (v.v) a / 2 for a
// fixed vector a. R_x(0) = x and T_0 R_x = Id, so it is a retraction; its maps have
// no closed-form inverse, which exercises the generic Newton inverse.
struct CurvedRetraction {
  std::string name() const { return "curved"; }
  template <class T, int N>
  Vec<T, N> retract(const Vec<T, N>& x, const Vec<T, N>& v) const {
    Vec<T, N> out = x + v;
    T vv = constant<T>(0.0);
    for (int i = 0; i < N; ++i) vv = vv + v[i] * v[i];
    for (int i = 0; i < N; ++i) out[i] = out[i] + (0.5 * (0.3 + 0.1 * i)) * vv;
    return out;
  }
};

// A map a user might write, with no inverse: a cubic perturbation of the theta map
// that keeps both axioms (R_d(x, 0) = (x, x); the cubic term has zero derivative).
struct UserMap {
  static constexpr bool provides_inverse = false;
  std::string name() const { return "user-cubic"; }
  bool symmetric() const { return false; }
  int order() const { return 1; }
  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    Vec<T, N> q1 = x + 0.7 * v;
    for (int i = 0; i < N; ++i) q1[i] = q1[i] + 0.2 * v[i] * v[i] * v[i] + 0.1 * v[i] * v[i] * x[i];
    return {Vec<T, N>(x - 0.3 * v), q1};
  }
};

// (x, x + 2v) violates Def. 2.2 (ii).
struct Wrong {
  static constexpr bool provides_inverse = false;
  std::string name() const { return "wrong"; }
  bool symmetric() const { return false; }
  int order() const { return 1; }
  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    return {x, Vec<T, N>(x + 2.0 * v)};
  }
};

// A theta map that claims a symmetry it does not have.
struct FalseClaim : ThetaMap {
  FalseClaim() : ThetaMap(0.3) {}
  bool symmetric() const { return true; }
};

template <int N, class M>
void expect_all_identities(const M& map) {
  const MapCheckReport r = check_map<N>(map);
  BOOST_TEST_CONTEXT(r.map_name << " in dimension " << N) {
    for (const auto& name : identity_names()) BOOST_TEST(r.residual(name) <= 1e-12, name << " = " << r.residual(name));
    if (r.claims_symmetric)
      BOOST_TEST(r.residual("adjoint_difference") <= 1e-12);
    else
      BOOST_TEST(r.residual("adjoint_difference") > 1e-3);
    BOOST_TEST(report_passes(r));
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(identities_hold_for_every_builtin_map) {
  for (double theta : {0.0, 0.25, 0.5, 0.8, 1.0}) {
    expect_all_identities<1>(ThetaMap(theta));
    expect_all_identities<3>(ThetaMap(theta));
  }
  expect_all_identities<2>(ThetaMap::explicit_euler());
  expect_all_identities<2>(ThetaMap::adjoint_euler());
  expect_all_identities<2>(ThetaMap::midpoint());
  for (double theta : {0.0, 0.5, 0.7}) {
    expect_all_identities<1>(RetractionMap<EuclideanRetraction>({}, theta));
    expect_all_identities<2>(RetractionMap<CurvedRetraction>({}, theta));
  }
}

BOOST_AUTO_TEST_CASE(identities_hold_for_a_user_map_with_generic_inverse) {
  expect_all_identities<1>(UserMap{});
  expect_all_identities<3>(UserMap{});
  expect_all_identities<2>(adjoint(UserMap{}));
}

BOOST_AUTO_TEST_CASE(checks_catch_a_map_that_breaks_the_axioms) {
  // (x, x + 2v) violates Def. 2.2 (ii); a checker that cannot fail proves nothing.
  const MapCheckReport r = check_map<2>(Wrong{});
  BOOST_TEST(r.residual("tangent_identity") > 0.5);
  BOOST_TEST(!report_passes(r));
  // a map that claims a symmetry it does not have is caught too
  BOOST_TEST(!report_passes(check_map<1>(FalseClaim{})));
}

BOOST_AUTO_TEST_CASE(theta_map_adjoint_is_one_minus_theta) {
  const ThetaMap m(0.3);
  const auto a = adjoint(m);
  const ThetaMap expected = m.adjoint();
  BOOST_TEST(expected.theta() == 0.7, boost::test_tools::tolerance(1e-15));
  Vec<double, 2> x(0.3, -0.4), v(0.5, 0.25);
  const auto r1 = a(x, v);
  const auto r2 = expected(x, v);
  BOOST_TEST(max_abs(r1.q0 - r2.q0) <= 1e-15);
  BOOST_TEST(max_abs(r1.q1 - r2.q1) <= 1e-15);
  // explicit Euler (x, x + v) has adjoint (x - v, x)
  const auto e = adjoint(ThetaMap::explicit_euler())(x, v);
  BOOST_TEST(max_abs(e.q0 - (x - v)) == 0.0);
  BOOST_TEST(max_abs(e.q1 - x) == 0.0);
}

BOOST_AUTO_TEST_CASE(midpoint_tangent_lift_closed_form) {
  // Eq. 3.8: R_d^T((q, v), (qdot, vdot)) = ((q - qdot/2, v - vdot/2), (q + qdot/2, v + vdot/2)),
  // and its inverse ((q0, v0), (q1, v1)) -> ((q0+q1)/2, (v0+v1)/2; q1-q0, v1-v0).
  const auto lift = tangent_lift(ThetaMap::midpoint());
  Vec<double, 4> X, V;
  X << 0.3, -0.2, 1.1, 0.4;  // (q, v) with n = 2
  V << 0.05, 0.07, -0.3, 0.2;  // (qdot, vdot)
  const auto r = lift(X, V);
  Vec<double, 4> e0, e1;
  e0 << X.head<2>() - V.head<2>() / 2, X.tail<2>() - V.tail<2>() / 2;
  e1 << X.head<2>() + V.head<2>() / 2, X.tail<2>() + V.tail<2>() / 2;
  BOOST_TEST(max_abs(r.q0 - e0) <= 1e-15);
  BOOST_TEST(max_abs(r.q1 - e1) <= 1e-15);
  const auto inv = lift.inverse(e0, e1);
  BOOST_TEST(max_abs(inv.x - X) <= 1e-15);
  BOOST_TEST(max_abs(inv.v - V) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(midpoint_cotangent_lift_closed_form) {
  // Eq. 3.9: R_d^{T*}(q, p, qdot, pdot) = (q - qdot/2, p - pdot/2; q + qdot/2, p + pdot/2)
  // and the inverse (q0, p0, q1, p1) -> ((q0+q1)/2, (p0+p1)/2, q1-q0, p1-p0).
  const ThetaMap m = ThetaMap::midpoint();
  Vec<double, 2> q(0.3, -0.7), p(1.2, 0.1), qd(0.1, 0.05), pd(-0.2, 0.3);
  const auto c = cotangent_lift(m, q, p, qd, pd);
  BOOST_TEST(max_abs(c.q0 - (q - qd / 2)) <= 1e-15);
  BOOST_TEST(max_abs(c.p0 - (p - pd / 2)) <= 1e-15);
  BOOST_TEST(max_abs(c.q1 - (q + qd / 2)) <= 1e-15);
  BOOST_TEST(max_abs(c.p1 - (p + pd / 2)) <= 1e-15);
  const auto b = cotangent_lift_inverse(m, c.q0, c.p0, c.q1, c.p1);
  BOOST_TEST(max_abs(b.q - (c.q0 + c.q1) / 2) <= 1e-15);
  BOOST_TEST(max_abs(b.p - (c.p0 + c.p1) / 2) <= 1e-15);
  BOOST_TEST(max_abs(b.qdot - (c.q1 - c.q0)) <= 1e-15);
  BOOST_TEST(max_abs(b.pdot - (c.p1 - c.p0)) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(cotangent_lift_of_q_minus_v_q) {
  // Sec. 5.1: the cotangent lift of R_d(q, v) = (q - v, q) is (q - qdot, p; q, p + pdot),
  // through the closed-form inverse and through the generic Newton inverse alike.
  Vec<double, 3> q(0.3, -0.7, 2.0), p(1.2, 0.1, -0.5), qd(0.1, 0.05, -0.2), pd(-0.2, 0.3, 0.7);
  const auto check = [&](const auto& map) {
    const auto c = cotangent_lift(map, q, p, qd, pd);
    BOOST_TEST(max_abs(c.q0 - (q - qd)) <= 1e-15);
    BOOST_TEST(max_abs(c.p0 - p) <= 1e-15);
    BOOST_TEST(max_abs(c.q1 - q) <= 1e-15);
    BOOST_TEST(max_abs(c.p1 - (p + pd)) <= 1e-15);
  };
  check(ThetaMap::adjoint_euler());
  check(RetractionMap<EuclideanRetraction>({}, 1.0));
}

BOOST_AUTO_TEST_CASE(generic_inverse_derivatives_match_closed_form) {
  // The Newton inverse differentiated through the implicit function theorem must
  // give the same first and second derivatives as the closed form.
  const ThetaMap closed(0.3);
  const RetractionMap<EuclideanRetraction> generic({}, 0.3);
  using J1 = ceres::Jet<double, 4>;
  using J2 = ceres::Jet<J1, 4>;
  Vec<J2, 2> q0, q1;
  const double a[4] = {0.2, -0.1, 0.5, 0.3};
  for (int i = 0; i < 2; ++i) {
    q0[i] = J2(J1(a[i], i), i);
    q1[i] = J2(J1(a[2 + i], 2 + i), 2 + i);
  }
  const auto tc = inverse(closed, q0, q1);
  const auto tg = inverse(generic, q0, q1);
  for (int i = 0; i < 2; ++i) {
    BOOST_TEST(std::fabs(tc.x[i].a.a - tg.x[i].a.a) <= 1e-15);
    BOOST_TEST(max_abs(tc.x[i].a.v - tg.x[i].a.v) <= 1e-15);
    BOOST_TEST(max_abs(tc.v[i].v[0].v - tg.v[i].v[0].v) <= 1e-14);
    for (int k = 0; k < 4; ++k) BOOST_TEST(std::fabs(tc.v[i].v[k].a - tg.v[i].v[k].a) <= 1e-15);
  }
}

BOOST_AUTO_TEST_CASE(invalid_theta_is_rejected) {
  BOOST_CHECK_THROW(ThetaMap(1.5), std::invalid_argument);
  BOOST_CHECK_THROW(ThetaMap(-0.1), std::invalid_argument);
  BOOST_CHECK_THROW(ThetaMap(NAN), std::invalid_argument);
}
