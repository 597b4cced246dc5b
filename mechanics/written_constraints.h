// Holonomic constraints g(t, q) = 0 on R^n written in a scene ([system] constraints):
// m expressions in the coordinates and the time t (rheonomic where t appears). They
// restrict the motion to the submanifold N_t = {q : g(t, q) = 0}; the constrained
// steps (solvers/constrained_step.h) keep q_k on it and the momenta on its hidden
// constraint Dg(t, q) v + g_t(t, q) = 0, v = FL^{-1}(q, p).
//
// Each constraint is parsed with WrittenSystem::Kind::constraint (the coordinates, t,
// the parameters and the definitions; no velocities). Evaluated in doubles; the rows
// of Dg and the time derivatives g_t by each constraint's derivative program
// (mechanics/derivative_program.h, built once per system, in the variables (q, t)),
// or by reverse mode on its tape where no program is built (kMaxProgramEntries); Dg as a sparse matrix
// (sparse_gradients, the pattern read off the tapes) by reverse mode on the tapes, at a
// cost that does not grow with the number of coordinates a constraint does not read.
//
// The measures of distance to the constraint that the runtime checks and reports are
// relative (relative_residuals below): |g_i(t, q)| / (|grad g_i| |q|) (for
// x^2 + y^2 - l^2 about the relative error of the length), and for the hidden
// constraint |grad g_i . v + dg_i/dt| / (|grad g_i| |v|) (the relative size of the
// velocity across the constraint), with |.| the Euclidean norm.
//
// Workspace is held per object: one object must not be used from two threads at once
// (copies are independent).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/written_dynamic.h"
#include "mechanics/written_lagrangian.h"

namespace dvm {

class WrittenConstraints {
 public:
  explicit WrittenConstraints(std::shared_ptr<const WrittenSystem> s) : system_(std::move(s)) {
    if (!system_ || system_->space != WrittenSystem::Space::euclidean)
      throw std::invalid_argument("WrittenConstraints: constraints are written on R^n");
    if (system_->constraints.empty()) throw std::invalid_argument("WrittenConstraints: the system writes no constraints");
    const int n = dim();
    // (a program's gradient has all n + 1 entries: beyond kMaxProgramEntries in all, as
    // in a long chain of links, the tapes alone, whose sparse gradients cost O(their length))
    const bool programs = static_cast<double>(count()) * (n + 1) <= kMaxProgramEntries;
    for (const Expression& e : system_->constraints) {
      programs_.push_back(programs ? DerivativeProgram::build(e, n + 1, false) : nullptr);
      if (programs_.back() && programs_.back()->has_blocks()) programs_.back() = nullptr;
      slots_.push_back(programs_.back() ? programs_.back()->workspace() : std::vector<double>());
    }
    qt_.setZero(n + 1);
    zero_.setZero(n + 1);
    gq_.resize(n + 1);
    gv_.resize(n + 1);
    sq_.setZero(n + 1);
    sv_.setZero(n + 1);
    // the coordinates each constraint reads, off its tape: a definition (a named
    // subexpression on the main tape) may read any, so a constraint reading one (or any
    // variable but a coordinate or t) is taken to depend on all of them
    for (const Expression& e : system_->constraints) {
      std::vector<char> reads(static_cast<std::size_t>(n), 0);
      bool all = false;
      e.for_each_variable([&](int block, int index) {
        if (block == 0 && index >= 0 && index < n)
          reads[static_cast<std::size_t>(index)] = 1;
        else if (!(block == 0 && index == n))
          all = true;
      });
      std::vector<int> row;
      for (int j = 0; j < n; ++j)
        if (all || reads[static_cast<std::size_t>(j)]) row.push_back(j);
      entries_ += row.size();
      pattern_.push_back(std::move(row));
    }
  }

  // The most gradient entries, count() x (dim() + 1), that the constraints' derivative
  // programs are built for (each holds its n + 1 outputs).
  static constexpr double kMaxProgramEntries = 1 << 20;

  int dim() const { return system_->dim(); }
  int count() const { return static_cast<int>(system_->constraints.size()); }

