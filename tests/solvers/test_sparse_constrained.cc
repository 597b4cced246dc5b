// The sparse constrained theta step (solvers/sparse_constrained_step.h) on chains of
// rigid links in Cartesian coordinates: the same equations as the dense
// ConstrainedThetaStep, so the same steps to round-off; the constraint and its hidden
// constraint kept at every step of a long chain; Dg's pattern read off the tapes; the
// rank of Dg by the sparse LDL^T of Dg Dg^T; with a force, the same steps as the dense
// forced step and the force's Jacobian entries read off its tapes; the step's derivatives
// (in the state and in a control input) the dense step's, and central differences.
#define BOOST_TEST_MODULE sparse_constrained
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/written_constraints.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_force.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/constrained_step.h"
#include "solvers/sparse_constrained_step.h"
#include "solvers/sparse_separable_step.h"

using namespace dvm;
using Eigen::VectorXd;

namespace {

constexpr double kM = 0.7, kL = 0.5, kG = 9.81, kK = 3.0;

// The chain hanging at angles a_i = 0.4 sin(i) from the downward vertical, its joints
// moving with angular rates w_i = 0.3 cos(2 i): a state on the constraints and on their
// hidden constraint, p = m v.
void chain_state(int k, VectorXd& q, VectorXd& p) {
  q.resize(2 * k);
  p.resize(2 * k);
  double x = 0, y = 0, vx = 0, vy = 0;
  for (int i = 0; i < k; ++i) {
    const double a = 0.4 * std::sin(i + 1.0), w = 0.3 * std::cos(2.0 * (i + 1));
    x += kL * std::sin(a);
    y -= kL * std::cos(a);
    vx += kL * std::cos(a) * w;
    vy += kL * std::sin(a) * w;
    q[2 * i] = x;
    q[2 * i + 1] = y;
    p[2 * i] = kM * vx;
    p[2 * i + 1] = kM * vy;
  }
}

// A chain of k point masses m joined by rods of length l, the first hung from the
// origin, in the plane (coordinates x1, y1, ..., xk, yk; y up), under gravity, its last
// mass tied by a spring of stiffness c to where chain_state puts it, (a, b): k
// constraints on 2k coordinates.
// `twice`: the first rod's constraint written a second time, times 1.1 (redundant); `centre`: one
// constraint more, the sum of the x_i held at its initial value (a row of Dg that
// couples every joint: no narrow band).
// `moving`: the chain hung from a support moved along x by 0.1 sin(2 t) (a constraint in t).
std::shared_ptr<WrittenSystem> chain(int k, bool twice = false, bool centre = false, bool moving = false) {
  auto s = std::make_shared<WrittenSystem>();
  s->name = "chain";
  for (int i = 1; i <= k; ++i) {
    s->coordinates.push_back("x" + std::to_string(i));
    s->coordinates.push_back("y" + std::to_string(i));
  }
  VectorXd q, p;
  chain_state(k, q, p);
  double xc = 0.0;
  for (int i = 0; i < k; ++i) xc += q[2 * i];
  s->params = {{"m", kM}, {"l", kL}, {"g", kG}, {"c", kK}, {"a", q[2 * k - 2]}, {"b", q[2 * k - 1]}, {"xc", xc}};
  s->check_names();
  std::string L;
  for (int i = 1; i <= k; ++i) {
    const std::string x = "x" + std::to_string(i), y = "y" + std::to_string(i);
    L += (i > 1 ? " + " : "") + ("m/2*(" + x + "_dot^2 + " + y + "_dot^2) - m*g*" + y);
  }
  const std::string xe = "x" + std::to_string(k), ye = "y" + std::to_string(k);
  L += " - c/2*((" + xe + " - a)^2 + (" + ye + " - b)^2)";
  s->lagrangian = Expression::parse(L, s->symbols(WrittenSystem::Kind::lagrangian));
  auto rod = [&](int i) {
    if (i == 1) return std::string(moving ? "(x1 - 0.1*sin(2*t))^2 + y1^2 - l^2" : "x1^2 + y1^2 - l^2");
    const std::string a = std::to_string(i - 1), b = std::to_string(i);
    return "(x" + b + " - x" + a + ")^2 + (y" + b + " - y" + a + ")^2 - l^2";
  };
  for (int i = 1; i <= k; ++i)
    s->constraints.push_back(Expression::parse(rod(i), s->symbols(WrittenSystem::Kind::constraint)));
  if (twice)  // (scaled: dependent to round-off, not exactly equal rows)
    s->constraints.push_back(Expression::parse("1.1*(" + rod(1) + ")", s->symbols(WrittenSystem::Kind::constraint)));
  if (centre) {
    std::string sum;
    for (int i = 1; i <= k; ++i) sum += (i > 1 ? " + x" : "x") + std::to_string(i);
    s->constraints.push_back(Expression::parse(sum + " - xc", s->symbols(WrittenSystem::Kind::constraint)));
  }
  return s;
}

using Dense = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints>;

// Forces on the chain of `chain`: a damping of every coordinate, a damper between the
// first two joints' horizontal velocities, a force in a position and a velocity, and a
// periodic drive of the last joint (t, and no coordinate); `control`: a control input u
// (tabulated: 0.3, then 1.7) pushing the last joint up in proportion to its x.
void add_forces(WrittenSystem& s, int k, bool control = false) {
  if (control) s.controls.push_back({"u", {}, {0.3, 1.7}, "test", "test"});
  const auto symbols = s.symbols(WrittenSystem::Kind::force);
  auto component = [&](const std::string& name) {
    for (std::size_t i = 0; i < s.coordinates.size(); ++i)
      if (s.coordinates[i] == name) return static_cast<int>(i);
    throw std::logic_error(name);
  };
  for (int i = 1; i <= k; ++i)
    for (const char* c : {"x", "y"}) {
      const std::string v = c + std::to_string(i);
      std::string f = "-0.2*" + v + "_dot";
      if (v == "x1") f += " - 0.5*(x1_dot - x2_dot)";
      if (v == "x2") f += " + 0.5*(x1_dot - x2_dot)";
      if (v == "y3") f += " - 0.3*x3*y3_dot";
      if (i == k && std::string(c) == "x") f += " + 0.4*sin(3*t)";
      if (control && i == k && std::string(c) == "y") f += " + u*x" + std::to_string(k);
      s.forces.emplace_back(component(v), Expression::parse(f, symbols));
    }
}

// 200 steps of h from (q0, p0) by the sparse step and by a dense one side by side: the
// largest relative difference of their states, of their works a step, the sparse run's
// total work, their Newton iterations, and how far the sparse run moved.
struct SideBySide {
  double worst = 0.0, worst_work = 0.0, work = 0.0, moved = 0.0;
  int sparse_iterations = 0, dense_iterations = 0;
};
template <class DenseStep>
SideBySide side_by_side(const SparseConstrainedThetaStep& sparse, const DenseStep& dense, const VectorXd& q0,
                        const VectorXd& p0, double h) {
  const Eigen::Index n = q0.size();
  VectorXd qs = q0, ps = p0, qd = q0, pd = p0, dqs = VectorXd::Zero(n), dps(n), dqd = dqs, dpd(n);
  SideBySide r;
  for (int j = 0; j < 200; ++j) {
    const double t = j * h;
    const StepSummary a = sparse.step(t, qs, ps, dqs, dps);
    const StepSummary b = dense.step(t, qd, pd, dqd, dpd);
    BOOST_REQUIRE_MESSAGE(a.converged && b.converged, a.message << " / " << b.message);
    qs += dqs;
    ps += dps;
    qd += dqd;
    pd += dpd;
    r.work += a.work;
    r.sparse_iterations += a.iterations;
    r.dense_iterations += b.iterations;
    r.worst = std::fmax(r.worst, std::fmax((qs - qd).lpNorm<Eigen::Infinity>() / qd.lpNorm<Eigen::Infinity>(),
                                           (ps - pd).lpNorm<Eigen::Infinity>() / pd.lpNorm<Eigen::Infinity>()));
    if (a.work != b.work)
      r.worst_work = std::fmax(r.worst_work, std::fabs(a.work - b.work) / std::fabs(b.work));
  }
  r.moved = (qs - q0).norm();
  return r;
}

}  // namespace

