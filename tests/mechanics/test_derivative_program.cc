// Derivative programs (mechanics/derivative_program.h): the gradient and Hessian of a
// written expression differentiated symbolically once, against the tape's own reverse
// mode (forward over reverse for the Hessian) and against nested Jets through the
// text, on texts that use every operation, definitions and constant folding; and the
// programs compiled to machine code (mechanics/native_code.h) against the interpreter.
#define BOOST_TEST_MODULE derivative_program
#include <boost/test/unit_test.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <ceres/jet.h>

#include "mechanics/derivative_program.h"
#include "mechanics/dynamic_system.h"
#include "mechanics/native_code.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_lagrangian.h"
#include "tests/random_vector.h"
#include "tests/scoped_env.h"

using namespace dvm;
using Eigen::MatrixXd;
using Eigen::VectorXd;

namespace {

std::shared_ptr<WrittenSystem> written(std::vector<std::string> coords, const std::string& L,
                                       std::vector<std::pair<std::string, std::string>> definitions = {},
                                       bool blocks = true) {
  auto s = std::make_shared<WrittenSystem>();
  s->name = "written";
  s->coordinates = std::move(coords);
  s->params = {{"m", 1.3}, {"g", 9.81}, {"k", 0.7}};
  s->definitions = std::move(definitions);
  s->check_names();
  s->lagrangian = Expression::parse(L, s->symbols(WrittenSystem::Kind::lagrangian), blocks);
  return s;
}

struct Derivatives {
  VectorXd Lq, Lv;
  MatrixXd Lqq, Lqv, Lvv;
};
Derivatives derivatives(const WrittenDynamic& L, const VectorXd& q, const VectorXd& v) {
  const int n = L.dim();
  Derivatives d{VectorXd(n), VectorXd(n), MatrixXd(n, n), MatrixXd(n, n), MatrixXd(n, n)};
  L.hessian(q, v, d.Lq, d.Lv, d.Lqq, d.Lqv, d.Lvv);
  VectorXd gq(n), gv(n);
  L.gradient(q, v, gq, gv);  // the gradient alone, to round-off the same
  const double scale = std::fmax(1.0, std::fmax(d.Lq.cwiseAbs().maxCoeff(), d.Lv.cwiseAbs().maxCoeff()));
  BOOST_TEST((gq - d.Lq).cwiseAbs().maxCoeff() <= 1e-15 * scale);
  BOOST_TEST((gv - d.Lv).cwiseAbs().maxCoeff() <= 1e-15 * scale);
  return d;
}
double largest(const Derivatives& d) {
  return std::max({d.Lq.cwiseAbs().maxCoeff(), d.Lv.cwiseAbs().maxCoeff(), d.Lqq.cwiseAbs().maxCoeff(),
                   d.Lqv.cwiseAbs().maxCoeff(), d.Lvv.cwiseAbs().maxCoeff()});
}
// Largest difference over all blocks, relative to the largest entry of b.
double difference(const Derivatives& a, const Derivatives& b) {
  const double m = std::max({(a.Lq - b.Lq).cwiseAbs().maxCoeff(), (a.Lv - b.Lv).cwiseAbs().maxCoeff(),
                             (a.Lqq - b.Lqq).cwiseAbs().maxCoeff(), (a.Lqv - b.Lqv).cwiseAbs().maxCoeff(),
                             (a.Lvv - b.Lvv).cwiseAbs().maxCoeff()});
  return m / std::fmax(1e-300, largest(b));
}

// Texts of two and three coordinates that use every operation the parser has.
struct Text {
  std::vector<std::string> coords;
  std::string L;
  std::vector<std::pair<std::string, std::string>> definitions;
};
std::vector<Text> texts() {
  return {
      {{"a", "b"},
       "(m + 1)/2*a_dot^2 + m/2*b_dot^2 + m*a_dot*b_dot*cos(a - b) + (m + 1)*g*cos(a) + m*g*cos(b)",
       {}},
      {{"x", "y"}, "(x_dot^2 + y_dot^2)/2 + k/sqrt(x^2 + y^2)", {}},
      {{"x", "y", "z"},
       "exp(x)*sin(y_dot) + log(2 + cos(z))*tan(x_dot/3) + atan2(y, z + 3) + sqrt(4 + x^2)*cbrt(2 + y^2)"
       " + pow(2 + y_dot^2, z/5) + abs(x + 5)*asin(x/9) + acos(y/9) + atan(z) + sinh(x)*cosh(z_dot) + tanh(y)"
       " + (x + y + 3)^2.5/(3 + z_dot^2) + 1/(x*y + 7) - (z - x_dot)^3 + x^-2 + 2^y - (y - 4)^-3",
       {}},
      // definitions, used several times, and a definition of a definition
      {{"x", "y"},
       "m/2*(x_dot^2 + y_dot^2) + k/r + r*s - s^2 + sin(s)*cos(s)",
       {{"r", "sqrt(x^2 + y^2 + 1)"}, {"s", "r*x_dot - y*y_dot"}}},
      // a term that is constant, a coordinate L does not use, and cancelling terms
      {{"x", "y", "z"}, "3 + x_dot^2/2 + z_dot^2/2 + (x - x)*y + cos(z) - cos(z) + y_dot*z", {}},
      // constant factors and signs inside products and quotients, multiples of one term
      // added and subtracted, constants over an expression, 2x as x + x
      {{"x", "y"},
       "m*x_dot^2/2 + y_dot^2/2 + 3*x*y_dot - 2*(y_dot*x) + (x + x)*y^2 - x*y^2*k + x/(2*y + 5) - 3/(y + 4)"
       " + (-x)/(y^2 + 1)*k - (2*x)/(-(y^2 + 3)) + k/sqrt(x^2 + y^2 + 1)/sqrt(x^2 + y^2 + 1)",
       {}},
  };
}

}  // namespace

