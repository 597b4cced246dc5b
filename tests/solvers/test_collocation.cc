// Gauss collocation on the stage forces (solvers/collocation_step.h), the Galerkin Gauss
// step of separable systems:
//   - its Nystrom tables satisfy the simplifying assumptions of the Gauss method
//     (C(s) through A^2, B(s) through b^T A) and equal the hand-written baseline's,
//     computed another way (examples/bench/hand_written.h);
//   - it gives the generic Galerkin step's trajectory (simplified Newton on the nodes,
//     solvers/galerkin_step.h) to round-off, s = 1..6, with compile-time and run-time
//     stage counts, on Kepler and a full mass matrix (Cholesky), and on the
//     run-time-sized systems (n bodies, a written chain) against DynamicGalerkinStep
//     (every separable built-in through the runtime: test_splitting.cc);
//   - a step whose fixed point does not contract (h omega large) is handed to the
//     generic step and gives its answer; beyond max_newton_dim it fails with a message;
//   - the starting guess keeps the sweeps per step low on a long Kepler run.
#define BOOST_TEST_MODULE collocation
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "examples/bench/hand_written.h"
#include "mechanics/dynamic_system.h"
#include "mechanics/expression.h"
#include "mechanics/nbody_dynamic.h"
#include "mechanics/systems_classic.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/collocation_step.h"
#include "solvers/integrate.h"
#include "tests/solvers/trajectories.h"

using namespace dvm;
using Eigen::VectorXd;
using dvm_test::trajectory;
using dvm_test::trajectory_difference;

namespace {

// Collocation against the generic Galerkin step on a fixed-size system, s = 1..6.
template <class S>
void check_against_generic(const S& L, const Vec<double, S::dim>& q0, const Vec<double, S::dim>& v0, double h,
                           int steps) {
  const Vec<double, S::dim> p0 = legendre(L, q0, v0);
  for (int s = 1; s <= kGalerkinMaxStages; ++s) {
    const SeparableGaussStep<S> C(L, s, h, StepOptions{}, q0);
    const GalerkinStep<S> G(L, QuadratureKind::gauss, s, h);
    const double d = trajectory_difference(trajectory(C, q0, p0, v0, steps), trajectory(G, q0, p0, v0, steps));
    BOOST_TEST_MESSAGE(L.name() << " s = " << s << ": relative difference " << d << ", sweeps "
                                << static_cast<double>(C.forces()) / (s * steps) << " per step");
    BOOST_TEST(d <= 1e-12, L.name() << " s = " << s << ": " << d);
    BOOST_TEST(C.newton_steps() == 0);
  }
}

// L = v^T M v / 2 - (|q|^2/2 + q0^4/4), M = [[2, 0.5], [0.5, 1]]: no closed-form velocity
struct FullMass {
  static constexpr int dim = 2;
  static constexpr Structure structure = Structure::separable;
  std::string name() const { return "full-mass"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    return 0.5 * (2.0 * v[0] * v[0] + v[0] * v[1] + v[1] * v[1]) -
           (0.5 * (q[0] * q[0] + q[1] * q[1]) + 0.25 * q[0] * q[0] * q[0] * q[0]);
  }
};

}  // namespace

