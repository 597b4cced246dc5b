// Products of manifolds (core/product_manifold.h) and the rigid body moving in space
// on R^3 x SO(3): identity checks of the product maps, the step staying on the
// manifold, Noether (linear and angular momentum where the symmetry holds), the
// centre of mass of a free body moving on its straight line, and the measured order
// against an independent reference.
#define BOOST_TEST_MODULE product
#include <boost/test/unit_test.hpp>

#include <array>

#include "core/manifold_checks.h"
#include "mechanics/product_systems.h"
#include "solvers/manifold_step.h"
#include "tests/verification/common.h"

using namespace dvm;

namespace {
using V3 = Vec<double, 3>;
using V6 = Vec<double, 6>;
using V12 = Vec<double, 12>;
using M3 = Mat<double, 3, 3>;
using BodyMap = ProductMap<EuclideanThetaMap<3>, SO3Map>;

BodyMap body_map(double theta, RetractionKind k = RetractionKind::exp) {
  return BodyMap(EuclideanThetaMap<3>(theta, "theta"), SO3Map(k, theta, "so3"));
}

template <class Map>
void expect_identities(const Map& map) {
  const MapCheckReport r = check_manifold_map(map, 8);
  BOOST_TEST_CONTEXT(map.name() << " symmetric=" << map.symmetric()) {
    for (const auto& name : identity_names()) BOOST_TEST(r.residual(name) <= 1e-12, name << " = " << r.residual(name));
    BOOST_TEST(r.residual("manifold_round_trip") <= 1e-13);
    BOOST_TEST(r.residual("closed_form_vs_newton") <= 1e-12);
    if (map.symmetric())
      BOOST_TEST(r.residual("adjoint_difference") <= 1e-12);
    else
      BOOST_TEST(r.residual("adjoint_difference") > 1e-3);
  }
}

struct Run {
  RunSummary run;
  V12 q;
  V6 p;
  double max_defect = 0, max_dp = 0, max_dJ = 0, max_dJ3 = 0, max_dE = 0, max_line = 0, max_r = 0;
  double max_dE_early = 0;  // max |E - E0| over t <= t_early
};

// Integrates from (r0, R0) with velocity (rdot0, w0) and records the invariants.
template <class Map>
Run run_body(const RigidBodyInSpace& L, const Map& R, double h, std::int64_t steps, const V3& r0, const M3& R0,
             const V6& v0, double t_early = 0.0) {
  const ManifoldStep<RigidBodyInSpace, Map> S(L, R, h);
  Run out;
  out.q = RigidBodyInSpace::point(r0, R0);
  out.p = manifold_legendre(L, out.q, v0);
  const V3 P0 = RigidBodyInSpace::linear_momentum(out.q, out.p), J0 = RigidBodyInSpace::angular_momentum(out.q, out.p);
  const double E0 = manifold_energy(L, out.q, v0);
  out.run = integrate(S, 0.0, out.q, out.p, v0, steps, [&](std::int64_t, double t, const V12& x, const V6& p,
                                                                    const StepSummary&) {
    out.max_defect = std::fmax(out.max_defect, SpaceBody::point_defect(x));
    out.max_dp = std::fmax(out.max_dp, max_abs(V3(RigidBodyInSpace::linear_momentum(x, p) - P0)));
    const V3 J = RigidBodyInSpace::angular_momentum(x, p);
    out.max_dJ = std::fmax(out.max_dJ, max_abs(V3(J - J0)));
    out.max_dJ3 = std::fmax(out.max_dJ3, std::fabs(J[2] - J0[2]));
    const double dE = std::fabs(manifold_energy(L, x, manifold_legendre_inverse(L, x, p)) - E0);
    out.max_dE = std::fmax(out.max_dE, dE);
    if (t <= t_early) out.max_dE_early = std::fmax(out.max_dE_early, dE);
    // a free centre of mass moves on r0 + t p0/m
    out.max_line = std::fmax(out.max_line, max_abs(V3(RigidBodyInSpace::position(x) - r0 - t * P0 / L.m)));
    out.max_r = std::fmax(out.max_r, RigidBodyInSpace::position(x).norm());
  });
  return out;
}

const V3 r0(0.3, -0.2, 1.0);
const M3 R0 = SO3::exp(V3(0.3, -0.7, 1.1));
const V6 v0 = (V6() << 0.5, 0.1, -0.3, 0.05, 1.0, 0.02).finished();

}  // namespace

BOOST_AUTO_TEST_CASE(identities_of_the_product_maps) {
  for (double theta : {0.5, 0.0}) {
    expect_identities(body_map(theta));
    expect_identities(body_map(theta, RetractionKind::cayley));
    expect_identities(ProductMap<SphereMap, EuclideanThetaMap<2>>(SphereMap(RetractionKind::projection, theta, "sp"),
                                                                   EuclideanThetaMap<2>(theta, "theta")));
  }
}