BOOST_AUTO_TEST_CASE(the_sparse_step_is_the_dense_step) {
  // the same equations: the same trajectory to round-off, for the midpoint and an
  // asymmetric theta, over 200 steps of a chain of 12 links (24 coordinates), whose
  // saddle-point matrices are factored in a band, and of the same chain with its
  // centre held (factored by the sparse LU)
  const int k = 12;
  for (bool centre : {false, true}) {
    const auto sys = chain(k, false, centre);
    const WrittenDynamic L(sys);
    BOOST_REQUIRE(L.separable());
    const auto con = std::make_shared<const WrittenConstraints>(sys);
    VectorXd q0, p0;
    chain_state(k, q0, p0);
    if (centre) {  // (the momentum along the centre's constraint too)
      VectorXd v(2 * k);
      BOOST_REQUIRE(SparseConstrainedThetaStep(L, SparseSeparableThetaStep::hessian_of(L, q0), con, 0.5, 0.01)
                        .project(0.0, q0, p0, v)
                        .empty());
    }
    const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
    for (double theta : {0.5, 0.3}) {
      const double h = 0.01;
      const SparseConstrainedThetaStep sparse(L, H, con, theta, h, {});
      BOOST_TEST(sparse.banded() == !centre);
      const Dense dense(L, ThetaMap(theta), h, con, {}, MomentumMap::constant);
      const SideBySide r = side_by_side(sparse, dense, q0, p0, h);
      BOOST_TEST_MESSAGE((centre ? "centre held, " : "") << "theta " << theta << ": largest relative difference "
                                                           << r.worst);
      BOOST_TEST(r.worst < 1e-11);
      // and the motion is not trivial
      BOOST_TEST(r.moved > 0.1);
    }
  }
}

