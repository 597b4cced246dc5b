// The spherical chain at any number of links (mechanics/spherical_chain.h,
// solvers/sphere_chain_step.h):
//   - the O(K) product with the mass matrix against the dense matrix of its formula, and
//     the Lagrangian against the compiled chain's (SphericalChain<4>);
//   - the banded LU against a dense LU, where pivoting is forced (zero diagonal), and the
//     coupled solve of the chain against the dense matrix D + c B^T M C;
//   - the step's residual and Jacobian against the compiled step's, differentiated by
//     Jets; the same steps at links of 1e-7 and of 1e3 (the banded solve is unit-free);
//     the same run from the initial velocity and from its momentum;
//   - the Legendre map and its inverse, each the other's inverse;
//   - through the runtime, at 1 to 4 links, every sphere map (theta 0.3 and 0.7 too),
//     composed and as a DIRK, gives the compiled steps' states (use_structure = false)
//     to 1e-14 (1e-13 where the map is inverted by Newton's method);
//   - on 200 links: the vertical angular momentum conserved to round-off (discrete
//     Noether) and the links on the sphere; on 20, second order in the state and energy;
//   - 5 links and more are refused where the compiled steps would be needed, naming
//     the key.
#define BOOST_TEST_MODULE sphere_chain
#include <boost/test/unit_test.hpp>

#include <array>
#include <utility>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/banded_solve.h"
#include "mechanics/manifold_systems.h"
#include "mechanics/spherical_chain.h"
#include "solvers/manifold_step.h"
#include "solvers/sphere_chain_step.h"
#include "solvers/runtime/errors.h"
#include "solvers/runtime/problem.h"
#include "solvers/runtime/registry.h"
#include "solvers/runtime/run.h"
#include "tests/solvers/structured_runs.h"

using namespace dvm;
using Eigen::MatrixXd;
using Eigen::VectorXd;

namespace {

VectorXd random_vector(int n, std::mt19937& g, double lo = -1.0, double hi = 1.0) {
  std::uniform_real_distribution<double> u(lo, hi);
  VectorXd x(n);
  for (int i = 0; i < n; ++i) x[i] = u(g);
  return x;
}

// K unit vectors and tangent vectors at them.
void random_state(int K, std::mt19937& g, VectorXd& x, VectorXd& v) {
  x = random_vector(3 * K, g);
  v = random_vector(3 * K, g);
  for (int i = 0; i < K; ++i) {
    x.segment<3>(3 * i).normalize();
    const Vec<double, 3> xi = x.segment<3>(3 * i);
    v.segment<3>(3 * i) -= xi.dot(v.segment<3>(3 * i)) * xi;
  }
}

// M = (l_i l_j mu_max(i,j)) (x) I_3, from its definition.
MatrixXd dense_mass(const VectorXd& m, const VectorXd& l) {
  const int K = static_cast<int>(m.size());
  MatrixXd M = MatrixXd::Zero(3 * K, 3 * K);
  for (int i = 0; i < K; ++i)
    for (int j = 0; j < K; ++j) {
      const double mu = m.tail(K - std::max(i, j)).sum();
      M.block<3, 3>(3 * i, 3 * j) = l[i] * l[j] * mu * Mat<double, 3, 3>::Identity();
    }
  return M;
}

// A hanging chain of K links, bent and moving sideways (the state of every run below).
Problem chain_problem(int K, double h, std::int64_t steps, double m = 0.0, double l = 0.0) {
  Problem pr;
  pr.system = &find_system_entry("spherical-chain", "test");
  pr.params = {{"n", K}, {"m", m > 0 ? m : 1.0 / K}, {"l", l > 0 ? l : 1.0 / K}, {"g", 9.81}};
  pr.dim = 3 * K;
  for (int k = 1; k <= K; ++k) {
    const double f = static_cast<double>(k) / K;
    const double a = 0.6 * std::sin(M_PI * k / (K + 1)) + 0.4 * f, b = 1.2 * f;
    const Vec<double, 3> x(std::sin(a) * std::cos(b), std::sin(a) * std::sin(b), -std::cos(a));
    const Vec<double, 3> v = (0.5 + 0.5 * f) * Vec<double, 3>(0, 0, 1).cross(x) + Vec<double, 3>(0.2, -0.1, 0.0).cross(x);
    for (int j = 0; j < 3; ++j) {
      pr.q.push_back(x[j]);
      pr.v.push_back(v[j]);
    }
  }
  pr.step = h;
  pr.steps = steps;
  pr.origin = "test";
  return pr;
}

Method method(const std::string& map, double theta = 0.5, const std::string& composition = "none") {
  Method me;
  me.map = &find_map_entry(map, "test");
  me.theta = me.map->takes_theta ? theta : me.map->theta;
  me.composition = composition;
  return me;
}

}  // namespace

