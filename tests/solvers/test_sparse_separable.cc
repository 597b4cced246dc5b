// The sparse Hessian of a written potential (mechanics/sparse_hessian.h) and the theta
// step that factors it (solvers/sparse_separable_step.h):
//   - on chains with fixed and periodic ends, a lattice, a text with a definition read
//     in a sum, a full mass matrix and a text without blocks, the pattern holds every
//     nonzero entry of the dense Hessian (forward over reverse, mechanics/
//     dynamic_system.h), the colouring gives each entry exactly, and columns of one
//     colour share no row; a chain takes one gradient pass (at most 8 colours);
//   - through the runtime, every theta map (alone, composed, DIRK, a theta per stage)
//     takes the sparse step on a written separable text and gives the generic dense
//     path's states (use_structure = false) to the Newton tolerance;
//   - a written chain beyond the dense steps' limit runs with the midpoint map, where the
//     dense path is refused naming its key, on the Jacobian factored at its first step;
//   - the step that factors a dense Jacobian (solvers/dense_separable_step.h) gives the
//     sparse step's states on every text, reports a singular Jacobian, and serves the
//     implicit theta maps on n bodies, equal to the generic path;
//   - on Lagrangians that are not separable, the run-time-sized theta step with its
//     Jacobian kept across steps gives the Newton steps' states (a mass matrix depending
//     on q, a term linear in v), and serves written texts from 8 coordinates on;
//   - on stiff steps a Jacobian formed at each step's start is exact (one per step), and
//     near-singular Jacobians are refused while a singular one at the solution is not.
#define BOOST_TEST_MODULE sparse_separable
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/sparse_hessian.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/dense_separable_step.h"
#include "solvers/dynamic_step.h"
#include "solvers/sparse_separable_step.h"
#include "solvers/runtime/problem.h"
#include "solvers/runtime/run.h"
#include "tests/solvers/structured_runs.h"
#include "tests/random_vector.h"

using namespace dvm;
using Eigen::MatrixXd;
using Eigen::VectorXd;

