// The registries of the runtime layer: one list per kind of choice a run is made of.
//
//   systems        the built-in mechanical systems and the written one ("lagrangian"):
//                  name, Lagrangian, parameters with defaults and meanings, space,
//                  number of coordinates, which forms, maps and methods it runs, and
//                  the factory of its runs (solvers/runtime/run.h)
//   maps           the discretization maps R_d : TQ -> Q x Q (paper Def. 2.2): name,
//                  formula, space, symmetry, order, how the inverse is found, theta
//   forms          lagrangian (position-momentum step of L_d, Sec. 5.3), hamiltonian
//                  (Eq. 5.1 from the cotangent lift), sode1 / sode2 (Eq. 4.1 / 4.2 from
//                  the tangent lift), newmark (Sec. 4.1)
//   compositions   solvers/composition_methods.h (paper Sec. 6)
//   galerkin       Galerkin discrete Lagrangians: quadrature x stages (order 2 stages)
//
// Scene validation, the listings (`dvm systems|maps|methods`), `--help` and the
// dispatch of a run all read these lists; nothing else spells out a name. A choice the
// lists do not support is refused (InputError naming the keys), never replaced by
// another. Adding a built-in system is its type (mechanics/) plus one entry in
// registry.cc whose factory instantiates the kernels for it (kernels_*.cc); adding a
// map of an existing type is one entry, a map of a new type also one alternative of
// the map variant its space dispatches on (solvers/runtime/kernels.h).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "mechanics/quadrature.h"
#include "solvers/composition_methods.h"
#include "solvers/runtime/errors.h"