BOOST_AUTO_TEST_CASE(free_body_conserves_linear_and_angular_momentum) {
  // k = 0, g = 0: every translation and rotation is a symmetry. Round-off: the centre of
  // mass travels to |r| ~ 25 and J = r x p + R Pi is formed from it, so both are held to
  // a few ulp per step of their size (|r| |p| + |Pi|), not of |J|.
  const RigidBodyInSpace L(2.0, V3(1.0, 2.0, 3.0));
  const int steps = 5000;
  const double eps = 2.2e-16;
  for (const BodyMap& R : {body_map(0.5), body_map(0.5, RetractionKind::cayley), body_map(0.0)}) {
    const Run r = run_body(L, R, 0.01, steps, r0, R0, v0);
    const V6 p0 = manifold_legendre(L, RigidBodyInSpace::point(r0, R0), v0);
    const double size = r.max_r * p0.head<3>().norm() + p0.tail<3>().norm();
    BOOST_TEST_CONTEXT(R.name() << " symmetric=" << R.symmetric()) {
      BOOST_TEST(!r.run.failed);
      BOOST_TEST_MESSAGE(R.name() << " symmetric=" << R.symmetric() << ": " << steps << " steps, |dP| " << r.max_dp
                                  << ", |dJ| " << r.max_dJ << " (" << r.max_dJ / (steps * eps * size)
                                  << " ulp per step), defect " << r.max_defect << ", off the line " << r.max_line
                                  << " (max |r| " << r.max_r << "), |dE| " << r.max_dE);
      BOOST_TEST(r.max_defect <= 1e-14);
      BOOST_TEST(r.max_dp <= 1e-14);
      BOOST_TEST(r.max_dJ <= steps * eps * size);
      BOOST_TEST(r.max_line <= steps * eps * r.max_r);
    }
  }
}

BOOST_AUTO_TEST_CASE(body_on_a_spring_under_gravity_conserves_vertical_angular_momentum) {
  // k > 0, g > 0: only rotations about the vertical through the origin remain.
  // Energy: the step is symplectic (a variational integrator), so |E - E0| stays O(h^p)
  // over the whole run, p the map's order (backward error analysis, GNI IX.8). Checked
  // by scaling: the largest error over t <= 25 at h = 0.005 (from the long run) and at
  // h/2 must differ by 2^p, to within the next term of the expansion (relative O(h^2)
  // for the symmetric map, whose expansion is even: log2 of the ratio within 0.02;
  // O(h) for the first-order one: within 0.1; measured 1.99994 and 1.0086); and the
  // long run to t = 100 must stay at that level (no drift: at most 1.5 times its
  // largest error up to t = 25).
  const RigidBodyInSpace L(1.0, V3(1.0, 1.5, 0.7), 9.81, 20.0, V3(0.1, 0.2, 0.3));
  const double h = 0.005, t_early = 25.0;
  for (const BodyMap& R : {body_map(0.5), body_map(0.0, RetractionKind::cayley)}) {
    const Run r = run_body(L, R, h, 20000, r0, R0, v0, t_early);
    const Run r2 = run_body(L, R, h / 2, 10000, r0, R0, v0, t_early);
    const double measured = std::log2(r.max_dE_early / r2.max_dE_early);
    BOOST_TEST_CONTEXT(R.name() << " symmetric=" << R.symmetric()) {
      BOOST_TEST(!r.run.failed);
      BOOST_TEST(!r2.run.failed);
      BOOST_TEST_MESSAGE(R.name() << ": 2e4 steps, |dJ3| " << r.max_dJ3 << ", |dJ| " << r.max_dJ << ", |dP| "
                                  << r.max_dp << ", |dE| " << r.max_dE << " (to t = 25: " << r.max_dE_early
                                  << ", at h/2 " << r2.max_dE_early << ": falls by 2^" << measured << "), defect "
                                  << r.max_defect);
      BOOST_TEST(r.max_defect <= 1e-14);
      BOOST_TEST(r.max_dJ3 <= 1e-12);
      BOOST_TEST(r.max_dJ >= 1e-3);  // the other components are not conserved
      BOOST_TEST(std::fabs(measured - R.order()) <= (R.symmetric() ? 0.02 : 0.1));
      BOOST_TEST(r.max_dE <= 1.5 * r.max_dE_early);
    }
  }
}