BOOST_AUTO_TEST_CASE(a_long_chain_stays_on_its_constraints) {
  // 200 links (400 coordinates, 200 constraints), midpoint steps to t = 1: |g| and the
  // hidden constraint's residual at round-off at every step, and the energy error of a
  // method of order 2, a quarter as large at half the step
  const int k = 200;
  const auto sys = chain(k);
  const WrittenDynamic L(sys);
  const auto con = std::make_shared<const WrittenConstraints>(sys);
  VectorXd q0, p0;
  chain_state(k, q0, p0);
  const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
  const VectorXd minv = L.parts().mass_diagonal.cwiseInverse();
  auto energy = [&](const VectorXd& x, const VectorXd& y) {
    return 0.5 * y.dot(minv.cwiseProduct(y)) - L.value(x, VectorXd::Zero(2 * k));
  };
  const double E0 = energy(q0, p0);
  auto run = [&](int steps) {
    const double h = 1.0 / steps;
    const SparseConstrainedThetaStep step(L, H, con, 0.5, h);
    VectorXd q = q0, p = p0, dq = VectorXd::Zero(2 * k), dp(2 * k);
    double worst_g = 0.0, worst_hidden = 0.0, worst_E = 0.0;
    for (int j = 0; j < steps; ++j) {
      const StepSummary s = step.step(j * h, q, p, dq, dp);
      BOOST_REQUIRE_MESSAGE(s.converged, s.message);
      q += dq;
      p += dp;
      double g, hidden;
      con->relative_residuals((j + 1) * h, q, VectorXd(minv.cwiseProduct(p)), g, hidden);
      worst_g = std::fmax(worst_g, g);
      worst_hidden = std::fmax(worst_hidden, hidden);
      worst_E = std::fmax(worst_E, std::fabs(energy(q, p) - E0));
    }
    BOOST_TEST_MESSAGE(steps << " steps: relative residuals " << worst_g << ", " << worst_hidden
                             << "; energy error " << worst_E << " of " << E0);
    BOOST_TEST(worst_g < 1e-12);
    BOOST_TEST(worst_hidden < 1e-12);
    return worst_E;
  };
  const double ratio = run(250) / run(500);
  BOOST_TEST_MESSAGE("energy error ratio " << ratio);
  BOOST_TEST(ratio > 3.5);
  BOOST_TEST(ratio < 4.5);
}

