// The one Newton driver: an equation F(x) = 0 of a step, solved by Newton's method with
// the linear algebra and the refresh of the Jacobian as policies.
//
// The minimum API of an equation E (what each discrete equation writes once):
//   using Vector, Matrix;                     Eigen types of the unknowns' size (fixed or
//                                             run-time) and of the Jacobian
//   void residual(const Vector& x, Vector& r)        r = F(x)
//   double jacobian(const Vector& x, Vector& r, Matrix& J)
//                                             r = F(x) and J = dF/dx at x; returns max|J_ij|
//                                             (INFINITY where it is not finite)
//   double scale(double xn, double Jmax) const  the size of the terms F is made of at x,
//                                             which the residual is judged against
//                                             (xn = max|x_i|, Jmax: the Jacobian's)
//   double offset() const                      the size of the point x is an increment of
//                                             (round-off in forming it sets a floor under F)
// and optionally
//   double norm(const Vector& v) const         the max norm the driver measures in, where the
//                                             equation checks finiteness itself (default:
//                                             inf_norm, NaN where any v_i is NaN)
// The equation holds its data (the step's start, its time, its size) and may keep what
// it evaluated at the last x (the caller reads the solution's by-products from it).
//
// Deduced here, once for every equation:
//   - the stopping rule of every step (newton_verdict_floored, solvers/newton.h): F below
//     its tolerance relative to the scale, or updates stalled at round-off;
//   - the correction from the last evaluation applied on convergence (it takes the
//     residual from the tolerance down to round-off; the reported residual is the one
//     measured before it);
//   - the refresh of the Jacobian (Refresh policies below): formed at every iteration,
//     kept within a step while each iteration shrinks the residual fourfold, kept across
//     steps by the same rule, or kept across steps while each correction shrinks
//     fourfold;
//   - StepSummary::iterations counts Newton iterations (residuals evaluated and judged),
//     StepSummary::jacobians the Jacobians formed and factored.
//
// Linear algebra policies LA: `bool factor(const Matrix& J, double Jmax)` (false where J is
// singular to working precision) and `void solve(const Vector& r, Vector& dx)` (dx =
// J^{-1} r; the driver passes two distinct vectors). DenseLUOf<K> (core/dense_solve.h) and FixedLU<N> below are
// dense ones; the tridiagonal and banded eliminations of the chains and the sparse
// factorisations of the separable steps are others.
//
// solve_newton (below) is the driver on an equation written as a Ceres-style functor,
// its Jacobian from ceres::Jet, at fixed size: the map-based steps (PositionMomentumStep,
// HamiltonianStep, SodeStep, ManifoldStep) solve by it.
#pragma once

#include <cmath>
#include <string>
#include <type_traits>
#include <utility>

#include "core/dense_solve.h"
#include "core/scalar.h"
#include "solvers/newton.h"

