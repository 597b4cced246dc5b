// The position-momentum step: closed-form special cases, both solvers, failures, and
// its derivative (against the closed form, central differences and A^T J A = J).
#define BOOST_TEST_MODULE solvers
#include <boost/test/unit_test.hpp>

#include <cmath>

#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "solvers/integrate.h"
#include "solvers/newton.h"
#include "solvers/position_momentum_step.h"

using namespace dvm;
using V1 = Vec<double, 1>;
using V2 = Vec<double, 2>;

BOOST_AUTO_TEST_CASE(midpoint_step_is_the_implicit_midpoint_rule) {
  // For the harmonic oscillator the implicit midpoint rule is the Cayley transform
  // z1 = (I - hA/2)^{-1} (I + hA/2) z0 with A = [[0, 1], [-w^2, 0]].
  const double w = 2.0, h = 0.1;
  for (SolverKind kind : {SolverKind::newton, SolverKind::tiny}) {
    StepOptions opt;
    opt.solver = kind;
    const PositionMomentumStep<HarmonicOscillator, ThetaMap> S(HarmonicOscillator(w), ThetaMap::midpoint(), h, opt);
    Mat<double, 2, 2> A;
    A << 0, 1, -w * w, 0;
    const Mat<double, 2, 2> I = Mat<double, 2, 2>::Identity();
    const Mat<double, 2, 2> C = (I - 0.5 * h * A).inverse() * (I + 0.5 * h * A);
    const V1 q0(0.7), p0(-0.3);
    V1 dq = V1::Zero(), dp = V1::Zero();
    const StepSummary s = S.step(0.0, q0, p0, dq, dp);
    BOOST_TEST(s.converged);
    BOOST_TEST(s.residual <= 1e-13 * s.scale);
    const V2 z1 = C * V2(q0[0], p0[0]);
    // Newton overshoots its tolerance to round-off; TinySolver stops as soon as the
    // residual meets the tolerance, which bounds the error in q1 by about
    // tol * scale / |J| with |J| = 1/h here.
    const double bound = kind == SolverKind::newton ? 1e-15 : opt.residual_tolerance * s.scale * h;
    BOOST_TEST_CONTEXT(to_string(kind)) {
      BOOST_TEST(std::fabs(q0[0] + dq[0] - z1[0]) <= bound);
      BOOST_TEST(std::fabs(p0[0] + dp[0] - z1[1]) <= bound);
    }
  }
}

