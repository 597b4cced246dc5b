// The Hessian of a written potential U(q) of many coordinates, as a sparse matrix.
//
// A chain, a ring or a lattice written with sum(...) has a potential whose Hessian
// d2U/dq_i dq_j has a few entries per row. Which entries may be nonzero is read off the
// tape (mechanics/expression.h):
//   - the additive terms of a sum of one shape are kept as a block (Expression::Block),
//     and a block's value enters the expression only as a term of its top-level sum
//     (Expression::parse emits blocks there and nowhere else); a term of a block
//     contributes every pair of the coordinates it reads, plus, when it reads a
//     definition (a named subexpression, evaluated on the main tape), every pair with
//     the coordinates the main tape reads;
//   - each additive term of the rest of the tape (terms outside blocks, with the
//     definitions they read) contributes every pair of the coordinates it reads: the
//     walls of a chain are two terms, one at each end, not one term coupling both.
// The union of these cliques holds every nonzero entry. It is checked when built: at the
// point given, the sparse Hessian times a pseudo-random vector must equal the Hessian-
// vector product of one forward-over-reverse pass (reverse gradient in Jets seeded
// with the vector) to round-off; a pattern that misses an entry fails that check.
//
// Evaluation by colouring (Coleman and More, "Estimation of sparse Jacobian matrices
// and graph coloring problems", SIAM J. Numer. Anal. 20 (1983)): columns that share no
// row get one colour (greedy distance-2 colouring in column order). The Hessian times
// the sum of the unit vectors of a colour has, in row i, the one entry H(i, j) of that
// colour's columns in row i. Those products are the reverse gradient of U evaluated
// in ceres::Jet<double, K> seeded with K colours a pass (K = 4 for at most 4 colours,
// else 8), by U's derivative program where one is built (mechanics/derivative_program.h:
// its blocks' loops run in Jets, faster than the tape's sweeps), else by the tape: the whole Hessian costs ceil(colours / K)
// gradient passes (a chain of neighbour terms has 3 colours, one pass in Jets of 4,
// where each end's wall term couples only its own particle), where the dense
// forward-over-reverse Hessian costs ceil(n / 8).
//
// The pattern is symmetric and includes the diagonal. Workspace is allocated at
// construction; an evaluation allocates nothing. The expression must outlive the
// object. One object must not be used from two threads at once.
#pragma once

#include <ceres/jet.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/derivative_program.h"
#include "mechanics/expression.h"

namespace dvm {

class SparsePotentialHessian {
 public:
  static constexpr int kColoursPerPass = 8;
  // Most entries a pattern may have (as many as a dense Hessian of 4096 coordinates).
  static constexpr std::size_t kMaxEntries = std::size_t{1} << 24;

  // Thrown when the cliques would give more than kMaxEntries entries.
  struct TooDense : std::length_error {
    using std::length_error::length_error;
  };

  // U: a tape in the coordinates (block 0) alone; n: their number; q: a point where U is
  // defined (the pattern check). Throws TooDense for a pattern beyond kMaxEntries, and
  // std::logic_error if the check fails.
  SparsePotentialHessian(const Expression& U, int n, const double* q) : U_(&U), n_(n) {
    if (n < 1) throw std::invalid_argument("a sparse Hessian needs at least one coordinate");
    build_pattern();
    colour();
    program_ = DerivativeProgram::build(U, n, false);
    if (colours_ <= 4)
      w4_.resize(n, program_.get());
    else
      w8_.resize(n, program_.get());
    check(q);
  }

  // Whether the gradients in Jets run U's derivative program (else its tape).
  bool runs_program() const { return program_ != nullptr; }

  int dim() const { return n_; }
  int colours() const { return colours_; }
  // Row indices of the entries of column j, ascending (the diagonal among them).
  const std::vector<std::vector<int>>& columns() const { return columns_; }
  std::size_t entries() const { return entries_; }
  // The colour of column j (columns of one colour share no row).
  int colour_of(int j) const { return colour_[static_cast<std::size_t>(j)]; }

  // H(i, j) for every entry of the pattern, column by column in the order of columns():
  // values must hold entries() numbers.
  void evaluate(const double* q, double* values) const {
    if (colours_ <= 4)
      evaluate(w4_, q, values);
    else
      evaluate(w8_, q, values);
  }

  // H(q) r by one forward-over-reverse pass (the check, and tests).
  void times(const double* q, const double* r, double* out) const {
    if (colours_ <= 4)
      times(w4_, q, r, out);
    else
      times(w8_, q, r, out);
  }