BOOST_AUTO_TEST_CASE(dg_pattern_is_read_off_the_tapes) {
  const auto sys = chain(4);
  const WrittenConstraints con(sys);
  const std::vector<std::vector<int>> expected = {{0, 1}, {0, 1, 2, 3}, {2, 3, 4, 5}, {4, 5, 6, 7}};
  BOOST_REQUIRE_EQUAL(con.pattern().size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i)
    BOOST_TEST(con.pattern()[i] == expected[i], boost::test_tools::per_element());
  BOOST_TEST(con.entries() == 14u);
  VectorXd q, p;
  chain_state(4, q, p);
  BOOST_CHECK_NO_THROW(con.check_pattern(0.0, q));
  // the sparse entries are the dense rows' nonzero ones, and g_t = 0
  Eigen::MatrixXd G(4, 8);
  VectorXd gt(4), sgt(4);
  con.gradients(0.0, q, G, gt);
  std::vector<double> S(con.entries());
  con.sparse_gradients(0.0, q, S.data(), sgt.data());
  std::size_t e = 0;
  for (int i = 0; i < 4; ++i)
    for (int j : expected[static_cast<std::size_t>(i)]) BOOST_TEST(S[e++] == G(i, j), boost::test_tools::tolerance(1e-15));
  BOOST_TEST(sgt.lpNorm<Eigen::Infinity>() == 0.0);
}

BOOST_AUTO_TEST_CASE(the_rank_of_dg_by_the_sparse_ldlt) {
  VectorXd q, p;
  chain_state(30, q, p);
  BOOST_TEST(SparseConstrainedThetaStep::rank(WrittenConstraints(chain(30)), 0.0, q) == 30);
  const int twice = SparseConstrainedThetaStep::rank(WrittenConstraints(chain(30, true)), 0.0, q);  // of 31
  BOOST_TEST((twice == 30 || twice == -1));
  // a chain pulled straight (every rod along x): full rank still, each rod's gradient
  // along its own rod
  VectorXd straight = VectorXd::Zero(60);
  for (int i = 0; i < 30; ++i) straight[2 * i] = kL * (i + 1);
  BOOST_TEST(SparseConstrainedThetaStep::rank(WrittenConstraints(chain(30)), 0.0, straight) == 30);
}

BOOST_AUTO_TEST_CASE(project_puts_the_momentum_on_the_hidden_constraint) {
  const int k = 10;
  const auto sys = chain(k);
  const WrittenDynamic L(sys);
  const auto con = std::make_shared<const WrittenConstraints>(sys);
  VectorXd q, p;
  chain_state(k, q, p);
  const VectorXd on = p;
  VectorXd off = p, v(2 * k);
  for (int i = 0; i < 2 * k; ++i) off[i] += 0.1 * std::cos(3.0 * i);  // across the rods too
  const SparseConstrainedThetaStep step(L, SparseSeparableThetaStep::hessian_of(L, q), con, 0.5, 0.01);
  const Dense dense(L, ThetaMap(0.5), 0.01, con, {}, MomentumMap::constant);
  VectorXd pd = off, vd(2 * k);
  BOOST_REQUIRE(step.project(0.0, q, off, v).empty());
  BOOST_REQUIRE(dense.project(0.0, q, pd, vd).empty());
  double g, hidden;
  con->relative_residuals(0.0, q, v, g, hidden);
  BOOST_TEST(hidden < 1e-14);
  BOOST_TEST((off - pd).lpNorm<Eigen::Infinity>() < 1e-13);
  BOOST_TEST((v - vd).lpNorm<Eigen::Infinity>() < 1e-13);
  // a momentum already on it stays
  VectorXd same = on;
  BOOST_REQUIRE(step.project(0.0, q, same, v).empty());
  BOOST_TEST((same - on).lpNorm<Eigen::Infinity>() < 1e-13);
}

