// Constrained steps (solvers/constrained_step.h, mechanics/written_constraints.h), and
// the derivatives of the forced steps in their control inputs: the
// pendulum in Cartesian coordinates, x^2 + y^2 = l^2, against the same pendulum in its
// angle; orders of the constrained theta steps and their compositions; the constraint
// and its hidden constraint kept to round-off at every step; the energy bounded; a
// support that moves (a constraint in t); the projection of a momentum onto the hidden
// constraint; steps that allocate nothing.
#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<long> news{0};
}
void* operator new(std::size_t n) {
  ++news;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

#define BOOST_TEST_MODULE constrained
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <tuple>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/written_constraints.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_force.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/composition.h"
#include "solvers/constrained_galerkin_step.h"
#include "solvers/constrained_hamiltonian_step.h"
#include "solvers/constrained_step.h"
#include "solvers/dynamic_galerkin_step.h"
#include "solvers/integrate.h"
#include "tests/verification/common.h"

using namespace dvm;
using Eigen::VectorXd;

namespace {

constexpr double kM = 1.3, kL = 0.9, kG = 9.81;

std::shared_ptr<WrittenSystem> system_of(std::vector<std::string> coords, const std::string& L,
                                         const std::vector<std::string>& constraints = {},
                                         const std::vector<std::pair<int, std::string>>& forces = {}) {
  auto s = std::make_shared<WrittenSystem>();
  s->name = "written";
  s->coordinates = std::move(coords);
  s->params = {{"m", kM}, {"l", kL}, {"g", kG}, {"A", 0.2}, {"w", 2.5}, {"c", 0.3}};
  s->check_names();
  s->lagrangian = Expression::parse(L, s->symbols(WrittenSystem::Kind::lagrangian));
  for (const auto& g : constraints) s->constraints.push_back(Expression::parse(g, s->symbols(WrittenSystem::Kind::constraint)));
  for (const auto& [i, f] : forces) s->forces.emplace_back(i, Expression::parse(f, s->symbols(WrittenSystem::Kind::force)));
  return s;
}

// The pendulum of mass m on a rod of length l, in Cartesian coordinates and in its angle
// a from the downward vertical (x = l sin a, y = -l cos a).
const auto cartesian = system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + y^2 - l^2"});
const auto angle = system_of({"a"}, "m*l^2*a_dot^2/2 + m*g*l*cos(a)");

using Step = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints>;

struct State {
  VectorXd q, p, v;
};
// The Cartesian state of the angle state (a, a_dot).
State cartesian_state(double a, double w) {
  State s{VectorXd(2), VectorXd(2), VectorXd(2)};
  s.q << kL * std::sin(a), -kL * std::cos(a);
  s.v << kL * std::cos(a) * w, kL * std::sin(a) * w;
  s.p = kM * s.v;
  return s;
}

// Central differences (eps 1e-6) of the map (q0, p0) -> (q1, p1) that `advance(q, p, dq,
// dp)` takes one step of (dq, dp: the increments).
template <class Advance>
Eigen::MatrixXd central_differences(const Advance& advance, const VectorXd& q0, const VectorXd& p0) {
  const Eigen::Index n = q0.size();
  Eigen::MatrixXd F(2 * n, 2 * n);
  const double eps = 1e-6;
  for (Eigen::Index j = 0; j < 2 * n; ++j) {
    VectorXd qa = q0, pa = p0, qb = q0, pb = p0, da, ea, db, eb;
    (j < n ? qa[j] : pa[j - n]) += eps;
    (j < n ? qb[j] : pb[j - n]) -= eps;
    advance(qa, pa, da, ea);
    advance(qb, pb, db, eb);
    F.col(j) << (da - db + qa - qb) / (2 * eps), (ea - eb + pa - pb) / (2 * eps);
  }
  return F;
}
// J = [0 I; -I 0] of 2n x 2n
// derivatives(t, q, p, dq, A, &B): A and B from one differentiation, as derivative()
// and control_derivative() (B, given) give them one at a time, to round-off
template <class S>
void check_joint_derivatives(const S& step, double t, const VectorXd& q, const VectorXd& p, const VectorXd& dq,
                             const Eigen::MatrixXd& B) {
  Eigen::MatrixXd A1, A2, B2;
  BOOST_REQUIRE(step.derivative(t, q, p, dq, A1));
  BOOST_REQUIRE(step.derivatives(t, q, p, dq, A2, &B2));
  BOOST_REQUIRE(A2.rows() == A1.rows() && A2.cols() == A1.cols());
  BOOST_REQUIRE(B2.rows() == B.rows() && B2.cols() == B.cols());
  BOOST_TEST((A2 - A1).lpNorm<Eigen::Infinity>() <= 1e-13 * A1.lpNorm<Eigen::Infinity>());
  BOOST_TEST((B2 - B).lpNorm<Eigen::Infinity>() <= 1e-13 * B.lpNorm<Eigen::Infinity>());
}

Eigen::MatrixXd J_of(Eigen::Index n) {
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  J.topRightCorner(n, n) = Eigen::MatrixXd::Identity(n, n);
  J.bottomLeftCorner(n, n) = -Eigen::MatrixXd::Identity(n, n);
  return J;
}

// The double pendulum in Cartesian coordinates (rods l and 1.1, masses m and 0.7), and a
// state on its constraints moving along them.
std::shared_ptr<WrittenSystem> cartesian_double() {
  return system_of({"x1", "y1", "x2", "y2"},
                   "m*(x1_dot^2 + y1_dot^2)/2 + 0.7*(x2_dot^2 + y2_dot^2)/2 - g*(m*y1 + 0.7*y2)",
                   {"x1^2 + y1^2 - l^2", "(x2 - x1)^2 + (y2 - y1)^2 - 1.1^2"});
}
void cartesian_double_state(VectorXd& q, VectorXd& p) {
  const double a = 0.8, b = 1.9, wa = 0.6, wb = -0.4;
  q.resize(4);
  p.resize(4);
  q << kL * std::sin(a), -kL * std::cos(a), kL * std::sin(a) + 1.1 * std::sin(b), -kL * std::cos(a) - 1.1 * std::cos(b);
  VectorXd v(4);
  v << kL * std::cos(a) * wa, kL * std::sin(a) * wa, kL * std::cos(a) * wa + 1.1 * std::cos(b) * wb,
      kL * std::sin(a) * wa + 1.1 * std::sin(b) * wb;
  p << kM * v[0], kM * v[1], 0.7 * v[2], 0.7 * v[3];
}
// A damped pendulum whose support moves as A cos(w t) (a constraint in t), and a state on
// its circle at t0, moving with the support.
std::shared_ptr<WrittenSystem> damped_on_moving_support() {
  return system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + (y - A*cos(w*t))^2 - l^2"},
                   {{0, "-c*x_dot"}, {1, "-c*(y_dot + A*w*sin(w*t))"}});
}
void moving_support_state(double t0, VectorXd& q, VectorXd& p) {
  const double ys = 0.2 * std::cos(2.5 * t0);
  q.resize(2);
  p.resize(2);
  q << kL * std::sin(0.7), ys - kL * std::cos(0.7);
  p << kM * 0.3 * std::cos(0.7), kM * (0.3 * std::sin(0.7) - 0.2 * 2.5 * std::sin(2.5 * t0));
}

Step step_of(double h, double theta = 0.5, const std::shared_ptr<WrittenSystem>& s = cartesian) {
  return Step(WrittenDynamic(s), ThetaMap(theta), h, std::make_shared<WrittenConstraints>(s), {}, MomentumMap::constant);
}
template <class S>
ComposedStep<S> composed(const S& base, const char* scheme) {
  const double h = base.step_size();
  return ComposedStep<S>(
      h, substeps(find_composition(scheme), base.map().symmetric()),
      [&](double hk) { return S(base.lagrangian(), base.map(), hk, std::make_shared<WrittenConstraints>(cartesian), {}, MomentumMap::constant); },
      [&](double hk) {
        return S(base.lagrangian(), base.map(), hk, std::make_shared<WrittenConstraints>(cartesian), {}, MomentumMap::constant).adjoint();
      });
}

// The angle pendulum at time T from (a0, w0), to about 1e-16: Galerkin Gauss s = 6
// (order 12) with h = 0.01.
void reference(double a0, double w0, double T, double& a, double& w) {
  const WrittenDynamic L(angle);
  const DynamicGalerkinStep<WrittenDynamic> S(L, QuadratureKind::gauss, 6, 0.01);
  VectorXd q(1), p(1), v(1);
  q << a0;
  v << w0;
  p << kM * kL * kL * w0;
  const RunSummary run = integrate(S, 0.0, q, p, v, std::lround(T / 0.01), [](auto&&...) {});
  BOOST_REQUIRE(!run.failed);
  a = q[0];
  w = p[0] / (kM * kL * kL);
}

template <class S>
double error_at(const S& step, double T, double a0, double w0, double a, double w) {
  State s = cartesian_state(a0, w0);
  const RunSummary run = integrate(step, 0.0, s.q, s.p, s.v, std::lround(T / step.step_size()), [](auto&&...) {});
  BOOST_TEST(!run.failed, run.failure.message);
  const State e = cartesian_state(a, w);
  return std::fmax((s.q - e.q).lpNorm<Eigen::Infinity>(), (s.p - e.p).lpNorm<Eigen::Infinity>());
}

}  // namespace