BOOST_AUTO_TEST_CASE(euler_maps_give_the_symplectic_euler_methods) {
  // adjoint Euler (q - v, q):  q1 = q0 + h p0,         p1 = p0 - h V'(q1)
  // explicit Euler (q, q + v): p1 = p0 - h V'(q0),      q1 = q0 + h p1
  const Pendulum P(1.0, 1.0, 1.0);
  const double h = 0.05;
  const V1 q0(1.1), p0(0.4);
  V1 dq = V1::Zero(), dp = V1::Zero();
  const PositionMomentumStep<Pendulum, ThetaMap> A(P, ThetaMap::adjoint_euler(), h);
  BOOST_TEST(A.step(0.0, q0, p0, dq, dp).converged);
  const double qa = q0[0] + h * p0[0];
  BOOST_TEST(std::fabs(q0[0] + dq[0] - qa) <= 1e-15);
  BOOST_TEST(std::fabs(p0[0] + dp[0] - (p0[0] - h * std::sin(qa))) <= 1e-15);
  dq.setZero();
  const PositionMomentumStep<Pendulum, ThetaMap> E(P, ThetaMap::explicit_euler(), h);
  BOOST_TEST(E.step(0.0, q0, p0, dq, dp).converged);
  const double pe = p0[0] - h * std::sin(q0[0]);
  BOOST_TEST(std::fabs(p0[0] + dp[0] - pe) <= 1e-15);
  BOOST_TEST(std::fabs(q0[0] + dq[0] - (q0[0] + h * pe)) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(generic_and_closed_form_paths_agree) {
  // Kepler, theta = 0.3: closed-form map inverse and gradient against the Newton
  // inverse and automatic differentiation; Newton against TinySolver.
  const double h = 0.02;
  StepOptions tiny;
  tiny.solver = SolverKind::tiny;
  const PositionMomentumStep<Kepler, ThetaMap> A(Kepler(), ThetaMap(0.3), h);
  const PositionMomentumStep<GenericOnly<Kepler>, RetractionMap<EuclideanRetraction>> B(
      GenericOnly<Kepler>{Kepler()}, RetractionMap<EuclideanRetraction>({}, 0.3), h);
  const PositionMomentumStep<Kepler, ThetaMap> C(Kepler(), ThetaMap(0.3), h, tiny);
  const V2 q0(0.4, 0.1), p0(0.2, 1.9);
  V2 dqa = h * p0, dqb = h * p0, dqc = h * p0, dpa, dpb, dpc;
  BOOST_TEST(A.step(0.0, q0, p0, dqa, dpa).converged);
  BOOST_TEST(B.step(0.0, q0, p0, dqb, dpb).converged);
  BOOST_TEST(C.step(0.0, q0, p0, dqc, dpc).converged);
  BOOST_TEST(max_abs(dqa - dqb) <= 1e-15);
  BOOST_TEST(max_abs(dpa - dpb) <= 1e-14);
  BOOST_TEST(max_abs(dqa - dqc) <= 1e-15);
  BOOST_TEST(max_abs(dpa - dpc) <= 1e-14);
}

BOOST_AUTO_TEST_CASE(a_step_that_cannot_converge_is_reported) {
  // One Newton iteration from a poor guess cannot meet the tolerance.
  StepOptions opt;
  opt.max_iterations = 1;
  const PositionMomentumStep<Pendulum, ThetaMap> S(Pendulum(), ThetaMap::midpoint(), 0.5, opt);
  V1 dq(1.0), dp;
  const StepSummary s = S.step(0.0, V1(2.0), V1(0.3), dq, dp);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.iterations == 1);
  BOOST_TEST(s.residual > opt.residual_tolerance * s.scale);
  BOOST_TEST(!s.message.empty());
  // TinySolver's result is checked too: it has no failure status of its own.
  opt.solver = SolverKind::tiny;
  const PositionMomentumStep<Pendulum, ThetaMap> T(Pendulum(), ThetaMap::midpoint(), 0.5, opt);
  dq = V1(1.0);
  BOOST_TEST(!T.step(0.0, V1(2.0), V1(0.3), dq, dp).converged);
}

namespace {
// x - 2 y = 0 with y the root of y^2 - c, which each evaluation finds by a TinySolver solve
// of its own, on the thread of the outer one: the outer solve's workspace must not be
// the inner one's.
struct NestedRoot {
  double c;
  template <class T>
  bool operator()(const T* x, T* r) const {
    V1 y(1.0);
    const StepSummary inner = solve_tiny<1>(Square{c}, y, 0.0, tiny_options(), c);
    if (!inner.converged) return false;
    r[0] = x[0] - 2.0 * y[0];
    return true;
  }
  struct Square {
    double c;
    template <class T>
    bool operator()(const T* y, T* r) const {
      r[0] = y[0] * y[0] - c;
      return true;
    }
  };
  static StepOptions tiny_options() {
    StepOptions o;
    o.solver = SolverKind::tiny;
    return o;
  }
};
}  // namespace

BOOST_AUTO_TEST_CASE(a_tiny_solve_inside_another_keeps_its_own_workspace) {
  for (double c : {2.0, 9.0}) {
    V1 x(0.5);
    const StepSummary s = solve_tiny<1>(NestedRoot{c}, x, 0.0, NestedRoot::tiny_options(), 1.0);
    BOOST_TEST(s.converged);
    BOOST_TEST(std::fabs(x[0] - 2.0 * std::sqrt(c)) <= 1e-14 * std::sqrt(c));
    // and a plain solve after it, on the same thread, still converges to its root
    V1 y(1.0);
    BOOST_TEST(solve_tiny<1>(NestedRoot::Square{c}, y, 0.0, NestedRoot::tiny_options(), c).converged);
    BOOST_TEST(std::fabs(y[0] - std::sqrt(c)) <= 1e-14 * std::sqrt(c));
  }
}

BOOST_AUTO_TEST_CASE(non_finite_states_are_reported) {
  // Kepler started at the singularity q = 0: the residual is not finite.
  const PositionMomentumStep<Kepler, ThetaMap> S(Kepler(), ThetaMap::explicit_euler(), 0.1);
  V2 dq = V2::Zero(), dp = V2::Zero();
  const StepSummary s = S.step(0.0, V2::Zero(), V2(1.0, 0.0), dq, dp);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("non-finite") != std::string::npos);
}

BOOST_AUTO_TEST_CASE(integrate_stops_at_the_failed_step) {
  // A Kepler orbit with a huge step hits a step whose Newton solve fails: the run
  // reports that step and leaves (q, p) at the last converged state.
  StepOptions opt;
  opt.max_iterations = 3;
  const PositionMomentumStep<Kepler, ThetaMap> S(Kepler(), ThetaMap::midpoint(), 0.9, opt);
  V2 q(0.4, 0.0), p(0.0, 2.0);
  std::int64_t last = 0;
  V2 q_last = q;
  const RunSummary run = integrate(S, 0.0, q, p, p, 1000, [&](std::int64_t k, double, const V2& qk, const V2&, const StepSummary& s) {
    BOOST_TEST(s.converged);
    last = k;
    q_last = qk;
  });
  BOOST_TEST(run.failed);
  BOOST_TEST(run.failed_step == last);
  BOOST_TEST(run.steps_done == last);
  BOOST_TEST(!run.failure.converged);
  BOOST_TEST(max_abs(q - q_last) == 0.0);
}

BOOST_AUTO_TEST_CASE(compensated_sum_keeps_the_low_bits) {
  CompensatedVector<1> s(V1(1.0));
  for (int i = 0; i < 1000000; ++i) s.add(V1(1e-16));
  BOOST_TEST(std::fabs(s.sum[0] - (1.0 + 1e-10)) <= 2e-16);
}