namespace {

struct Text {
  std::string what;
  std::shared_ptr<WrittenSystem> system;
};

// One array q[1..n] with the given ends, or plain names when `names` is given.
std::shared_ptr<WrittenSystem> written(int n, ExpressionSymbols::Boundary ends, const std::string& L,
                                       std::vector<std::pair<std::string, double>> params = {},
                                       std::vector<std::pair<std::string, std::string>> definitions = {},
                                       std::vector<std::string> names = {}) {
  auto s = std::make_shared<WrittenSystem>();
  s->name = "written";
  if (names.empty())
    s->add_array("q", n, ends);
  else
    s->coordinates = std::move(names);
  s->params = std::move(params);
  s->definitions = std::move(definitions);
  s->check_names();
  s->lagrangian = Expression::parse(L, s->symbols(WrittenSystem::Kind::lagrangian));
  return s;
}

std::vector<Text> texts() {
  using B = ExpressionSymbols::Boundary;
  const std::string fpu =
      "sum(i, 1, n, m/2*q_dot[i]^2) - sum(i, 1, n + 1, k/2*(q[i] - q[i-1])^2 + alpha/3*(q[i] - q[i-1])^3"
      " + beta/4*(q[i] - q[i-1])^4)";
  const std::vector<std::pair<std::string, double>> fp = {{"m", 1.3}, {"k", 1.0}, {"alpha", 0.25}, {"beta", 1.0}};
  std::vector<Text> out;
  auto with_n = [](std::vector<std::pair<std::string, double>> p, int n) {
    p.emplace_back("n", n);
    return p;
  };
  out.push_back({"fpu chain, fixed ends, n = 40", written(40, B::fixed, fpu, with_n(fp, 40))});
  out.push_back({"ring with on-site potential, periodic, n = 40",
                 written(40, B::periodic,
                         "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n, (q[i+1] - q[i])^4/4 + 1 - cos(q[i]))",
                         {{"n", 40}})});
  // a 6 x 6 lattice in one array: neighbours along a row (i, i+1) and across rows (i, i+6)
  out.push_back({"lattice 6 x 6",
                 written(36, B::fixed,
                         "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n - 1, (q[i+1] - q[i])^2/2)"
                         " - sum(i, 1, n - a, (q[i+a] - q[i])^4/4 + q[i]^2*q[i+a]/3)",
                         {{"n", 36}, {"a", 6}})});
  out.push_back({"a definition read in a sum, n = 30",
                 written(30, B::fixed, "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n, (q[i] - c)^2/2 + (q[i+1] - q[i])^4)",
                         {{"n", 30}}, {{"c", "q[3]/2 + sin(q[7])"}})});
  out.push_back({"full mass matrix, n = 24",
                 written(24, B::fixed,
                         "sum(i, 1, n, q_dot[i]^2) + sum(i, 1, n - 1, q_dot[i]*q_dot[i+1]/2)"
                         " - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + (q[i] - q[i-1])^4/4)",
                         {{"n", 24}})});
  out.push_back({"kepler, no blocks",
                 written(2, B::none, "(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)", {{"mu", 1.5}}, {}, {"x", "y"})});
  return out;
}

Problem written_problem(const std::shared_ptr<WrittenSystem>& w, const VectorXd& q, const VectorXd& v) {
  Problem pr;
  pr.system = &written_system_entry();
  pr.written = w;
  pr.dim = static_cast<int>(q.size());
  pr.q.assign(q.data(), q.data() + q.size());
  pr.v.assign(v.data(), v.data() + v.size());
  pr.step = 0.02;
  pr.steps = 100;
  return pr;
}

// Runs `me` and its reference, the same method with use_structure = false (a Jacobian
// from L's Hessian at every iteration, step_path "generic"); checks that both ran, the
// structure and step path reported, and that the final states agree within 1e-11.
// Returns the two reports (structured, reference).
std::pair<RunReport, RunReport> against_reference(const Problem& pr, const Method& me, const std::string& structure,
                                                  const std::string& path) {
  Method generic = me;
  generic.use_structure = false;
  validate(pr, me);
  RunReport a = run(pr, me), b = run(pr, generic);
  BOOST_TEST(!a.failed, a.loop.failure.message);
  BOOST_TEST(!b.failed, b.loop.failure.message);
  BOOST_TEST(a.structure == structure);
  BOOST_TEST(to_string(a.step_path) == path);
  BOOST_TEST(b.step_path == StepPath::generic);
  BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-11 * std::fmax(1.0, max_abs(b.q_final)));
  BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-11 * std::fmax(1.0, max_abs(b.p_final)));
  return {std::move(a), std::move(b)};
}

// Takes 50 steps of h = 0.02 with two steps of one equation from (q0, p0), each from its
// own previous increment; checks that the states agree to 1e-13 and returns the
// Jacobians each formed in all.
template <class A, class B>
std::pair<int, int> steps_agree(const A& a, const B& b, const VectorXd& q0, const VectorXd& p0) {
  const Eigen::Index n = q0.size();
  VectorXd qa = q0, pa = p0, qb = q0, pb = p0, dqa = VectorXd::Zero(n), dqb = dqa, dpa(n), dpb(n);
  int ia = 0, ib = 0;
  for (int k = 0; k < 50; ++k) {
    const StepSummary sa = a.step(0.0, qa, pa, dqa, dpa), sb = b.step(0.0, qb, pb, dqb, dpb);
    BOOST_TEST_REQUIRE(sa.converged, sa.message);
    BOOST_TEST_REQUIRE(sb.converged, sb.message);
    ia += sa.jacobians;
    ib += sb.jacobians;
    qa += dqa;
    pa += dpa;
    qb += dqb;
    pb += dpb;
  }
  BOOST_TEST((qa - qb).lpNorm<Eigen::Infinity>() <= 1e-13 * std::fmax(1.0, qa.lpNorm<Eigen::Infinity>()));
  BOOST_TEST((pa - pb).lpNorm<Eigen::Infinity>() <= 1e-13 * std::fmax(1.0, pa.lpNorm<Eigen::Infinity>()));
  return {ia, ib};
}

}  // namespace

