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
  std::vector<Variable> variables;
  std::vector<std::pair<std::string, double>> constants;  // parameters, in order

  // Every known name, variables then constants, for "unknown name" messages.
  std::string known_names() const {
    std::string out;
    for (const auto& v : variables) out += (out.empty() ? "" : ", ") + v.name;
    for (const auto& c : constants) out += (out.empty() ? "" : ", ") + c.first;
    out += (out.empty() ? "" : ", ") + std::string("pi");
    return out;
  }
};

class Expression {
 public:
  // Largest stack depth the evaluator supports (checked at parse time).
  static constexpr int kMaxStack = 24;
  // Longest text and deepest nesting the parser accepts (see the header comment).
  static constexpr std::size_t kMaxText = std::size_t{1} << 20;
  static constexpr int kMaxNesting = 256;

  enum class Op : std::uint8_t {
    Const, Var,
    Neg, Add, Sub, Mul, Div,
    AddC, MulC, DivC, RSubC, RDivC,  // x + c, x * c, x / c, c - x, c / x
    PowI, PowC, Pow,                  // x^n (integer n), x^c, x^y
    Sin, Cos, Tan, Asin, Acos, Atan, Exp, Log, Sqrt, Cbrt, Abs, Sinh, Cosh, Tanh,
    Atan2,
  };
  struct Instr {
    Op op;
    std::int8_t block = 0;
    std::int32_t index = 0;  // variable index, or the integer power
    double c = 0.0;          // constant operand
  };

  Expression() = default;

  // Parses `text`; throws ExpressionError.
  static Expression parse(const std::string& text, const ExpressionSymbols& symbols);

