// libFuzzer target: the expression parser of written Lagrangians
// (mechanics/expression.h). Text that parses is evaluated with doubles, with Jets
// (first derivatives) and by the reverse-mode gradient, at a fixed point.
//
// Any input must parse or throw ExpressionError; evaluation must not crash or run
// into undefined behaviour (non-finite values are fine: log(-1) is NaN). Run by
// `make fuzz`; seed corpus in tests/fuzz/corpus/expression.
#include <cstddef>
#include <cstdint>
#include <string>

#include <ceres/jet.h>

#include "mechanics/expression.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  dvm::ExpressionSymbols sym;
  sym.variables = {{"x", 0, 0}, {"y", 0, 1}, {"x_dot", 1, 0}, {"y_dot", 1, 1}, {"p_x", 2, 0}, {"p_y", 2, 1}};
  sym.constants = {{"m", 1.5}, {"k", 2.0}, {"g", 9.81}};
  dvm::Expression e;
  try {
    e = dvm::Expression::parse(text, sym);
  } catch (const dvm::ExpressionError& err) {
    if (err.offset > text.size()) __builtin_trap();  // the position must lie in the text
    return 0;
  }
  const double q[2] = {0.3, -0.7}, v[2] = {1.1, 0.2}, p[2] = {0.5, -1.5};
  volatile double value = e(q, v, p);
  (void)value;
  using J = ceres::Jet<double, 4>;
  const J qj[2] = {J(0.3, 0), J(-0.7, 1)}, vj[2] = {J(1.1, 2), J(0.2, 3)}, pj[2] = {J(0.5), J(-1.5)};
  volatile double d = e(qj, vj, pj).v[0];
  (void)d;
  if (!e.uses(2, 0) && !e.uses(2, 1)) {  // the gradient takes blocks 0 and 1 only
    double g0[2] = {0, 0}, g1[2] = {0, 0};
    e.gradient(q, v, g0, g1);
  }
  return 0;
}
