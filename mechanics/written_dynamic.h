// Lagrangians and Hamiltonians written in a scene as run-time-sized systems
// (mechanics/dynamic_system.h: the concept and how WrittenDynamic differentiates its
// text; mechanics/written_lagrangian.h: the text).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/dense_solve.h"
#include "core/scalar.h"
#include "mechanics/derivative_program.h"
#include "mechanics/dynamic_system.h"
#include "mechanics/native_code.h"
#include "mechanics/structure.h"
#include "mechanics/written_lagrangian.h"

namespace dvm {

// ---------------------------------------------------------------------------------
// Written expressions (mechanics/expression.h) differentiated in doubles for any n.

// How a written tape is differentiated: automatic = a DerivativeProgram
// (mechanics/derivative_program.h) where one is built, else reverse mode on the tape
// (forward over reverse for the Hessian); compiled = that program compiled to machine
// code (mechanics/native_code.h; NativeCodeError where there is none to compile); the
// other two force the tape one way (forward over forward is kept to check reverse mode
// against).
enum class WrittenDerivatives { automatic, forward_over_reverse, forward_over_forward, compiled };

namespace dynamic_detail {

// Value, gradient and Hessian of a tape in two blocks of n variables (block 0 = a,
// block 1 = b), with workspace sized at construction.
class TapeDerivatives {
 public:
  static constexpr int kForwardChunk = 8;

  TapeDerivatives(std::shared_ptr<const Expression> e, int n, WrittenDerivatives mode) : e_(std::move(e)), n_(n) {
    reverse_ = mode != WrittenDerivatives::forward_over_forward;
    if (mode == WrittenDerivatives::automatic || mode == WrittenDerivatives::compiled) {
      program_ = DerivativeProgram::build(*e_, n);
      if (!program_) program_ = DerivativeProgram::build(*e_, n, false);  // the gradient at least
    }
    if (program_) slots_ = program_->workspace();
    const std::size_t m = static_cast<std::size_t>(2 * n);
    if (reverse_) {
      chunk_ = 2 * n <= 2 ? 2 : (2 * n <= 4 ? 4 : 8);
      if (chunk_ == 2) j2_.resize(2 * m);
      if (chunk_ == 4) j4_.resize(2 * m);
      if (chunk_ == 8) j8_.resize(2 * m);
    } else {
      chunk_ = kForwardChunk;
      j8_.resize(2 * m);
      jj_.resize(m);
    }
  }

  bool reverse() const { return reverse_; }
  int chunk() const { return chunk_; }
  // The derivative program, or null when the tape is differentiated as it runs.
  const DerivativeProgram* program() const { return program_.get(); }
  // The same program compiled (DerivativeProgram::with_native) in its place, and the
  // seconds compiling it took.
  void use_compiled(std::shared_ptr<const DerivativeProgram> p, double seconds) {
    program_ = std::move(p);
    compile_seconds_ = seconds;
  }
  double compile_seconds() const { return compile_seconds_; }
  // Whether the gradient and Hessian run compiled code.
  bool compiled() const { return program_ && program_->compiled(); }
  const Expression& expression() const { return *e_; }

  double value(const double* a, const double* b) const { return (*e_)(a, b); }

  void gradient(const double* a, const double* b, DynOut ga, DynOut gb) const {
    if (program_) {
      program_->gradient(a, b, ga.data(), gb.data(), slots_.data());
      return;
    }
    if (reverse_) {
      ga.setZero();
      gb.setZero();
      e_->gradient(a, b, ga.data(), gb.data());
      return;
    }
    using J = ceres::Jet<double, kForwardChunk>;
    const int m = 2 * n_;
    J* in = j8_.data();
    for (int d0 = 0; d0 < m; d0 += kForwardChunk) {
      load(in, a, b);
      for (int k = 0; k < kForwardChunk && d0 + k < m; ++k) in[d0 + k].v[k] = 1.0;
      const J y = (*e_)(in, in + n_);
      for (int k = 0; k < kForwardChunk && d0 + k < m; ++k) {
        const int d = d0 + k;
        if (d < n_)
          ga[d] = y.v[k];
        else
          gb[d - n_] = y.v[k];
      }
    }
  }

