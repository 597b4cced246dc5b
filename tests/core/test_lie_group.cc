// A general matrix Lie group (core/lie_group.h): the exponential against closed forms
// on so(3), se(3) and sl(2), its derivatives at zero, the logarithm, the
// group-exponential maps against the specialised SO(3) maps, and every identity check
// of the manifold maps on SO(3), SE(3) and SL(2).
#define BOOST_TEST_MODULE core_lie_group
#include <boost/test/unit_test.hpp>

#include <random>

#include "core/lie_group.h"
#include "core/manifold_checks.h"

using namespace dvm;

namespace {
using V3 = Vec<double, 3>;
using V6 = Vec<double, 6>;
using M3 = Mat<double, 3, 3>;
using G3 = MatrixLieGroup<so3_algebra>;
using GE = MatrixLieGroup<se3_algebra>;
using GS = MatrixLieGroup<sl2_algebra>;
}  // namespace

BOOST_AUTO_TEST_CASE(exponential_against_closed_forms) {
  // so(3): Rodrigues' formula (SO3::exp), small to large angles
  for (const V3& w : {V3(1e-9, -2e-9, 3e-9), V3(1e-3, 0.0, -2e-3), V3(0.3, -0.7, 1.1), V3(2.0, 1.5, -1.0)}) {
    const double d = max_abs(M3(G3::exp(w) - SO3::exp(w)));
    BOOST_TEST_MESSAGE("so(3) |w| = " << w.norm() << ": |exp - Rodrigues| " << d);
    BOOST_TEST(d <= 4e-15);
  }
  // se(3): exp(hat(omega, u)) = [[exp(hat omega), V u], [0, 1]],
  // V = I + (1 - cos t)/t^2 W + (t - sin t)/t^3 W^2, t = |omega|
  for (const V6& xi : {(V6() << 0.3, -0.7, 1.1, 0.5, -0.2, 0.9).finished(),
                       (V6() << 1e-8, 0.0, 2e-8, 1.0, 2.0, -3.0).finished(),
                       (V6() << 2.5, 0.5, -0.4, -1.0, 0.3, 0.2).finished()}) {
    const V3 om = xi.head<3>(), u = xi.tail<3>();
    const double t = om.norm();
    const M3 W = SO3::hat(om);
    const double a = t < 1e-4 ? 0.5 : (1 - std::cos(t)) / (t * t), b = t < 1e-4 ? 1.0 / 6.0 : (t - std::sin(t)) / (t * t * t);
    const M3 V = M3::Identity() + a * W + b * W * W;
    Mat<double, 4, 4> expect = Mat<double, 4, 4>::Identity();
    expect.topLeftCorner<3, 3>() = SO3::exp(om);
    expect.topRightCorner<3, 1>() = V * u;
    const double d = max_abs(Mat<double, 4, 4>(GE::exp(xi) - expect));
    BOOST_TEST_MESSAGE("se(3): |exp - closed form| " << d);
    BOOST_TEST(d <= 1e-14);
  }
  // sl(2): X^2 = delta I with delta = a^2 + b c, so
  // exp(X) = cosh(r) I + sinh(r)/r X (delta = r^2 > 0) or cos(r) I + sin(r)/r X (delta = -r^2)
  for (const V3& xi : {V3(0.4, -0.3, 0.8), V3(0.1, 1.5, -2.0), V3(1.2, 0.7, 0.9)}) {
    const Mat<double, 2, 2> X = sl2_algebra::hat(xi);
    const double delta = xi[0] * xi[0] + xi[1] * xi[2], r = std::sqrt(std::fabs(delta));
    const Mat<double, 2, 2> expect = delta > 0
                                         ? Mat<double, 2, 2>(std::cosh(r) * Mat<double, 2, 2>::Identity() + std::sinh(r) / r * X)
                                         : Mat<double, 2, 2>(std::cos(r) * Mat<double, 2, 2>::Identity() + std::sin(r) / r * X);
    const Mat<double, 2, 2> E = GS::exp(xi);
    BOOST_TEST(max_abs(Mat<double, 2, 2>(E - expect)) <= 1e-14);
    BOOST_TEST(GS::point_defect(E) <= 1e-14);
  }
}