BOOST_AUTO_TEST_CASE(a_singular_saddle_point_fails_the_step) {
  // the first rod written twice: the saddle-point matrix is singular to working
  // precision (two proportional rows), whether factored in a band or by the sparse LU (the
  // centre held too: no narrow band); the step fails there and says so
  const int k = 12;
  for (bool centre : {false, true}) {
    const auto sys = chain(k, true, centre);
    const WrittenDynamic L(sys);
    const auto con = std::make_shared<const WrittenConstraints>(sys);
    VectorXd q, p;
    chain_state(k, q, p);
    const SparseConstrainedThetaStep step(L, SparseSeparableThetaStep::hessian_of(L, q), con, 0.5, 0.01);
    BOOST_TEST(step.banded() == !centre);
    VectorXd dq = VectorXd::Zero(2 * k), dp(2 * k);
    const StepSummary s = step.step(0.0, q, p, dq, dp);
    BOOST_TEST(!s.converged);
    BOOST_TEST_MESSAGE((centre ? "sparse LU: " : "banded: ") << s.message);
    // (Newton's factorisation refuses it: SparseLU alone would pass its pivots at
    // round-off, and the step would fail later, if at all)
    BOOST_TEST(s.message.find("singular step Jacobian") != std::string::npos, s.message);
  }
}

BOOST_AUTO_TEST_CASE(the_force_jacobian_entries_are_the_dense_ones) {
  // WrittenForce::sparse_jacobian's entries, placed by pattern(), are F_q and F_v as
  // jacobian() forms them densely, and no nonzero entry of those lies outside the pattern
  const int k = 4;
  const auto sys = chain(k);
  add_forces(*sys, k);
  const WrittenForce f(sys);
  const int n = 2 * k;
  VectorXd q, p;
  chain_state(k, q, p);
  const VectorXd v = p / kM;
  VectorXd F(n), Fs(n);
  Eigen::MatrixXd Fq(n, n), Fv(n, n);
  f.jacobian(0.7, q, v, F, Fq, Fv);
  std::vector<double> sq(f.q_entries()), sv(f.v_entries());
  f.sparse_jacobian(0.7, q, v, sq.data(), sv.data(), &Fs);
  BOOST_TEST((F - Fs).norm() == 0.0);
  Eigen::MatrixXd Pq = Eigen::MatrixXd::Zero(n, n), Pv = Pq;
  std::size_t eq = 0, ev = 0;
  for (const WrittenForce::Row& r : f.pattern()) {
    for (int j : r.q) Pq(r.i, j) = sq[eq++];
    for (int j : r.v) Pv(r.i, j) = sv[ev++];
  }
  BOOST_TEST((Pq - Fq).norm() == 0.0);
  BOOST_TEST((Pv - Fv).norm() == 0.0);
  // the couplings are there: x1 reads x2's velocity, y3 reads x3, and y3's velocity
  BOOST_TEST(Fv(0, 2) == 0.5);
  BOOST_TEST(Fq(5, 4) != 0.0);
  // a second call gives the same entries (the workspace is cleared between calls)
  std::vector<double> sq2(sq.size()), sv2(sv.size());
  f.sparse_jacobian(0.7, q, v, sq2.data(), sv2.data(), &Fs);
  BOOST_TEST(sq2 == sq);
  BOOST_TEST(sv2 == sv);
}