BOOST_AUTO_TEST_CASE(programs_equal_reverse_mode_on_the_tape) {
  // every text at three random points: the program (the default where one is built)
  // against the tape's reverse mode, and against forward over forward
  int t = 0;
  for (const Text& text : texts()) {
    const auto s = written(text.coords, text.L, text.definitions);
    const WrittenDynamic P(s), R(s, WrittenDerivatives::forward_over_reverse),
        F(s, WrittenDerivatives::forward_over_forward);
    BOOST_TEST_REQUIRE(P.derivative_program() != nullptr);
    BOOST_TEST(R.derivative_program() == nullptr);
    BOOST_TEST(F.derivative_program() == nullptr);
    const int n = s->dim();
    for (int k = 0; k < 3; ++k) {
      const VectorXd q = random_vector(n, 0.8, 10 * t + k), v = random_vector(n, 1.2, 100 + 10 * t + k);
      BOOST_TEST_CONTEXT(text.L << " at point " << k) {
        const Derivatives p = derivatives(P, q, v), r = derivatives(R, q, v), f = derivatives(F, q, v);
        BOOST_TEST(largest(r) > 0.1);
        BOOST_TEST(difference(p, r) <= 1e-14);
        BOOST_TEST(difference(p, f) <= 1e-14);
      }
    }
    ++t;
  }
}

BOOST_AUTO_TEST_CASE(fixed_size_gradient_through_the_program_in_jets) {
  // WrittenLagrangian<N>::gradient is the program evaluated in any scalar: in doubles it
  // is the reverse gradient, in Jets seeded in the 2N inputs its derivative is the
  // Hessian, which nested Jets through the text itself give independently
  const auto s = written({"a", "b"}, texts()[0].L);
  const WrittenLagrangian<2> L(s);
  BOOST_TEST_REQUIRE(L.program != nullptr);
  static_assert(has_gradient<WrittenLagrangian<2>>::value);
  const VectorXd q = random_vector(2, 0.8, 3), v = random_vector(2, 1.2, 4);
  using D = ceres::Jet<double, 4>;
  using DD = ceres::Jet<D, 4>;
  Vec<D, 2> qd, vd, gq, gv;
  Vec<DD, 2> qdd, vdd;
  for (int i = 0; i < 2; ++i) {
    qd[i] = D(q[i], i);
    vd[i] = D(v[i], 2 + i);
    qdd[i] = DD(D(q[i], i));
    qdd[i].v[i] = D(1.0);
    vdd[i] = DD(D(v[i], 2 + i));
    vdd[i].v[2 + i] = D(1.0);
  }
  L.gradient(qd, vd, gq, gv);
  const DD y = L(qdd, vdd);  // the tape in nested Jets: y.v[j].v[i] = d2L/dx_i dx_j
  for (int i = 0; i < 4; ++i) {
    const D& g = i < 2 ? gq[i] : gv[i - 2];
    BOOST_TEST(std::fabs(g.a - y.a.v[i]) <= 1e-14 * std::fabs(y.a.v[i]) + 1e-15);
    for (int j = 0; j < 4; ++j) BOOST_TEST(std::fabs(g.v[j] - y.v[j].v[i]) <= 1e-13);
  }
  // in doubles: the program's double path
  Vec<double, 2> aq, av;
  L.gradient(Vec<double, 2>(q), Vec<double, 2>(v), aq, av);
  for (int i = 0; i < 2; ++i) {
    BOOST_TEST(aq[i] == gq[i].a);
    BOOST_TEST(av[i] == gv[i].a);
  }
}

BOOST_AUTO_TEST_CASE(what_a_program_computes) {
  // the double pendulum's program: sin and cos of each of a - b, a and b computed
  // together (one sincos each), nothing computed twice, zeros not computed
  const auto s = written({"a", "b"}, texts()[0].L);
  const auto p = DerivativeProgram::build(s->lagrangian, 2);
  BOOST_TEST_REQUIRE(p != nullptr);
  int fused = 0, sin = 0, cos = 0;
  for (const auto& in : p->hessian_code()) {
    if (in.op == Expression::Op::Sin) (in.sign ? fused : sin) += 1;
    if (in.op == Expression::Op::Cos) ++cos;
  }
  BOOST_TEST(fused == 3);
  BOOST_TEST(sin == 0);
  BOOST_TEST(cos == 0);
  BOOST_TEST(p->gradient_code().size() < p->hessian_code().size());
  // a Lagrangian with constant derivatives: nothing to run
  const auto quadratic = DerivativeProgram::build(written({"x"}, "x_dot^2/2 - 3*x + 2")->lagrangian, 1);
  BOOST_TEST_REQUIRE(quadratic != nullptr);
  BOOST_TEST(quadratic->hessian_code().empty());
  auto w = quadratic->workspace();
  double x = 0.4, v = -1.5, gq, gv, Hqq, Hqv, Hvv;
  quadratic->hessian(&x, &v, &gq, &gv, &Hqq, 1, &Hqv, 1, &Hvv, 1, w.data());
  BOOST_TEST(gq == -3.0);
  BOOST_TEST(gv == -1.5);
  BOOST_TEST(Hqq == 0.0);
  BOOST_TEST(Hqv == 0.0);
  BOOST_TEST(Hvv == 1.0);
}

BOOST_AUTO_TEST_CASE(products_and_quotients_are_simplified) {
  // Kepler, L = |v|^2/2 + k/r: the derivatives of k/r are powers of 1/r times
  // coordinates, so one square root and one reciprocal serve every entry, and no
  // negation is computed (an output -x is read as x with its sign); the values are the
  // closed forms dL/dq = -k q/r^3, d2L/dq2 = k (3 q q^T/r^5 - I/r^3)
  const auto s = written({"x", "y"}, texts()[1].L);
  const auto p = DerivativeProgram::build(s->lagrangian, 2);
  BOOST_TEST_REQUIRE(p != nullptr);
  using Op = Expression::Op;
  int divisions = 0, negations = 0, roots = 0;
  for (const auto& in : p->hessian_code()) {
    if (in.op == Op::Div || in.op == Op::DivC || in.op == Op::RDivC) ++divisions;
    if (in.op == Op::Neg) ++negations;
    if (in.op == Op::Sqrt) ++roots;
  }
  BOOST_TEST(divisions == 1);
  BOOST_TEST(negations == 0);
  BOOST_TEST(roots == 1);
  const double k = 0.7, q[2] = {0.8, -0.5}, v[2] = {0.3, -1.1};
  const double r = std::sqrt(q[0] * q[0] + q[1] * q[1]);
  auto w = p->workspace();
  double gq[2], gv[2], Hqq[4], Hqv[4], Hvv[4];
  p->hessian(q, v, gq, gv, Hqq, 2, Hqv, 2, Hvv, 2, w.data());
  for (int i = 0; i < 2; ++i) {
    BOOST_TEST(std::fabs(gq[i] + k * q[i] / (r * r * r)) <= 1e-15);
    BOOST_TEST(gv[i] == v[i]);
    for (int j = 0; j < 2; ++j) {
      const double H = k * (3 * q[i] * q[j] / std::pow(r, 5) - (i == j ? 1.0 : 0.0) / (r * r * r));
      BOOST_TEST(std::fabs(Hqq[i + 2 * j] - H) <= 1e-14);
      BOOST_TEST(Hqv[i + 2 * j] == 0.0);
      BOOST_TEST(Hvv[i + 2 * j] == (i == j ? 1.0 : 0.0));
    }
  }
}