BOOST_AUTO_TEST_CASE(the_pattern_holds_every_entry_of_the_hessian_and_the_colours_give_each_once) {
  unsigned seed = 1;
  for (const Text& t : texts()) {
    BOOST_TEST_CONTEXT(t.what) {
      const WrittenDynamic L(t.system);
      BOOST_TEST_REQUIRE(L.separable());
      const int n = L.dim();
      const VectorXd q = random_vector(n, 0.6, seed++) + VectorXd::Constant(n, 0.1);
      const VectorXd v = random_vector(n, 0.5, seed++);
      const VectorXd q_kepler = (VectorXd(2) << 0.8, -0.3).finished();
      const VectorXd& x = n == 2 ? q_kepler : q;
      VectorXd Lq(n), Lv(n);
      MatrixXd Lqq(n, n), Lqv(n, n), Lvv(n, n);
      L.hessian(x, v, Lq, Lv, Lqq, Lqv, Lvv);  // Lqq = Hess U for L = T + U
      const SparsePotentialHessian H(L.parts().potential, n, x.data());
      std::vector<double> values(H.entries());
      H.evaluate(x.data(), values.data());
      MatrixXd S = MatrixXd::Zero(n, n);
      std::vector<std::vector<bool>> in(static_cast<std::size_t>(n), std::vector<bool>(static_cast<std::size_t>(n)));
      std::size_t k = 0;
      for (int j = 0; j < n; ++j)
        for (int i : H.columns()[static_cast<std::size_t>(j)]) {
          S(i, j) = values[k++];
          in[static_cast<std::size_t>(i)][static_cast<std::size_t>(j)] = true;
        }
      BOOST_TEST(k == H.entries());
      const double scale = Lqq.cwiseAbs().maxCoeff();
      BOOST_TEST(scale > 0.0);
      BOOST_TEST((S - Lqq).cwiseAbs().maxCoeff() <= 1e-13 * scale);
      int outside = 0, symmetric_misses = 0, shared_rows = 0;
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          if (!in[static_cast<std::size_t>(i)][static_cast<std::size_t>(j)] && Lqq(i, j) != 0.0) ++outside;
          if (in[static_cast<std::size_t>(i)][static_cast<std::size_t>(j)] != in[static_cast<std::size_t>(j)][static_cast<std::size_t>(i)])
            ++symmetric_misses;
        }
      for (int j = 0; j < n; ++j)
        for (int l = j + 1; l < n; ++l)
          if (H.colour_of(j) == H.colour_of(l))
            for (int i = 0; i < n; ++i)
              if (in[static_cast<std::size_t>(i)][static_cast<std::size_t>(j)] && in[static_cast<std::size_t>(i)][static_cast<std::size_t>(l)])
                ++shared_rows;
      BOOST_TEST(outside == 0);
      BOOST_TEST(symmetric_misses == 0);
      BOOST_TEST(shared_rows == 0);
      // H r by one pass equals the sparse matrix times r
      const VectorXd r = random_vector(n, 1.0, seed++);
      VectorXd Hr(n);
      H.times(x.data(), r.data(), Hr.data());
      BOOST_TEST((Hr - Lqq * r).cwiseAbs().maxCoeff() <= 1e-13 * scale * r.cwiseAbs().sum());
      if (t.what.rfind("fpu", 0) == 0 || t.what.rfind("ring", 0) == 0) {
        BOOST_TEST(H.colours() <= SparsePotentialHessian::kColoursPerPass);  // one gradient pass a Jacobian
        BOOST_TEST(H.entries() <= static_cast<std::size_t>(3 * n + 4));
      }
      // the walls of the fixed chain are two terms of their own, each at one end: the
      // pattern is tridiagonal (3 colours), and so is the step's Jacobian, factored in
      // its band; a ring's corner entries, or terms reading a definition of far
      // coordinates, take the sparse LDL^T
      if (t.what.rfind("fpu", 0) == 0) {
        BOOST_TEST(H.colours() == 3);
        BOOST_TEST(H.entries() == static_cast<std::size_t>(3 * n - 2));
      }
      if (n >= 3) {
        const auto shared = std::make_shared<SparsePotentialHessian>(L.parts().potential, n, x.data());
        const bool banded = t.what.rfind("fpu", 0) == 0 || t.what.rfind("lattice", 0) == 0 ||
                            t.what.rfind("full mass", 0) == 0;
        BOOST_TEST(SparseSeparableThetaStep(L, shared, 0.5, 0.01).banded() == banded);
      }
    }
  }
  // a chain of 10^4: still a few colours and O(n) entries
  using B = ExpressionSymbols::Boundary;
  const auto big = written(10000, B::fixed,
                           "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + (q[i] - q[i-1])^4/4)",
                           {{"n", 10000}});
  const WrittenDynamic Lb(big);
  const VectorXd qb = random_vector(10000, 0.3, 99);
  const SparsePotentialHessian Hb(Lb.parts().potential, 10000, qb.data());
  BOOST_TEST(Hb.colours() == 3);
  BOOST_TEST(Hb.entries() == std::size_t{3 * 10000 - 2});
}