namespace dvm {

class Run;
struct Problem;
struct Method;

// ---- spaces -------------------------------------------------------------------------
enum class Space { euclidean, sphere, rotation };
// "R^n", "S^2", "SO(3)" (the spherical chain lives on (S^2)^n and is listed under S^2)
const char* to_string(Space s);

// ---- forms --------------------------------------------------------------------------
enum class Form { lagrangian, hamiltonian, sode1, sode2, newmark };
constexpr int kFormCount = 5;
const char* to_string(Form f);

struct FormEntry {
  Form form;
  std::string name;
  std::string description;
  bool uses_map;  // newmark is its own discretization (gamma, beta)
};
const std::vector<FormEntry>& form_registry();
// Throws InputError naming `key` for an unknown name.
Form find_form(const std::string& name, const std::string& key);

// ---- lifts --------------------------------------------------------------------------
// How the map on Q becomes the map on the bundle a form discretizes: the hamiltonian
// form (Eq. 5.1) needs a map on T*Q, the sode forms (Eq. 4.1, 4.2) a map on TQ.
// `automatic` is each form's default: the cotangent lift for hamiltonian, the tangent
// lift for sode1 and sode2.
enum class Lift { automatic, cotangent, none, tangent, legendre };
const char* to_string(Lift l);

struct LiftEntry {
  Lift lift;
  std::string name;
  std::vector<Form> forms;  // the forms it applies to
  std::string description;
};
const std::vector<LiftEntry>& lift_registry();
// Throws InputError naming `key` for an unknown name.
Lift find_lift(const std::string& name, const std::string& key);
// The lift a form uses when the method names none (Lift::automatic for forms without one).
Lift default_lift(Form f);

// ---- maps ---------------------------------------------------------------------------
// How a map's type is built: the family decides the C++ type the kernels dispatch on.
enum class MapFamily {
  theta,             // R^n: ThetaMap(theta), closed-form inverse
  retraction_theta,  // R^n: RetractionMap<EuclideanRetraction>(theta), Newton inverse (generic path)
  sphere,            // S^2: SphereMap(retraction, theta)
  rotation,          // SO(3): SO3Map(retraction, theta)
  written,           // R^n: WrittenMap from the scene's [map] section, Newton inverse (generic path)
};
// written: the retraction of the scene's [map] section (Method::written_retraction)
enum class MapRetraction { none, exp, projection, cayley, written };

struct MapEntry {
  std::string name;
  std::string formula;
  Space space;
  MapFamily family;
  MapRetraction retraction;
  double theta;        // the map's theta (the default, for maps that take one)
  bool takes_theta;    // integrator.theta may be set
  bool closed_inverse;  // else Newton's method (the generic path)
  std::string note;
  bool symmetric(double th) const { return th == 0.5; }
  int order(double th) const { return symmetric(th) ? 2 : 1; }
};
const std::vector<MapEntry>& map_registry();
// The maps that take integrator.theta, for messages: map = "theta", "retraction-theta", ...
std::string theta_map_names();
// Throws InputError ("<where>: unknown map ...; expected one of: ...").
const MapEntry& find_map_entry(const std::string& name, const std::string& where);

// ---- compositions and Galerkin methods ------------------------------------------------
// composition_schemes() and find_composition() (solvers/composition_methods.h) are the
// registry of compositions; "none" is the map's own step.
struct GalerkinEntry {
  QuadratureKind quadrature;
  int stages;
  int points;
  int order;
  std::string citation;
  std::string note;  // what the method is at s = 1
};
constexpr int kGalerkinStagesMax = 6;
const std::vector<GalerkinEntry>& galerkin_registry();

// ---- systems ------------------------------------------------------------------------
struct ParamEntry {
  std::string name;
  double default_value;
  std::string meaning;
};

// What a system runs. A combination outside these is refused by validate().
struct SystemCapabilities {
  std::vector<Form> forms;         // forms of initial-value runs
  bool retraction_maps = true;     // maps inverted by Newton's method (retraction-theta)
  bool composition = true;         // compositions of its steps, in each of its forms
  bool galerkin = true;            // method = "galerkin" (lagrangian form)
  bool boundary_value = false;     // [problem] kind = "boundary-value" (lagrangian form)
  std::string note;                // why something is missing, for messages and listings
  bool tiny_solver = true;         // solver = "tiny" (ceres::TinySolver) for its map-based steps
  bool written_maps = true;        // map = "written" (the fixed-size steps on R^n), "sphere-written" or
                                   // "so3-written" (S^2, (S^2)^K, SO(3))
  bool linearize = false;          // dvm run --linearize on R^n (the built-in systems of fixed size,
                                   // the chain, n bodies; a Lagrangian written on R^n takes it whatever its
                                   // entry; on S^2 and SO(3) the rules of validate())
};

using RunFactory = std::unique_ptr<Run> (*)(const Problem&, const Method&);

struct SystemEntry {
  std::string name;
  std::string lagrangian;  // the Lagrangian, for listings
  Space space;
  // Numbers per state vector as a scene gives them: coordinates on R^n, the embedded
  // unit vector on S^2 (3, per link for the spherical chain), the body angular
  // velocity on SO(3) (3; the rotation is a quaternion or a matrix). 0: found from the
  // parameters (chain: n) or the scene (nbody: 3 x bodies; lagrangian: coordinates).
  int dim;
  std::vector<ParamEntry> params;
  SystemCapabilities caps;
  RunFactory factory;
  std::string dim_note;  // how dim is found when it is 0
};
const std::vector<SystemEntry>& system_registry();
// Throws InputError ("<where>: unknown system ...; expected one of: ...").
const SystemEntry& find_system_entry(const std::string& name, const std::string& where);
// The entry of Lagrangians written in a scene on R^n, S^2, (S^2)^K (space sphere,
// factors K = 2..4) or SO(3) (name "lagrangian", not listed as built-in); `forced`: on
// R^n with forces (system.forces), "lagrangian with forces", which runs what the forced
// step is built for.
// `constrained`: on R^n with constraints (system.constraints, forces or not), "lagrangian
// with constraints", which runs what the constrained step is built for.
// `time_dependent`: on R^n a Lagrangian that reads t (WrittenSystem::time_dependent;
// without constraints), "lagrangian depending on time".
const SystemEntry& written_system_entry(Space space = Space::euclidean, int factors = 1, bool forced = false,
                                        bool constrained = false, bool time_dependent = false);

}  // namespace dvm