BOOST_AUTO_TEST_CASE(products_of_products_many_levels_deep) {
  // d1 = x y, d_k = d_{k-1} d_{k-1}, 40 levels: d40 = (x y)^(2^39), whose count of
  // factors would pass any integer's range (the builder stops counting past the few it
  // reorders); at x y = 1 every value is exact: dL/dx = 2^39 y, dL/dy = 2^39 x
  std::vector<std::pair<std::string, std::string>> defs = {{"d1", "x*y"}};
  for (int k = 2; k <= 40; ++k)
    defs.push_back({"d" + std::to_string(k), "d" + std::to_string(k - 1) + "*d" + std::to_string(k - 1)});
  const auto s = written({"x", "y"}, "x_dot^2/2 + y_dot^2/2 + d40", defs);
  const auto p = DerivativeProgram::build(s->lagrangian, 2);
  BOOST_TEST_REQUIRE(p != nullptr);
  const double q[2] = {1.0, 1.0}, v[2] = {0.5, -0.25};
  auto w = p->workspace();
  double gq[2], gv[2];
  p->gradient(q, v, gq, gv, w.data());
  BOOST_TEST(gq[0] == std::ldexp(1.0, 39));
  BOOST_TEST(gq[1] == std::ldexp(1.0, 39));
  BOOST_TEST(gv[0] == 0.5);
  BOOST_TEST(gv[1] == -0.25);
}

BOOST_AUTO_TEST_CASE(blocks_are_differentiated_once_for_their_shape) {
  // texts whose sums become blocks (Expression::Block): their gradient programs against
  // the tape's reverse mode, with fixed and periodic ends, a list of parameters (a
  // constant that varies from term to term), a block whose value the gradient needs
  // (a product with another term), and a block next to plain terms and a definition
  struct Case {
    ExpressionSymbols::Boundary ends;
    std::string L;
  };
  using B = ExpressionSymbols::Boundary;
  const std::vector<Case> cases = {
      {B::fixed,
       "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + (q[i] - q[i-1])^3/12 + "
       "(q[i] - q[i-1])^4/4)"},
      {B::periodic, "sum(i, 1, n, k[i]*q_dot[i]^2/2) - sum(i, 1, n, k[i]*(1 - cos(q[i+1] - q[i])))"},
      {B::fixed, "sum(i, 1, n, q_dot[i]^2/2)*(1 + q[1]^2) - sum(i, 1, n, q[i]*q_dot[i]*sin(q[i+1]) + exp(q[i]/k[i]))"},
      {B::fixed, "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n, q[i]^2/2 + q[i]^4/(k[i] + q[i]^2)) + c*q_dot[3]"},
  };
  const int n = 40;
  std::vector<double> k(n);
  for (int i = 0; i < n; ++i) k[static_cast<std::size_t>(i)] = 1.0 + 0.05 * i;
  int t = 0;
  for (const Case& c : cases) {
    auto s = std::make_shared<WrittenSystem>();
    s->add_array("q", n, c.ends);
    s->params = {{"n", n}};
    s->param_arrays = {{"k", k}};
    s->definitions = {{"c", "q[3]/2 + sin(q[7])"}};
    s->check_names();
    s->lagrangian = Expression::parse(c.L, s->symbols(WrittenSystem::Kind::lagrangian));
    BOOST_TEST_CONTEXT(c.L) {
      BOOST_TEST(!s->lagrangian.blocks().empty());
      BOOST_TEST(DerivativeProgram::build(s->lagrangian, n) == nullptr);  // no Hessian program with blocks
      const WrittenDynamic P(s), R(s, WrittenDerivatives::forward_over_reverse);
      BOOST_TEST_REQUIRE(P.derivative_program() != nullptr);
      BOOST_TEST(P.derivative_program()->has_blocks());
      BOOST_TEST(!P.derivative_program()->has_hessian());
      for (int point = 0; point < 2; ++point) {
        const VectorXd q = random_vector(n, 0.6, 50 + 10 * t + point), v = random_vector(n, 0.8, 90 + 10 * t + point);
        // the Hessian is the tape's either way, the gradient the program's
        const Derivatives p = derivatives(P, q, v), r = derivatives(R, q, v);
        BOOST_TEST(largest(r) > 0.1);
        BOOST_TEST(difference(p, r) <= 1e-14);
        // the program in Jets, blocks included (what the sparse Hessian of a potential
        // runs): seeded with a direction (dq, dv), the derivative parts of its gradient
        // are the tape's Hessian times that direction
        using J2 = ceres::Jet<double, 2>;
        const DerivativeProgram& prog = *P.derivative_program();
        const VectorXd dq = random_vector(n, 1.0, 130 + 10 * t + point), dv = random_vector(n, 1.0, 170 + 10 * t + point);
        std::vector<J2> a(static_cast<std::size_t>(n)), b(a), ga(a), gb(a);
        for (int i = 0; i < n; ++i) {
          a[static_cast<std::size_t>(i)] = J2(q[i]);
          a[static_cast<std::size_t>(i)].v << dq[i], 1.0;
          b[static_cast<std::size_t>(i)] = J2(v[i]);
          b[static_cast<std::size_t>(i)].v << dv[i], 0.0;
        }
        std::vector<J2> slots = prog.workspace_any<J2>();
        prog.gradient_blocks_any(a.data(), b.data(), ga.data(), gb.data(), slots.data());
        const VectorXd Hq = r.Lqq * dq + r.Lqv * dv, Hv = r.Lqv.transpose() * dq + r.Lvv * dv;
        const VectorXd sq = r.Lqq.rowwise().sum(), sv = r.Lqv.colwise().sum().transpose();
        const double scale = largest(r) * (dq.cwiseAbs().sum() + dv.cwiseAbs().sum());
        double worst = 0.0;
        for (int i = 0; i < n; ++i) {
          const auto& x = ga[static_cast<std::size_t>(i)];
          const auto& y = gb[static_cast<std::size_t>(i)];
          worst = std::max({worst, std::fabs(x.a - r.Lq[i]) / largest(r), std::fabs(y.a - r.Lv[i]) / largest(r),
                            std::fabs(x.v[0] - Hq[i]) / scale, std::fabs(y.v[0] - Hv[i]) / scale,
                            std::fabs(x.v[1] - sq[i]) / scale, std::fabs(y.v[1] - sv[i]) / scale});
        }
        BOOST_TEST(worst <= 1e-14);
      }
    }
    ++t;
  }
}

