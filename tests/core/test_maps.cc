// Discretization maps on R^n: the identities of Def. 2.2, Prop. 2.4, 3.2, 3.4, the
// relations between lifts and adjoints (Props. 3.3, 3.6, 3.7) and the paper's closed
// forms (Ex. 3.4, Eqs. 3.8-3.9, Sec. 5.1).
#define BOOST_TEST_MODULE core_maps
#include <boost/test/unit_test.hpp>

#include <random>

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

namespace {

// Sample points of R^3 (entries uniform in [-a, a]) for the lift relations below.
struct Samples {
  std::mt19937 rng{7};
  Vec<double, 3> operator()(double a) {
    std::uniform_real_distribution<double> U(-a, a);
    return Vec<double, 3>(U(rng), U(rng), U(rng));
  }
};

// Non-symmetric maps with closed-form, generic (Newton) and no user-given inverse, and
// a symmetric map from a curved retraction, each applied to the checks below.
template <class F>
void for_lift_test_maps(F&& check) {
  check(ThetaMap(0.3));
  check(RetractionMap<CurvedRetraction>({}, 0.3));
  check(UserMap{});
  check(RetractionMap<CurvedRetraction>({}, 0.5));
}

}  // namespace

BOOST_AUTO_TEST_CASE(tangent_lift_of_the_adjoint_is_the_adjoint_of_the_tangent_lift) {
  // Prop. 3.3: (R_d^*)^T = (R_d^T)^*, so the tangent lift of a symmetric map is symmetric.
  // Both sides through different code: the left differentiates the adjoint map, the
  // right swaps the points of the lifted map at the reversed velocity of TQ.
  Samples rnd;
  for_lift_test_maps([&](const auto& map) {
    const auto left = tangent_lift(adjoint(map));
    const auto right = adjoint(tangent_lift(map));
    double d = 0.0, sym = 0.0;
    for (int k = 0; k < 8; ++k) {
      Vec<double, 6> X, V;  // (q, v) and (qdot, vdot) with n = 3
      X << rnd(1.0), rnd(0.5);
      V << rnd(0.5), rnd(0.5);
      const auto a = left(X, V), b = right(X, V), c = tangent_lift(map)(X, V);
      d = std::fmax(d, std::fmax(max_abs(a.q0 - b.q0), max_abs(a.q1 - b.q1)));
      sym = std::fmax(sym, std::fmax(max_abs(c.q0 - b.q0), max_abs(c.q1 - b.q1)));
    }
    BOOST_TEST_CONTEXT(map.name() << " symmetric=" << map.symmetric()) {
      BOOST_TEST(d <= 1e-15);
      if (map.symmetric())
        BOOST_TEST(sym <= 1e-15);
      else
        BOOST_TEST(sym > 1e-3);
    }
  });
}

BOOST_AUTO_TEST_CASE(cotangent_lift_of_the_adjoint_is_the_adjoint_of_the_cotangent_lift) {
  // Prop. 3.7: (R_d^*)^{T*} = (R_d^{T*})^*, where the adjoint of a map on T*Q swaps the two
  // points of the map at the reversed velocity: (R^{T*})^*(z, zdot) = (R^{T*}_2(z, -zdot),
  // R^{T*}_1(z, -zdot)) with z = (q, p), zdot = (qdot, pdot). A symmetric map's cotangent
  // lift is symmetric.
  Samples rnd;
  for_lift_test_maps([&](const auto& map) {
    double d = 0.0, sym = 0.0;
    for (int k = 0; k < 8; ++k) {
      const Vec<double, 3> q = rnd(1.0), p = rnd(1.0), qd = rnd(0.5), pd = rnd(0.5);
      const auto a = cotangent_lift(adjoint(map), q, p, qd, pd);
      const auto b = cotangent_lift(map, q, p, Vec<double, 3>(-qd), Vec<double, 3>(-pd));  // swapped below
      const auto c = cotangent_lift(map, q, p, qd, pd);
      d = std::fmax(d, std::fmax(std::fmax(max_abs(a.q0 - b.q1), max_abs(a.p0 - b.p1)),
                                 std::fmax(max_abs(a.q1 - b.q0), max_abs(a.p1 - b.p0))));
      sym = std::fmax(sym, std::fmax(std::fmax(max_abs(c.q0 - b.q1), max_abs(c.p0 - b.p1)),
                                     std::fmax(max_abs(c.q1 - b.q0), max_abs(c.p1 - b.p0))));
    }
    BOOST_TEST_CONTEXT(map.name() << " symmetric=" << map.symmetric()) {
      BOOST_TEST(d <= 1e-14);
      if (map.symmetric())
        BOOST_TEST(sym <= 1e-14);
      else
        BOOST_TEST(sym > 1e-3);
    }
  });
}

BOOST_AUTO_TEST_CASE(tangent_and_cotangent_lifts_are_dual) {
  // Prop. 3.6: <Phi(alpha_q0, alpha_q1), R_d^T(w)> = <(R_d^{T*})^{-1}(alpha_q0, alpha_q1), w>^T
  // for w in TTQ based at (q, v) = R_d^{-1}(q0, q1). In coordinates, with w = (dq, dv),
  // Phi(q0, p0; q1, p1) = (q0, q1; -p0, p1) and alpha_Q(q, p, qdot, pdot) = (q, qdot; pdot, p):
  //   -p0 . dq0 + p1 . dq1 = pdot . dq + p . dv,
  // where R_d^T((q, v), (dq, dv)) = ((q0, dq0), (q1, dq1)) is the tangent lift (forward
  // Jets through the map) and (q, p, qdot = v, pdot) the inverse cotangent lift (the
  // transposed Jacobian, Eq. 3.6) at (q0, p0; q1, p1).
  Samples rnd;
  for_lift_test_maps([&](const auto& map) {
    double worst = 0.0, size = 0.0;
    for (int k = 0; k < 8; ++k) {
      const Vec<double, 3> q = rnd(1.0), v = rnd(0.5), p0 = rnd(1.0), p1 = rnd(1.0);
      const auto pts = map(q, v);
      const auto back = cotangent_lift_inverse(map, pts.q0, p0, pts.q1, p1);
      BOOST_TEST(max_abs(back.q - q) <= 1e-14);
      BOOST_TEST(max_abs(back.qdot - v) <= 1e-14);
      for (int j = 0; j < 4; ++j) {
        const Vec<double, 3> dq = rnd(1.0), dv = rnd(1.0);
        // R_d^T = T R_d o kappa_Q: tangent_lift(X, V) differentiates R_d at (X.head, V.head)
        // along (X.tail, V.tail)
        Vec<double, 6> X, W;
        X << q, dq;
        W << v, dv;
        const auto t = tangent_lift(map)(X, W);
        const double left = -p0.dot(t.q0.template tail<3>()) + p1.dot(t.q1.template tail<3>());
        const double right = back.pdot.dot(dq) + back.p.dot(dv);
        worst = std::fmax(worst, std::fabs(left - right));
        size = std::fmax(size, std::fabs(left));
      }
    }
    BOOST_TEST_CONTEXT(map.name()) {
      BOOST_TEST(size > 0.1);  // the pairing is not trivially zero
      BOOST_TEST(worst <= 1e-14);
    }
  });
}