  void hessian(const double* a, const double* b, DynOut ga, DynOut gb, DynMatOut Haa, DynMatOut Hab,
               DynMatOut Hbb) const {
    if (program_ && program_->has_hessian()) {
      program_->hessian(a, b, ga.data(), gb.data(), Haa.data(), static_cast<int>(Haa.outerStride()), Hab.data(),
                        static_cast<int>(Hab.outerStride()), Hbb.data(), static_cast<int>(Hbb.outerStride()), slots_.data());
      return;
    }
    if (!reverse_) return forward_over_forward(a, b, ga, gb, Haa, Hab, Hbb);
    switch (chunk_) {
      case 2: return forward_over_reverse<2>(j2_.data(), a, b, ga, gb, Haa, Hab, Hbb);
      case 4: return forward_over_reverse<4>(j4_.data(), a, b, ga, gb, Haa, Hab, Hbb);
      default: return forward_over_reverse<8>(j8_.data(), a, b, ga, gb, Haa, Hab, Hbb);
    }
  }

 private:
  template <class J>
  void load(J* in, const double* a, const double* b) const {
    for (int i = 0; i < n_; ++i) {
      in[i] = J(a[i]);
      in[n_ + i] = J(b[i]);
    }
  }

  // The reverse gradient in Jets seeded in directions d0..d0+K-1 of the 2n inputs
  // gives columns d0..d0+K-1 of the Hessian: ceil(2n/K) passes.
  template <int K>
  void forward_over_reverse(ceres::Jet<double, K>* w, const double* a, const double* b, DynOut ga, DynOut gb,
                            DynMatOut Haa, DynMatOut Hab, DynMatOut Hbb) const {
    using J = ceres::Jet<double, K>;
    const int n = n_, m = 2 * n;
    J* in = w;
    J* out = w + m;
    for (int d0 = 0; d0 < m; d0 += K) {
      load(in, a, b);
      for (int i = 0; i < m; ++i) out[i] = J(0.0);
      for (int k = 0; k < K && d0 + k < m; ++k) in[d0 + k].v[k] = 1.0;
      e_->gradient(in, in + n, out, out + n);
      if (d0 == 0)
        for (int i = 0; i < n; ++i) {
          ga[i] = out[i].a;
          gb[i] = out[n + i].a;
        }
      for (int k = 0; k < K && d0 + k < m; ++k) {
        const int d = d0 + k;
        if (d < n) {
          for (int i = 0; i < n; ++i) Haa(i, d) = out[i].v[k];
        } else {
          for (int i = 0; i < n; ++i) {
            Hab(i, d - n) = out[i].v[k];
            Hbb(i, d - n) = out[n + i].v[k];
          }
        }
      }
    }
  }

  // Jet<Jet<double, 8>, 8>: the inner level seeded in chunk c1, the outer in chunk
  // c2 >= c1, gives the Hessian block (c1, c2); diagonal chunks give the gradient.
  void forward_over_forward(const double* a, const double* b, DynOut ga, DynOut gb, DynMatOut Haa, DynMatOut Hab,
                            DynMatOut Hbb) const {
    constexpr int K = kForwardChunk;
    using J = ceres::Jet<double, K>;
    using JJ = ceres::Jet<J, K>;
    const int n = n_, m = 2 * n;
    JJ* in = jj_.data();
    auto store = [&](int r, int c, double h) {
      if (r > c) std::swap(r, c);
      if (c < n) {
        Haa(r, c) = h;
        Haa(c, r) = h;
      } else if (r >= n) {
        Hbb(r - n, c - n) = h;
        Hbb(c - n, r - n) = h;
      } else {
        Hab(r, c - n) = h;
      }
    };
    for (int c1 = 0; c1 < m; c1 += K)
      for (int c2 = c1; c2 < m; c2 += K) {
        for (int i = 0; i < m; ++i) {
          J x(i < n ? a[i] : b[i - n]);
          if (i >= c1 && i < c1 + K) x.v[i - c1] = 1.0;
          in[i] = JJ(x);
          if (i >= c2 && i < c2 + K) in[i].v[i - c2] = J(1.0);
        }
        const JJ y = (*e_)(in, in + n);
        if (c1 == c2)
          for (int k = 0; k < K && c1 + k < m; ++k) {
            const int d = c1 + k;
            if (d < n)
              ga[d] = y.a.v[k];
            else
              gb[d - n] = y.a.v[k];
          }
        for (int k2 = 0; k2 < K && c2 + k2 < m; ++k2)
          for (int k1 = 0; k1 < K && c1 + k1 < m; ++k1) store(c1 + k1, c2 + k2, y.v[k2].v[k1]);
      }
  }