BOOST_AUTO_TEST_CASE(terms_that_read_definitions_stay_out_of_blocks) {
  // Sixteen squared velocities written as definitions (the middles of scissor_lift.toml's
  // links): a sum of one shape long enough for a block, whose terms read definitions. A
  // block's program reads only q and v, so they stay on the tape as plain terms, and the
  // text keeps its Hessian program; beside a block of terms in q alone, the gradient
  // program. Both against the tape's reverse mode.
  std::vector<std::string> coords;
  std::vector<std::pair<std::string, std::string>> defs;
  std::string squares, springs;
  for (int i = 0; i < 16; ++i) {
    coords.push_back("y" + std::to_string(i));
    const std::string y = coords.back(), prev = i ? coords[static_cast<std::size_t>(i - 1)] : "y15";
    defs.emplace_back("u" + std::to_string(i), "cos(" + y + ")*" + y + "_dot + sin(" + prev + ")*" + prev + "_dot");
    squares += (i ? " + " : "") + ("u" + std::to_string(i)) + "^2/2";
    springs += " - (" + y + " - " + prev + ")^2/2";
  }
  for (const bool with_block : {false, true}) {
    const auto s = written(coords, squares + (with_block ? springs : " - y0^2/2"), defs);
    BOOST_TEST_CONTEXT((with_block ? "beside a block" : "alone")) {
      BOOST_TEST(s->lagrangian.blocks().size() == (with_block ? 1u : 0u));
      const WrittenDynamic P(s), R(s, WrittenDerivatives::forward_over_reverse);
      BOOST_TEST_REQUIRE(P.derivative_program() != nullptr);
      BOOST_TEST(P.derivative_program()->has_hessian() == !with_block);
      for (int point = 0; point < 2; ++point) {
        const VectorXd q = random_vector(16, 0.6, 300 + point), v = random_vector(16, 0.8, 310 + point);
        const Derivatives p = derivatives(P, q, v), r = derivatives(R, q, v);
        BOOST_TEST(largest(r) > 0.1);
        BOOST_TEST(difference(p, r) <= 1e-14);
      }
    }
  }
  // A definition read by a sum's terms (its value one for all of them): those terms stay
  // on the tape, out of the block the velocities' terms make, so the text keeps its
  // gradient program (the block leaves it without a Hessian program).
  auto s = std::make_shared<WrittenSystem>();
  s->add_array("q", 30, ExpressionSymbols::Boundary::fixed);
  s->params = {{"n", 30}};
  s->definitions = {{"c", "q[3]/2 + sin(q[7])"}};
  s->check_names();
  s->lagrangian = Expression::parse("sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n, (q[i] - c)^2/2)",
                                    s->symbols(WrittenSystem::Kind::lagrangian));
  BOOST_TEST(s->lagrangian.blocks().size() == 1u);
  {
    const WrittenDynamic Ps(s), Rs(s, WrittenDerivatives::forward_over_reverse);
    BOOST_TEST_REQUIRE(Ps.derivative_program() != nullptr);
    BOOST_TEST(!Ps.derivative_program()->has_hessian());
    const VectorXd qs = random_vector(30, 0.6, 21), vs = random_vector(30, 0.8, 22);
    BOOST_TEST(difference(derivatives(Ps, qs, vs), derivatives(Rs, qs, vs)) <= 1e-14);
  }
}

BOOST_AUTO_TEST_CASE(several_tapes_evaluated_as_one_program) {
  // the double pendulum's mass entries and potential (Expression::split_mass): the
  // values of the tapes to round-off, cos(a - b) made once though two entries' tapes
  // could share it, and sin and cos of a computed together where one tape needs each
  auto s = written({"a", "b"}, "1.5*a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*cos(a)");
  std::vector<Expression> mass;
  Expression U;
  BOOST_TEST_REQUIRE(Expression::split_mass(s->lagrangian.text(), s->symbols(WrittenSystem::Kind::lagrangian), 2, mass, U));
  const ExpressionSymbols sym = s->symbols(WrittenSystem::Kind::lagrangian);
  const Expression extra = Expression::parse("sin(a) + cos(a - b)^2", sym);
  std::vector<const Expression*> tapes;
  for (const Expression& e : mass) tapes.push_back(&e);
  tapes.push_back(&U);
  tapes.push_back(&extra);
  const auto p = DerivativeProgram::build_values(tapes, 2);
  BOOST_TEST_REQUIRE(p != nullptr);
  BOOST_TEST(p->values_only());
  BOOST_TEST(p->outputs() == tapes.size());
  BOOST_TEST(p->c_source("x").empty());
  int fused = 0, cos = 0, sin = 0;
  for (const auto& in : p->gradient_code()) {
    if (in.op == Expression::Op::Sin) (in.sign ? fused : sin) += 1;
    if (in.op == Expression::Op::Cos) ++cos;
  }
  BOOST_TEST(fused == 1);  // sin a and cos a
  BOOST_TEST(sin == 0);
  BOOST_TEST(cos == 1);  // cos(a - b), once
  auto w = p->workspace();
  std::vector<double> out(tapes.size());
  for (int k = 0; k < 20; ++k) {
    const VectorXd q = random_vector(2, 3.0, 10 + k);
    p->values(q.data(), nullptr, out.data(), w.data());
    for (std::size_t i = 0; i < tapes.size(); ++i) {
      const double t = (*tapes[i])(q.data());
      BOOST_TEST(std::fabs(out[i] - t) <= 1e-15 * std::fmax(1.0, std::fabs(t)));
    }
  }
  // not built for a tape with blocks, or for none
  auto chain = std::make_shared<WrittenSystem>();
  chain->add_array("q", 20, ExpressionSymbols::Boundary::none);
  chain->check_names();
  const Expression blocks = Expression::parse("sum(i, 1, 19, cos(q[i+1] - q[i]))", chain->symbols(WrittenSystem::Kind::lagrangian));
  BOOST_TEST_REQUIRE(!blocks.blocks().empty());
  BOOST_TEST(DerivativeProgram::build_values({&blocks}, 20) == nullptr);
  BOOST_TEST(DerivativeProgram::build_values({}, 2) == nullptr);
}

