#include "solvers/runtime/problem.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "mechanics/written_lagrangian.h"
#include "mechanics/written_retraction.h"
#include "solvers/runtime/run.h"  // shortest: 0.3, not 0.29999999999999999

namespace dvm {

StepOptions Method::step_options() const {
  StepOptions opt;
  opt.solver = solver;
  opt.max_iterations = max_iterations;
  opt.residual_tolerance = tolerance;
  opt.accept_tolerance = std::fmax(opt.accept_tolerance, tolerance);
  return opt;
}

bool Method::basic_symmetric() const {
  if (galerkin) return true;
  if (form == Form::newmark) return newmark_gamma == 0.5;
  if (map && map->family == MapFamily::written) return written_map && written_map->symmetric();
  return map && map->symmetric(theta);
}

int Method::order() const {
  if (galerkin) return 2 * stages;
  if (composition == "dirk" && !thetas.empty()) return partitioned_dirk_thetas(weights, thetas).order;
  if (composition != "none") return scheme().order;
  if (form == Form::newmark) return newmark_gamma == 0.5 ? 2 : 1;
  if (map && map->family == MapFamily::written) return written_map ? written_map->order() : 0;
  return map ? map->order(theta) : 0;
}

CompositionScheme Method::scheme() const {
  if (composition == "dirk") {
    if (weights.empty()) throw std::invalid_argument("\"dirk\" needs its weights: integrator.weights = [b1, b2, ...]");
    return dirk_scheme(weights);
  }
  return find_composition(composition);
}

std::string Method::map_label() const {
  if (galerkin) return "none";
  if (form == Form::newmark) return "newmark";
  if (!map) return "none";
  if (map->family == MapFamily::retraction_theta) return "retraction-theta(euclidean)";
  return map->name;
}


std::string Method::label() const {
  std::string s;
  if (galerkin)
    s = std::string("galerkin ") + to_string(quadrature) + " s=" + std::to_string(stages) + " (order " +
        std::to_string(2 * stages) + ")";
  else
    s = map_label();
  if (!galerkin && form != Form::newmark && map && map->family == MapFamily::written && written_map) {
    s += " " + written_map->name() + " (";
    s += written_map->is_retraction() ? "retraction " + written_map->text(0) + ", theta " + shortest(theta)
                                      : "q0 = " + written_map->text(0) + ", q1 = " + written_map->text(1);
    s += ")";
  }
  if (!galerkin && map && map->retraction == MapRetraction::written && written_retraction)
    s += " " + written_retraction->name() + " (" + written_retraction->text() + ", theta " + shortest(theta) + ")";
  if (form != Form::lagrangian && !galerkin) s += ", " + std::string(to_string(form)) + " form";
  if (lift != Lift::automatic && lift != default_lift(form)) s += ", lift " + std::string(to_string(lift));
  if (composition != "none") s += ", composition " + composition;
  auto list = [&](const char* what, const std::vector<double>& x) {
    if (x.empty()) return;
    s += std::string(" (") + what;
    for (std::size_t i = 0; i < x.size(); ++i) s += (i ? ", " : "") + shortest(x[i]);
    s += ")";
  };
  list("", weights);
  list("thetas ", thetas);
  return s;
}

namespace {

// The most numbers the Jacobian of a boundary-value problem may hold (2^27 doubles, 1
// GiB): three n x n blocks per interior node, 3 (K - 1) n^2 for K steps of n
// coordinates. Ceres' normal equations hold about as many again.
constexpr double kMaxBoundaryValueJacobian = 134217728.0;

std::string fmt_exact(double x) {
  std::ostringstream out;
  out.precision(17);
  out << x;
  return out.str();
}

std::string form_list(const std::vector<Form>& forms) {
  std::string out;
  for (std::size_t i = 0; i < forms.size(); ++i)
    out += (i == 0 ? "" : i + 1 == forms.size() ? " and " : ", ") + std::string(to_string(forms[i]));
  return out;
}

}  // namespace

bool Problem::forced() const { return written && !written->forces.empty(); }
bool Problem::constrained() const { return written && !written->constraints.empty(); }

void require_boundary_value(const SystemEntry& sys) {
  if (!sys.caps.boundary_value)
    throw InputError("problem.kind: boundary-value problems run on the fixed-size R^n systems, Lagrangians written "
                     "on R^n (without forces, constraints or t) and on S^2, and the spherical pendulum only, not on " +
                     sys.name + (sys.caps.note.empty() ? "" : " (" + sys.caps.note + ")"));
}

void validate(const Problem& pr, const Method& me) {
  if (!pr.system) throw InputError("system: no system given");
  const SystemEntry& sys = *pr.system;
  const SystemCapabilities& caps = sys.caps;
  const std::string& name = sys.name;
  const std::string note = caps.note.empty() ? "" : " (" + caps.note + ")";

  // [problem]
  if (pr.boundary_value) {
    require_boundary_value(sys);
    if (me.form != Form::lagrangian)
      throw InputError("integrator.form: a boundary-value problem solves the discrete Euler-Lagrange equations; "
                       "expected form = \"lagrangian\", got \"" + std::string(to_string(me.form)) + "\"");
    if (me.composition != "none") throw InputError("integrator.composition: a boundary-value problem takes no composition");
    if (me.galerkin) throw InputError("integrator.method: a boundary-value problem takes no method = \"galerkin\"");
    if (pr.steps < 2 || pr.steps > 100000000)
      throw InputError("problem.steps: got " + std::to_string(pr.steps) + ", expected a whole number from 2 to 100000000");
    const double n = pr.dim;
    if (n >= 1 && 3.0 * static_cast<double>(pr.steps - 1) * n * n > kMaxBoundaryValueJacobian)
      throw InputError("problem.steps: K = " + std::to_string(pr.steps) + " steps, n = " + std::to_string(pr.dim) +
                       " coordinates: the Jacobian of the boundary-value problem would hold 3 (K - 1) n^2 = " +
                       fmt_exact(3.0 * static_cast<double>(pr.steps - 1) * n * n) +
                       " numbers, beyond the 2^27 (1 GiB) it may hold; expected at most " +
                       std::to_string(static_cast<std::int64_t>(kMaxBoundaryValueJacobian / (3.0 * n * n)) + 1) +
                       " steps");
  }

  if (pr.compile && (!pr.written || pr.written->space != WrittenSystem::Space::euclidean))
    throw InputError("system.compile: compiled derivatives are for Lagrangians written on R^n (system.lagrangian "
                     "without system.space, or space = \"R^n\"); " +
                     std::string(pr.written ? "on S^2 and SO(3) a written Lagrangian is differentiated in Jets"
                                            : "a built-in system's derivatives are compiled with dvm"));
  // [system] written on a space: the entry of that space
  if (pr.written) {
    const Space space = pr.written->space == WrittenSystem::Space::sphere     ? Space::sphere
                        : pr.written->space == WrittenSystem::Space::rotation ? Space::rotation
                                                                              : Space::euclidean;
    if (&sys != &written_system_entry(space, pr.written->factors, !pr.written->forces.empty(),
                                      !pr.written->constraints.empty(), pr.written->time_dependent()))
      throw InputError(std::string("system.space: the written system lives on ") + to_string(space) +
                       " but the problem names the system entry \"" + name + "\" on " + to_string(sys.space));
  }

  // [integrator] form
  if (std::find(caps.forms.begin(), caps.forms.end(), me.form) == caps.forms.end())
    throw InputError("integrator.form: " + name + " runs the " + form_list(caps.forms) + " form" +
                     (caps.forms.size() > 1 ? "s" : "") + " only, got \"" + to_string(me.form) + "\"" + note);
  if (me.form == Form::hamiltonian && pr.written && sys.space != Space::euclidean && pr.written->hamiltonian.empty())
    throw InputError(std::string("integrator.form: on ") + to_string(sys.space) +
                     " the hamiltonian form runs the Hamiltonian written in the scene (system.hamiltonian, in " +
                     (sys.space == Space::sphere ? "the coordinates and their momenta p_<name>" : "R11 ... R33 and pi1 pi2 pi3") +
                     "); this scene writes none");

  // [integrator] method = "galerkin"
  if (me.galerkin) {
    if (!caps.galerkin) throw InputError("integrator.method: " + name + " takes no method = \"galerkin\"" + note);
    if (me.form != Form::lagrangian)
      throw InputError("integrator.method: method = \"galerkin\" is a discrete Lagrangian: it runs the lagrangian "
                       "form only, not form = \"" + std::string(to_string(me.form)) + "\"");
    if (me.composition != "none")
      throw InputError("integrator.composition: method = \"galerkin\" takes no composition (it reaches high order "
                       "itself: order 2 stages)");
    if (me.stages < 1 || me.stages > kGalerkinStagesMax)
      throw InputError("integrator.stages: got " + std::to_string(me.stages) + ", expected a whole number from 1 to " +
                       std::to_string(kGalerkinStagesMax));
    if (pr.constrained() && me.quadrature != QuadratureKind::lobatto)
      throw InputError("integrator.quadrature: method = \"galerkin\" with system.constraints holds them at its "
                       "quadrature nodes, which must include the ends of the step: quadrature = \"lobatto\", not \"" +
                       std::string(to_string(me.quadrature)) + "\"");
  }

  // [integrator] map
  const bool needs_map = !me.galerkin && me.form != Form::newmark;
  if (needs_map && !me.map) throw InputError("integrator.map: missing (form \"" + std::string(to_string(me.form)) + "\" is built from a map)");
  if (me.map) {
    const MapEntry& m = *me.map;
    if (m.space != sys.space) {
      std::string fitting;
      for (const MapEntry& e : map_registry())
        if (e.space == sys.space) fitting += (fitting.empty() ? "" : ", ") + e.name;
      throw InputError("integrator.map: map \"" + m.name + "\" lives on " + to_string(m.space) + " but " + name +
                       " lives on " + to_string(sys.space) + "; expected one of: " + fitting);
    }
    if (!(me.theta >= 0.0 && me.theta <= 1.0))
      throw InputError("integrator.theta: got " + fmt_exact(me.theta) + ", expected a number in [0, 1]");
    if (!m.takes_theta && me.theta != m.theta)
      throw InputError("integrator.theta: theta applies only to " + theta_map_names() + ", not \"" + m.name + "\"");
    if ((m.family == MapFamily::retraction_theta || m.family == MapFamily::written) && !caps.retraction_maps)
      throw InputError("integrator.map: " + name + " runs the theta-family maps (explicit-euler, adjoint-euler, "
                       "midpoint, theta), got \"" + m.name + "\"" + note);
    if (m.family == MapFamily::written && !caps.written_maps)
      throw InputError("integrator.map: " + name + " runs on the run-time-sized steps, which take the theta-family maps; "
                       "map = \"written\" runs on the built-in systems of fixed size" + note);
    if (m.retraction == MapRetraction::written && !caps.written_maps)
      throw InputError("integrator.map: " + name + " takes no written retraction (map = \"" + m.name + "\")" + note);
    if (m.retraction == MapRetraction::written && !me.written_retraction)
      throw InputError("integrator.map: map = \"" + m.name + "\" needs the scene's [map] section (retraction = [...])");
    if (m.family == MapFamily::written && !me.written_map)
      throw InputError("integrator.map: map = \"written\" needs the scene's [map] section (q0 and q1, or retraction)");
    if (m.family == MapFamily::written && !me.written_map->is_retraction() && me.theta != m.theta)
      throw InputError("integrator.theta: theta applies to a written retraction, not to a map written as q0 and q1");
    if (m.family == MapFamily::written && me.written_map->is_retraction() && me.theta != me.written_map->theta())
      throw InputError("integrator.theta: " + fmt_exact(me.theta) + " is not the written retraction's theta " +
                       fmt_exact(me.written_map->theta()));
  }

  // [integrator] lift
  if (me.lift != Lift::automatic) {
    const LiftEntry* l = nullptr;
    for (const LiftEntry& e : lift_registry())
      if (e.lift == me.lift) l = &e;
    if (!l) throw InputError("integrator.lift: unknown lift");
    if (me.galerkin || std::find(l->forms.begin(), l->forms.end(), me.form) == l->forms.end())
      throw InputError("integrator.lift: lift = \"" + l->name + "\" applies to the " + form_list(l->forms) +
                       " form" + (l->forms.size() > 1 ? "s" : "") + ", not to " +
                       (me.galerkin ? std::string("method = \"galerkin\"") : "form = \"" + std::string(to_string(me.form)) + "\"") +
                       " (the lagrangian form and Galerkin use the map on Q itself; newmark its own map on TQ)");
    if ((me.lift == Lift::none || me.lift == Lift::legendre) && me.map && me.map->family != MapFamily::theta &&
        sys.space == Space::euclidean)
      throw InputError("integrator.lift: lift = \"" + l->name + "\" is built for the theta maps (explicit-euler, "
                       "adjoint-euler, midpoint, theta), not integrator.map = \"" + me.map->name +
                       "\" (retraction-theta is the theta map in closed form: map = \"theta\")");
    if (me.lift == Lift::none && sys.space != Space::euclidean)
      throw InputError(std::string("integrator.lift: lift = \"none\" applies the map to (q, p) in T*Q = R^{2n}; on ") +
                       to_string(sys.space) + " the hamiltonian form takes the cotangent lift (lift = \"cotangent\")");
    if (me.lift == Lift::none && pr.constrained())
      throw InputError("integrator.lift: lift = \"none\" applies the map to (q, p) in T*Q = R^{2n}; with "
                       "system.constraints the hamiltonian form takes the cotangent lift (lift = \"cotangent\"), "
                       "whose step with multipliers keeps (q, p) on the constraint's cotangent bundle");
  }

  // [integrator] composition
  if (!me.weights.empty() && me.composition != "dirk")
    throw InputError("integrator.weights: weights apply only to composition = \"dirk\", not \"" + me.composition +
                     "\"");
  if (me.composition != "none") {
    try {
      me.scheme();
    } catch (const std::invalid_argument& e) {
      const bool weights = me.composition == "dirk";
      std::vector<std::string> names = {"none", "dirk"};
      for (const auto& c : composition_schemes()) names.push_back(c.name);
      throw InputError(std::string(weights ? "integrator.weights: " : "integrator.composition: ") + e.what() +
                       (weights ? std::string() : did_you_mean(me.composition, names)));
    }
    if (!caps.composition) throw InputError("integrator.composition: " + name + " takes no composition" + note);
    if (me.scheme().kind == CompositionKind::rkn_splitting) {
      // kicks and drifts: the explicit Euler map and its adjoint, on R^n, in a form where
      // they are the two symplectic Euler methods (the structure is checked when the run starts)
      const std::string what = "integrator.composition: \"" + me.composition +
                               "\" is a splitting into kicks and drifts for separable systems: ";
      if (sys.space != Space::euclidean)
        throw InputError(what + "it runs on R^n, not on " + to_string(sys.space));
      if (pr.forced())
        throw InputError(what + "its kicks are the gradient of a potential, and system.forces are not (the forced "
                                "step takes the other compositions)");
      if (pr.constrained())
        throw InputError(what + "its drifts leave system.constraints (the constrained step takes the other "
                                "compositions)");
      if (me.form != Form::lagrangian && me.form != Form::hamiltonian)
        throw InputError(what + "expected form = \"lagrangian\" or \"hamiltonian\", got \"" +
                         std::string(to_string(me.form)) + "\"");
      if (!me.map || me.map->family != MapFamily::theta || !(me.theta == 0.0 || me.theta == 1.0))
        throw InputError(what + "it composes the explicit Euler map with its adjoint; expected integrator.map = "
                                "\"explicit-euler\" or \"adjoint-euler\" (the same method), got \"" +
                         (me.map ? me.map->name : std::string("none")) + "\"" +
                         (me.map && me.map->takes_theta ? " with theta " + shortest(me.theta) : std::string()));
      if (me.form == Form::hamiltonian && me.effective_lift() != Lift::cotangent)
        throw InputError(what + "with the hamiltonian form the stages are the cotangent lifts of the Euler maps; "
                                "got integrator.lift = \"" + std::string(to_string(me.effective_lift())) + "\"");
    }
  }
  if (!me.thetas.empty()) {
    if (me.composition != "dirk")
      throw InputError("integrator.thetas: thetas apply only to composition = \"dirk\" (a theta per stage), not \"" +
                       me.composition + "\"");
    if (me.galerkin || me.form == Form::newmark)
      throw InputError(std::string("integrator.thetas: stage i takes the map at theta_i, and ") +
                       (me.galerkin ? "method = \"galerkin\" takes no map" : "form = \"newmark\" uses its own map on TQ"));
    const bool per_stage = me.map && me.map->takes_theta &&
                           !(me.map->family == MapFamily::written && me.written_map && !me.written_map->is_retraction());
    if (!per_stage)
      throw InputError("integrator.thetas: stage i takes the map at theta_i; expected a map that takes theta (" +
                       theta_map_names() + ", or a written retraction), got " +
                       (me.map ? "\"" + me.map->name + "\"" : std::string("no map")));
    if (me.theta != me.map->theta)
      throw InputError("integrator.theta: with integrator.thetas each stage has its own theta; give thetas only");
    try {
      partitioned_dirk_thetas(me.weights, me.thetas);
      // a written retraction is checked at each theta it will run at
      if (me.map->family == MapFamily::written && me.written_map)
        for (double th : me.thetas) me.written_map->at_theta(th);
    } catch (const std::invalid_argument& e) {
      throw InputError(std::string("integrator.thetas: ") + e.what());
    }
  }

  // [integrator] newmark
  if (me.form == Form::newmark) {
    if (!(me.newmark_gamma >= 0.0 && me.newmark_gamma <= 1.0))
      throw InputError("integrator.gamma: got " + fmt_exact(me.newmark_gamma) + ", expected a number in [0, 1]");
    if (!(me.newmark_beta >= 0.0 && me.newmark_beta <= 0.5))
      throw InputError("integrator.beta: got " + fmt_exact(me.newmark_beta) + ", expected a number in [0, 0.5]");
  }

  // the solve of each step
  if (me.solver == SolverKind::tiny) {
    if (!caps.tiny_solver)
      throw InputError("integrator.solver: " + name + " takes no solver = \"tiny\"" + note);
    if (me.galerkin)
      throw InputError("integrator.solver: method = \"galerkin\" solves its stage equations by simplified Newton; "
                       "solver = \"tiny\" applies to the map-based steps");
    if (pr.boundary_value)
      throw InputError("integrator.solver: a boundary-value problem is solved by Ceres' sparse least squares; "
                       "solver = \"tiny\" applies to the steps of initial-value problems");
  }
  if (me.max_iterations < 1 || me.max_iterations > 1000)
    throw InputError("integrator.max_iterations: got " + std::to_string(me.max_iterations) +
                     ", expected a whole number from 1 to 1000");
  if (!(me.tolerance > 0.0 && me.tolerance < 1.0))
    throw InputError("integrator.tolerance: got " + fmt_exact(me.tolerance) +
                     ", expected a number in (0, 1) (relative residual tolerance)");

  // dvm run --linearize: the steps that give their derivative (DynamicThetaStep::derivative,
  // ConstrainedThetaStep::derivative, DynamicGalerkinStep::derivative,
  // ConstrainedGalerkinStep::derivative, DynamicHamiltonianThetaStep::derivative,
  // ConstrainedHamiltonianThetaStep::derivative, the
  // first, third and fifth also for the built-in systems of fixed size
  // (make_run_time_sized_run); on S^2 and SO(3) ManifoldStep::derivatives and
  // ManifoldHamiltonianStep::derivatives)
  if (me.linearize) {
    const std::string what = "--linearize: the derivative of each step is given by the position-momentum step of the "
                             "theta-family maps, by their hamiltonian form and by Galerkin, for the built-in systems "
                             "of fixed size on R^n, for the chain (the theta-family maps), n bodies and Lagrangians "
                             "written on R^n (constrained or not), and by the "
                             "position-momentum step of the maps of S^2 and SO(3) (forced or not, not constrained) "
                             "and their hamiltonian form (not forced), for their built-in and written systems";
    if (sys.space == Space::euclidean) {
      if (!pr.written && !caps.linearize) throw InputError(what + ", not the built-in system " + name);
      if (!me.galerkin && me.map && me.map->family == MapFamily::written)
        throw InputError("integrator.map: " + what + ", not map = \"written\"");
      if (me.solver == SolverKind::tiny)
        throw InputError("integrator.solver: " + what + ", solved by Newton's method: not solver = \"tiny\"");
    } else {
      const bool chain = pr.written ? pr.written->factors > 1 : name == "spherical-chain";
      if (chain) throw InputError(what + ", not on (S^2)^K (" + (pr.written ? "system.space" : "system " + name) + ")");
      if (me.galerkin)
        throw InputError(what + ", not integrator.method = \"galerkin\" on " + std::string(to_string(sys.space)));
      if (pr.constrained()) throw InputError(pr.constraints_where + ": " + what);
    }
    if (pr.boundary_value) throw InputError(what + "; problem.kind = \"boundary-value\" takes no steps");
    const bool hamiltonian = me.form == Form::hamiltonian && !me.galerkin;
    if (me.form != Form::lagrangian && !hamiltonian)
      throw InputError(what + ", not integrator.form = \"" + std::string(to_string(me.form)) + "\"");
    if (hamiltonian && sys.space != Space::euclidean && pr.forced())
      throw InputError(pr.forces_where + ": " + what + "; not integrator.form = \"hamiltonian\" with forces on " +
                       std::string(to_string(sys.space)));
    if (me.composition != "none" && me.scheme().kind == CompositionKind::rkn_splitting)
      throw InputError("integrator.composition: --linearize differentiates theta steps and their compositions; a "
                       "splitting into kicks and drifts (\"" + me.composition + "\") gives no derivative");
  }
  // tabulated controls: one value per step
  if (pr.written && !pr.boundary_value)
    for (const WrittenSystem::Control& c : pr.written->controls)
      if (!c.table.empty() && static_cast<std::int64_t>(c.table.size()) != pr.steps)
        throw InputError(c.where + ": " + c.source + " holds " + std::to_string(c.table.size()) +
                         " values, expected one per step: " + std::to_string(pr.steps) +
                         " (integrator.steps, or t_end / step)");
  if (pr.project_velocity && !pr.constrained())
    throw InputError(pr.project_velocity_where + ": projects the initial velocity onto the hidden constraint of "
                                                 "system.constraints, and the system writes none");

  // the time grid
  if (!(pr.step > 0.0) || !std::isfinite(pr.step))
    throw InputError("integrator.step: got " + fmt_exact(pr.step) + ", expected a positive number");
  if (!pr.boundary_value) {
    if (pr.steps < 1) throw InputError("integrator.steps: got " + std::to_string(pr.steps) + ", expected at least 1");
    if (pr.steps > kMaxSteps)
      throw InputError("integrator.steps: got " + std::to_string(pr.steps) + " steps, expected at most 2^53 = " +
                       std::to_string(kMaxSteps) + " (beyond that the step index is not exact in t = k h)");
    if (!std::isfinite(static_cast<double>(pr.steps) * pr.step))
      throw InputError("integrator.steps: " + std::to_string(pr.steps) + " steps of " + fmt_exact(pr.step) +
                       " overflow the time (t_end = inf); expected a finite t_end");
  }

  // the state's sizes (a scene reader checks them with their positions; this guards
  // every other caller)
  auto size_check = [&](const std::vector<double>& x, std::size_t n, const char* key) {
    if (x.size() != n)
      throw InputError(std::string(key) + ": got " + std::to_string(x.size()) + " numbers, expected " +
                       std::to_string(n));
    for (double c : x)
      if (!std::isfinite(c)) throw InputError(std::string(key) + ": expected finite numbers");
  };
  const std::size_t nq = sys.space == Space::rotation ? 4 : static_cast<std::size_t>(pr.dim);
  const std::size_t nv = sys.space == Space::rotation ? 3 : static_cast<std::size_t>(pr.dim);
  if (pr.dim < 1) throw InputError("system: the number of coordinates is not known");
  size_check(pr.q, nq, "initial.q");
  if (pr.boundary_value) {
    size_check(pr.q_final, nq, "problem.q_final");
    // On S^2, antipodal end points are joined by every great circle: no path between
    // them is singled out, and the solve's starting path (the chord, normalised)
    // passes through the centre. Refused to the 1e-12 that points are taken on S^2.
    for (std::size_t k = 0; sys.space == Space::sphere && k + 2 < nq; k += 3) {
      const double sum = std::sqrt(std::pow(pr.q[k] + pr.q_final[k], 2) + std::pow(pr.q[k + 1] + pr.q_final[k + 1], 2) +
                                   std::pow(pr.q[k + 2] + pr.q_final[k + 2], 2));
      if (!(sum > 1e-12))
        throw InputError("problem.q_final: " + std::string(nq > 3 ? "link " + std::to_string(k / 3 + 1) + " is " : "") +
                         "antipodal to initial.q (|q_final + q| = " + fmt_exact(sum) +
                         ", within 1e-12): every great circle joins the two points, so no path between them is "
                         "singled out; expected end points that are not antipodal");
    }
  } else {
    size_check(pr.momentum_given ? pr.p : pr.v, nv, pr.momentum_given ? "initial.p" : "initial.v");
  }
}

}  // namespace dvm
