// Written expressions: a Lagrangian (or energy, or Hamiltonian) given as text, e.g.
//
//   "0.5*m*l^2*theta_dot^2 + m*g*l*cos(theta)"
//
// parsed once into a compact postfix tape and then evaluated for any scalar type T
// (double, ceres::Jet, nested Jets), so that everything the engine derives from a
// built-in Lagrangian it derives from a written one: gradients, the velocity Hessian,
// the discrete Lagrangian and the Jacobian of the step equations.
//
// Grammar (usual precedence, ^ binds tightest and to the right, -x^2 = -(x^2)):
//   expr    := term (('+' | '-') term)*
//   term    := unary (('*' | '/') unary)*
//   unary   := ('-' | '+') unary | power
//   power   := primary (('^' | '**') unary)?
//   primary := number | name | name '(' expr (',' expr)* ')' | '(' expr ')'
// Functions: sin cos tan asin acos atan exp log sqrt cbrt abs sinh cosh tanh (one
// argument), atan2(y, x), pow(x, y). The constant pi. (No min/max: a Lagrangian must
// be smooth for its derivatives to mean anything; abs is there for |x| away from 0.)
//
// Many coordinates. A name may stand for an array (of variables, or of constants: a
// parameter given as a list); its entries are name[index], numbered from 1:
//   primary := ... | name '[' expr ']' | 'sum' '(' name ',' expr ',' expr ',' expr ')'
// sum(i, a, b, body) is body_a + body_{a+1} + ... + body_b with the index name i bound
// to each whole number from a to b in turn (0 when b < a); inside the body i is that
// number, so q[i+1] - q[i], k[i] * i and a nested sum(j, i + 1, n, ...) all work. The
// bounds and every index must come out as whole numbers from constants and the
// indices of enclosing sums (checked as the text is read, with the offset). A sum is
// unrolled when the text is read: the tape holds every term, so evaluation costs the
// same as the text written out by hand, and the whole expression after unrolling is
// limited to Expression::kMaxNodes operations. An index outside 1..size is refused,
// unless the array says what lies beyond its ends: `fixed` (entries 0 and size + 1
// are 0: walls at rest) or `periodic` (the index is taken modulo the size).
//
// Definitions (ExpressionSymbols::definitions) name subexpressions: each is evaluated
// once per evaluation (stored by a Let instruction, read back as a variable of a fourth
// block) and differentiated through; one that folds to a number is used as that number.
// Many terms of one shape are evaluated as a block (Expression::Block), an instruction
// at a time across the terms.
//
// Names are resolved at parse time: each is a variable (an index into one of up to
// three input blocks, e.g. q, v and p) or a constant (a parameter value). Constant
// sub-expressions are folded, and an operation with a constant operand becomes a
// single instruction (x * c, x + c, c - x, c / x, x^n with n an integer), which for
// Jets costs a scaling instead of a full product rule. Evaluation runs the tape on a
// small fixed stack: no strings, no allocation, no virtual call.
//
// Errors are thrown as ExpressionError with the offset (0-based, in bytes) in the
// text where the problem is, and a message saying what was expected.
//
// Limits (input beyond them is refused with the offset, never a crash): the text is at
// most Expression::kMaxText bytes; parentheses, signs, right-hand sides of '^' and
// function arguments nest at most Expression::kMaxNesting levels (the parser recurses
// once per level; everything after it walks the tree without recursion, so a flat sum
// of any length within kMaxText is fine); evaluation needs a stack of at most
// Expression::kMaxStack values (an expression leaning right, a+(b+(c+...)), needs one
// per level).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <new>
#include <tuple>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "core/scalar.h"

namespace dvm {

struct ExpressionError : std::invalid_argument {
  ExpressionError(std::size_t offset_, const std::string& message)
      : std::invalid_argument(message), offset(offset_) {}
  std::size_t offset;  // position in the expression text
};

// What a name in an expression means.
struct ExpressionSymbols {
  struct Variable {
    std::string name;
    int block;  // 0, 1 or 2: which input array
    int index;  // position in that array
  };
  // What name[0] and name[size + 1] are (beyond them every index is refused, but for
  // periodic arrays, whose indices wrap around).
  enum class Boundary { none, fixed, periodic };
  // name[1] ... name[size]: entries offset ... offset + size - 1 of a block.
  struct Array {
    std::string name;
    int block;
    int offset;
    int size;
    Boundary boundary = Boundary::none;
  };
  struct ConstantArray {
    std::string name;
    std::vector<double> values;  // name[1] is values[0]
  };
  std::vector<Variable> variables;
  std::vector<std::pair<std::string, double>> constants;  // parameters, in order
  std::vector<Array> arrays;
  std::vector<ConstantArray> constant_arrays;
  // Named subexpressions, {name, text}: a definition may use the names above and the
  // definitions before it; where an expression uses it, it is evaluated once per
  // evaluation of the expression (Expression::kMaxDefinitions at most).
  std::vector<std::pair<std::string, std::string>> definitions;

  // Every known name, variables then constants, for "unknown name" messages.
  std::string known_names() const {
    std::string out;
    auto add = [&](const std::string& n) { out += (out.empty() ? "" : ", ") + n; };
    for (const auto& v : variables) add(v.name);
    for (const auto& a : arrays) add(a.name + "[1.." + std::to_string(a.size) + "]");
    for (const auto& c : constants) add(c.first);
    for (const auto& c : constant_arrays) add(c.name + "[1.." + std::to_string(c.values.size()) + "]");
    for (const auto& d : definitions) add(d.first);
    add("pi");
    return out;
  }
};

// How an expression in blocks 0 and 1 (q and v) depends on block 1, read off its
// additive terms (Expression::split_velocity). A term is homogeneous of degree d in v
// when it is built from v by sums of terms of equal degree, products (degrees add),
// quotients by v-free terms and whole powers, with any function of the other variables
// and the constants as coefficients. The terms are sorted as
//   potential   free of v (degree 0)
//   kinetic     of degree 2 and free of q: v^T M v / 2 with M constant
//   mechanical  of degree 2 with coefficients that depend on q
//   other       anything else (degree 1, 3, ..., or v inside a function)
struct VelocitySplit {
  bool quadratic = false;      // no `other` terms: L = v^T M(q) v / 2 + U(q)
  bool constant_mass = false;  // quadratic with no `mechanical` terms: M constant
  bool diagonal = false;       // constant_mass and every kinetic term uses one velocity
  int kinetic_terms = 0, potential_terms = 0, mechanical_terms = 0, other_terms = 0;
};

class Expression {
 public:
  // Largest stack depth the evaluator supports (checked at parse time).
  static constexpr int kMaxStack = 24;
  // Longest text and deepest nesting the parser accepts (see the header comment).
  static constexpr std::size_t kMaxText = std::size_t{1} << 20;
  static constexpr int kMaxNesting = 256;
  // Most operations an expression may have once its sums are unrolled.
  static constexpr std::size_t kMaxNodes = std::size_t{1} << 20;
  // Most definitions (ExpressionSymbols::definitions) an expression may use.
  static constexpr int kMaxDefinitions = 64;

  enum class Op : std::uint8_t {
    Const, Var,
    Neg, Add, Sub, Mul, Div,
    AddC, MulC, DivC, RSubC, RDivC,  // x + c, x * c, x / c, c - x, c / x
    PowI, PowC, Pow,                  // x^n (integer n), x^c, x^y
    Sin, Cos, Tan, Asin, Acos, Atan, Exp, Log, Sqrt, Cbrt, Abs, Sinh, Cosh, Tanh,
    Atan2,
    Block,  // pushes the sum of the terms of blocks_[index] (array-at-a-time, see Block)
    Let,    // pops the value of definition `index` (read back as Var of block 3)
  };
  struct Instr {
    Op op;
    std::int8_t block = 0;
    std::int32_t index = 0;  // variable index, or the integer power
    double c = 0.0;          // constant operand
  };

  Expression() = default;

  // Parses `text`; throws ExpressionError.
  static Expression parse(const std::string& text, const ExpressionSymbols& symbols, bool blocks = true);

  // Many additive terms of one shape (the terms of a sum over a chain, a lattice or
  // pairs: the same operations on different variables and constants) are kept as a
  // block, evaluated an instruction at a time across all its terms rather than a term
  // at a time: one dispatch per instruction of the body, then tight loops over the
  // terms. The top-level additive terms of an expression are grouped by shape; a group
  // of at least kMinBlock terms becomes a block (parse(..., blocks = false) keeps every
  // term on the tape, the reference the blocks are tested against).
  static constexpr int kMinBlock = 16;
  struct Block {
    std::vector<Instr> body;                      // the first term's instructions (postfix)
    std::vector<std::int32_t> arg_a, arg_b;       // operands of each body instruction
    int terms = 0;
    std::vector<std::vector<std::int32_t>> index;  // per Var instruction: its index in each term
    std::vector<std::vector<double>> c;            // per instruction whose constant varies: each term's
  };
  const std::vector<Block>& blocks() const { return blocks_; }

  const std::string& text() const { return text_; }
  const std::vector<Instr>& tape() const { return tape_; }
  int stack_depth() const { return depth_; }
  // Whether variable (block, index) appears in the expression after folding.
  bool uses(int block, int index) const {
    for (const auto& in : tape_)
      if (in.op == Op::Var && in.block == block && in.index == index) return true;
    for (const Block& b : blocks_)
      for (std::size_t j = 0; j < b.body.size(); ++j)
        if (b.body[j].op == Op::Var && b.body[j].block == block)
          for (std::int32_t i : b.index[j])
            if (i == index) return true;
    return false;
  }
  // Calls f(block, index) for every variable the expression reads (with repeats).
  template <class F>
  void for_each_variable(F&& f) const {
    for (const auto& in : tape_)
      if (in.op == Op::Var) f(int(in.block), int(in.index));
    for (const Block& b : blocks_)
      for (std::size_t j = 0; j < b.body.size(); ++j)
        if (b.body[j].op == Op::Var)
          for (std::int32_t i : b.index[j]) f(int(b.body[j].block), int(i));
  }
  bool empty() const { return tape_.empty(); }

  // The value for the inputs b0, b1, b2 (blocks of variables; unused ones may be null).
  template <class T>
  T operator()(const T* b0, const T* b1 = nullptr, const T* b2 = nullptr) const;