BOOST_AUTO_TEST_CASE(the_velocity_and_energy_of_a_mass_matrix_read_off_the_text) {
  // L = v^T M(q) v / 2 + U(q) with M's entries read off the text: v = M(q)^{-1} p and
  // E = <p, v>/2 - U(q) by one program of M's entries and U, against the velocity that
  // gave p and E_L = <L_v, v> - L from the tape
  const auto s = written({"a", "b"}, texts()[0].L);
  const WrittenDynamic L(s);
  BOOST_TEST_REQUIRE(L.parts().has_mass_entries());
  BOOST_TEST_REQUIRE(L.parts().mass_program != nullptr);
  for (int k = 0; k < 10; ++k) {
    const VectorXd q = random_vector(2, 2.0, 30 + k), v = random_vector(2, 1.0, 50 + k);
    VectorXd gq(2), p(2), w(2);
    L.gradient(q, v, gq, p);
    BOOST_TEST_REQUIRE(L.closed_velocity(q, p, w));
    BOOST_TEST((w - v).cwiseAbs().maxCoeff() <= 1e-14 * std::fmax(1.0, v.cwiseAbs().maxCoeff()));
    const double E = p.dot(v) - L.value(q, v);
    BOOST_TEST(std::fabs(L.energy_at(q, w, p) - E) <= 1e-14 * std::fmax(1.0, std::fabs(E)));
    // at another q than the last velocity's: U evaluated there, not the one kept
    const VectorXd q2 = q + VectorXd::Constant(2, 0.3);
    VectorXd p2(2);
    L.gradient(q2, v, gq, p2);
    const double E2 = p2.dot(v) - L.value(q2, v);
    BOOST_TEST(std::fabs(L.energy_at(q2, v, p2) - E2) <= 1e-14 * std::fmax(1.0, std::fabs(E2)));
  }
  // a separable text (M constant): v = M^{-1} p, U(q) its terms free of v
  const WrittenDynamic K(written({"x", "y"}, texts()[1].L));
  BOOST_TEST_REQUIRE(K.separable());
  for (int k = 0; k < 5; ++k) {
    const VectorXd q = random_vector(2, 2.0, 70 + k), v = random_vector(2, 1.0, 80 + k);
    VectorXd gq(2), p(2), w(2);
    K.gradient(q, v, gq, p);
    BOOST_TEST_REQUIRE(K.closed_velocity(q, p, w));
    const double E = p.dot(v) - K.value(q, v);
    BOOST_TEST(std::fabs(K.energy_at(q, w, p) - E) <= 1e-14 * std::fmax(1.0, std::fabs(E)));
  }
  // M(q) singular to working precision (M = [1 + cos a, 1; 1, 1] at a = pi/2): no closed
  // form there (Newton's method then reports the degeneracy), one a little away
  const WrittenDynamic S(written({"a", "b"}, "a_dot^2/2 + a_dot*b_dot + b_dot^2/2 + cos(a)*a_dot^2/2 + cos(b)"));
  BOOST_TEST_REQUIRE(S.parts().has_mass_entries());
  VectorXd q(2), p(2), w(2);
  p << 0.3, -0.2;
  q << std::acos(0.0), 0.1;
  BOOST_TEST(!S.closed_velocity(q, p, w));
  q[0] = 1.5;
  BOOST_TEST_REQUIRE(S.closed_velocity(q, p, w));
  VectorXd gq(2), pw(2);
  S.gradient(q, w, gq, pw);
  BOOST_TEST((pw - p).cwiseAbs().maxCoeff() <= 1e-14);
}

BOOST_AUTO_TEST_CASE(programs_are_not_built_beyond_their_scope) {
  // more than 32 coordinates (64 inputs): a gradient program, no Hessian program
  std::string L33;
  std::vector<std::string> c33;
  for (int i = 0; i < 33; ++i) {
    c33.push_back("y" + std::to_string(i));
    L33 += (i ? " + " : "") + c33.back() + "_dot^2/2 - cos(" + c33.back() + ")*" + c33.back() + "_dot";
  }
  const auto wide = written(c33, L33, {}, false);
  BOOST_TEST(DerivativeProgram::build(wide->lagrangian, 33) == nullptr);
  const WrittenDynamic P(wide), R(wide, WrittenDerivatives::forward_over_reverse);
  BOOST_TEST_REQUIRE(P.derivative_program() != nullptr);
  BOOST_TEST(!P.derivative_program()->has_hessian());
  const VectorXd q = random_vector(33, 0.5, 1), v = random_vector(33, 0.5, 2);
  BOOST_TEST(difference(derivatives(P, q, v), derivatives(R, q, v)) <= 1e-14);
  // a graph beyond kMaxNodes (30000 terms of different shapes, each on the tape): the tape
  const auto large = written({"x"}, "x_dot^2/2 + sum(i, 1, 30000, sin(x*i))", {}, false);
  BOOST_TEST(DerivativeProgram::build(large->lagrangian, 1) == nullptr);
  BOOST_TEST(DerivativeProgram::build(large->lagrangian, 1, false) == nullptr);
  BOOST_TEST(WrittenDynamic(large).derivative_program() == nullptr);
  // a power whose exponent varies from term to term inside a block: the tape, whose
  // pow(x, c) and c pow(x, c - 1) are finite at x = 0
  auto p = std::make_shared<WrittenSystem>();
  p->add_array("q", 20, ExpressionSymbols::Boundary::none);
  std::vector<double> e;
  for (int i = 0; i < 20; ++i) e.push_back(1.5 + i);
  p->params = {{"n", 20}};
  p->param_arrays = {{"e", e}};
  p->check_names();
  p->lagrangian = Expression::parse("sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n, q[i]^e[i])",
                                    p->symbols(WrittenSystem::Kind::lagrangian));
  BOOST_TEST(!p->lagrangian.blocks().empty());
  const WrittenDynamic W(p);
  BOOST_TEST(W.derivative_program() == nullptr);
  VectorXd gq(20), gv(20);
  W.gradient(VectorXd::Zero(20), VectorXd::Zero(20), gq, gv);
  BOOST_TEST(gq.allFinite());
  BOOST_TEST(gq.cwiseAbs().maxCoeff() == 0.0);
}

// ---- compiled programs (mechanics/native_code.h) -----------------------------------------