BOOST_AUTO_TEST_CASE(exponential_is_differentiable_at_zero_and_log_inverts_it) {
  // d/dxi_i exp(hat xi) at xi = 0 is the generator E_i (a constant small-norm branch
  // would give zero); at xi = 1e-9 e_1 the derivative is still E_1 to 1e-9.
  using D = ceres::Jet<double, 6>;
  for (double s : {0.0, 1e-9}) {
    Vec<D, 6> x;
    for (int i = 0; i < 6; ++i) x[i] = seed<double, 6>(i == 0 ? s : 0.0, i);
    const Mat<D, 4, 4> E = GE::exp(x);
    double d = 0.0;
    for (int i = 0; i < 6; ++i) {
      V6 e = V6::Zero();
      e[i] = 1.0;
      const Mat<double, 4, 4> Ei = se3_algebra::hat(e);
      for (int k = 0; k < 16; ++k) d = std::fmax(d, std::fabs(E(k).v[i] - Ei(k)));
    }
    BOOST_TEST(d <= 2e-9);
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double rt = 0.0;
  for (int k = 0; k < 20; ++k) {
    V6 xi;
    for (int i = 0; i < 6; ++i) xi[i] = 1.2 * U(rng);
    rt = std::fmax(rt, max_abs(V6(GE::log(GE::exp(xi)) - xi)));
    V3 w(U(rng), U(rng), U(rng));
    rt = std::fmax(rt, max_abs(V3(G3::log(G3::exp(w)) - SO3::log(SO3::exp(w)))));
  }
  BOOST_TEST(rt <= 1e-13);
}

BOOST_AUTO_TEST_CASE(group_exponential_maps_agree_with_the_so3_maps) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (double theta : {0.5, 0.0, 0.3}) {
    const LieGroupExpMap<so3_algebra> G(theta, "group-exp");
    const SO3Map S(RetractionKind::exp, theta, "so3-exp");
    double d = 0.0, di = 0.0;
    for (int k = 0; k < 16; ++k) {
      const M3 R = SO3::exp(V3(2 * U(rng), 2 * U(rng), 2 * U(rng)));
      const V3 w(U(rng), U(rng), U(rng));
      const auto a = G(R, w);
      const auto b = S(R, w);
      d = std::fmax(d, std::fmax(max_abs(M3(a.q0 - b.q0)), max_abs(M3(a.q1 - b.q1))));
      const auto ia = G.inverse(b.q0, b.q1);
      const auto ib = S.inverse(b.q0, b.q1);
      di = std::fmax(di, std::fmax(max_abs(M3(ia.x - ib.x)), max_abs(V3(ia.v - ib.v))));
    }
    BOOST_TEST_MESSAGE("theta " << theta << ": |R_d group - R_d so3| " << d << ", inverses " << di);
    BOOST_TEST(d <= 1e-14);
    BOOST_TEST(di <= 1e-13);
  }
}

namespace {
template <class Map>
void expect_identities(const Map& map) {
  const MapCheckReport r = check_manifold_map(map, 8);
  BOOST_TEST_CONTEXT(Map::Manifold::name << " theta=" << map.theta()) {
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

BOOST_AUTO_TEST_CASE(identities_of_the_group_exponential_maps) {
  for (double theta : {0.5, 0.0}) {
    expect_identities(LieGroupExpMap<so3_algebra>(theta, "group-exp"));
    expect_identities(LieGroupExpMap<se3_algebra>(theta, "group-exp"));
    expect_identities(LieGroupExpMap<sl2_algebra>(theta, "group-exp"));
  }
}
