// Solving the small fixed-size nonlinear systems of a step, F(x) = 0, x in R^N.
//
// The options and the report of every step's solve (StepOptions, StepSummary), the
// stopping rule every Newton iteration of dvm judges by (newton_verdict), and
// ceres::TinySolver as the second solver of the systems written as a functor
// `template <class T> bool operator()(const T* x, T* r) const`, as Ceres' autodiff
// expects, whose Jacobian comes from ceres::Jet:
//   newton  Newton's method, J dx = -F, one Jacobian evaluation per iteration
//           (solve_newton, by the one driver: solvers/newton_driver.h);
//   tiny    ceres::TinySolver (Levenberg-Marquardt on the normal equations).
// Both report a StepSummary. Convergence is judged on the residual itself (Newton
// then applies the correction from that last evaluation),
// |F(x)|_inf <= residual_tolerance * scale, with `scale` the size of the terms that
// make up F (given by the caller); a solve that stalls above that is accepted only
// if its residual is below accept_tolerance * scale. TinySolver cannot report a
// failure itself (its Status has no failure value), so its result is re-evaluated
// and checked here.
#pragma once

#include <ceres/jet.h>
// TinySolver leaves a member uninitialised until its first Update(); GCC 12 warns
// about it at the header's own lines (clang has no such warning).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <ceres/tiny_solver.h>
#include <ceres/tiny_solver_autodiff_function.h>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#include <cmath>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>

#include "core/dense_solve.h"
#include "core/scalar.h"

namespace dvm {

enum class SolverKind { newton, tiny };

inline const char* to_string(SolverKind k) { return k == SolverKind::newton ? "newton" : "tiny"; }

struct StepOptions {
  SolverKind solver = SolverKind::newton;
  int max_iterations = 25;
  // converged when |F|_inf <= residual_tolerance * scale
  double residual_tolerance = 2e-15;
  // a solve whose Newton updates have stalled at |dx| <= stall_tolerance (|x| + x0),
  // with x0 the size of the point the unknown is an increment of (round-off in
  // forming that point sets a floor under the residual), is accepted when
  // |F|_inf <= accept_tolerance * scale
  double stall_tolerance = 1e-14;
  double accept_tolerance = 1e-10;
  // added to the scale, so that a state at rest (all terms zero) can converge
  double absolute_floor = 1e-300;
};

struct StepSummary {
  bool converged = false;
  int iterations = 0;     // Newton iterations: residuals evaluated and judged
  int jacobians = 0;      // Jacobians formed (fewer than iterations where one is kept)
  double residual = NAN;  // |F|_inf at the returned x
  double scale = NAN;     // the scale the residual was judged against
  double work = 0.0;      // a step with forces: their discrete work over the step (else 0)
  std::string message;    // why a solve failed

  // Marks the step failed, saying why.
  void fail(std::string why) {
    converged = false;
    message = std::move(why);
  }
};

// The force type of a step that takes none: the steps with a force term
// (solvers/dynamic_step.h, dynamic_galerkin_step.h) take a Force type, NoForce by
// default, so that an unforced step compiles to the same code as one written without.
struct NoForce {};
template <class Force>
constexpr bool is_force_v = !std::is_same_v<Force, NoForce>;

// The stopping rule shared by every Newton loop of dvm, judged after an evaluation
// that filled s.residual and s.scale; dxn is the size of the last update and x_size
// the size it is compared with. `converged` also when the updates have stalled at a
// residual below accept_tolerance, or at the round-off floor of the residual's own
// evaluation (`floor`: what an error of the unknown's size times machine epsilon
// moves the residual by; the caller knows it, e.g. |J| eps (|x| + x0)); `failed`
// (with a message) when they stalled above both.
enum class NewtonVerdict { iterate, converged, failed };

inline NewtonVerdict newton_verdict(StepSummary& s, double dxn, double x_size, const StepOptions& opt,
                                    double floor = 0.0) {
  const bool small = s.residual <= opt.residual_tolerance * s.scale;
  const bool stalled = dxn <= opt.stall_tolerance * x_size;
  if (!small && !stalled) return NewtonVerdict::iterate;
  s.converged = small || s.residual <= opt.accept_tolerance * s.scale || s.residual <= floor;
  if (s.converged) return NewtonVerdict::converged;
  s.message = "Newton stalled above the residual tolerance";
  return NewtonVerdict::failed;
}

// newton_verdict, and where the updates stalled above the tolerances, again with the
// round-off floor of the residual: formed from points of size x_size (a map inverted by
// Newton's method forms q1 = q0 + dq) it cannot go below |J| eps x_size, and 64 times
// that is round-off, whatever the scale of its terms.
inline NewtonVerdict newton_verdict_floored(StepSummary& s, double dxn, double x_size, const StepOptions& opt,
                                           double jacobian_norm) {
  NewtonVerdict verdict = newton_verdict(s, dxn, x_size, opt);
  if (verdict == NewtonVerdict::failed) {
    const double floor = 64.0 * std::numeric_limits<double>::epsilon() * jacobian_norm * x_size;
    verdict = newton_verdict(s, dxn, x_size, opt, floor);
    if (verdict == NewtonVerdict::converged) s.message.clear();
  }
  return verdict;
}

// A system of N unknowns seen by ceres::TinySolver: the functor f behind two function
// pointers, one evaluating it on doubles and one on the Jets of N directions (the two
// calls TinySolverAutoDiffFunction makes). Every step's f is a type of its own: with f
// itself, TinySolver and its autodiff wrapper would be compiled again for each step
// type, map and composition of every kernel; through this they are compiled once per N.
// The evaluations are f's own, through one indirect call each.
template <int N>
class TinyResidual {
 public:
  using Jet = ceres::Jet<double, N>;
  template <class F>
  explicit TinyResidual(const F& f) : f_(&f), on_doubles_(&evaluate<F, double>), on_jets_(&evaluate<F, Jet>) {}
  bool operator()(const double* x, double* r) const { return on_doubles_(f_, x, r); }
  bool operator()(const Jet* x, Jet* r) const { return on_jets_(f_, x, r); }

