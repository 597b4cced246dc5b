// The FPU chain: closed-form gradient and tridiagonal Hessian against automatic
// differentiation; the O(n) dynamic-size step against the generic fixed-size steps;
// discrete Noether for translations (free ends) on both paths; large chains solve.
#define BOOST_TEST_MODULE chain
#include <boost/test/unit_test.hpp>

#include <random>

#include "mechanics/chain.h"
#include "mechanics/hamiltonian.h"
#include "solvers/chain_step.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"
#include "tests/random_vector.h"

using namespace dvm;
using Eigen::VectorXd;

BOOST_AUTO_TEST_CASE(gradient_and_hessian_match_automatic_differentiation) {
  for (bool fixed : {true, false}) {
    const FPUChain C(6, 1.3, 0.8, 0.7, 1.9, fixed);
    const VectorXd q = random_vector(6, 0.5, 7);
    constexpr int K = 6;
    using D = ceres::Jet<double, K>;
    Vec<D, K> qd;
    for (int i = 0; i < K; ++i) qd[i] = D(q[i], i);
    const D V = C.potential(qd);
    VectorXd g, diag, off;
    C.gradient(q, g);
    C.hessian(q, diag, off);
    BOOST_TEST(std::fabs(V.a - C.potential(q)) <= 1e-15);
    for (int i = 0; i < K; ++i) BOOST_TEST(std::fabs(g[i] - V.v[i]) <= 1e-14);
    // Hessian columns: differentiate the gradient along each unit vector
    using D2 = ceres::Jet<D, K>;
    Vec<D2, K> qq;
    for (int i = 0; i < K; ++i) qq[i] = D2(D(q[i], i), Vec<D, K>::Unit(i).eval());
    const D2 W = C.potential(qq);
    for (int i = 0; i < K; ++i)
      for (int j = 0; j < K; ++j) {
        const double hij = W.v[i].v[j];
        const double expect = i == j ? diag[i] : (std::abs(i - j) == 1 ? off[std::min(i, j)] : 0.0);
        BOOST_TEST(std::fabs(hij - expect) <= 1e-13);
      }
  }
}

// The one-pass derivatives the chain step uses give the separate calls' values exactly
// (the same operations in the same order), at a state with springs of both signs.
BOOST_AUTO_TEST_CASE(one_pass_derivatives_equal_the_separate_calls) {
  for (bool fixed : {true, false})
    for (int n : {1, 2, 7}) {
      const FPUChain C(n, 1.3, 0.8, -0.7, 1.9, fixed);
      const VectorXd q = random_vector(n, 0.9, 11);
      VectorXd g, diag, off, g1, diag1, off1;
      C.gradient(q, g);
      C.hessian(q, diag, off);
      double force_max = -1.0, stiffness_max = -1.0;
      C.derivatives(q, g1, diag1, off1, force_max, stiffness_max);
      BOOST_TEST(g1 == g);
      BOOST_TEST(diag1 == diag);
      BOOST_TEST(off1 == off);
      BOOST_TEST(force_max + stiffness_max * max_abs(q) == C.gradient_scale(q));
      BOOST_TEST((force_max > 0.0) == (C.bonds() > 0));  // (a free chain of one particle has no bond)
    }
}

BOOST_AUTO_TEST_CASE(dynamic_chain_step_equals_the_generic_fixed_size_step) {
  constexpr int n = 5;
  for (bool fixed : {true, false})
    for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap(0.3), ThetaMap::adjoint_euler()}) {
      const FPUChain C(n, 1.0, 1.0, 0.5, 2.0, fixed);
      const double h = 0.05;
      const VectorXd q0 = random_vector(n, 0.4, 3), p0 = random_vector(n, 0.6, 4);
      const ChainStep S(C, R, h);
      VectorXd dq = h * p0, dp = VectorXd::Zero(n);
      const StepSummary s = S.step(0.0, q0, p0, dq, dp);
      BOOST_TEST(s.converged);
      const PositionMomentumStep<FixedChain<n>, ThetaMap> G(FixedChain<n>(C), R, h);
      Vec<double, n> gq = q0, gp = p0, gdq = h * gp, gdp = Vec<double, n>::Zero();
      BOOST_TEST(G.step(0.0, gq, gp, gdq, gdp).converged);
      BOOST_TEST_CONTEXT(R.name() << (fixed ? " fixed" : " free")) {
        BOOST_TEST(max_abs(VectorXd(dq - gdq)) <= 1e-15);
        BOOST_TEST(max_abs(VectorXd(dp - gdp)) <= 1e-15);
      }
    }
}