 private:
  // The cliques of the terms, as sorted coordinate lists, merged into columns_.
  void build_pattern() {
    const Expression& U = *U_;
    std::vector<int> main;
    for (const auto& in : U.tape())
      if (in.op == Expression::Op::Var && in.block == 0) main.push_back(in.index);
    unique(main);
    std::vector<std::vector<int>> cols(static_cast<std::size_t>(n_));
    std::vector<int> term;
    std::size_t pairs = 0;  // before merging: a bound on the entries
    auto clique = [&](std::vector<int>& s) {
      unique(s);
      pairs += s.size() * s.size();
      if (pairs > kMaxEntries)
        throw TooDense("the potential's Hessian has terms coupling too many coordinates for a sparse matrix (more "
                       "than " + std::to_string(kMaxEntries) + " entries)");
      for (int j : s) {
        require_index(j);
        auto& c = cols[static_cast<std::size_t>(j)];
        c.insert(c.end(), s.begin(), s.end());
      }
    };
    for (std::vector<int>& c : main_cliques(U)) clique(c);
    for (const Expression::Block& b : U.blocks()) {
      bool reads_definition = false;
      for (const auto& in : b.body)
        if (in.op == Expression::Op::Var && in.block == 3) reads_definition = true;
      for (int k = 0; k < b.terms; ++k) {
        term.clear();
        for (std::size_t j = 0; j < b.body.size(); ++j)
          if (b.body[j].op == Expression::Op::Var && b.body[j].block == 0)
            term.push_back(b.index[j][static_cast<std::size_t>(k)]);
        if (reads_definition) term.insert(term.end(), main.begin(), main.end());
        clique(term);
      }
    }
    entries_ = 0;
    columns_.resize(static_cast<std::size_t>(n_));
    for (int j = 0; j < n_; ++j) {
      auto& c = cols[static_cast<std::size_t>(j)];
      c.push_back(j);
      unique(c);
      entries_ += c.size();
      columns_[static_cast<std::size_t>(j)] = std::move(c);
    }
  }

  // The cliques of the main tape's terms: the tape run on sets of coordinates, each
  // value a list of cliques whose terms it adds up. Sums, differences and products by
  // constants keep the lists apart; any other operation joins its operands' cliques into
  // one; a block's value adds nothing here (its terms are cliques of their own, and it
  // enters only as a term of the top-level sum); a definition holds the list of the
  // value it was given.
  static std::vector<std::vector<int>> main_cliques(const Expression& U) {
    using Op = Expression::Op;
    using List = std::vector<std::vector<int>>;
    std::vector<List> stack, defs;
    auto join = [](List& l) {
      std::vector<int> all;
      for (auto& c : l) all.insert(all.end(), c.begin(), c.end());
      l.clear();
      if (!all.empty()) l.push_back(std::move(all));
    };
    for (const auto& in : U.tape()) {
      switch (in.op) {
        case Op::Const: case Op::Block: stack.emplace_back(); break;
        case Op::Var:
          if (in.block == 0)
            stack.push_back(List{{in.index}});
          else if (in.block == 3)
            stack.push_back(defs.at(static_cast<std::size_t>(in.index)));
          else
            stack.emplace_back();
          break;
        case Op::Let:
          if (defs.size() <= static_cast<std::size_t>(in.index)) defs.resize(static_cast<std::size_t>(in.index) + 1);
          defs[static_cast<std::size_t>(in.index)] = std::move(stack.back());
          stack.pop_back();
          break;
        case Op::Add: case Op::Sub: case Op::Mul: case Op::Div: case Op::Pow: case Op::Atan2: {
          List b = std::move(stack.back());
          stack.pop_back();
          List& a = stack.back();
          a.insert(a.end(), std::make_move_iterator(b.begin()), std::make_move_iterator(b.end()));
          if (in.op != Op::Add && in.op != Op::Sub) join(a);
          break;
        }
        case Op::Neg: case Op::AddC: case Op::MulC: case Op::DivC: case Op::RSubC: break;
        default: join(stack.back()); break;
      }
    }
    return stack.empty() ? List{} : std::move(stack.back());
  }

  // Greedy distance-2 colouring: column j takes the smallest colour no column sharing a
  // row with it has.
  void colour() {
    colour_.assign(static_cast<std::size_t>(n_), -1);
    std::vector<int> mark;  // mark[c] == j: colour c is taken for column j
    colours_ = 0;
    for (int j = 0; j < n_; ++j) {
      for (int i : columns_[static_cast<std::size_t>(j)])
        for (int k : columns_[static_cast<std::size_t>(i)]) {  // the pattern is symmetric: row i of column k
          const int c = colour_[static_cast<std::size_t>(k)];
          if (c >= 0) mark[static_cast<std::size_t>(c)] = j;
        }
      int c = 0;
      while (c < colours_ && mark[static_cast<std::size_t>(c)] == j) ++c;
      if (c == colours_) {
        ++colours_;
        mark.push_back(-1);
      }
      colour_[static_cast<std::size_t>(j)] = c;
    }
  }

  // The inputs (q, then v = 0) and the reverse gradient of U, in Jets of K directions.
  template <int K>
  struct Work {
    using Jet = ceres::Jet<double, K>;
    std::vector<Jet> in, out, slots;  // slots: the program's workspace, in Jets
    void resize(int n, const DerivativeProgram* program) {
      in.resize(static_cast<std::size_t>(2 * n));
      out.resize(static_cast<std::size_t>(2 * n));
      if (program) slots = program->workspace_any<Jet>();
    }
  };