BOOST_AUTO_TEST_CASE(mass_matrix_and_lagrangian) {
  std::mt19937 g(7);
  const int K = 7;
  const VectorXd m = random_vector(K, g, 0.5, 2.0), l = random_vector(K, g, 0.3, 1.5);
  const DynamicSphericalChain L(m, l, 9.81);
  const MatrixXd M = dense_mass(m, l);
  for (int trial = 0; trial < 3; ++trial) {
    const VectorXd u = random_vector(3 * K, g);
    VectorXd Mu;
    L.mass_times(u, Mu);
    BOOST_TEST((Mu - M * u).cwiseAbs().maxCoeff() <= 1e-14 * (M * u).cwiseAbs().maxCoeff() * K);
  }
  // the compiled chain's Lagrangian: L(x, v) - L(x, 0) = v^T M v / 2 and L(x, 0) = -U(x)
  const SphericalChain<4> C(m.head<4>(), l.head<4>(), 9.81);
  const DynamicSphericalChain L4(m.head(4), l.head(4), 9.81);
  VectorXd x, v;
  random_state(4, g, x, v);
  const Vec<double, 12> xs = x, vs = v, zero = Vec<double, 12>::Zero();
  BOOST_TEST(std::fabs(-C(xs, zero) - L4.potential(x)) <= 1e-14);
  BOOST_TEST(std::fabs(L4.energy(x, v) - (C(xs, vs) - 2.0 * C(xs, zero))) <= 1e-13);
}

BOOST_AUTO_TEST_CASE(banded_lu_against_dense) {
  std::mt19937 g(3);
  // a general band, and the bands with solves of fixed length (tridiagonal, pentadiagonal)
  for (const auto& band : {std::pair<int, int>{3, 5}, {1, 1}, {2, 2}}) {
    const int n = 40, kl = band.first, ku = band.second;
    BOOST_TEST_CONTEXT("kl = " << kl << ", ku = " << ku) {
      BandedLU B(n, kl, ku);
      MatrixXd A = MatrixXd::Zero(n, n);
      for (int i = 0; i < n; ++i)
        for (int j = std::max(0, i - kl); j <= std::min(n - 1, i + ku); ++j)
          A(i, j) = B.at(i, j) = random_vector(1, g)[0];
      for (int i = 0; i < n; i += 3) A(i, i) = B.at(i, i) = 0.0;  // every third pivot needs a row exchange
      const VectorXd b = random_vector(n, g);
      VectorXd x = b;
      BOOST_TEST_REQUIRE(B.factor());
      B.solve(x);
      const VectorXd y = A.partialPivLu().solve(b);
      BOOST_TEST((x - y).cwiseAbs().maxCoeff() <= 1e-11 * y.cwiseAbs().maxCoeff());
      BOOST_TEST((A * x - b).cwiseAbs().maxCoeff() <= 1e-12);
    }
  }
  // a singular matrix is reported, not solved
  BandedLU S(4, 1, 1);
  S.at(0, 0) = 1.0;
  S.at(1, 0) = 2.0;  // rows 2 and 3 zero
  BOOST_TEST(!S.factor());
}

BOOST_AUTO_TEST_CASE(coupled_solve_against_dense) {
  std::mt19937 g(11);
  const int K = 6;
  const VectorXd m = random_vector(K, g, 0.5, 2.0), l = random_vector(K, g, 0.3, 1.5);
  const DynamicSphericalChain L(m, l, 9.81);
  ChainCouplingSolve solve(L);
  std::vector<Mat<double, 2, 2>> D(K);
  std::vector<Mat<double, 3, 2>> B(K), C(K);
  MatrixXd Dd = MatrixXd::Zero(2 * K, 2 * K), Bd = MatrixXd::Zero(3 * K, 2 * K), Cd = Bd;
  for (int i = 0; i < K; ++i) {
    D[i] = Mat<double, 2, 2>::Random();
    B[i] = Mat<double, 3, 2>::Random();
    C[i] = Mat<double, 3, 2>::Random();
    Dd.block<2, 2>(2 * i, 2 * i) = D[i];
    Bd.block<3, 2>(3 * i, 2 * i) = B[i];
    Cd.block<3, 2>(3 * i, 2 * i) = C[i];
  }
  const double c = 25.0;
  const MatrixXd J = Dd + c * Bd.transpose() * dense_mass(m, l) * Cd;
  const VectorXd r = random_vector(2 * K, g);
  BOOST_TEST_REQUIRE(solve.factor(D, B, C, c));
  VectorXd delta;
  solve.solve(r, delta);
  const VectorXd ref = J.partialPivLu().solve(r);
  BOOST_TEST((delta - ref).cwiseAbs().maxCoeff() <= 1e-11 * ref.cwiseAbs().maxCoeff());
}

