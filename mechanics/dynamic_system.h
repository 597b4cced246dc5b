// Lagrangians and Hamiltonians of run-time size: systems on Q = R^n with n chosen at
// run time, which provide their own derivatives in doubles.
//
// A Lagrangian L : TQ -> R enters the step equations only through its first and
// second derivatives (solvers/dynamic_step.h, solvers/dynamic_galerkin_step.h):
//
//   gradient   L_q = dL/dq,  L_v = dL/dv                                  (n each)
//   Hessian    L_qq = d2L/dq2,  L_qv(i, j) = d2L/dq_i dv_j,  L_vv = d2L/dv2   (n x n)
//
// (L_vq = L_qv^T, so these three blocks are the whole symmetric 2n x 2n Hessian). From
// them (Abraham-Marsden, Foundations of Mechanics, Sec. 3.6; paper Sec. 5.1):
//
//   Legendre map       p = FL(q, v) = L_v(q, v)
//   energy             E_L(q, v) = <L_v(q, v), v> - L(q, v)
//   inverse Legendre   v = FL^{-1}(q, p): a closed form, or Newton's method on
//                      L_v(q, v) - p = 0 with the matrix L_vv (regularity: L_vv invertible)
//   Hamiltonian        H(q, p) = <p, v> - L(q, v),  v = FL^{-1}(q, p), with
//                      H_q = -L_q(q, v),  H_p = v,
//                      and, differentiating L_v(q, v(q, p)) = p (implicit functions),
//                      dv/dp = L_vv^{-1},  dv/dq = -L_vv^{-1} L_vq, hence
//                      H_pp = L_vv^{-1},  H_qp = -L_qv L_vv^{-1},
//                      H_qq = -L_qq + L_qv L_vv^{-1} L_qv^T:
//                      second derivatives of L suffice, no third ones.
//
// The concept. A run-time-sized system (Lagrangian in (q, v) or Hamiltonian in (q, p):
// the shape is the same, with the second block named v or p) is a type providing
//
//   int dim() const;                                   // n
//   std::string name() const;
//   double value(const DynIn& q, const DynIn& v) const;
//   void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const;
//   void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv,
//                DynMatOut Lqq, DynMatOut Lqv, DynMatOut Lvv) const;   // gradient too
// and optionally (detected by has_dynamic_velocity) the closed-form inverse Legendre map
//   void velocity(const DynIn& q, const DynIn& p, DynOut v) const;
//
// DynIn, DynOut, DynMatOut are Eigen::Ref of VectorXd / MatrixXd: a vector, a segment of
// one or a column of a matrix binds without a copy. Outputs must already have their sizes
// (n, n x n); an implementation then allocates nothing. Some implementations keep
// mutable workspace, so one object must not be used from two threads at once (copies
// are independent).
//
// Why. A fixed-size system (mechanics/lagrangian.h) is differentiated by nested
// ceres::Jet of its size, so every size is a separate compiled instantiation of every
// step. Here the size is data: a step type is compiled once per system type.
//
// Implementations (this header holds the concept, the generic Legendre maps and
// FixedAsDynamic; mechanics/nbody_dynamic.h NBodyDynamic; mechanics/written_dynamic.h
// the written systems, so that a file stepping only fixed-size systems compiles none
// of their code):
//   FixedAsDynamic<S>    any fixed-size Lagrangian of mechanics/: its closed-form
//                        gradient (or one Jet level) for L_q, L_v, and one Jet level of
//                        size 2 dim through the closed-form gradient (nested Jets when it
//                        has none) for the Hessian; its closed-form velocity if it has one.
//   NBodyDynamic         the N-body Lagrangian of NBody<B> (systems_classic.h) for any
//                        number of bodies: closed-form gradient, Hessian (one 3 x 3 block
//                        per pair) and velocity; total momentum and angular momentum.
//   WrittenDynamic       a WrittenSystem (written_lagrangian.h) of any dimension: the value
//                        by its tape in doubles; the gradient and the Hessian by a
//                        DerivativeProgram (mechanics/derivative_program.h: the tape
//                        differentiated symbolically once, run as straight-line double
//                        operations) where one is built: the Hessian up to 32
//                        coordinates for tapes without blocks, the gradient for any
//                        tape whose blocks read no definition. Otherwise the gradient by
//                        reverse mode (Expression::gradient), the Hessian by forward over
//                        reverse: the reverse gradient evaluated in ceres::Jet<double, K>,
//                        seeded in K of the 2n input directions per pass, ceil(2n/K)
//                        passes (K = 2, 4 or 8: the smallest >= 2n, else 8). Forced
//                        forward (WrittenDerivatives::forward_over_forward, for checking):
//                        the gradient in chunks of 8 directions, the Hessian by
//                        Jet<Jet<double, 8>, 8> over pairs of chunks (about (2n/8)^2 / 2
//                        passes). WrittenDerivatives::compiled: the programs (L's and,
//                        for a separable L, its potential's) compiled to machine code
//                        by the machine's C compiler in one run (mechanics/native_code.h),
//                        the same results to the bit; NativeCodeError where a program
//                        cannot be (blocks; a graph too large to build) or the compiler
//                        fails. A program is faster than the tape's forward over
//                        reverse for the gradient and the Hessian
//                        (bench_written_lagrangian measures both).
//                        Its structure is read off the text (Expression::split_velocity):
//                        when L = v^T M v / 2 + U(q) with M constant and positive definite
//                        (separable()), the inverse Legendre map is v = M^{-1} p in closed
//                        form (M diagonal: a product by 1/m; else a Cholesky factor) and
//                        WrittenSeparable views it as a declared separable system, whose
//                        force is the gradient of U alone (U's own program, or its tape).
//                        On the tape, the Hessian is by forward over reverse, which
//                        beat forward over forward at every size measured (1 to 6
//                        coordinates): where no program is built, that.
//   WrittenDynamicHamiltonian  the Hamiltonian H(q, p) written in a scene, the same way
//                        (its text is parsed a second time with p as the second block, so
//                        that reverse mode, which differentiates blocks 0 and 1, applies).
//   LegendreDynamicHamiltonian<Sys>  H of any run-time-sized Lagrangian by the Legendre
//                        transform above; regularity (reciprocal condition of L_vv, as
//                        mechanics/hamiltonian.h) is checked wherever L_vv^{-1} is formed,
//                        and a degenerate L throws DegenerateLagrangianError.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include "core/dense_solve.h"
#include "core/scalar.h"
#include "mechanics/lagrangian.h"

