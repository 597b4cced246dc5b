// Whole-trajectory (boundary-value) problems: one sparse Ceres problem for all interior
// nodes reproduces the one-step integrator, and a pendulum with 10^4 nodes solves; the
// poll hook is called after every iteration and stops the solve by throwing. The
// run-time-sized problem (its residual's Jacobian written out from L's Hessian) agrees
// with the fixed-size one (Jets) to round-off, and its Jacobian with central
// differences of its residual.
#define BOOST_TEST_MODULE boundary_value
#include <boost/test/unit_test.hpp>

#include <random>

#include "mechanics/dynamic_system.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "solvers/boundary_value.h"
#include "solvers/dynamic_boundary_value.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"

using namespace dvm;
using V1 = Vec<double, 1>;

namespace {

template <class System, class Map>
std::vector<V1> shoot(const System& L, const Map& R, double h, int K, const V1& q0, const V1& p0) {
  const PositionMomentumStep<System, Map> S(L, R, h);
  std::vector<V1> traj{q0};
  V1 q = q0, p = p0;
  const RunSummary run = integrate(S, 0.0, q, p, legendre_inverse(L, q0, p0), K,
                                   [&](std::int64_t, double, const V1& qk, const V1&, const StepSummary&) {
                                     traj.push_back(qk);
                                   });
  BOOST_REQUIRE(!run.failed);
  return traj;
}

}  // namespace

BOOST_AUTO_TEST_CASE(harmonic_boundary_value_reproduces_the_one_step_trajectory) {
  // Shoot from (q0, p0) with the position-momentum step, keep the end node, solve the
  // boundary-value problem between the two ends from a straight-line guess: the nodes
  // and the momenta must be the shot ones.
  const HarmonicOscillator H(1.0);
  const double h = 0.01;
  const int K = 200;  // T = 2 < pi: no conjugate points, the solution is unique
  for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap(0.3)}) {
    const V1 q0(1.0), p0(0.3);
    const std::vector<V1> traj = shoot(H, R, h, K, q0, p0);
    const BoundaryValueProblem<HarmonicOscillator, ThetaMap> B(H, R, h);
    const auto res = B.solve(traj.front(), traj.back(), K);
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(res.converged, res.message);
      double dev = 0.0;
      for (int k = 0; k <= K; ++k) dev = std::fmax(dev, std::fabs(res.q[k][0] - traj[k][0]));
      BOOST_TEST_MESSAGE(R.name() << ": max |q_bvp - q_shot| = " << dev << ", DEL residual " << res.max_residual
                                  << ", iterations " << res.iterations);
      BOOST_TEST(dev <= 1e-12);
      BOOST_TEST(std::fabs(res.p[0][0] - p0[0]) <= 1e-11);
    }
  }
}

BOOST_AUTO_TEST_CASE(pendulum_with_ten_thousand_nodes_solves) {
  // q(0) = 0, q(2) = 1.5 rad (a large swing), h = 2e-4: 9999 unknown nodes.
  const Pendulum P(1.0, 1.0, 1.0);
  const double h = 2e-4;
  const int K = 10000;
  const BoundaryValueProblem<Pendulum, ThetaMap> B(P, ThetaMap::midpoint(), h);
  const auto res = B.solve(V1(0.0), V1(1.5), K);
  BOOST_TEST_MESSAGE("pendulum 1e4 nodes: DEL residual " << res.max_residual << " (scale " << res.scale
                                                         << "), iterations " << res.iterations << "; "
                                                         << res.message);
  BOOST_TEST(res.converged, res.message);
  BOOST_TEST(res.q.front()[0] == 0.0);
  BOOST_TEST(res.q.back()[0] == 1.5);
  // It is a trajectory: the energy of the midpoint states varies only at O(h^2), and
  // shooting from (q_0, p_0) retraces the nodes.
  double emin = INFINITY, emax = -INFINITY;
  for (int k = 0; k <= K; ++k) {
    const double E = 0.5 * res.p[k][0] * res.p[k][0] - std::cos(res.q[k][0]);
    emin = std::fmin(emin, E);
    emax = std::fmax(emax, E);
  }
  BOOST_TEST(emax - emin <= 1e-7);
  const std::vector<V1> traj = shoot(P, ThetaMap::midpoint(), h, K, res.q[0], res.p[0]);
  double dev = 0.0;
  for (int k = 0; k <= K; ++k) dev = std::fmax(dev, std::fabs(res.q[k][0] - traj[k][0]));
  BOOST_TEST_MESSAGE("pendulum: max |q_bvp - q_shot| = " << dev);
  BOOST_TEST(dev <= 1e-8);
}

