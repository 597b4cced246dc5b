// S^2 and SO(3): retractions, discretization maps, closed-form inverses and domains,
// every identity of the R^n checks on each map's local representation, and the
// tangent and cotangent lifts of the paper's Ex. 3.5 (S^2) and Ex. 3.6 (SO(3), Cayley)
// in closed form, and the differentiable inverse of the maps of any theta (Prop. 2.3).
#define BOOST_TEST_MODULE core_manifolds
#include <boost/test/unit_test.hpp>

#include <random>

#include "core/manifold_checks.h"

using namespace dvm;

namespace {

std::vector<SphereMap> sphere_maps() {
  std::vector<SphereMap> out;
  for (auto k : {RetractionKind::exp, RetractionKind::projection})
    for (double theta : {0.0, 0.5, 1.0, 0.3}) out.emplace_back(k, theta, "sphere-" + to_string(k));
  return out;
}
std::vector<SO3Map> so3_maps() {
  std::vector<SO3Map> out;
  for (auto k : {RetractionKind::exp, RetractionKind::cayley})
    for (double theta : {0.0, 0.5, 1.0, 0.3}) out.emplace_back(k, theta, "so3-" + to_string(k));
  return out;
}

template <class Map>
void expect_identities(const Map& map) {
  const MapCheckReport r = check_manifold_map(map);
  BOOST_TEST_CONTEXT(map.name() << " theta=" << map.theta()) {
    for (const auto& name : identity_names()) BOOST_TEST(r.residual(name) <= 1e-12, name << " = " << r.residual(name));
    BOOST_TEST(r.residual("manifold_round_trip") <= 1e-13);
    BOOST_TEST(r.residual("closed_form_vs_newton") <= 1e-12);
    if (map.symmetric())
      BOOST_TEST(r.residual("adjoint_difference") <= 1e-12);
    else
      BOOST_TEST(r.residual("adjoint_difference") > 1e-3);
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(identities_of_every_sphere_map) {
  for (const auto& m : sphere_maps()) expect_identities(m);
}

BOOST_AUTO_TEST_CASE(identities_of_every_so3_map) {
  for (const auto& m : so3_maps()) expect_identities(m);
}

BOOST_AUTO_TEST_CASE(retractions_stay_on_the_manifold_and_are_retractions) {
  const Vec<double, 3> x = base_point<Sphere>();
  const Vec<double, 3> v = Sphere::tangent(x, Vec<double, 2>(0.7, -1.9));
  BOOST_TEST(Sphere::point_defect(Sphere::exp(x, v)) <= 1e-15);
  BOOST_TEST(Sphere::point_defect(Sphere::projection(x, v)) <= 1e-15);
  // exp_x(v) is the great circle: angle between x and exp_x(v) is |v|
  BOOST_TEST(std::acos(x.dot(Sphere::exp(x, v))) == v.norm(), boost::test_tools::tolerance(1e-13));
  BOOST_TEST(max_abs(Sphere::log(x, Sphere::exp(x, v)) - v) <= 1e-14);
  const Mat<double, 3, 3> R = base_point<SO3>();
  const Vec<double, 3> w(0.4, 2.2, -1.0);
  BOOST_TEST(SO3::point_defect(SO3::mul(R, SO3::exp(w))) <= 1e-15);
  BOOST_TEST(SO3::point_defect(SO3::mul(R, SO3::cay(w))) <= 1e-15);
  BOOST_TEST(max_abs(SO3::log(SO3::exp(w)) - w) <= 1e-14);
  BOOST_TEST(max_abs(SO3::cay_inverse(SO3::cay(w)) - w) <= 1e-14);
  // Cayley: rotation about w by 2 atan(|w|/2)
  const double angle = 2 * std::atan(w.norm() / 2);
  BOOST_TEST(SO3::log(SO3::cay(w)).norm() == angle, boost::test_tools::tolerance(1e-13));
}

BOOST_AUTO_TEST_CASE(small_angle_branches_keep_their_derivatives) {
  // d/dt exp(t w) at t = 0 is hat(w), also exactly at zero and across the Taylor
  // branch boundary; the same for the sphere and for log.
  using J = ceres::Jet<double, 1>;
  for (double t0 : {0.0, 1e-9, 0.99e-2, 1.01e-2}) {
    const Vec<double, 3> w(0.3, -0.5, 0.8);
    Vec<J, 3> wj;
    for (int i = 0; i < 3; ++i) wj[i] = J(t0 * w[i], Vec<double, 1>::Constant(w[i]));
    const Mat<J, 3, 3> E = SO3::exp(wj);
    Mat<double, 3, 3> dE, E0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        dE(i, j) = E(i, j).v[0];
        E0(i, j) = E(i, j).a;
      }
    // the body velocity of t -> exp(t w) is w for every t (same axis)
    BOOST_TEST(max_abs(SO3::vee(Mat<double, 3, 3>(E0.transpose() * dE)) - w) <= 1e-12, "t0 = " << t0);
    const Vec<double, 3> x(0.0, 0.0, 1.0), u(1.0, 0.0, 0.0);
    Vec<J, 3> xj = constants<J>(x), uj;
    for (int i = 0; i < 3; ++i) uj[i] = J(t0 * u[i], Vec<double, 1>::Constant(u[i]));
    const Vec<J, 3> y = Sphere::exp(xj, uj);
    // d/dt exp_x(t u) = -sin t x + cos t u
    BOOST_TEST(std::fabs(y[0].v[0] - std::cos(t0)) <= 1e-12);
    BOOST_TEST(std::fabs(y[2].v[0] + std::sin(t0)) <= 1e-12);
    const Vec<J, 3> l = Sphere::log(xj, y);
    BOOST_TEST(std::fabs(l[0].v[0] - 1.0) <= 1e-12, "t0 = " << t0);
  }
}

BOOST_AUTO_TEST_CASE(projection_map_closed_form_inverse_and_domain) {
  // The paper's projection map R_d(x, v) = (x, (x + v)/|x + v|) has inverse
  // R_d^{-1}(x0, x1) = (x0, x1/(x0.x1) - x0), defined where x0.x1 > 0.
  const SphereMap m(RetractionKind::projection, 0.0, "sphere-projection-fixed");
  const Vec<double, 3> x0 = base_point<Sphere>();
  const Vec<double, 3> x1 = Sphere::exp(x0, Sphere::tangent(x0, Vec<double, 2>(0.4, 0.9)));
  const auto t = m.inverse(x0, x1);
  BOOST_TEST(max_abs(t.x - x0) == 0.0);
  BOOST_TEST(max_abs(t.v - (x1 / x0.dot(x1) - x0)) <= 1e-15);
  BOOST_TEST(Sphere::tangent_defect(x0, t.v) <= 1e-15);
  const Vec<double, 3> far = Sphere::exp(x0, Sphere::tangent(x0, Vec<double, 2>(1.6, 0.3)));  // x0.far < 0
  BOOST_CHECK_THROW(m.inverse(x0, far), MapDomainError);
  // antipodal points for the midpoint maps; a rotation by pi for Cayley
  const SphereMap mid(RetractionKind::exp, 0.5, "sphere-exp");
  BOOST_CHECK_THROW(mid.inverse(x0, Vec<double, 3>(-x0)), MapDomainError);
  const SO3Map cay(RetractionKind::cayley, 0.0, "so3-cayley-fixed");
  const Mat<double, 3, 3> R = base_point<SO3>();
  const Mat<double, 3, 3> Rpi = R * SO3::exp(Vec<double, 3>(M_PI, 0.0, 0.0));
  BOOST_CHECK_THROW(cay.inverse(R, Rpi), MapDomainError);
  BOOST_CHECK_THROW(SO3Map(RetractionKind::cayley, 0.5, "c").inverse(R, Rpi), MapDomainError);
}

namespace {

// Largest difference between two nested Jets, over the value and every derivative part.
template <class T>
double jet_difference(const T& a, const T& b) {
  if constexpr (is_jet_v<T>) {
    double m = jet_difference(a.a, b.a);
    for (int i = 0; i < a.v.size(); ++i) m = std::fmax(m, jet_difference(a.v[i], b.v[i]));
    return m;
  } else {
    return std::fabs(a - b);
  }
}
template <class P>
double jet_difference_all(const P& a, const P& b) {
  double m = 0;
  for (Eigen::Index i = 0; i < a.size(); ++i) m = std::fmax(m, jet_difference(a(i), b(i)));
  return m;
}

// q0 = chart(c0, eta) and q1 = chart(c1, xi) as nested Jets in (eta, xi): every first
// and second derivative of whatever is computed from them.
template <class M>
auto seeded_pair(const typename M::template Point<double>& c0, const typename M::template Point<double>& c1) {
  constexpr int n = 2 * M::dim;
  using J = ceres::Jet<double, n>;
  using JJ = ceres::Jet<J, n>;
  Vec<JJ, M::dim> eta, xi;
  for (int i = 0; i < M::dim; ++i) {
    eta[i] = JJ(J(0.0, i), i);
    xi[i] = JJ(J(0.0, M::dim + i), M::dim + i);
  }
  return std::make_pair(M::chart(c0, eta), M::chart(c1, xi));
}

}  // namespace

BOOST_AUTO_TEST_CASE(inverse_for_any_theta_has_exact_second_derivatives) {
  // Prop. 2.3 allows any theta in [0, 1]. Where no closed-form inverse exists, the
  // inverse is Newton's method in a chart and its derivatives come from the implicit
  // function theorem. Then R_d(R_d^{-1}(q0, q1)) = (q0, q1) holds in every first and
  // second derivative with respect to q0 and q1, which is what the discrete
  // Euler-Lagrange equations differentiate.
  const Vec<double, 3> x0 = base_point<Sphere>();
  const Vec<double, 3> x1 = Sphere::exp(x0, Sphere::tangent(x0, Vec<double, 2>(0.3, -0.2)));
  for (auto kind : {RetractionKind::exp, RetractionKind::projection})
    for (double theta : {0.3, 0.8}) {
      const SphereMap m(kind, theta, "sphere-" + to_string(kind));
      BOOST_TEST(!m.closed_form_inverse());
      const auto q = seeded_pair<Sphere>(x0, x1);
      const auto t = m.inverse(q.first, q.second);
      const auto r = m(t.x, t.v);
      BOOST_TEST(jet_difference_all(r.q0, q.first) <= 1e-12, m.name() << " theta " << theta);
      BOOST_TEST(jet_difference_all(r.q1, q.second) <= 1e-12, m.name() << " theta " << theta);
      BOOST_TEST(std::fabs(value(detail::dot(t.x, t.x)) - 1.0) <= 1e-15);
      BOOST_TEST(std::fabs(value(detail::dot(t.x, t.v))) <= 1e-15);
      // the relative form (q0 and the difference q1 - q0) is the same map
      const auto u = m.inverse_relative(q.first, Sphere::relative(q.first, q.second));
      BOOST_TEST(jet_difference_all(u.x, t.x) <= 1e-14);
      BOOST_TEST(jet_difference_all(u.v, t.v) <= 1e-14);
    }
  const Mat<double, 3, 3> R0 = base_point<SO3>(), R1 = R0 * SO3::exp(Vec<double, 3>(0.2, 0.1, -0.3));
  const auto q = seeded_pair<SO3>(R0, R1);
  const SO3Map cay(RetractionKind::cayley, 0.3, "so3-cayley");
  BOOST_TEST(!cay.closed_form_inverse());
  const auto t = cay.inverse(q.first, q.second);
  const auto r = cay(t.x, t.v);
  BOOST_TEST(jet_difference_all(r.q0, q.first) <= 1e-12);
  BOOST_TEST(jet_difference_all(r.q1, q.second) <= 1e-12);
  // The exponential map has a closed-form inverse for every theta (w = log(q0^T q1),
  // x = q0 exp(theta w)): the Newton path reproduces it with both derivatives.
  const SO3Map ex(RetractionKind::exp, 0.3, "so3-exp");
  const auto closed = ex.inverse(q.first, q.second);
  const auto newton = newton_manifold_inverse(ex, q.first, q.second);
  BOOST_TEST(jet_difference_all(closed.x, newton.x) <= 1e-12);
  BOOST_TEST(jet_difference_all(closed.v, newton.v) <= 1e-12);
}

BOOST_AUTO_TEST_CASE(sphere_midpoint_closed_form) {
  // Exponential midpoint: the base point is the geodesic midpoint and |v| the angle.
  const SphereMap m(RetractionKind::exp, 0.5, "sphere-exp");
  const Vec<double, 3> q0(1.0, 0.0, 0.0), q1(0.0, 1.0, 0.0);
  const auto t = m.inverse(q0, q1);
  BOOST_TEST(max_abs(t.x - Vec<double, 3>(1.0, 1.0, 0.0) / std::sqrt(2.0)) <= 1e-15);
  BOOST_TEST(max_abs(t.v - (M_PI / 2) * Vec<double, 3>(-1.0, 1.0, 0.0) / std::sqrt(2.0)) <= 1e-15);
  // projection midpoint: v = 2 (q1 - q0)/|q0 + q1|
  const auto p = SphereMap(RetractionKind::projection, 0.5, "sphere-projection").inverse(q0, q1);
  BOOST_TEST(max_abs(p.v - 2.0 * (q1 - q0) / std::sqrt(2.0)) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(identities_of_the_product_maps) {
  // (S^2)^2 with each sphere map applied factor by factor.
  for (const auto& m : sphere_maps()) {
    if (m.theta() == 0.3) continue;
    expect_identities(SpherePowerMap<2>(m));
  }
}

namespace {

using J1 = ceres::Jet<double, 1>;

template <int R, int C>
Mat<double, R, C> values(const Mat<J1, R, C>& a) {
  Mat<double, R, C> out;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) out(i, j) = a(i, j).a;
  return out;
}
template <int R, int C>
Mat<double, R, C> derivatives(const Mat<J1, R, C>& a) {
  Mat<double, R, C> out;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) out(i, j) = a(i, j).v[0];
  return out;
}
template <int R, int C>
Mat<J1, R, C> moving(const Mat<double, R, C>& a, const Mat<double, R, C>& da) {
  Mat<J1, R, C> out;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) out(i, j) = J1(a(i, j), Vec<double, 1>::Constant(da(i, j)));
  return out;
}

}  // namespace

BOOST_AUTO_TEST_CASE(tangent_lift_on_the_sphere_is_the_papers_ex_3_5) {
  // Ex. 3.5: R_d(x, xi) = (x, cos|xi| x + sin|xi| xi/|xi|) (the exp map with theta = 0),
  // and its tangent lift R_d^T(x, xdot, xi, xidot) = (x, xdot; R^2(x, xi),
  // cos|xi| xdot + N xidot) in the embedding R^3, with N the derivative of R^2 in xi:
  //   N_ij = -sin|xi| x_i xi_j/|xi| + cos|xi| xi_i xi_j/|xi|^2 + sin|xi| (delta_ij |xi|^2 - xi_i xi_j)/|xi|^3.
  // (The paper prints the middle term over |xi|; differentiating cos|xi| x + sin|xi| xi/|xi|
  // gives |xi|^2, and the two agree only where |xi| = 1.) The generic path is the map
  // itself evaluated on Jets moving along (xdot, xidot), a tangent vector of TS^2 at (x, xi):
  // x.xdot = 0 and x.xidot + xdot.xi = 0.
  const SphereMap map(RetractionKind::exp, 0.0, "sphere-exp");
  std::mt19937 rng(35);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double worst = 0.0;
  for (int k = 0; k < 12; ++k) {
    const Vec<double, 3> x = Vec<double, 3>(U(rng), U(rng), U(rng)).normalized();
    const Vec<double, 3> xi = Sphere::tangent(x, Vec<double, 2>(2.0 * U(rng), 2.0 * U(rng)));  // |xi| up to 2.8
    const Vec<double, 3> xdot = Sphere::tangent(x, Vec<double, 2>(U(rng), U(rng)));
    Vec<double, 3> xidot = Vec<double, 3>(U(rng), U(rng), U(rng));
    xidot -= (x.dot(xidot) + xdot.dot(xi)) * x;  // x.xidot = -xdot.xi
    BOOST_REQUIRE(std::fabs(x.dot(xidot) + xdot.dot(xi)) <= 1e-15);

    const auto r = map(moving<3, 1>(x, xdot), moving<3, 1>(xi, xidot));
    const double n = xi.norm(), c = std::cos(n), s = std::sin(n);
    Mat<double, 3, 3> N;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        N(i, j) = -s * x[i] * xi[j] / n + c * xi[i] * xi[j] / (n * n) +
                  s * ((i == j ? n * n : 0.0) - xi[i] * xi[j]) / (n * n * n);
    const Vec<double, 3> q1 = c * x + s * xi / n, q1dot = c * xdot + N * xidot;
    worst = std::fmax(worst, max_abs(Vec<double, 3>(values<3, 1>(r.q0) - x)));
    worst = std::fmax(worst, max_abs(Vec<double, 3>(derivatives<3, 1>(r.q0) - xdot)));
    worst = std::fmax(worst, max_abs(Vec<double, 3>(values<3, 1>(r.q1) - q1)));
    worst = std::fmax(worst, max_abs(Vec<double, 3>(derivatives<3, 1>(r.q1) - q1dot)));
  }
  BOOST_TEST(worst <= 1e-14);
}

BOOST_AUTO_TEST_CASE(tangent_lift_of_the_cayley_map_is_the_papers_ex_3_6) {
  // Ex. 3.6: R_d,cay(A, X) = (A, A cay(A^T X)), cay(Y) = (I - Y/2)^{-1} (I + Y/2), and
  // R^T(A, Adot, X, Xdot) = (A, Adot; A cay(A^T X), M Adot + N Xdot) with
  //   M Adot = Adot cay(A^T X) + A dcay(A^T X)[Adot^T X],   N Xdot = A dcay(A^T X)[A^T Xdot],
  // the two partial derivatives of A cay(A^T X), where dcay(Y)[Z] = (I - Y/2)^{-1} (Z/2)
  // (I + cay(Y)) (differentiate (I - Y/2) cay(Y) = I + Y/2). dvm's map takes the body
  // velocity w, X = A hat(w); along A(t) = A exp(t hat(eta)), w(t) = w + t wdot, the
  // velocities are Adot = A hat(eta), Xdot = Adot hat(w) + A hat(wdot), and the generic
  // path is the map evaluated on Jets moving along (Adot, wdot).
  const SO3Map map(RetractionKind::cayley, 0.0, "so3-cayley");
  using M3 = Mat<double, 3, 3>;
  using V3 = Vec<double, 3>;
  const M3 I = M3::Identity();
  auto cay = [&](const M3& Y) { return M3((I - Y / 2).inverse() * (I + Y / 2)); };
  auto dcay = [&](const M3& Y, const M3& Z) { return M3((I - Y / 2).inverse() * (Z / 2) * (I + cay(Y))); };
  std::mt19937 rng(36);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double worst = 0.0;
  for (int k = 0; k < 12; ++k) {
    const M3 A = SO3::exp(V3(2 * U(rng), 2 * U(rng), 2 * U(rng)));
    const V3 w(2 * U(rng), 2 * U(rng), 2 * U(rng)), eta(U(rng), U(rng), U(rng)), wdot(U(rng), U(rng), U(rng));
    const M3 X = A * SO3::hat(w), Adot = A * SO3::hat(eta), Xdot = Adot * SO3::hat(w) + A * SO3::hat(wdot);

    const auto r = map(moving<3, 3>(A, Adot), moving<3, 1>(w, wdot));
    const M3 Y = A.transpose() * X;
    const M3 q1 = A * cay(Y);
    const M3 q1dot = Adot * cay(Y) + A * dcay(Y, Adot.transpose() * X) + A * dcay(Y, A.transpose() * Xdot);
    worst = std::fmax(worst, max_abs(M3(values<3, 3>(r.q0) - A)));
    worst = std::fmax(worst, max_abs(M3(derivatives<3, 3>(r.q0) - Adot)));
    worst = std::fmax(worst, max_abs(M3(values<3, 3>(r.q1) - q1)));
    worst = std::fmax(worst, max_abs(M3(derivatives<3, 3>(r.q1) - q1dot)));
  }
  BOOST_TEST(worst <= 1e-14);
}

namespace {

// The maps of Ex. 3.5 and 3.6 written in the embedding, as the paper computes their
// lifts: R^3 x R^3 -> R^3 x R^3, (x, xi) -> (x, cos|xi| x + sin|xi| xi/|xi|), and
// R^9 x R^9 -> R^9 x R^9, (A, X) -> (A, A cay(A^T X)) with cay(Y) = (I - Y/2)^{-1} (I + Y/2)
// for any 3 x 3 matrix Y (matrices stored column-major). The generic R^n cotangent lift
// (core/map_operations.h) applies to them unchanged.
struct EmbeddedSphereExp {
  [[maybe_unused]] static constexpr bool provides_inverse = false;  // (the map concept; no inverse is asked for)
  std::string name() const { return "embedded sphere exp"; }
  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& xi) const {
    return {x, Sphere::exp(x, xi)};
  }
};
struct EmbeddedCayley {
  [[maybe_unused]] static constexpr bool provides_inverse = false;
  std::string name() const { return "embedded cayley"; }
  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& a, const Vec<T, N>& x) const {
    Mat<T, 3, 3> A, X, L, R;
    for (int i = 0; i < 9; ++i) {
      A(i) = a[i];
      X(i) = x[i];
    }
    const Mat<T, 3, 3> Y = A.transpose() * X;
    for (int i = 0; i < 9; ++i) {
      L(i) = (i % 4 == 0 ? T(1.0) : T(0.0)) - 0.5 * Y(i);
      R(i) = (i % 4 == 0 ? T(1.0) : T(0.0)) + 0.5 * Y(i);
    }
    Mat<T, 3, 3> C;  // cay(Y) = L^{-1} R, column by column
    for (int j = 0; j < 3; ++j) C.col(j) = solve_dense<T, 3, 3>(L, Vec<T, 3>(R.col(j)));
    const Mat<T, 3, 3> B = A * C;
    Vec<T, N> b;
    for (int i = 0; i < 9; ++i) b[i] = B(i);
    return {a, b};
  }
};

}  // namespace