// The constrained theta steps converge to the angle pendulum's trajectory at their
// orders: the midpoint (RATTLE-type) 2, theta = 0.3 composed with its adjoint 2 (the
// adjoint of the constrained theta step is the constrained (1 - theta) step), the triple
// jump 4, Kahan and Li's order 8 composition 8; explicit Euler, not symmetric, 1.
BOOST_AUTO_TEST_CASE(constrained_steps_converge_to_the_angle_pendulum_at_their_orders) {
  const double a0 = 1.1, w0 = 0.4, T = 1.0;
  double a, w;
  reference(a0, w0, T, a, w);
  std::vector<double> hs, mid, euler, verlet, jump, eight;
  for (int k = 0; k < 4; ++k) {
    const double h = 0.05 / std::pow(2.0, k);
    hs.push_back(h);
    mid.push_back(error_at(step_of(h), T, a0, w0, a, w));
    euler.push_back(error_at(step_of(h / 16, 0.0), T, a0, w0, a, w));
    verlet.push_back(error_at(composed(step_of(h, 0.3), "stormer-verlet"), T, a0, w0, a, w));
    jump.push_back(error_at(composed(step_of(h), "triple-jump:4"), T, a0, w0, a, w));
  }
  std::vector<double> h8, e8;
  for (int k = 0; k < 3; ++k) {  // (from h = 0.2: at h = 0.4, h omega = 1.3, not yet asymptotic)
    const double h = 0.2 / std::pow(2.0, k);
    h8.push_back(h);
    e8.push_back(error_at(composed(step_of(h), "kahan-li8"), T, a0, w0, a, w));
  }
  const double o_mid = verification::fit_order(hs, mid), o_euler = verification::fit_order(hs, euler);
  const double o_verlet = verification::fit_order(hs, verlet), o_jump = verification::fit_order(hs, jump);
  const double o_eight = verification::fit_order(h8, e8, 1e-13);  // (the last error 6e-12; the reference's 1e-16)
  BOOST_TEST_MESSAGE("constrained orders: midpoint " << o_mid << ", explicit Euler " << o_euler
                                                     << ", theta 0.3 with its adjoint " << o_verlet << ", triple jump "
                                                     << o_jump << ", kahan-li8 " << o_eight << " (errors at h = "
                                                     << h8.back() << ": " << e8.back() << ")");
  BOOST_TEST(std::fabs(o_mid - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_euler - 1.0) <= 0.15);
  BOOST_TEST(std::fabs(o_verlet - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_jump - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_eight - 8.0) <= 0.4);
  BOOST_TEST(mid.back() <= 1e-3);  // close to the solution, not only converging
}

// Galerkin with Lobatto quadrature under the constraint (solvers/constrained_galerkin_step.h):
// degree s = 1, 2, 3 converge to the angle pendulum at orders 2s (positions and momenta),
// and every step ends on the constraint and its hidden constraint to round-off.
BOOST_AUTO_TEST_CASE(constrained_lobatto_galerkin_keeps_its_order_2s) {
  const double a0 = 1.1, w0 = 0.4, T = 1.0;
  double a, w;
  reference(a0, w0, T, a, w);
  const WrittenConstraints g(cartesian);
  for (int stages = 1; stages <= 3; ++stages) {
    std::vector<double> hs, errs;
    double worst_g = 0.0, worst_hidden = 0.0;
    for (int k = 0; k < 4; ++k) {
      const double h = (stages == 1 ? 0.05 : 0.1) / std::pow(2.0, k);
      const ConstrainedGalerkinStep<WrittenDynamic, WrittenConstraints, NoForce> step(
          WrittenDynamic(cartesian), stages, h, std::make_shared<WrittenConstraints>(cartesian), {},
          MomentumMap::constant);
      State st = cartesian_state(a0, w0);
      const RunSummary run = integrate(step, 0.0, st.q, st.p, st.v, std::lround(T / h), [&](auto&&, double t, const auto& q, const auto& p, auto&&...) {
        double rg, rh;
        g.relative_residuals(t, q, p / kM, rg, rh);
        worst_g = std::fmax(worst_g, rg);
        worst_hidden = std::fmax(worst_hidden, rh);
      });
      BOOST_TEST_REQUIRE(!run.failed, run.failure.message);
      const State e = cartesian_state(a, w);
      hs.push_back(h);
      errs.push_back(std::fmax((st.q - e.q).lpNorm<Eigen::Infinity>(), (st.p - e.p).lpNorm<Eigen::Infinity>()));
    }
    const double order = verification::fit_order(hs, errs, 1e-13);
    BOOST_TEST_MESSAGE("constrained Lobatto Galerkin s = " << stages << ": order " << order << " (errors " << errs.front()
                                                           << " .. " << errs.back() << "), residuals " << worst_g << ", "
                                                           << worst_hidden);
    BOOST_TEST(std::fabs(order - 2.0 * stages) <= 0.1 * stages);
    BOOST_TEST(worst_g <= 1e-14);
    BOOST_TEST(worst_hidden <= 1e-13);
  }
}

// The derivative of Lobatto Galerkin under constraints (ConstrainedGalerkinStep::
// derivative, by the implicit function theorem) against central differences of the step
// map, each step solved afresh (relative 1e-7), on the Cartesian double pendulum, s = 2
// and 3 at h = 0.2; and the step is symplectic on the constraint's cotangent bundle:
// with A_0, A_1 the derivatives of two successive steps, A_0^T A_1^T J A_1 A_0 =
// A_0^T J A_0 to 1e-12 (at h = 0.2 a method of order 4 or 6 that is not symplectic misses
// it by about h^5 or h^7, 3e-4 or 1e-5). With a force, on a damped pendulum on a moving
// support (a constraint in t), the derivative against central differences too.
BOOST_AUTO_TEST_CASE(the_derivative_of_constrained_lobatto_galerkin_and_its_symplecticity) {
  const auto pendulum2 = cartesian_double();
  VectorXd q0, p0;
  cartesian_double_state(q0, p0);
  // one step from (q, p) at t, solved afresh; its central differences in (q, p)
  auto advance = [](const auto& S, double t, const VectorXd& q, const VectorXd& p, VectorXd& dq, VectorXd& dp) {
    S.reset();
    dq = VectorXd::Zero(q.size());
    dp.resize(q.size());
    const StepSummary r = S.step(t, q, p, dq, dp);
    BOOST_REQUIRE_MESSAGE(r.converged, r.message);
  };
  auto differences = [&](const auto& S, double t, const VectorXd& q, const VectorXd& p) {
    return central_differences(
        [&](const VectorXd& qa, const VectorXd& pa, VectorXd& da, VectorXd& ea) { advance(S, t, qa, pa, da, ea); }, q, p);
  };
  const Eigen::Index n = 4;
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  J.topRightCorner(n, n) = Eigen::MatrixXd::Identity(n, n);
  J.bottomLeftCorner(n, n) = -Eigen::MatrixXd::Identity(n, n);
  for (int stages : {2, 3}) {
    BOOST_TEST_CONTEXT("s = " << stages) {
      const double h = 0.2;
      const ConstrainedGalerkinStep<WrittenDynamic, WrittenConstraints, NoForce> S(
          WrittenDynamic(pendulum2), stages, h, std::make_shared<WrittenConstraints>(pendulum2), {}, MomentumMap::constant);
      VectorXd dq, dp;
      advance(S, 0.0, q0, p0, dq, dp);
      Eigen::MatrixXd A0, A1;
      BOOST_REQUIRE(S.derivative(0.0, q0, p0, dq, A0));
      const Eigen::MatrixXd F0 = differences(S, 0.0, q0, p0);
      const double err = (A0 - F0).lpNorm<Eigen::Infinity>() / A0.lpNorm<Eigen::Infinity>();
      const VectorXd q1 = q0 + dq, p1 = p0 + dp;
      VectorXd dq1, dp1;
      advance(S, h, q1, p1, dq1, dp1);
      BOOST_REQUIRE(S.derivative(h, q1, p1, dq1, A1));
      const Eigen::MatrixXd before = A0.transpose() * J * A0, after = A0.transpose() * A1.transpose() * J * A1 * A0;
      const double d = (after - before).lpNorm<Eigen::Infinity>() / before.lpNorm<Eigen::Infinity>();
      BOOST_TEST_MESSAGE("constrained Lobatto Galerkin s = " << stages << ": derivative against central differences "
                                                             << err << ", |A0^T (A1^T J A1 - J) A0| / |A0^T J A0| = " << d);
      BOOST_TEST(err <= 1e-7);
      BOOST_TEST(d <= 1e-12);
      BOOST_TEST((A0.transpose() * J * A0 - J).lpNorm<Eigen::Infinity>() > 1e-3);  // not on all of R^{2n}
    }
  }
  // forced, with a constraint in t (B, in a control: the_derivative_in_the_controls_...)
  {
    using Forced = ConstrainedGalerkinStep<WrittenDynamic, WrittenConstraints, WrittenForce>;
    const auto forced = damped_on_moving_support();
    const Forced S(WrittenDynamic(forced), 2, 0.05, std::make_shared<WrittenConstraints>(forced), {}, MomentumMap::constant,
                   std::make_shared<WrittenForce>(forced));
    VectorXd q, p, dq, dp;
    const double t0 = 0.4;
    moving_support_state(t0, q, p);
    advance(S, t0, q, p, dq, dp);
    Eigen::MatrixXd A;
    BOOST_REQUIRE(S.derivative(t0, q, p, dq, A));
    const double err = (A - differences(S, t0, q, p)).lpNorm<Eigen::Infinity>() / A.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("forced, on a moving support: derivative against central differences " << err);
    BOOST_TEST(err <= 1e-7);
  }
}