  // Reverse mode: adds the gradient of the value with respect to the variables of
  // blocks 0 and 1 to g0 and g1 (the caller zeroes them). One forward sweep stores
  // every intermediate value, one backward sweep propagates adjoints: the cost is a
  // small multiple of one evaluation, independent of the number of variables, and
  // for Jets it keeps the scalar one nesting level shallower than forward mode.
  // Tapes of up to kStackTape instructions keep their intermediate values on the
  // stack; longer ones in a buffer kept per thread and scalar type (grown, never
  // shrunk), so a call allocates nothing once the buffer has its size. Returns true.
  static constexpr int kStackTape = 256;
  template <class T>
  bool gradient(const T* b0, const T* b1, T* g0, T* g1) const;

  // The terms of `text` (in q, block 0, and v, block 1) sorted by their degree in v
  // (VelocitySplit). When the split is quadratic with a constant mass, `kinetic` and
  // `potential` receive the sums of those terms (so that text = kinetic + potential),
  // each a tape of its own. Throws ExpressionError as parse does.
  static VelocitySplit split_velocity(const std::string& text, const ExpressionSymbols& symbols,
                                      Expression* kinetic = nullptr, Expression* potential = nullptr);

  // For a text quadratic in the n velocities, L = v^T M(q) v / 2 + U(q) (VelocitySplit::
  // quadratic), the entries of M(q) read off its terms, each an expression in q (block
  // 0): M_ii = d2L/dv_i^2, M_ij = d2L/dv_i dv_j, found per term by polarisation (a term
  // t of degree 2 has M_ii = 2 t(e_i) and M_ij = t(e_i + e_j) - t(e_i) - t(e_j)), the
  // velocities set to those constants and the result folded (so a term a_dot * b_dot *
  // c(q) gives M_ab = c(q) alone). `mass` receives the upper triangle row by row
  // (n (n + 1) / 2 entries), `potential` U(q). Returns false, leaving both as they were,
  // when the text is not quadratic, n > kMaxMassDim, a definition the text uses
  // depends on the velocities, or a term in several velocities does not vanish when
  // all but one are zero (its cross entries would be differences that can cancel; the
  // caller then forms M from gradients), or a term with its velocities set to those
  // constants folds to a value that is not finite (x_dot^0 * 20/0, which parse accepts
  // as a product with a velocity: the text is not finite anywhere). Throws
  // ExpressionError where parse does.
  static constexpr int kMaxMassDim = 8;
  static bool split_mass(const std::string& text, const ExpressionSymbols& symbols, int n,
                         std::vector<Expression>& mass, Expression& potential);

  // One operation on scalars of any type: the same code folds constants (T = double)
  // and evaluates (any T).
  template <class T>
  static T unary(Op op, const T& x, const Instr& in);
  template <class T>
  static T binary(Op op, const T& x, const T& y);

 private:
  // Reverse mode through one instruction: z = op(x, y) with adjoint w adds to the
  // adjoints of its operands (ay for binary operations only).
  template <class T>
  static void backward(const Instr& in, const T& w, const T& z, const T& x, const T* y, T& ax, T* ay);
  // Throws ExpressionError when an evaluation would need more than kMaxStack slots.
  static void require_depth(int depth);
  // A block's values, instruction by instruction across its terms: val[j * terms + k]
  // is instruction j of term k (raw storage, constructed here); returns their sum.
  template <class T>
  static T block_forward(const Block& b, const T* const* in, T* val);
  // Its reverse sweep for the adjoint w of the sum, adding to grads[0], grads[1].
  template <class T>
  static void block_backward(const Block& b, const T& w, const T* val, T* adj, T* const* grads);

  std::string text_;
  std::vector<Instr> tape_;
  std::vector<Block> blocks_;
  int depth_ = 0;
  int definitions_ = 0;  // Let instructions on the tape
};

namespace expression_detail {

// x^n by repeated squaring (exact derivatives for any scalar, any sign of x).
template <class T>
T power_int(const T& x, int n) {
  if (n == 0) return constant<T>(1.0);
  if (n < 0) return constant<T>(1.0) / power_int(x, -n);
  if (n == 1) return x;
  if (n == 2) return x * x;
  T half = power_int(x, n / 2);
  T sq = half * half;
  return (n % 2) ? T(sq * x) : sq;
}

// x^c for a constant real c, recursively through nested Jets.
template <class T>
T power_const(const T& x, double c) {
  if constexpr (is_jet_v<T>) {
    using S = typename T::Scalar;
    const S d = c * power_const<S>(x.a, c - 1.0);
    T out;
    out.a = power_const<S>(x.a, c);
    out.v = x.v * d;
    return out;
  } else {
    return std::pow(x, c);
  }
}

template <class T>
T absolute(const T& x) {
  return value(x) < 0.0 ? T(-x) : x;
}

}  // namespace expression_detail

template <class T>
T Expression::unary(Op op, const T& x, const Instr& in) {
  using std::acos;
  using std::asin;
  using std::atan;
  using std::cbrt;
  using std::cos;
  using std::cosh;
  using std::exp;
  using std::log;
  using std::sin;
  using std::sinh;
  using std::sqrt;
  using std::tan;
  using std::tanh;
  switch (op) {
    case Op::Neg: return -x;
    case Op::AddC: return x + in.c;
    case Op::MulC: return x * in.c;
    case Op::DivC: return x / in.c;
    case Op::RSubC: return in.c - x;
    case Op::RDivC: return in.c / x;
    case Op::PowI: return expression_detail::power_int(x, in.index);
    case Op::PowC: return expression_detail::power_const(x, in.c);
    case Op::Sin: return sin(x);
    case Op::Cos: return cos(x);
    case Op::Tan: return tan(x);
    case Op::Asin: return asin(x);
    case Op::Acos: return acos(x);
    case Op::Atan: return atan(x);
    case Op::Exp: return exp(x);
    case Op::Log: return log(x);
    case Op::Sqrt: return sqrt(x);
    case Op::Cbrt: return cbrt(x);
    case Op::Abs: return expression_detail::absolute(x);
    case Op::Sinh: return sinh(x);
    case Op::Cosh: return cosh(x);
    case Op::Tanh: return tanh(x);
    default: return x;  // not reached: the parser emits unary ops only here
  }
}

template <class T>
T Expression::binary(Op op, const T& x, const T& y) {
  using std::atan2;
  using std::exp;
  using std::log;
  switch (op) {
    case Op::Add: return x + y;
    case Op::Sub: return x - y;
    case Op::Mul: return x * y;
    case Op::Div: return x / y;
    case Op::Pow: return exp(y * log(x));
    case Op::Atan2: return atan2(x, y);
    default: return x;  // not reached
  }
}

template <class T>
T Expression::operator()(const T* b0, const T* b1, const T* b2) const {
  // The stack is raw storage: a Jet of Jets is large, and zeroing kMaxStack of them on
  // every call would cost more than the arithmetic. Each slot is constructed when
  // pushed. Jets hold fixed-size Eigen vectors and are trivially destructible.
  static_assert(std::is_trivially_destructible_v<T>, "the expression stack never runs destructors");
  alignas(T) unsigned char raw[kMaxStack * sizeof(T)];
  T* s = std::launder(reinterpret_cast<T*>(raw));
  alignas(T) unsigned char raw_defs[kMaxDefinitions * sizeof(T)];  // raw: only Let writes it
  T* defs = std::launder(reinterpret_cast<T*>(raw_defs));
  const T* blocks[4] = {b0, b1, b2, defs};
  // The top of the stack is held in x, apart from the slots below it (s[0..top]): in
  // doubles it stays in a register, where a stack slot would be stored by one operation
  // and loaded by the next, each waiting on the other. The first push stores this zero.
  T x = constant<T>(0.0);
  int top = -1;
  using std::sqrt;
  for (const Instr& in : tape_) {
    switch (in.op) {
      case Op::Let:
        new (&defs[in.index]) T(x);
        x = s[top--];
        break;
      case Op::Const:
        new (&s[++top]) T(x);
        x = constant<T>(in.c);
        break;
      case Op::Var:
        new (&s[++top]) T(x);
        x = blocks[in.block][in.index];
        break;
      // the common operations inline (through unary and binary, a call and a second
      // dispatch each, they cost more than their arithmetic in doubles; sqrt is one
      // instruction)
      case Op::Add: x = s[top--] + x; break;
      case Op::Sub: x = s[top--] - x; break;
      case Op::Mul: x = s[top--] * x; break;
      case Op::Div: x = s[top--] / x; break;
      case Op::Neg: x = -x; break;
      case Op::AddC: x = x + in.c; break;
      case Op::MulC: x = x * in.c; break;
      case Op::DivC: x = x / in.c; break;
      case Op::RSubC: x = in.c - x; break;
      case Op::RDivC: x = in.c / x; break;
      case Op::PowI: x = in.index == 2 ? T(x * x) : expression_detail::power_int(x, in.index); break;
      case Op::Sqrt: x = sqrt(x); break;
      case Op::Pow: case Op::Atan2:
        x = binary(in.op, s[top--], x);
        break;
      case Op::Block: {
        const Block& b = blocks_[static_cast<std::size_t>(in.index)];
        thread_local std::vector<T> work;
        const std::size_t need = b.body.size() * static_cast<std::size_t>(b.terms);
        if (work.size() < need) work.resize(need);
        new (&s[++top]) T(x);
        x = block_forward(b, blocks, work.data());
        break;
      }
      default: x = unary(in.op, x, in); break;
    }
  }
  return x;
}

template <class T>
void Expression::backward(const Instr& in, const T& w, const T& z, const T& x, const T* y, T& ax, T* ay) {
  using std::cos;
  using std::cosh;
  using std::log;
  using std::sin;
  using std::sinh;
  using std::sqrt;
  switch (in.op) {
    case Op::Neg: ax -= w; break;
    case Op::AddC: ax += w; break;
    case Op::MulC: ax += w * in.c; break;
    case Op::DivC: ax += w / in.c; break;
    case Op::RSubC: ax -= w; break;
    case Op::RDivC: ax -= w * (z / x); break;
    case Op::PowI:
      if (in.index != 0) ax += w * (static_cast<double>(in.index) * expression_detail::power_int(x, in.index - 1));
      break;
    case Op::PowC: ax += w * (in.c * expression_detail::power_const(x, in.c - 1.0)); break;
    case Op::Sin: ax += w * cos(x); break;
    case Op::Cos: ax -= w * sin(x); break;
    case Op::Tan: ax += w * (1.0 + z * z); break;
    case Op::Asin: ax += w / sqrt(1.0 - x * x); break;
    case Op::Acos: ax -= w / sqrt(1.0 - x * x); break;
    case Op::Atan: ax += w / (1.0 + x * x); break;
    case Op::Exp: ax += w * z; break;
    case Op::Log: ax += w / x; break;
    case Op::Sqrt: ax += w * (0.5 / z); break;
    case Op::Cbrt: ax += w * (z / (3.0 * x)); break;
    case Op::Abs:
      if (value(x) < 0.0)
        ax -= w;
      else
        ax += w;
      break;
    case Op::Sinh: ax += w * cosh(x); break;
    case Op::Cosh: ax += w * sinh(x); break;
    case Op::Tanh: ax += w * (1.0 - z * z); break;
    case Op::Add: ax += w; *ay += w; break;
    case Op::Sub: ax += w; *ay -= w; break;
    case Op::Mul: ax += w * *y; *ay += w * x; break;
    case Op::Div: ax += w / *y; *ay -= w * (z / *y); break;
    case Op::Pow: ax += w * (z * *y / x); *ay += w * (z * log(x)); break;
    case Op::Atan2: {  // atan2(x, y): d/dx = y/r^2, d/dy = -x/r^2
      const T r2 = x * x + *y * *y;
      ax += w * (*y / r2);
      *ay -= w * (x / r2);
      break;
    }
    default: break;
  }
}

template <class T>
T Expression::block_forward(const Block& b, const T* const* in, T* val) {
  const std::size_t m = static_cast<std::size_t>(b.terms);
  for (std::size_t j = 0; j < b.body.size(); ++j) {
    const Instr& ins = b.body[j];
    T* out = val + j * m;
    const std::vector<double>& cs = b.c[j];
    switch (ins.op) {
      case Op::Const:
        for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(constant<T>(cs.empty() ? ins.c : cs[k]));
        continue;
      case Op::Var: {
        const T* src = in[ins.block];
        const std::int32_t* ix = b.index[j].data();
        for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(src[ix[k]]);
        continue;
      }
      default: break;
    }
    const T* x = val + static_cast<std::size_t>(b.arg_a[j]) * m;
    if (b.arg_b[j] >= 0) {
      const T* y = val + static_cast<std::size_t>(b.arg_b[j]) * m;
      switch (ins.op) {  // the common operations as plain loops (vectorised for doubles)
        case Op::Add: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] + y[k]); break;
        case Op::Sub: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] - y[k]); break;
        case Op::Mul: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] * y[k]); break;
        default: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(binary(ins.op, x[k], y[k])); break;
      }
      continue;
    }
    if (cs.empty()) {
      switch (ins.op) {
        case Op::MulC: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] * ins.c); break;
        case Op::AddC: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] + ins.c); break;
        case Op::Neg: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(-x[k]); break;
        case Op::PowI:
          if (ins.index == 2) {
            for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] * x[k]);
            break;
          }
          if (ins.index == 3) {
            for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(x[k] * x[k] * x[k]);
            break;
          }
          if (ins.index == 4) {
            for (std::size_t k = 0; k < m; ++k) {
              const T x2 = x[k] * x[k];
              new (&out[k]) T(x2 * x2);
            }
            break;
          }
          [[fallthrough]];
        default: for (std::size_t k = 0; k < m; ++k) new (&out[k]) T(unary(ins.op, x[k], ins)); break;
      }
    } else {
      Instr t = ins;
      for (std::size_t k = 0; k < m; ++k) {
        t.c = cs[k];
        new (&out[k]) T(unary(ins.op, x[k], t));
      }
    }
  }
  const T* last = val + (b.body.size() - 1) * m;
  T sum = last[0];
  for (std::size_t k = 1; k < m; ++k) sum += last[k];
  return sum;
}