 private:
  template <class F, class T>
  static bool evaluate(const void* f, const T* x, T* r) {
    return (*static_cast<const F*>(f))(x, r);
  }
  const void* f_;
  bool (*on_doubles_)(const void*, const double*, double*);
  bool (*on_jets_)(const void*, const Jet*, Jet*);
};

// The system f(x) = 0 (a TinyResidual) solved by ceres::TinySolver, with the result
// checked here. s0: as for solve_newton (solvers/newton_driver.h), the residual's scale
// at x is s0 + max|J| max|x|.
template <int N>
StepSummary solve_tiny_residual(const TinyResidual<N>& f, Vec<double, N>& x, double x0, const StepOptions& opt,
                                double s0) {
  using AD = ceres::TinySolverAutoDiffFunction<TinyResidual<N>, N, N>;
  AD fn(f);  // holds a reference to f, which outlives it
  ceres::TinySolver<AD> solver;
  solver.options.max_num_iterations = opt.max_iterations;
  solver.options.gradient_tolerance = 0.0;
  solver.options.function_tolerance = 0.0;
  // TinySolver's own stall test is |dx| <= tol (|x| + tol), relative to x alone; the
  // floor set by x0 is left to the residual check below.
  (void)x0;
  solver.options.parameter_tolerance = opt.stall_tolerance;
  // cost = |F|^2/2; stop once |F| is below the tolerance for the current scale
  Vec<double, N> r = Vec<double, N>::Zero();
  Mat<double, N, N> J = Mat<double, N, N>::Zero();
  fn(x.data(), r.data(), J.data());
  const double scale0 = s0 + max_abs(J) * max_abs(x) + opt.absolute_floor;
  const double target = opt.residual_tolerance * scale0;
  solver.options.cost_threshold = 0.5 * target * target;
  const auto& summary = solver.Solve(fn, &x);
  StepSummary s;
  s.iterations = s.jacobians = summary.iterations + 1;
  fn(x.data(), r.data(), J.data());
  s.residual = max_abs(r);
  s.scale = s0 + max_abs(J) * max_abs(x) + opt.absolute_floor;
  s.converged = std::isfinite(s.residual) && s.residual <= opt.accept_tolerance * s.scale;
  if (!s.converged) s.message = "TinySolver ended above the residual tolerance";
  return s;
}

// Compiled once, in solvers/tiny_solver.cc, for the sizes of the runtime's steps
// (DVM_TINY_SOLVER_SIZES): a kernel file then compiles no TinySolver of its own. Other
// sizes are compiled where they are used.
#define DVM_TINY_SOLVER_SIZES(X) X(1) X(2) X(3) X(4) X(6) X(8) X(12)
#define DVM_TINY_SOLVER_DECLARE(N)                                                                                  \
  extern template StepSummary solve_tiny_residual<N>(const TinyResidual<N>&, Vec<double, N>&, double, const StepOptions&, \
                                                     double);
DVM_TINY_SOLVER_SIZES(DVM_TINY_SOLVER_DECLARE)
#undef DVM_TINY_SOLVER_DECLARE

// The functor f (`template <class T> bool operator()(const T* x, T* r) const`) solved by
// ceres::TinySolver (solve_tiny_residual).
template <int N, class F>
StepSummary solve_tiny(const F& f, Vec<double, N>& x, double x0, const StepOptions& opt, double s0) {
  return solve_tiny_residual<N>(TinyResidual<N>(f), x, x0, opt, s0);
}

}  // namespace dvm