namespace {

// Exactly equal, bit for bit (NaN equal to NaN).
bool same_bits(const double* a, const double* b, int n) { return std::memcmp(a, b, sizeof(double) * n) == 0; }

// Whether the machine's C compiler runs (these tests need it; a build machine has one).
bool compiler_runs() {
  static const bool ok = [] {
    try {
      compile_programs({});
      return true;
    } catch (const NativeCodeError& e) {
      BOOST_TEST_MESSAGE("no C compiler: " << e.what());
      return false;
    }
  }();
  return ok;
}

}  // namespace

BOOST_AUTO_TEST_CASE(compiled_programs_give_the_interpreters_results_to_the_bit) {
  // every text, and powers the interpreter forms by repeated squaring (x^13, x^-7),
  // |x| on both sides of 0, sin and cos of one argument (one sincos): the compiled
  // gradient and Hessian equal the interpreted ones bit for bit at 5 random points,
  // written into matrices with leading dimensions larger than n
  BOOST_TEST_REQUIRE(compiler_runs());
  std::vector<Text> all = texts();
  all.push_back({{"x", "y"}, "x_dot^2/2 + y_dot^2/2 + x^13*y - y^-7 + abs(x - 0.5)*y^2 + sin(x)*cos(x)*y_dot", {}});
  int t = 0;
  for (const Text& text : all) {
    const auto s = written(text.coords, text.L, text.definitions);
    const int n = s->dim();
    const auto P = DerivativeProgram::build(s->lagrangian, n);
    BOOST_TEST_REQUIRE(P != nullptr);
    const WrittenDynamic F(s, WrittenDerivatives::forward_over_forward);
    const auto C = compile_programs({P.get()})[0];
    BOOST_TEST(C->compiled());
    BOOST_TEST(!P->compiled());
    std::vector<double> w = P->workspace();
    const int ld = n + 2;
    for (int k = 0; k < 5; ++k) {
      const VectorXd a = random_vector(n, 0.8, 500 + 10 * t + k), b = random_vector(n, 1.2, 900 + 10 * t + k);
      std::vector<double> gi(2 * n, -1.0), gc(2 * n, -2.0), hi(2 * n), hc(2 * n);
      std::vector<double> Hi(3 * ld * n, 7.0), Hc(3 * ld * n, 7.0);  // untouched padding must stay equal
      P->gradient(a.data(), b.data(), gi.data(), gi.data() + n, w.data());
      C->gradient(a.data(), b.data(), gc.data(), gc.data() + n, nullptr);
      P->hessian(a.data(), b.data(), hi.data(), hi.data() + n, Hi.data(), ld, Hi.data() + ld * n, ld,
                 Hi.data() + 2 * ld * n, ld, w.data());
      C->hessian(a.data(), b.data(), hc.data(), hc.data() + n, Hc.data(), ld, Hc.data() + ld * n, ld,
                 Hc.data() + 2 * ld * n, ld, nullptr);
      // the compiled code reads every input before it writes an output: the gradient
      // written over its own inputs is the same
      std::vector<double> over(a.data(), a.data() + n);
      over.insert(over.end(), b.data(), b.data() + n);
      C->gradient(over.data(), over.data() + n, over.data(), over.data() + n, nullptr);
      BOOST_TEST(same_bits(over.data(), gc.data(), 2 * n), text.L << ": gradient over its inputs");
      BOOST_TEST_CONTEXT(text.L << " at point " << k) {
        BOOST_TEST(same_bits(gi.data(), gc.data(), 2 * n));
        BOOST_TEST(same_bits(hi.data(), hc.data(), 2 * n));
        BOOST_TEST(same_bits(Hi.data(), Hc.data(), 3 * ld * n));
        // and both are L's derivatives: the tape's forward over forward, to round-off
        const Derivatives f = derivatives(F, a, b);
        Derivatives c{Eigen::Map<const VectorXd>(hi.data(), n), Eigen::Map<const VectorXd>(hi.data() + n, n),
                      MatrixXd(n, n), MatrixXd(n, n), MatrixXd(n, n)};
        for (int j = 0; j < n; ++j)
          for (int i = 0; i < n; ++i) {
            c.Lqq(i, j) = Hi[j * ld + i];
            c.Lqv(i, j) = Hi[ld * n + j * ld + i];
            c.Lvv(i, j) = Hi[2 * ld * n + j * ld + i];
          }
        BOOST_TEST(largest(f) > 0.1);
        BOOST_TEST(difference(c, f) <= 1e-13);
        for (int i = 0; i < n; ++i) {
          BOOST_TEST(std::fabs(gi[i] - f.Lq[i]) <= 1e-13 * largest(f));
          BOOST_TEST(std::fabs(gi[n + i] - f.Lv[i]) <= 1e-13 * largest(f));
        }
      }
    }
    ++t;
  }
}

BOOST_AUTO_TEST_CASE(written_systems_with_compiled_derivatives) {
  BOOST_TEST_REQUIRE(compiler_runs());
  // Kepler: L's program and its potential's, compiled in one run, give the interpreted
  // gradient, Hessian and force to the bit
  const auto s = written({"x", "y"}, "m/2*(x_dot^2 + y_dot^2) + k/sqrt(x^2 + y^2)");
  const WrittenDynamic P(s), C(s, WrittenDerivatives::compiled);
  BOOST_TEST(!P.compiled());
  BOOST_TEST(C.compiled());
  BOOST_TEST(C.compile_seconds() > 0.0);
  BOOST_TEST_REQUIRE(C.separable());
  BOOST_TEST(C.parts().potential_program->compiled());
  const VectorXd q = random_vector(2, 0.8, 3), v = random_vector(2, 1.2, 4);
  const Derivatives p = derivatives(P, q, v), c = derivatives(C, q, v);
  BOOST_TEST(difference(p, c) == 0.0);
  VectorXd Fp(2), Fc(2), Lv(2);
  WrittenSeparable(P).gradient(q, VectorXd::Zero(2), Fp, Lv);
  WrittenSeparable(C).gradient(q, VectorXd::Zero(2), Fc, Lv);
  BOOST_TEST(same_bits(Fp.data(), Fc.data(), 2));
  BOOST_TEST(std::fabs(Fp[0] + 0.7 * q[0] / std::pow(q.squaredNorm(), 1.5)) <= 1e-15);  // -k q / |q|^3
  // a written Hamiltonian
  auto h = written({"x", "y"}, "m/2*(x_dot^2 + y_dot^2) + k/sqrt(x^2 + y^2)");
  h->hamiltonian = Expression::parse("(p_x^2 + p_y^2)/(2*m) - k/sqrt(x^2 + y^2)",
                                     h->symbols(WrittenSystem::Kind::hamiltonian));
  const WrittenDynamicHamiltonian Hp(h), Hc(h, WrittenDerivatives::compiled);
  BOOST_TEST(Hc.compiled());
  VectorXd a(2), b(2), c2(2), d(2);
  Hp.gradient(q, v, a, b);
  Hc.gradient(q, v, c2, d);
  BOOST_TEST(same_bits(a.data(), c2.data(), 2));
  BOOST_TEST(same_bits(b.data(), d.data(), 2));
}