template <class T>
void Expression::block_backward(const Block& b, const T& w, const T* val, T* adj, T* const* grads) {
  const std::size_t m = static_cast<std::size_t>(b.terms), n = b.body.size();
  for (std::size_t j = 0; j + 1 < n; ++j)
    for (std::size_t k = 0; k < m; ++k) new (&adj[j * m + k]) T(constant<T>(0.0));
  for (std::size_t k = 0; k < m; ++k) new (&adj[(n - 1) * m + k]) T(w);
  for (std::size_t j = n; j-- > 0;) {
    const Instr& ins = b.body[j];
    const T* aj = adj + j * m;
    if (ins.op == Op::Const) continue;
    if (ins.op == Op::Var) {
      if (ins.block != 2) {
        T* g = grads[ins.block];
        const std::int32_t* ix = b.index[j].data();
        for (std::size_t k = 0; k < m; ++k) g[ix[k]] += aj[k];
      }
      continue;
    }
    const std::size_t a = static_cast<std::size_t>(b.arg_a[j]) * m;
    const std::vector<double>& cs = b.c[j];
    const T* z = val + j * m;
    if (b.arg_b[j] >= 0) {
      const std::size_t bb = static_cast<std::size_t>(b.arg_b[j]) * m;
      switch (ins.op) {
        case Op::Add:
          for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k], adj[bb + k] += aj[k];
          break;
        case Op::Sub:
          for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k], adj[bb + k] -= aj[k];
          break;
        case Op::Mul:
          for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k] * val[bb + k], adj[bb + k] += aj[k] * val[a + k];
          break;
        default:
          for (std::size_t k = 0; k < m; ++k) backward(ins, aj[k], z[k], val[a + k], &val[bb + k], adj[a + k], &adj[bb + k]);
      }
      continue;
    }
    if (cs.empty()) {
      switch (ins.op) {
        case Op::MulC: for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k] * ins.c; break;
        case Op::AddC: for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k]; break;
        case Op::Neg: for (std::size_t k = 0; k < m; ++k) adj[a + k] -= aj[k]; break;
        case Op::PowI:
          if (ins.index == 2) {
            for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k] * (2.0 * val[a + k]);
            break;
          }
          if (ins.index == 3) {
            for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k] * (3.0 * (val[a + k] * val[a + k]));
            break;
          }
          if (ins.index == 4) {
            for (std::size_t k = 0; k < m; ++k) adj[a + k] += aj[k] * (4.0 * (val[a + k] * val[a + k] * val[a + k]));
            break;
          }
          [[fallthrough]];
        default:
          for (std::size_t k = 0; k < m; ++k) backward(ins, aj[k], z[k], val[a + k], static_cast<const T*>(nullptr), adj[a + k], static_cast<T*>(nullptr));
      }
    } else {
      Instr t = ins;
      for (std::size_t k = 0; k < m; ++k) {
        t.c = cs[k];
        backward(t, aj[k], z[k], val[a + k], static_cast<const T*>(nullptr), adj[a + k], static_cast<T*>(nullptr));
      }
    }
  }
}

template <class T>
bool Expression::gradient(const T* b0, const T* b1, T* g0, T* g1) const {
  static_assert(std::is_trivially_destructible_v<T>, "the expression arrays never run destructors");
  const int n = static_cast<int>(tape_.size());
  // Storage: on the stack for short tapes, else in a per-thread buffer (raw: each slot
  // is constructed when written, as for the evaluation stack).
  struct Slot {
    alignas(T) unsigned char bytes[2 * sizeof(T)];
    std::int32_t a, b;
  };
  Slot small[kStackTape];
  Slot* slots = small;
  if (n > kStackTape) {
    thread_local std::vector<Slot> buffer;
    if (buffer.size() < static_cast<std::size_t>(n)) buffer.resize(static_cast<std::size_t>(n));
    slots = buffer.data();
  }
  // the blocks' values and adjoints, kept from the forward sweep to the backward one
  T* block_store = nullptr;
  if (!blocks_.empty()) {
    std::size_t need = 0;
    for (const Block& b : blocks_) need += 2 * b.body.size() * static_cast<std::size_t>(b.terms);
    thread_local std::vector<T> store;
    if (store.size() < need) store.resize(need);
    block_store = store.data();
  }
  auto block_values = [&](int id) {
    std::size_t off = 0;
    for (int k = 0; k < id; ++k) off += 2 * blocks_[static_cast<std::size_t>(k)].body.size() *
                                        static_cast<std::size_t>(blocks_[static_cast<std::size_t>(k)].terms);
    return block_store + off;
  };
  std::int32_t stack[kMaxStack];
  struct Values {  // val[i], adj[i], arg_a[i], arg_b[i] of instruction i
    Slot* s;
    T& operator[](int i) const { return *std::launder(reinterpret_cast<T*>(s[i].bytes)); }
  };
  struct Adjoints {
    Slot* s;
    T& operator[](int i) const { return *std::launder(reinterpret_cast<T*>(s[i].bytes + sizeof(T))); }
  };
  const Values val{slots};
  const Adjoints adj{slots};
  // definitions: their values (read as block 3) and adjoints
  alignas(T) unsigned char raw_defs[2 * kMaxDefinitions * sizeof(T)];
  T* defs = std::launder(reinterpret_cast<T*>(raw_defs));
  T* defs_adj = defs + kMaxDefinitions;
  for (int k = 0; k < definitions_; ++k) new (&defs_adj[k]) T(constant<T>(0.0));
  const T* blocks[4] = {b0, b1, nullptr, defs};
  T* grads[4] = {g0, g1, nullptr, defs_adj};
  int top = -1;
  for (int i = 0; i < n; ++i) {
    const Instr& in = tape_[static_cast<std::size_t>(i)];
    switch (in.op) {
      case Op::Let:  // pops: nothing pushed
        slots[i].a = stack[top--];
        new (&val[i]) T(val[slots[i].a]);
        new (&defs[in.index]) T(val[i]);
        new (&adj[i]) T(constant<T>(0.0));
        continue;
      case Op::Const: new (&val[i]) T(constant<T>(in.c)); break;
      case Op::Var: new (&val[i]) T(blocks[in.block][in.index]); break;
      case Op::Block:
        new (&val[i]) T(block_forward(blocks_[static_cast<std::size_t>(in.index)], blocks, block_values(in.index)));
        break;
      case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2:
        slots[i].a = stack[top - 1];
        slots[i].b = stack[top];
        top -= 2;
        new (&val[i]) T(binary(in.op, val[slots[i].a], val[slots[i].b]));
        break;
      default:
        slots[i].a = stack[top--];
        new (&val[i]) T(unary(in.op, val[slots[i].a], in));
        break;
    }
    stack[++top] = i;
    new (&adj[i]) T(constant<T>(0.0));
  }
  adj[n - 1] = constant<T>(1.0);
  for (int i = n - 1; i >= 0; --i) {
    const Instr& in = tape_[static_cast<std::size_t>(i)];
    const T& w = adj[i];
    switch (in.op) {
      case Op::Const: continue;
      case Op::Var:
        if (in.block != 2) grads[in.block][in.index] += w;
        continue;
      case Op::Let:  // all its uses come later on the tape: their adjoints are in
        adj[slots[i].a] += defs_adj[in.index];
        continue;
      case Op::Block: {
        const Block& b = blocks_[static_cast<std::size_t>(in.index)];
        T* v = block_values(in.index);
        block_backward(b, w, v, v + b.body.size() * static_cast<std::size_t>(b.terms), grads);
        continue;
      }
      case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2:
        backward(in, w, val[i], val[slots[i].a], &val[slots[i].b], adj[slots[i].a], &adj[slots[i].b]);
        continue;
      default:
        backward(in, w, val[i], val[slots[i].a], static_cast<const T*>(nullptr), adj[slots[i].a], static_cast<T*>(nullptr));
    }
  }
  return true;
}