namespace dvm {

// (DynIn, DynOut, DynMatOut: core/dense_solve.h)

// Whether S is a run-time-sized system (the concept above).
template <class S, class = void>
struct is_dynamic_system : std::false_type {};
template <class S>
struct is_dynamic_system<
    S, std::void_t<decltype(int(std::declval<const S&>().dim())),
                   decltype(std::declval<const S&>().hessian(
                       std::declval<const DynIn&>(), std::declval<const DynIn&>(), std::declval<DynOut>(),
                       std::declval<DynOut>(), std::declval<DynMatOut>(), std::declval<DynMatOut>(),
                       std::declval<DynMatOut>()))>> : std::true_type {};
template <class S>
inline constexpr bool is_dynamic_system_v = is_dynamic_system<S>::value;

// Whether a run-time-sized system may depend on the time: void set_time(double t) const
// sets the t its next evaluations read (WrittenDynamic of a Lagrangian L(t, q, v)). The
// step equations set it at each node before they evaluate L (ThetaEquation at t0 +
// theta h, the Galerkin step at each quadrature node, the constrained step's projection
// at t0 + h); a run's view sets its own copy's at each monitored state.
template <class S, class = void>
struct has_time : std::false_type {};
template <class S>
struct has_time<S, std::void_t<decltype(std::declval<const S&>().set_time(0.0))>> : std::true_type {};

// Whether a run-time-sized Lagrangian has a closed-form inverse Legendre map.
template <class S, class = void>
struct has_dynamic_velocity : std::false_type {};
template <class S>
struct has_dynamic_velocity<S, std::void_t<decltype(std::declval<const S&>().velocity(
                                   std::declval<const DynIn&>(), std::declval<const DynIn&>(),
                                   std::declval<DynOut>()))>> : std::true_type {};

// Whether a run-time-sized Lagrangian may have a closed-form inverse Legendre map known
// only at run time: bool closed_velocity(q, p, v) const, true when it wrote v.
template <class S, class = void>
struct has_runtime_velocity : std::false_type {};
template <class S>
struct has_runtime_velocity<S, std::void_t<decltype(bool(std::declval<const S&>().closed_velocity(
                                   std::declval<const DynIn&>(), std::declval<const DynIn&>(),
                                   std::declval<DynOut>())))>> : std::true_type {};

namespace dynamic_detail {
using ::dvm::inf_norm;  // (core/scalar.h)
}  // namespace dynamic_detail


namespace dynamic_detail {

// 1 / (|W|_inf |W^{-1}|_inf), as velocity_hessian_rcond (mechanics/hamiltonian.h), in
// loops (no temporaries).
inline double rcond_inf(const Eigen::MatrixXd& W, const Eigen::MatrixXd& Winv) {
  auto norm = [](const Eigen::MatrixXd& A) {
    double m = 0.0;
    for (Eigen::Index i = 0; i < A.rows(); ++i) {
      double s = 0.0;
      for (Eigen::Index j = 0; j < A.cols(); ++j) s += std::fabs(A(i, j));
      if (std::isnan(s)) return s;
      if (s > m) m = s;
    }
    return m;
  };
  const double a = norm(W);
  if (!(a > 0.0) || !std::isfinite(a)) return 0.0;
  const double rc = 1.0 / (a * norm(Winv));
  return std::isfinite(rc) ? rc : 0.0;
}

template <class Sys>
[[noreturn]] void throw_not_regular(const Sys& L, const DynIn& q, const DynIn& v, double rc) {
  std::ostringstream msg;
  msg << L.name() << " is not regular at q = [" << q.transpose() << "], v = [" << v.transpose()
      << "]: the velocity Hessian d2L/dv2 is singular (reciprocal condition " << rc
      << "), so the Legendre map cannot be inverted and there is no Hamiltonian there";
  throw DegenerateLagrangianError(msg.str());
}

// Workspace of the Newton inverse of the Legendre map: three n x n blocks and a
// factorisation, sized by the first Newton iteration that needs them (legendre_newton),
// not before, so that a system whose velocity has a closed form never holds them.
// `current`: the derivative blocks held are those at the v returned (Newton stopped on
// the residual of an evaluation at that v), so a caller that needs them there can reuse
// them.
struct LegendreWork {
  Eigen::VectorXd Lq, Lv, r;
  Eigen::MatrixXd Lqq, Lqv, Lvv;
  DenseLU lu;
  bool current = false;
  explicit LegendreWork(int n = 0) { resize(n); }
  void resize(int n) {
    Lq.resize(n);
    Lv.resize(n);
    r.resize(n);
    Lqq.resize(n, n);
    Lqv.resize(n, n);
    Lvv.resize(n, n);
    lu.resize(n);
  }
};

// Newton's method for v with L_v(q, v) = p from the v given (legendre_inverse's, apart
// from it so that the closed forms, which a run meets at every monitored step, do not
// carry this loop).
template <class Sys>
void legendre_newton(const Sys& L, const DynIn& q, const DynIn& p, DynOut v, LegendreWork& w) {
  const double scale = std::fmax(1e-300, max_abs(p));
  if (w.Lvv.rows() != L.dim()) w.resize(L.dim());
  for (int it = 0; it < 50; ++it) {
    L.hessian(q, v, w.Lq, w.Lv, w.Lqq, w.Lqv, w.Lvv);
    w.r = w.Lv - p;
    if (max_abs(w.r) <= 1e-14 * scale) {
      w.current = true;
      return;
    }
    if (!w.lu.factor(w.Lvv))
      throw DegenerateLagrangianError(L.name() + ": the velocity Hessian d2L/dv2 is singular; "
                                                 "the Legendre transform cannot be inverted");
    w.lu.solve(w.r, w.r);
    v -= w.r;
    if (max_abs(w.r) <= 4e-16 * std::fmax(1.0, max_abs(v))) return;
  }
  throw DegenerateLagrangianError(L.name() + ": Newton's method for the inverse Legendre map did not converge");
}

// v with L_v(q, v) = p: the closed form, or Newton's method from the v given, or from
// v = 0 with from_rest (the rule of legendre_inverse in mechanics/lagrangian.h). Throws
// DegenerateLagrangianError.
template <class Sys>
void legendre_inverse(const Sys& L, const DynIn& q, const DynIn& p, DynOut v, LegendreWork& w,
                      bool from_rest = false) {
  w.current = false;
  if constexpr (has_dynamic_velocity<Sys>::value) {
    L.velocity(q, p, v);
  } else {
    if constexpr (has_runtime_velocity<Sys>::value)
      if (L.closed_velocity(q, p, v)) return;
    if (from_rest) v.setZero();
    legendre_newton(L, q, p, v, w);
  }
}

}  // namespace dynamic_detail

// p = L_v(q, v).
template <class Sys, std::enable_if_t<is_dynamic_system_v<Sys>, int> = 0>
Eigen::VectorXd legendre(const Sys& L, const DynIn& q, const DynIn& v) {
  Eigen::VectorXd a(L.dim()), b(L.dim());
  L.gradient(q, v, a, b);
  return b;
}

// E_L(q, v) = <L_v, v> - L.
template <class Sys, std::enable_if_t<is_dynamic_system_v<Sys>, int> = 0>
double energy(const Sys& L, const DynIn& q, const DynIn& v) {
  Eigen::VectorXd a(L.dim()), b(L.dim());
  L.gradient(q, v, a, b);
  return b.dot(v) - L.value(q, v);
}

// v with L_v(q, v) = p: the closed form, or Newton's method from `guess` (zero if not
// given). Throws DegenerateLagrangianError where L_vv is singular.
template <class Sys, std::enable_if_t<is_dynamic_system_v<Sys>, int> = 0>
Eigen::VectorXd legendre_inverse(const Sys& L, const DynIn& q, const DynIn& p, const DynIn& guess) {
  Eigen::VectorXd v = guess;
  // closed forms without the n x n workspace of Newton's method
  if constexpr (has_dynamic_velocity<Sys>::value) {
    L.velocity(q, p, v);
    return v;
  }
  if constexpr (has_runtime_velocity<Sys>::value)
    if (L.closed_velocity(q, p, v)) return v;
  dynamic_detail::LegendreWork w;  // sized by legendre_newton, which alone uses it
  dynamic_detail::legendre_inverse(L, q, p, v, w);
  return v;
}
template <class Sys, std::enable_if_t<is_dynamic_system_v<Sys>, int> = 0>
Eigen::VectorXd legendre_inverse(const Sys& L, const DynIn& q, const DynIn& p) {
  return legendre_inverse(L, q, p, Eigen::VectorXd::Zero(L.dim()));
}

// Throws DegenerateLagrangianError, naming the point, when L_vv(q, v) is singular to
// working precision (reciprocal condition not above rcond_floor), as require_regular
// of mechanics/hamiltonian.h.
template <class Sys, std::enable_if_t<is_dynamic_system_v<Sys>, int> = 0>
void require_regular(const Sys& L, const DynIn& q, const DynIn& v, double rcond_floor = 1e-12) {
  const int n = L.dim();
  dynamic_detail::LegendreWork w(n);
  L.hessian(q, v, w.Lq, w.Lv, w.Lqq, w.Lqv, w.Lvv);
  double rc = 0.0;
  if (w.lu.factor(w.Lvv)) {
    Eigen::MatrixXd Winv(n, n);
    w.lu.inverse(Winv);
    rc = dynamic_detail::rcond_inf(w.Lvv, Winv);
  }
  if (!(rc > rcond_floor)) dynamic_detail::throw_not_regular(L, q, v, rc);
}

// The inverse Legendre map with the regularity check at the start (v = 0) and at the
// solution, as legendre_inverse_checked of mechanics/hamiltonian.h.
template <class Sys, std::enable_if_t<is_dynamic_system_v<Sys>, int> = 0>
Eigen::VectorXd legendre_inverse_checked(const Sys& L, const DynIn& q, const DynIn& p) {
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(L.dim());
  require_regular(L, q, zero);
  const Eigen::VectorXd v = legendre_inverse(L, q, p, zero);
  require_regular(L, q, v);
  return v;
}

// ---------------------------------------------------------------------------------
// A fixed-size Lagrangian of mechanics/ seen as a run-time-sized one.

template <class S>
class FixedAsDynamic {
 public:
  static constexpr int N = S::dim;
  using V = Vec<double, N>;

