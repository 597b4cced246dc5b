// ceres::TinySolver on the systems of the steps (solve_tiny_function, solvers/newton.h),
// compiled once, at run-time size.
#include "solvers/newton.h"

// TinySolver leaves a member uninitialised until its first Update(); GCC 12 warns
// about it at the header's own lines (clang has no such warning).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <ceres/tiny_solver.h>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#include <Eigen/Core>

namespace dvm {

namespace {

// TinySolver and the vectors of one solve, sized at its first solve of a size.
struct TinyWork {
  ceres::TinySolver<TinyFunction> solver;
  Eigen::VectorXd x, r;
  Eigen::MatrixXd J;
};

StepSummary solve_in(TinyWork& w, const TinyFunction& f, double* x_io, const StepOptions& opt, double s0) {
  auto& solver = w.solver;
  auto &x = w.x, &r = w.r;
  auto& J = w.J;
  const int n = f.NumParameters();
  x = Eigen::Map<const Eigen::VectorXd>(x_io, n);
  r.setZero(n);
  J.setZero(n, n);
  solver.options = {};
  solver.options.max_num_iterations = opt.max_iterations;
  solver.options.gradient_tolerance = 0.0;
  solver.options.function_tolerance = 0.0;
  // TinySolver's own stall test is |dx| <= tol (|x| + tol), relative to x alone (x0 plays
  // no part); the residual is checked below.
  solver.options.parameter_tolerance = opt.stall_tolerance;
  // cost = |F|^2/2; stop once |F| is below the tolerance for the current scale
  f(x.data(), r.data(), J.data());
  const double scale0 = s0 + max_abs(J) * max_abs(x) + opt.absolute_floor;
  const double target = opt.residual_tolerance * scale0;
  solver.options.cost_threshold = 0.5 * target * target;
  const auto& summary = solver.Solve(f, &x);
  StepSummary s;
  s.iterations = s.jacobians = summary.iterations + 1;
  f(x.data(), r.data(), J.data());
  s.residual = max_abs(r);
  s.scale = s0 + max_abs(J) * max_abs(x) + opt.absolute_floor;
  s.converged = std::isfinite(s.residual) && s.residual <= opt.accept_tolerance * s.scale;
  if (!s.converged) s.message = "TinySolver ended above the residual tolerance";
  Eigen::Map<Eigen::VectorXd>(x_io, n) = x;
  return s;
}

}  // namespace

StepSummary solve_tiny_function(const TinyFunction& f, double* x, double /*x0*/, const StepOptions& opt, double s0) {
  // One workspace per thread (the runs of dvm sweep and of the Python module's threads
  // each have their own); a solve started inside another's evaluation of f, on the same
  // thread, gets a workspace of its own.
  thread_local TinyWork work;
  thread_local bool busy = false;
  if (busy) {
    TinyWork nested;
    return solve_in(nested, f, x, opt, s0);
  }
  busy = true;
  struct Release {
    bool& b;
    ~Release() { b = false; }
  } release{busy};
  return solve_in(work, f, x, opt, s0);
}

}  // namespace dvm