namespace dvm {

// How the driver refreshes the Jacobian.
enum class Refresh {
  every_iteration,  // Newton's method
  within_step,      // a Jacobian formed in the step serves later iterations of it while
                    // each shrinks the residual fourfold (kept_jacobian_serves)
  across_steps,     // the same, and the factorisation of an earlier step serves the next
  contracting,      // kept across steps while the corrections contract: refreshed (once in
                    // a step) where a correction after the first exceeds a quarter of the
                    // one before, or where the iteration stalls above its tolerance; the
                    // simplified Newton of implicit Runge-Kutta codes (Hairer and Wanner,
                    // Solving ODEs II, IV.8), which the Galerkin steps use
};

// Whether the driver keeps a factorisation from one call to the next.
constexpr bool keeps_across_steps(Refresh r) { return r == Refresh::across_steps || r == Refresh::contracting; }

// What the driver keeps between steps (Refresh::across_steps and Refresh::contracting).
struct DriverState {
  bool valid = false;  // a factorisation is held
  double Jmax = 0.0;   // the largest entry of the Jacobian factored
};

// Whether a factorisation formed at an earlier iterate still serves at this one: the
// residual shrank fourfold since the last iterate, within the first half of the
// iteration budget (Newton's method from there on, so that a small budget converges
// where Newton's method does), or it already meets the stopping rule (a residual at
// round-off shrinks no more, whatever J is). scale: the residual's scale with that
// Jacobian; verdict(probe): the caller's stopping rule on a copy of s.
template <class Verdict>
bool kept_jacobian_serves(const StepSummary& s, double last, int it, double scale, const StepOptions& opt,
                          Verdict&& verdict) {
  if (s.residual <= 0.25 * last && 2 * (it + 1) <= opt.max_iterations) return true;
  StepSummary probe = s;
  probe.scale = scale;
  return verdict(probe) == NewtonVerdict::converged;
}

namespace driver_detail {

// The norm the driver measures x, F(x) and the corrections in: the equation's own
// (double norm(const Vector&) const) where it has one, else max|v_i| with a NaN anywhere
// giving NaN (inf_norm).
template <class E, class = void>
struct has_norm : std::false_type {};
template <class E>
struct has_norm<E, std::void_t<decltype(std::declval<const E&>().norm(std::declval<const typename E::Vector&>()))>>
    : std::true_type {};
template <class E>
double norm(const E& eq, const typename E::Vector& v) {
  if constexpr (has_norm<E>::value)
    return eq.norm(v);
  else
    return inf_norm(v);
}

// "singular step Jacobian", with the factorisation that failed where the policy names it
// (const char* name() const).
template <class LA, class = void>
struct has_name : std::false_type {};
template <class LA>
struct has_name<LA, std::void_t<decltype(std::declval<const LA&>().name())>> : std::true_type {};
template <class LA>
std::string singular(const LA& la) {
  if constexpr (has_name<LA>::value)
    return std::string("singular step Jacobian (") + la.name() + " failed)";
  else
    return "singular step Jacobian";
}

}  // namespace driver_detail

// Solves F(x) = 0 from x (the guess in, the solution out; dx the correction applied last,
// zero if none). r, dx: workspace of x's size; start: too, used with a kept Jacobian only;
// J: of the Jacobian's; la: the factorisation; state: what is kept across steps
// (Refresh::across_steps; else only within this call). A non-finite residual at an
// iterate reached through a kept Jacobian starts the iteration again from the guess
// with a fresh one. Throws nothing itself; the equation's exceptions pass through.
// (Every return is of the one summary s, so that it is built in the caller's storage.)
// newton_drive_inlined is the same, inlined into its caller: for a step whose iterations
// cost little beside the driver's own bookkeeping (the fixed-size Galerkin steps, measured
// by bench_galerkin_kepler; the fixed-size steps solved by solve_newton below, measured by
// the generic-midpoint rows of bench_ratios and bench_written_lagrangian).
template <class E, class LA>
[[gnu::always_inline]] inline StepSummary newton_drive_inlined(E& eq, LA& la, Refresh refresh, const StepOptions& opt,
                                                               typename E::Vector& x, typename E::Vector& r,
                                                               typename E::Vector& dx, typename E::Matrix& J,
                                                               DriverState& state, typename E::Vector& start) {
  auto norm = [&eq](const typename E::Vector& v) { return driver_detail::norm(eq, v); };
  StepSummary s;
  if (!keeps_across_steps(refresh)) state.valid = false;
  const bool contracting = refresh == Refresh::contracting;
  const double x0 = eq.offset();
  double dxn = INFINITY, last = INFINITY;
  bool formed = false;  // a Jacobian formed in this call
  if (refresh != Refresh::every_iteration) start = x;
  auto failed = [&](std::string message) {
    s.fail(std::move(message));
    if (contracting) state.valid = false;
  };
  for (int it = 0; it < opt.max_iterations; ++it) {
    double xn = norm(x);
    bool fresh = !state.valid || refresh == Refresh::every_iteration;
    double kept_scale = 0.0;  // the residual's scale with the kept Jacobian (when it serves)
    if (!fresh) {
      eq.residual(x, r);
      s.residual = norm(r);
      if (!std::isfinite(s.residual) && !formed) {
        // a kept Jacobian took the iterate out of the equation's domain: from the guess again
        x = start;
        xn = norm(x);
        state.valid = false;
        dxn = last = INFINITY;
        fresh = true;
      } else {
        const double Jmax = state.Jmax;
        kept_scale = eq.scale(xn, Jmax) + opt.absolute_floor;
        // (Refresh::contracting judges the kept Jacobian by the correction, below)
        if (!contracting)
          fresh = !kept_jacobian_serves(s, last, it, kept_scale, opt, [&](StepSummary& probe) {
            return newton_verdict_floored(probe, dxn, xn + x0, opt, Jmax);
          });
      }
    }
    if (fresh) {
      state.Jmax = eq.jacobian(x, r, J);
      s.residual = norm(r);
      ++s.jacobians;
      formed = true;
      state.valid = std::isfinite(state.Jmax) && la.factor(J, state.Jmax);
      if (std::isfinite(state.Jmax) && !state.valid) {
        // singular: accepted only where the stopping rule accepts the iterate as it is
        s.iterations = it + 1;
        s.scale = eq.scale(xn, state.Jmax) + opt.absolute_floor;
        if (std::isfinite(s.residual) &&
            newton_verdict_floored(s, dxn, xn + x0, opt, state.Jmax) == NewtonVerdict::converged) {
          dx.setZero();  // (no correction applied)
          return s;
        }
        failed(driver_detail::singular(la));
        return s;
      }
    }
    s.iterations = it + 1;
    const double Jmax = state.Jmax;
    s.scale = fresh ? eq.scale(xn, Jmax) + opt.absolute_floor : kept_scale;
    if (!std::isfinite(s.residual) || !std::isfinite(Jmax)) {
      state.valid = false;
      failed("non-finite residual or Jacobian");
      return s;
    }
    const NewtonVerdict verdict = newton_verdict_floored(s, dxn, xn + x0, opt, Jmax);
    if (verdict == NewtonVerdict::failed) {
      if (contracting) state.valid = false;
      if (!contracting || formed) return s;
      // stalled on a kept Jacobian: a fresh one at this iterate
      s.message.clear();
      dxn = INFINITY;
      continue;
    }
    la.solve(r, dx);
    const double step = norm(dx);
    if (!std::isfinite(step)) {
      state.valid = false;
      failed(driver_detail::singular(la));
      return s;
    }
    x -= dx;  // (on convergence too: the correction already paid for)
    if (verdict == NewtonVerdict::converged) return s;
    if (contracting && it >= 1 && !formed && step > 0.25 * dxn) {
      // the corrections contract poorly: a fresh Jacobian at the new iterate
      state.valid = false;
      dxn = INFINITY;
      continue;
    }
    dxn = step;
    last = s.residual;
  }
  failed("no convergence within " + std::to_string(opt.max_iterations) + " iterations (" +
         std::to_string(s.jacobians) + " Jacobians formed)");
  return s;
}

template <class E, class LA>
StepSummary newton_drive(E& eq, LA& la, Refresh refresh, const StepOptions& opt, typename E::Vector& x,
                         typename E::Vector& r, typename E::Vector& dx, typename E::Matrix& J, DriverState& state,
                         typename E::Vector& start) {
  return newton_drive_inlined(eq, la, refresh, opt, x, r, dx, J, state, start);
}

// The dense factorisation of a fixed-size step: Eigen's closed-form inverse up to 4
// unknowns (singular where its determinant is zero or not finite), DenseLUOf<N> above.
template <int N>
class FixedLU {
 public:
  bool factor(const Mat<double, N, N>& J, double Jmax) {
    if constexpr (N <= 4) {
      bool invertible = false;
      double det = 0.0;
      J.computeInverseAndDetWithCheck(f_, det, invertible, 0.0);
      return invertible && std::isfinite(det);
    } else {
      return f_.factor(J, Jmax);
    }
  }
  void solve(const Vec<double, N>& r, Vec<double, N>& dx) const {
    if constexpr (N <= 4)
      dx = f_ * r;  // (a product: Eigen evaluates it into a temporary, so dx may alias r)
    else
      f_.solve(r, dx);
  }