  explicit FixedAsDynamic(S system) : system_(std::move(system)) {}
  int dim() const { return N; }
  std::string name() const { return system_.name(); }
  const S& system() const { return system_; }

  // (Inputs and outputs are contiguous: they are read and written as fixed-size maps.)
  double value(const DynIn& q, const DynIn& v) const { return system_(in(q), in(v)); }

  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const {
    V a, b;
    lagrangian_gradient(system_, in(q), in(v), a, b);
    Eigen::Map<V>(Lq.data()) = a;
    Eigen::Map<V>(Lv.data()) = b;
  }

  // One Jet level of size 2N through the gradient (nested Jets if it is not closed form).
  void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
               DynMatOut Lvv) const {
    using D = ceres::Jet<double, 2 * N>;
    Vec<D, N> qd, vd, a, b;
    const double* qp = q.data();
    const double* vp = v.data();
    for (int i = 0; i < N; ++i) {
      qd[i] = seed<double, 2 * N>(qp[i], i);
      vd[i] = seed<double, 2 * N>(vp[i], N + i);
    }
    lagrangian_gradient(system_, qd, vd, a, b);
    for (int i = 0; i < N; ++i) {
      Lq[i] = a[i].a;
      Lv[i] = b[i].a;
      for (int j = 0; j < N; ++j) {
        Lqq(i, j) = a[i].v[j];
        Lqv(i, j) = a[i].v[N + j];
        Lvv(i, j) = b[i].v[N + j];
      }
    }
  }