BOOST_AUTO_TEST_CASE(free_chain_conserves_total_momentum) {
  // Translations q_i -> q_i + c leave a free chain's L invariant; the discrete
  // momentum map of the theta-map L_d is sum_i p_i, conserved to round-off.
  const int n = 64;
  const FPUChain C(n, 1.0, 1.0, 0.25, 1.0, false);
  const VectorXd q0 = random_vector(n, 0.3, 11), p0 = random_vector(n, 0.5, 12) + VectorXd::Constant(n, 0.2);
  for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap(0.3)}) {
    const ChainStep S(C, R, 0.05);
    VectorXd q = q0, p = p0;
    const double P0 = FPUChain::total_momentum(p0), E0 = C.energy(q0, p0);
    double worst = 0.0, worstE = 0.0;
    const RunSummary run = integrate(S, 0.0, q, p, VectorXd(p0 / C.m), 4000,
                                     [&](std::int64_t, double, const VectorXd& qk, const VectorXd& pk,
                                         const StepSummary&) {
                                       worst = std::fmax(worst, std::fabs(FPUChain::total_momentum(pk) - P0));
                                       worstE = std::fmax(worstE, std::fabs(C.energy(qk, pk) - E0));
                                     });
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(!run.failed);
      BOOST_TEST_MESSAGE(R.name() << ": max |P - P0| = " << worst << ", max |E - E0| = " << worstE);
      BOOST_TEST(worst <= 1e-12);
      // the energy is not conserved exactly, but stays bounded (no drift): a sanity
      // bound far below E0, which is O(n)
      BOOST_TEST(worstE <= 0.05 * E0);
    }
  }
  // With walls the translation symmetry is broken and the momentum changes: the
  // measurement above can fail.
  const FPUChain W(n, 1.0, 1.0, 0.25, 1.0, true);
  const ChainStep S(W, ThetaMap::midpoint(), 0.05);
  VectorXd q = q0, p = p0;
  integrate(S, 0.0, q, p, p0, 400, [](auto&&...) {});
  BOOST_TEST(std::fabs(FPUChain::total_momentum(p) - FPUChain::total_momentum(p0)) >= 1e-2);
}

BOOST_AUTO_TEST_CASE(translation_noether_on_the_generic_paths) {
  // The same symmetry through the generic fixed-size Lagrangian and Hamiltonian steps.
  constexpr int n = 4;
  const FPUChain C(n, 1.0, 1.0, 0.5, 1.5, false);
  const Vec<double, n> q0 = random_vector(n, 0.3, 21), p0 = random_vector(n, 0.5, 22);
  const double P0 = p0.sum();
  {
    const PositionMomentumStep<FixedChain<n>, ThetaMap> S(FixedChain<n>(C), ThetaMap(0.3), 0.05);
    Vec<double, n> q = q0, p = p0;
    double worst = 0.0;
    integrate(S, 0.0, q, p, p0, 1000,
              [&](std::int64_t, double, const auto&, const auto& pk, const StepSummary&) {
                worst = std::fmax(worst, std::fabs(FPUChain::total_momentum(pk) - P0));
              });
    BOOST_TEST(worst <= 1e-13);
  }
  {
    using H = LegendreHamiltonian<FixedChain<n>>;
    const HamiltonianStep<H, ThetaMap> S(H(FixedChain<n>(C)), ThetaMap::midpoint(), 0.05);
    Vec<double, n> q = q0, p = p0;
    double worst = 0.0;
    integrate(S, 0.0, q, p, p0, 1000,
              [&](std::int64_t, double, const auto&, const auto& pk, const StepSummary&) {
                worst = std::fmax(worst, std::fabs(FPUChain::total_momentum(pk) - P0));
              });
    BOOST_TEST(worst <= 1e-13);
  }
}