  std::shared_ptr<const Expression> e_;
  std::shared_ptr<const DerivativeProgram> program_;
  mutable std::vector<double> slots_;  // the program's workspace
  int n_;
  bool reverse_ = true;
  int chunk_ = 8;
  mutable std::vector<ceres::Jet<double, 2>> j2_;
  mutable std::vector<ceres::Jet<double, 4>> j4_;
  mutable std::vector<ceres::Jet<double, 8>> j8_;
  mutable std::vector<ceres::Jet<ceres::Jet<double, kForwardChunk>, kForwardChunk>> jj_;
  double compile_seconds_ = 0.0;
};

inline const WrittenSystem& checked_written(const std::shared_ptr<const WrittenSystem>& s) {
  if (!s || s->dim() < 1) throw std::invalid_argument("a written system needs at least one coordinate");
  if (s->space != WrittenSystem::Space::euclidean)
    throw std::invalid_argument(s->name + ": a Lagrangian written on S^2 or SO(3) runs on its manifold's steps");
  if (s->lagrangian.empty()) throw std::invalid_argument(s->name + ": the written system has no Lagrangian");
  return *s;
}

// WrittenDerivatives::compiled: the tape's program and `also` (a second program, or
// null) compiled in one run of the compiler; the tape takes its compiled program and
// the second compiled program is returned (null if none was given).
inline std::shared_ptr<const DerivativeProgram> compile_programs_of(TapeDerivatives& tape, const std::string& name,
                                                                   const std::shared_ptr<const DerivativeProgram>& also) {
  if (!tape.program())
    throw NativeCodeError(name + ": compiled derivatives: the text's derivative graph exceeds 2^16 operations; it is "
                                 "differentiated on the tape");
  std::vector<const DerivativeProgram*> p{tape.program()};
  if (also) p.push_back(also.get());
  double seconds = 0.0;
  auto c = compile_programs(p, default_c_compiler(), &seconds);
  tape.use_compiled(c[0], seconds);
  return also ? c[1] : nullptr;
}

}  // namespace dynamic_detail

// What the text of a written Lagrangian says about its structure, and for a separable
// one (v^T M v / 2 + U(q), M constant) its two parts and M.
struct WrittenParts {
  VelocitySplit split;
  Expression kinetic, potential;  // when split.constant_mass: L = kinetic + potential
  bool separable = false;         // constant_mass and M positive definite
  // L(t, q, v) = v^T M v / 2 + U(t, q) with M constant in q and t (its only structure
  // read: the SODE and Newmark steps then evaluate L itself at their times)
  bool timed_constant_mass = false;
  Eigen::VectorXd mass_diagonal;  // M when split.diagonal
  Eigen::VectorXd inverse_mass;   // and its reciprocals (v = p * (1/m): the explicit steps
                                  // carry v in their chain from force to force, where a
                                  // division would cost 3 to 4 times a product's latency)
  double uniform_inverse_mass = 0.0;  // 1/m when every diagonal entry is m (else 0): a
                                      // scalar product, no array of reciprocals read
  Eigen::MatrixXd mass;           // M otherwise, with its Cholesky factor
  Eigen::LLT<Eigen::MatrixXd> mass_factor;
  std::vector<bool> cyclic;       // coordinates L does not depend on
  // The potential's gradient as a DerivativeProgram (separable only; null where none
  // is built: then its tape's reverse mode).
  std::shared_ptr<const DerivativeProgram> potential_program;
  // When quadratic with M depending on q (and n <= Expression::kMaxMassDim): the
  // entries of M(q) read off the text (Expression::split_mass), upper triangle row by
  // row, and U(q), its terms free of the velocities (`potential` then holds U).
  std::vector<Expression> mass_entries;
  bool has_mass_entries() const { return !mass_entries.empty(); }
  // Those entries and U(q) as one program (DerivativeProgram::build_values), outputs in
  // that order; null where none is built (then each tape is evaluated).
  std::shared_ptr<const DerivativeProgram> mass_program;

  // A full M is formed from n gradients of the kinetic tape and factored; beyond this
  // size (a dense factor of 8 n^2 bytes) such a system takes the generic path.
  static constexpr int kMaxDenseMass = 2000;