  // g(t, q) into g (size count()).
  template <class Q, class Out>
  void value(double t, const Q& q, Out& g) const {
    load(t, q);
    const int m = count();
    for (int i = 0; i < m; ++i) g[i] = system_->constraints[static_cast<std::size_t>(i)](qt_.data(), zero_.data());
  }

  // g, its Jacobian G(i, j) = dg_i/dq_j (count() x dim(), sized by the caller) and
  // g_t(i) = dg_i/dt.
  template <class Q, class Out, class Mat, class Out2>
  void jacobian(double t, const Q& q, Out& g, Mat& G, Out2& gt) const {
    gradients(t, q, G, gt);
    for (int i = 0; i < count(); ++i) g[i] = system_->constraints[static_cast<std::size_t>(i)](qt_.data(), zero_.data());
  }
  // G and g_t alone (the value is the tape's, the gradients the programs').
  template <class Q, class Mat, class Out2>
  void gradients(double t, const Q& q, Mat& G, Out2& gt) const {
    load(t, q);
    const int m = count(), n = dim();
    for (int i = 0; i < m; ++i) {
      row_gradient(static_cast<std::size_t>(i));
      for (int j = 0; j < n; ++j) G(i, j) = gq_[j];
      gt[i] = gq_[n];
    }
  }

  // Where Dg may be nonzero: row i lists, ascending, the coordinates constraint i reads
  // (all of them where it reads a definition); entries() in all.
  const std::vector<std::vector<int>>& pattern() const { return pattern_; }
  std::size_t entries() const { return entries_; }

  // Dg's entries in the order of pattern() (row by row) into G (entries() numbers) and
  // g_t into gt (count()), by reverse mode on each constraint's tape: O(the tapes'
  // length), nothing of size dim() per constraint, where gradients() fills dense rows.
  template <class Q>
  void sparse_gradients(double t, const Q& q, double* G, double* gt) const {
    load(t, q);
    const int m = count(), n = dim();
    std::size_t e = 0;
    for (int i = 0; i < m; ++i) {
      const auto k = static_cast<std::size_t>(i);
      // sq_ is zero outside a call: the tape adds to it, the entries read are cleared
      system_->constraints[k].gradient(qt_.data(), zero_.data(), sq_.data(), sv_.data());
      for (int j : pattern_[k]) {
        G[e++] = sq_[j];
        sq_[j] = 0.0;
      }
      gt[i] = sq_[n];
      sq_[n] = 0.0;
    }
  }

  // Throws std::logic_error where Dg at (t, q) has a nonzero entry outside pattern() (the
  // reading of the tapes missed a dependence; the sparse steps would drop it). Row by
  // row, as gradients() forms them: O(count() dim()) time, O(dim()) memory.
  void check_pattern(double t, const Eigen::VectorXd& q) const {
    const int m = count(), n = dim();
    load(t, q);
    for (int i = 0; i < m; ++i) {
      const auto k = static_cast<std::size_t>(i);
      row_gradient(k);
      const auto& r = pattern_[k];
      for (int j = 0; j < n; ++j)
        if (gq_[j] != 0.0 && !std::binary_search(r.begin(), r.end(), j))
          throw std::logic_error("constraint " + std::to_string(i + 1) + " depends on coordinate " + std::to_string(j + 1) +
                                 ", which its tape does not read");
    }
  }