BOOST_AUTO_TEST_CASE(every_theta_map_takes_the_sparse_step_and_equals_the_generic_path) {
  const std::vector<Method> methods = implicit_theta_methods();
  int compared = 0;
  unsigned seed = 11;
  for (const Text& t : texts()) {
    const int n = t.system->dim();
    const VectorXd q = n == 2 ? (VectorXd(2) << 0.8, 0.0).finished() : random_vector(n, 0.4, seed++);
    const VectorXd v = n == 2 ? (VectorXd(2) << 0.0, 1.2).finished() : random_vector(n, 0.3, seed++);
    const Problem pr = written_problem(t.system, q, v);
    for (const Method& me : methods) {
      BOOST_TEST_CONTEXT(t.what << ", " << me.label()) {
        // below 3 coordinates (Kepler) the generic step, as for the built-in systems
        // (kernels::kStructuredNewtonMinDim)
        const auto ab = against_reference(pr, me, "separable", n >= 3 ? "separable-sparse-newton" : "generic");
        BOOST_TEST((ab.first.hessian_colours >= 1) == (n >= 3));
        ++compared;
      }
    }
  }
  BOOST_TEST(compared == 90);
  // the report says how the steps were taken
  Method mid;
  mid.map = &find_map_entry("midpoint", "test");
  mid.theta = 0.5;
  const std::string j = report_json(run(written_problem(texts()[0].system, random_vector(40, 0.4, 5),
                                                        random_vector(40, 0.3, 6)),
                                        mid));
  BOOST_TEST(j.find("\"step_path\": \"separable-sparse-newton\"") != std::string::npos, j);
  BOOST_TEST(j.find("\"hessian_colours\": ") != std::string::npos, j);
}

BOOST_AUTO_TEST_CASE(a_written_chain_beyond_the_dense_limit_runs_the_midpoint_map) {
  using B = ExpressionSymbols::Boundary;
  const int n = 6000;
  const auto w = written(n, B::fixed,
                         "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + (q[i] - q[i-1])^4/4)",
                         {{"n", n}});
  VectorXd q(n), v = VectorXd::Zero(n);
  for (int i = 0; i < n; ++i) q[i] = 0.3 * std::sin(0.7 * i);
  Problem pr = written_problem(w, q, v);
  pr.step = 0.1;
  pr.steps = 20;
  Method mid;
  mid.map = &find_map_entry("midpoint", "test");
  mid.theta = 0.5;
  validate(pr, mid);
  const RunReport a = run(pr, mid);
  BOOST_TEST(!a.failed, a.loop.failure.message);
  BOOST_TEST(a.step_path == StepPath::separable_sparse_newton);
  BOOST_TEST(a.hessian_colours <= 4);
  // the midpoint map keeps a quadratic-plus-quartic chain's energy to O(h^2) (bounded),
  // and the springs, stretched at the start, set the particles moving
  BOOST_TEST(std::fabs(a.energy_final - a.energy_initial) <= 1e-3 * std::fabs(a.energy_initial));
  BOOST_TEST(max_abs(a.p_final) > 1e-6);
  // the Jacobian factored at the first step serves the others (simplified Newton across
  // steps: a Hessian pass costs several gradients)
  BOOST_TEST(a.jacobians <= 3, a.jacobians << " Jacobians in " << a.steps << " steps");
  Method generic = mid;
  generic.use_structure = false;
  try {
    (void)run(pr, generic);
    BOOST_TEST(false, "the dense path ran beyond its limit");
  } catch (const std::exception& e) {
    const std::string m = e.what();
    BOOST_TEST(m.find("integrator.map") != std::string::npos, m);
    BOOST_TEST(m.find("4096") != std::string::npos, m);
  }
}