// ---------------------------------------------------------------------------------
// Parsing (inline: small, and keeps mechanics/ header-only).

namespace expression_detail {

struct Node {
  Expression::Op op;
  std::size_t pos;  // where in the text (for messages)
  double c = 0.0;
  int block = 0, index = 0;
  std::vector<std::unique_ptr<Node>> kids;
  bool is_const() const { return op == Expression::Op::Const; }
  Node() = default;
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;
  // A flat sum of n terms is a tree n deep: tear it down from a work list, so that no
  // destructor runs with children left (the default would recurse n deep).
  ~Node() {
    std::vector<std::unique_ptr<Node>> pending = std::move(kids);
    while (!pending.empty()) {
      std::unique_ptr<Node> n = std::move(pending.back());
      pending.pop_back();
      if (!n) continue;  // a slot left empty by an exception in simplify()
      for (auto& k : n->kids) pending.push_back(std::move(k));
      n->kids.clear();
    }
  }
};
using NodePtr = std::unique_ptr<Node>;

struct Function {
  const char* name;
  Expression::Op op;
  int arity;  // 1, or 2 for atan2 and pow
};
inline const std::vector<Function>& functions() {
  using O = Expression::Op;
  static const std::vector<Function> list = {
      {"sin", O::Sin, 1},   {"cos", O::Cos, 1},     {"tan", O::Tan, 1},   {"asin", O::Asin, 1},
      {"acos", O::Acos, 1}, {"atan", O::Atan, 1},   {"exp", O::Exp, 1},   {"log", O::Log, 1},
      {"sqrt", O::Sqrt, 1}, {"cbrt", O::Cbrt, 1},   {"abs", O::Abs, 1},   {"sinh", O::Sinh, 1},
      {"cosh", O::Cosh, 1}, {"tanh", O::Tanh, 1},   {"atan2", O::Atan2, 2}, {"pow", O::Pow, 2},
  };
  return list;
}
inline std::string function_names() {
  std::string out;
  for (const auto& f : functions()) out += (out.empty() ? "" : ", ") + std::string(f.name);
  return out;
}

NodePtr simplify(NodePtr root);

// The definitions an expression uses (ExpressionSymbols::definitions), shared by the
// parsers of the expression and of each definition: each is parsed at its first use,
// and gets the next slot (so a definition's own definitions have lower slots).
struct Definitions {
  std::vector<NodePtr> trees;   // by slot
  std::vector<int> slot;        // by definition: its slot, -1 while unused, -2 a constant
  std::vector<double> value;    // by definition: its value when it folds to a constant
  std::size_t nodes = 0;        // made so far (Expression::kMaxNodes), all texts together
  std::size_t folded = 0;       // made in indices and bounds and folded away (4 kMaxNodes)
};

class Parser {
 public:
  Parser(const std::string& text, const ExpressionSymbols& symbols, Definitions* defs = nullptr, int visible = -1)
      : t_(text), sym_(symbols), defs_(defs ? defs : &own_), visible_(visible < 0 ? static_cast<int>(symbols.definitions.size()) : visible) {
    if (defs_->slot.size() != symbols.definitions.size()) {
      defs_->slot.assign(symbols.definitions.size(), -1);
      defs_->value.assign(symbols.definitions.size(), 0.0);
    }
  }
  Definitions& definitions() { return *defs_; }

  NodePtr parse() {
    if (t_.size() > Expression::kMaxText)
      fail(Expression::kMaxText, "the expression is " + std::to_string(t_.size()) + " bytes long; at most " +
                                     std::to_string(Expression::kMaxText) + " are accepted");
    skip();
    if (i_ >= t_.size()) fail(i_, "expected an expression, got an empty text");
    NodePtr n = expr();
    skip();
    if (i_ < t_.size())
      fail(i_, "unexpected " + describe(i_) + "; expected an operator (+ - * / ^) or the end of the expression");
    return n;
  }

 private:
  [[noreturn]] void fail(std::size_t pos, const std::string& msg) const { throw ExpressionError(pos, msg); }

  std::string describe(std::size_t pos) const {
    if (pos >= t_.size()) return "end of the expression";
    return std::string("'") + t_[pos] + "'";
  }

  void skip() {
    while (i_ < t_.size() && std::isspace(static_cast<unsigned char>(t_[i_]))) ++i_;
  }
  bool accept(char c) {
    skip();
    if (i_ < t_.size() && t_[i_] == c) {
      ++i_;
      return true;
    }
    return false;
  }

  NodePtr make(Expression::Op op, std::size_t pos) {
    if (++defs_->nodes > Expression::kMaxNodes)
      fail(pos, "the expression has more than " + std::to_string(Expression::kMaxNodes) +
                    " operations once its sums are unrolled; write a smaller system or fewer terms");
    auto n = std::make_unique<Node>();
    n->op = op;
    n->pos = pos;
    return n;
  }
  NodePtr make_const(double c, std::size_t pos) {
    NodePtr n = make(Expression::Op::Const, pos);
    n->c = c;
    return n;
  }
  NodePtr make2(Expression::Op op, std::size_t pos, NodePtr a, NodePtr b) {
    NodePtr n = make(op, pos);
    n->kids.push_back(std::move(a));
    n->kids.push_back(std::move(b));
    return n;
  }

  // An operand is required at i_: say what was found instead.
  void need_operand(const char* after) {
    skip();
    if (i_ >= t_.size() || std::string("+*/^),").find(t_[i_]) != std::string::npos)
      fail(i_, std::string("expected a number, name or '(' after ") + after + ", got " + describe(i_));
  }

  NodePtr expr() {
    NodePtr n = term();
    while (true) {
      skip();
      const std::size_t at = i_;
      if (accept('+')) {
        need_operand("'+'");
        n = make2(Expression::Op::Add, at, std::move(n), term());
      } else if (accept('-')) {
        need_operand("'-'");
        n = make2(Expression::Op::Sub, at, std::move(n), term());
      } else {
        return n;
      }
    }
  }

  NodePtr term() {
    NodePtr n = unary();
    while (true) {
      skip();
      const std::size_t at = i_;
      if (i_ + 1 < t_.size() && t_[i_] == '*' && t_[i_ + 1] == '*') return n;  // '**' belongs to power()
      if (accept('*')) {
        need_operand("'*'");
        n = make2(Expression::Op::Mul, at, std::move(n), unary());
      } else if (accept('/')) {
        need_operand("'/'");
        n = make2(Expression::Op::Div, at, std::move(n), unary());
      } else {
        return n;
      }
    }
  }

  // Every recursion of the parser passes through unary(): parentheses and function
  // arguments (primary -> expr -> term -> unary), signs and the right side of '^'.
  struct Nesting {
    explicit Nesting(Parser& p) : p_(p) {
      if (++p_.nesting_ > Expression::kMaxNesting)
        p_.fail(p_.i_, "the expression nests deeper than " + std::to_string(Expression::kMaxNesting) +
                           " levels (parentheses, signs, powers and function calls); write it flatter");
    }
    ~Nesting() { --p_.nesting_; }
    Parser& p_;
  };

  NodePtr unary() {
    skip();
    const Nesting level(*this);
    const std::size_t at = i_;
    if (accept('-')) {
      need_operand("'-'");
      NodePtr n = make(Expression::Op::Neg, at);
      n->kids.push_back(unary());
      return n;
    }
    if (accept('+')) {
      need_operand("'+'");
      return unary();
    }
    return power();
  }

  NodePtr power() {
    NodePtr base = primary();
    skip();
    const std::size_t at = i_;
    bool pow = false;
    if (i_ + 1 < t_.size() && t_[i_] == '*' && t_[i_ + 1] == '*') {
      i_ += 2;
      pow = true;
    } else if (accept('^')) {
      pow = true;
    }
    if (!pow) return base;
    need_operand("'^'");
    return make2(Expression::Op::Pow, at, std::move(base), unary());
  }