BOOST_AUTO_TEST_CASE(the_forced_sparse_step_is_the_forced_dense_step) {
  // with damping, a damper between joints, a force in a position and a drive in t: the
  // same trajectory and the same work as the dense forced step, to round-off, over 200
  // steps of a chain of 12 links (a band) and of the same chain with its centre held
  // (sparse LU), for the midpoint and an asymmetric theta; the force takes energy out
  const int k = 12;
  using DenseForced = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>;
  for (bool centre : {false, true}) {
    const auto sys = chain(k, false, centre);
    add_forces(*sys, k);
    const WrittenDynamic L(sys);
    BOOST_REQUIRE(L.separable());
    const auto con = std::make_shared<const WrittenConstraints>(sys);
    const auto force = std::make_shared<const WrittenForce>(sys);
    VectorXd q0, p0;
    chain_state(k, q0, p0);
    const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
    if (centre) {
      VectorXd v(2 * k);
      BOOST_REQUIRE(SparseConstrainedThetaStep(L, H, con, 0.5, 0.01).project(0.0, q0, p0, v).empty());
    }
    for (double theta : {0.5, 0.3}) {
      const double h = 0.01;
      const SparseConstrainedThetaStep sparse(L, H, con, theta, h, {}, force);
      BOOST_TEST(sparse.forced());
      BOOST_TEST(sparse.banded() == !centre);
      const DenseForced dense(L, ThetaMap(theta), h, con, {}, MomentumMap::constant, force);
      const SideBySide r = side_by_side(sparse, dense, q0, p0, h);
      const int its = r.sparse_iterations, itd = r.dense_iterations;
      BOOST_TEST_MESSAGE((centre ? "centre held, " : "") << "theta " << theta << ": largest relative difference "
                                                           << r.worst << ", of the work " << r.worst_work
                                                           << "; iterations " << its << " and " << itd);
      BOOST_TEST(r.worst < 1e-11);
      BOOST_TEST(r.worst_work < 1e-9);
      // the same Jacobian (the force's entries included), so the same iterations up to a
      // step that stops one sooner or later at round-off (without the force's F_v entries
      // the sparse step takes more)
      BOOST_TEST(std::abs(its - itd) <= 2);
      BOOST_TEST(r.moved > 0.1);
      // the damping dominates the drive over these 2 s: negative work
      BOOST_TEST(r.work < 0.0);
    }
  }
}

BOOST_AUTO_TEST_CASE(the_sparse_derivative_is_the_dense_derivative) {
  // A = d(q1, p1)/d(q0, p0) and B = d(q1, p1)/du of one step equal the dense step's
  // (which tests/solvers/test_constrained.cc checks against central differences) to
  // round-off: a chain of 12 links, banded and with its centre held (sparse LU), with and
  // without a force (damping, a drive in t and a control input in a position), hung from
  // a fixed and from a moving support (the constraints' second derivatives in t), for the
  // midpoint and an asymmetric theta
  const int k = 12, n = 2 * k;
  using DenseForced = ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>;
  for (bool centre : {false, true})
    for (bool forced : {false, true})
      for (bool moving : {false, true}) {
        const auto sys = chain(k, false, centre, moving);
        if (forced) add_forces(*sys, k, true);
        const WrittenDynamic L(sys);
        const auto con = std::make_shared<const WrittenConstraints>(sys);
        std::shared_ptr<const WrittenForce> force;
        if (forced) {
          auto signal = std::make_shared<ControlSignal>(sys->controls);
          signal->set_step(1);
          force = std::make_shared<const WrittenForce>(sys, signal);
        }
        VectorXd q0, p0, v(n);
        chain_state(k, q0, p0);
        const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
        if (centre || moving)  // (the momentum on the hidden constraints at t = 0)
          BOOST_REQUIRE(SparseConstrainedThetaStep(L, H, con, 0.5, 0.01).project(0.0, q0, p0, v).empty());
        for (double theta : {0.5, 0.3}) {
          const double h = 0.01, t0 = 0.0;
          const SparseConstrainedThetaStep sparse(L, H, con, theta, h, {}, force);
          BOOST_TEST(sparse.controls() == (forced ? 1 : 0));
          VectorXd dqs = VectorXd::Zero(n), dps(n), dqd = dqs, dpd(n);
          BOOST_REQUIRE(sparse.step(t0, q0, p0, dqs, dps).converged);
          Eigen::MatrixXd As, Ad, Bs, Bd;
          BOOST_REQUIRE(sparse.derivative(t0, q0, p0, dqs, As));
          if (forced) {
            const DenseForced dense(L, ThetaMap(theta), h, con, {}, MomentumMap::constant, force);
            BOOST_REQUIRE(dense.step(t0, q0, p0, dqd, dpd).converged);
            BOOST_REQUIRE(dense.derivative(t0, q0, p0, dqd, Ad));
            BOOST_REQUIRE(sparse.control_derivative(t0, q0, p0, dqs, Bs));
            BOOST_REQUIRE(dense.control_derivative(t0, q0, p0, dqd, Bd));
          } else {
            const Dense dense(L, ThetaMap(theta), h, con, {}, MomentumMap::constant);
            BOOST_REQUIRE(dense.step(t0, q0, p0, dqd, dpd).converged);
            BOOST_REQUIRE(dense.derivative(t0, q0, p0, dqd, Ad));
          }
          const double err = (As - Ad).lpNorm<Eigen::Infinity>() / Ad.lpNorm<Eigen::Infinity>();
          BOOST_TEST_MESSAGE((centre ? "centre held, " : "") << (forced ? "forced, " : "") << (moving ? "moving, " : "")
                                                               << "theta " << theta << ": A differs by " << err);
          BOOST_TEST(err < 1e-11);
          BOOST_TEST((As - Eigen::MatrixXd::Identity(2 * n, 2 * n)).lpNorm<Eigen::Infinity>() > 1e-3);
          if (forced) {
            BOOST_REQUIRE(Bs.cols() == 1);
            const double eb = (Bs - Bd).lpNorm<Eigen::Infinity>() / Bd.lpNorm<Eigen::Infinity>();
            BOOST_TEST(eb < 1e-11, "B differs by " << eb);
            BOOST_TEST(Bd.lpNorm<Eigen::Infinity>() > 1e-5);  // the control moves the step (by h^2 u x / m)
            // both from one differentiation, as each alone
            Eigen::MatrixXd Aj, Bj;
            BOOST_REQUIRE(sparse.derivatives(t0, q0, p0, dqs, Aj, &Bj));
            BOOST_REQUIRE(Aj.rows() == As.rows() && Bj.cols() == Bs.cols());
            BOOST_TEST((Aj - As).lpNorm<Eigen::Infinity>() <= 1e-13 * As.lpNorm<Eigen::Infinity>());
            BOOST_TEST((Bj - Bs).lpNorm<Eigen::Infinity>() <= 1e-13 * Bs.lpNorm<Eigen::Infinity>());
          }
        }
      }
}

