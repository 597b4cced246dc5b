// What a run is: a Problem (what to integrate) and a Method (how), as typed values.
//
//   Problem   a system of the registry with its parameters (or a system written in a
//             scene), the initial state or the boundary values, and the time grid
//             t_k = k h, k = 0..steps.
//   Method    the form, the discretization map (and its theta), the composition,
//             the Galerkin stages and quadrature, Newmark's (gamma, beta), and the
//             options of each step's solve.
//
// validate(problem, method) checks every rule that involves more than one value, once,
// with one message per rule naming the keys as a scene writes them ('integrator.form',
// 'problem.kind', ...). A scene reader (solvers/runtime/scene.cc), a C++ caller or a
// binding fills these structs; make_run (solvers/runtime/run.h) validates again, so
// nothing unchecked reaches a kernel.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "mechanics/written_map.h"
#include "solvers/newton.h"
#include "solvers/runtime/registry.h"

namespace dvm {

struct WrittenSystem;  // mechanics/written_lagrangian.h

struct Problem {
  const SystemEntry* system = nullptr;
  std::map<std::string, double> params;            // every parameter, defaults filled in
  std::vector<double> masses;                      // nbody: one per body
  std::shared_ptr<const WrittenSystem> written;    // the written system ("lagrangian")
  // system.compile: a Lagrangian (and Hamiltonian) written on R^n differentiated by
  // compiled code (WrittenDerivatives::compiled, mechanics/native_code.h)
  bool compile = false;
  int dim = 0;                                     // length of q as stored (see SystemEntry::dim)

  // The initial state. R^n: q, and p or v. S^2: the unit vector(s) q and a tangent p
  // or v. SO(3): q the unit quaternion [w, x, y, z], v the body angular velocity or p
  // the body angular momentum.
  std::vector<double> q, p, v;
  bool momentum_given = false;

  // A boundary-value problem: q is q_0, q_final is q_K, steps = K.
  bool boundary_value = false;
  std::vector<double> q_final;

  double step = 0.0;        // h
  std::int64_t steps = 0;   // K

  // Where the problem came from, for messages ("examples/scenes/kepler.toml").
  std::string origin;
  // Where the written system's texts are, for messages about them.
  std::string written_where, hamiltonian_where;
  // Where the written system's forces are (system.forces), empty where it writes none.
  std::string forces_where;
  bool forced() const;  // the written system has forces (system.forces)
  // Where its constraints are (system.constraints), empty where it writes none.
  std::string constraints_where;
  bool constrained() const;  // the written system has constraints (system.constraints)
  // [initial] project_velocity: an initial velocity (or momentum) off the hidden
  // constraint is projected onto it instead of refused (and where the key was given).
  bool project_velocity = false;
  std::string project_velocity_where;
};

class WrittenRetraction;  // mechanics/written_retraction.h

struct Method {
  Form form = Form::lagrangian;
  const MapEntry* map = nullptr;  // none: newmark, galerkin without a map
  double theta = 0.5;             // the map's theta (set from the entry when it takes none)
  // map = "written": the map the scene writes (mechanics/written_map.h).
  std::shared_ptr<const WrittenMap> written_map;
  // map = "sphere-written" or "so3-written": the retraction the scene writes in the
  // embedding (mechanics/written_retraction.h); theta is integrator.theta.
  std::shared_ptr<const WrittenRetraction> written_retraction;
  // The composition ("none": the basic method's own step); "dirk" takes its weights
  // from `weights` (the symplectic DIRK of those weights with the midpoint map).
  std::string composition = "none";
  std::vector<double> weights;
  // composition = "dirk" only: a theta per stage (stage i takes the map at theta_i;
  // with the hamiltonian form and the theta map the symplectic partitioned pair of
  // Sec. 6.2, solvers/partitioned_dirk.h). Empty: every stage takes the map itself.
  std::vector<double> thetas;
  // How the map reaches the bundle of the form (registry.h): automatic is the
  // cotangent lift for hamiltonian and the tangent lift for sode1/sode2.
  Lift lift = Lift::automatic;
  bool galerkin = false;
  int stages = 2;
  QuadratureKind quadrature = QuadratureKind::gauss;
  double newmark_gamma = 0.5, newmark_beta = 0.25;
  SolverKind solver = SolverKind::newton;
  // Use the system's structure where it allows cheaper steps that solve the same
  // equations (mechanics/structure.h): an explicit Euler map (theta 0 or 1, composed or
  // not) on a separable system steps by kicks and drifts, with no solve
  // (solvers/splitting_step.h). false: every step by the generic path (Newton's method
  // or TinySolver on the step equation), e.g. to compare the two. solver = "tiny"
  // asks for the generic path too.
  bool use_structure = true;
  // The run writes the derivative of every step (dvm run --linearize, OutputSpec::
  // linearize): validate admits the steps that give one, and the kernels take them.
  bool linearize = false;
  int max_iterations = 25;
  double tolerance = 2e-15;

  // The options of each step's solve.
  StepOptions step_options() const;
  // The basic method is its own adjoint.
  bool basic_symmetric() const;
  // The order the method is built to have.
  int order() const;
  // The composition's coefficients (find_composition, or dirk_scheme of `weights`);
  // throws std::invalid_argument for an unknown name or weights it refuses.
  CompositionScheme scheme() const;
  // The lift the form uses: `lift`, or the form's default (registry.h).
  Lift effective_lift() const { return lift == Lift::automatic ? default_lift(form) : lift; }
  // "midpoint", "galerkin gauss s=4 (order 8)", "newmark", ...
  std::string map_label() const;
  std::string label() const;
};

// Every rule between the values of a problem and a method; throws InputError naming
// the keys. Single values (a theta in [0, 1], a positive step) are checked too.
void validate(const Problem& problem, const Method& method);
// The rule of [problem] kind = "boundary-value" alone (a reader checks it before
// reading the keys that kind brings).
void require_boundary_value(const SystemEntry& system);

// The largest number of steps: t_k = k h is formed from k as a double, exact to 2^53.
constexpr std::int64_t kMaxSteps = std::int64_t(1) << 53;

}  // namespace dvm