// At t = 10, Kahan and Li's order 8 composition of the constrained midpoint with h =
// 0.01 gives the angle pendulum's state to 1e-10.
BOOST_AUTO_TEST_CASE(the_cartesian_pendulum_agrees_with_its_angle_twin_at_t_10) {
  const double a0 = 2.0, w0 = 0.0, T = 10.0;
  double a, w;
  reference(a0, w0, T, a, w);
  const double e = error_at(composed(step_of(0.01), "kahan-li8"), T, a0, w0, a, w);
  BOOST_TEST_MESSAGE("Cartesian against angle pendulum at t = 10: " << e);
  BOOST_TEST(e <= 1e-10);
}

// Every step keeps |g(q_k)| and the hidden constraint |Dg(q_k) M^{-1} p_k| at round-off
// relative to the terms (WrittenConstraints::relative_residuals), for the midpoint and a
// composition with negative substeps; the energy error stays bounded: no larger over
// the second half of 20000 steps (30 periods) than over the first, and for the midpoint
// of order 2 (a quarter at half the step).
BOOST_AUTO_TEST_CASE(every_step_stays_on_the_constraint_and_its_hidden_constraint) {
  const WrittenConstraints g(cartesian);
  const WrittenDynamic L(cartesian);
  auto run = [&](const char* scheme, double h, std::int64_t steps, double& worst_g, double& worst_v, double& worst_E,
                 double& first_half) {
    State s = cartesian_state(2.5, 0.3);
    const double E0 = energy(L, s.q, s.v);
    worst_g = worst_v = worst_E = first_half = 0.0;
    auto observe = [&](std::int64_t k, double t, const VectorXd& q, const VectorXd& p, const StepSummary&) {
      if (k == steps / 2) first_half = worst_E;
      double a, b;
      const VectorXd v = p / kM;
      g.relative_residuals(t, q, v, a, b);
      worst_g = std::fmax(worst_g, a);
      worst_v = std::fmax(worst_v, b);
      worst_E = std::fmax(worst_E, std::fabs(energy(L, q, v) - E0));
    };
    const RunSummary r = std::string(scheme) == "none" ? integrate(step_of(h), 0.0, s.q, s.p, s.v, steps, observe)
                                                       : integrate(composed(step_of(h), scheme), 0.0, s.q, s.p, s.v, steps, observe);
    BOOST_TEST(!r.failed, r.failure.message);
  };
  for (const char* scheme : {"none", "suzuki5"}) {
    BOOST_TEST_CONTEXT(scheme) {
      double worst_g, worst_v, worst_E, first_half;
      run(scheme, 0.01, 20000, worst_g, worst_v, worst_E, first_half);
      BOOST_TEST_MESSAGE(scheme << ": max relative |g| " << worst_g << ", hidden " << worst_v << ", |E - E0| " << worst_E);
      BOOST_TEST(worst_g <= 1e-14);
      BOOST_TEST(worst_v <= 1e-13);  // (round-off relative to |grad g| |v|, largest where v is small)
      BOOST_TEST(worst_E <= 1.01 * first_half);
      if (std::string(scheme) == "none") {  // the error is O(h^2): a quarter at h / 2
        double g2, v2, E2, half2;
        run(scheme, 0.005, 40000, g2, v2, E2, half2);
        BOOST_TEST_MESSAGE("midpoint energy error at h and h / 2: " << worst_E << ", " << E2);
        BOOST_TEST(std::fabs(worst_E / E2 - 4.0) <= 0.2);
      }
    }
  }
}

// A support moved by y_s(t) = A cos(w t): g = x^2 + (y - y_s)^2 - l^2 (rheonomic). The
// constraint holds at every step, the hidden constraint Dg v + g_t = 0 too, and the
// midpoint and the triple jump converge at orders 2 and 4 (against the triple jump at
// a step 16 times smaller).
BOOST_AUTO_TEST_CASE(a_moving_support_is_a_constraint_in_t) {
  const auto moving =
      system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + (y - A*cos(w*t))^2 - l^2"});
  const WrittenConstraints g(moving);
  auto make = [&](double h) {
    return Step(WrittenDynamic(moving), ThetaMap::midpoint(), h, std::make_shared<WrittenConstraints>(moving), {}, MomentumMap::constant);
  };
  auto jump = [&](double h) {
    const Step b = make(h);
    return ComposedStep<Step>(
        h, substeps(find_composition("triple-jump:4"), true), [&](double hk) { return make(hk); },
        [&](double hk) { return make(hk).adjoint(); });
  };
  const double T = 1.0;
  auto final_state = [&](const auto& S, double& worst) {
    // at t = 0 the support is at y = A: the bob below it, moving with it (v_y = 0 = dy_s/dt)
    State s{VectorXd(2), VectorXd(2), VectorXd(2)};
    s.q << kL * std::sin(0.7), 0.2 - kL * std::cos(0.7);
    s.v << 0.0, 0.0;
    s.p = kM * s.v;
    worst = 0.0;
    const RunSummary run = integrate(S, 0.0, s.q, s.p, s.v, std::lround(T / S.step_size()),
                                     [&](std::int64_t, double t, const VectorXd& q, const VectorXd& p, const StepSummary&) {
                                       double a, b;
                                       g.relative_residuals(t, q, p / kM, a, b);
                                       worst = std::fmax(worst, std::fmax(a, b));
                                     });
    BOOST_TEST(!run.failed, run.failure.message);
    return s;
  };
  double worst;
  const State ref = final_state(jump(0.05 / 32), worst);
  std::vector<double> hs, mid, four;
  for (int k = 0; k < 3; ++k) {
    const double h = 0.05 / std::pow(2.0, k);
    hs.push_back(h);
    const State a = final_state(make(h), worst);
    BOOST_TEST(worst <= 1e-13);
    mid.push_back((a.q - ref.q).lpNorm<Eigen::Infinity>());
    const State b = final_state(jump(h), worst);
    BOOST_TEST(worst <= 1e-13);
    four.push_back((b.q - ref.q).lpNorm<Eigen::Infinity>());
  }
  const double o2 = verification::fit_order(hs, mid), o4 = verification::fit_order(hs, four);
  BOOST_TEST_MESSAGE("moving support: orders " << o2 << ", " << o4);
  BOOST_TEST(std::fabs(o2 - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o4 - 4.0) <= 0.25);
}

