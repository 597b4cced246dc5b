// Derivatives of a written expression as straight-line programs in doubles.
//
// A tape (mechanics/expression.h) is differentiated at run time by reverse mode, and
// its Hessian by reverse mode evaluated in ceres::Jets: every evaluation walks the
// tape's stack, and every Jet operation carries all the directions at once, zero or
// not. For the few-coordinate systems people write first (a pendulum, Kepler, a double
// pendulum) that overhead is most of the cost of a step.
//
// A DerivativeProgram differentiates the tape once, symbolically, when it is built:
//
//   1. the tape becomes a graph of operations, each made once (equal operations on
//      equal operands are one node; constants folded; x + 0, x * 1, x * 0, x - x,
//      -(-x) simplified), with the set of inputs each node depends on. The chain rule
//      multiplies partial derivatives that carry constant factors and signs, so these
//      move outward through products and quotients and fold ((c x)(d y) = (c d)(x y),
//      c x + d x = (c + d) x, x + x = 2 x, -x - y = -(x + y)); c / x is c (1 / x), and
//      a / x is a product where 1 / x is a node already (one division for all the
//      powers of 1/r in the derivatives of k/r); a product of up to 8 factors is made
//      in one order, so that equal products are one node and products that share
//      their first factors share their partial products. These regroup products and
//      sums, so they hold to round-off, like the rest;
//   2. reverse mode on the graph: the adjoint of every node is itself a node, built by
//      the chain rule (each operation's partial derivatives are nodes too), so the
//      gradient entries are nodes of the same graph;
//   3. forward mode on the gradient nodes, one input direction j at a time, skipping
//      every node that does not depend on input j: the Hessian entries H(i, j), i >= j,
//      are nodes as well (the upper half is their mirror);
//   4. the nodes the outputs need are numbered in order and written out as two
//      instruction lists, one for the gradient, one for the gradient and the Hessian
//      (the value stays the tape's). Evaluating one is a single loop over plain double
//      operations with their operand slots fixed: no stack, no Jets, no work on
//      zeros; where sin x and cos x are both needed, one sincos gives them; an output
//      -x or c x is read as x times its factor.
//
// The derivatives are the ones reverse mode computes, by the same formulas
// (Expression::backward): they agree with the tape's to round-off, not to the bit
// (a sum of adjoints may be added in another order).
//
// Blocks (Expression::Block: many additive terms of one shape, a chain's bonds) are
// differentiated the same way, once for the shape: the body of a term becomes a graph
// of its own whose inputs are the term's variables (and its constants that vary from
// term to term), and its partial derivatives are nodes of that graph. A program runs a
// block's graph an instruction at a time across all its terms (tight loops over arrays),
// then adds each term's partial derivatives, times the block's adjoint, to the gradient
// entries of the term's variables. It runs kBlockRun terms at a time (the arrays a run
// touches stay in the first-level cache); a variable whose terms read consecutive
// coordinates (q[i], q[i-1]) is copied and added as a range, not index by index; a
// partial derivative -x or c x adds x times its factor. The gradient also runs in any
// scalar type: in Jets (gradient_any without blocks, gradient_blocks_any with them) it
// gives derivatives of the gradient, as the fixed-size steps and the sparse Hessian of
// a potential take them.
//
// Scope: two input blocks of n variables each (q and v, or q and p). The Hessian only
// for tapes without blocks and 2n <= kMaxInputs; the gradient for any n. Definitions
// (Let) are nodes like any other. A program that would exceed kMaxNodes nodes (in its
// main graph or in a block's), or whose blocks read a definition or raise to a power
// that varies from term to term, is not built: build() returns null and the caller
// keeps the tape. Operations on non-finite values give what the formulas give; a node proven
// zero is not evaluated, so where the tape would compute 0 * inf = NaN in a term that
// does not matter to the result, the program gives the finite answer.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>
#include <new>
#include <tuple>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "mechanics/expression.h"

namespace dvm {

class DerivativeProgram {
 public:
  static constexpr int kMaxInputs = 64;               // 2n: one bit per input in a node's dependencies
  static constexpr std::size_t kMaxNodes = 1u << 16;  // largest graph built
  static constexpr std::size_t kBlockRun = 256;        // terms of a block run at a time

  // The program of `e` in blocks 0 and 1 of n variables each, or null when a graph
  // would exceed kMaxNodes, or `hessian` is asked for a tape with blocks or with
  // 2n > kMaxInputs. Without `hessian`, only the gradient (hessian() must not be called).
  static std::shared_ptr<const DerivativeProgram> build(const Expression& e, int n, bool hessian = true);

  // The values of several tapes without blocks, in blocks 0 and 1 of n variables each,
  // as one program: the tapes are read into one graph (step 1), so that an operation
  // they share is made once, and where one needs sin x and another cos x one sincos
  // gives both. Null where a tape is empty or has blocks, or the graph would exceed
  // kMaxNodes. Such a program has values() only (not gradient(), hessian() or a C
  // source): the entries of a mass matrix M(q) and the potential, each a tape of its
  // own, cost one run instead of one walk of the interpreter's stack per tape. The
  // values agree with the tapes' to round-off, not to the bit (products regrouped).
  static std::shared_ptr<const DerivativeProgram> build_values(const std::vector<const Expression*>& tapes, int n);
  bool values_only() const { return values_only_; }
  std::size_t outputs() const { return grad_out_.size(); }
  // out[i]: the value of tape i at (a, b) (b may be null where no tape reads block 1);
  // v: a workspace().
  void values(const double* a, const double* b, double* out, double* v) const {
    load(a, b, v);
    run(grad_code_, v, a, b);
    for (std::size_t i = 0; i < grad_out_.size(); ++i) out[i] = v[grad_out_[i]] * grad_factor_[i];
  }

  int dim() const { return n_; }
  bool has_hessian() const { return has_hessian_; }
  // Whether the tape had blocks (then gradient_any, which runs no blocks, must not be called).
  bool has_blocks() const { return !blocks_.empty(); }
  // The instructions, for inspection: the gradient program, then with the Hessian.
  struct Instr;
  const std::vector<Instr>& gradient_code() const { return grad_code_; }
  const std::vector<Instr>& hessian_code() const { return hess_code_; }

  // The slots an evaluation works in, constants filled in (and the arrays of the
  // blocks): one per caller (a program is shared by the copies of a system; its
  // workspace is not).
  std::vector<double> workspace() const {
    std::vector<double> w = constants_;
    for (const BlockProgram& B : blocks_) {
      w.resize(B.offset + B.slots * B.terms, 0.0);
      for (const auto& c : B.constants)
        std::fill_n(w.begin() + static_cast<std::ptrdiff_t>(B.offset + static_cast<std::size_t>(c.first) * B.terms),
                    B.terms, c.second);
      for (const auto& in : B.inputs)  // the constants that vary from term to term
        if (!in.values.empty() && in.slot >= 0)
          std::copy(in.values.begin(), in.values.end(),
                    w.begin() + static_cast<std::ptrdiff_t>(B.offset + static_cast<std::size_t>(in.slot) * B.terms));
    }
    return w;
  }

  // ga, gb receive dL/da and dL/db (n each, overwritten; gb may be null: dL/db is not
  // wanted, the force of a potential); v: a workspace().
  void gradient(const double* a, const double* b, double* ga, double* gb, double* v) const {
    if (gradient_fn_) return gradient_fn_(a, b, ga, gb);
    load(a, b, v);
    run(grad_code_, v, a, b);
    gradient_out(v, ga, gb);
  }
  // The gradient in any scalar type T (a ceres::Jet gives derivatives of the gradient:
  // the fixed-size steps take one Jet level through a Lagrangian's gradient). v: slots()
  // values of T, written here before they are read (raw storage will do).
  std::size_t slots() const { return constants_.size(); }
  template <class T>
  void gradient_any(const T* a, const T* b, T* ga, T* gb, T* v) const {
    for (const auto& c : constant_slots_) new (&v[c.first]) T(constant<T>(c.second));
    for (const auto& in : inputs_) new (&v[in.first]) T(in.second < n_ ? a[in.second] : b[in.second - n_]);
    run_any(grad_code_, v);
    gradient_out(v, ga, gb);  // (no blocks)
  }

