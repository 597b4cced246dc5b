// Kernels for systems whose size is known only at run time (mechanics/dynamic_system.h):
// N bodies with any number of bodies, Lagrangians written in a scene with any number
// of coordinates. One instantiation per system type, none per size:
//
//   form / method   step (solvers/dynamic_step.h, solvers/dynamic_galerkin_step.h)
//   lagrangian      ExplicitSplittingStep for theta 0 or 1 on a separable system (n
//                   bodies; a written Lagrangian whose text is separable, through
//                   WrittenSeparable), composition included;
//                   SparseSeparableThetaStep for the other theta maps on a written
//                   separable Lagrangian (sparse Hessian of U, any size), and
//                   DenseSeparableThetaStep<Sys> on the other separable systems (n
//                   bodies; a written text whose Hessian of U is not sparse);
//                   DynamicThetaStep<Sys>   (the theta-family maps, its Jacobian
//                   kept across steps from kKeptJacobianMinDim coordinates unless
//                   use_structure = false; retraction-theta
//                   with the flat retraction R_x(v) = x + v is the theta map itself,
//                   R_d(x, v) = (x - theta v, x + (1 - theta) v), and is inverted here
//                   in closed form)
//   hamiltonian     DynamicHamiltonianThetaStep of the scene's written H, or of H from
//                   L by the Legendre transform
//   sode1 / sode2   DynamicSodeStep<Sys> (solvers/dynamic_sode_step.h) through the tangent
//   / newmark       or Legendre lift of the theta maps, or Newmark's map; separable systems
//                   only (U(q), or U(t, q) for a written Lagrangian in t)
//   galerkin        DynamicGalerkinStep<Sys>
//   boundary value  DynamicBoundaryValueProblem<Sys> (solvers/dynamic_boundary_value.h) of
//                   a written Lagrangian, the theta-family maps; none with forces,
//                   constraints or L(t, q, v)
//   composition     ComposedStep of any of these steps, the adjoint stages at 1 - theta
//                   (Newmark's at (1 - gamma, 1/2 - gamma + beta))
//   system.forces   the theta, Galerkin and Hamiltonian steps with their Force
//                   (WrittenForce), never the structured separable paths of an
//                   unconstrained system
//   system.constraints  ConstrainedThetaStep (solvers/constrained_step.h), forces or
//                   not, composed or not (make_constrained_run, kernels_constrained.cc:
//                   of fixed size for 2 and 3 coordinates and one constraint without a
//                   force; SparseConstrainedThetaStep for a separable text of 12
//                   coordinates or more, forces or not), and ConstrainedGalerkinStep (Lobatto,
//                   solvers/constrained_galerkin_step.h); the initial state checked
//                   against the constraints (check_constrained_start)
//   L(t, q, v)      (a written Lagrangian that reads t) the generic steps above, which
//                   evaluate L at their nodes' times (has_time); its text is given no
//                   separable or mechanical structure (WrittenParts), so no structured
//                   path is taken; the view evaluates it at t_k (after_step). The SODE
//                   and Newmark steps take it where M is constant (sode_applies)
// Included only by the kernels_*.cc translation units.
#pragma once

#include <cmath>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/nbody_dynamic.h"
#include "mechanics/written_constraints.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_force.h"
#include "solvers/dynamic_boundary_value.h"
#include "solvers/dynamic_galerkin_step.h"
#include "solvers/dynamic_sode_step.h"
#include "solvers/dynamic_step.h"
#include "solvers/dense_separable_step.h"
#include "solvers/sparse_separable_step.h"
#include "solvers/runtime/kernels.h"