BOOST_AUTO_TEST_CASE(the_poll_hook_sees_every_iteration_and_can_stop_the_solve) {
  // BoundaryValueOptions::poll is called after each Ceres iteration, 0 (the start)
  // first; an exception it throws stops the solve and comes out of solve().
  const Pendulum P(1.0, 1.0, 1.0);
  const double h = 2e-3;
  const int K = 1000;
  const BoundaryValueProblem<Pendulum, ThetaMap> B(P, ThetaMap::midpoint(), h);
  std::vector<int> seen;
  BoundaryValueOptions opt;
  opt.poll = [&](int iteration) { seen.push_back(iteration); };
  const auto res = B.solve(V1(0.0), V1(1.5), K, opt);
  BOOST_TEST(res.converged, res.message);
  BOOST_REQUIRE(!seen.empty());
  // (the iteration that meets a stopping rule is counted, and may not be called back)
  BOOST_TEST(static_cast<int>(seen.size()) <= res.iterations);
  BOOST_TEST(static_cast<int>(seen.size()) >= res.iterations - 1);
  for (std::size_t i = 0; i < seen.size(); ++i) BOOST_TEST(seen[i] == static_cast<int>(i));
  // the same problem, stopped at iteration 1 of the several it takes
  BOOST_REQUIRE(res.iterations > 2);
  struct Stop {
    int iteration;
  };
  seen.clear();
  opt.poll = [&](int iteration) {
    seen.push_back(iteration);
    if (iteration == 1) throw Stop{iteration};
  };
  bool stopped = false;
  try {
    B.solve(V1(0.0), V1(1.5), K, opt);
  } catch (const Stop& s) {
    stopped = s.iteration == 1;
  }
  BOOST_TEST(stopped);
  BOOST_TEST((seen == std::vector<int>{0, 1}));
}

BOOST_AUTO_TEST_CASE(run_time_sized_jacobian_matches_central_differences) {
  // The double pendulum (L_qv and L_vv depend on q: every block of the written-out
  // Jacobian counts) at theta 0.3 and 1/2: each of the three n x n blocks of d DEL /
  // d(a, b, c) against central differences of DEL, to 1e-7 relative to the block's size.
  using VX = Eigen::VectorXd;
  const DoublePendulum D(1.0, 1.5, 1.0, 0.7, 9.81);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (double theta : {0.3, 0.5}) {
    const DynamicBoundaryValueProblem<FixedAsDynamic<DoublePendulum>> B(FixedAsDynamic<DoublePendulum>(D), theta, 0.05);
    for (int trial = 0; trial < 5; ++trial) {
      VX x[3];
      for (VX& xi : x) xi = VX::NullaryExpr(2, [&] { return u(rng); });
      VX r(2);
      using Row = Eigen::Matrix<double, 2, 2, Eigen::RowMajor>;
      Row J[3];
      double* Jp[3] = {J[0].data(), J[1].data(), J[2].data()};
      B.evaluate(x[0].data(), x[1].data(), x[2].data(), r.data(), Jp);
      BOOST_TEST((r - B.del(x[0], x[1], x[2])).cwiseAbs().maxCoeff() <= 1e-14 * (1.0 + r.cwiseAbs().maxCoeff()));
      const double e = 1e-6;
      for (int node = 0; node < 3; ++node) {
        Row Jfd;
        for (int j = 0; j < 2; ++j) {
          VX xp[3] = {x[0], x[1], x[2]}, xm[3] = {x[0], x[1], x[2]};
          xp[node][j] += e;
          xm[node][j] -= e;
          Jfd.col(j) = (B.del(xp[0], xp[1], xp[2]) - B.del(xm[0], xm[1], xm[2])) / (2.0 * e);
        }
        const double diff = (J[node] - Jfd).cwiseAbs().maxCoeff(), size = J[node].cwiseAbs().maxCoeff();
        BOOST_TEST(diff <= 1e-7 * size, "theta " << theta << " node " << node << ": |J - J_fd| = " << diff
                                                 << ", |J| = " << size);
      }
    }
  }
}