  explicit WrittenParts(const WrittenSystem& w) {
    const int n = w.dim();
    cyclic.assign(static_cast<std::size_t>(n), true);
    w.lagrangian.for_each_variable([&](int block, int index) {
      if (block == 0 && index < n) cyclic[static_cast<std::size_t>(index)] = false;  // (index n: the time)
    });
    // L(t, q, v): no parts are read off the text (they would read t, which the
    // structured steps and closed forms do not pass); the general path, Newton's
    // method for v = FL^{-1}(t, q, p). Only whether M is constant (t counts as a
    // coordinate: a kinetic term in t is not constant).
    if (w.time_dependent()) {
      const VelocitySplit s = Expression::split_velocity(w.lagrangian.text(), w.symbols(WrittenSystem::Kind::lagrangian));
      timed_constant_mass = s.constant_mass && s.kinetic_terms > 0;
      return;
    }
    split = Expression::split_velocity(w.lagrangian.text(), w.symbols(WrittenSystem::Kind::lagrangian), &kinetic,
                                       &potential);
    if (split.quadratic && !split.constant_mass) {
      try {
        Expression::split_mass(w.lagrangian.text(), w.symbols(WrittenSystem::Kind::lagrangian), n, mass_entries,
                               potential);
      } catch (const ExpressionError&) {  // a limit met by the rewritten entries (the text itself
        mass_entries.clear();             // parsed above): M then comes from gradients
      }
      if (has_mass_entries()) {
        std::vector<const Expression*> tapes;
        for (const Expression& e : mass_entries) tapes.push_back(&e);
        tapes.push_back(&potential);
        mass_program = DerivativeProgram::build_values(tapes, n);
      }
    }
    if (!split.constant_mass || split.kinetic_terms == 0) return;
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(n);
    Eigen::VectorXd e(n), g0(n), g1(n);
    auto mass_times = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) {  // M v = dT/dv
      g0.setZero();
      out.setZero(n);
      kinetic.gradient(zero.data(), v.data(), g0.data(), out.data());
    };
    if (split.diagonal) {
      mass_times(Eigen::VectorXd::Ones(n), mass_diagonal);
      separable = (mass_diagonal.array() > 0.0).all() && mass_diagonal.allFinite();
      inverse_mass = mass_diagonal.cwiseInverse();
      if (separable && (mass_diagonal.array() == mass_diagonal[0]).all()) uniform_inverse_mass = inverse_mass[0];
      if (separable) potential_program = DerivativeProgram::build(potential, n, false);
      return;
    }
    if (n > kMaxDenseMass) return;
    Eigen::MatrixXd M(n, n);
    for (int j = 0; j < n; ++j) {
      e.setZero();
      e[j] = 1.0;
      mass_times(e, g1);
      M.col(j) = g1;
    }
    mass_factor.compute(M);
    separable = M.allFinite() && mass_factor.info() == Eigen::Success;
    mass = std::move(M);
    if (separable) potential_program = DerivativeProgram::build(potential, n, false);
  }
  // v = M^{-1} p (separable only)
  // (loops on the entries: on a vector of run-time size of a few coordinates they cost
  // less than Eigen's vectorised expression, which first checks the alignment, and as
  // much on one or on many; the run's energy solves this every step)
  void velocity(const DynIn& p, DynOut v) const {
    const Eigen::Index n = p.size();
    const double* in = p.data();
    double* out = v.data();
    if (uniform_inverse_mass != 0.0) {
      const double c = uniform_inverse_mass;
      for (Eigen::Index i = 0; i < n; ++i) out[i] = in[i] * c;
    } else if (split.diagonal) {
      const double* w = inverse_mass.data();
      for (Eigen::Index i = 0; i < n; ++i) out[i] = in[i] * w[i];
    } else {
      v = mass_factor.solve(p);
    }
  }
};

// A written Lagrangian (written_lagrangian.h) of any dimension.
class WrittenDynamic {
 public:
  explicit WrittenDynamic(std::shared_ptr<const WrittenSystem> s,
                          WrittenDerivatives mode = WrittenDerivatives::automatic)
      : system_(std::move(s)),
        timed_(dynamic_detail::checked_written(system_).time_dependent()),
        tape_(std::shared_ptr<const Expression>(system_, &system_->lagrangian), system_->dim() + (timed_ ? 1 : 0),
              mode),
        parts_(parts_of(*system_, mode, tape_)),
        Lq_(system_->dim()),
        Lv_(system_->dim()) {
    if (timed_) time_ = Timed(system_->dim());
  }

  // The structure read off the text, and for a separable L its parts.
  const WrittenParts& parts() const { return *parts_; }
  bool separable() const { return parts_->separable; }
  // v = FL^{-1}(q, p) where the text's structure gives it by a linear solve: v = M^{-1} p
  // for a separable L (M constant, factored once), and v = M(q)^{-1} p for a text that is
  // quadratic in the velocities, L = v^T M(q) v / 2 + U(q) (p = M(q) v; M(q) from the
  // entries read off the text (WrittenParts::mass_entries), else column i of M(q) is
  // L_v(q, e_i), a gradient each; then factored). Returns false otherwise, and
  // where M(q) is singular: Newton's method then (which reports the degeneracy).
  bool closed_velocity(const DynIn& q, const DynIn& p, DynOut v) const {
    if (parts_->separable) {
      parts_->velocity(p, v);
      return true;
    }
    if (!parts_->split.quadratic) return false;
    return mass_velocity(q, p, v);
  }