// project() puts a momentum on the hidden constraint along the constraint normal:
// p - G^T mu with G M^{-1} (p - G^T mu) = 0, i.e. the radial part of the velocity removed.
BOOST_AUTO_TEST_CASE(project_removes_the_velocity_across_the_constraint) {
  const Step S = step_of(0.01);
  State s = cartesian_state(0.6, 1.2);
  const VectorXd tangential = s.p;
  const VectorXd radial = 0.7 * s.q;  // along G^T = 2 q
  VectorXd p = tangential + radial, v = VectorXd::Zero(2);
  BOOST_TEST(S.project(0.0, s.q, p, v).empty());
  BOOST_TEST((p - tangential).lpNorm<Eigen::Infinity>() <= 1e-15);
  BOOST_TEST((v - tangential / kM).lpNorm<Eigen::Infinity>() <= 1e-15);
}

// With a damping force -c v on the bob, the constrained steps give the damped angle
// pendulum (its generalized force -c l^2 a_dot): the triple jump of the constrained
// midpoint converges to it at order 4, and the forces' work is negative.
BOOST_AUTO_TEST_CASE(a_damped_constrained_pendulum_is_the_damped_angle_pendulum) {
  const auto damped = system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + y^2 - l^2"},
                                {{0, "-c*x_dot"}, {1, "-c*y_dot"}});
  const auto damped_angle = system_of({"a"}, "m*l^2*a_dot^2/2 + m*g*l*cos(a)", {}, {{0, "-c*l^2*a_dot"}});
  using Forced = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>;
  const double a0 = 1.5, T = 1.0;
  double a, w;
  {
    using G = DynamicGalerkinStep<WrittenDynamic, WrittenForce>;
    const G S(WrittenDynamic(damped_angle), QuadratureKind::gauss, 6, 0.01, {}, std::make_shared<WrittenForce>(damped_angle));
    VectorXd q(1), p(1), v(1);
    q << a0;
    v << 0.0;
    p << 0.0;
    BOOST_REQUIRE(!integrate(S, 0.0, q, p, v, 100, [](auto&&...) {}).failed);
    a = q[0];
    w = p[0] / (kM * kL * kL);
  }
  auto make = [&](double h) {
    return Forced(WrittenDynamic(damped), ThetaMap::midpoint(), h, std::make_shared<WrittenConstraints>(damped), {},
                  MomentumMap::constant, std::make_shared<WrittenForce>(damped));
  };
  std::vector<double> hs, errors;
  double W = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double h = 0.05 / std::pow(2.0, k);
    const ComposedStep<Forced> S(
        h, substeps(find_composition("triple-jump:4"), true), [&](double hk) { return make(hk); },
        [&](double hk) { return make(hk).adjoint(); });
    State s = cartesian_state(a0, 0.0);
    W = 0.0;
    const RunSummary run = integrate(S, 0.0, s.q, s.p, s.v, std::lround(T / h),
                                     [&](std::int64_t, double, const VectorXd&, const VectorXd&,
                                         const StepSummary& st) { W += st.work; });
    BOOST_TEST(!run.failed, run.failure.message);
    const State e = cartesian_state(a, w);
    hs.push_back(h);
    errors.push_back(std::fmax((s.q - e.q).lpNorm<Eigen::Infinity>(), (s.p - e.p).lpNorm<Eigen::Infinity>()));
  }
  const double order = verification::fit_order(hs, errors);
  BOOST_TEST_MESSAGE("damped constrained pendulum: order " << order << ", error " << errors.back() << ", W = " << W);
  BOOST_TEST(std::fabs(order - 4.0) <= 0.25);
  BOOST_TEST(errors.back() <= 1e-4);  // (the undamped triple jump's error at this step: 1e-5)
  BOOST_TEST(W < 0.0);
}

// A step allocates nothing once the step object exists.
BOOST_AUTO_TEST_CASE(a_constrained_step_allocates_nothing) {
  const Step S = step_of(0.01);
  State s = cartesian_state(1.0, 0.5);
  VectorXd dq = VectorXd::Zero(2), dp(2);
  S.step(0.0, s.q, s.p, dq, dp);  // (a first step: buffers of the tapes grown)
  const long before = news.load();
  for (int k = 0; k < 10; ++k) {
    const StepSummary r = S.step(0.0, s.q, s.p, dq, dp);
    BOOST_TEST(r.converged);
  }
  BOOST_TEST(news.load() - before == 0);
}

// The three ways of solving the right transform (MomentumMap: Newton's method, one solve
// with M(q), M^{-1} kept) give the same trajectory to round-off on the Cartesian
// pendulum, where all three apply; and on a Lagrangian whose mass depends on q (the
// pendulum in polar coordinates r, a with the constraint r - l = 0, M = diag(m, m r^2)),
// `general` and `linear` agree with each other and with the angle pendulum.
BOOST_AUTO_TEST_CASE(the_momentum_maps_agree) {
  const auto run = [](const std::shared_ptr<WrittenSystem>& s, MomentumMap kind, VectorXd q, VectorXd p) {
    const Step S(WrittenDynamic(s), ThetaMap::midpoint(), 0.01, std::make_shared<WrittenConstraints>(s), {}, kind);
    VectorXd v = VectorXd::Zero(q.size());
    BOOST_TEST(!integrate(S, 0.0, q, p, v, 500, [](auto&&...) {}).failed);
    VectorXd out(2 * q.size());
    out << q, p;
    return out;
  };
  const State c = cartesian_state(1.2, 0.5);
  const VectorXd a = run(cartesian, MomentumMap::general, c.q, c.p), b = run(cartesian, MomentumMap::linear, c.q, c.p),
                 d = run(cartesian, MomentumMap::constant, c.q, c.p);
  BOOST_TEST((a - b).lpNorm<Eigen::Infinity>() <= 1e-13);
  BOOST_TEST((a - d).lpNorm<Eigen::Infinity>() <= 1e-13);
  const auto polar = system_of({"r", "a"}, "m*(r_dot^2 + r^2*a_dot^2)/2 + m*g*r*cos(a)", {"r - l"});
  VectorXd q(2), p(2);
  q << kL, 1.2;
  p << 0.0, kM * kL * kL * 0.5;
  const VectorXd e = run(polar, MomentumMap::general, q, p), f = run(polar, MomentumMap::linear, q, p);
  BOOST_TEST((e - f).lpNorm<Eigen::Infinity>() <= 1e-13);
  // the angle pendulum's midpoint step is this constrained step with r = l throughout
  const WrittenDynamic La(angle);
  const DynamicThetaStep<WrittenDynamic> A(La, ThetaMap::midpoint(), 0.01);
  VectorXd qa(1), pa(1), va(1);
  qa << 1.2;
  pa << kM * kL * kL * 0.5;
  va << 0.5;
  BOOST_TEST(!integrate(A, 0.0, qa, pa, va, 500, [](auto&&...) {}).failed);
  BOOST_TEST(std::fabs(e[0] - kL) <= 1e-14);
  BOOST_TEST(std::fabs(e[1] - qa[0]) <= 1e-12);
  BOOST_TEST(std::fabs(e[3] - pa[0]) <= 1e-12);
}