BOOST_AUTO_TEST_CASE(the_sparse_derivative_against_central_differences) {
  // independently of the dense step: the columns of A against central differences of the
  // step in each coordinate and momentum (relative 1e-7), for the forced chain on its
  // moving support with theta = 0.3, factored by the sparse LU (the centre held)
  const int k = 12, n = 2 * k;
  const auto sys = chain(k, false, true, true);
  add_forces(*sys, k);
  const WrittenDynamic L(sys);
  const auto con = std::make_shared<const WrittenConstraints>(sys);
  const auto force = std::make_shared<const WrittenForce>(sys);
  VectorXd q0, p0, v(n);
  chain_state(k, q0, p0);
  const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
  BOOST_REQUIRE(SparseConstrainedThetaStep(L, H, con, 0.5, 0.01).project(0.0, q0, p0, v).empty());
  const double h = 0.02;
  const SparseConstrainedThetaStep S(L, H, con, 0.3, h, {}, force);
  BOOST_TEST(!S.banded());
  auto advance = [&](const VectorXd& q, const VectorXd& p) {
    VectorXd dq = VectorXd::Zero(n), dp(n), z(2 * n);
    const StepSummary r = S.step(0.0, q, p, dq, dp);
    BOOST_REQUIRE_MESSAGE(r.converged, r.message);
    z << q + dq, p + dp;
    return z;
  };
  VectorXd dq = VectorXd::Zero(n), dp(n);
  BOOST_REQUIRE(S.step(0.0, q0, p0, dq, dp).converged);
  Eigen::MatrixXd A;
  BOOST_REQUIRE(S.derivative(0.0, q0, p0, dq, A));
  const double eps = 1e-6;
  double worst = 0.0;
  for (int j = 0; j < 2 * n; ++j) {
    VectorXd qa = q0, pa = p0, qb = q0, pb = p0;
    (j < n ? qa[j] : pa[j - n]) += eps;
    (j < n ? qb[j] : pb[j - n]) -= eps;
    const VectorXd fd = (advance(qa, pa) - advance(qb, pb)) / (2 * eps);
    worst = std::fmax(worst, (A.col(j) - fd).lpNorm<Eigen::Infinity>() / A.lpNorm<Eigen::Infinity>());
  }
  BOOST_TEST_MESSAGE("A against central differences: " << worst);
  BOOST_TEST(worst < 1e-7);
}
