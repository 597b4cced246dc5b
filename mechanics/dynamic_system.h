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
// Implementations:
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

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/dense_solve.h"
#include "core/map_operations.h"
#include "core/scalar.h"
#include "mechanics/derivative_program.h"
#include "mechanics/native_code.h"
#include "mechanics/lagrangian.h"
#include "mechanics/nbody_momenta.h"
#include "mechanics/structure.h"
#include "mechanics/systems.h"
#include "mechanics/written_lagrangian.h"

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

// Workspace of the Newton inverse of the Legendre map, sized once. `current`: the
// derivative blocks held are those at the v returned (Newton stopped on the residual
// of an evaluation at that v), so a caller that needs them there can reuse them.
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
  dynamic_detail::LegendreWork w(L.dim());
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

// ---------------------------------------------------------------------------------
// The N-body Lagrangian of any number of bodies B in R^3 (systems_classic.h, NBody<B>):
//
//   L = sum_i m_i |v_i|^2/2 + sum_{i<j} k_ij / r_ij,   k_ij = G m_i m_j,
//   r_ij = |d|, d = q_i - q_j.
//
// With f = k_ij / r_ij^3: L_{q_i} gets -f d and L_{q_j} gets +f d from the pair; its
// Hessian block is B_ij = f (3 d d^T / r_ij^2 - I), added to (i, i) and (j, j) and
// subtracted from (i, j) and (j, i). L_qv = 0, L_vv = diag(m_i I_3), v_i = p_i / m_i.
class NBodyDynamic {
 public:
  static constexpr Structure structure = Structure::separable;
  double G = 1.0;
  std::vector<double> mass;

  NBodyDynamic(double G_, std::vector<double> masses) : G(G_), mass(std::move(masses)) {
    if (mass.empty()) throw std::invalid_argument("nbody: at least one body is needed");
    if (!std::isfinite(G) || G < 0) throw std::invalid_argument("nbody: parameter G must be finite and >= 0");
    for (double m : mass) detail::require_positive("nbody", "mass", m);
  }
  std::string name() const { return "nbody"; }
  int bodies() const { return static_cast<int>(mass.size()); }
  int dim() const { return 3 * bodies(); }
  double m(int i) const { return mass[static_cast<std::size_t>(i)]; }

  double value(const DynIn& q, const DynIn& v) const {
    const int B = bodies();
    double kin = 0.0, pot = 0.0;
    for (int i = 0; i < B; ++i)
      kin += m(i) * (v[3 * i] * v[3 * i] + v[3 * i + 1] * v[3 * i + 1] + v[3 * i + 2] * v[3 * i + 2]);
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        const double dx = q[3 * i] - q[3 * j], dy = q[3 * i + 1] - q[3 * j + 1], dz = q[3 * i + 2] - q[3 * j + 2];
        pot += (G * m(i) * m(j)) / std::sqrt(dx * dx + dy * dy + dz * dz);
      }
    return 0.5 * kin + pot;
  }

  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const {
    const int B = bodies();
    Lq.setZero();
    for (int i = 0; i < B; ++i)
      for (int a = 0; a < 3; ++a) Lv[3 * i + a] = m(i) * v[3 * i + a];
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        double d[3];
        for (int a = 0; a < 3; ++a) d[a] = q[3 * i + a] - q[3 * j + a];
        const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const double f = (G * m(i) * m(j)) / (r2 * std::sqrt(r2));
        for (int a = 0; a < 3; ++a) {
          const double fa = f * d[a];
          Lq[3 * i + a] -= fa;
          Lq[3 * j + a] += fa;
        }
      }
  }

  void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
               DynMatOut Lvv) const {
    const int B = bodies();
    Lq.setZero();
    Lqq.setZero();
    Lqv.setZero();
    Lvv.setZero();
    for (int i = 0; i < B; ++i)
      for (int a = 0; a < 3; ++a) {
        Lv[3 * i + a] = m(i) * v[3 * i + a];
        Lvv(3 * i + a, 3 * i + a) = m(i);
      }
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        double d[3];
        for (int a = 0; a < 3; ++a) d[a] = q[3 * i + a] - q[3 * j + a];
        const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const double f = (G * m(i) * m(j)) / (r2 * std::sqrt(r2));
        const double g = 3.0 * f / r2;
        for (int a = 0; a < 3; ++a) {
          const double fa = f * d[a];
          Lq[3 * i + a] -= fa;
          Lq[3 * j + a] += fa;
          for (int b = 0; b < 3; ++b) {
            const double Bab = g * d[a] * d[b] - (a == b ? f : 0.0);
            Lqq(3 * i + a, 3 * i + b) += Bab;
            Lqq(3 * j + a, 3 * j + b) += Bab;
            Lqq(3 * i + a, 3 * j + b) -= Bab;
            Lqq(3 * j + a, 3 * i + b) -= Bab;
          }
        }
      }
  }

  void velocity(const DynIn&, const DynIn& p, DynOut v) const {
    for (int i = 0; i < bodies(); ++i)
      for (int a = 0; a < 3; ++a) v[3 * i + a] = p[3 * i + a] / m(i);
  }

  // Total momentum (3) and total angular momentum (3) (mechanics/nbody_momenta.h).
  static std::array<double, 6> momenta(const DynIn& q, const DynIn& p) {
    return nbody_momenta(q.data(), p.data(), static_cast<int>(q.size() / 3));
  }
};

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
    // L(t, q, v): no structure is read off the text (its parts would read t, which the
    // structured steps and closed forms do not pass); the general path, Newton's
    // method for v = FL^{-1}(t, q, p)
    if (w.time_dependent()) return;
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
    if (parts_->split.quadratic && !parts_->separable) mass_ = Mass(system_->dim(), parts_->mass_program.get());
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
    if (mass_.unit.size() != dim()) return false;  // not quadratic in the velocities
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
    if (parts_->has_mass_entries()) return 0.5 * p.dot(v) - mass_and_potential(q)[mass_.potential];
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
    Mass& m = mass_;
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
    Mass& m = mass_;
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
    explicit Timed(int n)
        : q(Eigen::VectorXd::Zero(n + 1)), v(Eigen::VectorXd::Zero(n + 1)), gq(n + 1), gv(n + 1), Hqq(n + 1, n + 1),
          Hqv(n + 1, n + 1), Hvv(n + 1, n + 1) {}
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
  mutable Mass mass_;    // sized only for a text quadratic in the velocities and not separable
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