  // The gradient in any scalar type T with the blocks run too: v, a workspace_any<T>()
  // (the blocks' arrays in T). The sparse Hessian of a chain's potential runs it in Jets
  // (mechanics/sparse_hessian.h).
  template <class T>
  std::vector<T> workspace_any() const {
    const std::vector<double> w = workspace();
    std::vector<T> out;
    out.reserve(w.size());
    for (double x : w) out.push_back(constant<T>(x));
    return out;
  }
  template <class T>
  void gradient_blocks_any(const T* a, const T* b, T* ga, T* gb, T* v) const {
    for (const auto& in : inputs_) v[in.first] = in.second < n_ ? a[in.second] : b[in.second - n_];
    run_any(grad_code_, v, a, b);
    gradient_out(v, ga, gb);
  }

  // The gradient and the Hessian's blocks Haa, Hab (Hab(i, j) = d2/da_i db_j) and Hbb,
  // column-major with leading dimensions lda, ldab, ldb.
  void hessian(const double* a, const double* b, double* ga, double* gb, double* Haa, int lda, double* Hab, int ldab,
               double* Hbb, int ldb, double* v) const {
    if (hessian_fn_) return hessian_fn_(a, b, ga, gb, Haa, lda, Hab, ldab, Hbb, ldb);
    load(a, b, v);
    run(hess_code_, v, a, b);
    const int n = n_;
    for (int i = 0; i < n; ++i) {
      ga[i] = grad_factor_[static_cast<std::size_t>(i)] * v[grad_out_[static_cast<std::size_t>(i)]];
      gb[i] = grad_factor_[static_cast<std::size_t>(n + i)] * v[grad_out_[static_cast<std::size_t>(n + i)]];
    }
    // H(r, c) of the 2n inputs, stored for r >= c
    auto H = [&](int r, int c) {
      const auto k = static_cast<std::size_t>(r * (r + 1) / 2 + c);
      return hess_factor_[k] * v[hess_out_[k]];
    };
    for (int j = 0; j < n; ++j)
      for (int i = j; i < n; ++i) {
        Haa[i + j * lda] = Haa[j + i * lda] = H(i, j);
        Hbb[i + j * ldb] = Hbb[j + i * ldb] = H(n + i, n + j);
      }
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) Hab[i + j * ldab] = H(n + j, i);
  }

  // ---- machine code (mechanics/native_code.h compiles it) ----
  // The program as one C translation unit's functions
  //   void <prefix>_gradient(const double* a, const double* b, double* ga, double* gb)
  //   void <prefix>_hessian(a, b, ga, gb, double* Haa, int lda, double* Hab, int ldab,
  //                         double* Hbb, int ldb)   (with the Hessian only)
  // with the contracts of gradient() and hessian(). They perform the interpreter's
  // operations in its order, on the same libm functions, so compiled without
  // contraction into fused multiply-adds and without value-changing optimizations they
  // give its results to the bit. Every input is read before any output is written (a
  // caller may pass overlapping arrays). Empty where the program has blocks (sums over
  // arrays, whose loops are not written out).
  std::string c_source(const std::string& prefix) const;
  using GradientFn = void (*)(const double*, const double*, double*, double*);
  using HessianFn = void (*)(const double*, const double*, double*, double*, double*, int, double*, int, double*, int);
  // A copy whose gradient() and hessian() call compiled functions (code: what keeps them
  // loaded; hessian_fn may be null only for a program without the Hessian).
  std::shared_ptr<const DerivativeProgram> with_native(GradientFn gradient_fn, HessianFn hessian_fn,
                                                       std::shared_ptr<const void> code) const {
    auto p = std::make_shared<DerivativeProgram>(*this);
    p->gradient_fn_ = gradient_fn;
    p->hessian_fn_ = hessian_fn;
    p->native_ = std::move(code);
    return p;
  }
  // Whether gradient() and hessian() run compiled code.
  bool compiled() const { return gradient_fn_ != nullptr; }

  // One operation of a program: slots[out] = op(slots[a], slots[b]) (c and k: the
  // constant and the integer power of the one-operand forms). Sin with `sign` set is
  // sin and cos of one operand at once: slots[out] = sin, slots[k] = cos.
  struct Instr {
    Expression::Op op;
    bool sign = false;  // Abs: the sign of the operand (the derivative of |x|); Sin: and cos
    std::int32_t a = 0, b = 0, out = 0, k = 0;
    double c = 0.0;
  };

 private:
  friend class DerivativeProgramBuilder;
  // A block's program: its body's graph over arrays of `terms` values per slot.
  struct BlockProgram {
    std::size_t terms = 0, slots = 0;
    std::size_t offset = 0;  // where its arrays start in the workspace
    std::vector<Instr> code;
    // the term's inputs: a variable (block 0 or 1, its index in each term) or a
    // constant that varies from term to term (values); slot -1 where none is needed
    struct Input {
      std::int32_t slot = -1;
      int block = 0;
      std::vector<std::int32_t> index;
      std::vector<double> values;
      // index[k] = first + k for every term (a chain's neighbours): copied and added as
      // ranges; -1 otherwise
      std::int32_t first = -1;
    };
    std::vector<Input> inputs;
    std::vector<std::pair<std::int32_t, double>> constants;  // slots filled with one constant
    struct Partial {
      std::int32_t input, slot;  // d(term)/d(input) is factor times the array of `slot`
      double factor = 1.0;
    };
    std::vector<Partial> partials;
    std::int32_t root = -1;     // the terms' values (-1: the block's value is not needed)
    std::int32_t adjoint = -1;  // the block's adjoint, a slot of the main program (-1: none)
  };
  // The gradient from a run's slots v: the main program's entries, then each block's
  // partial derivatives times its adjoint added to its terms' variables.
  template <class T>
  void gradient_out(const T* v, T* ga, T* gb) const {
    for (int i = 0; i < n_; ++i)
      ga[i] = v[grad_out_[static_cast<std::size_t>(i)]] * grad_factor_[static_cast<std::size_t>(i)];
    for (int i = 0; gb && i < n_; ++i)
      gb[i] = v[grad_out_[static_cast<std::size_t>(n_ + i)]] * grad_factor_[static_cast<std::size_t>(n_ + i)];
    for (const BlockProgram& B : blocks_) {
      if (B.adjoint < 0) continue;
      const T* arrays = v + B.offset;
      for (const auto& d : B.partials) {
        const T w = v[B.adjoint] * d.factor;
        const auto& in = B.inputs[static_cast<std::size_t>(d.input)];
        T* g = in.block == 0 ? ga : gb;
        if (!g) continue;
        const T* dk = arrays + static_cast<std::size_t>(d.slot) * B.terms;
        if (in.first >= 0) {
          T* gk = g + in.first;
          for (std::size_t k = 0; k < B.terms; ++k) gk[k] += w * dk[k];
        } else {
          const std::int32_t* ix = in.index.data();
          for (std::size_t k = 0; k < B.terms; ++k) g[ix[k]] += w * dk[k];
        }
      }
    }
  }
  void load(const double* a, const double* b, double* v) const {
    for (const auto& in : inputs_) v[in.first] = in.second < n_ ? a[in.second] : b[in.second - n_];
  }
  void run(const std::vector<Instr>& code, double* v, const double* a, const double* b) const;
  // (a, b: the inputs, read by the blocks; none where the code has no block)
  template <class T>
  void run_any(const std::vector<Instr>& code, T* v, const T* a = nullptr, const T* b = nullptr) const;
  // Runs block B's program into its arrays (in doubles or any scalar type); returns the
  // block's value (0 where unneeded).
  template <class T>
  T run_block(const BlockProgram& B, T* v, const T* a, const T* b) const;