BOOST_AUTO_TEST_CASE(tables_satisfy_the_gauss_simplifying_assumptions) {
  for (int s = 1; s <= kGalerkinMaxStages; ++s) {
    const GaussNystromTables t(s);
    BOOST_TEST_CONTEXT("s = " << s) {
      for (int k = 1; k <= s; ++k) {
        // B(s) through bbar = b^T A: sum_i bbar_i c_i^{k-1} = 1 / (k (k + 1))
        double sb = 0.0;
        for (int i = 0; i < s; ++i) sb += t.bbar[i] * std::pow(t.c[i], k - 1);
        BOOST_TEST(std::fabs(sb - 1.0 / (k * (k + 1))) <= 1e-15);
      }
      for (int i = 0; i < s; ++i) {
        // C(s) twice: sum_j abar_ij c_j^{k-1} = c_i^{k+1} / (k (k + 1)), k = 1..s-1
        for (int k = 1; k < s; ++k) {
          double sa = 0.0;
          for (int j = 0; j < s; ++j) sa += t.abar[i][j] * std::pow(t.c[j], k - 1);
          BOOST_TEST(std::fabs(sa - std::pow(t.c[i], k + 1) / (k * (k + 1))) <= 1e-15);
        }
        // E extrapolates every polynomial of degree <= s through 0 exactly:
        // sum_k E_ik c_k^m = (1 + c_i)^m - 1
        for (int m = 1; m <= s; ++m) {
          double se = 0.0;
          for (int k = 0; k < s; ++k) se += t.E[i][k] * std::pow(t.c[k], m);
          BOOST_TEST(std::fabs(se - (std::pow(1.0 + t.c[i], m) - 1.0)) <= 1e-12 * std::pow(2.0, m));
        }
      }
    }
  }
  // the hand-written baseline computes s = 6 another way (monomials, its own nodes)
  const GaussNystromTables t(6);
  const bench::HandGaussTables<6> u;
  for (int i = 0; i < 6; ++i) {
    BOOST_TEST(std::fabs(t.c[i] - u.c[i]) <= 1e-16);
    BOOST_TEST(std::fabs(t.b[i] - u.b[i]) <= 1e-16);
    BOOST_TEST(std::fabs(t.bbar[i] - u.bbar[i]) <= 1e-16);
    for (int j = 0; j < 6; ++j) {
      BOOST_TEST(std::fabs(t.abar[i][j] - u.abar[i][j]) <= 1e-16);
      BOOST_TEST(std::fabs(t.E[i][j] - u.E[i][j]) <= 1e-12);
    }
  }
}