  template <class T = S, std::enable_if_t<has_velocity<T>::value, int> = 0>
  void velocity(const DynIn& q, const DynIn& p, DynOut v) const {
    Eigen::Map<V>(v.data()) = system_.velocity(in(q), in(p));
  }

 private:
  static V in(const DynIn& x) {
    eigen_assert(x.size() == N);
    return Eigen::Map<const V>(x.data());
  }
  S system_;
};

// The Hamiltonian of a regular run-time-sized Lagrangian, by the Legendre transform.
//
// v = FL^{-1}(q, p) is the closed form, or Newton's method from v = 0 (as
// LegendreHamiltonian of mechanics/hamiltonian.h, so that both give the same v); the
// derivatives of L at the last Newton iterate are reused when it is v itself (Newton
// stops on the residual there: one evaluation of L's Hessian saved per call).
// value() and gradient() need only v; hessian() forms L_vv^{-1}, checks the reciprocal
// condition of L_vv (above 1e-12, as require_regular) and throws
// DegenerateLagrangianError where it fails.
template <class Sys>
class LegendreDynamicHamiltonian {
 public:
  explicit LegendreDynamicHamiltonian(Sys L) : L_(std::move(L)) {
    const int n = L_.dim();
    v_.resize(n);
    Lq_.resize(n);
    Lv_.resize(n);
    Winv_.resize(n, n);
    T_.resize(n, n);
    lu_.resize(n);
    work_.resize(n);
  }