  int dim() const { return system_->dim(); }
  std::string name() const { return system_->name; }
  const std::shared_ptr<const WrittenSystem>& system() const { return system_; }
  // Whether derivatives go through reverse mode (else the tape is differentiated forward).
  bool reverse_mode() const { return tape_.reverse(); }
  // The derivative program the gradient and Hessian come from, or null (the tape).
  const DerivativeProgram* derivative_program() const { return tape_.program(); }
  // Whether its derivatives run compiled code (WrittenDerivatives::compiled), and the
  // seconds the compiler took.
  bool compiled() const { return tape_.compiled(); }
  double compile_seconds() const { return tape_.compile_seconds(); }

  // L(t, q, v): whether the text reads t, and the t the evaluations below read (0 until
  // set). The tape then runs on n + 1 inputs per block, (q, t) and (v, 0), and the
  // derivatives in t are dropped.
  bool time_dependent() const { return timed_; }
  void set_time(double t) const { time_.t = t; }

  double value(const DynIn& q, const DynIn& v) const {
    if (timed_) return tape_.value(time_.load(q, v), time_.v.data());
    return tape_.value(q.data(), v.data());
  }
  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const {
    if (timed_) {
      Timed& w = time_;
      tape_.gradient(w.load(q, v), w.v.data(), w.gq, w.gv);
      const Eigen::Index n = Lq.size();
      Lq = w.gq.head(n);
      Lv = w.gv.head(n);
      return;
    }
    tape_.gradient(q.data(), v.data(), Lq, Lv);
  }
  void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
               DynMatOut Lvv) const {
    if (timed_) {
      Timed& w = time_;
      w.size_hessians();
      tape_.hessian(w.load(q, v), w.v.data(), w.gq, w.gv, w.Hqq, w.Hqv, w.Hvv);
      const Eigen::Index n = Lq.size();
      Lq = w.gq.head(n);
      Lv = w.gv.head(n);
      Lqq = w.Hqq.topLeftCorner(n, n);
      Lqv = w.Hqv.topLeftCorner(n, n);
      Lvv = w.Hvv.topLeftCorner(n, n);
      return;
    }
    tape_.hessian(q.data(), v.data(), Lq, Lv, Lqq, Lqv, Lvv);
  }

  // The monitored energy at (q, p) with v = FL^{-1}(q, p): the written one if given,
  // else E_L = <L_v, v> - L = <p, v> - L(q, v) (L_v(q, v) = p, to the tolerance v was
  // solved to); for L = v^T M v / 2 + U(q), M constant or with its entries read off the
  // text, that is <p, v> / 2 - U(q): U's terms evaluated, not L's. (A separable text's U
  // is its terms of degree 0 in the velocities, which may still name one, as x_dot^0.)
  double energy_at(const DynIn& q, const DynIn& v, const DynIn& p) const {
    if (!system_->energy.empty()) return system_->energy(q.data(), v.data(), p.data());
    if (parts_->has_mass_entries()) return 0.5 * p.dot(v) - mass_and_potential(q)[mass_work().potential];
    if (parts_->separable) return 0.5 * p.dot(v) - parts_->potential(q.data(), v.data());
    return p.dot(v) - value(q, v);
  }
  bool has_hamiltonian() const { return !system_->hamiltonian.empty(); }
  double hamiltonian(const DynIn& q, const DynIn& p) const {
    return system_->hamiltonian(q.data(), static_cast<const double*>(nullptr), p.data());
  }
  // A coordinate that L does not depend on is cyclic: its momentum is conserved.
  bool cyclic(int i) const { return parts_->cyclic[static_cast<std::size_t>(i)]; }

 private:
  // The parts read off the text; compiled: L's program and the potential's in one run.
  static std::shared_ptr<const WrittenParts> parts_of(const WrittenSystem& s, WrittenDerivatives mode,
                                                      dynamic_detail::TapeDerivatives& tape) {
    auto parts = std::make_shared<WrittenParts>(s);
    if (mode == WrittenDerivatives::compiled)
      parts->potential_program = dynamic_detail::compile_programs_of(tape, s.name, parts->potential_program);
    return parts;
  }
  // closed_velocity for a text quadratic in the velocities: v = M(q)^{-1} p.
  bool mass_velocity(const DynIn& q, const DynIn& p, DynOut v) const {
    Mass& m = mass_work();
    if (parts_->has_mass_entries()) {
      const int n = dim();
      const double* entries = mass_and_potential(q);
      std::size_t k = 0;
      for (int i = 0; i < n; ++i)
        for (int j = i; j < n; ++j, ++k) m.M(i, j) = m.M(j, i) = entries[k];
    } else {
      for (int i = 0; i < dim(); ++i) {
        m.unit[i] = 1.0;
        gradient(q, m.unit, Lq_, Lv_);
        m.M.col(i) = Lv_;
        m.unit[i] = 0.0;
      }
    }
    if (dim() == 2) {
      // two degrees of freedom (common): Cramer's rule, one division where an
      // elimination waits on two in a row (the run's energy solves this every step).
      // Singular where DenseLU finds it so: a pivot not above 1e-14 max |M_ij|, the
      // first pivot max(|a|, |c|), the second |det| over the first.
      const double a = m.M(0, 0), b = m.M(0, 1), c = m.M(1, 0), d = m.M(1, 1);
      const double first = std::fmax(std::fabs(a), std::fabs(c));
      const double tiny = 1e-14 * std::fmax(first, std::fmax(std::fabs(b), std::fabs(d)));
      const double det = a * d - b * c;
      if (!(first > tiny) || !(std::fabs(det) > tiny * first) || !std::isfinite(det)) return false;
      const double r = 1.0 / det, p0 = p[0], p1 = p[1];
      v[0] = (d * p0 - b * p1) * r;
      v[1] = (a * p1 - c * p0) * r;
    } else {
      if (!m.lu.factor(m.M)) return false;
      m.lu.solve(p, v);
    }
    return v.allFinite();
  }

  // Workspace of closed_velocity for a text quadratic in the velocities (M(q) and its LU).
  struct Mass {
    Mass() = default;
    explicit Mass(int n, const DerivativeProgram* program)
        : unit(Eigen::VectorXd::Zero(n)),
          M(n, n),
          lu(n),
          potential(static_cast<std::size_t>(n * (n + 1) / 2)),
          values(potential + 1),
          at(Eigen::VectorXd::Constant(n, std::numeric_limits<double>::quiet_NaN())) {
      if (program) work = program->workspace();
    }
    Eigen::VectorXd unit;  // e_i, zero between uses
    Eigen::MatrixXd M;
    DenseLU lu;
    // With the entries read off the text: their values and U's (the last) at q = `at`
    // (NaN until the first evaluation), and the workspace of their program.
    std::size_t potential = 0;
    std::vector<double> values, work;
    Eigen::VectorXd at;
  };
  // The entries of M(q), upper triangle row by row, then U(q), evaluated once per q: the
  // run's energy at q_k reads U(q_k) after v = M(q_k)^{-1} p_k was solved there.
  const double* mass_and_potential(const DynIn& q) const {
    Mass& m = mass_work();
    if (m.at == q) return m.values.data();
    if (const DerivativeProgram* prog = parts_->mass_program.get()) {
      prog->values(q.data(), nullptr, m.values.data(), m.work.data());
    } else {
      for (std::size_t k = 0; k < m.potential; ++k) m.values[k] = parts_->mass_entries[k](q.data());
      m.values[m.potential] = parts_->potential(q.data());
    }
    m.at = q;
    return m.values.data();
  }
  // The time and the tape's inputs and outputs of n + 1 entries (L(t, q, v) only).
  struct Timed {
    Timed() = default;
    explicit Timed(int n) : q(Eigen::VectorXd::Zero(n + 1)), v(Eigen::VectorXd::Zero(n + 1)), gq(n + 1), gv(n + 1) {}
    // the (n + 1) x (n + 1) blocks, at the first Hessian (a run that asks for none, an
    // explicit step of thousands of coordinates, holds none)
    void size_hessians() {
      const Eigen::Index m = q.size();
      if (Hqq.rows() == m) return;
      Hqq.resize(m, m);
      Hqv.resize(m, m);
      Hvv.resize(m, m);
    }
    // (q, t) and (v, 0); returns the first
    const double* load(const DynIn& qi, const DynIn& vi) {
      const Eigen::Index n = qi.size();
      q.head(n) = qi;
      q[n] = t;
      v.head(n) = vi;
      return q.data();
    }
    double t = 0.0;
    Eigen::VectorXd q, v, gq, gv;
    Eigen::MatrixXd Hqq, Hqv, Hvv;
  };
  std::shared_ptr<const WrittenSystem> system_;
  bool timed_;
  dynamic_detail::TapeDerivatives tape_;
  std::shared_ptr<const WrittenParts> parts_;
  mutable Eigen::VectorXd Lq_, Lv_;
  // mass_'s workspace for a text quadratic in the velocities and not separable, sized at
  // its first use (the n x n M(q) and its factorisation: a run refused for its size, or a
  // copy of L made before any use, holds none)
  Mass& mass_work() const {
    if (mass_.unit.size() != dim()) mass_ = Mass(dim(), parts_->mass_program.get());
    return mass_;
  }
  mutable Mass mass_;
  mutable Timed time_;   // sized only for L(t, q, v)
};