BOOST_AUTO_TEST_CASE(equals_the_generic_galerkin_step) {
  // (every separable built-in, through the runtime: tests/solvers/test_splitting.cc)
  using V2 = Vec<double, 2>;
  check_against_generic(Kepler(1.0), V2(0.4, 0.0), V2(0.0, 2.0), 0.05, 200);
  // a mass matrix with no closed-form inverse: solved with its Cholesky factor
  check_against_generic(FullMass{}, V2(0.7, -0.3), V2(0.2, 0.1), 0.1, 100);
  // a compile-time stage count: the same numbers as the run-time one
  const Kepler K(1.0);
  const V2 q0(0.4, 0.0), p0(0.0, 2.0);
  const SeparableGaussStep<Kepler, 6> A(K, 6, 0.05, StepOptions{}, q0);
  const SeparableGaussStep<Kepler> B(K, 6, 0.05, StepOptions{}, q0);
  BOOST_TEST(trajectory_difference(trajectory(A, q0, p0, p0, 200), trajectory(B, q0, p0, p0, 200)) <= 1e-15);
  BOOST_CHECK_THROW((SeparableGaussStep<Kepler, 6>(K, 4, 0.05, StepOptions{}, q0)), std::invalid_argument);
  BOOST_CHECK_THROW(SeparableGaussStep<Kepler>(K, 7, 0.05, StepOptions{}, q0), std::invalid_argument);
  BOOST_CHECK_THROW(SeparableGaussStep<Kepler>(K, 2, 0.0, StepOptions{}, q0), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(run_time_sized_systems_equal_the_dynamic_galerkin_step) {
  // three bodies, and the fixed-size NBody<3> through the same method
  VectorXd q(9), v(9);
  q << 1, 0, 0, -1, 0, 0, 0, 0.5, 0.1;
  v << 0, 0.5, 0, 0, -0.5, 0.1, 0.2, 0, 0;
  const NBodyDynamic D(1.0, {1.0, 1.0, 0.1});
  const VectorXd p = legendre(D, q, v);
  for (int s : {1, 3, 6}) {
    const SeparableGaussStep<NBodyDynamic> C(D, s, 0.01, StepOptions{}, q);
    const DynamicGalerkinStep<NBodyDynamic> G(D, QuadratureKind::gauss, s, 0.01);
    const auto a = trajectory(C, q, p, v, 100);
    BOOST_TEST(trajectory_difference(a, trajectory(G, q, p, v, 100)) <= 1e-12, "n bodies, s = " << s);
    const SeparableGaussStep<NBody<3>> F(NBody<3>(1.0, {1.0, 1.0, 0.1}), s, 0.01, StepOptions{}, Vec<double, 9>(q));
    BOOST_TEST(trajectory_difference(a, trajectory(F, Vec<double, 9>(q), Vec<double, 9>(p), Vec<double, 9>(v), 100)) <= 1e-13);
  }
  // a written FPU-like chain of 40 particles with walls, a sum in its text
  auto w = std::make_shared<WrittenSystem>();
  w->add_array("q", 40, ExpressionSymbols::Boundary::fixed);
  w->params = {{"n", 40.0}, {"beta", 1.0}};
  w->check_names();
  w->lagrangian = Expression::parse("sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + "
                                    "beta/4*(q[i] - q[i-1])^4)",
                                    w->symbols(WrittenSystem::Kind::lagrangian));
  const WrittenDynamic L(w);
  BOOST_REQUIRE(L.separable());
  VectorXd x(40), u = VectorXd::Zero(40);
  for (int i = 0; i < 40; ++i) x[i] = std::sin(M_PI * (i + 1) / 41.0);
  const VectorXd px = legendre(L, x, u);
  const SeparableGaussStep<WrittenSeparable, 0, WrittenDynamic> C(WrittenSeparable(L), L, 4, 0.05, StepOptions{}, x);
  const DynamicGalerkinStep<WrittenDynamic> G(L, QuadratureKind::gauss, 4, 0.05);
  BOOST_TEST(trajectory_difference(trajectory(C, x, px, u, 100), trajectory(G, x, px, u, 100)) <= 1e-12);
  BOOST_TEST(C.newton_steps() == 0);
}

BOOST_AUTO_TEST_CASE(steps_that_do_not_contract_are_solved_by_newton) {
  // q'' = -omega^2 q: the sweep multiplies errors by about (h omega)^2 |abar|, so
  // h omega = 4 diverges and h omega = 0.2 contracts
  using V1 = Vec<double, 1>;
  const V1 q0(1.0), p0(0.0);
  for (double homega : {4.0, 0.2})
    for (int s : {2, 5}) {
      const HarmonicOscillator L(homega / 0.1);
      const SeparableGaussStep<HarmonicOscillator> C(L, s, 0.1, StepOptions{}, q0);
      const GalerkinStep<HarmonicOscillator> G(L, QuadratureKind::gauss, s, 0.1);
      BOOST_TEST_CONTEXT("h omega = " << homega << ", s = " << s) {
        BOOST_TEST(trajectory_difference(trajectory(C, q0, p0, p0, 50), trajectory(G, q0, p0, p0, 50)) <= 1e-12);
        BOOST_TEST(C.newton_steps() == (homega > 1.0 ? 50 : 0));
      }
    }
  // beyond the size where a dense Newton iteration is allowed, the step fails and says why
  const SeparableGaussStep<HarmonicOscillator> C(HarmonicOscillator(40.0), 3, 0.1, StepOptions{}, q0, 0);
  V1 q = q0, p = p0;
  const RunSummary r = integrate(C, 0.0, q, p, p0, 5, [](auto&&...) {});
  BOOST_TEST(r.failed);
  BOOST_TEST(r.failed_step == 0);
  BOOST_TEST(r.failure.message.find("fixed-point iteration") != std::string::npos, r.failure.message);
}

BOOST_AUTO_TEST_CASE(the_starting_guess_keeps_kepler_near_three_sweeps_a_step) {
  // e = 0.6, h = 0.125 (the step that reaches 1e-8 at t = 1000): s = 6 takes 3.74 sweeps a
  // step (22.5 forces). Started from c h v0 at every step it takes 5.5 (measured with the
  // guess disabled): the extrapolated polynomial is what keeps it low.
  const Kepler K(1.0);
  Vec<double, 2> q(0.4, 0.0), p(0.0, 2.0);
  const Vec<double, 2> v0 = p;
  const SeparableGaussStep<Kepler> C(K, 6, 0.125, StepOptions{}, q);
  const int steps = 8000;
  const RunSummary r = integrate(C, 0.0, q, p, v0, steps, [](auto&&...) {});
  BOOST_REQUIRE(!r.failed);
  const double sweeps = static_cast<double>(r.solver_iterations) / steps;
  BOOST_TEST_MESSAGE("Kepler, s = 6, h = 0.125: " << sweeps << " sweeps per step");
  BOOST_TEST(sweeps <= 4.0);
  BOOST_TEST(C.newton_steps() == 0);
  // the error at t = 1000 is the method's (1.1e-8 measured in bench_galerkin_kepler)
  Vec<double, 2> qe, pe;
  K.exact(0.125 * steps, Vec<double, 2>(0.4, 0.0), Vec<double, 2>(0.0, 2.0), qe, pe);
  BOOST_TEST((q - qe).cwiseAbs().maxCoeff() <= 2e-8);
}