  NodePtr primary() {
    skip();
    const std::size_t at = i_;
    if (i_ >= t_.size()) fail(i_, "expected a number, name or '(', got the end of the expression");
    const char ch = t_[i_];
    if (std::isdigit(static_cast<unsigned char>(ch)) || ch == '.') {
      const char* begin = t_.c_str() + i_;
      char* end = nullptr;
      const double x = std::strtod(begin, &end);
      if (end == begin) fail(at, "expected a number, got " + describe(at));
      i_ += static_cast<std::size_t>(end - begin);
      if (!std::isfinite(x)) fail(at, "the number is not finite");
      return make_const(x, at);
    }
    if (std::isalpha(static_cast<unsigned char>(ch)) || ch == '_') {
      std::size_t j = i_;
      while (j < t_.size() && (std::isalnum(static_cast<unsigned char>(t_[j])) || t_[j] == '_')) ++j;
      const std::string name = t_.substr(i_, j - i_);
      i_ = j;
      skip();
      if (i_ < t_.size() && t_[i_] == '(') return name == "sum" ? sum(at) : call(name, at);
      if (i_ < t_.size() && t_[i_] == '[') return element(name, at);
      for (auto k = indices_.rbegin(); k != indices_.rend(); ++k)
        if (k->first == name) return make_const(static_cast<double>(k->second), at);
      for (int k = 0; k < static_cast<int>(sym_.definitions.size()); ++k)
        if (sym_.definitions[static_cast<std::size_t>(k)].first == name) return definition(k, at);
      for (const auto& a : sym_.arrays)
        if (a.name == name)
          fail(at, "'" + name + "' is an array of " + std::to_string(a.size) + " entries; write " + name +
                       "[index], the index a whole number from 1 to " + std::to_string(a.size));
      for (const auto& a : sym_.constant_arrays)
        if (a.name == name)
          fail(at, "'" + name + "' is a list of " + std::to_string(a.values.size()) + " numbers; write " + name +
                       "[index], the index a whole number from 1 to " + std::to_string(a.values.size()));
      for (const auto& v : sym_.variables)
        if (v.name == name) {
          NodePtr n = make(Expression::Op::Var, at);
          n->block = v.block;
          n->index = v.index;
          return n;
        }
      for (const auto& c : sym_.constants)
        if (c.first == name) return make_const(c.second, at);
      if (name == "pi") return make_const(M_PI, at);
      for (const auto& f : functions())
        if (name == f.name) fail(i_, "expected '(' after the function name '" + name + "'");
      if (name == "sum") fail(i_, "expected '(' after 'sum': sum(i, first, last, term)");
      if (name == "t")
        fail(at, "unknown name 't': the time is a variable of a Lagrangian written on R^n, of the forces, the "
                 "constraints and the controls; an energy, a Hamiltonian, an invariant or a Lagrangian on S^2 or "
                 "SO(3) does not depend on it; known names: " +
                     sym_.known_names());
      fail(at, "unknown name '" + name + "'; known names: " + sym_.known_names());
    }
    if (accept('(')) {
      need_operand("'('");
      NodePtr n = expr();
      if (!accept(')')) fail(i_, "expected ')' to close the '(' at offset " + std::to_string(at) + ", got " + describe(i_));
      return n;
    }
    fail(at, "expected a number, name or '(', got " + describe(at));
  }

  // An expression that must come out as a whole number (a sum's bound, an index): it
  // may use constants and the indices of enclosing sums, nothing that varies.
  long whole_number(const char* what) {
    skip();
    const std::size_t at = i_;
    need_operand(what);
    // the nodes made here are gone once it is folded; they count toward a budget of
    // their own (an index may hold a sum, made again at each use)
    const std::size_t kept = defs_->nodes;
    NodePtr n = simplify(expr());
    defs_->folded += defs_->nodes - kept;
    defs_->nodes = kept;
    if (defs_->folded > 4 * Expression::kMaxNodes)
      fail(at, "the indices and bounds of sums take more than " + std::to_string(4 * Expression::kMaxNodes) +
                   " operations to compute; write them more simply");
    if (!n->is_const())
      fail(at, std::string("expected ") + what +
                   " made of numbers, parameters and sum indices only (a whole number known before the run)");
    const double x = n->c;
    if (!(x == std::floor(x)) || std::fabs(x) > 1e9)
      fail(at, std::string("expected ") + what + " to be a whole number, got " + std::to_string(x));
    return static_cast<long>(x);
  }

  // sum(i, first, last, term): the term for i = first, ..., last, added left to right.
  // The term's text is read once per value of i; with no values (last < first) it is
  // read once with range checks off, so that its syntax is still checked.
  NodePtr sum(std::size_t at) {
    accept('(');
    skip();
    const std::size_t name_at = i_;
    std::size_t j = i_;
    while (j < t_.size() && (std::isalnum(static_cast<unsigned char>(t_[j])) || t_[j] == '_')) ++j;
    if (j == i_ || std::isdigit(static_cast<unsigned char>(t_[i_])))
      fail(i_, "expected the name of the index after 'sum(', got " + describe(i_));
    const std::string index = t_.substr(i_, j - i_);
    i_ = j;
    if (known(index))
      fail(name_at, "the index name '" + index + "' is already taken (a variable, parameter, function or enclosing "
                    "index); choose another");
    if (!accept(',')) fail(i_, "expected ',' after the index name in sum(" + index + ", first, last, term)");
    const long first = whole_number("the first value of the index");
    if (!accept(',')) fail(i_, "expected ',' after the first value in sum(" + index + ", first, last, term)");
    const long last = whole_number("the last value of the index");
    if (!accept(',')) fail(i_, "expected ',' after the last value in sum(" + index + ", first, last, term)");
    need_operand("','");
    const std::size_t body = i_;
    NodePtr total;
    const bool empty = last < first;
    if (empty) ++dry_;
    for (long k = first; empty ? k == first : k <= last; ++k) {
      i_ = body;
      indices_.emplace_back(index, k);
      NodePtr term = expr();
      indices_.pop_back();
      total = total ? make2(Expression::Op::Add, at, std::move(total), std::move(term)) : std::move(term);
    }
    if (empty) {
      --dry_;
      total = make_const(0.0, at);
    }
    if (!accept(')')) fail(i_, "expected ')' to close sum(" + index + ", ...) opened at offset " + std::to_string(at) +
                                   ", got " + describe(i_));
    return total;
  }

  // name[index]: an entry of an array of variables or of constants.
  NodePtr element(const std::string& name, std::size_t at) {
    const ExpressionSymbols::Array* var = nullptr;
    const ExpressionSymbols::ConstantArray* con = nullptr;
    for (const auto& a : sym_.arrays)
      if (a.name == name) var = &a;
    for (const auto& a : sym_.constant_arrays)
      if (a.name == name) con = &a;
    if (!var && !con) {
      if (known(name)) fail(at, "'" + name + "' is not an array: it takes no index");
      fail(at, "unknown array '" + name + "'; known names: " + sym_.known_names());
    }
    accept('[');
    const std::size_t index_at = i_;
    const long k = whole_number("an index");
    if (!accept(']')) fail(i_, "expected ']' to close the index of '" + name + "', got " + describe(i_));
    const long size = var ? var->size : static_cast<long>(con->values.size());
    using B = ExpressionSymbols::Boundary;
    const B boundary = var ? var->boundary : B::none;
    long e = k;
    if (boundary == B::periodic) e = ((k - 1) % size + size) % size + 1;
    if (e >= 1 && e <= size) {
      if (con) return make_const(con->values[static_cast<std::size_t>(e - 1)], at);
      NodePtr n = make(Expression::Op::Var, at);
      n->block = var->block;
      n->index = var->offset + static_cast<int>(e - 1);
      return n;
    }
    if (boundary == B::fixed && (e == 0 || e == size + 1)) return make_const(0.0, at);
    if (dry_ > 0) return make_const(0.0, at);  // inside an empty sum: never evaluated
    std::string range = "1 to " + std::to_string(size);
    if (boundary == B::fixed) range = "0 to " + std::to_string(size + 1) + " (0 and " + std::to_string(size + 1) +
                                      " are the fixed ends)";
    fail(index_at, "index " + std::to_string(k) + " of '" + name + "' is outside " + range +
                       (boundary == B::none && var ? "; an array of coordinates may declare fixed or periodic ends" : ""));
  }

  // A use of definition k: its value, read back from its slot (Var of block 3); the
  // definition is parsed at its first use, seeing the definitions before it only.
  NodePtr definition(int k, std::size_t at) {
    const auto& [name, text] = sym_.definitions[static_cast<std::size_t>(k)];
    if (k >= visible_)
      fail(at, "'" + name + "' is defined after the definition that uses it; a definition may use the ones "
                            "before it only");
    if (dry_ > 0) return make_const(0.0, at);  // inside a sum with no terms: never evaluated
    int& slot = defs_->slot[static_cast<std::size_t>(k)];
    if (slot == -1) {
      NodePtr tree;
      try {
        Parser sub(text, sym_, defs_, k);
        sub.nesting_ = nesting_;  // one limit for the whole recursion
        tree = simplify(sub.parse());
      } catch (const ExpressionError& e) {
        fail(at, "in the definition of '" + name + "' (character " + std::to_string(e.offset + 1) + " of \"" + text +
                     "\"): " + e.what());
      }
      if (tree->is_const()) {  // a number: used as one (folded, x^k a whole power)
        slot = -2;
        defs_->value[static_cast<std::size_t>(k)] = tree->c;
      } else {
        if (static_cast<int>(defs_->trees.size()) >= Expression::kMaxDefinitions)
          fail(at, "more than " + std::to_string(Expression::kMaxDefinitions) + " definitions are used");
        slot = static_cast<int>(defs_->trees.size());
        defs_->trees.push_back(std::move(tree));
      }
    }
    if (slot == -2) return make_const(defs_->value[static_cast<std::size_t>(k)], at);
    NodePtr n = make(Expression::Op::Var, at);
    n->block = 3;
    n->index = slot;
    return n;
  }

  // Whether a name already means something here.
  bool known(const std::string& name) const {
    if (name == "pi" || name == "sum" || name == "t") return true;
    for (const auto& d : sym_.definitions)
      if (d.first == name) return true;
    for (const auto& f : functions())
      if (name == f.name) return true;
    for (const auto& v : sym_.variables)
      if (v.name == name) return true;
    for (const auto& c : sym_.constants)
      if (c.first == name) return true;
    for (const auto& a : sym_.arrays)
      if (a.name == name) return true;
    for (const auto& a : sym_.constant_arrays)
      if (a.name == name) return true;
    for (const auto& k : indices_)
      if (k.first == name) return true;
    return false;
  }

  NodePtr call(const std::string& name, std::size_t at) {
    const Function* f = nullptr;
    for (const auto& g : functions())
      if (name == g.name) f = &g;
    if (!f) fail(at, "unknown function '" + name + "'; known functions: " + function_names());
    accept('(');
    std::vector<NodePtr> args;
    need_operand("'('");
    args.push_back(expr());
    while (accept(',')) {
      need_operand("','");
      args.push_back(expr());
    }
    if (!accept(')')) fail(i_, "expected ',' or ')' in the arguments of " + name + ", got " + describe(i_));
    if (static_cast<int>(args.size()) != f->arity)
      fail(at, "function '" + name + "' takes " + std::to_string(f->arity) + " argument" +
                   (f->arity > 1 ? "s" : "") + ", got " + std::to_string(args.size()));
    NodePtr n = make(f->op, at);
    n->kids = std::move(args);
    return n;
  }