// A written Lagrangian whose text is separable (WrittenDynamic::separable()), seen as a
// system that declares it (mechanics/structure.h), for the explicit steps of
// solvers/splitting_step.h: dL/dq is the reverse gradient of the potential's tape only,
// dL/dv = M v, v = M^{-1} p.
class WrittenSeparable {
 public:
  static constexpr Structure structure = Structure::separable;
  explicit WrittenSeparable(const WrittenDynamic& L) : L_(L), parts_(&L.parts()) {
    if (!L.separable()) throw std::invalid_argument(L.name() + ": the written Lagrangian is not separable");
    if (parts_->potential_program) work_ = parts_->potential_program->workspace();
  }
  int dim() const { return L_.dim(); }
  std::string name() const { return L_.name(); }
  double value(const DynIn& q, const DynIn& v) const { return L_.value(q, v); }
  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const {
    if (parts_->potential_program) {  // U has no v: Lv receives zeros, then M v
      parts_->potential_program->gradient(q.data(), v.data(), Lq.data(), Lv.data(), work_.data());
    } else {
      Lq.setZero();
      parts_->potential.gradient(q.data(), v.data(), Lq.data(), Lv.data());  // U has no v: Lv untouched
    }
    if (parts_->split.diagonal)
      Lv = v.cwiseProduct(parts_->mass_diagonal);
    else if (v.isZero(0.0))  // the force alone (the explicit steps ask at v = 0)
      Lv.setZero();
    else
      Lv.noalias() = parts_->mass * v;
  }
  void velocity(const DynIn&, const DynIn& p, DynOut v) const { parts_->velocity(p, v); }
  // dL/dq at v = 0, the force of the explicit steps: U's gradient alone, nothing of v
  // read or formed
  void force(const DynIn& q, DynOut F) const {
    if (parts_->potential_program) {
      parts_->potential_program->gradient(q.data(), zero_.data(), F.data(), nullptr, work_.data());
    } else {
      F.setZero();
      parts_->potential.gradient(q.data(), zero_.data(), F.data(), lv_.data());  // U has no v: lv_ untouched
    }
  }