  // The second derivatives at (t, q), for the derivative of a constrained step: H[i]
  // (dim() x dim()) receives the Hessian of g_i in q, and row i of Gqt the gradient in
  // q of dg_i/dt. Mat, Mat2: matrices of doubles (fixed maximum sizes will do). A Hessian
  // program per constraint is built at the first call, and the workspace; later calls
  // allocate only where H or Gqt must grow.
  template <class Q, class Mat, class Mat2>
  void second_derivatives(double t, const Q& q, std::vector<Mat>& H, Mat2& Gqt) const {
    const int m = count(), n = dim();
    if (hessians_.empty()) {
      for (const Expression& e : system_->constraints)
        hessians_.emplace_back(std::make_shared<const Expression>(e), n + 1, WrittenDerivatives::automatic);
      hga_.resize(n + 1);
      hgb_.resize(n + 1);
      Haa_.resize(n + 1, n + 1);
      Hab_.resize(n + 1, n + 1);
      Hbb_.resize(n + 1, n + 1);
    }
    load(t, q);
    if (H.size() != static_cast<std::size_t>(m)) H.resize(static_cast<std::size_t>(m));
    Gqt.resize(m, n);
    for (int i = 0; i < m; ++i) {
      hessians_[static_cast<std::size_t>(i)].hessian(qt_.data(), zero_.data(), hga_, hgb_, Haa_, Hab_, Hbb_);
      H[static_cast<std::size_t>(i)] = Haa_.topLeftCorner(n, n);
      Gqt.row(i) = Haa_.block(n, 0, 1, n);
    }
  }

  // The same second derivatives on the pattern, for the derivative of the sparse
  // constrained step: for constraint i, whose row of pattern() lists k coordinates, H
  // receives its Hessian in those coordinates (k x k, row by row) after the entries of
  // the constraints before it (hessian_entries() in all), and Gqt the gradient of dg_i/dt
  // in them (k entries, entries() in all). By forward mode over the reverse sweep of each
  // constraint's tape, in Jets seeded in 8 of its coordinates at a time: ceil(k / 8)
  // sweeps a constraint, nothing of size dim() per constraint.
  template <class Q>
  void sparse_second_derivatives(double t, const Q& q, double* H, double* Gqt) const {
    using J = ceres::Jet<double, kSecondChunk>;
    const int n = dim();
    if (jq_.size() != static_cast<std::size_t>(n + 1)) {
      jq_.assign(static_cast<std::size_t>(n + 1), J(0.0));
      jv_.assign(static_cast<std::size_t>(n + 1), J(0.0));
      jg_.assign(static_cast<std::size_t>(n + 1), J(0.0));
      jgv_.assign(static_cast<std::size_t>(n + 1), J(0.0));
    }
    // (the inputs' derivative parts, and the adjoints, are zero between sweeps: each
    // sweep clears the entries it seeded or that the tape wrote)
    for (int i = 0; i < n; ++i) jq_[static_cast<std::size_t>(i)].a = q[i];
    jq_[static_cast<std::size_t>(n)].a = t;
    std::size_t eh = 0, eg = 0;
    for (int c = 0; c < count(); ++c) {
      const std::vector<int>& row = pattern_[static_cast<std::size_t>(c)];
      const int k = static_cast<int>(row.size());
      for (int first = 0; first < k; first += kSecondChunk) {
        const int w = std::min(kSecondChunk, k - first);
        for (int d = 0; d < w; ++d) jq_[static_cast<std::size_t>(row[static_cast<std::size_t>(first + d)])].v[d] = 1.0;
        system_->constraints[static_cast<std::size_t>(c)].gradient(jq_.data(), jv_.data(), jg_.data(), jgv_.data());
        for (int a = 0; a < k; ++a) {
          const J& g = jg_[static_cast<std::size_t>(row[static_cast<std::size_t>(a)])];
          for (int d = 0; d < w; ++d) H[eh + static_cast<std::size_t>(a * k + first + d)] = g.v[d];
        }
        const J& gt = jg_[static_cast<std::size_t>(n)];
        for (int d = 0; d < w; ++d) Gqt[eg + static_cast<std::size_t>(first + d)] = gt.v[d];
        for (int d = 0; d < w; ++d) jq_[static_cast<std::size_t>(row[static_cast<std::size_t>(first + d)])].v[d] = 0.0;
        for (int j : row) jg_[static_cast<std::size_t>(j)] = J(0.0);
        jg_[static_cast<std::size_t>(n)] = J(0.0);
        if (k == n)  // (a row of all coordinates: the constraint may read a definition, which may
                     // read a velocity, zero here; a shorter row reads coordinates and t only)
          for (J& g : jgv_) g = J(0.0);
      }
      eh += static_cast<std::size_t>(k) * static_cast<std::size_t>(k);
      eg += static_cast<std::size_t>(k);
    }
  }
  // The number of entries of sparse_second_derivatives' H: the sum of k^2 over the rows.
  std::size_t hessian_entries() const {
    std::size_t e = 0;
    for (const auto& row : pattern_) e += row.size() * row.size();
    return e;
  }