// The step's derivative by the implicit function theorem. For the harmonic oscillator
// the midpoint step is linear, z1 = (I - hA/2)^{-1} (I + hA/2) z0: its derivative is
// that matrix.
BOOST_AUTO_TEST_CASE(the_step_derivative_of_the_midpoint_oscillator_is_the_cayley_transform) {
  const double w = 2.0, h = 0.1;
  const PositionMomentumStep<HarmonicOscillator, ThetaMap> S(HarmonicOscillator(w), ThetaMap::midpoint(), h);
  const V1 q0(0.7), p0(-0.3);
  V1 dq = h * p0, dp;
  BOOST_TEST_REQUIRE(S.step(0.0, q0, p0, dq, dp).converged);
  Mat<double, 2, 2> A, G, I = Mat<double, 2, 2>::Identity();
  BOOST_TEST_REQUIRE(S.derivative(q0, dq, A));
  G << 0.0, 1.0, -w * w, 0.0;
  const Mat<double, 2, 2> cayley = (I - 0.5 * h * G).inverse() * (I + 0.5 * h * G);
  BOOST_TEST((A - cayley).cwiseAbs().maxCoeff() <= 1e-14);
}

// Against central differences of the step itself (relative 1e-7) and symplectic to
// 1e-12, for closed-form gradients (pendulum, Kepler), automatic differentiation
// (the double pendulum), the map given as a retraction (Kepler, GenericOnly), and a
// symmetric and an asymmetric theta.
namespace {
template <class Step>
void check_derivative(const Step& S, const Vec<double, Step::N>& q0, const Vec<double, Step::N>& p0,
                      const Vec<double, Step::N>& guess) {
  constexpr int N = Step::N;
  using V = Vec<double, N>;
  using Y = Vec<double, 2 * N>;  // (named out here: g++ 12 fails on it inside the lambda)
  auto flow = [&](const V& q, const V& p) {
    V dq = guess, dp;
    BOOST_TEST_REQUIRE(S.step(0.0, q, p, dq, dp).converged);
    Y y;
    y << q + dq, p + dp;
    return y;
  };
  V dq = guess, dp;
  BOOST_TEST_REQUIRE(S.step(0.0, q0, p0, dq, dp).converged);
  Mat<double, 2 * N, 2 * N> A, C;
  BOOST_TEST_REQUIRE(S.derivative(q0, dq, A));
  const double eps = 1e-5;
  for (int j = 0; j < 2 * N; ++j) {
    V qa = q0, pa = p0, qb = q0, pb = p0;
    (j < N ? qa[j] : pa[j - N]) += eps;
    (j < N ? qb[j] : pb[j - N]) -= eps;
    C.col(j) = (flow(qa, pa) - flow(qb, pb)) / (2.0 * eps);
  }
  const double size = std::max(1.0, A.cwiseAbs().maxCoeff());
  BOOST_TEST((A - C).cwiseAbs().maxCoeff() <= 1e-7 * size);
  Mat<double, 2 * N, 2 * N> J = Mat<double, 2 * N, 2 * N>::Zero();
  J.template topRightCorner<N, N>().setIdentity();
  J.template bottomLeftCorner<N, N>() = -Mat<double, N, N>::Identity();
  BOOST_TEST((A.transpose() * J * A - J).cwiseAbs().maxCoeff() <= 1e-12 * size * size);
}
}  // namespace

BOOST_AUTO_TEST_CASE(the_step_derivative_against_central_differences_and_symplectic) {
  for (double theta : {0.5, 0.3}) {
    BOOST_TEST_CONTEXT("theta = " << theta) {
      const double h = 0.05;
      const Pendulum P(1.3, 0.8, 9.81);
      check_derivative(PositionMomentumStep<Pendulum, ThetaMap>(P, ThetaMap(theta), h), V1(2.0), V1(0.4),
                       V1(h * 0.4 / (1.3 * 0.8 * 0.8)));
      const V2 q0(0.4, 0.1), p0(0.2, 1.9);
      check_derivative(PositionMomentumStep<Kepler, ThetaMap>(Kepler(), ThetaMap(theta), 0.02), q0, p0, 0.02 * p0);
      check_derivative(PositionMomentumStep<GenericOnly<Kepler>, RetractionMap<EuclideanRetraction>>(
                           GenericOnly<Kepler>{Kepler()}, RetractionMap<EuclideanRetraction>({}, theta), 0.02),
                       q0, p0, 0.02 * p0);
      const DoublePendulum D(1.3, 0.7, 1.1, 0.9, 9.81);
      const V2 a0(0.5, 0.3), b0(0.2, -0.1);
      check_derivative(PositionMomentumStep<DoublePendulum, ThetaMap>(D, ThetaMap(theta), 0.02), a0, b0,
                       V2(0.02 * legendre_inverse(D, a0, b0)));
    }
  }
}