// The derivative of the constrained step (ConstrainedThetaStep::derivative, the implicit
// function theorem on its two equations) against central differences of the step map
// (q0, p0) -> (q1, p1) in every direction of R^{2n}, relative 1e-7: the double pendulum
// in Cartesian coordinates (two constraints) at theta = 0.3 and 1/2, and a damped pendulum
// on a moving support (a constraint in t, a force). Without forces the step is
// symplectic on the constraint's cotangent bundle: for the vectors A_0 x that the first
// step's derivative maps onto it, the next step's A_1 keeps J, A_0^T A_1^T J A_1 A_0 =
// A_0^T J A_0 to 1e-12 (on all of R^{2n} it does not: A_0^T J A_0 != J).
BOOST_AUTO_TEST_CASE(the_derivative_of_the_constrained_step_is_its_linearisation) {
  const auto pendulum2 = cartesian_double();
  const auto moving = damped_on_moving_support();
  VectorXd q2, p2;
  cartesian_double_state(q2, p2);
  auto check = [](const auto& S, double t0, const VectorXd& q0, const VectorXd& p0, bool symplectic) {
    const Eigen::Index n = q0.size();
    auto advance = [&](const VectorXd& q, const VectorXd& p, VectorXd& dq, VectorXd& dp) {
      dq = VectorXd::Zero(n);
      const StepSummary s = S.step(t0, q, p, dq, dp);
      BOOST_REQUIRE_MESSAGE(s.converged, s.message);
    };
    VectorXd dq(n), dp(n);
    advance(q0, p0, dq, dp);
    Eigen::MatrixXd A;
    BOOST_REQUIRE(S.derivative(t0, q0, p0, dq, A));
    Eigen::MatrixXd F(2 * n, 2 * n);
    const double eps = 1e-6;
    for (Eigen::Index j = 0; j < 2 * n; ++j) {
      VectorXd qa = q0, pa = p0, qb = q0, pb = p0, da(n), ea(n), db(n), eb(n);
      (j < n ? qa[j] : pa[j - n]) += eps;
      (j < n ? qb[j] : pb[j - n]) -= eps;
      advance(qa, pa, da, ea);
      advance(qb, pb, db, eb);
      F.col(j) << (qa + da - qb - db) / (2 * eps), (pa + ea - pb - eb) / (2 * eps);
    }
    const double err = (A - F).lpNorm<Eigen::Infinity>() / A.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("constrained step derivative against central differences: " << err);
    BOOST_TEST(err <= 1e-7);
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2 * n, 2 * n);
    J.topRightCorner(n, n) = Eigen::MatrixXd::Identity(n, n);
    J.bottomLeftCorner(n, n) = -Eigen::MatrixXd::Identity(n, n);
    if (!symplectic) return;
    Eigen::MatrixXd A1;
    const VectorXd q1 = q0 + dq, p1 = p0 + dp;
    VectorXd dq1(n), dp1(n);
    advance(q1, p1, dq1, dp1);
    BOOST_REQUIRE(S.derivative(t0 + S.step_size(), q1, p1, dq1, A1));
    const Eigen::MatrixXd before = A.transpose() * J * A, after = A.transpose() * A1.transpose() * J * A1 * A;
    const double s = (after - before).lpNorm<Eigen::Infinity>() / before.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("on the constraint's cotangent bundle, |A0^T (A1^T J A1 - J) A0| / |A0^T J A0| = " << s);
    BOOST_TEST(s <= 1e-12);
    BOOST_TEST((A.transpose() * J * A - J).lpNorm<Eigen::Infinity>() > 1e-3);  // not on all of R^{2n}
  };
  for (double theta : {0.3, 0.5}) {
    BOOST_TEST_CONTEXT("double pendulum, theta " << theta) {
      const Step S(WrittenDynamic(pendulum2), ThetaMap(theta), 0.01, std::make_shared<WrittenConstraints>(pendulum2), {},
                   MomentumMap::general);
      check(S, 0.0, q2, p2, true);
    }
  }
  {
    using Forced = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>;
    const Forced S(WrittenDynamic(moving), ThetaMap(0.3), 0.01, std::make_shared<WrittenConstraints>(moving), {},
                   MomentumMap::constant, std::make_shared<WrittenForce>(moving));
    VectorXd q, p;
    const double t0 = 0.4;
    moving_support_state(t0, q, p);
    BOOST_TEST_CONTEXT("moving support with damping") { check(S, t0, q, p, false); }
  }
  // the hamiltonian form (ConstrainedHamiltonianThetaStep::derivative), the same checks:
  // the Cartesian double pendulum (separable: the same map as the position-momentum
  // step, and its constraints curved, so that their Hessians enter), a pendulum in polar
  // coordinates held on r^2 = l^2 (L not separable: its mass matrix depends on r), and
  // the damped pendulum on the moving support
  using HL = LegendreDynamicHamiltonian<WrittenDynamic>;
  const auto polar = system_of({"r", "a"}, "m*(r_dot^2 + r^2*a_dot^2)/2 + m*g*r*cos(a)", {"r^2 - l^2"});
  VectorXd qp(2), pp(2);
  qp << kL, 1.2;
  pp << 0.0, kM * kL * kL * 0.5;
  for (double theta : {0.3, 0.5}) {
    for (const auto& [name, sys, q0, p0] : {std::tuple{"double pendulum", pendulum2, q2, p2},
                                            std::tuple{"polar pendulum", polar, qp, pp}}) {
      BOOST_TEST_CONTEXT("hamiltonian form, " << name << ", theta " << theta) {
        const WrittenDynamic L(sys);
        const ConstrainedHamiltonianThetaStep<HL, WrittenDynamic, WrittenConstraints> S(
            HL(L), L, ThetaMap(theta), 0.01, std::make_shared<WrittenConstraints>(sys));
        check(S, 0.0, q0, p0, true);
      }
    }
  }
  {
    const WrittenDynamic L(moving);
    const ConstrainedHamiltonianThetaStep<HL, WrittenDynamic, WrittenConstraints, WrittenForce> S(
        HL(L), L, ThetaMap(0.3), 0.01, std::make_shared<WrittenConstraints>(moving), {}, MomentumMap::constant,
        std::make_shared<WrittenForce>(moving));
    VectorXd q, p;
    const double t0 = 0.4;
    moving_support_state(t0, q, p);
    BOOST_TEST_CONTEXT("hamiltonian form, moving support with damping") { check(S, t0, q, p, false); }
  }
}

// The step compiled for its size (ConstrainedThetaStep<..., 2, 1>, what the runtime takes
// for a pendulum or a planar linkage) gives the run-time-sized step's trajectory (the same
// operations in the same order) and its derivative; with a force too.
BOOST_AUTO_TEST_CASE(the_fixed_size_step_is_the_run_time_sized_one) {
  const auto damped = system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + y^2 - l^2"},
                                {{0, "-c*x_dot"}, {1, "-c*y_dot"}});
  const auto con = std::make_shared<WrittenConstraints>(damped);
  const auto force = std::make_shared<WrittenForce>(damped);
  const WrittenDynamic L(damped);
  using Dyn = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>;
  using Fix = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce, 2, 1>;
  const Dyn a(L, ThetaMap(0.3), 0.01, con, {}, MomentumMap::constant, force);
  const Fix b(L, ThetaMap(0.3), 0.01, con, {}, MomentumMap::constant, force);
  State sa = cartesian_state(1.3, 0.2), sb = sa;
  BOOST_TEST(!integrate(a, 0.0, sa.q, sa.p, sa.v, 300, [](auto&&...) {}).failed);
  BOOST_TEST(!integrate(b, 0.0, sb.q, sb.p, sb.v, 300, [](auto&&...) {}).failed);
  BOOST_TEST((sa.q - sb.q).lpNorm<Eigen::Infinity>() <= 1e-15);
  BOOST_TEST((sa.p - sb.p).lpNorm<Eigen::Infinity>() <= 1e-15);
  VectorXd dq = VectorXd::Zero(2), dp(2);
  BOOST_TEST(b.step(3.0, sb.q, sb.p, dq, dp).converged);
  Eigen::MatrixXd Aa, Ab;
  BOOST_TEST(a.derivative(3.0, sb.q, sb.p, dq, Aa));
  BOOST_TEST(b.derivative(3.0, sb.q, sb.p, dq, Ab));
  BOOST_TEST((Aa - Ab).lpNorm<Eigen::Infinity>() <= 1e-13 * Aa.lpNorm<Eigen::Infinity>());
  // unforced: the derivative of fixed size (its matrices on the stack) is the
  // run-time-sized one, and allocates nothing once its workspace is sized
  using DynFree = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints>;
  using FixFree = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, NoForce, 2, 1>;
  const WrittenDynamic P(cartesian);
  const auto pc = std::make_shared<WrittenConstraints>(cartesian);
  const DynFree c(P, ThetaMap(0.5), 0.01, pc, {}, MomentumMap::constant);
  const FixFree d(P, ThetaMap(0.5), 0.01, pc, {}, MomentumMap::constant);
  State s = cartesian_state(1.3, 0.2);
  dq.setZero();
  BOOST_TEST(d.step(0.0, s.q, s.p, dq, dp).converged);
  Eigen::MatrixXd Ac, Ad;
  BOOST_TEST(c.derivative(0.0, s.q, s.p, dq, Ac));
  BOOST_TEST(d.derivative(0.0, s.q, s.p, dq, Ad));
  BOOST_TEST((Ac - Ad).lpNorm<Eigen::Infinity>() <= 1e-13 * Ac.lpNorm<Eigen::Infinity>());
  const long before = news.load();
  BOOST_TEST(d.derivative(0.0, s.q, s.p, dq, Ad));
  BOOST_TEST(news.load() - before == 0);
  BOOST_CHECK_THROW(Fix(WrittenDynamic(cartesian), ThetaMap(0.5), 0.01,
                        std::make_shared<WrittenConstraints>(system_of({"x", "y", "z"}, "x_dot^2 + y_dot^2 + z_dot^2",
                                                                       {"x^2 + y^2 + z^2 - 1"})),
                        {}, MomentumMap::general, force),
                    std::invalid_argument);
}