 private:
  WrittenDynamic L_;  // holds the parts alive
  const WrittenParts* parts_;
  mutable std::vector<double> work_;  // the potential program's workspace
  Eigen::VectorXd zero_ = Eigen::VectorXd::Zero(L_.dim());  // v = 0 (U reads none of it)
  mutable Eigen::VectorXd lv_ = Eigen::VectorXd::Zero(L_.dim());
};

// The same separable view at a size known when it is compiled, K coordinates (the
// runtime makes K = 1 and 2): a system of fixed size (S::dim) for the explicit steps,
// whose force and velocity work on vectors of length K. dL/dq is the potential
// program's gradient (compiled where L was built with WrittenDerivatives::compiled) or
// the potential tape's reverse gradient; dL/dv = M v; v = M^{-1} p by M's diagonal or
// the Cholesky factor of M (2 x 2). L.dim() must be K and L separable.
template <int K>
class WrittenSeparableOf {
 public:
  static constexpr int dim = K;
  static constexpr Structure structure = Structure::separable;
  using V = Vec<double, K>;
  explicit WrittenSeparableOf(const WrittenDynamic& L) : L_(L), parts_(&L.parts()), program_(parts_->potential_program.get()) {
    if (L.dim() != K)
      throw std::invalid_argument(L.name() + ": " + std::to_string(L.dim()) + " coordinates, a step compiled for " +
                                  std::to_string(K));
    if (!L.separable()) throw std::invalid_argument(L.name() + ": the written Lagrangian is not separable");
    if (program_) work_ = program_->workspace();
    diagonal_ = parts_->split.diagonal;
    if (diagonal_) {
      mass_diagonal_ = parts_->mass_diagonal;
      inverse_mass_ = parts_->inverse_mass;
    } else {
      mass_ = parts_->mass;
      factor_.compute(mass_);
    }
  }
  std::string name() const { return L_.name(); }
  void gradient(const V& q, const V& v, V& Lq, V& Lv) const {
    if (program_) {
      program_->gradient(q.data(), v.data(), Lq.data(), Lv.data(), work_.data());
    } else {
      Lq.setZero();
      parts_->potential.gradient(q.data(), v.data(), Lq.data(), Lv.data());
    }
    Lv = diagonal_ ? V(v.cwiseProduct(mass_diagonal_)) : V(mass_ * v);
  }
  // dL/dq at v = 0 (as WrittenSeparable::force): U's gradient alone, no dL/dv formed
  void force(const V& q, V& F) const {
    const V zero = V::Zero();
    if (program_) {
      program_->gradient(q.data(), zero.data(), F.data(), nullptr, work_.data());
    } else {
      V lv;  // U has no v: untouched
      F.setZero();
      parts_->potential.gradient(q.data(), zero.data(), F.data(), lv.data());
    }
  }
  V velocity(const V&, const V& p) const { return diagonal_ ? V(p.cwiseProduct(inverse_mass_)) : V(factor_.solve(p)); }