 private:
  std::conditional_t<(N <= 4), Mat<double, N, N>, DenseLUOf<N>> f_;
};

// An equation written as a Ceres-style functor f(x, r) of N unknowns and N residuals,
// for the driver: the Jacobian from one level of Jets, the residual's scale
// s0 + max|J| max|x| (s0: the size of the terms that make up F where they do not scale
// with the unknowns, e.g. |p0|), the unknowns an increment of a point of size x0.
// DoubleResidual: the residual alone (asked for with a kept Jacobian) from f on doubles,
// else through the Jets.
template <int N, class F, bool DoubleResidual = false>
class JetEquation {
 public:
  using Vector = Vec<double, N>;
  using Matrix = Mat<double, N, N>;
  JetEquation(const F& f, double s0, double x0) : f_(f), s0_(s0), x0_(x0) {}

  // (The driver asks for the residual alone only with a kept Jacobian; solve_newton forms
  // one at every iteration. It goes through the Jets, so that f is not instantiated on
  // doubles for nothing.)
  void residual(const Vector& x, Vector& r) const {
    if constexpr (DoubleResidual) {
      f_(x.data(), r.data());
    } else {
      Matrix J;
      jacobian(x, r, J);
    }
  }
  double jacobian(const Vector& x, Vector& r, Matrix& J) const {
    using D = ceres::Jet<double, N>;
    Vec<D, N> xd, rd;
    for (int i = 0; i < N; ++i) xd[i] = D(x[i], i);
    f_(xd.data(), rd.data());
    for (int i = 0; i < N; ++i) {
      r[i] = rd[i].a;
      J.row(i) = rd[i].v.transpose();
    }
    return max_abs(J);
  }
  double scale(double xn, double Jmax) const { return s0_ + Jmax * xn; }
  double offset() const { return x0_; }

