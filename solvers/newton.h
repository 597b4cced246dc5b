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

// A system of n unknowns seen by ceres::TinySolver, which is compiled once, at run-time
// size (solvers/tiny_solver.cc), for every step type, size, map and composition: the
// functor f behind one function pointer, compiled with f in the step's translation unit,
// that evaluates it on doubles, or on the Jets of its N unknowns where the Jacobian is
// asked for (column-major, as TinySolver reads it: what ceres::TinySolverAutoDiffFunction
// does for a size known when compiled). The interface of TinySolver's Function.
class TinyFunction {
 public:
  using Scalar = double;
  enum { NUM_RESIDUALS = Eigen::Dynamic, NUM_PARAMETERS = Eigen::Dynamic };
  // f, of N unknowns and N residuals (held by reference: it outlives the solve)
  template <int N, class F>
  static TinyFunction of(const F& f) {
    return TinyFunction(N, &f, &evaluate<N, F>);
  }
  int NumResiduals() const { return n_; }
  int NumParameters() const { return n_; }
  bool operator()(const double* x, double* r, double* J) const { return evaluate_(f_, x, r, J); }

 private:
  using Evaluate = bool (*)(const void*, const double*, double*, double*);
  TinyFunction(int n, const void* f, Evaluate e) : n_(n), f_(f), evaluate_(e) {}
  template <int N, class F>
  static bool evaluate(const void* f, const double* x, double* r, double* J) {
    const F& fn = *static_cast<const F*>(f);
    if (!J) return fn(x, r);
    using Jet = ceres::Jet<double, N>;
    Jet xj[N], rj[N];
    for (int i = 0; i < N; ++i) xj[i] = Jet(x[i], i);
    if (!fn(xj, rj)) return false;
    for (int i = 0; i < N; ++i) {
      r[i] = rj[i].a;
      for (int j = 0; j < N; ++j) J[i + N * j] = rj[i].v[j];
    }
    return true;
  }
  int n_;
  const void* f_;
  Evaluate evaluate_;
};

// The system f(x) = 0 (x: its n unknowns, the guess in, the result out) solved by
// ceres::TinySolver, with the result checked here. s0: as for solve_newton
// (solvers/newton_driver.h), the residual's scale at x is s0 + max|J| max|x|; x0 (the
// size of the point x is an increment of) is not read, TinySolver's stall test being
// relative to x alone. The solver's workspace is kept per thread (allocated at a
// thread's first solve of a size).
StepSummary solve_tiny_function(const TinyFunction& f, double* x, double x0, const StepOptions& opt, double s0);

// The functor f (`template <class T> bool operator()(const T* x, T* r) const`) solved by
// ceres::TinySolver (solve_tiny_function).
template <int N, class F>
StepSummary solve_tiny(const F& f, Vec<double, N>& x, double x0, const StepOptions& opt, double s0) {
  return solve_tiny_function(TinyFunction::of<N>(f), x.data(), x0, opt, s0);
}

}  // namespace dvm