// The dense Jacobian (solvers/dense_separable_step.h) against the sparse one, step by
// step, on every text: the same equation, so the same states to round-off; the full mass
// matrix of one text takes its non-diagonal branch.
BOOST_AUTO_TEST_CASE(the_dense_jacobian_gives_the_sparse_steps) {
  unsigned seed = 21;
  int compared = 0;
  for (const Text& t : texts()) {
    const WrittenDynamic L(t.system);
    const int n = L.dim();
    const VectorXd q0 = n == 2 ? (VectorXd(2) << 0.8, 0.0).finished() : random_vector(n, 0.4, seed++);
    const VectorXd v0 = n == 2 ? (VectorXd(2) << 0.0, 1.2).finished() : random_vector(n, 0.3, seed++);
    VectorXd Lq(n), p0(n);
    L.gradient(q0, v0, Lq, p0);
    const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
    const auto work = DenseSeparableThetaStep<WrittenDynamic>::workspace(L);
    for (double theta : {0.3, 0.5, 0.7}) {
      const SparseSeparableThetaStep sparse(L, H, theta, 0.02);
      const DenseSeparableThetaStep<WrittenDynamic> dense(L, work, theta, 0.02);
      BOOST_TEST_CONTEXT(t.what << ", theta " << theta) {
        const int jacobians = steps_agree(sparse, dense, q0, p0).second;
        // the factorisation of the first step serves most of the others
        BOOST_TEST(jacobians <= 10, jacobians << " Jacobians in 50 steps");
        ++compared;
      }
    }
  }
  BOOST_TEST(compared == 18);
}

// At h = 1/8 and the midpoint map, x_dot^2/2 + 128 x^2 (an inverted oscillator) makes
// J = 1/h - h/4 * 256 exactly zero: a failed step that says so, not a run off to infinity.
BOOST_AUTO_TEST_CASE(a_singular_dense_jacobian_is_a_failed_step_with_its_reason) {
  const auto w = written(1, ExpressionSymbols::Boundary::none, "x_dot^2/2 + 128*x^2", {}, {}, {"x"});
  const WrittenDynamic L(w);
  const DenseSeparableThetaStep<WrittenDynamic> step(L, DenseSeparableThetaStep<WrittenDynamic>::workspace(L), 0.5,
                                                      0.125);
  VectorXd q(1), p(1), dq = VectorXd::Zero(1), dp(1);
  q << 0.1;
  p << 0.2;
  const StepSummary s = step.step(0.0, q, p, dq, dp);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("singular step Jacobian (dense LU factorisation failed)") != std::string::npos, s.message);
}

// Built-in n bodies (declared separable, Hess U in closed form): every implicit theta map
// takes the dense structured step and gives the generic path's states (use_structure =
// false: the 2n x 2n Hessian of L and a dense LU at every iteration) to the Newton
// tolerance, on a fraction of the Jacobians.
BOOST_AUTO_TEST_CASE(n_bodies_take_the_dense_structured_step_and_equal_the_generic_path) {
  Problem pr;
  pr.system = &find_system_entry("nbody", "test");
  for (const ParamEntry& e : pr.system->params) pr.params[e.name] = e.default_value;
  const int bodies = 6;
  pr.masses = {0.1, 0.08, 0.06, 0.04, 0.03, 0.02};
  // bodies at least about 1 apart (the first coordinate i, jittered by 0.2)
  VectorXd q = random_vector(3 * bodies, 0.2, 31);
  for (int i = 0; i < bodies; ++i) q[3 * i] += i;
  const VectorXd v = random_vector(3 * bodies, 0.3, 32);
  pr.dim = 3 * bodies;
  pr.q.assign(q.data(), q.data() + q.size());
  pr.v.assign(v.data(), v.data() + v.size());
  pr.step = 0.01;
  pr.steps = 100;
  int compared = 0;
  for (const Method& me : implicit_theta_methods()) {
    BOOST_TEST_CONTEXT(me.label()) {
      const RunReport b = against_reference(pr, me, "separable", "separable-dense-newton").second;
      // the generic path forms a Jacobian at every step
      BOOST_TEST(b.solver_iterations >= b.steps);
      ++compared;
    }
  }
  BOOST_TEST(compared == 15);
  Method mid;
  mid.map = &find_map_entry("midpoint", "test");
  mid.theta = 0.5;
  const RunReport a = run(pr, mid);
  BOOST_TEST(a.jacobians <= 5, a.jacobians << " Jacobians in " << a.steps << " steps");
}