  int n_ = 0;
  std::vector<Instr> grad_code_, hess_code_;
  std::vector<std::pair<std::int32_t, std::int32_t>> inputs_;  // {slot, input}: input < n in a, else b
  // the outputs' slots, each read times its factor (an output -x or c x is read as x)
  std::vector<std::int32_t> grad_out_, hess_out_;
  std::vector<double> grad_factor_, hess_factor_;
  std::vector<double> constants_;  // the slots with the constants in place (the rest 0)
  std::vector<std::pair<std::int32_t, double>> constant_slots_;
  std::vector<BlockProgram> blocks_;
  bool has_hessian_ = false;
  bool values_only_ = false;  // built by build_values
  GradientFn gradient_fn_ = nullptr;  // compiled code (with_native), or null
  HessianFn hessian_fn_ = nullptr;
  std::shared_ptr<const void> native_;
};

namespace derivative_program_detail {

// Every operation, for doubles and Jets: Expression's own (unary and binary), and the
// sign of x, which only a program has (the derivative of |x|).
template <class T>
T apply(const DerivativeProgram::Instr& in, const T& x, const T& y) {
  using Op = Expression::Op;
  switch (in.op) {
    case Op::Abs:
      if (in.sign) return constant<T>(value(x) < 0.0 ? -1.0 : 1.0);
      return expression_detail::absolute(x);
    case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2:
      return Expression::binary(in.op, x, y);
    default: {
      Expression::Instr e;
      e.op = in.op;
      e.index = in.k;
      e.c = in.c;
      return Expression::unary(in.op, x, e);
    }
  }
}

}  // namespace derivative_program_detail

template <class T>
void DerivativeProgram::run_any(const std::vector<Instr>& code, T* v, const T* a, const T* b) const {
  // each result constructed in its slot (the slots may be raw storage, see gradient_any)
  using Op = Expression::Op;
  using std::cos;
  for (const Instr& in : code) {
    const T& x = v[in.a];
    T* z = &v[in.out];
    switch (in.op) {  // the common operations inline
      case Op::Add: new (z) T(x + v[in.b]); break;
      case Op::Sub: new (z) T(x - v[in.b]); break;
      case Op::Mul: new (z) T(x * v[in.b]); break;
      case Op::Div: new (z) T(x / v[in.b]); break;
      case Op::Neg: new (z) T(-x); break;
      case Op::AddC: new (z) T(x + in.c); break;
      case Op::MulC: new (z) T(x * in.c); break;
      case Op::PowI: new (z) T(in.k == 2 ? T(x * x) : expression_detail::power_int(x, in.k)); break;
      case Op::Sin:
        if (in.sign) new (&v[in.k]) T(cos(x));  // sin and cos of one operand (see Instr)
        new (z) T(derivative_program_detail::apply(in, x, x));
        break;
      case Op::Block: new (z) T(run_block(blocks_[static_cast<std::size_t>(in.k)], v, a, b)); break;
      default: new (z) T(derivative_program_detail::apply(in, x, v[in.b])); break;
    }
  }
}

// A block an instruction at a time across all its terms; the common operations as plain
// loops (vectorised in doubles).
template <class T>
T DerivativeProgram::run_block(const BlockProgram& B, T* v, const T* a, const T* b) const {
  using Op = Expression::Op;
  const std::size_t m = B.terms;
  T* w = v + B.offset;
  // by runs of kBlockRun terms: a run's operands stay in the first-level cache from one
  // instruction to the next, however many terms the block has
  for (std::size_t k0 = 0; k0 < m; k0 += kBlockRun) {
    const std::size_t k1 = std::min(m, k0 + kBlockRun);
    for (const auto& in : B.inputs) {
      if (in.slot < 0 || !in.values.empty()) continue;  // (varying constants: in place already)
      const T* src = in.block == 0 ? a : b;
      T* dst = w + static_cast<std::size_t>(in.slot) * m;
      if (in.first >= 0) {
        std::copy(src + in.first + k0, src + in.first + k1, dst + k0);
        continue;
      }
      const std::int32_t* ix = in.index.data();
      for (std::size_t k = k0; k < k1; ++k) dst[k] = src[ix[k]];
    }
    for (const Instr& in : B.code) {
      const T* x = w + static_cast<std::size_t>(in.a) * m;
      const T* y = w + static_cast<std::size_t>(in.b) * m;
      T* z = w + static_cast<std::size_t>(in.out) * m;
      switch (in.op) {
        case Op::Add: for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] + y[k]; break;
        case Op::Sub: for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] - y[k]; break;
        case Op::Mul: for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] * y[k]; break;
        case Op::Div: for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] / y[k]; break;
        case Op::Neg: for (std::size_t k = k0; k < k1; ++k) z[k] = -x[k]; break;
        case Op::AddC: for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] + in.c; break;
        case Op::MulC: for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] * in.c; break;
        case Op::PowI:
          if (in.k == 2) {
            for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] * x[k];
            break;
          }
          if (in.k == 3) {
            for (std::size_t k = k0; k < k1; ++k) z[k] = x[k] * x[k] * x[k];
            break;
          }
          [[fallthrough]];
        default:
          for (std::size_t k = k0; k < k1; ++k) z[k] = derivative_program_detail::apply(in, x[k], y[k]);
      }
    }
  }
  if (B.root < 0) return constant<T>(0.0);
  const T* r = w + static_cast<std::size_t>(B.root) * m;
  T sum = r[0];
  for (std::size_t k = 1; k < m; ++k) sum += r[k];
  return sum;
}

// In doubles: direct threading (each operation jumps to the next one's code through a
// table, a GNU extension that GCC and Clang have), which lets the branch predictor
// learn the sequence where one shared switch jump would not.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"
inline void DerivativeProgram::run(const std::vector<Instr>& code, double* v, const double* a,
                                   const double* b) const {
  static_assert(static_cast<int>(Expression::Op::Block) == 30 && static_cast<int>(Expression::Op::Let) == 31,
                "the table follows Expression::Op");
  static void* const table[] = {&&other, &&other, &&neg, &&add, &&sub, &&mul, &&div, &&addc, &&mulc, &&divc, &&rsubc,
                                &&rdivc, &&powi, &&other, &&other, &&sin, &&cos, &&other, &&other, &&other, &&other,
                                &&other, &&other, &&sqrt, &&other, &&other, &&other, &&other, &&other, &&other, &&block,
                                &&other};
  const Instr* in = code.data();
  const Instr* const end = in + code.size();
  if (in == end) return;
#define DVM_NEXT                                   \
  do {                                             \
    if (++in == end) return;                       \
    goto* table[static_cast<int>(in->op)];         \
  } while (0)
  goto* table[static_cast<int>(in->op)];
neg: v[in->out] = -v[in->a]; DVM_NEXT;
add: v[in->out] = v[in->a] + v[in->b]; DVM_NEXT;
sub: v[in->out] = v[in->a] - v[in->b]; DVM_NEXT;
mul: v[in->out] = v[in->a] * v[in->b]; DVM_NEXT;
div: v[in->out] = v[in->a] / v[in->b]; DVM_NEXT;
addc: v[in->out] = v[in->a] + in->c; DVM_NEXT;
mulc: v[in->out] = v[in->a] * in->c; DVM_NEXT;
divc: v[in->out] = v[in->a] / in->c; DVM_NEXT;
rsubc: v[in->out] = in->c - v[in->a]; DVM_NEXT;
rdivc: v[in->out] = in->c / v[in->a]; DVM_NEXT;
powi: {
  const double x = v[in->a];
  v[in->out] = in->k == 2 ? x * x : expression_detail::power_int(x, in->k);
  DVM_NEXT;
}
sin:
  if (in->sign)
    ::sincos(v[in->a], &v[in->out], &v[in->k]);
  else
    v[in->out] = std::sin(v[in->a]);
  DVM_NEXT;
cos: v[in->out] = std::cos(v[in->a]); DVM_NEXT;
sqrt: v[in->out] = std::sqrt(v[in->a]); DVM_NEXT;
other: v[in->out] = derivative_program_detail::apply(*in, v[in->a], v[in->b]); DVM_NEXT;
block: v[in->out] = run_block(blocks_[static_cast<std::size_t>(in->k)], v, a, b); DVM_NEXT;
#undef DVM_NEXT
}
#pragma GCC diagnostic pop