BOOST_AUTO_TEST_CASE(legendre_map_and_inverse) {
  std::mt19937 g(5);
  const int K = 30;
  const DynamicSphericalChain L(random_vector(K, g, 0.5, 2.0), random_vector(K, g, 0.3, 1.5), 9.81);
  ChainCouplingSolve solve(L);
  VectorXd x, v;
  random_state(K, g, x, v);
  const VectorXd p = chain_legendre(L, x, v);
  BOOST_TEST(DynamicSpherePower::tangent_defect(x, p) <= 1e-15 * p.cwiseAbs().maxCoeff());
  const VectorXd w = chain_legendre_inverse(L, x, p, solve);
  BOOST_TEST((w - v).cwiseAbs().maxCoeff() <= 1e-12 * v.cwiseAbs().maxCoeff());
  // <p, v> is twice the kinetic energy
  BOOST_TEST(std::fabs(p.dot(v) - 2.0 * (L.energy(x, v) - L.potential(x))) <= 1e-12 * std::fabs(p.dot(v)));
}

// The step's residual and its Jacobian D + B^T M C / h (dense) against the compiled
// step's residual differentiated by Jets (ManifoldStep<SphericalChain<3>, ...>::Residual),
// at an unknown away from the solution, for closed-form and Newton-inverted maps.
BOOST_AUTO_TEST_CASE(residual_and_jacobian_against_the_compiled_step) {
  constexpr int K = 3;
  std::mt19937 g(13);
  const VectorXd m = random_vector(K, g, 0.5, 2.0), l = random_vector(K, g, 0.3, 1.5);
  const SphericalChain<K> C(m, l, 9.81);
  const DynamicSphericalChain D(m, l, 9.81);
  VectorXd x, v;
  random_state(K, g, x, v);
  const VectorXd p = chain_legendre(D, x, v), xi = 0.05 * random_vector(2 * K, g);
  const double h = 0.05;
  int maps = 0;
  for (const auto& [kind, theta] : std::vector<std::pair<RetractionKind, double>>{
           {RetractionKind::exp, 0.5}, {RetractionKind::projection, 0.0}, {RetractionKind::exp, 0.3},
           {RetractionKind::projection, 1.0}}) {
    const SphereMap f(kind, theta, "test");
    const SphereChainStep S(D, f, h);
    VectorXd r;
    MatrixXd J;
    S.residual_and_jacobian(x, p, xi, r, J);
    using Compiled = ManifoldStep<SphericalChain<K>, SpherePowerMap<K>>;
    const Compiled T(C, SpherePowerMap<K>(f), h);
    const Vec<double, 3 * K> xs = x, ps = p;
    const Compiled::Residual res{&T.discrete_lagrangian(), xs, SpherePower<K>::covector_to_local(xs, ps), nullptr, 0.0};
    using Jt = ceres::Jet<double, 2 * K>;
    Vec<Jt, 2 * K> xj, rj;
    for (int i = 0; i < 2 * K; ++i) xj[i] = Jt(xi[i], i);
    res(xj.data(), rj.data());
    VectorXd r_ref(2 * K);
    MatrixXd J_ref(2 * K, 2 * K);
    for (int i = 0; i < 2 * K; ++i) {
      r_ref[i] = rj[i].a;
      J_ref.row(i) = rj[i].v.transpose();
    }
    BOOST_TEST_CONTEXT("kind " << static_cast<int>(kind) << ", theta " << theta) {
      BOOST_TEST((r - r_ref).cwiseAbs().maxCoeff() <= 1e-14 * r_ref.cwiseAbs().maxCoeff());
      BOOST_TEST((J - J_ref).cwiseAbs().maxCoeff() <= 1e-13 * J_ref.cwiseAbs().maxCoeff());
      BOOST_TEST(r_ref.cwiseAbs().maxCoeff() > 1e-3);  // away from the solution
    }
    ++maps;
  }
  BOOST_TEST(maps == 4);
}