BOOST_AUTO_TEST_CASE(cotangent_lifts_are_the_papers_ex_3_5_and_3_6) {
  // The paper's cotangent lifts, from DR = [[I, 0], [M, N]] and its inverse
  // [[I, 0], [-N^{-1} M, N^{-1}]]:
  //   R_d^{T*}(q, p, qdot, pdot) = (q, -pdot + p N^{-1} M; R^2(q, qdot), p N^{-1})
  // (p a row covector), with M = cos|xi| I and N as in the tangent-lift test above on
  // S^2 (Ex. 3.5), and M Adot = Adot cay(Y) + A dcay(Y)[Adot^T X],
  // N Xdot = A dcay(Y)[A^T Xdot], Y = A^T X on SO(3) (Ex. 3.6), here at X = qdot. The
  // generic path is dvm::cotangent_lift of the maps written in the embedding.
  using M3 = Mat<double, 3, 3>;
  using V3 = Vec<double, 3>;
  std::mt19937 rng(37);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double worst_sphere = 0.0, worst_cayley = 0.0;
  for (int k = 0; k < 12; ++k) {
    const V3 x = V3(U(rng), U(rng), U(rng)).normalized();
    const V3 xi = Sphere::tangent(x, Vec<double, 2>(2.0 * U(rng), 2.0 * U(rng)));
    const V3 p(U(rng), U(rng), U(rng)), pdot(U(rng), U(rng), U(rng));
    const double n = xi.norm(), c = std::cos(n), s = std::sin(n);
    M3 N;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        N(i, j) = -s * x[i] * xi[j] / n + c * xi[i] * xi[j] / (n * n) +
                  s * ((i == j ? n * n : 0.0) - xi[i] * xi[j]) / (n * n * n);
    const V3 pNinv = N.transpose().lu().solve(p);  // the row p N^{-1}, as a column
    const auto r = cotangent_lift(EmbeddedSphereExp{}, x, p, xi, pdot);
    worst_sphere = std::fmax(worst_sphere, max_abs(V3(r.q0 - x)));
    worst_sphere = std::fmax(worst_sphere, max_abs(V3(r.p0 - (-pdot + c * pNinv))));
    worst_sphere = std::fmax(worst_sphere, max_abs(V3(r.q1 - (c * x + s * xi / n))));
    worst_sphere = std::fmax(worst_sphere, max_abs(V3(r.p1 - pNinv)));
  }
  const M3 I = M3::Identity();
  auto cay = [&](const M3& Y) { return M3((I - Y / 2).inverse() * (I + Y / 2)); };
  auto dcay = [&](const M3& Y, const M3& Z) { return M3((I - Y / 2).inverse() * (Z / 2) * (I + cay(Y))); };
  using V9 = Vec<double, 9>;
  using M9 = Mat<double, 9, 9>;
  auto flat = [](const M3& a) { return V9(Eigen::Map<const V9>(a.data())); };
  for (int k = 0; k < 12; ++k) {
    const M3 A = SO3::exp(V3(2 * U(rng), 2 * U(rng), 2 * U(rng)));
    const M3 X = A * SO3::hat(V3(2 * U(rng), 2 * U(rng), 2 * U(rng)));
    const M3 Y = A.transpose() * X;
    M9 Mb, Nb;  // the blocks, column by column from the closed forms
    for (int e = 0; e < 9; ++e) {
      M3 E = M3::Zero();
      E(e) = 1.0;
      Mb.col(e) = flat(E * cay(Y) + A * dcay(Y, E.transpose() * X));
      Nb.col(e) = flat(A * dcay(Y, A.transpose() * E));
    }
    V9 p, pdot;
    for (int i = 0; i < 9; ++i) {
      p[i] = U(rng);
      pdot[i] = U(rng);
    }
    const V9 pNinv = Nb.transpose().lu().solve(p);
    const V9 p0 = -pdot + Mb.transpose() * pNinv;  // the row p N^{-1} M - pdot
    const auto r = cotangent_lift(EmbeddedCayley{}, flat(A), p, flat(X), pdot);
    worst_cayley = std::fmax(worst_cayley, max_abs(V9(r.q0 - flat(A))));
    worst_cayley = std::fmax(worst_cayley, max_abs(V9(r.p0 - p0)));
    worst_cayley = std::fmax(worst_cayley, max_abs(V9(r.q1 - flat(A * cay(Y)))));
    worst_cayley = std::fmax(worst_cayley, max_abs(V9(r.p1 - pNinv)));
  }
  BOOST_TEST_MESSAGE("Ex. 3.5 cotangent lift vs generic: " << worst_sphere << "; Ex. 3.6: " << worst_cayley);
  BOOST_TEST(worst_sphere <= 1e-13);
  BOOST_TEST(worst_cayley <= 1e-13);
}