BOOST_AUTO_TEST_CASE(large_chains_solve) {
  // 20000 particles, a few implicit midpoint steps, each converging in a few Newton
  // iterations (the tridiagonal solve is exact Newton).
  const int n = 20000;
  const FPUChain C(n, 1.0, 1.0, 0.25, 1.0, true);
  VectorXd q(n), p = random_vector(n, 0.1, 5);
  for (int i = 0; i < n; ++i) q[i] = 0.5 * std::sin(M_PI * (i + 1) / (n + 1.0));
  const double E0 = C.energy(q, p);
  const ChainStep S(C, ThetaMap::midpoint(), 0.02);
  {
    // the first step solves the midpoint equations at this size, to round-off:
    // p0 - (m/h) dq - (h/2) grad V(q0 + dq/2) = 0 and p1 - p0 = -h grad V(q0 + dq/2)
    VectorXd dq = 0.02 * p, dp(n), g(n);
    BOOST_TEST_REQUIRE(S.step(0.0, q, p, dq, dp).converged);
    C.gradient(VectorXd(q + 0.5 * dq), g);
    const double scale = p.lpNorm<Eigen::Infinity>();
    BOOST_TEST(VectorXd(p - (C.m / 0.02) * dq - 0.01 * g).lpNorm<Eigen::Infinity>() <= 1e-13 * scale);
    BOOST_TEST(VectorXd(dp + 0.02 * g).lpNorm<Eigen::Infinity>() <= 1e-15 * scale);
    BOOST_TEST(dq.lpNorm<Eigen::Infinity>() >= 1e-3);  // it moved
  }
  const RunSummary run = integrate(S, 0.0, q, p, p, 20, [](auto&&...) {});
  BOOST_TEST(!run.failed);
  BOOST_TEST(run.max_step_iterations <= 5);
  BOOST_TEST(std::fabs(C.energy(q, p) - E0) <= 1e-3 * E0);
}

BOOST_AUTO_TEST_CASE(accepted_step_gets_the_last_newton_correction) {
  // As solve_newton does, the chain's Newton loop applies the correction of the
  // residual it accepted. With a loose tolerance (1e-4) and a zero guess the step is
  // accepted after two iterations at a residual near 1e-5; the returned increment
  // then satisfies the step equation p0 - (m/h) dq - h (1 - theta) grad V(q0 + theta dq) = 0
  // to round-off (without the correction the residual left would be the accepted one).
  const int n = 50;
  const FPUChain C(n, 1.0, 1.0, 0.5, 2.0, true);
  const double h = 0.05;
  VectorXd q0(n), p0(n);
  for (int i = 0; i < n; ++i) {
    q0[i] = 0.3 * std::sin(0.7 * i + 0.2);
    p0[i] = 0.5 * std::cos(1.3 * i);
  }
  StepOptions opt;
  opt.residual_tolerance = 1e-4;
  opt.accept_tolerance = 1e-4;
  for (double th : {0.5, 0.3}) {
    const ChainStep S(C, ThetaMap(th), h, opt);
    VectorXd dq = VectorXd::Zero(n), dp(n), g(n);
    const StepSummary s = S.step(0.0, q0, p0, dq, dp);
    BOOST_TEST_REQUIRE(s.converged);
    C.gradient(VectorXd(q0 + th * dq), g);
    const double left = VectorXd(p0 - (C.m / h) * dq - h * (1.0 - th) * g).lpNorm<Eigen::Infinity>();
    BOOST_TEST_MESSAGE("chain, theta " << th << ": accepted residual " << s.residual << ", left after the step "
                                       << left);
    BOOST_TEST(s.residual >= 1e-8 * s.scale);  // the accepted residual was not round-off
    BOOST_TEST(left <= 1e-13 * s.scale);
  }
}
