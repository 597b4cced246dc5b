// libFuzzer target: the expression parser of written Lagrangians
// (mechanics/expression.h), arrays, lists, sums and definitions included. Text that parses is
// evaluated with doubles, with Jets (first derivatives) and by the reverse-mode
// gradient, at a fixed point, split by its degree in the velocities, and differentiated
// symbolically (mechanics/derivative_program.h: the program built, then its gradient and
// Hessian evaluated, in doubles and in Jets).
//
// Any input must parse or throw ExpressionError; evaluation must not crash or run
// into undefined behaviour (non-finite values are fine: log(-1) is NaN). Where it has
// them, the reverse-mode gradient must agree with the forward-mode (Jet) derivatives and
// the derivative program's gradient with the reverse mode's (differential checks). Run by
// `make fuzz`; seed corpus in tests/fuzz/corpus/expression.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <ceres/jet.h>

#include "mechanics/derivative_program.h"
#include "mechanics/expression.h"

// Two computations of the same derivatives must agree where both are finite and below
// 1e8 in size: to 1e-6 relative to the larger of 1, their sizes and reach, the size the
// text's value gives its derivatives (|f| / 0.1: a term of the value's size moved by an
// input of the inputs' smallest size). A text whose huge terms cancel in a derivative
// (x/y_dot^2 * 2444444444444444444/x: a value of 6e19, its derivative in x zero up to
// its terms' round-off) is thus held to its terms' round-off, and beyond 1e8 not
// compared. (Texts that cancel larger terms in their value too, or overflow, are not
// compared either.)
static void agree(const double* a, const double* b, int n, double reach = 1.0) {
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(a[i]) || !std::isfinite(b[i])) continue;
    const double size = std::fmax(std::fmax(1.0, reach), std::fmax(std::fabs(a[i]), std::fabs(b[i])));
    if (!(size <= 1e8)) continue;
    if (std::fabs(a[i] - b[i]) > 1e-6 * size) __builtin_trap();
  }
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  // two scalars and an array of 3 (fixed ends) in each block, a list, and constants
  // usable as sizes in sums: the syntax of sums and indices (sum(i, 1, n, q[i] - q[i-1]))
  dvm::ExpressionSymbols sym;
  sym.variables = {{"x", 0, 0}, {"y", 0, 1}, {"x_dot", 1, 0}, {"y_dot", 1, 1}, {"p_x", 2, 0}, {"p_y", 2, 1}};
  sym.arrays = {{"q", 0, 2, 3, dvm::ExpressionSymbols::Boundary::fixed},
                {"q_dot", 1, 2, 3, dvm::ExpressionSymbols::Boundary::fixed},
                {"r", 0, 2, 3, dvm::ExpressionSymbols::Boundary::periodic},
                {"p_q", 2, 2, 3, dvm::ExpressionSymbols::Boundary::none}};
  sym.constants = {{"m", 1.5}, {"k", 2.0}, {"g", 9.81}, {"n", 3.0}};
  sym.constant_arrays = {{"c", {0.5, -1.0, 2.0}}};
  sym.definitions = {{"r", "sqrt(x^2 + y^2)"}, {"s", "r*q[1] + x_dot*c[2]"}, {"u", "sum(i, 1, n, s*q[i])"}};
  dvm::Expression e;
  try {
    e = dvm::Expression::parse(text, sym);
  } catch (const dvm::ExpressionError& err) {
    if (err.offset > text.size()) __builtin_trap();  // the position must lie in the text
    return 0;
  }
  const double q[5] = {0.3, -0.7, 0.1, 0.2, -0.4}, v[5] = {1.1, 0.2, -0.3, 0.5, 0.9}, p[5] = {0.5, -1.5, 1, 2, 3};
  const double value = e(q, v, p);
  const double reach = std::isfinite(value) ? std::fabs(value) / 0.1 : 0.0;
  using J = ceres::Jet<double, 4>;
  const J qj[5] = {J(0.3, 0), J(-0.7, 1), J(0.1), J(0.2), J(-0.4)},
          vj[5] = {J(1.1, 2), J(0.2, 3), J(-0.3), J(0.5), J(0.9)}, pj[5] = {J(0.5), J(-1.5), J(1), J(2), J(3)};
  const J forward = e(qj, vj, pj);
  volatile double d = forward.v[0];
  (void)d;
  bool momenta = false;  // the gradient takes blocks 0 and 1 only
  for (int i = 0; i < 5; ++i) momenta = momenta || e.uses(2, i);
  if (!momenta) {
    double g0[5] = {0, 0, 0, 0, 0}, g1[5] = {0, 0, 0, 0, 0};
    e.gradient(q, v, g0, g1);
    // differential: the reverse-mode gradient against the forward-mode Jet derivatives
    // in x, y, x_dot, y_dot, where both are finite and of moderate size (the two sum the
    // same chain-rule products in different orders: round-off apart, far less than the
    // tolerance unless the text cancels huge terms, which the size bound keeps out)
    const double reverse[4] = {g0[0], g0[1], g1[0], g1[1]};
    agree(reverse, forward.v.data(), 4, reach);
    // the symbolic derivatives (none are built for texts with blocks), against the tape
    if (const auto program = dvm::DerivativeProgram::build(e, 5)) {
      std::vector<double> work = program->workspace();
      double h[3][25], p0[5], p1[5];
      program->gradient(q, v, p0, p1, work.data());
      agree(g0, p0, 5, reach);
      agree(g1, p1, 5, reach);
      program->hessian(q, v, p0, p1, h[0], 5, h[1], 5, h[2], 5, work.data());
      std::vector<J> slots(program->slots());
      J gj0[5], gj1[5];
      program->gradient_any(qj, vj, gj0, gj1, slots.data());
    }
  }
  // the velocity split reads the same text the same way
  try {
    dvm::Expression kin, pot;
    const dvm::VelocitySplit s = dvm::Expression::split_velocity(text, sym, &kin, &pot);
    if (s.constant_mass && !momenta) {
      volatile double t = kin(q, v, p) + pot(q, v, p);
      (void)t;
    }
    // M(q) read off the terms: its first column against L_v(q, e_1), as the gradient finds it
    std::vector<dvm::Expression> mass;
    dvm::Expression u;
    if (s.quadratic && !momenta && dvm::Expression::split_mass(text, sym, 5, mass, u)) {
      double unit[5] = {1, 0, 0, 0, 0}, g0[5] = {0, 0, 0, 0, 0}, g1[5] = {0, 0, 0, 0, 0}, column[5];
      e.gradient(q, unit, g0, g1);
      for (int i = 0; i < 5; ++i) column[i] = mass[static_cast<std::size_t>(i)](q);  // row 0: (0, i)
      agree(column, g1, 5);
      volatile double t = u(q);
      (void)t;
    }
  } catch (const dvm::ExpressionError&) {
    __builtin_trap();  // parse accepted it
  }
  return 0;
}