// The banded solve is made dimensionless: links of 1e-7 and of 1e3 (masses 1e-5 and
// 1e4) step as the compiled steps do, and a chain of 20000 links of 1e-5 starts.
BOOST_AUTO_TEST_CASE(units_do_not_matter) {
  for (const auto& [l, m, h] : std::vector<std::array<double, 3>>{{1e-7, 1e-5, 1e-6}, {1e3, 1e4, 1.0}}) {
    const Problem pr = chain_problem(3, h, 8, m, l);
    Method me = method("sphere-exp");
    const RunReport a = run(pr, me);
    me.use_structure = false;
    const RunReport b = run(pr, me);
    BOOST_TEST_CONTEXT("l = " << l << ", m = " << m) {
      BOOST_TEST_REQUIRE(!a.failed, a.loop.failure.message);
      BOOST_TEST_REQUIRE(!b.failed, b.loop.failure.message);
      BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-14);
      BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-13 * max_abs(b.p_final));
    }
  }
  // 20000 links: the step moves every link and keeps what it must (unit vectors, the
  // vertical angular momentum by discrete Noether, the energy to the step's accuracy)
  const RunReport big = run(chain_problem(20000, 1e-5, 2, 1e-5, 1e-5), method("sphere-exp"));
  BOOST_TEST_REQUIRE(!big.failed, big.loop.failure.message);
  BOOST_TEST(max_diff(big.q_final, big.q_initial) >= 1e-6);
  BOOST_TEST(big.max_point_defect <= 1e-14);
  BOOST_TEST_REQUIRE(big.invariants.size() == 1u);
  BOOST_TEST(big.invariants[0].max_abs_error <= 1e-10 * std::fabs(big.invariants[0].initial.at(0)));
  BOOST_TEST(big.max_abs_energy_error <= 1e-9 * std::fabs(big.energy_initial));
}

// The same run from the initial velocity and from the momentum it gives.
BOOST_AUTO_TEST_CASE(from_velocity_or_momentum) {
  Problem pv = chain_problem(30, 1e-3, 20);
  const DynamicSphericalChain L(VectorXd::Constant(30, 1.0 / 30), VectorXd::Constant(30, 1.0 / 30), 9.81);
  const VectorXd q = Eigen::Map<const VectorXd>(pv.q.data(), 90), v = Eigen::Map<const VectorXd>(pv.v.data(), 90);
  const VectorXd p = chain_legendre(L, q, v);
  Problem pp = pv;
  pp.v.clear();
  pp.p.assign(p.data(), p.data() + p.size());
  pp.momentum_given = true;
  const RunReport a = run(pv, method("sphere-projection")), b = run(pp, method("sphere-projection"));
  BOOST_TEST_REQUIRE(!a.failed);
  BOOST_TEST_REQUIRE(!b.failed);
  BOOST_TEST(std::fabs(a.energy_initial - b.energy_initial) <= 1e-14 * std::fabs(a.energy_initial));
  BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-14);
  BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-14 * max_abs(a.p_final));
}

BOOST_AUTO_TEST_CASE(agrees_with_the_compiled_steps) {
  int runs = 0;
  for (int K = 1; K <= 4; ++K) {
    const Problem pr = chain_problem(K, 0.01, 8);
    std::vector<std::pair<Method, double>> methods;  // the method, the agreement expected
    for (const char* map : {"sphere-exp", "sphere-projection", "sphere-exp-fixed", "sphere-projection-fixed"})
      for (const char* comp : {"none", "triple-jump"}) methods.push_back({method(map, 0.5, comp), 1e-14});
    // the theta maps invert by Newton's method inside the step: its tolerance, not round-off
    // (measured at most 3.8e-15 in q and 5e-14 in p; the DIRK 1.5e-14 and 2.4e-13)
    for (double th : {0.3, 0.7})
      for (const char* map : {"sphere-exp-theta", "sphere-projection-theta"}) methods.push_back({method(map, th), 1e-13});
    Method dirk = method("sphere-exp-theta", 0.5, "dirk");
    dirk.thetas = {0.2, 0.5, 0.8};
    dirk.weights = {0.3, 0.4, 0.3};
    methods.push_back({dirk, 1e-13});
    for (auto& [me, tol] : methods) {
      me.use_structure = true;
      const RunReport a = run(pr, me);
      me.use_structure = false;
      const RunReport b = run(pr, me);
      const std::string what = std::to_string(K) + " links, " + me.map->name + " theta " + std::to_string(me.theta) +
                               ", " + me.composition;
      BOOST_TEST_REQUIRE(!a.failed, what << ": " << a.message);
      BOOST_TEST_REQUIRE(!b.failed, what << ": " << b.message);
      BOOST_TEST(a.step_path == StepPath::sphere_chain_banded_newton, what);
      BOOST_TEST(b.step_path != a.step_path, what);
      BOOST_TEST(max_diff(a.q_final, b.q_final) <= tol, what << ": q differs by " << max_diff(a.q_final, b.q_final));
      BOOST_TEST(max_diff(a.p_final, b.p_final) <= 10 * tol * std::fmax(1.0, max_abs(b.p_final)),
                 what << ": p differs by " << max_diff(a.p_final, b.p_final));
      BOOST_TEST(std::fabs(a.energy_initial - b.energy_initial) <= 1e-14 * std::fabs(b.energy_initial), what);
      BOOST_TEST_MESSAGE(what << ": q " << max_diff(a.q_final, b.q_final) << ", p " << max_diff(a.p_final, b.p_final));
      ++runs;
    }
  }
  BOOST_TEST(runs == 4 * 13);
}