namespace dvm::kernels {

// What a run-time-sized system monitors besides the energy.
inline std::vector<InvariantReport> dynamic_invariant_names(const NBodyDynamic&) {
  std::vector<InvariantReport> out;
  for (const char* n : {"momentum x", "momentum y", "momentum z", "angular momentum x", "angular momentum y",
                        "angular momentum z"}) {
    InvariantReport r;
    r.name = n;
    r.initial = {0.0};
    out.push_back(r);
  }
  return out;
}
inline void dynamic_invariant_values(const NBodyDynamic&, const Eigen::VectorXd& q, const Eigen::VectorXd& p,
                                     double* out) {
  const auto m = NBodyDynamic::momenta(q, p);
  for (int i = 0; i < 6; ++i) out[i] = m[static_cast<std::size_t>(i)];
}
// A coordinate that L does not depend on, no force acts along and no constraint
// involves: its momentum is conserved (with a force along it, it changes by the force's
// impulse; a constraint in it exerts a force along it too).
inline bool conserved_momentum(const WrittenDynamic& L, int i) {
  if (!L.cyclic(i)) return false;
  for (const auto& f : L.system()->forces)
    if (f.first == i) return false;
  for (const Expression& g : L.system()->constraints)
    if (g.uses(0, i)) return false;
  return true;
}
// The scene's own invariants ([system] invariants, in its order), then the momentum of
// each coordinate that L does not depend on and no force acts along (cyclic: conserved),
// up to kMaxInvariantValues in all.
inline std::vector<InvariantReport> dynamic_invariant_names(const WrittenDynamic& L) {
  std::vector<InvariantReport> out;
  for (const auto& [name, expression] : L.system()->invariants) {
    InvariantReport r;
    r.name = name;
    r.initial = {0.0};
    out.push_back(r);
  }
  for (int i = 0; i < L.dim() && static_cast<int>(out.size()) < kMaxInvariantValues; ++i)
    if (conserved_momentum(L, i)) {
      InvariantReport r;
      r.name = "p_" + L.system()->coordinates[static_cast<std::size_t>(i)] + " (cyclic)";
      r.initial = {0.0};
      out.push_back(r);
    }
  return out;
}
// The scene's own invariants, also written as CSV columns after the energy (none for n
// bodies). The run's buffers hold kMaxInvariantValues values: the scene reader's limit
// must not exceed it.
static_assert(kMaxWrittenInvariants <= kMaxInvariantValues, "[system] invariants would overrun the run's buffers");
inline std::size_t own_invariant_count(const NBodyDynamic&) { return 0; }
inline std::size_t own_invariant_count(const WrittenDynamic& L) { return L.system()->invariants.size(); }
inline int written_invariant_values(const NBodyDynamic&, const Eigen::VectorXd&, const Eigen::VectorXd&, double*) {
  return 0;
}
// The scene's invariants at (q, p) (v = FL^{-1}(q, p) for the expressions), into out.
inline int written_invariant_values(const WrittenDynamic& L, const Eigen::VectorXd& q, const Eigen::VectorXd& p,
                                    double* out) {
  const auto& own = L.system()->invariants;
  if (own.empty()) return 0;
  const Eigen::VectorXd v = legendre_inverse(L, q, p);
  for (std::size_t i = 0; i < own.size(); ++i) out[i] = own[i].second(q.data(), v.data(), p.data());
  return static_cast<int>(own.size());
}
inline void dynamic_invariant_values(const WrittenDynamic& L, const Eigen::VectorXd& q, const Eigen::VectorXd& p,
                                     double* out) {
  int k = written_invariant_values(L, q, p, out);
  for (int i = 0; i < L.dim() && k < kMaxInvariantValues; ++i)
    if (conserved_momentum(L, i)) out[k++] = p[i];
}
// n bodies: v = M^{-1} p in closed form, so <dL/dv, v> = <p, v> and E = <p, v> - L(q, v)
// without the gradient (whose pair loop costs as much as L's)
inline double dynamic_energy(const NBodyDynamic& L, const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                             const Eigen::VectorXd& p) {
  return p.dot(v) - L.value(q, v);
}
inline double dynamic_energy(const WrittenDynamic& L, const Eigen::VectorXd& q, const Eigen::VectorXd& v,
                             const Eigen::VectorXd& p) {
  return L.energy_at(q, v, p);
}

// The run's view of a run-time-sized system; K: the number of coordinates where the
// runtime compiles the run for it (the state then of fixed size), else Dynamic.
template <class Sys, int K = Eigen::Dynamic>
struct DynamicView {
  using Point = Vec<double, K>;
  using Covector = Vec<double, K>;
  static constexpr bool erase_steps = true;  // (AnyRnStep: their steps solve an equation each step)
  Sys L;
  std::vector<std::string> names;  // coordinate names of the columns (empty: q0.., p0..)
  Vec<double, 2> sigma0 = Vec<double, 2>::Zero();  // the scale of d2L/dv2 at the initial state
  bool constant_hessian = false;  // d2L/dv2 is the same everywhere (sigma0 is then not computed)
  int n() const { return L.dim(); }

  // d2L/dv2 at (q, v)
  Eigen::MatrixXd velocity_hessian(const Point& q, const Point& v) const {
    const int m = n();
    Eigen::VectorXd Lq(m), Lv(m);
    Eigen::MatrixXd Lqq(m, m), Lqv(m, m), Lvv(m, m);
    L.hessian(q, v, Lq, Lv, Lqq, Lqv, Lvv);
    return Lvv;
  }