// Builds a DerivativeProgram (the steps of the header comment).
class DerivativeProgramBuilder {
  using Op = Expression::Op;
  using Instr = DerivativeProgram::Instr;

 public:
  DerivativeProgramBuilder(int n, bool hessian) : n_(n), hessian_(hessian) {}

  // Step 1 for each tape and step 4 with their values as the outputs.
  bool build_values(const std::vector<const Expression*>& tapes, DerivativeProgram& out) {
    if (tapes.empty()) return false;
    for (const Expression* e : tapes)
      if (e->empty() || !e->blocks().empty()) return false;
    try {
      std::vector<int> roots;
      for (const Expression* e : tapes) roots.push_back(read(*e));
      emit(roots, {}, out);
      out.hess_code_.clear();  // (emit writes the same code twice without Hessian entries)
      out.values_only_ = true;
      return true;
    } catch (const TooLarge&) {
      return false;
    }
  }

  bool build(const Expression& e, DerivativeProgram& out) {
    if (e.empty()) return false;
    if (hessian_ && (!e.blocks().empty() || 2 * n_ > DerivativeProgram::kMaxInputs)) return false;
    try {
      const int value = read(e);
      const int m = 2 * n_;
      const std::vector<int> adj = adjoints(value);  // 2. reverse mode
      std::vector<int> grad(static_cast<std::size_t>(m), zero());
      for (int j = 0; j < m; ++j) {
        const int var = find_var(j);
        if (var >= 0 && var < static_cast<int>(adj.size()) && adj[static_cast<std::size_t>(var)] >= 0)
          grad[static_cast<std::size_t>(j)] = adj[static_cast<std::size_t>(var)];
      }
      // 3. forward mode on the gradient, one direction at a time: H(i, j) for i >= j
      const std::size_t before = nodes_.size();
      std::vector<int> hess(hessian_ ? static_cast<std::size_t>(m * (m + 1) / 2) : 0, zero());
      std::vector<int> tangent(hessian_ ? before : 0);
      for (int j = 0; j < (hessian_ ? m : 0); ++j) {
        const std::uint64_t bit = std::uint64_t{1} << j;
        int top = 0;  // the highest node a gradient entry i >= j needs
        for (int i = j; i < m; ++i) top = std::max(top, grad[static_cast<std::size_t>(i)]);
        for (int i = 0; i <= top; ++i) {
          const Node nd = nodes_[static_cast<std::size_t>(i)];
          int& t = tangent[static_cast<std::size_t>(i)];
          t = -1;
          if (!(nd.deps & bit)) continue;
          if (nd.op == Op::Var) {
            t = one();
            continue;
          }
          const auto d = partials(i);
          const int ta = tangent[static_cast<std::size_t>(nd.a)];
          const int tb = nd.b >= 0 ? tangent[static_cast<std::size_t>(nd.b)] : -1;
          if (ta >= 0) t = mul(d.first, ta);
          if (tb >= 0) t = t < 0 ? mul(d.second, tb) : add(t, mul(d.second, tb));
        }
        for (int i = j; i < m; ++i) {
          const int t = tangent[static_cast<std::size_t>(grad[static_cast<std::size_t>(i)])];
          if (t >= 0) hess[static_cast<std::size_t>(i * (i + 1) / 2 + j)] = t;
        }
      }
      emit(grad, hess, out);
      out.has_hessian_ = hessian_;
      // the blocks' programs, with their arrays after the main program's slots
      std::size_t offset = out.constants_.size();
      for (std::size_t k = 0; k < blocks_.size(); ++k) {
        DerivativeProgram::BlockProgram B;
        if (blocks_[k] && !block_program(*blocks_[k], block_value_[k], B)) return false;
        const int w = block_adjoint_[k];
        B.adjoint = w >= 0 ? emitted_slot_[static_cast<std::size_t>(w)] : -1;
        B.offset = offset;
        offset += B.slots * B.terms;
        out.blocks_.push_back(std::move(B));
      }
      return true;
    } catch (const TooLarge&) {
      return false;
    }
  }