BOOST_AUTO_TEST_CASE(what_cannot_be_compiled_is_refused) {
  // a text with sums over arrays (blocks) has no C source
  auto chain = std::make_shared<WrittenSystem>();
  chain->name = "chain";
  chain->add_array("q", 64, ExpressionSymbols::Boundary::fixed);
  chain->params = {{"n", 64}};
  chain->check_names();
  chain->lagrangian = Expression::parse("sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^4/4)",
                                        chain->symbols(WrittenSystem::Kind::lagrangian));
  const auto P = DerivativeProgram::build(chain->lagrangian, 64, false);
  BOOST_TEST_REQUIRE(P != nullptr);
  BOOST_TEST_REQUIRE(P->has_blocks());
  BOOST_TEST(P->c_source("f").empty());
  try {
    const WrittenDynamic L(chain, WrittenDerivatives::compiled);
    BOOST_FAIL("a text with blocks was compiled");
  } catch (const NativeCodeError& e) {
    BOOST_TEST(std::string(e.what()).find("blocks") != std::string::npos, e.what());
  }
  // a compiler that fails or does not exist: its command and status in the message
  const auto s = written({"x"}, "x_dot^2/2 - x^4");
  const auto K = DerivativeProgram::build(s->lagrangian, 1);
  for (const std::string cc : {"false", "dvm-no-such-compiler"}) {
    try {
      compile_programs({K.get()}, cc);
      BOOST_FAIL("compiled with " + cc);
    } catch (const NativeCodeError& e) {
      const std::string m = e.what();
      BOOST_TEST(m.find(cc) != std::string::npos, m);
      BOOST_TEST(m.find(cc == "false" ? "status 1" : "status 127") != std::string::npos, m);
    }
  }
  // $DVM_CC names the compiler
  {
    const dvm_test::ScopedEnv cc("DVM_CC", "false");
    BOOST_TEST(default_c_compiler() == "false");
    BOOST_CHECK_THROW(WrittenDynamic(s, WrittenDerivatives::compiled), NativeCodeError);
  }
  {
    const dvm_test::ScopedEnv cc("DVM_CC", "");
    BOOST_TEST(default_c_compiler() == "cc");
  }
}

// The process keeps the last 16 objects it loaded: the same programs compiled again
// with the same compiler run no compiler and call the same code; another text, or
// another compiler command, runs it; the 16 most recent stay, the 17th back is
// compiled again. A compiler command that logs each run to a file counts them.
BOOST_AUTO_TEST_CASE(compiled_objects_are_loaded_once_per_process) {
  BOOST_TEST_REQUIRE(compiler_runs());
  char pattern[] = "/tmp/dvm-test-compiles-XXXXXX";
  BOOST_TEST_REQUIRE(::mkdtemp(pattern) != nullptr);
  const std::string log = std::string(pattern) + "/runs";
  const std::string counting = "f() { echo run >> '" + log + "'; cc \"$@\"; }; f";
  auto runs = [&] {
    std::ifstream in(log);
    int lines = 0;
    for (std::string line; std::getline(in, line);) ++lines;
    return lines;
  };
  // a text no other case compiles (another case's object may be kept already)
  auto program = [](int k) {
    const auto s = written({"x"}, "x_dot^2/2 - x^4/" + std::to_string(k + 7) + " + " + std::to_string(k) + "*x");
    return DerivativeProgram::build(s->lagrangian, 1);
  };
  const auto P = program(0);
  const auto A = compile_programs({P.get()}, counting)[0];
  const auto B = compile_programs({P.get()}, counting)[0];
  BOOST_TEST(runs() == 1);
  BOOST_TEST(A->compiled());
  BOOST_TEST(B->compiled());
  const double q[1] = {0.7}, v[1] = {-0.3};
  double ga[2][1], gb[2][1];
  std::vector<double> w = P->workspace();
  A->gradient(q, v, ga[0], gb[0], w.data());
  B->gradient(q, v, ga[1], gb[1], w.data());
  BOOST_TEST(same_bits(ga[0], ga[1], 1));
  BOOST_TEST(same_bits(gb[0], gb[1], 1));
  compile_programs({P.get()}, counting + " ");  // another command: compiled
  BOOST_TEST(runs() == 2);
  for (int k = 1; k <= 15; ++k) compile_programs({program(k).get()}, counting);
  BOOST_TEST(runs() == 17);
  compile_programs({P.get()}, counting + " ");  // the 16th most recent: kept
  BOOST_TEST(runs() == 17);
  compile_programs({P.get()}, counting);  // the 17th: compiled again
  BOOST_TEST(runs() == 18);
  std::filesystem::remove_all(pattern);
}