  std::vector<std::string> columns() const {
    std::vector<std::string> c{"t"};
    for (int i = 0; i < n(); ++i) c.push_back(names.empty() ? "q" + std::to_string(i) : names[static_cast<std::size_t>(i)]);
    for (int i = 0; i < n(); ++i)
      c.push_back(names.empty() ? "p" + std::to_string(i) : "p_" + names[static_cast<std::size_t>(i)]);
    c.push_back("energy");
    const std::vector<InvariantReport> named = dynamic_invariant_names(L);  // the scene's own first
    for (std::size_t i = 0; i < own_invariant_count(L); ++i) c.push_back(named[i].name);
    return c;
  }
  int row_size() const { return 2 * n() + 2 + static_cast<int>(own_invariant_count(L)); }
  void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const {
    row[0] = t;
    for (int i = 0; i < n(); ++i) row[1 + i] = q[i], row[1 + n() + i] = p[i];
    row[2 * n() + 1] = E;
    if (own_invariant_count(L) > 0) written_invariant_values(L, q, p, row + 2 * n() + 2);
  }
  // E at (q, p), v = FL^{-1}(q, p) as legendre_inverse finds it (a closed form, else
  // Newton's method from v = 0), in the view's workspace: a run monitors the energy
  // every step by default, and vectors allocated per call are a visible part of a
  // written system's step (compare `dvm run` of a written scene with
  // output.monitor_every at its default and at the step count).
  double energy(const Point& q, const Covector& p) const { return dynamic_energy(L, q, velocity_at(q, p), p); }
  int invariant_count() const { return static_cast<int>(dynamic_invariant_names(L).size()); }
  void invariants(const Point& q, const Covector& p, double* out) const { dynamic_invariant_values(L, q, p, out); }
  std::vector<InvariantReport> invariant_reports(const double* I0) const {
    std::vector<InvariantReport> r = dynamic_invariant_names(L);
    for (std::size_t i = 0; i < r.size(); ++i) r[i].initial[0] = I0[i];
    return r;
  }
  double point_defect(const Point&) const { return -1.0; }
  // With constraints (system.constraints): the relative residuals of the constraint and
  // of its hidden constraint at (t, q, p) (WrittenConstraints::relative_residuals, v =
  // FL^{-1}(q, p) in the view's workspace); false without.
  bool constraint_residuals(double t, const Point& q, const Covector& p, double& g, double& hidden) const {
    if (!constraints) return false;
    constraints->relative_residuals(t, q, velocity_at(q, p), g, hidden);
    return true;
  }
  std::shared_ptr<WrittenConstraints> constraints = nullptr;  // the view's own (their workspace), or null
  // The run's control inputs (system.controls), or null: after step k - 1 -> k the
  // forces read u_k (ControlSignal::set_step). A Lagrangian L(t, q, v) is evaluated at
  // t_k by what the view monitors there (the energy, invariants, constraint residuals).
  std::shared_ptr<const ControlSignal> controls = nullptr;
  void after_step(std::int64_t k, double t) const {
    if (controls) controls->set_step(k);
    if constexpr (has_time<Sys>::value) L.set_time(t);
  }
  void finish_report(RunReport& r, const Point& q, const Covector& p) const {
    r.q_final.assign(q.data(), q.data() + q.size());
    r.p_final.assign(p.data(), p.data() + p.size());
    r.q_embedded = r.q_final;
  }
  // what the Legendre transform looks like where a solve stopped (mechanics/hamiltonian.h)
  void diagnose(std::string& message, const Point& q, const Covector& p) const {
    try {
      const Vec<double, 2> s = matrix_hessian_scale(velocity_hessian(q, legendre_inverse(L, q, p)));
      message += "; " + legendre_scale_diagnosis(s, constant_hessian ? s : sigma0);
    } catch (const std::domain_error& e) {
      message += std::string("; at the last completed state the Legendre transform cannot be inverted: ") + e.what();
    }
  }
  bool exact(double, const Point&, const Covector&, std::vector<double>&, std::vector<double>&) const { return false; }