  const std::string& t_;
  const ExpressionSymbols& sym_;
  Definitions own_;
  Definitions* defs_;  // shared with the parsers of the definitions
  int visible_;        // the definitions this text may use: 0 .. visible_ - 1
  std::size_t i_ = 0;
  int nesting_ = 0;
  std::vector<std::pair<std::string, long>> indices_;  // the enclosing sums' indices and values
  int dry_ = 0;                                     // > 0: inside a sum with no terms
};

// Constant folding and strength reduction of one node whose children are simplified.
inline NodePtr simplify_node(NodePtr n) {
  using O = Expression::Op;
  if (n->kids.empty()) return n;
  bool all_const = true;
  for (const auto& k : n->kids) all_const = all_const && k->is_const();
  if (all_const) {
    Expression::Instr in{};  // the node's own constant operand or power (x + c, x^n, ...)
    in.c = n->c;
    in.index = n->index;
    double x;
    if (n->kids.size() == 1)
      x = Expression::unary<double>(n->op, n->kids[0]->c, in);
    else
      x = n->op == O::Pow ? std::pow(n->kids[0]->c, n->kids[1]->c)
                          : Expression::binary<double>(n->op, n->kids[0]->c, n->kids[1]->c);
    if (!std::isfinite(x))
      throw ExpressionError(n->pos, std::string("this operation on constants gives ") + (std::isnan(x) ? "nan" : "inf") +
                                        " (an overflow, a division by zero or a value outside a function's "
                                        "domain); expected finite values");
    n->kids.clear();
    n->op = O::Const;
    n->c = x;
    return n;
  }
  if (n->kids.size() != 2) return n;
  NodePtr& a = n->kids[0];
  NodePtr& b = n->kids[1];
  auto to_unary = [&](O op, NodePtr keep, double c) {
    n->op = op;
    n->c = c;
    n->kids.clear();
    n->kids.push_back(std::move(keep));
    return std::move(n);
  };
  if (b->is_const()) {
    const double c = b->c;
    switch (n->op) {
      case O::Add: return to_unary(O::AddC, std::move(a), c);
      case O::Sub: return to_unary(O::AddC, std::move(a), -c);
      case O::Mul: return to_unary(O::MulC, std::move(a), c);
      case O::Div: return to_unary(O::DivC, std::move(a), c);
      case O::Pow:
        if (c == std::floor(c) && std::fabs(c) <= 64) {
          NodePtr out = to_unary(O::PowI, std::move(a), 0.0);
          out->index = static_cast<int>(c);
          return out;
        }
        if (c == 0.5) {
          n->op = O::Sqrt;
          n->kids.pop_back();
          return n;
        }
        return to_unary(O::PowC, std::move(a), c);
      default: return n;
    }
  }
  if (a->is_const()) {
    const double c = a->c;
    switch (n->op) {
      case O::Add: return to_unary(O::AddC, std::move(b), c);
      case O::Sub: return to_unary(O::RSubC, std::move(b), c);
      case O::Mul: return to_unary(O::MulC, std::move(b), c);
      case O::Div: return to_unary(O::RDivC, std::move(b), c);
      default: return n;
    }
  }
  return n;
}

// Constant folding and strength reduction, bottom up (a post-order walk with a work
// list: the tree may be as deep as a sum is long).
inline NodePtr simplify(NodePtr root) {
  struct Item {
    NodePtr* slot;
    bool expanded;
  };
  std::vector<Item> work{{&root, false}};
  while (!work.empty()) {
    Item& top = work.back();
    NodePtr* slot = top.slot;
    if (!top.expanded) {
      top.expanded = true;  // before the push below moves `top`
      for (auto& k : (*slot)->kids) work.push_back({&k, false});
      continue;
    }
    work.pop_back();
    *slot = simplify_node(std::move(*slot));
  }
  return root;
}

// Postfix emission (post-order with a work list); returns the stack depth the tree
// needs: a node with children needing da and db needs max(da, 1 + db).
inline int emit(const Node& root, std::vector<Expression::Instr>& tape) {
  using O = Expression::Op;
  struct Item {
    const Node* n;
    bool expanded;
  };
  std::vector<Item> work{{&root, false}};
  std::vector<int> depths;
  while (!work.empty()) {
    Item& top = work.back();
    const Node& n = *top.n;
    if (!top.expanded) {
      top.expanded = true;
      for (auto k = n.kids.rbegin(); k != n.kids.rend(); ++k) work.push_back({k->get(), false});
      continue;
    }
    work.pop_back();
    Expression::Instr in{};
    in.op = n.op;
    in.c = n.c;
    if (n.op == O::Var) {
      in.block = static_cast<std::int8_t>(n.block);
      in.index = n.index;
    }
    if (n.op == O::PowI) in.index = n.index;
    int depth = 1;
    if (n.kids.size() == 1) {
      depth = depths.back();
      depths.pop_back();
    } else if (n.kids.size() == 2) {
      const int db = depths.back();
      depths.pop_back();
      const int da = depths.back();
      depths.pop_back();
      depth = std::max(da, 1 + db);
    }
    tape.push_back(in);
    depths.push_back(depth);
  }
  return depths.back();
}

}  // namespace expression_detail