// Lagrangians that are not separable: DynamicThetaStep with its Jacobian kept across
// steps (simplified Newton, Refresh::across_steps of solvers/newton_driver.h) against the same step forming one at
// every iteration, step by step: a mass matrix depending on q (mechanical) and a term
// linear in v (a charge in a magnetic field, general).
BOOST_AUTO_TEST_CASE(a_kept_jacobian_gives_the_newton_steps_on_lagrangians_that_are_not_separable) {
  using B = ExpressionSymbols::Boundary;
  const int n = 12;
  const std::vector<Text> cases = {
      {"mass matrix depending on q, n = 12",
       written(n, B::none,
               "sum(i, 1, n, (1 + q[i]^2/2)*q_dot[i]^2/2) - sum(i, 1, n - 1, (q[i+1] - q[i])^2/2 + (q[i+1] - q[i])^4/4)"
               " - sum(i, 1, n, q[i]^2/2)",
               {{"n", n}})},
      {"charge in a magnetic field",
       written(3, B::none,
               "(x_dot^2 + y_dot^2 + z_dot^2)/2 + b*(1 + z^2/4)*(x*y_dot - y*x_dot)/2 - (x^2 + y^2 + z^2)/2",
               {{"b", 1.5}}, {}, {"x", "y", "z"})}};
  unsigned seed = 41;
  int compared = 0;
  for (const Text& t : cases) {
    const WrittenDynamic L(t.system);
    BOOST_TEST_REQUIRE(!L.separable());
    const int m = L.dim();
    const VectorXd q0 = random_vector(m, 0.4, seed++), v0 = random_vector(m, 0.3, seed++);
    VectorXd Lq(m), p0(m);
    L.gradient(q0, v0, Lq, p0);
    for (double theta : {0.3, 0.5, 0.7}) {
      const DynamicThetaStep<WrittenDynamic> kept(L, ThetaMap(theta), 0.02, {}, true), each(L, ThetaMap(theta), 0.02);
      BOOST_TEST_REQUIRE(kept.keeps_jacobian());
      BOOST_TEST_CONTEXT(t.what << ", theta " << theta) {
        const auto [jacobians, newton] = steps_agree(kept, each, q0, p0);
        BOOST_TEST(jacobians <= 10, jacobians << " Jacobians in 50 steps");
        BOOST_TEST(newton >= 100, newton << " Newton iterations in 50 steps");
        ++compared;
      }
    }
  }
  BOOST_TEST(compared == 6);
}

// Through the runtime: a mechanical text of 12 coordinates takes the kept Jacobian with
// every implicit theta map (step_path kept-jacobian-newton) and ends within 1e-11 of the
// reference path (use_structure = false: a Jacobian at every iteration); below 8
// coordinates, where a Hessian costs about a gradient, the step forms one every iteration.
BOOST_AUTO_TEST_CASE(mechanical_texts_keep_their_jacobian_from_eight_coordinates) {
  using B = ExpressionSymbols::Boundary;
  const std::string L =
      "sum(i, 1, n, (1 + q[i]^2/2)*q_dot[i]^2/2) - sum(i, 1, n - 1, (q[i+1] - q[i])^2/2 + (q[i+1] - q[i])^4/4)"
      " - sum(i, 1, n, q[i]^2/2)";
  const Problem pr =
      written_problem(written(12, B::none, L, {{"n", 12}}), random_vector(12, 0.4, 51), random_vector(12, 0.3, 52));
  int compared = 0;
  for (const Method& me : implicit_theta_methods()) {
    BOOST_TEST_CONTEXT(me.label()) {
      const auto ab = against_reference(pr, me, "mechanical", "kept-jacobian-newton");
      BOOST_TEST(ab.first.jacobians < ab.second.jacobians / 4);
      ++compared;
    }
  }
  BOOST_TEST(compared == 15);
  Method mid;
  mid.map = &find_map_entry("midpoint", "test");
  mid.theta = 0.5;
  const RunReport small =
      run(written_problem(written(7, B::none, L, {{"n", 7}}), random_vector(7, 0.4, 53), random_vector(7, 0.3, 54)),
          mid);
  BOOST_TEST(small.step_path == StepPath::generic);
}