namespace {

// Independent reference: long-double RK4 on the Newton-Euler equations
//   m r'' = F,  F = -m g e3 - k (r + R b);   q' = q (0, w)/2;
//   I w' = (I w) x w + b x (R^T F_spring),   F_spring = -k (r + R b).
void body_reference(const RigidBodyInSpace& L, double t_end, const V3& r, const M3& R, const V6& v, V3& r1, M3& R1,
                    V6& v1) {
  using LD = long double;
  const Vec<double, 4> q0 = SO3::to_quaternion(R);
  std::array<LD, 13> y{r[0], r[1], r[2], q0[0], q0[1], q0[2], q0[3], v[0], v[1], v[2], v[3], v[4], v[5]};
  auto f = [&](const std::array<LD, 13>& s) {
    std::array<LD, 13> d{};
    const LD w = s[3], x = s[4], yq = s[5], z = s[6];
    LD Rm[3][3] = {{1 - 2 * (yq * yq + z * z), 2 * (x * yq - w * z), 2 * (x * z + w * yq)},
                   {2 * (x * yq + w * z), 1 - 2 * (x * x + z * z), 2 * (yq * z - w * x)},
                   {2 * (x * z - w * yq), 2 * (yq * z + w * x), 1 - 2 * (x * x + yq * yq)}};
    LD a[3], Fs[3], Fb[3];
    for (int i = 0; i < 3; ++i) a[i] = s[i] + Rm[i][0] * L.b[0] + Rm[i][1] * L.b[1] + Rm[i][2] * L.b[2];
    for (int i = 0; i < 3; ++i) Fs[i] = -(LD)L.k * a[i];
    for (int i = 0; i < 3; ++i) Fb[i] = Rm[0][i] * Fs[0] + Rm[1][i] * Fs[1] + Rm[2][i] * Fs[2];
    for (int i = 0; i < 3; ++i) {
      d[i] = s[7 + i];
      d[7 + i] = (Fs[i] - (i == 2 ? (LD)L.m * L.g : 0)) / L.m;
    }
    const LD w0 = s[10], w1 = s[11], w2 = s[12];
    d[3] = -0.5L * (x * w0 + yq * w1 + z * w2);
    d[4] = 0.5L * (w * w0 + yq * w2 - z * w1);
    d[5] = 0.5L * (w * w1 + z * w0 - x * w2);
    d[6] = 0.5L * (w * w2 + x * w1 - yq * w0);
    const LD I0 = L.inertia[0], I1 = L.inertia[1], I2 = L.inertia[2];
    const LD b0 = L.b[0], b1 = L.b[1], b2 = L.b[2];
    d[10] = ((I1 * w1) * w2 - (I2 * w2) * w1 + (b1 * Fb[2] - b2 * Fb[1])) / I0;
    d[11] = ((I2 * w2) * w0 - (I0 * w0) * w2 + (b2 * Fb[0] - b0 * Fb[2])) / I1;
    d[12] = ((I0 * w0) * w1 - (I1 * w1) * w0 + (b0 * Fb[1] - b1 * Fb[0])) / I2;
    return d;
  };
  verification::rk4(f, y, t_end, 40000);
  r1 = V3((double)y[0], (double)y[1], (double)y[2]);
  Vec<double, 4> q((double)y[3], (double)y[4], (double)y[5], (double)y[6]);
  R1 = SO3::from_quaternion(q / q.norm());
  for (int i = 0; i < 6; ++i) v1[i] = (double)y[7 + i];
}

}  // namespace

BOOST_AUTO_TEST_CASE(measured_orders_on_the_body_on_a_spring) {
  // Error of (r, R) at t = 1 against the reference; steps 1/20 ... 1/160.
  const RigidBodyInSpace L(1.0, V3(1.0, 1.5, 0.7), 9.81, 20.0, V3(0.1, 0.2, 0.3));
  V3 rr;
  M3 Rr;
  V6 vr;
  body_reference(L, 1.0, r0, R0, v0, rr, Rr, vr);
  for (const BodyMap& R : {body_map(0.5), body_map(0.5, RetractionKind::cayley), body_map(0.0)}) {
    std::vector<double> hs, errs;
    for (int steps : {20, 40, 80, 160}) {
      const Run r = run_body(L, R, 1.0 / steps, steps, r0, R0, v0);
      BOOST_REQUIRE(!r.run.failed);
      hs.push_back(1.0 / steps);
      errs.push_back(std::fmax(max_abs(V3(RigidBodyInSpace::position(r.q) - rr)),
                               max_abs(M3(RigidBodyInSpace::attitude(r.q) - Rr))));
    }
    const double order = verification::fit_order(hs, errs);
    BOOST_TEST_MESSAGE(R.name() << " symmetric=" << R.symmetric() << ": order " << order << " (errors " << errs[0]
                                << " ... " << errs.back() << ")");
    BOOST_TEST(std::fabs(order - R.order()) <= 0.1);
  }
}