  // v = FL^{-1}(q, p) for energy() and constraint_residuals(), in the view's workspace
  const Eigen::VectorXd& velocity_at(const Point& q, const Covector& p) const {
    if (velocity_.size() != n()) velocity_.resize(n());
    dynamic_detail::legendre_inverse(L, q, p, velocity_, legendre_, true);
    return velocity_;
  }
  // velocity_at's workspace (sized at the first call, the n x n blocks of Newton's
  // method only where L's velocity has no closed form; a copy of the view has its own)
  mutable Eigen::VectorXd velocity_ = Eigen::VectorXd();
  mutable dynamic_detail::LegendreWork legendre_ = dynamic_detail::LegendreWork(0);
};

// Whether a run-time-sized system is separable: declared (n bodies), or read off the
// text of a written Lagrangian (WrittenDynamic::separable()).
template <class Sys>
bool dynamic_separable(const Sys& L) {
  if constexpr (std::is_same_v<Sys, WrittenDynamic>)
    return L.separable();
  else
    return (void)L, is_separable_v<Sys>;
}

// Whether the SODE and Newmark steps (solvers/dynamic_sode_step.h) take the system: a
// separable one, or a written L(t, q, v) = v^T M v / 2 + U(t, q) with M constant (they
// evaluate it at their times; M's definiteness is checked when M^{-1} is formed).
template <class Sys>
bool sode_applies(const Sys& L) {
  if constexpr (std::is_same_v<Sys, WrittenDynamic>)
    return L.separable() || L.parts().timed_constant_mass;
  else
    return dynamic_separable(L);
}

// A written Lagrangian's structure, from its text (WrittenParts): separable when its
// terms are v^T M v / 2 with M constant plus terms in q, and M is positive definite (its
// factorisation); mechanical when the quadratic terms' coefficients depend on q and
// the sample test of mechanics/structure.h finds M(q) symmetric positive definite
// around the initial state; general otherwise.
inline void report_structure(RunReport& r, const WrittenDynamic& L, const Eigen::VectorXd& q,
                             const Eigen::VectorXd& v0, const Problem&) {
  const WrittenParts& w = L.parts();
  Structure s = Structure::general;
  if (w.separable) {
    s = Structure::separable;
  } else if (w.split.quadratic && !w.split.constant_mass) {
    try {
      if (test_structure(L, Structure::mechanical, q, v0).holds) s = Structure::mechanical;
    } catch (const std::exception&) {
      // a sample outside the Lagrangian's domain: "general"
    }
  }
  r.structure = structure_name(s);
  r.structure_source = "expression";
  r.step_path = StepPath::generic;
  const DerivativeProgram* d = L.derivative_program();
  r.derivatives = !d ? "tape" : d->has_hessian() ? "program" : "gradient-program";
  r.compiled = L.compiled();
  r.compile_seconds = L.compile_seconds();
  if (r.compiled && !d->has_hessian()) r.interpreted = "L's Hessian (on the tape: over 32 coordinates)";
}

// From this many coordinates an implicit theta map on a separable system solves the
// structured equation (sparse or dense, its Jacobian kept across steps); below, the
// generic step of fixed size (kFixedWrittenMaxDim) costs less (bench_written_lagrangian
// compares them). The fixed-size built-ins draw the line at the same place
// (solvers/runtime/kernels_rn.h).
constexpr int kStructuredNewtonMinDim = 3;

// The dense steps of a run-time-sized system form n x n matrices (the Newton Jacobian,
// the velocity Hessian); beyond this many coordinates they are refused rather than
// left to run out of memory or time.
constexpr int kMaxDenseDynamicDim = 4096;
// Refuses (InputError, exit 2) n coordinates beyond kMaxDenseDynamicDim for `what` (the
// key and value that ask for the dense step), `otherwise` appended (what would run).
inline void require_dense_size(int n, const std::string& what, const std::string& otherwise = "") {
  if (n > kMaxDenseDynamicDim)
    throw InputError(what + " needs dense " + std::to_string(n) + " x " + std::to_string(n) + " matrices, beyond the " +
                     std::to_string(kMaxDenseDynamicDim) + " coordinates the run-time-sized dense steps take" +
                     otherwise);
}

// From this many coordinates the position-momentum step of a Lagrangian that is not
// separable keeps its Jacobian across steps (simplified Newton, Refresh::across_steps of solvers/newton_driver.h).
// A kept Jacobian takes more gradients of L a step (its iteration converges linearly)
// where Newton's method takes fewer Hessians; a written Hessian of n <= 4 coordinates
// is one pass of 8 forward derivatives, about a gradient's cost, so there keeping it
// loses; from n = 8 it wins, by more as n grows (a written chain whose mass matrix
// depends on q, measured by bench_written_lagrangian; solvers/README.md has the table).
constexpr int kKeptJacobianMinDim = 8;

// Up to this many coordinates the position-momentum step of a written Lagrangian is
// compiled for its size (DynamicThetaStep<WrittenDynamic, K>, K = 1, 2): loops, norms
// and LU of fixed length, one Hessian of L a step where its first Jacobian serves
// (solvers/dynamic_step.h), faster at these sizes than keeping the Jacobian across
// steps (Refresh::across_steps of solvers/newton_driver.h). The explicit steps of a
// separable text of so few coordinates are compiled for its size too, and so is their
// run's state (WrittenSeparableOf<K>, DynamicView<Sys, K>). bench_written_lagrangian
// measures both choices.
constexpr int kFixedWrittenMaxDim = 2;

// A written system's derivatives: compiled where the scene asks (system.compile), the
// compiler's failure an input error naming the key. make(mode) builds the system.
template <class Make>
auto compiled_or_not(const Make& make, const Problem& pr) {
  if (!pr.compile) return make(WrittenDerivatives::automatic);
  try {
    return make(WrittenDerivatives::compiled);
  } catch (const NativeCodeError& e) {
    throw InputError(pr.origin + ": system.compile: " + e.what());
  }
}

// The force at the initial state (t = 0) is finite, or the run is refused.
inline void require_finite_force(const WrittenForce& force, const Problem& pr, const Eigen::VectorXd& q,
                                 const Eigen::VectorXd& v) {
  Eigen::VectorXd F(q.size());
  force.value(0.0, q, v, F);
  if (F.allFinite()) return;
  std::ostringstream m;
  m.precision(17);
  m << pr.forces_where << ": the force is not finite at the initial state (t = 0): F = [";
  for (Eigen::Index i = 0; i < F.size(); ++i) m << (i ? ", " : "") << F[i];
  throw InputError(m.str() + "]");
}

// The initial state of a constrained run (system.constraints): the constraint Jacobian
// Dg(0, q) of full rank m, q on the constraints and v on their hidden constraint, each
// to kConstraintStartTolerance relative; an initial velocity (or momentum) off the
// hidden constraint is refused, or projected onto it where the scene sets
// initial.project_velocity (p, v0 are then replaced). Throws InputError naming the key.
void check_constrained_start(const WrittenDynamic& L, const Problem& pr, const Eigen::VectorXd& q,
                             Eigen::VectorXd& p, Eigen::VectorXd& v0);

// From this many coordinates a constrained theta step on a separable Lagrangian, with a
// force or not, is the sparse one (solvers/sparse_constrained_step.h); below, the dense
// one costs less (bench_constrained's table of chains compares them).
constexpr int kSparseConstrainedMinDim = 12;

// The run of a written system with constraints (system.constraints): the constrained
// theta step, with the force where the system has one (the lagrangian form of the
// theta-family maps, composed or not: the registry's "lagrangian with constraints"),
// from the initial state make_dynamic_run checked. Its own translation unit
// (kernels_constrained.cc), compiled beside kernels_written.cc.
std::unique_ptr<Run> make_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                          const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                          const Eigen::VectorXd& p, const Eigen::VectorXd& v0, const RunReport& base,
                                          const std::shared_ptr<const ControlSignal>& signal);