// Where the Hessian terms weigh as much as M / h (h = 0.5: h theta (1 - theta) |Hess U|
// and the L_qv terms are a fifth to a half of M / h or L_vv / h) and amplitudes are small
// (0.05, so that J hardly changes within a step), a Jacobian formed at the starting guess
// of each step (reset() before every step) is exact, so simplified Newton contracts
// fourfold an iteration and each step forms exactly one. A wrong term slows the
// contraction and forms a second one, which the comparisons of states above cannot see
// (any Jacobian close enough converges to the same root). Checked by breaking the code:
// L_qv transposed in DynamicThetaStep fails the charge in a magnetic field; Hess U
// dropped from the dense or the sparse Jacobian, or its sign flipped, fails the stiffer
// texts. (At h = 1 the exact Jacobians need a second one on some steps.)
BOOST_AUTO_TEST_CASE(a_fresh_jacobian_is_exact_one_per_step_on_stiff_steps) {
  using B = ExpressionSymbols::Boundary;
  const double h = 0.5;
  auto run_steps = [&](const auto& step, const VectorXd& q0, const VectorXd& p0) {
    VectorXd q = q0, p = p0, dq = VectorXd::Zero(q0.size()), dp(q0.size());
    int one_each = 0;
    for (int k = 0; k < 10; ++k) {
      step.reset();
      const StepSummary s = step.step(0.0, q, p, dq, dp);
      BOOST_TEST(s.converged, s.message);
      if (!s.converged) break;
      one_each += s.jacobians == 1;
      q += dq;
      p += dp;
    }
    return one_each;
  };
  unsigned seed = 61;
  int checked = 0;
  for (const Text& t : texts()) {
    const WrittenDynamic L(t.system);
    const int n = L.dim();
    if (n == 2) continue;  // (Kepler: h = 0.5 is half an orbit)
    const VectorXd q0 = random_vector(n, 0.05, seed++), v0 = random_vector(n, 0.05, seed++);
    VectorXd Lq(n), p0(n);
    L.gradient(q0, v0, Lq, p0);
    const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
    const auto work = DenseSeparableThetaStep<WrittenDynamic>::workspace(L);
    for (double theta : {0.3, 0.5, 0.7}) {
      BOOST_TEST_CONTEXT(t.what << ", theta " << theta) {
        BOOST_TEST(run_steps(SparseSeparableThetaStep(L, H, theta, h), q0, p0) == 10);
        BOOST_TEST(run_steps(DenseSeparableThetaStep<WrittenDynamic>(L, work, theta, h), q0, p0) == 10);
        ++checked;
      }
    }
  }
  // not separable: a mass matrix depending on q, and a term linear in v (L_qv not
  // symmetric: its transpose is a different matrix)
  const std::vector<Text> others = {
      {"mass matrix depending on q, n = 12",
       written(12, B::none,
               "sum(i, 1, n, (1 + q[i]^2/2)*q_dot[i]^2/2) - sum(i, 1, n - 1, (q[i+1] - q[i])^2/2 + (q[i+1] - q[i])^4/4)"
               " - sum(i, 1, n, q[i]^2/2)",
               {{"n", 12}})},
      {"charge in a magnetic field",
       written(3, B::none,
               "(x_dot^2 + y_dot^2 + z_dot^2)/2 + b*(1 + z^2/4)*(x*y_dot - y*x_dot)/2 - (x^2 + y^2 + z^2)/2",
               {{"b", 1.5}}, {}, {"x", "y", "z"})}};
  for (const Text& t : others) {
    const WrittenDynamic L(t.system);
    const int n = L.dim();
    const VectorXd q0 = random_vector(n, 0.05, seed++), v0 = random_vector(n, 0.05, seed++);
    VectorXd Lq(n), p0(n);
    L.gradient(q0, v0, Lq, p0);
    for (double theta : {0.3, 0.5, 0.7}) {
      BOOST_TEST_CONTEXT(t.what << ", theta " << theta) {
        BOOST_TEST(run_steps(DynamicThetaStep<WrittenDynamic>(L, ThetaMap(theta), h, {}, true), q0, p0) == 10);
        ++checked;
      }
    }
  }
  BOOST_TEST(checked == 21);
}