BOOST_AUTO_TEST_CASE(run_time_sized_problem_agrees_with_the_fixed_size_one) {
  // The same boundary-value problems solved by Jets of the three nodes (fixed size) and
  // by the written-out Jacobian (run-time size): the same discrete Euler-Lagrange
  // equations, so the same nodes and momenta to round-off, for the midpoint map and
  // theta = 0.3; and both reproduce the shot trajectory.
  using VX = Eigen::VectorXd;
  using V2 = Vec<double, 2>;
  const DoublePendulum D(1.0, 1.0, 1.0, 1.0, 1.0);
  const double h = 0.01;
  const int K = 150;
  for (const ThetaMap& R : {ThetaMap::midpoint(), ThetaMap(0.3)}) {
    const BoundaryValueProblem<DoublePendulum, ThetaMap> F(D, R, h);
    const DynamicBoundaryValueProblem<FixedAsDynamic<DoublePendulum>> B(FixedAsDynamic<DoublePendulum>(D), R.theta(), h);
    const V2 qa(0.4, -0.2), qb(0.1, 0.5);
    const auto f = F.solve(qa, qb, K);
    const auto b = B.solve(VX(qa), VX(qb), K);
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(f.converged, f.message);
      BOOST_TEST(b.converged, b.message);
      BOOST_REQUIRE(b.q.size() == f.q.size());
      double dq = 0.0, dp = 0.0, qmax = 0.0, pmax = 0.0;
      for (std::size_t k = 0; k < f.q.size(); ++k) {
        dq = std::fmax(dq, (b.q[k] - VX(f.q[k])).cwiseAbs().maxCoeff());
        dp = std::fmax(dp, (b.p[k] - VX(f.p[k])).cwiseAbs().maxCoeff());
        qmax = std::fmax(qmax, f.q[k].cwiseAbs().maxCoeff());
        pmax = std::fmax(pmax, f.p[k].cwiseAbs().maxCoeff());
      }
      BOOST_TEST_MESSAGE(R.name() << ": run-time against fixed size, max |dq| = " << dq << ", max |dp| = " << dp
                                  << "; iterations " << b.iterations << " and " << f.iterations);
      BOOST_TEST(dq <= 1e-12 * qmax);
      BOOST_TEST(dp <= 1e-10 * pmax);
      BOOST_TEST(std::fabs(b.scale - f.scale) <= 1e-12 * f.scale);
      // the solved path is the one-step integrator's from (q_0, p_0)
      const PositionMomentumStep<DoublePendulum, ThetaMap> S(D, R, h);
      V2 q = f.q[0], p = V2(b.p[0]);
      double dev = 0.0;
      for (int k = 0; k < K; ++k) {
        V2 dqk, dpk;
        BOOST_REQUIRE(S.step(0.0, q, p, dqk, dpk).converged);
        q += dqk;
        p += dpk;
        dev = std::fmax(dev, (VX(q) - b.q[static_cast<std::size_t>(k + 1)]).cwiseAbs().maxCoeff());
      }
      BOOST_TEST(dev <= 1e-9, "shot from the run-time-sized (q_0, p_0): max |q - q_bvp| = " << dev);
    }
  }
}