 private:
  struct TooLarge {};
  struct Node {
    Op op;
    bool sign;
    std::int32_t a, b, k;
    double c;
    std::uint64_t deps;  // the inputs it depends on
    int factors;         // a product's factors, up to kMaxFactors + 1 (1 for any other node; see mul)
  };
  struct Key {
    Op op;
    bool sign;
    std::int32_t a, b, k;
    std::uint64_t cbits;
    bool operator==(const Key& o) const {
      return op == o.op && sign == o.sign && a == o.a && b == o.b && k == o.k && cbits == o.cbits;
    }
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      std::uint64_t h = static_cast<std::uint64_t>(k.op) * 0x9E3779B97F4A7C15ull;
      for (std::uint64_t x : {std::uint64_t(k.sign), std::uint64_t(std::uint32_t(k.a)), std::uint64_t(std::uint32_t(k.b)),
                              std::uint64_t(std::uint32_t(k.k)), k.cbits})
        h = (h ^ x) * 0x100000001B3ull + (h >> 29);
      return static_cast<std::size_t>(h);
    }
  };
  static std::uint64_t bits(double c) {
    std::uint64_t u;
    std::memcpy(&u, &c, sizeof u);
    return u;
  }

  // A node made once: equal keys give the same node.
  int make(Op op, int a, int b = -1, double c = 0.0, int k = 0, bool sign = false) {
    const Key key{op, sign, a, b, k, bits(c)};
    auto it = memo_.find(key);
    if (it != memo_.end()) return it->second;
    if (nodes_.size() >= DerivativeProgram::kMaxNodes) throw TooLarge{};
    std::uint64_t deps = 0;
    if (op == Op::Var && k == 0) deps = std::uint64_t{1} << std::min(a, 63);  // (k = 1: a constant input)
    if (op == Op::Block) deps = ~std::uint64_t{0};
    if (op != Op::Var && op != Op::Const && op != Op::Block) {
      deps = nodes_[static_cast<std::size_t>(a)].deps;
      if (b >= 0) deps |= nodes_[static_cast<std::size_t>(b)].deps;
    }
    // (counted up to kMaxFactors + 1 only: products of products double it at each level)
    const int factors = op == Op::Mul ? std::min(nodes_[static_cast<std::size_t>(a)].factors +
                                                     nodes_[static_cast<std::size_t>(b)].factors,
                                                 kMaxFactors + 1)
                                      : 1;
    nodes_.push_back({op, sign, a, b, k, c, deps, factors});
    const int id = static_cast<int>(nodes_.size()) - 1;
    memo_.emplace(key, id);
    return id;
  }
  int constant(double c) { return make(Op::Const, -1, -1, c); }
  int zero() { return constant(0.0); }
  int one() { return constant(1.0); }
  bool is_const(int i) const { return nodes_[static_cast<std::size_t>(i)].op == Op::Const; }
  double cval(int i) const { return nodes_[static_cast<std::size_t>(i)].c; }
  bool is(int i, double c) const { return is_const(i) && cval(i) == c; }
  int find_var(int input) const {
    auto it = memo_.find(Key{Op::Var, false, input, -1, 0, bits(0.0)});
    return it == memo_.end() ? -1 : it->second;
  }

  // An operation with constants folded and the trivial cases simplified.
  int op1(Op op, int a, double c = 0.0, int k = 0, bool sign = false) {
    if (is_const(a)) {
      Instr in{op, sign, 0, 0, 0, k, c};
      return constant(derivative_program_detail::apply<double>(in, cval(a), 0.0));
    }
    switch (op) {
      case Op::Neg: {  // -(-x) = x, -(c x) = (-c) x, -(x - y) = y - x where that is a node: exact
        const Node u = nodes_[static_cast<std::size_t>(a)];
        if (u.op == Op::Neg) return u.a;
        if (u.op == Op::MulC) return op1(Op::MulC, u.a, -u.c);
        if (u.op == Op::Sub) {  // (otherwise the sign stays outward, where it may fold)
          const auto reversed = memo_.find(Key{Op::Sub, false, u.b, u.a, 0, bits(0.0)});
          if (reversed != memo_.end()) return reversed->second;
        }
        break;
      }
      case Op::MulC: {
        if (c == 1.0) return a;
        if (c == 0.0) return zero();
        if (c == -1.0) return op1(Op::Neg, a);
        const Node u = nodes_[static_cast<std::size_t>(a)];
        if (u.op == Op::Neg) return op1(Op::MulC, u.a, -c);
        if (u.op == Op::MulC) return op1(Op::MulC, u.a, u.c * c);  // (x d) c = x (d c), to round-off
        break;
      }
      case Op::AddC:
        if (c == 0.0) return a;
        break;
      case Op::DivC:
        if (c == 1.0) return a;
        break;
      case Op::RDivC:  // c / x = c (1 / x): one reciprocal for every constant over x
        if (c != 1.0) return op1(Op::MulC, make(Op::RDivC, a, -1, 1.0), c);
        break;
      case Op::PowI:
        if (k == 1) return a;
        if (k == 0) return one();
        break;
      default: break;
    }
    return make(op, a, -1, c, k, sign);
  }
  int op2(Op op, int a, int b) {
    if (is_const(a) && is_const(b)) {
      Instr in{op, false, 0, 0, 0, 0, 0.0};
      return constant(derivative_program_detail::apply<double>(in, cval(a), cval(b)));
    }
    if ((op == Op::Add || op == Op::Mul) && a > b) std::swap(a, b);  // commutative: one order
    return make(op, a, b);
  }
  int add(int a, int b) {
    if (is(a, 0.0)) return b;
    if (is(b, 0.0)) return a;
    if (is_const(a)) return op1(Op::AddC, b, cval(a));
    if (is_const(b)) return op1(Op::AddC, a, cval(b));
    if (nodes_[static_cast<std::size_t>(b)].op == Op::Neg) return sub(a, nodes_[static_cast<std::size_t>(b)].a);
    if (nodes_[static_cast<std::size_t>(a)].op == Op::Neg) return sub(b, nodes_[static_cast<std::size_t>(a)].a);
    if (a == b) return op1(Op::MulC, a, 2.0);  // x + x = 2 x, exact: a factor that may fold
    const auto [ca, xa] = coefficient(a);
    const auto [cb, xb] = coefficient(b);
    if (xa == xb) return op1(Op::MulC, xa, ca + cb);  // c x + d x = (c + d) x, to round-off
    return op2(Op::Add, a, b);
  }
  int sub(int a, int b) {
    if (is(b, 0.0)) return a;
    if (is(a, 0.0)) return op1(Op::Neg, b);
    if (a == b) return zero();
    if (is_const(a) && !is_const(b)) return op1(Op::RSubC, b, cval(a));
    if (is_const(b) && !is_const(a)) return op1(Op::AddC, a, -cval(b));
    if (nodes_[static_cast<std::size_t>(b)].op == Op::Neg) return add(a, nodes_[static_cast<std::size_t>(b)].a);
    if (op(a) == Op::Neg) return neg(add(arg(a), b));  // -x - y = -(x + y): the sign outward
    // y - x where x - y is a node: its negation (the sign outward, one difference)
    const auto reversed = memo_.find(Key{Op::Sub, false, b, a, 0, bits(0.0)});
    if (reversed != memo_.end()) return neg(reversed->second);
    const auto [ca, xa] = coefficient(a);
    const auto [cb, xb] = coefficient(b);
    if (xa == xb) return op1(Op::MulC, xa, ca - cb);  // c x - d x = (c - d) x, to round-off
    return op2(Op::Sub, a, b);
  }
  int mul(int a, int b) {
    if (is(a, 0.0) || is(b, 0.0)) return zero();
    // signs outward, where they cancel or turn a sum into a difference
    const bool na = nodes_[static_cast<std::size_t>(a)].op == Op::Neg, nb = nodes_[static_cast<std::size_t>(b)].op == Op::Neg;
    if (na && nb) return mul(nodes_[static_cast<std::size_t>(a)].a, nodes_[static_cast<std::size_t>(b)].a);
    if (na) return neg(mul(nodes_[static_cast<std::size_t>(a)].a, b));
    if (nb) return neg(mul(a, nodes_[static_cast<std::size_t>(b)].a));
    if (is_const(a) && !is_const(b)) return op1(Op::MulC, b, cval(a));
    if (is_const(b) && !is_const(a)) return op1(Op::MulC, a, cval(b));
    // constant factors outward, where they meet and fold: (c x) (d y) = (c d) (x y), to
    // round-off (a reverse pass makes such products at every chain rule)
    if (op(a) == Op::MulC) return op1(Op::MulC, mul(arg(a), b), cval(a));
    if (op(b) == Op::MulC) return op1(Op::MulC, mul(a, arg(b)), cval(b));
    // a product of few factors in one order (the latest made first), so that equal
    // products are one node and products sharing their first factors share their
    // partial products: x^2 y r^-3 and y r^-3 and r^-3 are one chain (the
    // derivatives of a potential of r multiply powers of 1/r by coordinates)
    const int fa = nodes_[static_cast<std::size_t>(a)].factors, fb = nodes_[static_cast<std::size_t>(b)].factors;
    if (fa + fb <= kMaxFactors) {
      int f[kMaxFactors], m = 0;
      factors_of(a, f, m);
      factors_of(b, f, m);
      // largest first, by insertion: at most kMaxFactors entries (std::sort on such an
      // array draws a false -Warray-bounds from g++ 12 at -O3)
      for (int i = 1; i < m; ++i) {
        const int x = f[i];
        int j = i;
        for (; j > 0 && f[j - 1] < x; --j) f[j] = f[j - 1];
        f[j] = x;
      }
      int p = f[0];
      for (int i = 1; i < m; ++i) p = op2(Op::Mul, p, f[i]);
      return p;
    }
    return op2(Op::Mul, a, b);
  }
  static constexpr int kMaxFactors = 8;
  // x as c y: (c, y) where x = c y or (c = -1) x = -y is a node, (1, x) otherwise
  // (add and sub meet no negation here: they turn it into a difference or a sum first)
  std::pair<double, int> coefficient(int x) const {
    if (op(x) == Op::MulC) return {cval(x), arg(x)};
    if (op(x) == Op::Neg) return {-1.0, arg(x)};
    return {1.0, x};
  }
  void factors_of(int i, int* f, int& m) const {
    const Node& nd = nodes_[static_cast<std::size_t>(i)];
    if (nd.op != Op::Mul) {
      f[m++] = i;
      return;
    }
    factors_of(nd.a, f, m);
    factors_of(nd.b, f, m);
  }
  int div(int a, int b) {
    if (is(a, 0.0) && !is(b, 0.0)) return zero();
    if (is_const(b) && !is_const(a)) return op1(Op::DivC, a, cval(b));
    if (is_const(a) && !is_const(b)) return op1(Op::RDivC, b, cval(a));  // c / x
    // signs and constant factors outward, as in mul
    if (op(a) == Op::Neg) return neg(div(arg(a), b));
    if (op(b) == Op::Neg) return neg(div(a, arg(b)));
    if (op(a) == Op::MulC) return op1(Op::MulC, div(arg(a), b), cval(a));
    // a / x = a (1 / x) where 1 / x is a node already: a product in place of a division
    // (the derivatives of c / x, a / x and sqrt(x) all divide by x again)
    const auto recip = memo_.find(Key{Op::RDivC, false, b, -1, 0, bits(1.0)});
    if (recip != memo_.end()) return mul(a, recip->second);
    return op2(Op::Div, a, b);
  }
  Op op(int i) const { return nodes_[static_cast<std::size_t>(i)].op; }
  int arg(int i) const { return nodes_[static_cast<std::size_t>(i)].a; }
  int neg(int a) { return op1(Op::Neg, a); }

  // The tape as a graph (step 1); returns the node of its value.
  int read(const Expression& e) {
    std::vector<int> stack, defs(static_cast<std::size_t>(Expression::kMaxDefinitions), -1);
    for (const auto& in : e.tape()) {
      switch (in.op) {
        case Op::Const: stack.push_back(constant(in.c)); break;
        case Op::Var:
          if (in.block == 3)
            stack.push_back(defs[static_cast<std::size_t>(in.index)]);
          else if (in.block == 0 || in.block == 1)
            stack.push_back(make(Op::Var, in.block * n_ + in.index));
          else
            throw TooLarge{};  // block 2 (momenta) is not an input of a program
          break;
        case Op::Let:
          defs[static_cast<std::size_t>(in.index)] = stack.back();
          stack.pop_back();
          break;
        case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2: {
          const int b = stack.back();
          stack.pop_back();
          const int a = stack.back();
          stack.back() = in.op == Op::Add ? add(a, b)
                         : in.op == Op::Sub ? sub(a, b)
                         : in.op == Op::Mul ? mul(a, b)
                         : in.op == Op::Div ? div(a, b)
                                            : op2(in.op, a, b);
          break;
        }
        case Op::Block: {
          const std::size_t k = static_cast<std::size_t>(in.index);
          if (blocks_.size() <= k) {
            blocks_.resize(k + 1, nullptr);
            block_adjoint_.resize(k + 1, -1);
            block_value_.resize(k + 1, false);
          }
          blocks_[k] = &e.blocks()[k];
          stack.push_back(make(Op::Block, -1, -1, 0.0, in.index));
          break;
        }
        default: stack.back() = op1(in.op, stack.back(), in.c, in.index); break;
      }
    }
    return stack.back();
  }

  // The partial derivatives of node i with respect to its operands (the formulas of
  // Expression::backward), as nodes; the second is unused for one-operand nodes.
  std::pair<int, int> partials(int i) {
    const Node nd = nodes_[static_cast<std::size_t>(i)];
    const int x = nd.a, y = nd.b;
    auto sq = [&](int u) { return op1(Op::PowI, u, 0.0, 2); };
    switch (nd.op) {
      case Op::Neg: return {constant(-1.0), -1};
      case Op::Add: return {one(), one()};
      case Op::Sub: return {one(), constant(-1.0)};
      case Op::Mul: return {y, x};
      case Op::Div: return {div(one(), y), neg(div(i, y))};
      case Op::AddC: return {one(), -1};
      case Op::MulC: return {constant(nd.c), -1};
      case Op::DivC: return {constant(1.0 / nd.c), -1};
      case Op::RSubC: return {constant(-1.0), -1};
      case Op::RDivC: return {neg(div(i, x)), -1};
      case Op::PowI:
        return {nd.k == 0 ? zero() : op1(Op::MulC, op1(Op::PowI, x, 0.0, nd.k - 1), static_cast<double>(nd.k)), -1};
      case Op::PowC: return {op1(Op::MulC, op1(Op::PowC, x, nd.c - 1.0), nd.c), -1};
      case Op::Pow: return {div(mul(i, y), x), mul(i, op1(Op::Log, x))};
      case Op::Sin: return {op1(Op::Cos, x), -1};
      case Op::Cos: return {neg(op1(Op::Sin, x)), -1};
      case Op::Tan: return {add(one(), sq(i)), -1};
      case Op::Asin: return {div(one(), op1(Op::Sqrt, sub(one(), sq(x)))), -1};
      case Op::Acos: return {neg(div(one(), op1(Op::Sqrt, sub(one(), sq(x))))), -1};
      case Op::Atan: return {div(one(), add(one(), sq(x))), -1};
      case Op::Exp: return {i, -1};
      case Op::Log: return {div(one(), x), -1};
      case Op::Sqrt: return {div(constant(0.5), i), -1};
      case Op::Cbrt: return {div(i, op1(Op::MulC, x, 3.0)), -1};
      case Op::Abs: return {nd.sign ? zero() : op1(Op::Abs, x, 0.0, 0, true), -1};
      case Op::Sinh: return {op1(Op::Cosh, x), -1};
      case Op::Cosh: return {op1(Op::Sinh, x), -1};
      case Op::Tanh: return {sub(one(), sq(i)), -1};
      case Op::Atan2: {
        const int r2 = add(sq(x), sq(y));
        return {div(y, r2), neg(div(x, r2))};
      }
      default: return {zero(), zero()};
    }
  }

  // Reverse mode from `root` (step 2): the adjoint node of every node up to it (-1:
  // none), each a sum of products of adjoints and partial derivatives; a block's
  // adjoint is kept in block_adjoint_ (its terms' partials are its own program's).
  std::vector<int> adjoints(int root) {
    std::vector<int> adj(nodes_.size(), -1);
    adj[static_cast<std::size_t>(root)] = one();
    for (int i = root; i >= 0; --i) {
      const int w = adj[static_cast<std::size_t>(i)];
      const Node nd = nodes_[static_cast<std::size_t>(i)];
      if (nd.op == Op::Block) block_adjoint_[static_cast<std::size_t>(nd.k)] = w;
      if (w < 0 || nd.deps == 0 || nd.op == Op::Var || nd.op == Op::Block) continue;
      const auto d = partials(i);
      auto push = [&](int operand, int partial) {
        const int t = mul(w, partial);
        int& slot = adj[static_cast<std::size_t>(operand)];
        slot = slot < 0 ? t : add(slot, t);
      };
      if (nodes_[static_cast<std::size_t>(nd.a)].deps) push(nd.a, d.first);
      if (nd.b >= 0 && nodes_[static_cast<std::size_t>(nd.b)].deps) push(nd.b, d.second);
    }
    return adj;
  }

  // Marks `root` and every node it reads, transitively.
  void mark(std::vector<char>& need, int root) const {
    std::vector<int> work{root};
    while (!work.empty()) {
      const int i = work.back();
      work.pop_back();
      if (need[static_cast<std::size_t>(i)]) continue;
      need[static_cast<std::size_t>(i)] = 1;
      const Node& nd = nodes_[static_cast<std::size_t>(i)];
      if (nd.op == Op::Var || nd.op == Op::Const || nd.op == Op::Block) continue;
      work.push_back(nd.a);
      if (nd.b >= 0) work.push_back(nd.b);
    }
  }

  // Step 4: number the nodes the outputs need and write the two programs. Where a
  // program needs both sin x and cos x, one instruction computes them (sincos).
  void emit(std::vector<int> grad, std::vector<int> hess, DerivativeProgram& out) {
    const std::size_t count = nodes_.size();
    // an output -x or c x is x read times its factor: no instruction for the product
    auto outward = [&](std::vector<int>& roots, std::vector<double>& factor) {
      factor.resize(roots.size());
      for (std::size_t i = 0; i < roots.size(); ++i) std::tie(factor[i], roots[i]) = coefficient(roots[i]);
    };
    outward(grad, out.grad_factor_);
    outward(hess, out.hess_factor_);
    std::vector<char> need_grad(count, 0), need_all(count, 0);
    for (int g : grad) mark(need_grad, g);
    // every block with an adjoint runs (its partial derivatives), and its adjoint is an
    // output; a block computes its value where these need it
    for (int w : block_adjoint_)
      if (w >= 0) mark(need_grad, w);
    for (std::size_t i = 0; i < count; ++i)
      if (nodes_[i].op == Op::Block) block_value_[static_cast<std::size_t>(nodes_[i].k)] = need_grad[i] != 0;
    for (std::size_t k = 0; k < block_adjoint_.size(); ++k)
      if (block_adjoint_[k] >= 0) need_grad[static_cast<std::size_t>(find_block(static_cast<int>(k)))] = 1;
    need_all = need_grad;
    for (int h : hess) mark(need_all, h);
    std::vector<std::int32_t> slot(count, -1);
    std::vector<double> slots;
    out.n_ = n_;
    for (std::size_t i = 0; i < count; ++i) {
      if (!need_all[i]) continue;
      const Node& nd = nodes_[i];
      slot[i] = static_cast<std::int32_t>(slots.size());
      slots.push_back(nd.op == Op::Const ? nd.c : 0.0);
      if (nd.op == Op::Var) out.inputs_.push_back({slot[i], nd.a});
      if (nd.op == Op::Const) out.constant_slots_.push_back({slot[i], nd.c});
    }
    // the cos node of each operand whose sin is a node too
    std::unordered_map<int, int> cos_of;
    for (std::size_t i = 0; i < count; ++i)
      if (need_all[i] && nodes_[i].op == Op::Cos) cos_of[nodes_[i].a] = static_cast<int>(i);
    auto write = [&](const std::vector<char>& need, std::vector<Instr>& code) {
      std::vector<char> done(count, 0);
      for (std::size_t i = 0; i < count; ++i) {
        const Node& nd = nodes_[i];
        if (!need[i] || done[i] || nd.op == Op::Var || nd.op == Op::Const) continue;
        if (nd.op == Op::Block) {
          code.push_back(Instr{Op::Block, false, 0, 0, slot[i], nd.k, 0.0});
          continue;
        }
        Instr in{nd.op, nd.sign, slot[static_cast<std::size_t>(nd.a)],
                 nd.b >= 0 ? slot[static_cast<std::size_t>(nd.b)] : 0, slot[i], nd.k, nd.c};
        auto partner = [&](int operand) {  // the cos node of a sin node's operand, if this program needs it
          auto it = cos_of.find(operand);
          return it != cos_of.end() && need[static_cast<std::size_t>(it->second)] ? it->second : -1;
        };
        if (nd.op == Op::Sin && partner(nd.a) >= 0) {
          in.sign = true;
          in.k = slot[static_cast<std::size_t>(partner(nd.a))];
          done[static_cast<std::size_t>(partner(nd.a))] = 1;
        }
        if (nd.op == Op::Cos) {  // its sin later in the order: computed together here
          auto it = memo_.find(Key{Op::Sin, false, nd.a, -1, 0, bits(0.0)});
          if (it != memo_.end() && need[static_cast<std::size_t>(it->second)]) {
            in = Instr{Op::Sin, true, slot[static_cast<std::size_t>(nd.a)], 0,
                       slot[static_cast<std::size_t>(it->second)], slot[i], 0.0};
            done[static_cast<std::size_t>(it->second)] = 1;
          }
        }
        code.push_back(in);
      }
    };
    write(need_grad, out.grad_code_);
    write(need_all, out.hess_code_);
    for (int g : grad) out.grad_out_.push_back(slot[static_cast<std::size_t>(g)]);
    for (int h : hess) out.hess_out_.push_back(slot[static_cast<std::size_t>(h)]);
    out.constants_ = std::move(slots);
    emitted_slot_ = std::move(slot);
  }

  int find_block(int k) const {
    auto it = memo_.find(Key{Op::Block, false, -1, -1, k, bits(0.0)});
    return it == memo_.end() ? -1 : it->second;
  }

  // A block's program (see the header comment): its body read into a graph of a fresh
  // builder, inputs the term's variables (equal index lists are one input) and its
  // varying constants; the partial derivatives by reverse mode from the term's value.
  static bool block_program(const Expression::Block& b, bool value, DerivativeProgram::BlockProgram& out) {
    DerivativeProgramBuilder g(0, false);
    using Input = DerivativeProgram::BlockProgram::Input;
    std::vector<Input> inputs;
    auto variable = [&](int block, const std::vector<std::int32_t>& index) {
      for (std::size_t i = 0; i < inputs.size(); ++i)
        if (inputs[i].values.empty() && inputs[i].block == block && inputs[i].index == index)
          return g.make(Op::Var, static_cast<int>(i));
      inputs.push_back(Input{-1, block, index, {}});
      return g.make(Op::Var, static_cast<int>(inputs.size()) - 1);
    };
    auto varying = [&](const std::vector<double>& values) {
      inputs.push_back(Input{-1, 0, {}, values});
      return g.make(Op::Var, static_cast<int>(inputs.size()) - 1, -1, 0.0, 1);
    };
    try {
      std::vector<int> node(b.body.size());
      for (std::size_t j = 0; j < b.body.size(); ++j) {
        const Expression::Instr& in = b.body[j];
        const std::vector<double>& cs = b.c[j];
        if (in.op == Op::Var) {
          if (in.block != 0 && in.block != 1) return false;
          node[j] = variable(in.block, b.index[j]);
          continue;
        }
        if (in.op == Op::Const) {
          node[j] = cs.empty() ? g.constant(in.c) : varying(cs);
          continue;
        }
        const int x = node[static_cast<std::size_t>(b.arg_a[j])];
        if (b.arg_b[j] >= 0) {
          const int y = node[static_cast<std::size_t>(b.arg_b[j])];
          node[j] = in.op == Op::Add ? g.add(x, y)
                    : in.op == Op::Sub ? g.sub(x, y)
                    : in.op == Op::Mul ? g.mul(x, y)
                    : in.op == Op::Div ? g.div(x, y)
                                       : g.op2(in.op, x, y);
          continue;
        }
        if (cs.empty()) {
          node[j] = g.op1(in.op, x, in.c, in.index);
          continue;
        }
        const int c = varying(cs);  // a constant operand that varies: two operands
        switch (in.op) {
          case Op::AddC: node[j] = g.add(x, c); break;
          case Op::MulC: node[j] = g.mul(x, c); break;
          case Op::DivC: node[j] = g.div(x, c); break;
          case Op::RSubC: node[j] = g.sub(c, x); break;
          case Op::RDivC: node[j] = g.div(c, x); break;
          // x^c with c varying (pow(x, c) on the tape, finite at x = 0 where
          // exp(c log x) and its derivative are not): such a block stays on the tape
          default: return false;
        }
      }
      const int root = node.back();
      const std::vector<int> adj = g.adjoints(root);
      // the outputs: each variable's partial derivative (unless it is zero), the value
      struct Partial {
        int input, node;
        double factor;  // a partial -x or c x is x added times its factor: no array pass for it
      };
      std::vector<Partial> partial;
      for (std::size_t i = 0; i < inputs.size(); ++i) {
        if (!inputs[i].values.empty()) continue;
        const int var = g.make(Op::Var, static_cast<int>(i));
        const int d = var < static_cast<int>(adj.size()) ? adj[static_cast<std::size_t>(var)] : -1;
        if (d < 0 || g.is(d, 0.0)) continue;
        const auto [c, x] = g.coefficient(d);
        partial.push_back({static_cast<int>(i), x, c});
      }
      const std::size_t count = g.nodes_.size();
      std::vector<char> need(count, 0);
      for (const auto& d : partial) g.mark(need, d.node);
      if (value) g.mark(need, root);
      std::vector<std::int32_t> slot(count, -1);
      std::int32_t slots = 0;
      for (std::size_t i = 0; i < count; ++i) {
        if (!need[i]) continue;
        const Node& nd = g.nodes_[i];
        slot[i] = slots++;
        if (nd.op == Op::Const) out.constants.push_back({slot[i], nd.c});
        if (nd.op == Op::Var) inputs[static_cast<std::size_t>(nd.a)].slot = slot[i];
        if (nd.op == Op::Var || nd.op == Op::Const) continue;
        out.code.push_back(Instr{nd.op, nd.sign, slot[static_cast<std::size_t>(nd.a)],
                                 nd.b >= 0 ? slot[static_cast<std::size_t>(nd.b)] : 0, slot[i], nd.k, nd.c});
      }
      for (const auto& d : partial) out.partials.push_back({d.input, slot[static_cast<std::size_t>(d.node)], d.factor});
      out.root = value ? slot[static_cast<std::size_t>(root)] : -1;
      out.slots = static_cast<std::size_t>(slots);
      out.terms = static_cast<std::size_t>(b.terms);
      for (Input& in : inputs) {
        bool contiguous = !in.index.empty() && in.values.empty();
        for (std::size_t k = 1; contiguous && k < in.index.size(); ++k)
          contiguous = in.index[k] == in.index[0] + static_cast<std::int32_t>(k);
        in.first = contiguous ? in.index[0] : -1;
      }
      out.inputs = std::move(inputs);
      return true;
    } catch (const TooLarge&) {
      return false;
    }
  }

  int n_;
  bool hessian_;
  std::vector<const Expression::Block*> blocks_;  // the tape's blocks, by index
  std::vector<int> block_adjoint_;                // each block's adjoint node (-1: none)
  std::vector<bool> block_value_;                 // whether the outputs need its value
  std::vector<std::int32_t> emitted_slot_;        // the main program's slot of each node
  std::vector<Node> nodes_;
  std::unordered_map<Key, int, KeyHash> memo_;
};