  template <int K>
  void evaluate(Work<K>& w, const double* q, double* values) const {
    for (int c0 = 0; c0 < colours_; c0 += K) {
      load(w, q);
      for (int i = 0; i < n_; ++i) {
        const int c = colour_[static_cast<std::size_t>(i)] - c0;
        if (c >= 0 && c < K) w.in[static_cast<std::size_t>(i)].v[c] = 1.0;
      }
      gradient(w);
      std::size_t k = 0;
      for (int j = 0; j < n_; ++j) {
        const auto& col = columns_[static_cast<std::size_t>(j)];
        const int c = colour_[static_cast<std::size_t>(j)] - c0;
        if (c < 0 || c >= K) {
          k += col.size();
          continue;
        }
        for (int i : col) values[k++] = w.out[static_cast<std::size_t>(i)].v[c];
      }
    }
  }
  template <int K>
  void times(Work<K>& w, const double* q, const double* r, double* out) const {
    load(w, q);
    for (int i = 0; i < n_; ++i) w.in[static_cast<std::size_t>(i)].v[0] = r[i];
    gradient(w);
    for (int i = 0; i < n_; ++i) out[i] = w.out[static_cast<std::size_t>(i)].v[0];
  }
  template <int K>
  void load(Work<K>& w, const double* q) const {
    using Jet = typename Work<K>::Jet;
    for (int i = 0; i < n_; ++i) {
      w.in[static_cast<std::size_t>(i)] = Jet(q[i]);
      w.in[static_cast<std::size_t>(n_ + i)] = Jet(0.0);
    }
  }
  template <int K>
  void gradient(Work<K>& w) const {
    using Jet = typename Work<K>::Jet;
    if (program_) {
      program_->gradient_blocks_any(w.in.data(), w.in.data() + n_, w.out.data(), w.out.data() + n_, w.slots.data());
      return;
    }
    for (auto& o : w.out) o = Jet(0.0);
    U_->gradient(w.in.data(), w.in.data() + n_, w.out.data(), w.out.data() + n_);
  }

  // The sparse Hessian times a fixed pseudo-random vector against one pass with it.
  void check(const double* q) {
    std::vector<double> r(static_cast<std::size_t>(n_)), direct(static_cast<std::size_t>(n_)),
        sparse(static_cast<std::size_t>(n_), 0.0), abs(static_cast<std::size_t>(n_), 0.0), values(entries_);
    std::uint64_t x = 0x9E3779B97F4A7C15ull;
    for (double& ri : r) {
      x ^= x << 13;
      x ^= x >> 7;
      x ^= x << 17;
      ri = 0.5 + static_cast<double>(x >> 11) * 0x1.0p-53;  // in [0.5, 1.5): no cancellation by sign
    }
    times(q, r.data(), direct.data());
    evaluate(q, values.data());
    std::size_t k = 0;
    for (int j = 0; j < n_; ++j)
      for (int i : columns_[static_cast<std::size_t>(j)]) {
        sparse[static_cast<std::size_t>(i)] += values[k] * r[static_cast<std::size_t>(j)];
        abs[static_cast<std::size_t>(i)] += std::fabs(values[k]) * r[static_cast<std::size_t>(j)];
        ++k;
      }
    for (int i = 0; i < n_; ++i) {
      const double d = std::fabs(sparse[static_cast<std::size_t>(i)] - direct[static_cast<std::size_t>(i)]);
      const double tol = 1e-12 * (abs[static_cast<std::size_t>(i)] + std::fabs(direct[static_cast<std::size_t>(i)])) + 1e-300;
      if (!(d <= tol) && std::isfinite(direct[static_cast<std::size_t>(i)]))
        throw std::logic_error("the sparsity pattern read off the expression misses Hessian entries in row " +
                               std::to_string(i) + " (sparse product " + std::to_string(sparse[static_cast<std::size_t>(i)]) +
                               ", direct " + std::to_string(direct[static_cast<std::size_t>(i)]) + ")");
    }
  }

  void require_index(int j) const {
    if (j < 0 || j >= n_)
      throw std::logic_error("the expression reads coordinate " + std::to_string(j) + " of " + std::to_string(n_));
  }
  static void unique(std::vector<int>& s) {
    std::sort(s.begin(), s.end());
    s.erase(std::unique(s.begin(), s.end()), s.end());
  }

  const Expression* U_;
  int n_;
  std::vector<std::vector<int>> columns_;
  std::size_t entries_ = 0;
  std::vector<int> colour_;
  int colours_ = 0;
  std::shared_ptr<const DerivativeProgram> program_;  // U's gradient program (null: the tape)
  mutable Work<4> w4_;  // at most 4 colours
  mutable Work<8> w8_;  // more
};

}  // namespace dvm