namespace expression_detail {

// The top-level additive terms of `root`, each with the factor that the sums, signs and
// constant factors above it give it, and the sum of the constant terms (a work list: a
// flat sum is a tree as deep as it is long).
struct Term {
  NodePtr* slot;
  double scale;
};
// A node of no children (a constant, or an operation whose kids the caller adds).
inline NodePtr make_node(Expression::Op op, double c, std::size_t pos = 0) {
  auto n = std::make_unique<Node>();
  n->op = op;
  n->pos = pos;
  n->c = c;
  return n;
}
// sum += scale * x, a tree of Add nodes (sum null: x alone)
inline void add_scaled(NodePtr& sum, NodePtr x, double scale) {
  using O = Expression::Op;
  if (scale != 1.0) {
    NodePtr m = make_node(O::MulC, scale);
    m->kids.push_back(std::move(x));
    x = std::move(m);
  }
  if (!sum) {
    sum = std::move(x);
    return;
  }
  NodePtr a = make_node(O::Add, 0.0);
  a->kids.push_back(std::move(sum));
  a->kids.push_back(std::move(x));
  sum = std::move(a);
}
inline std::vector<Term> additive_terms(NodePtr& root, double& constant_term) {
  using O = Expression::Op;
  std::vector<Term> terms, work{{&root, 1.0}};
  // the constants added with Neumaier's compensated sum (a long sum of constants folds
  // to its value rounded once, not once per term)
  double sum = 0.0, carry = 0.0;
  auto add_constant = [&](double c) {
    const double t = sum + c;
    carry += std::fabs(sum) >= std::fabs(c) ? (sum - t) + c : (c - t) + sum;
    sum = t;
  };
  while (!work.empty()) {
    const Term t = work.back();
    work.pop_back();
    Node& n = **t.slot;
    switch (n.op) {
      case O::Add: work.push_back({&n.kids[1], t.scale}); work.push_back({&n.kids[0], t.scale}); break;
      case O::Sub: work.push_back({&n.kids[1], -t.scale}); work.push_back({&n.kids[0], t.scale}); break;
      case O::Neg: work.push_back({&n.kids[0], -t.scale}); break;
      case O::MulC: work.push_back({&n.kids[0], t.scale * n.c}); break;
      case O::DivC: work.push_back({&n.kids[0], t.scale / n.c}); break;
      case O::AddC: add_constant(t.scale * n.c); work.push_back({&n.kids[0], t.scale}); break;
      case O::RSubC: add_constant(t.scale * n.c); work.push_back({&n.kids[0], -t.scale}); break;
      case O::Const: add_constant(t.scale * n.c); break;
      default: terms.push_back(t); break;
    }
  }
  constant_term = sum + carry;
  return terms;
}

// Whether an instruction carries a constant (its value may differ between the terms
// of a block).
inline bool has_constant(Expression::Op op) {
  using O = Expression::Op;
  return op == O::Const || op == O::AddC || op == O::MulC || op == O::DivC || op == O::RSubC || op == O::RDivC ||
         op == O::PowC;
}

// Emits `root` into `tape`, with its top-level terms of one shape grouped into blocks
// (Expression::Block) where a group has at least kMinBlock terms; otherwise as emit()
// does. Returns the stack depth.
inline int emit_blocked(NodePtr& root, std::vector<Expression::Instr>& tape, std::vector<Expression::Block>& blocks) {
  using O = Expression::Op;
  using Instr = Expression::Instr;
  double constant_term = 0.0;
  std::vector<Term> terms = additive_terms(root, constant_term);
  if (static_cast<int>(terms.size()) < Expression::kMinBlock) return emit(*root, tape);
  // each term as its own tape, times its factor; its shape is the operations without
  // the variables' indices and the constants
  std::vector<std::vector<Instr>> tapes(terms.size());
  std::vector<int> depths(terms.size());
  std::vector<std::string> shapes(terms.size());
  std::map<std::string, std::vector<std::size_t>> groups;
  std::vector<std::string> order;  // shapes in order of first appearance
  for (std::size_t t = 0; t < terms.size(); ++t) {
    depths[t] = emit(**terms[t].slot, tapes[t]);
    Instr scale{};
    scale.op = O::MulC;
    scale.c = terms[t].scale;
    tapes[t].push_back(scale);
    std::string& key = shapes[t];
    for (const Instr& in : tapes[t]) {
      key += static_cast<char>(in.op);
      key += static_cast<char>(in.block);
      if (in.op == O::PowI) key += std::to_string(in.index) + ",";
      // A term that reads a definition (block 3) stays on the tape, in a group of its
      // own: a block's derivative program reads only q and v (DerivativeProgramBuilder::
      // block_program), so one such block would leave the whole text without a program
      // (16 squared velocities written as definitions, scissor_lift.toml).
      if (in.op == O::Var && in.block == 3) key += "#" + std::to_string(t);
    }
    auto& g = groups[key];
    if (g.empty()) order.push_back(key);
    g.push_back(t);
  }
  bool any = false;
  for (const auto& [key, g] : groups) any = any || static_cast<int>(g.size()) >= Expression::kMinBlock;
  if (!any) return emit(*root, tape);
  int depth = 1;
  bool first = true;
  auto add = [&](int d) {  // a term pushed: add it to what is below
    depth = std::max(depth, first ? d : 1 + d);
    if (!first) {
      Instr plus{};
      plus.op = O::Add;
      tape.push_back(plus);
    }
    first = false;
  };
  // groups too small for a block stay on the tape; the others go into one block per
  // number of terms: sum_k (A_k + B_k) = sum_k A_k + sum_k B_k for any pairing of the
  // terms, and where the groups come from one sum the pairs share subexpressions (the
  // bond length of a chain in each power of it), computed once (below)
  std::map<std::size_t, std::vector<const std::vector<std::size_t>*>> by_count;
  std::vector<std::size_t> counts;
  for (const std::string& key : order) {
    const std::vector<std::size_t>& g = groups[key];
    if (static_cast<int>(g.size()) < Expression::kMinBlock) {
      for (std::size_t t : g) {
        std::vector<Instr>& mine = tapes[t];
        if (mine.back().c == 1.0) mine.pop_back();  // a factor of 1
        tape.insert(tape.end(), mine.begin(), mine.end());
        add(depths[t]);
      }
      continue;
    }
    auto& bucket = by_count[g.size()];
    if (bucket.empty()) counts.push_back(g.size());
    bucket.push_back(&g);
  }
  for (std::size_t m : counts) {
    Expression::Block b;
    b.terms = static_cast<int>(m);
    // one body for the bucket, equal instructions merged: the same operation on the
    // same operands with the same indices and constants in every term
    std::map<std::vector<std::int32_t>, std::int32_t> index_ids;
    std::map<std::vector<double>, std::int32_t> constant_ids;
    std::map<std::tuple<int, int, int, double, std::int32_t, std::int32_t, std::int32_t, std::int32_t>, std::int32_t>
        seen;
    std::vector<std::int32_t> index_of, constant_of;  // per body instruction: ids (-1: none)
    std::vector<std::vector<std::int32_t>> index_lists;
    std::vector<std::vector<double>> constant_lists;
    auto push = [&](Instr in, std::int32_t a, std::int32_t bb, std::vector<std::int32_t> ix,
                    std::vector<double> cs) -> std::int32_t {
      std::int32_t ixid = -1, cid = -1;
      if (!ix.empty()) {
        auto [it, fresh] = index_ids.emplace(ix, static_cast<std::int32_t>(index_lists.size()));
        if (fresh) index_lists.push_back(std::move(ix));
        ixid = it->second;
      }
      if (!cs.empty()) {
        auto [it, fresh] = constant_ids.emplace(cs, static_cast<std::int32_t>(constant_lists.size()));
        if (fresh) constant_lists.push_back(std::move(cs));
        cid = it->second;
      }
      const auto key = std::make_tuple(int(in.op), int(in.block), in.op == O::Var ? 0 : int(in.index),
                                       cid >= 0 ? 0.0 : in.c, a, bb, ixid, cid);
      auto [it, fresh] = seen.emplace(key, static_cast<std::int32_t>(b.body.size()));
      if (fresh) {
        b.body.push_back(in);
        b.arg_a.push_back(a);
        b.arg_b.push_back(bb);
        index_of.push_back(ixid);
        constant_of.push_back(cid);
      }
      return it->second;
    };
    std::int32_t total = -1;
    for (const std::vector<std::size_t>* g : by_count[m]) {
      const std::vector<Instr>& shape = tapes[g->front()];
      std::vector<std::int32_t> remap(shape.size()), stack;
      for (std::size_t j = 0; j < shape.size(); ++j) {
        const Instr& in = shape[j];
        std::vector<std::int32_t> ix;
        std::vector<double> cs;
        if (in.op == O::Var) {
          for (std::size_t t : *g) ix.push_back(tapes[t][j].index);
        } else if (has_constant(in.op)) {
          bool varies = false;
          for (std::size_t t : *g) varies = varies || tapes[t][j].c != in.c;
          if (varies)
            for (std::size_t t : *g) cs.push_back(tapes[t][j].c);
        }
        std::int32_t a = -1, bb = -1;
        if (in.op == O::Const || in.op == O::Var) {
        } else if (in.op == O::Add || in.op == O::Sub || in.op == O::Mul || in.op == O::Div || in.op == O::Pow ||
                   in.op == O::Atan2) {
          bb = stack.back();
          stack.pop_back();
          a = stack.back();
          stack.pop_back();
        } else {
          a = stack.back();
          stack.pop_back();
        }
        remap[j] = push(in, a, bb, std::move(ix), std::move(cs));
        stack.push_back(remap[j]);
      }
      if (total < 0) {
        total = remap.back();
      } else {
        Instr plus{};
        plus.op = O::Add;
        total = push(plus, total, remap.back(), {}, {});
      }
    }
    // the sum must be the last instruction (block_forward adds up the last column)
    if (total != static_cast<std::int32_t>(b.body.size()) - 1) {
      Instr one{};
      one.op = O::MulC;
      one.c = 1.0;
      b.body.push_back(one);
      b.arg_a.push_back(total);
      b.arg_b.push_back(-1);
      index_of.push_back(-1);
      constant_of.push_back(-1);
    }
    b.index.assign(b.body.size(), {});
    b.c.assign(b.body.size(), {});
    for (std::size_t j = 0; j < b.body.size(); ++j) {
      if (index_of[j] >= 0) b.index[j] = index_lists[static_cast<std::size_t>(index_of[j])];
      if (constant_of[j] >= 0) b.c[j] = constant_lists[static_cast<std::size_t>(constant_of[j])];
    }
    Instr in{};
    in.op = O::Block;
    in.index = static_cast<std::int32_t>(blocks.size());
    blocks.push_back(std::move(b));
    tape.push_back(in);
    add(1);
  }
  if (constant_term != 0.0) {
    Instr c{};
    c.op = O::AddC;
    c.c = constant_term;
    tape.push_back(c);
  }
  return depth;
}

}  // namespace expression_detail

namespace expression_detail {

// The definitions (simplified when parsed) in slot order, each followed by the Let that
// stores it (a definition's own definitions have lower slots: they come first).
// Returns the depth.
inline int emit_definitions(const Definitions& d, std::vector<Expression::Instr>& tape) {
  int depth = 0;
  for (std::size_t k = 0; k < d.trees.size(); ++k) {
    depth = std::max(depth, emit(*d.trees[k], tape));
    Expression::Instr let{};
    let.op = Expression::Op::Let;
    let.index = static_cast<std::int32_t>(k);
    tape.push_back(let);
  }
  return depth;
}

}  // namespace expression_detail

inline Expression Expression::parse(const std::string& text, const ExpressionSymbols& symbols, bool blocks) {
  expression_detail::Parser p(text, symbols);
  expression_detail::NodePtr root = expression_detail::simplify(p.parse());
  Expression e;
  e.text_ = text;
  const int defs = expression_detail::emit_definitions(p.definitions(), e.tape_);
  e.definitions_ = static_cast<int>(p.definitions().trees.size());
  e.depth_ = blocks ? expression_detail::emit_blocked(root, e.tape_, e.blocks_) : expression_detail::emit(*root, e.tape_);
  e.depth_ = std::max(e.depth_, defs);
  require_depth(e.depth_);
  return e;
}

inline void Expression::require_depth(int depth) {
  if (depth > kMaxStack)
    throw ExpressionError(0, "the expression nests too deeply (needs a stack of " + std::to_string(depth) +
                                 ", at most " + std::to_string(kMaxStack) + "); write it as a flatter sum");
}

namespace expression_detail {

// The nodes under `root` in post-order (children before parents), without recursion.
inline std::vector<const Node*> post_order(const Node& root) {
  std::vector<const Node*> out;
  std::vector<std::pair<const Node*, bool>> work{{&root, false}};
  while (!work.empty()) {
    auto [n, expanded] = work.back();
    work.pop_back();
    if (expanded) {
      out.push_back(n);
      continue;
    }
    work.push_back({n, true});
    for (auto k = n->kids.rbegin(); k != n->kids.rend(); ++k) work.push_back({k->get(), false});
  }
  return out;
}

// The degree in block 1 of the subtree at each node (VelocitySplit): -1 when it is not
// homogeneous, with whether block 0 appears and which block-1 variable (-1: none,
// -2: more than one).
struct Degree {
  int degree = 0;
  bool uses_q = false;
  int velocity = -1;
};
inline Degree term_degree(const Node& term, const std::vector<Degree>& definitions) {
  using O = Expression::Op;
  std::vector<Degree> stack;
  for (const Node* n : post_order(term)) {
    Degree d;
    const std::size_t k = n->kids.size();
    std::vector<Degree> kids(stack.end() - static_cast<std::ptrdiff_t>(k), stack.end());
    stack.resize(stack.size() - k);
    for (const Degree& c : kids) {
      d.uses_q = d.uses_q || c.uses_q;
      if (c.velocity != -1) d.velocity = (d.velocity == -1 || d.velocity == c.velocity) ? c.velocity : -2;
    }
    auto all_zero = [&] {
      for (const Degree& c : kids)
        if (c.degree != 0) return false;
      return true;
    };
    switch (n->op) {
      case O::Const: d.degree = 0; break;
      case O::Var:
        if (n->block == 3) {  // a definition: what its text is
          const Degree& e = definitions[static_cast<std::size_t>(n->index)];
          d.degree = e.degree;
          d.uses_q = e.uses_q;
          d.velocity = e.velocity;
          break;
        }
        d.degree = n->block == 1 ? 1 : 0;
        d.uses_q = n->block == 0;
        if (n->block == 1) d.velocity = n->index;
        break;
      case O::Neg: case O::MulC: case O::DivC: d.degree = kids[0].degree; break;
      case O::Add: case O::Sub: d.degree = kids[0].degree == kids[1].degree ? kids[0].degree : -1; break;
      case O::Mul: d.degree = kids[0].degree < 0 || kids[1].degree < 0 ? -1 : kids[0].degree + kids[1].degree; break;
      case O::Div: d.degree = kids[1].degree == 0 ? kids[0].degree : -1; break;
      case O::PowI:
        d.degree = kids[0].degree == 0 ? 0 : kids[0].degree < 0 || n->index < 0 ? -1 : n->index * kids[0].degree;
        break;
      default: d.degree = all_zero() ? 0 : -1; break;  // x + c, c - x, c / x, functions, powers
    }
    stack.push_back(d);
  }
  return stack.back();
}

}  // namespace expression_detail

