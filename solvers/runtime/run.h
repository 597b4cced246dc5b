// A Run: one problem integrated by one method, built once by make_run.
//
//   auto run = dvm::make_run(problem, method);   // validates, dispatches once
//   dvm::Recorder rec(output);                   // optional: CSV / .npy rows
//   dvm::RunReport r = run->execute(&rec);       // the whole loop, then the summary
//   dvm::print_report(r, json);                  // the end-of-run table or JSON
//
// make_run resolves every choice of the problem and the method once, into one
// instantiation of a templated kernel (solvers/runtime/kernels.h): the loop inside
// execute() has no runtime dispatch, and at most one virtual call per step (the step of
// a run-time-sized or manifold system, or of a form compiled once per size, behind
// AnyRnStep or AnyPointStep; the steps of the fixed-size systems' own kernels are
// called directly). The kernel owns its
// step object and workspace. Initial-value and boundary-value problems, every form,
// every space, return the same report; numerical failures are reported in it
// (status "failed", the step, time, residual and message), never thrown.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "solvers/integrate.h"
#include "solvers/runtime/problem.h"
#include "solvers/runtime/recorder.h"

namespace dvm {

// How a run's steps use the structure of their equation (JSON step_path, named by
// to_string):
//   generic                     the step of the form and map as written (Newton on the
//                               whole equation, or the method's own solve)
//   explicit-splitting          kicks and drifts, no solve (solvers/splitting_step.h)
//   gauss-collocation           Gauss collocation iterated on the stage forces
//                               (solvers/collocation_step.h)
//   separable-newton            Newton on the structured equation, Jacobian M/h + Hess U
//                               (solvers/separable_theta_step.h)
//   separable-sparse-newton     the same with the sparse Hessian of a written potential
//                               (solvers/sparse_separable_step.h)
//   separable-dense-newton      the same with a dense Hessian of U kept across steps, n
//                               bodies (solvers/dense_separable_step.h)
//   constrained-sparse-newton   a theta map on a separable Lagrangian with constraints,
//                               the sparse saddle-point Jacobian formed once a step
//                               (solvers/sparse_constrained_step.h)
//   kept-jacobian-newton        a Lagrangian of run-time size that is not separable,
//                               its Jacobian kept across steps (Refresh::across_steps,
//                               solvers/newton_driver.h)
//   sphere-chain-banded-newton  the spherical chain's own step, banded Jacobian
//                               (solvers/sphere_chain_step.h)
// none: not reported (the manifold steps other than the chain's).
enum class StepPath {
  none,
  generic,
  explicit_splitting,
  gauss_collocation,
  separable_newton,
  separable_sparse_newton,
  separable_dense_newton,
  constrained_sparse_newton,
  kept_jacobian_newton,
  sphere_chain_banded_newton,
};
const char* to_string(StepPath p);  // "" for none
std::ostream& operator<<(std::ostream& o, StepPath p);

// A conserved quantity monitored along the run (besides the energy).
struct InvariantReport {
  std::string name;              // "angular momentum", "p_phi (cyclic)", ...
  std::vector<double> initial;   // its components at t = 0
  double max_abs_error = 0.0;    // max over the run and the components of |I(t) - I(0)|
  bool array = false;            // reported as an array (a vector quantity, or one per link)
};

struct RunReport {
  bool failed = false;
  std::string system;        // the system's display name
  std::string manifold;      // "S^2", "SO(3)", "(S^2)^n"; empty on R^n
  std::string map;           // the map's name; "none" for galerkin, "newmark" for newmark
  std::string method;        // "map" or "galerkin"
  std::string composition;   // "none" or the composition's name
  std::vector<double> weights;  // composition "dirk": its weights
  std::vector<double> thetas;   // composition "dirk": a theta per stage (empty: none given)
  std::string lift;             // hamiltonian and sode forms: the lift of the map; empty otherwise
  std::string solver;        // "newton" or "tiny"
  std::string form;
  std::string method_label;  // for the text table
  // R^n, fixed size: the system's structure ("separable", "mechanical", "general"),
  // whether the system declares it ("declared", checked at startup) or it was read off
  // the Lagrangian at sample points ("sampled"), and how each step is taken (StepPath).
  std::string structure, structure_source;
  StepPath step_path = StepPath::none;
  // How a Lagrangian written on R^n is differentiated: "program" (gradient and Hessian
  // differentiated symbolically once, mechanics/derivative_program.h),
  // "gradient-program" (the gradient so, the Hessian by forward over reverse mode on the
  // tape: texts with blocks of terms, or of more than 32 coordinates) or "tape" (both on
  // the tape: a power varying from term to term inside a block, or a graph beyond the
  // program's size).
  // Empty: not a written Lagrangian on R^n.
  std::string derivatives;
  // system.compile: whether those derivatives run compiled code, and the seconds the
  // C compiler took (before the run; not in wall_seconds)
  bool compiled = false;
  double compile_seconds = 0.0;
  // system.compile: what the chosen step still evaluates interpreted ("" nothing): the
  // sparse Hessian of U (step_path separable-sparse-newton, evaluated in Jets), L's
  // Hessian where its program has none (over 32 coordinates: on the tape)
  std::string interpreted;
  // step_path separable-sparse-newton: the colours of the Hessian's columns, so the
  // gradient passes per Jacobian are ceil(colours / 8) (-1: not such a path)
  int hessian_colours = -1;
  // step_path gauss-collocation: the steps whose fixed-point iteration did not converge,
  // solved by the generic Galerkin step's Newton iteration instead (-1: not such a path)
  std::int64_t newton_steps = -1;
  bool boundary_value = false;
  double step = 0.0;
  std::int64_t steps = 0, steps_requested = 0;
  double t_final = 0.0;
  std::vector<double> q_final, p_final;   // as stored (SO(3): quaternion [w, x, y, z])
  // The initial state as stored (boundary-value problems: the solved end, p_initial the
  // discrete momentum found there)
  std::vector<double> q_initial, p_initial;
  // The final point in embedding coordinates (SO(3): the nine entries of R), for
  // distances between runs.
  std::vector<double> q_embedded;
  double energy_initial = 0.0, energy_final = 0.0, max_abs_energy_error = 0.0;
  // A system with forces (system.forces): the discrete work W_k of the forces from t = 0
  // (the sum of each step's, StepSummary::work) and the energy balance E_k - E_0 - W_k,
  // its largest magnitude over the monitored steps; max_abs_energy_error is then the
  // energy's change, not a conservation error.
  bool forced = false;
  double work = 0.0, max_abs_energy_balance = 0.0;
  // A Lagrangian L(t, q, v) (system.lagrangian reads t): its energy <p, v> - L is not
  // conserved (it changes by minus the integral of dL/dt); max_abs_energy_error is then
  // its largest change, not a conservation error.
  bool time_dependent = false;
  // A system with holonomic constraints (system.constraints): how many, and the largest
  // relative residuals of the constraint and of its hidden constraint at the monitored
  // steps (WrittenConstraints::relative_residuals, mechanics/written_constraints.h).
  bool constrained = false;
  int constraints = 0;
  double max_constraint_residual = 0.0, max_hidden_constraint_residual = 0.0;
  double max_point_defect = -1.0;  // manifolds only (< 0: not reported)
  std::vector<InvariantReport> invariants;
  double wall_seconds = 0.0;
  std::int64_t monitor_every = 1;  // initial-value runs: the steps between evaluations of the energy
  // Iterations of the step equations' solves (Newton, fixed-point sweeps, or Ceres'
  // iterations for boundary values), summed over the steps, and the Jacobians formed
  // (fewer where a Jacobian is kept within or across steps).
  std::int64_t solver_iterations = 0, jacobians = 0;
  int max_step_iterations = 0;
  int order = 0;  // the order the method is built to have (Method::order; 0: none stated)
  // galerkin
  int stages = 0;
  std::string quadrature;
  // newmark
  bool newmark = false;
  double gamma = 0.0, beta = 0.0;
  // boundary-value problems
  double max_del_residual = 0.0, residual_scale = 0.0;
  double momentum_spread = -1.0;  // S^2: spread of J3 along the solution (< 0: none)
  std::string message;
  // initial-value problems: the loop's summary (failure: step, time, residual, message)
  RunSummary loop;
  // output
  std::vector<std::string> written;  // files written (complete runs)
  std::string kept;                  // the .partial files of a failed run
  bool output_error = false;         // a file could not be finished (write error)
};

class Run {
 public:
  virtual ~Run() = default;
  // Integrates (or solves the boundary-value problem), writing rows to `recorder`
  // when given. Throws InputError only for output that cannot be opened (before any
  // step); numerical failures are in the report.
  virtual RunReport execute(Recorder* recorder) = 0;
  // The exact solution at time t from the initial state, where the system has one
  // (q in embedding coordinates as RunReport::q_embedded, p as stored); false if not.
  virtual bool exact(double t, std::vector<double>& q, std::vector<double>& p) const = 0;
  // The energy at the initial state (finite, or the problem was refused).
  virtual double initial_energy() const = 0;
};

// Validates the problem and the method (validate in problem.h) and builds the run.
// Throws InputError for bad input (unknown names, combinations the registry does not
// support, a degenerate Lagrangian at the initial state, a non-finite initial energy).
std::unique_ptr<Run> make_run(const Problem& problem, const Method& method);

// The end-of-run summary: a table on stdout (quiet: nothing) or JSON; a failure's
// message on stderr.
// The summary goes to `to`: standard output, or standard error when the rows stream to
// standard output.
void print_report(const RunReport& report, bool json, bool quiet, std::FILE* to = stdout);

// The JSON object of a report (the "failure" object included).
std::string report_json(const RunReport& report);

// What a failed run prints on stderr (after "dvm: "): the step, its times, the
// residual and why it stopped, or the boundary-value solve's residuals; "" for a run
// that did not fail.
std::string run_failure_message(const RunReport& report);

// x with the fewest significant digits (15 to 17) that read back as x.
std::string shortest(double x);

}  // namespace dvm