 private:
  WrittenDynamic L_;  // holds the parts alive
  const WrittenParts* parts_;
  const DerivativeProgram* program_;
  mutable std::vector<double> work_;
  bool diagonal_ = true;
  V mass_diagonal_, inverse_mass_;
  Mat<double, K, K> mass_;
  Eigen::LLT<Mat<double, K, K>> factor_;
};

// The Hamiltonian H(q, p) written in a scene (system.hamiltonian), for the Hamiltonian
// form (Eq. 5.1) of any dimension. Block 1 of the concept is p.
class WrittenDynamicHamiltonian {
 public:
  explicit WrittenDynamicHamiltonian(std::shared_ptr<const WrittenSystem> s,
                                     WrittenDerivatives mode = WrittenDerivatives::automatic)
      : system_(std::move(s)), tape_(reparse(system_), system_->dim(), mode) {
    if (mode == WrittenDerivatives::compiled) dynamic_detail::compile_programs_of(tape_, name(), nullptr);
  }
  // Whether its derivatives run compiled code (WrittenDerivatives::compiled), and the
  // seconds the compiler took.
  bool compiled() const { return tape_.compiled(); }
  double compile_seconds() const { return tape_.compile_seconds(); }

  int dim() const { return system_->dim(); }
  std::string name() const { return system_->name.empty() ? "hamiltonian" : system_->name; }
  bool reverse_mode() const { return tape_.reverse(); }

  double value(const DynIn& q, const DynIn& p) const { return tape_.value(q.data(), p.data()); }
  void gradient(const DynIn& q, const DynIn& p, DynOut Hq, DynOut Hp) const {
    tape_.gradient(q.data(), p.data(), Hq, Hp);
  }
  void hessian(const DynIn& q, const DynIn& p, DynOut Hq, DynOut Hp, DynMatOut Hqq, DynMatOut Hqp,
               DynMatOut Hpp) const {
    tape_.hessian(q.data(), p.data(), Hq, Hp, Hqq, Hqp, Hpp);
  }

 private:
  // The scene's H parses with q as block 0 and p as block 2; reverse mode differentiates
  // blocks 0 and 1, so the same text is parsed again with p as block 1 (the same
  // names, constants and folding: the same tape up to the block index).
  static std::shared_ptr<const Expression> reparse(const std::shared_ptr<const WrittenSystem>& s) {
    if (!s || s->dim() < 1) throw std::invalid_argument("a written system needs at least one coordinate");
    if (s->space != WrittenSystem::Space::euclidean)
      throw std::invalid_argument(s->name + ": a Hamiltonian written on S^2 or SO(3) runs on its manifold's steps");
    if (s->hamiltonian.empty())
      throw std::invalid_argument(s->name + ": the Hamiltonian form needs a written Hamiltonian H(q, p)");
    ExpressionSymbols sym = s->symbols(WrittenSystem::Kind::hamiltonian);  // q: block 0, p: block 2
    for (auto& v : sym.variables)
      if (v.block == 2) v.block = 1;
    for (auto& a : sym.arrays)
      if (a.block == 2) a.block = 1;
    return std::make_shared<const Expression>(Expression::parse(s->hamiltonian.text(), sym));
  }

  std::shared_ptr<const WrittenSystem> system_;
  dynamic_detail::TapeDerivatives tape_;
};

// ---------------------------------------------------------------------------------

}  // namespace dvm