inline std::string DerivativeProgram::c_source(const std::string& prefix) const {
  if (values_only_) return {};
  using Op = Expression::Op;
  if (!blocks_.empty()) return {};
  auto literal = [](double c) -> std::string {
    if (std::isnan(c)) return "NAN";
    if (std::isinf(c)) return c > 0.0 ? "HUGE_VAL" : "(-HUGE_VAL)";
    char buf[48];
    std::snprintf(buf, sizeof buf, "(%a)", c);  // exact
    return buf;
  };
  auto slot = [](std::int32_t k) { return "v" + std::to_string(k); };
  std::vector<int> input(constants_.size(), -1);
  for (const auto& in : inputs_) input[static_cast<std::size_t>(in.first)] = in.second;
  // Every slot a local: the inputs and constants initialised, the rest assigned by the code.
  auto declare = [&]() {
    std::string d;
    for (std::size_t k = 0; k < constants_.size(); ++k) {
      const int i = input[k];
      d += "  double " + slot(static_cast<std::int32_t>(k)) + " = " +
           (i < 0 ? literal(constants_[k]) : i < n_ ? "a[" + std::to_string(i) + "]" : "b[" + std::to_string(i - n_) + "]") +
           ";\n";
    }
    return d;
  };
  int temps = 0;
  std::string body;
  // x^k as power_int forms it (expression.h), into temporaries; the name of the result
  std::function<std::string(const std::string&, long long)> power = [&](const std::string& x, long long k) -> std::string {
    if (k == 0) return "1.0";
    auto temp = [&](const std::string& e) {
      const std::string t = "t" + std::to_string(temps++);
      body += "  const double " + t + " = " + e + ";\n";
      return t;
    };
    if (k < 0) return temp("1.0 / " + power(x, -k));
    if (k == 1) return x;
    if (k == 2) return temp(x + " * " + x);
    const std::string half = power(x, k / 2), sq = temp(half + " * " + half);
    return k % 2 ? temp(sq + " * " + x) : sq;
  };
  auto code = [&](const std::vector<Instr>& instrs) -> bool {
    body.clear();
    for (const Instr& in : instrs) {
      const std::string z = "  " + slot(in.out) + " = ", x = slot(in.a), y = slot(in.b), c = literal(in.c);
      auto call = [&](const char* f) { body += z + f + "(" + x + ");\n"; };
      switch (in.op) {
        case Op::Neg: body += z + "-" + x + ";\n"; break;
        case Op::Add: body += z + x + " + " + y + ";\n"; break;
        case Op::Sub: body += z + x + " - " + y + ";\n"; break;
        case Op::Mul: body += z + x + " * " + y + ";\n"; break;
        case Op::Div: body += z + x + " / " + y + ";\n"; break;
        case Op::AddC: body += z + x + " + " + c + ";\n"; break;
        case Op::MulC: body += z + x + " * " + c + ";\n"; break;
        case Op::DivC: body += z + x + " / " + c + ";\n"; break;
        case Op::RSubC: body += z + c + " - " + x + ";\n"; break;
        case Op::RDivC: body += z + c + " / " + x + ";\n"; break;
        case Op::PowI: {
          const std::string r = power(x, in.k);
          body += z + r + ";\n";
          break;
        }
        case Op::PowC: body += z + "pow(" + x + ", " + c + ");\n"; break;
        case Op::Pow: body += z + "exp(" + y + " * log(" + x + "));\n"; break;
        case Op::Atan2: body += z + "atan2(" + x + ", " + y + ");\n"; break;
        case Op::Abs:
          body += z + "(" + x + " < 0.0 ? " + (in.sign ? "-1.0 : 1.0" : "-" + x + " : " + x) + ");\n";
          break;
        case Op::Sin:
          if (in.sign)
            body += "  sincos(" + x + ", &" + slot(in.out) + ", &" + slot(in.k) + ");\n";
          else
            call("sin");
          break;
        case Op::Cos: call("cos"); break;
        case Op::Tan: call("tan"); break;
        case Op::Asin: call("asin"); break;
        case Op::Acos: call("acos"); break;
        case Op::Atan: call("atan"); break;
        case Op::Exp: call("exp"); break;
        case Op::Log: call("log"); break;
        case Op::Sqrt: call("sqrt"); break;
        case Op::Cbrt: call("cbrt"); break;
        case Op::Sinh: call("sinh"); break;
        case Op::Cosh: call("cosh"); break;
        case Op::Tanh: call("tanh"); break;
        default: return false;  // Const, Var, Let, Block: not in a program without blocks
      }
    }
    return true;
  };
  const int n = n_;
  // an output: its slot times its factor (a product commutes exactly, so the order of
  // gradient_out and hessian() does not matter)
  auto out = [&](std::int32_t s, double f) { return slot(s) + " * " + literal(f); };
  auto gradient_outputs = [&]() {
    std::string g;
    for (int i = 0; i < 2 * n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      if (i == n) g += "  if (gb) {\n";
      g += std::string(i < n ? "  ga[" : "    gb[") + std::to_string(i < n ? i : i - n) +
           "] = " + out(grad_out_[k], grad_factor_[k]) + ";\n";
    }
    return g + "  }\n";
  };
  std::string src = "void " + prefix + "_gradient(const double* a, const double* b, double* ga, double* gb) {\n" +
                    declare();
  if (!code(grad_code_)) return {};
  src += body + gradient_outputs() + "}\n";
  if (!has_hessian_) return src;
  src += "void " + prefix +
         "_hessian(const double* a, const double* b, double* ga, double* gb, double* Haa, int lda, double* Hab, "
         "int ldab, double* Hbb, int ldb) {\n" + declare();
  if (!code(hess_code_)) return {};
  src += body + gradient_outputs();
  auto H = [&](int r, int c) {
    const auto k = static_cast<std::size_t>(r * (r + 1) / 2 + c);
    return out(hess_out_[k], hess_factor_[k]);
  };
  auto at = [](const char* m, int i, int j, const char* ld) {
    return std::string(m) + "[" + std::to_string(i) + " + " + std::to_string(j) + " * " + ld + "]";
  };
  for (int j = 0; j < n; ++j)
    for (int i = j; i < n; ++i) {
      src += "  " + at("Haa", i, j, "lda") + " = " + at("Haa", j, i, "lda") + " = " + H(i, j) + ";\n";
      src += "  " + at("Hbb", i, j, "ldb") + " = " + at("Hbb", j, i, "ldb") + " = " + H(n + i, n + j) + ";\n";
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) src += "  " + at("Hab", i, j, "ldab") + " = " + H(n + j, i) + ";\n";
  return src + "}\n";
}

inline std::shared_ptr<const DerivativeProgram> DerivativeProgram::build(const Expression& e, int n, bool hessian) {
  auto p = std::make_shared<DerivativeProgram>();
  DerivativeProgramBuilder b(n, hessian);
  if (!b.build(e, *p)) return nullptr;
  return p;
}

inline std::shared_ptr<const DerivativeProgram> DerivativeProgram::build_values(
    const std::vector<const Expression*>& tapes, int n) {
  auto p = std::make_shared<DerivativeProgram>();
  DerivativeProgramBuilder b(n, false);
  if (!b.build_values(tapes, *p)) return nullptr;
  return p;
}

}  // namespace dvm