// What compiling can meet on a machine, each refused with what to do and nothing left
// behind: $TMPDIR that does not exist or holds a quote, a compiler killed by a signal,
// compiled code that cannot be loaded; the scratch directory is gone after a success
// and after each failure.
BOOST_AUTO_TEST_CASE(native_compilation_failures_name_their_cause_and_leave_nothing) {
  BOOST_TEST_REQUIRE(compiler_runs());
  const auto s = written({"x"}, "x_dot^2/2 - x^4");
  const auto P = DerivativeProgram::build(s->lagrangian, 1);
  BOOST_TEST_REQUIRE(P != nullptr);
  char pattern[] = "/tmp/dvm-test-native-XXXXXX";
  BOOST_TEST_REQUIRE(::mkdtemp(pattern) != nullptr);
  const std::string tmp = pattern;
  const auto empty = [&] { return std::filesystem::is_empty(tmp); };
  // (the TMPDIR cases compile a text of their own: P, compiled once, is loaded already,
  // and its next compilation would write nothing)
  const auto Q = DerivativeProgram::build(written({"x"}, "x_dot^2/2 - x^6")->lagrangian, 1);
  BOOST_TEST_REQUIRE(Q != nullptr);
  const auto refused = [&](const std::string& cc, const std::string& says, const DerivativeProgram* program = nullptr) {
    try {
      compile_programs({program ? program : P.get()}, cc);
      BOOST_ERROR("compiled with '" << cc << "'");
    } catch (const NativeCodeError& e) {
      BOOST_TEST(std::string(e.what()).find(says) != std::string::npos, e.what());
    }
    BOOST_TEST(empty(), "files left behind after '" << cc << "'");
  };
  {
    const dvm_test::ScopedEnv t("TMPDIR", tmp);
    BOOST_TEST_REQUIRE(!compile_programs({P.get()}).empty());  // a success leaves nothing
    BOOST_TEST(empty());
    refused("kill -KILL $$; true", "was killed by signal 9");
    // a "compiler" that writes something that is not a shared object where -o says
    const std::string fake = tmp + "-fake-cc.sh";
    std::ofstream(fake) << "#!/bin/sh\nwhile [ \"$1\" != -o ]; do shift; done\necho 'not an object' > \"$2\"\n";
    std::filesystem::permissions(fake, std::filesystem::perms::owner_all);
    refused(fake, "cannot load the compiled code");
    std::filesystem::remove(fake);
  }
  {
    const dvm_test::ScopedEnv t("TMPDIR", tmp + "/missing");
    refused(default_c_compiler(), "set TMPDIR to a writable directory", Q.get());
  }
  {
    const dvm_test::ScopedEnv t("TMPDIR", tmp + "/it's");
    refused(default_c_compiler(), "TMPDIR contains a quote", Q.get());
  }
  std::filesystem::remove_all(tmp);
}

namespace {

// Whether arithmetic on subnormal numbers is exact in this process (no flush-to-zero).
bool subnormals_kept() {
  volatile double tiny = 0x1p-1022, half = 0.5;
  return tiny * half == 0x1p-1023 && 0x1p-1023 != 0.0;
}

// The C compiler's own crtfastmath.o (gcc's; "" where there is none).
std::string crtfastmath() {
  FILE* p = ::popen((default_c_compiler() + " -print-file-name=crtfastmath.o 2>/dev/null").c_str(), "r");
  if (!p) return "";
  char buf[4096] = {0};
  const bool got = std::fgets(buf, sizeof buf, p) != nullptr;
  ::pclose(p);
  std::string path = got ? buf : "";
  while (!path.empty() && (path.back() == '\n' || path.back() == ' ')) path.pop_back();
  return path.find('/') != std::string::npos && std::ifstream(path).good() ? path : "";
}

}  // namespace

BOOST_AUTO_TEST_CASE(compiled_code_keeps_the_interpreters_arithmetic) {
  BOOST_TEST_REQUIRE(compiler_runs());
  BOOST_TEST_REQUIRE(subnormals_kept());
  // x^c with c = 1e-17: the derivative's power c - 1 rounds to -1.0 exactly, which gcc
  // would write as 1/x; glibc's pow(x, -1.0) differs from 1/x in the last bit here
  {
    const auto s = written({"x"}, "x_dot^2/2 - x^1e-17");
    const auto P = DerivativeProgram::build(s->lagrangian, 1);
    BOOST_TEST_REQUIRE(P != nullptr);
    const auto C = compile_programs({P.get()})[0];
    std::vector<double> w = P->workspace();
    const double q = 0x1.2d753ba068f6fp+9, v = 0.3;
    double gi[2], gc[2];
    P->gradient(&q, &v, gi, gi + 1, w.data());
    C->gradient(&q, &v, gc, gc + 1, nullptr);
    BOOST_TEST(same_bits(gi, gc, 2), gi[0] << " against " << gc[0]);
    BOOST_TEST(gi[0] == -1e-17 * std::pow(q, 1e-17 - 1.0));
  }
  // a compiler command with -ffast-math: our flags after it undo it, the results stay
  // the interpreter's, and flush-to-zero does not reach this process
  const auto s = written({"x", "y"}, "m/2*(x_dot^2 + y_dot^2) + k/sqrt(x^2 + y^2) + x^2*y/(1 + y^2)");
  const auto P = DerivativeProgram::build(s->lagrangian, 2);
  BOOST_TEST_REQUIRE(P != nullptr);
  {
    const dvm_test::ScopedEnv cc("DVM_CC", default_c_compiler() + " -ffast-math -O3");
    const auto C = compile_programs({P.get()})[0];
    BOOST_TEST(subnormals_kept());
    std::vector<double> w = P->workspace();
    for (int k = 0; k < 5; ++k) {
      const VectorXd a = random_vector(2, 0.8, 40 + k), b = random_vector(2, 1.2, 50 + k);
      double gi[4], gc[4];
      P->gradient(a.data(), b.data(), gi, gi + 2, w.data());
      C->gradient(a.data(), b.data(), gc, gc + 2, nullptr);
      BOOST_TEST(same_bits(gi, gc, 4));
    }
  }
}

// Whether the C compiler has a crtfastmath.o to link in (gcc's); the case below is
// reported as skipped where it has none.
boost::test_tools::assertion_result has_crtfastmath(boost::unit_test::test_unit_id) {
  boost::test_tools::assertion_result r(!crtfastmath().empty());
  r.message() << "the C compiler has no crtfastmath.o";
  return r;
}

// Code whose loading sets flush-to-zero (crtfastmath.o linked in by hand) is refused and
// the process's modes are put back.
BOOST_AUTO_TEST_CASE(code_that_changes_the_floating_point_modes_is_refused,
                     *boost::unit_test::precondition(has_crtfastmath)) {
  BOOST_TEST_REQUIRE(compiler_runs());
  const auto s = written({"x", "y"}, "m/2*(x_dot^2 + y_dot^2) + k/sqrt(x^2 + y^2) + x^2*y/(1 + y^2)");
  const auto P = DerivativeProgram::build(s->lagrangian, 2);
  BOOST_TEST_REQUIRE(P != nullptr);
  const dvm_test::ScopedEnv cc("DVM_CC", default_c_compiler() + " '" + crtfastmath() + "'");
  try {
    compile_programs({P.get()});
    BOOST_FAIL("code that sets flush-to-zero was loaded");
  } catch (const NativeCodeError& e) {
    BOOST_TEST(std::string(e.what()).find("floating-point control modes") != std::string::npos, e.what());
  }
  BOOST_TEST(subnormals_kept());
}