inline VelocitySplit Expression::split_velocity(const std::string& text, const ExpressionSymbols& symbols,
                                                Expression* kinetic, Expression* potential) {
  using namespace expression_detail;
  using O = Op;
  Parser p(text, symbols);
  NodePtr root = simplify(p.parse());
  Definitions& defs = p.definitions();
  std::vector<Degree> def_degrees;  // by slot (a definition's definitions first)
  for (const auto& tree : defs.trees) def_degrees.push_back(term_degree(*tree, def_degrees));
  double constant_term = 0.0;
  std::vector<Term> terms = additive_terms(root, constant_term);
  VelocitySplit out;
  std::vector<Term> kin, pot;
  bool diagonal = true;
  for (const Term& t : terms) {
    const Degree d = term_degree(**t.slot, def_degrees);
    if (d.degree == 0) {
      ++out.potential_terms;
      pot.push_back(t);
    } else if (d.degree == 2 && !d.uses_q) {
      ++out.kinetic_terms;
      kin.push_back(t);
      diagonal = diagonal && d.velocity >= 0;
    } else if (d.degree == 2) {
      ++out.mechanical_terms;
    } else {
      ++out.other_terms;
    }
  }
  out.quadratic = out.other_terms == 0;
  out.constant_mass = out.quadratic && out.mechanical_terms == 0;
  out.diagonal = out.constant_mass && diagonal;
  if (!out.constant_mass) return out;
  // the two sums, as trees of their own (the terms moved out of `root`)
  auto assemble = [&](std::vector<Term>& group, double c, const char* what, Expression* e) {
    if (!e) return;
    NodePtr sum;
    for (Term& t : group) add_scaled(sum, std::move(*t.slot), t.scale);
    if (!sum) sum = make_node(O::Const, c);
    else if (c != 0.0) {
      NodePtr a = make_node(O::AddC, c);
      a->kids.push_back(std::move(sum));
      sum = std::move(a);
    }
    Expression r;
    r.text_ = std::string(what) + " terms of: " + text;
    r.depth_ = emit_definitions(defs, r.tape_);  // every definition, each part its own copy
    r.definitions_ = static_cast<int>(defs.trees.size());
    r.depth_ = std::max(r.depth_, emit_blocked(sum, r.tape_, r.blocks_));
    require_depth(r.depth_);
    *e = std::move(r);
  };
  assemble(kin, 0.0, "the kinetic", kinetic);
  assemble(pot, constant_term, "the potential", potential);
  return out;
}

namespace expression_detail {

// A copy of `term` with the block-1 variables (the velocities) replaced by the constants
// e[index], products and quotients with a zero factor folded to zero and zero addends
// dropped (for the finite values of the other variables that a mass matrix is formed
// at, these are the values the operations would give), then simplified. `budget`: the
// nodes still allowed (Expression::kMaxNodes), decreased; null when it runs out.
inline NodePtr substitute_velocities(const Node& term, const double* e, std::size_t& budget) {
  using O = Expression::Op;
  std::vector<NodePtr> stack;
  auto constant = [](std::size_t pos, double c) { return make_node(O::Const, c, pos); };
  auto zero = [](const NodePtr& n) { return n->is_const() && n->c == 0.0; };
  for (const Node* src : post_order(term)) {
    if (budget == 0) return nullptr;
    --budget;
    std::vector<NodePtr> kids(src->kids.size());
    for (std::size_t k = kids.size(); k-- > 0;) {
      kids[k] = std::move(stack.back());
      stack.pop_back();
    }
    if (src->op == O::Var && src->block == 1) {
      stack.push_back(constant(src->pos, e[src->index]));
      continue;
    }
    const bool zero_product =
        ((src->op == O::Mul) && (zero(kids[0]) || zero(kids[1]))) ||
        ((src->op == O::Div || src->op == O::DivC || src->op == O::Neg) && zero(kids[0])) ||
        (src->op == O::MulC && (zero(kids[0]) || src->c == 0.0)) ||
        (src->op == O::PowI && src->index > 0 && zero(kids[0]));
    if (zero_product) {
      stack.push_back(constant(src->pos, 0.0));
      continue;
    }
    if ((src->op == O::Add || src->op == O::Sub) && zero(kids[1])) {
      stack.push_back(std::move(kids[0]));
      continue;
    }
    if (src->op == O::Add && zero(kids[0])) {
      stack.push_back(std::move(kids[1]));
      continue;
    }
    auto n = std::make_unique<Node>();
    n->op = src->op == O::Sub && zero(kids[0]) ? O::Neg : src->op;
    n->pos = src->pos;
    n->c = src->c;
    n->block = src->block;
    n->index = src->index;
    if (src->op == O::Sub && zero(kids[0]))
      n->kids.push_back(std::move(kids[1]));
    else
      n->kids = std::move(kids);
    stack.push_back(std::move(n));
  }
  return simplify(std::move(stack.back()));
}

}  // namespace expression_detail

inline bool Expression::split_mass(const std::string& text, const ExpressionSymbols& symbols, int n,
                                   std::vector<Expression>& mass, Expression& potential) {
  using namespace expression_detail;
  using O = Op;
  if (n < 1 || n > kMaxMassDim) return false;
  Parser p(text, symbols);
  NodePtr root = simplify(p.parse());
  Definitions& defs = p.definitions();
  // past the parse, an ExpressionError (a term folded to a value that is not finite)
  // means no split: the caller forms M from gradients
  try {
    std::vector<Degree> def_degrees;
    for (const auto& tree : defs.trees) {
      def_degrees.push_back(term_degree(*tree, def_degrees));
      if (def_degrees.back().degree != 0) return false;  // a definition in the velocities
    }
    double constant_term = 0.0;
    std::vector<Term> terms = additive_terms(root, constant_term);
    const auto entry = [n](int i, int j) { return i * n - i * (i - 1) / 2 + (j - i); };  // i <= j
    std::vector<NodePtr> sums(static_cast<std::size_t>(n * (n + 1) / 2));
    auto add = [](NodePtr& sum, NodePtr x, double scale) {  // zeros (folded products) left out
      if (!(x->is_const() && x->c == 0.0)) add_scaled(sum, std::move(x), scale);
    };
    std::size_t budget = kMaxNodes;
    std::vector<Term> pot;
    std::vector<double> e(static_cast<std::size_t>(n), 0.0);
    for (const Term& t : terms) {
      const Degree d = term_degree(**t.slot, def_degrees);
      if (d.degree == 0) {
        pot.push_back(t);
        continue;
      }
      if (d.degree != 2) return false;
      std::vector<int> used;  // the velocities the term reads
      for (const Node* x : post_order(**t.slot))
        if (x->op == O::Var && x->block == 1 && std::find(used.begin(), used.end(), x->index) == used.end())
          used.push_back(x->index);
      std::sort(used.begin(), used.end());
      std::vector<NodePtr> at_unit(used.size());  // t(e_i)
      for (std::size_t a = 0; a < used.size(); ++a) {
        e[static_cast<std::size_t>(used[a])] = 1.0;
        at_unit[a] = substitute_velocities(**t.slot, e.data(), budget);
        e[static_cast<std::size_t>(used[a])] = 0.0;
        if (!at_unit[a]) return false;
      }
      // a term in two or more velocities is read off only where t(e_i) folds to zero for
      // each of them (c(q) v_i v_j, not (v_i + v_j)^2 c(q)): then M_ij = t(e_i + e_j)
      // exactly, where the difference t(e_i + e_j) - t(e_i) - t(e_j) could cancel
      if (used.size() > 1)
        for (const NodePtr& x : at_unit)
          if (!(x->is_const() && x->c == 0.0)) return false;
      for (std::size_t a = 0; a < used.size(); ++a)
        for (std::size_t b = a + 1; b < used.size(); ++b) {
          e[static_cast<std::size_t>(used[a])] = e[static_cast<std::size_t>(used[b])] = 1.0;
          NodePtr both = substitute_velocities(**t.slot, e.data(), budget);
          e[static_cast<std::size_t>(used[a])] = e[static_cast<std::size_t>(used[b])] = 0.0;
          if (!both) return false;
          add(sums[static_cast<std::size_t>(entry(used[a], used[b]))], std::move(both), t.scale);
        }
      for (std::size_t a = 0; a < used.size(); ++a)
        add(sums[static_cast<std::size_t>(entry(used[a], used[a]))], std::move(at_unit[a]), 2.0 * t.scale);
    }
    auto emit_sum = [&](NodePtr sum, const std::string& what) {
      Expression r;
      r.text_ = what + " of: " + text;
      if (!sum) sum = make_node(O::Const, 0.0);
      sum = simplify(std::move(sum));
      // the definitions this sum reads, and theirs (a definition reads lower slots only)
      std::vector<bool> needed(defs.trees.size(), false);
      auto mark = [&](const Node& tree) {
        for (const Node* x : post_order(tree))
          if (x->op == O::Var && x->block == 3) needed[static_cast<std::size_t>(x->index)] = true;
      };
      mark(*sum);
      for (std::size_t k = defs.trees.size(); k-- > 0;)
        if (needed[k]) mark(*defs.trees[k]);
      for (std::size_t k = 0; k < defs.trees.size(); ++k)
        if (needed[k]) {
          r.depth_ = std::max(r.depth_, emit(*defs.trees[k], r.tape_));
          Instr let{};
          let.op = O::Let;
          let.index = static_cast<std::int32_t>(k);
          r.tape_.push_back(let);
          r.definitions_ = static_cast<int>(k) + 1;  // the slots (gradient() zeroes their adjoints)
        }
      r.depth_ = std::max(r.depth_, emit_blocked(sum, r.tape_, r.blocks_));
      require_depth(r.depth_);
      return r;
    };
    std::vector<Expression> entries;
    for (int i = 0; i < n; ++i)
      for (int j = i; j < n; ++j)
        entries.push_back(emit_sum(std::move(sums[static_cast<std::size_t>(entry(i, j))]),
                                   "M(q) entry (" + std::to_string(i) + ", " + std::to_string(j) + ")"));
    NodePtr u;  // (a term of degree 0 may still read a velocity, as v^0: set to 0 here)
    std::fill(e.begin(), e.end(), 0.0);
    for (Term& t : pot) {
      NodePtr x = substitute_velocities(**t.slot, e.data(), budget);
      if (!x) return false;
      add(u, std::move(x), t.scale);
    }
    if (constant_term != 0.0) add(u, make_node(O::Const, constant_term), 1.0);
    potential = emit_sum(std::move(u), "the potential terms");
    mass = std::move(entries);
    return true;
  } catch (const ExpressionError&) {
    return false;
  }
}

}  // namespace dvm