 private:
  const F& f_;
  double s0_, x0_;
};

// Newton's method on f(x) = 0 from x (updated in place), a Jacobian formed and factored
// at every iteration; s0 and x0 as for JetEquation. The driver is inlined here: a step of
// one or two unknowns costs little more than the call and the driver's bookkeeping.
template <int N, class F>
StepSummary solve_newton(const F& f, Vec<double, N>& x, double x0, const StepOptions& opt, double s0) {
  JetEquation<N, F> eq(f, s0, x0);
  FixedLU<N> la;
  Vec<double, N> r, dx, start;
  Mat<double, N, N> J;
  DriverState state;
  return newton_drive_inlined(eq, la, Refresh::every_iteration, opt, x, r, dx, J, state, start);
}

// Newton's method whose Jacobian, formed at the first iterate, serves the later iterations
// of the call while each shrinks the residual fourfold (Refresh::within_step; refreshed
// otherwise), their residuals evaluated on doubles: for equations whose Jacobian costs
// many residuals (nested Jets; the Hamiltonian step on S^2 and SO(3)).
template <int N, class F>
StepSummary solve_newton_kept(const F& f, Vec<double, N>& x, double x0, const StepOptions& opt, double s0) {
  JetEquation<N, F, true> eq(f, s0, x0);
  FixedLU<N> la;
  Vec<double, N> r, dx, start;
  Mat<double, N, N> J;
  DriverState state;
  return newton_drive_inlined(eq, la, Refresh::within_step, opt, x, r, dx, J, state, start);
}

// The solver StepOptions::solver names: solve_newton or solve_tiny (solvers/newton.h).
template <int N, class F>
StepSummary solve_step_system(const F& f, Vec<double, N>& x, double x0, const StepOptions& opt, double s0) {
  return opt.solver == SolverKind::newton ? solve_newton<N>(f, x, x0, opt, s0) : solve_tiny<N>(f, x, x0, opt, s0);
}

}  // namespace dvm