BOOST_AUTO_TEST_CASE(long_chain_invariants) {
  const int K = 200;
  for (const char* map : {"sphere-exp", "sphere-projection"}) {
    const RunReport a = run(chain_problem(K, 1e-3, 40), method(map));
    BOOST_TEST_REQUIRE(!a.failed, "step " << a.loop.failed_step << ": " << a.loop.failure.message);
    BOOST_TEST(a.steps == 40);
    const InvariantReport& J = a.invariants.at(0);
    BOOST_TEST(J.name == "vertical angular momentum");
    BOOST_TEST(J.max_abs_error <= 1e-15 * std::fmax(1.0, std::fabs(J.initial.at(0))), map);
    BOOST_TEST(a.max_point_defect <= 1e-15, map);
    BOOST_TEST(a.max_abs_energy_error <= 1e-5 * std::fabs(a.energy_initial), map);
    // one Jacobian a step: the simplified Newton iteration contracts with it (a wrong
    // Jacobian block would still converge, refactoring, to the same states)
    BOOST_TEST(a.jacobians <= a.steps + 2, map << ": " << a.jacobians << " Jacobians");
  }
}

// Second order (the map sphere-exp) in the state, against h / 64, and in the energy, on
// 20 links with steps where h omega is small for every mode of the chain (on 200 links
// the same steps are still before the asymptotic regime: orders 0.85, 1.5, 1.85).
BOOST_AUTO_TEST_CASE(second_order) {
  const int K = 20;
  const Method me = method("sphere-exp");
  const double T = 0.2;
  std::vector<RunReport> r;
  for (int k = 0; k < 4; ++k) {
    const std::int64_t steps = 40LL << k;  // h = 5e-3 ... 6.25e-4
    r.push_back(run(chain_problem(K, T / static_cast<double>(steps), steps), me));
    BOOST_TEST_REQUIRE(!r.back().failed, "step " << r.back().loop.failed_step << ": " << r.back().loop.failure.message);
  }
  const RunReport fine = run(chain_problem(K, T / 2560.0, 2560), me);
  BOOST_TEST_REQUIRE(!fine.failed);
  for (std::size_t k = 0; k + 1 < r.size(); ++k) {
    const double e0 = max_diff(r[k].q_final, fine.q_final), e1 = max_diff(r[k + 1].q_final, fine.q_final);
    BOOST_TEST(std::log2(e0 / e1) >= 1.9, "state order " << std::log2(e0 / e1) << " at refinement " << k);
    BOOST_TEST(std::log2(e0 / e1) <= 2.2, "state order " << std::log2(e0 / e1) << " at refinement " << k);
    const double f = r[k].max_abs_energy_error / r[k + 1].max_abs_energy_error;
    BOOST_TEST(std::log2(f) >= 1.8, "energy order " << std::log2(f) << " at refinement " << k);
    BOOST_TEST_MESSAGE("refinement " << k << ": state order " << std::log2(e0 / e1) << ", energy order " << std::log2(f));
  }
}

BOOST_AUTO_TEST_CASE(compiled_steps_refused_beyond_four_links) {
  const Problem pr = chain_problem(5, 0.01, 2);
  Method me = method("sphere-exp");
  BOOST_TEST(!run(pr, me).failed);
  me.use_structure = false;
  BOOST_CHECK_EXCEPTION(make_run(pr, me), InputError, [](const InputError& e) {
    return std::string(e.what()).rfind("integrator.use_structure", 0) == 0 &&
           std::string(e.what()).find("system.params.n = 5") != std::string::npos;
  });
  me.use_structure = true;
  me.solver = SolverKind::tiny;
  BOOST_CHECK_EXCEPTION(make_run(pr, me), InputError, [](const InputError& e) {
    return std::string(e.what()).rfind("integrator.solver", 0) == 0;
  });
  // at 4 links the compiled steps still run either way
  me.use_structure = false;
  BOOST_TEST(!run(chain_problem(4, 0.01, 2), me).failed);
}