  // The largest relative residuals of the constraint and of its hidden constraint at
  // (t, q) with velocity v (the measures of the header comment; a term whose
  // denominator is 0 counts its numerator).
  void relative_residuals(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& v, double& position,
                          double& velocity) const {
    row_terms(t, q, v, g_, gn_, across_);
    const double qn = q.norm(), vn = v.norm();
    position = velocity = 0.0;
    for (int i = 0; i < count(); ++i) {
      const double gn = gn_[i], a = std::fabs(g_[i]), b = std::fabs(across_[i]);
      position = std::fmax(position, gn * qn > 0.0 ? a / (gn * qn) : a);
      velocity = std::fmax(velocity, gn * vn > 0.0 ? b / (gn * vn) : b);
    }
  }

  // The terms of those measures, per constraint i at (t, q) with velocity v: g_i,
  // |grad g_i| and grad g_i . v + dg_i/dt (each resized to count()), from the sparse
  // rows (no count() x dim() matrix).
  void row_terms(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& v, Eigen::VectorXd& g,
                 Eigen::VectorXd& norm, Eigen::VectorXd& across) const {
    const int m = count();
    g.resize(m);
    norm.resize(m);
    across.resize(m);
    sparse_.resize(static_cast<Eigen::Index>(entries_));
    sparse_gradients(t, q, sparse_.data(), across.data());  // (g_t first)
    value(t, q, g);
    std::size_t e = 0;
    for (int i = 0; i < m; ++i) {
      double gn = 0.0;
      for (int j : pattern_[static_cast<std::size_t>(i)]) {
        const double a = sparse_[static_cast<Eigen::Index>(e++)];
        gn += a * a;
        across[i] += a * v[j];
      }
      norm[i] = std::sqrt(gn);
    }
  }

 private:
  // constraint k's gradient in (q, t) at the loaded point into gq_ (n + 1 entries)
  void row_gradient(std::size_t k) const {
    if (programs_[k]) {
      programs_[k]->gradient(qt_.data(), zero_.data(), gq_.data(), gv_.data(), slots_[k].data());
    } else {
      gq_.setZero();
      gv_.setZero();
      system_->constraints[k].gradient(qt_.data(), zero_.data(), gq_.data(), gv_.data());
    }
  }
  template <class Q>
  void load(double t, const Q& q) const {
    const int n = dim();
    for (int i = 0; i < n; ++i) qt_[i] = q[i];
    qt_[n] = t;
  }

  std::shared_ptr<const WrittenSystem> system_;
  std::vector<std::shared_ptr<const DerivativeProgram>> programs_;  // per constraint, or null
  mutable std::vector<std::vector<double>> slots_;                  // their workspaces
  mutable std::vector<dynamic_detail::TapeDerivatives> hessians_;   // second_derivatives()'s
  static constexpr int kSecondChunk = 8;  // sparse_second_derivatives' directions a sweep
  mutable std::vector<ceres::Jet<double, kSecondChunk>> jq_, jv_, jg_, jgv_;  // and its Jets
  mutable Eigen::VectorXd hga_, hgb_;                                // and their workspace
  mutable Eigen::MatrixXd Haa_, Hab_, Hbb_;
  mutable Eigen::VectorXd qt_, zero_, gq_, gv_;  // (q, t), a zero velocity block, one gradient
  mutable Eigen::VectorXd sq_, sv_;  // sparse_gradients()'s, zero between calls
  mutable Eigen::VectorXd g_, gn_, across_, sparse_;  // relative_residuals()'s
  std::vector<std::vector<int>> pattern_;  // the coordinates each constraint reads
  std::size_t entries_ = 0;
};

}  // namespace dvm