// A Jacobian singular at round-off but not zero (the oscillator below with its stiffness
// 1e-13 off the singular one, and a second coordinate that sets J's scale) is refused as
// singular, and an exactly singular one is accepted where the starting guess already
// meets the stopping rule (a state at rest at the equilibrium: nothing to correct).
BOOST_AUTO_TEST_CASE(near_singular_jacobians_and_a_singular_one_at_the_solution) {
  const auto w = written(2, ExpressionSymbols::Boundary::none, "x_dot^2/2 + y_dot^2/2 + 128.0000000000001*x^2 - y^2/2",
                         {}, {}, {"x", "y"});
  const WrittenDynamic L(w);
  const DenseSeparableThetaStep<WrittenDynamic> step(L, DenseSeparableThetaStep<WrittenDynamic>::workspace(L), 0.5,
                                                      0.125);
  VectorXd q(2), p(2), dq = VectorXd::Zero(2), dp(2);
  q << 0.1, 0.2;
  p << 0.2, 0.1;
  const StepSummary s = step.step(0.0, q, p, dq, dp);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("singular step Jacobian (dense LU factorisation failed)") != std::string::npos, s.message);
  const auto exact = written(1, ExpressionSymbols::Boundary::none, "x_dot^2/2 + 128*x^2", {}, {}, {"x"});
  const WrittenDynamic E(exact);
  const DenseSeparableThetaStep<WrittenDynamic> at_rest(E, DenseSeparableThetaStep<WrittenDynamic>::workspace(E), 0.5,
                                                         0.125);
  VectorXd z = VectorXd::Zero(1), dz = VectorXd::Zero(1), dpz(1);
  const StepSummary r = at_rest.step(0.0, z, z, dz, dpz);
  BOOST_TEST(r.converged, r.message);
  BOOST_TEST(dz.norm() == 0.0);
  BOOST_TEST(dpz.norm() == 0.0);
}

// A kept Jacobian spends more iterations than Newton's method (7 to 8 a step on this
// chain where Newton takes 3); with a budget of 4 iterations (integrator.max_iterations)
// the kept step forms a Jacobian at every iteration once half the budget is gone, so it
// converges wherever Newton's method does.
BOOST_AUTO_TEST_CASE(a_small_iteration_budget_forms_a_new_jacobian_in_time) {
  const auto w = written(12, ExpressionSymbols::Boundary::none,
                         "sum(i, 1, n, (1 + q[i]^2/2)*q_dot[i]^2/2) - sum(i, 1, n - 1, (q[i+1] - q[i])^2/2 + (q[i+1] - "
                         "q[i])^4/4) - sum(i, 1, n, q[i]^2/2)",
                         {{"n", 12}});
  const WrittenDynamic L(w);
  const VectorXd q0 = random_vector(12, 0.4, 71), v0 = random_vector(12, 0.3, 72);
  VectorXd Lq(12), p0(12);
  L.gradient(q0, v0, Lq, p0);
  StepOptions few;
  few.max_iterations = 4;
  const DynamicThetaStep<WrittenDynamic> kept(L, ThetaMap::midpoint(), 0.02, few, true),
      each(L, ThetaMap::midpoint(), 0.02, few);
  const auto [jacobians, newton] = steps_agree(kept, each, q0, p0);
  BOOST_TEST(jacobians < newton, jacobians << " Jacobians kept, " << newton << " by Newton's method");
}