// Control inputs (WrittenForce with a ControlSignal): the derivative B = d(q1, p1)/du of a
// step in a control held over it, against central differences in the tabulated value
// u_k (relative 1e-7), for the unconstrained theta step (a cart-pole pushed along x) and
// its Hamiltonian form, the constrained one and constrained Lobatto Galerkin s = 2 (the Cartesian pendulum pushed
// sideways); the signal's step index picks u_k.
BOOST_AUTO_TEST_CASE(the_derivative_in_the_controls_is_the_linearisation_in_u) {
  auto with_control = [](std::shared_ptr<WrittenSystem> s, std::vector<double> table) {
    s->controls.push_back({"u", {}, std::move(table), "test", "test"});
    return s;
  };
  auto cartpole = with_control(
      system_of({"x", "a"}, "(1 + m)/2*x_dot^2 + m*l*cos(a)*x_dot*a_dot + m*l^2/2*a_dot^2 + m*g*l*cos(a)"), {0.3, 1.7});
  cartpole->forces.emplace_back(0, Expression::parse("u - c*x_dot", cartpole->symbols(WrittenSystem::Kind::force)));
  auto pushed = with_control(system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + y^2 - l^2"}), {0.3, 1.7});
  pushed->forces.emplace_back(0, Expression::parse("u*y^2", pushed->symbols(WrittenSystem::Kind::force)));
  auto check = [](const auto& make, const std::shared_ptr<WrittenSystem>& s, const VectorXd& q0, const VectorXd& p0) {
    const auto signal = std::make_shared<ControlSignal>(s->controls);
    signal->set_step(1);  // u_1 = 1.7
    const auto S = make(std::make_shared<WrittenForce>(s, signal));
    BOOST_TEST(S.controls() == 1);
    const Eigen::Index n = q0.size();
    auto advance = [&](VectorXd& dq, VectorXd& dp) {
      dq = VectorXd::Zero(n);
      dp = VectorXd::Zero(n);  // (the starting guess of the Hamiltonian step)
      const StepSummary r = S.step(0.1, q0, p0, dq, dp);
      BOOST_REQUIRE_MESSAGE(r.converged, r.message);
    };
    VectorXd dq(n), dp(n);
    advance(dq, dp);
    Eigen::MatrixXd B;
    BOOST_REQUIRE(S.control_derivative(0.1, q0, p0, dq, B));
    BOOST_TEST(B.cols() == 1);
    check_joint_derivatives(S, 0.1, q0, p0, dq, B);
    // the same step with u_1 moved by +-eps (its own signal: the force's copy reads it)
    auto moved = [&](double du) {
      auto t = s->controls;
      t[0].table[1] += du;
      auto sig = std::make_shared<ControlSignal>(t);
      sig->set_step(1);
      const auto Su = make(std::make_shared<WrittenForce>(s, sig));
      VectorXd d = VectorXd::Zero(n), e = VectorXd::Zero(n);
      BOOST_REQUIRE(Su.step(0.1, q0, p0, d, e).converged);
      VectorXd z(2 * n);
      z << q0 + d, p0 + e;
      return z;
    };
    const double eps = 1e-6;
    const VectorXd fd = (moved(eps) - moved(-eps)) / (2 * eps);
    const double err = (B.col(0) - fd).lpNorm<Eigen::Infinity>() / fd.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("B against central differences in u: " << err);
    BOOST_TEST(err <= 1e-7);
    BOOST_TEST(fd.lpNorm<Eigen::Infinity>() > 1e-3);  // the control moves the step
    // the step read u_1, not u_0: with u_0 the step differs
    signal->set_step(0);
    VectorXd d0(n), e0(n);
    advance(d0, e0);
    BOOST_TEST((d0 - dq).lpNorm<Eigen::Infinity>() > 1e-6);
  };
  VectorXd q(2), p(2);
  q << 0.1, 0.4;
  p << 0.2, -0.1;
  check([&](std::shared_ptr<WrittenForce> f) {
    return DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce>(WrittenDynamic(cartpole), ThetaMap(0.3), 0.01,
                                                                          {}, false, f);
  }, cartpole, q, p);
  // the Hamiltonian theta step of the same cart-pole (H from L by the Legendre transform)
  check([&](std::shared_ptr<WrittenForce> f) {
    using H = LegendreDynamicHamiltonian<WrittenDynamic>;
    return DynamicHamiltonianThetaStep<H, WrittenForce>(H(WrittenDynamic(cartpole)), ThetaMap(0.3), 0.01, {}, false, f);
  }, cartpole, q, p);
  const State c = cartesian_state(0.7, 0.4);
  check([&](std::shared_ptr<WrittenForce> f) {
    return ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>(
        WrittenDynamic(pushed), ThetaMap(0.3), 0.01, std::make_shared<WrittenConstraints>(pushed), {},
        MomentumMap::general, f);
  }, pushed, c.q, c.p);
  check([&](std::shared_ptr<WrittenForce> f) {
    using H = LegendreDynamicHamiltonian<WrittenDynamic>;
    const WrittenDynamic L(pushed);
    return ConstrainedHamiltonianThetaStep<H, WrittenDynamic, WrittenConstraints, WrittenForce>(
        H(L), L, ThetaMap(0.3), 0.01, std::make_shared<WrittenConstraints>(pushed), {}, MomentumMap::general, f);
  }, pushed, c.q, c.p);
  check([&](std::shared_ptr<WrittenForce> f) {
    return ConstrainedGalerkinStep<WrittenDynamic, WrittenConstraints, WrittenForce>(
        WrittenDynamic(pushed), 2, 0.01, std::make_shared<WrittenConstraints>(pushed), {}, MomentumMap::general, f);
  }, pushed, c.q, c.p);
}

// The derivative of a composition (ComposedStep::derivative: the chain rule over its
// substeps, solved again from the step's start) against central differences of the
// composed step, relative 1e-7: the triple jump of the constrained midpoint on the
// Cartesian double pendulum, and Suzuki's five stages of the theta = 0.3 step with its
// adjoint on a cart-pole with a control (A and B). The unforced composition is
// symplectic: A^T J A = J to 1e-12 for the theta step's, and on the constraint's
// cotangent bundle for the constrained one's.

BOOST_AUTO_TEST_CASE(the_derivative_of_a_composition_is_the_product_of_its_substeps) {
  auto central = [](const auto& S, const VectorXd& q0, const VectorXd& p0) {
    return central_differences(
        [&](const VectorXd& q, const VectorXd& p, VectorXd& d, VectorXd& e) {
          d = VectorXd::Zero(q.size());
          e = VectorXd::Zero(q.size());
          BOOST_REQUIRE(S.step(0.2, q, p, d, e).converged);
        },
        q0, p0);
  };
  {
    const auto pendulum2 = cartesian_double();
    auto make = [&](double hk) {
      return Step(WrittenDynamic(pendulum2), ThetaMap::midpoint(), hk, std::make_shared<WrittenConstraints>(pendulum2),
                  {}, MomentumMap::constant);
    };
    const ComposedStep<Step> S(0.02, substeps(find_composition("triple-jump:4"), true), make,
                               [&](double hk) { return make(hk).adjoint(); });
    VectorXd q, p;
    cartesian_double_state(q, p);
    VectorXd dq = VectorXd::Zero(4), dp(4);
    BOOST_REQUIRE(S.step(0.2, q, p, dq, dp).converged);
    Eigen::MatrixXd A, A1;
    BOOST_REQUIRE(S.derivative(0.2, q, p, dq, A));
    const Eigen::MatrixXd F = central(S, q, p);
    const double err = (A - F).lpNorm<Eigen::Infinity>() / A.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("composed constrained step: derivative against central differences " << err);
    BOOST_TEST(err <= 1e-7);
    const VectorXd q1 = q + dq, p1 = p + dp;
    VectorXd dq1 = VectorXd::Zero(4), dp1(4);
    BOOST_REQUIRE(S.step(0.22, q1, p1, dq1, dp1).converged);
    BOOST_REQUIRE(S.derivative(0.22, q1, p1, dq1, A1));
    const Eigen::MatrixXd J = J_of(4), before = A.transpose() * J * A,
                          after = A.transpose() * A1.transpose() * J * A1 * A;
    BOOST_TEST((after - before).lpNorm<Eigen::Infinity>() <= 1e-12 * before.lpNorm<Eigen::Infinity>());
  }
  {
    auto cartpole =
        system_of({"x", "a"}, "(1 + m)/2*x_dot^2 + m*l*cos(a)*x_dot*a_dot + m*l^2/2*a_dot^2 + m*g*l*cos(a)");
    cartpole->controls.push_back({"u", {}, {0.4, 1.1}, "test", "test"});
    cartpole->forces.emplace_back(0, Expression::parse("u - c*x_dot", cartpole->symbols(WrittenSystem::Kind::force)));
    using Forced = DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce>;
    auto composed_with = [&](double u) {
      auto c = cartpole->controls;
      c[0].table[0] = u;
      const auto force = std::make_shared<WrittenForce>(cartpole, std::make_shared<ControlSignal>(c));
      auto make = [&](double hk) { return Forced(WrittenDynamic(cartpole), ThetaMap(0.3), hk, {}, false, force); };
      return ComposedStep<Forced>(0.02, substeps(find_composition("suzuki5"), false), make,
                                  [&](double hk) { return make(hk).adjoint(); });
    };
    const auto S = composed_with(0.4);
    VectorXd q(2), p(2), dq = VectorXd::Zero(2), dp(2);
    q << 0.1, 0.5;
    p << 0.3, -0.2;
    BOOST_REQUIRE(S.step(0.2, q, p, dq, dp).converged);
    Eigen::MatrixXd A, B;
    BOOST_REQUIRE(S.derivative(0.2, q, p, dq, A));
    BOOST_REQUIRE(S.control_derivative(0.2, q, p, dq, B));
    BOOST_TEST(S.controls() == 1);
    check_joint_derivatives(S, 0.2, q, p, dq, B);
    const double err = (A - central(S, q, p)).lpNorm<Eigen::Infinity>() / A.lpNorm<Eigen::Infinity>();
    auto end = [&](double u) {
      VectorXd d = VectorXd::Zero(2), e(2);
      BOOST_REQUIRE(composed_with(u).step(0.2, q, p, d, e).converged);
      VectorXd z(4);
      z << q + d, p + e;
      return z;
    };
    const VectorXd fd = (end(0.4 + 1e-6) - end(0.4 - 1e-6)) / 2e-6;
    const double errB = (B.col(0) - fd).lpNorm<Eigen::Infinity>() / fd.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("composed forced step: A " << err << ", B " << errB << " against central differences");
    BOOST_TEST(err <= 1e-7);
    BOOST_TEST(errB <= 1e-7);
  }
  {
    // unforced: the composition of the theta = 0.3 step with its adjoint is symplectic
    const auto written2 = system_of({"a", "b"}, "a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*cos(a) + cos(b)");
    using Plain = DynamicThetaStep<WrittenDynamic>;
    auto make = [&](double hk) { return Plain(WrittenDynamic(written2), ThetaMap(0.3), hk); };
    const ComposedStep<Plain> S(0.05, substeps(find_composition("kahan-li8"), false), make,
                                [&](double hk) { return make(hk).adjoint(); });
    VectorXd q(2), p(2), dq = VectorXd::Zero(2), dp(2);
    q << 0.5, 0.3;
    p << 0.2, -0.1;
    BOOST_REQUIRE(S.step(0.0, q, p, dq, dp).converged);
    Eigen::MatrixXd A;
    BOOST_REQUIRE(S.derivative(0.0, q, p, dq, A));
    const Eigen::MatrixXd J = J_of(2);
    BOOST_TEST((A.transpose() * J * A - J).lpNorm<Eigen::Infinity>() <= 1e-12);
    BOOST_TEST((A - central(S, q, p)).lpNorm<Eigen::Infinity>() <= 1e-7 * A.lpNorm<Eigen::Infinity>());
  }
}

// The Galerkin step's derivative (DynamicGalerkinStep::derivative, control_derivative:
// the implicit function theorem on the stage equations, the stages solved again)
// against central differences of the step, relative 1e-7: Gauss s = 2 and Lobatto
// s = 3 on a double pendulum in its angles, symplectic there (A^T J A = J to 1e-12);
// Gauss s = 2 on a damped cart-pole pushed by a control (A and B; A^T J A != J); Gauss
// s = 3 on a Lagrangian in t (exp(c t) L) at t0 = 0.7, symplectic.
BOOST_AUTO_TEST_CASE(the_galerkin_derivative_is_the_linearisation_of_the_stages) {
  const double t0 = 0.7;
  auto fresh_step = [&](const auto& S, const VectorXd& q, const VectorXd& p, VectorXd& d, VectorXd& e) {
    S.reset();  // (no continuation from the previous call's polynomial)
    d = VectorXd::Zero(q.size());
    e = VectorXd::Zero(q.size());
    const StepSummary r = S.step(t0, q, p, d, e);
    BOOST_REQUIRE_MESSAGE(r.converged, r.message);
  };
  auto central = [&](const auto& S, const VectorXd& q0, const VectorXd& p0) {
    return central_differences(
        [&](const VectorXd& q, const VectorXd& p, VectorXd& d, VectorXd& e) { fresh_step(S, q, p, d, e); }, q0, p0);
  };
  // A at (q, p) against central differences; returns A
  auto check_A = [&](const auto& S, const VectorXd& q, const VectorXd& p) {
    VectorXd dq, dp;
    fresh_step(S, q, p, dq, dp);
    Eigen::MatrixXd A;
    BOOST_REQUIRE(S.derivative(t0, q, p, dq, A));
    const Eigen::MatrixXd C = central(S, q, p);
    const double err = (A - C).lpNorm<Eigen::Infinity>() / A.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("Galerkin s = " << S.stages() << ": A against central differences " << err);
    BOOST_TEST(err <= 1e-7);
    BOOST_TEST((A - Eigen::MatrixXd::Identity(A.rows(), A.cols())).lpNorm<Eigen::Infinity>() > 1e-3);
    return A;
  };
  VectorXd q(2), p(2);
  q << 0.5, -0.3;
  p << 0.2, 0.4;
  {
    const auto dp = system_of({"a", "b"}, "a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*g*cos(a) + g*cos(b)");
    for (const auto& [kind, s] : {std::pair{QuadratureKind::gauss, 2}, std::pair{QuadratureKind::lobatto, 3}}) {
      const DynamicGalerkinStep<WrittenDynamic> S(WrittenDynamic(dp), kind, s, 0.05);
      const Eigen::MatrixXd A = check_A(S, q, p), J = J_of(2);
      BOOST_TEST((A.transpose() * J * A - J).lpNorm<Eigen::Infinity>() <= 1e-12 * A.squaredNorm());
    }
  }
  {
    auto cartpole = system_of({"x", "a"}, "(1 + m)/2*x_dot^2 + m*l*cos(a)*x_dot*a_dot + m*l^2/2*a_dot^2 + m*g*l*cos(a)");
    cartpole->controls.push_back({"u", {}, {0.3, 1.7}, "test", "test"});
    cartpole->forces.emplace_back(0, Expression::parse("u - c*x_dot", cartpole->symbols(WrittenSystem::Kind::force)));
    auto make = [&](const std::vector<WrittenSystem::Control>& controls) {
      auto signal = std::make_shared<ControlSignal>(controls);
      signal->set_step(1);
      return DynamicGalerkinStep<WrittenDynamic, WrittenForce>(WrittenDynamic(cartpole), QuadratureKind::gauss, 2, 0.05,
                                                               {}, std::make_shared<WrittenForce>(cartpole, signal));
    };
    const auto S = make(cartpole->controls);
    BOOST_TEST(S.controls() == 1);
    const Eigen::MatrixXd A = check_A(S, q, p), J = J_of(2);
    BOOST_TEST((A.transpose() * J * A - J).lpNorm<Eigen::Infinity>() > 1e-6);  // damped
    VectorXd dq, dpk;
    fresh_step(S, q, p, dq, dpk);
    Eigen::MatrixXd B;
    BOOST_REQUIRE(S.control_derivative(t0, q, p, dq, B));
    check_joint_derivatives(S, t0, q, p, dq, B);
    auto moved = [&](double du) {
      auto c = cartpole->controls;
      c[0].table[1] += du;
      const auto Su = make(c);
      VectorXd d, e;
      fresh_step(Su, q, p, d, e);
      VectorXd z(4);
      z << q + d, p + e;
      return z;
    };
    const double eps = 1e-6;
    const VectorXd fd = (moved(eps) - moved(-eps)) / (2 * eps);
    const double err = (B.col(0) - fd).lpNorm<Eigen::Infinity>() / fd.lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("Galerkin B against central differences in u: " << err);
    BOOST_TEST(err <= 1e-7);
    BOOST_TEST(fd.lpNorm<Eigen::Infinity>() > 1e-3);
  }
  {
    const auto timed = system_of({"a", "b"}, "exp(c*t)*(a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*g*cos(a) + g*cos(b))");
    const DynamicGalerkinStep<WrittenDynamic> S(WrittenDynamic(timed), QuadratureKind::gauss, 3, 0.05);
    const Eigen::MatrixXd A = check_A(S, q, p), J = J_of(2);
    BOOST_TEST((A.transpose() * J * A - J).lpNorm<Eigen::Infinity>() <= 1e-12 * A.squaredNorm());
  }
}

// The constrained Hamiltonian theta step (solvers/constrained_hamiltonian_step.h).
// Its equation's Jacobian against central differences of its residual (relative 1e-7)
// on the pendulum in polar coordinates, whose H (L's Legendre transform) is not
// separable, at theta = 0.3, with and without a damping force.
BOOST_AUTO_TEST_CASE(the_constrained_hamiltonian_equation_has_the_jacobian_of_its_residual) {
  const auto polar = system_of({"r", "a"}, "m*(r_dot^2 + r^2*a_dot^2)/2 + m*g*r*cos(a)", {"r^2 - l^2"},
                               {{1, "-c*a_dot + 0.2*cos(w*t)"}});
  const WrittenDynamic L(polar);
  const LegendreDynamicHamiltonian<WrittenDynamic> H(L);
  const WrittenConstraints g(polar);
  const WrittenForce F(polar);
  VectorXd q0(2), p0(2), y(5);
  q0 << 0.95 * kL, 1.1;
  p0 << 0.2, kM * kL * kL * 0.4;
  y << 0.01, -0.03, 0.02, -0.05, 0.3;
  auto check = [&](auto& eq, const char* what) {
    eq.begin(q0, p0, 0.4);
    VectorXd r(5), r1(5), r2(5);
    Eigen::MatrixXd J(5, 5), D(5, 5);
    eq.jacobian(y, r, J);  // (sets the multiplier's scale, which the residual reads)
    for (int j = 0; j < 5; ++j) {
      const double e = 1e-6 * std::fmax(1.0, std::fabs(y[j]));
      VectorXd a = y, b = y;
      a[j] += e;
      b[j] -= e;
      eq.residual(a, r1);
      eq.residual(b, r2);
      D.col(j) = (r1 - r2) / (2.0 * e);
    }
    eq.jacobian(y, r, J);
    BOOST_TEST_MESSAGE(what << ": |J - D| = " << (J - D).lpNorm<Eigen::Infinity>() << " of " << J.lpNorm<Eigen::Infinity>());
    BOOST_TEST((J - D).lpNorm<Eigen::Infinity>() <= 1e-7 * J.lpNorm<Eigen::Infinity>(), what);
    BOOST_TEST(J.col(4).lpNorm<Eigen::Infinity>() > 0.0, what);  // the multiplier enters
  };
  ConstrainedHamiltonianThetaEquation<LegendreDynamicHamiltonian<WrittenDynamic>, WrittenConstraints> plain(H, g, 0.3, 0.1);
  check(plain, "unforced");
  ConstrainedHamiltonianThetaEquation<LegendreDynamicHamiltonian<WrittenDynamic>, WrittenConstraints, WrittenForce> forced(
      H, g, 0.3, 0.1, &F);
  check(forced, "forced");
}

// On a separable Lagrangian the Hamiltonian theta step is the position-momentum step of
// the same map, so the constrained steps are one map too: the Cartesian pendulum at
// theta = 0.3 and 1/2, and the damped pendulum on a moving support (a constraint in t
// and a force), 400 steps each, the same states to 1e-12. On the pendulum in polar
// coordinates (r = l held by the constraint, H not separable) the constrained
// Hamiltonian midpoint is the angle pendulum's midpoint step (the angle's equations do
// not read p_r, which the multiplier takes); the constraint and its hidden constraint
// hold to 1e-13 at every step.
BOOST_AUTO_TEST_CASE(the_constrained_hamiltonian_step_is_the_lagrangian_one_where_they_agree) {
  using HL = LegendreDynamicHamiltonian<WrittenDynamic>;
  auto compare = [&](const std::shared_ptr<WrittenSystem>& s, double theta, bool forced, const char* what) {
    const ThetaMap R(theta);
    const auto con = std::make_shared<WrittenConstraints>(s);
    const WrittenDynamic L(s);
    auto run = [&](const auto& S) {
      const State c = cartesian_state(0.9, 0.4);
      State x = c;
      x.q[1] += s->name == "moving" ? 0.2 : 0.0;  // (the support starts at y = A)
      const RunSummary r = integrate(S, 0.0, x.q, x.p, x.v, 400, [](auto&&...) {});
      BOOST_TEST(!r.failed, what << ": " << r.failure.message);
      VectorXd out(4);
      out << x.q, x.p;
      return out;
    };
    VectorXd a, b;
    if (forced) {
      const auto f = std::make_shared<const WrittenForce>(s);
      a = run(ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>(L, R, 0.01, con, {},
                                                                                      MomentumMap::general, f));
      b = run(ConstrainedHamiltonianThetaStep<HL, WrittenDynamic, WrittenConstraints, WrittenForce>(
          HL(L), L, R, 0.01, con, {}, MomentumMap::general, f));
    } else {
      a = run(Step(L, R, 0.01, con, {}, MomentumMap::general));
      b = run(ConstrainedHamiltonianThetaStep<HL, WrittenDynamic, WrittenConstraints>(HL(L), L, R, 0.01, con));
    }
    BOOST_TEST_MESSAGE(what << " theta " << theta << ": " << (a - b).lpNorm<Eigen::Infinity>());
    BOOST_TEST((a - b).lpNorm<Eigen::Infinity>() <= 1e-12 * a.lpNorm<Eigen::Infinity>(), what << " theta " << theta);
  };
  compare(cartesian, 0.3, false, "Cartesian pendulum");
  compare(cartesian, 0.5, false, "Cartesian pendulum");
  auto moving = system_of({"x", "y"}, "m*(x_dot^2 + y_dot^2)/2 - m*g*y", {"x^2 + (y - A*cos(w*t))^2 - l^2"},
                          {{0, "-c*x_dot"}, {1, "-c*y_dot + 0.3*sin(w*t)"}});
  moving->name = "moving";
  compare(moving, 0.5, true, "damped pendulum on a moving support");

  const auto polar = system_of({"r", "a"}, "m*(r_dot^2 + r^2*a_dot^2)/2 + m*g*r*cos(a)", {"r - l"});
  const WrittenDynamic Lp(polar);
  const WrittenConstraints g(polar);
  const ConstrainedHamiltonianThetaStep<HL, WrittenDynamic, WrittenConstraints> S(
      HL(Lp), Lp, ThetaMap::midpoint(), 0.01, std::make_shared<WrittenConstraints>(polar), {}, MomentumMap::linear);
  VectorXd q(2), p(2), v(2);
  q << kL, 1.2;
  p << 0.0, kM * kL * kL * 0.5;
  v << 0.0, 0.5;
  double worst = 0.0;
  BOOST_TEST(!integrate(S, 0.0, q, p, v, 500,
                        [&](std::int64_t, double t, const VectorXd& qk, const VectorXd& pk, const StepSummary&) {
                          VectorXd vk(2);
                          vk << pk[0] / kM, pk[1] / (kM * qk[0] * qk[0]);
                          double a, b;
                          g.relative_residuals(t, qk, vk, a, b);
                          worst = std::fmax(worst, std::fmax(a, b));
                        })
                  .failed);
  const WrittenDynamic La(angle);
  const DynamicThetaStep<WrittenDynamic> A(La, ThetaMap::midpoint(), 0.01);
  VectorXd qa(1), pa(1), va(1);
  qa << 1.2;
  pa << kM * kL * kL * 0.5;
  va << 0.5;
  BOOST_TEST(!integrate(A, 0.0, qa, pa, va, 500, [](auto&&...) {}).failed);
  BOOST_TEST(std::fabs(q[0] - kL) <= 1e-14);
  BOOST_TEST(std::fabs(q[1] - qa[0]) <= 1e-12);
  BOOST_TEST(std::fabs(p[1] - pa[0]) <= 1e-12);
  BOOST_TEST(worst <= 1e-13);
}