// The constrained run on sparse matrices (SparseConstrainedThetaStep) for
// make_constrained_run, from a separable L with its constraints and its force (or
// none); null where the potential's Hessian is not sparse enough for it. Its own
// translation unit (kernels_sparse_constrained.cc).
std::unique_ptr<Run> make_sparse_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                                 const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                                 const Eigen::VectorXd& p, const Eigen::VectorXd& v0, RunReport base,
                                                 const std::shared_ptr<const WrittenConstraints>& con,
                                                 const std::shared_ptr<const WrittenForce>& force);

// `hamiltonian`: the written H, when the scene gives one (null: H from L).
template <class Sys>
std::unique_ptr<Run> make_dynamic_run(const Sys& L, const Problem& pr, const Method& me,
                                      const std::vector<std::string>& names,
                                      const std::shared_ptr<const WrittenSystem>& hamiltonian) {
  using V = Eigen::VectorXd;
  DynamicView<Sys> view{L, names};
  RunReport base = base_report(pr, me, L.name());
  const StepOptions opt = me.step_options();
  const double h = pr.step;
  const int n = L.dim();
  const std::string where = pr.written ? pr.written_where : pr.origin;
  // --linearize (a written Lagrangian, n bodies) takes the theta step of run-time size or
  // Galerkin, never the structured paths or the steps compiled for a size below: only
  // those runs compile their steps' derivatives
  constexpr bool linearizable = std::is_same_v<Sys, WrittenDynamic> || std::is_same_v<Sys, NBodyDynamic>;

  // the initial state, with the velocity Hessian checked where it is used; a declared
  // separable system has d2L/dv2 = M, constant and positive definite (checked at sample
  // points by report_structure below), so no n x n matrix is formed and factored for it
  // (n bodies: 3n x 3n)
  const bool constant_hessian = dynamic_separable(L);
  view.constant_hessian = constant_hessian;
  const V q = Eigen::Map<const V>(pr.q.data(), n);
  V p(n), v0(n);
  auto dense_limit = [&](const std::string& what) {
    require_dense_size(n, what,
                       "; on a separable system map = \"explicit-euler\" or \"adjoint-euler\", composed or not, steps "
                       "without them");
  };
  if (pr.boundary_value) {
    // a written Lagrangian, with a map of the theta family (validate refuses n bodies,
    // forces, constraints, L in t and written maps here); dense n x n Jacobian blocks
    if constexpr (std::is_same_v<Sys, WrittenDynamic>) {
      dense_limit("problem.kind = \"boundary-value\" (the Jacobian blocks of its nodes)");
      const ThetaMap R = dynamic_theta_map(me);
      return std::make_unique<BoundaryValueRun<DynamicView<Sys>, DynamicBoundaryValueProblem<Sys>>>(
          view, DynamicBoundaryValueProblem<Sys>(L, R.theta(), h), Eigen::Map<const V>(pr.q.data(), n),
          Eigen::Map<const V>(pr.q_final.data(), n), pr.steps, h, me.max_iterations, base, false);
    } else {
      throw InputError("problem.kind: unsupported");  // refused by validate()
    }
  }
  if (!constant_hessian)
    dense_limit("system: a Lagrangian that is not separable (its velocity Hessian, checked at the start)");
  const std::vector<std::string> velocities = velocity_names(pr);
  auto check = [&](const V& v) {
    if (!constant_hessian) require_regular_hessian(view.velocity_hessian(q, v), where, velocities);
  };
  if (pr.momentum_given) {
    p = Eigen::Map<const V>(pr.p.data(), n);
    check(V::Zero(n));
    try {
      v0 = legendre_inverse(L, q, p);
    } catch (const DegenerateLagrangianError& e) {
      throw InputError(where + ": the Lagrangian is degenerate at the initial state: " + e.what());
    }
  } else {
    v0 = Eigen::Map<const V>(pr.v.data(), n);
    p = legendre(L, q, v0);
  }
  check(v0);
  if (!constant_hessian) view.sigma0 = matrix_hessian_scale(view.velocity_hessian(q, v0));
  if constexpr (std::is_same_v<Sys, WrittenDynamic>) {
    if (hamiltonian) {
      const double H = L.hamiltonian(q, p), E = energy(L, q, v0);
      if (!(std::fabs(H - E) <= 1e-9 * std::fmax(1.0, std::fabs(E)))) {
        std::ostringstream m;
        m.precision(17);
        m << pr.hamiltonian_where << ": system.hamiltonian does not match the Legendre transform of the Lagrangian at "
          << "the initial state: H(q, p) = " << H << " but E_L(q, v) = <p, v> - L = " << E;
        throw InputError(m.str());
      }
    }
  }
  // system.controls: one signal for the run, read by every copy of the force
  std::shared_ptr<const ControlSignal> signal;
  if constexpr (std::is_same_v<Sys, WrittenDynamic>)
    if (!pr.written->controls.empty()) {
      signal = std::make_shared<const ControlSignal>(pr.written->controls);
      view.controls = signal;
    }
  if constexpr (std::is_same_v<Sys, WrittenDynamic>)
    if (pr.constrained()) {
      check_constrained_start(L, pr, q, p, v0);
      view.constraints = std::make_shared<WrittenConstraints>(pr.written);
      base.constrained = true;
      base.constraints = static_cast<int>(pr.written->constraints.size());
    }
  if (!std::isfinite(view.energy(q, p))) refuse_nonfinite_energy(pr);
  if constexpr (std::is_same_v<Sys, WrittenDynamic>) base.time_dependent = L.time_dependent();
  report_structure(base, L, q, v0, pr);
  require_splitting_structure(base, me, pr);

  // the sode and newmark forms (paper Sec. 4) on a separable system, whose acceleration's
  // Jacobian comes from L's Hessian (solvers/dynamic_sode_step.h): the tangent or Legendre
  // lift of a theta map, or Newmark's map on TQ; composed or not, as the fixed-size steps
  // are; with the force where the system has one (Force: NoForce for none)
  auto sode_run = [&](auto force) -> std::unique_ptr<Run> {
    using Force = std::remove_const_t<typename decltype(force)::element_type>;
    const std::string form = "form = \"" + std::string(to_string(me.form)) + "\"";
    if (!sode_applies(L))
      throw InputError(pr.origin + ": key 'integrator.form': " + form +
                       " on a system of run-time size needs a separable Lagrangian, "
                       "v^T M v / 2 - U(q) or - U(t, q) with M constant (its acceleration's Jacobian then needs "
                       "second derivatives of L only); " + where + " is not separable (the built-in systems of fixed "
                       "size run these forms on any Lagrangian)");
    dense_limit("integrator.form: " + form);
    using Step = DynamicSodeStep<Sys, Force>;
    MassInverse Minv;
    try {
      Minv = Step::mass_inverse(L, q, v0);
    } catch (const std::invalid_argument&) {  // (separable texts are checked when read: only L(t, q, v) here)
      throw InputError(pr.origin + ": key 'integrator.form': " + form + " needs the constant mass matrix M = "
                       "d2L/dv2 positive definite; " + where + " has an M that is not");
    }
    if (me.form == Form::newmark) {
      const Step basic(L, Minv, SodeScheme::newmark(me.newmark_gamma, me.newmark_beta), h, opt, force);
      auto make = [](double hk, const Step& b) { return b.with_step(hk); };
      const auto stages = composition_stages(
          me, basic, me.newmark_gamma == 0.5, [](const Step& b) { return b.adjoint(); },
          [&](double) -> Step { throw InputError("integrator.thetas: unsupported"); });  // refused by validate()
      return composable_run(view, me, h, stages, make, q, p, v0, base, pr.steps);
    }
    const bool first = me.form == Form::sode1, legendre = me.effective_lift() == Lift::legendre;
    auto make = [&](double hk, const ThetaMap& Rk) {
      return Step(L, Minv, SodeScheme::sode(first, Rk.theta(), legendre), hk, opt, force);
    };
    return composable_run(view, me, h, rn_stages(me, dynamic_theta_map(me)), make, q, p, v0, base, pr.steps);
  };

  // system.constraints: the constrained theta and Galerkin steps (kernels_constrained.cc)
  if constexpr (std::is_same_v<Sys, WrittenDynamic>)
    if (pr.constrained()) return make_constrained_run(L, pr, me, view, q, p, v0, base, signal);

  // system.forces: the forced steps (the forms and methods the registry's "lagrangian
  // with forces" admits: the theta step, composed or not, Galerkin, the Hamiltonian
  // step, the SODE and Newmark steps), never the structured paths below, whose
  // equations have no force term; sizes and Jacobian refresh as the unforced steps' below
  if constexpr (std::is_same_v<Sys, WrittenDynamic>)
    if (pr.forced()) {
      const auto force = std::make_shared<WrittenForce>(pr.written, signal);
      require_finite_force(*force, pr, q, v0);
      base.forced = true;
      if (me.form == Form::sode1 || me.form == Form::sode2 || me.form == Form::newmark)
        return sode_run(std::shared_ptr<const WrittenForce>(force));
      if (me.galerkin) {
        dense_limit("integrator.method: method = \"galerkin\" with system.forces");
        return stepper_run<linearizable>(
            view, DynamicGalerkinStep<Sys, WrittenForce>(L, me.quadrature, me.stages, h, opt, force), q, p, v0, base,
            pr.steps);
      }
      dense_limit("integrator.map: map = \"" + me.map->name + "\" with system.forces");
      const ThetaMap R = dynamic_theta_map(me);
      if (me.form == Form::hamiltonian) {  // the forced Hamilton equations, as the unforced form below
        const bool on_bundle = me.effective_lift() == Lift::none;
        auto run_with = [&](const auto& H) {
          using Step = DynamicHamiltonianThetaStep<std::decay_t<decltype(H)>, WrittenForce>;
          auto make = [&](double hk, const ThetaMap& Rk) { return Step(H, Rk, hk, opt, on_bundle, force); };
          return composable_run<linearizable>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
        };
        if (hamiltonian) {
          const auto H =
              compiled_or_not([&](WrittenDerivatives m) { return WrittenDynamicHamiltonian(hamiltonian, m); }, pr);
          base.compile_seconds += H.compile_seconds();
          return run_with(H);
        }
        return run_with(LegendreDynamicHamiltonian<Sys>(L));
      }
      if (n <= kFixedWrittenMaxDim && me.use_structure && !me.linearize) {
        auto run_fixed = [&](auto k) {
          constexpr int K = decltype(k)::value;
          auto make = [&](double hk, const ThetaMap& Rk) {
            return DynamicThetaStep<Sys, K, WrittenForce>(L, Rk, hk, opt, false, force);
          };
          return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
        };
        if (n == 1) return run_fixed(std::integral_constant<int, 1>());
        return run_fixed(std::integral_constant<int, 2>());
      }
      const bool keep = me.use_structure && n >= kKeptJacobianMinDim;
      if (keep) base.step_path = StepPath::kept_jacobian_newton;
      auto make = [&](double hk, const ThetaMap& Rk) {
        return DynamicThetaStep<Sys, Eigen::Dynamic, WrittenForce>(L, Rk, hk, opt, keep, force);
      };
      return composable_run<linearizable>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
    }

  // (--linearize: the generic theta step, which gives its derivative)
  if (me.form == Form::lagrangian && !me.galerkin && !me.linearize) {
    const ThetaMap R = dynamic_theta_map(me);
    if (splitting_applies(me, R)) {
      if constexpr (is_separable_v<Sys>)
        return splitting_run(view, L, R, me, h, q, p, v0, base, pr.steps);
      if constexpr (std::is_same_v<Sys, WrittenDynamic>) {
        if (L.separable() && n <= kFixedWrittenMaxDim && me.use_structure) {
          // compiled for its size, the run's state too (kFixedWrittenMaxDim)
          auto run_fixed = [&](auto k) {
            constexpr int K = decltype(k)::value;
            using Step = ExplicitSplittingStep<WrittenSeparableOf<K>>;
            base.step_path = StepPath::explicit_splitting;
            base.interpreted.clear();  // the force alone (U's program, compiled with L's)
            const Vec<double, K> qk = q, pk = p, vk = v0;
            const DynamicView<Sys, K> fixed{view.L, view.names, view.sigma0, view.constant_hessian};
            return stepper_run(
                fixed, Step(WrittenSeparableOf<K>(L), R.theta(), h, method_substeps(me, R.symmetric()), qk), qk, pk,
                vk, base, pr.steps);
          };
          if (n == 1) return run_fixed(std::integral_constant<int, 1>());
          return run_fixed(std::integral_constant<int, 2>());
        }
        if (L.separable()) {
          base.interpreted.clear();  // the force alone (U's program, compiled with L's)
          return splitting_run(view, WrittenSeparable(L), R, me, h, q, p, v0, base, pr.steps);
        }
      }
    }
  }
  if (collocation_applies(me) && !me.linearize) {  // (--linearize: the Newton step, which gives its derivative)
    // any size: the Newton iteration a step may be handed to is dense (at most the limit)
    if constexpr (is_separable_v<Sys>)
      return collocation_run(view, SeparableGaussStep<Sys>(L, me.stages, h, opt, q, kMaxDenseDynamicDim), q, p, v0,
                             base, pr.steps);
    if constexpr (std::is_same_v<Sys, WrittenDynamic>)
      if (L.separable())
        return collocation_run(view,
                               SeparableGaussStep<WrittenSeparable, 0, WrittenDynamic>(WrittenSeparable(L), L, me.stages,
                                                                                       h, opt, q, kMaxDenseDynamicDim),
                               q, p, v0, base, pr.steps);
  }
  // a theta map (composed or not, a theta per stage included) on a separable system:
  // Newton on the structured equation, with the sparse Hessian of U where the text of a
  // written Lagrangian gives one, a dense one otherwise (n bodies)
  if (me.form == Form::lagrangian && !me.galerkin && dynamic_separable(L) && separable_newton_applies(me) &&
      n >= kStructuredNewtonMinDim && !me.linearize) {
    const ThetaMap R = dynamic_theta_map(me);
    if constexpr (std::is_same_v<Sys, WrittenDynamic>) {
      std::shared_ptr<SparsePotentialHessian> H;
      try {
        H = SparseSeparableThetaStep::hessian_of(L, q);
      } catch (const SparsePotentialHessian::TooDense&) {
        // terms coupling most coordinates: the dense Jacobian below, within its limit
      }
      if (H) {
        auto make = [&](double hk, const ThetaMap& Rk) { return SparseSeparableThetaStep(L, H, Rk.theta(), hk, opt); };
        base.step_path = StepPath::separable_sparse_newton;
        base.hessian_colours = H->colours();
        if (base.compiled) base.interpreted = "the sparse Hessian of U (in Jets, by colours)";
        return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
      }
    }
    dense_limit("integrator.map: map = \"" + me.map->name + "\" in the lagrangian form");
    using Step = DenseSeparableThetaStep<Sys>;
    const auto work = Step::workspace(L);
    auto make = [&](double hk, const ThetaMap& Rk) { return Step(L, work, Rk.theta(), hk, opt); };
    base.step_path = StepPath::separable_dense_newton;
    return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
  }
  if (me.form == Form::sode1 || me.form == Form::sode2 || me.form == Form::newmark)
    return sode_run(std::shared_ptr<const NoForce>());
  dense_limit(me.galerkin ? std::string("integrator.method: method = \"galerkin\"")
                          : "integrator.map: map = \"" + me.map->name + "\" in the " + to_string(me.form) + " form");
  if (me.galerkin)
    return stepper_run<linearizable>(view, DynamicGalerkinStep<Sys>(L, me.quadrature, me.stages, h, opt), q, p, v0,
                                     base, pr.steps);
  const ThetaMap R = dynamic_theta_map(me);
  if (me.form == Form::hamiltonian) {
    // lift = "none": the theta map on T*Q itself (P = p0 + theta dp, not 1 - theta)
    const bool on_bundle = me.effective_lift() == Lift::none;
    auto run_with = [&](const auto& H) {
      using Step = DynamicHamiltonianThetaStep<std::decay_t<decltype(H)>>;
      auto make = [&](double hk, const ThetaMap& Rk) { return Step(H, Rk, hk, opt, on_bundle); };
      return composable_run<linearizable>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
    };
    if constexpr (std::is_same_v<Sys, WrittenDynamic>)
      if (hamiltonian) {
        const auto H = compiled_or_not([&](WrittenDerivatives m) { return WrittenDynamicHamiltonian(hamiltonian, m); }, pr);
        base.compile_seconds += H.compile_seconds();
        return run_with(H);
      }
    return run_with(LegendreDynamicHamiltonian<Sys>(L));
  }
  if (me.form != Form::lagrangian) throw InputError("integrator.form: unsupported");  // refused by validate()
  // simplified Newton across steps (the Jacobian from L's Hessian kept while it serves)
  // where L's Hessian costs several gradients; use_structure = false forms a Jacobian at
  // every iteration, the reference path
  const bool keep = me.use_structure && n >= kKeptJacobianMinDim;
  if constexpr (std::is_same_v<Sys, WrittenDynamic>) {
    // (use_structure = false: the run-time-sized step, a Jacobian at every iteration)
    if (n <= kFixedWrittenMaxDim && me.use_structure && !me.linearize) {
      auto run_fixed = [&](auto k) {
        constexpr int K = decltype(k)::value;
        auto make = [&](double hk, const ThetaMap& Rk) { return DynamicThetaStep<Sys, K>(L, Rk, hk, opt); };
        return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
      };
      if (n == 1) return run_fixed(std::integral_constant<int, 1>());
      return run_fixed(std::integral_constant<int, 2>());
    }
  }
  if (keep) base.step_path = StepPath::kept_jacobian_newton;
  auto make = [&](double hk, const ThetaMap& Rk) { return DynamicThetaStep<Sys>(L, Rk, hk, opt, keep); };
  return composable_run<linearizable>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
}

}  // namespace dvm::kernels