  const std::string& text() const { return text_; }
  const std::vector<Instr>& tape() const { return tape_; }
  int stack_depth() const { return depth_; }
  // Whether variable (block, index) appears in the expression after folding.
  bool uses(int block, int index) const {
    for (const auto& in : tape_)
      if (in.op == Op::Var && in.block == block && in.index == index) return true;
    return false;
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
  // Tapes longer than kMaxTape are refused (returns false): use forward mode then.
  static constexpr int kMaxTape = 256;
  template <class T>
  bool gradient(const T* b0, const T* b1, T* g0, T* g1) const;

  // One operation on scalars of any type: the same code folds constants (T = double)
  // and evaluates (any T).
  template <class T>
  static T unary(Op op, const T& x, const Instr& in);
  template <class T>
  static T binary(Op op, const T& x, const T& y);

 private:
  std::string text_;
  std::vector<Instr> tape_;
  int depth_ = 0;
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
  const T* blocks[3] = {b0, b1, b2};
  int top = -1;
  for (const Instr& in : tape_) {
    switch (in.op) {
      case Op::Const: new (&s[++top]) T(constant<T>(in.c)); break;
      case Op::Var: new (&s[++top]) T(blocks[in.block][in.index]); break;
      case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2:
        s[top - 1] = binary(in.op, s[top - 1], s[top]);
        --top;
        break;
      default: s[top] = unary(in.op, s[top], in); break;
    }
  }
  return s[0];
}

template <class T>
bool Expression::gradient(const T* b0, const T* b1, T* g0, T* g1) const {
  using std::cos;
  using std::cosh;
  using std::log;
  using std::sin;
  using std::sinh;
  using std::sqrt;
  static_assert(std::is_trivially_destructible_v<T>, "the expression arrays never run destructors");
  const int n = static_cast<int>(tape_.size());
  if (n > kMaxTape) return false;
  alignas(T) unsigned char raw_val[kMaxTape * sizeof(T)], raw_adj[kMaxTape * sizeof(T)];
  T* val = std::launder(reinterpret_cast<T*>(raw_val));
  T* adj = std::launder(reinterpret_cast<T*>(raw_adj));
  std::int16_t arg_a[kMaxTape], arg_b[kMaxTape], stack[kMaxStack];
  const T* blocks[2] = {b0, b1};
  T* grads[2] = {g0, g1};
  int top = -1;
  for (int i = 0; i < n; ++i) {
    const Instr& in = tape_[static_cast<std::size_t>(i)];
    switch (in.op) {
      case Op::Const: new (&val[i]) T(constant<T>(in.c)); break;
      case Op::Var: new (&val[i]) T(blocks[in.block][in.index]); break;
      case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2:
        arg_a[i] = stack[top - 1];
        arg_b[i] = stack[top];
        top -= 2;
        new (&val[i]) T(binary(in.op, val[arg_a[i]], val[arg_b[i]]));
        break;
      default:
        arg_a[i] = stack[top--];
        new (&val[i]) T(unary(in.op, val[arg_a[i]], in));
        break;
    }
    stack[++top] = static_cast<std::int16_t>(i);
    new (&adj[i]) T(constant<T>(0.0));
  }
  adj[n - 1] = constant<T>(1.0);
  for (int i = n - 1; i >= 0; --i) {
    const Instr& in = tape_[static_cast<std::size_t>(i)];
    const T& w = adj[i];
    const T& z = val[i];
    if (in.op == Op::Const) continue;
    if (in.op == Op::Var) {
      if (in.block < 2) grads[in.block][in.index] += w;
      continue;
    }
    const int a = arg_a[i];
    const T& x = val[a];
    switch (in.op) {
      case Op::Neg: adj[a] -= w; break;
      case Op::AddC: adj[a] += w; break;
      case Op::MulC: adj[a] += w * in.c; break;
      case Op::DivC: adj[a] += w / in.c; break;
      case Op::RSubC: adj[a] -= w; break;
      case Op::RDivC: adj[a] -= w * (z / x); break;
      case Op::PowI:
        if (in.index != 0) adj[a] += w * (static_cast<double>(in.index) * expression_detail::power_int(x, in.index - 1));
        break;
      case Op::PowC: adj[a] += w * (in.c * expression_detail::power_const(x, in.c - 1.0)); break;
      case Op::Sin: adj[a] += w * cos(x); break;
      case Op::Cos: adj[a] -= w * sin(x); break;
      case Op::Tan: adj[a] += w * (1.0 + z * z); break;
      case Op::Asin: adj[a] += w / sqrt(1.0 - x * x); break;
      case Op::Acos: adj[a] -= w / sqrt(1.0 - x * x); break;
      case Op::Atan: adj[a] += w / (1.0 + x * x); break;
      case Op::Exp: adj[a] += w * z; break;
      case Op::Log: adj[a] += w / x; break;
      case Op::Sqrt: adj[a] += w * (0.5 / z); break;
      case Op::Cbrt: adj[a] += w * (z / (3.0 * x)); break;
      case Op::Abs:
        if (value(x) < 0.0)
          adj[a] -= w;
        else
          adj[a] += w;
        break;
      case Op::Sinh: adj[a] += w * cosh(x); break;
      case Op::Cosh: adj[a] += w * sinh(x); break;
      case Op::Tanh: adj[a] += w * (1.0 - z * z); break;
      default: {
        const int b = arg_b[i];
        const T& y = val[b];
        switch (in.op) {
          case Op::Add: adj[a] += w; adj[b] += w; break;
          case Op::Sub: adj[a] += w; adj[b] -= w; break;
          case Op::Mul: adj[a] += w * y; adj[b] += w * x; break;
          case Op::Div: adj[a] += w / y; adj[b] -= w * (z / y); break;
          case Op::Pow: adj[a] += w * (z * y / x); adj[b] += w * (z * log(x)); break;
          case Op::Atan2: {  // atan2(x, y): d/dx = y/r^2, d/dy = -x/r^2
            const T r2 = x * x + y * y;
            adj[a] += w * (y / r2);
            adj[b] -= w * (x / r2);
            break;
          }
          default: break;
        }
      }
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

class Parser {
 public:
  Parser(const std::string& text, const ExpressionSymbols& symbols) : t_(text), sym_(symbols) {}

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

  static NodePtr make(Expression::Op op, std::size_t pos) {
    auto n = std::make_unique<Node>();
    n->op = op;
    n->pos = pos;
    return n;
  }
  static NodePtr make_const(double c, std::size_t pos) {
    NodePtr n = make(Expression::Op::Const, pos);
    n->c = c;
    return n;
  }
  static NodePtr make2(Expression::Op op, std::size_t pos, NodePtr a, NodePtr b) {
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
      if (i_ < t_.size() && t_[i_] == '(') return call(name, at);
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
  std::size_t i_ = 0;
  int nesting_ = 0;
};

// Constant folding and strength reduction of one node whose children are simplified.
inline NodePtr simplify_node(NodePtr n) {
  using O = Expression::Op;
  if (n->kids.empty()) return n;
  bool all_const = true;
  for (const auto& k : n->kids) all_const = all_const && k->is_const();
  Expression::Instr dummy{};
  if (all_const) {
    double x;
    if (n->kids.size() == 1)
      x = Expression::unary<double>(n->op, n->kids[0]->c, dummy);
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

inline Expression Expression::parse(const std::string& text, const ExpressionSymbols& symbols) {
  expression_detail::Parser p(text, symbols);
  expression_detail::NodePtr root = expression_detail::simplify(p.parse());
  Expression e;
  e.text_ = text;
  e.depth_ = expression_detail::emit(*root, e.tape_);
  if (e.depth_ > kMaxStack)
    throw ExpressionError(0, "the expression nests too deeply (needs a stack of " + std::to_string(e.depth_) +
                                 ", at most " + std::to_string(kMaxStack) + "); write it as a flatter sum");
  return e;
}

}  // namespace dvm