  int dim() const { return L_.dim(); }
  std::string name() const { return L_.name(); }
  const Sys& lagrangian() const { return L_; }
  // L(t, q, v) (has_time): H(t, q, p) at the time set, L's own.
  template <class S = Sys, std::enable_if_t<has_time<S>::value, int> = 0>
  void set_time(double t) const {
    L_.set_time(t);
  }

  // v = FL^{-1}(q, p). A Newton inverse that fails on a singular L_vv is reported
  // naming the point where it started (v = 0) when L is singular there.
  void velocity(const DynIn& q, const DynIn& p, DynOut v) const {
    v.setZero();
    try {
      dynamic_detail::legendre_inverse(L_, q, p, v, work_);
    } catch (const DegenerateLagrangianError&) {
      require_regular(L_, q, Eigen::VectorXd::Zero(L_.dim()));
      throw;
    }
  }

  double value(const DynIn& q, const DynIn& p) const {
    velocity(q, p, v_);
    return p.dot(v_) - L_.value(q, v_);
  }

  // H_q = -L_q(q, v), H_p = v.
  void gradient(const DynIn& q, const DynIn& p, DynOut Hq, DynOut Hp) const {
    velocity(q, p, v_);
    if (work_.current)  // Newton's last evaluation was at v
      Hq = -work_.Lq;
    else {
      L_.gradient(q, v_, Lq_, Lv_);
      Hq = -Lq_;
    }
    Hp = v_;
  }

  // H_pp = W^{-1}, H_qp = -L_qv W^{-1}, H_qq = -L_qq + L_qv W^{-1} L_qv^T, W = L_vv.
  void hessian(const DynIn& q, const DynIn& p, DynOut Hq, DynOut Hp, DynMatOut Hqq, DynMatOut Hqp,
               DynMatOut Hpp) const {
    velocity(q, p, v_);
    if (!work_.current) L_.hessian(q, v_, work_.Lq, work_.Lv, work_.Lqq, work_.Lqv, work_.Lvv);
    const Eigen::MatrixXd &Lqq = work_.Lqq, &Lqv = work_.Lqv, &Lvv = work_.Lvv;
    double rc = 0.0;
    if (lu_.factor(Lvv)) {
      lu_.inverse(Winv_);
      rc = dynamic_detail::rcond_inf(Lvv, Winv_);
    }
    if (!(rc > 1e-12)) dynamic_detail::throw_not_regular(L_, q, v_, rc);
    Hq = -work_.Lq;
    Hp = v_;
    Hpp = Winv_;
    T_.noalias() = Lqv * Winv_;
    Hqp = -T_;
    Hqq.noalias() = T_ * Lqv.transpose();
    Hqq -= Lqq;
  }

 private:
  Sys L_;
  mutable Eigen::VectorXd v_, Lq_, Lv_;
  mutable Eigen::MatrixXd Winv_, T_;
  mutable DenseLU lu_;
  mutable dynamic_detail::LegendreWork work_;
};

}  // namespace dvm
