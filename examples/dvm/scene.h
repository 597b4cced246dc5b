// Scenes: what the `dvm run` command reads (a TOML file plus --set overrides),
// validated once into plain values before anything runs.
//
//   [system]      builtin = "pendulum"    params = { m = 1.0, l = 1.0, g = 1.0 }
//   [initial]     q = [...]   and one of   p = [...]   or   v = [...]
//   [integrator]  map = "midpoint" | "explicit-euler" | "adjoint-euler" | "theta"
//                 theta = 0.5 (map = "theta" only)   step = 0.01
//                 steps = N   or   t_end = T
//                 solver = "newton" | "tiny"        (optional, default newton)
//                 max_iterations = 25   tolerance = 2e-15   (optional: the solver's
//                 iteration bound and relative residual tolerance)
//                 composition = "none" | "stormer-verlet" | "triple-jump" | ... |
//                 "triple-jump:<order>"   (optional: the basic method's step, of
//                 any form, on any space, composed; see `dvm methods`)
//                 method = "map" | "galerkin"   stages = 1..6   quadrature = "gauss" |
//                 "lobatto"   (optional: Galerkin discrete Lagrangians, see below)
//   [output]      csv = "out.csv"   every = 1        (both optional)
//                 npy = "out.npy"                    (optional: NumPy float64 rows)
// or, instead of builtin, a Lagrangian written in the scene (scene_written.h):
//   [system]      coordinates = ["x"]   lagrangian = "x_dot^2/2 - x^2/2"
//                 params = { ... }   energy = "..."   hamiltonian = "..."   name = "..."
// and builtin = "nbody" takes masses = [m0, m1, ...] (2 to 6 bodies in R^3).
//   [problem]     kind = "initial-value" | "boundary-value"   q_final = [...]   steps = K
//
// Systems on S^2 take q = unit vector [x, y, z] and v or p tangent to it; systems on
// SO(3) take   rotation = [w, x, y, z] (unit quaternion)  or  R = [[...], [...], [...]]
// and          omega = [...] (body angular velocity)  or  pi = [...] (body momentum).
// Points off the manifold and velocities that are not tangent are refused with the
// size of the defect (never projected).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace dvm {
struct WrittenSystem;  // mechanics/written_lagrangian.h
}

namespace dvm::cli {

// Written Lagrangians are compiled for 1 to kMaxWrittenDim coordinates.
constexpr int kMaxWrittenDim = 6;

// Bad input: the message names the file, the key, the value and what was expected.
struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct ParamInfo {
  std::string name;
  double default_value;
  std::string meaning;
};

struct SystemInfo {
  std::string name;
  int dim;  // length of initial.q (S^2: 3, the embedded unit vector; SO(3): see Scene)
  std::string lagrangian;
  std::vector<ParamInfo> params;
  std::string space = "R^n";  // "R^n", "S^2" or "SO(3)"
};

struct MapInfo {
  std::string name;
  std::string formula;
  bool symmetric;  // for "theta": symmetric only at theta = 1/2
  int order;
  bool closed_inverse;
  std::string note;
  std::string space = "R^n";  // where the map lives: "R^n", "S^2" or "SO(3)"
};

const std::vector<SystemInfo>& systems();
const std::vector<MapInfo>& maps();
const SystemInfo& find_system(const std::string& name, const std::string& where);
const MapInfo& find_map(const std::string& name, const std::string& where);

struct Scene {
  std::string path;
  std::string system;
  std::map<std::string, double> params;  // every parameter, defaults filled in
  std::vector<double> q, p, v;  // SO(3): q is the unit quaternion [w, x, y, z], v omega, p pi
  bool momentum_given = false;  // p given (else v)
  std::string space = "R^n";
  std::string map;
  double theta = 0.5;
  double step = 0.0;
  std::int64_t steps = 0;
  std::string solver = "newton";
  int max_iterations = 25;
  double tolerance = 2e-15;
  // "none" or a composition method (solvers/composition_methods.h), its stages the
  // steps of the basic method (map and form; issue 5)
  std::string composition = "none";
  // Galerkin discrete Lagrangians (issue 9):
  //   [integrator] method = "map" (default: the map's own step, possibly composed) |
  //                "galerkin" (degree-`stages` curves, quadrature "gauss" of s points or
  //                "lobatto" of s + 1; order 2 stages; R^n, S^2, SO(3), lagrangian form
  //                only; no map needed, a map named is validated and unused)
  //                stages = 1..6 (default 2)   quadrature = "gauss" (default) | "lobatto"
  std::string method = "map";
  int stages = 2;
  std::string quadrature = "gauss";
  std::string csv;  // empty: no CSV
  std::int64_t every = 1;

  // Integrator forms and whole-trajectory problems (issue 3):
  //   [integrator] form = "lagrangian" | "hamiltonian" | "sode1" | "sode2" | "newmark"
  //                gamma = 0.5, beta = 0.25 (newmark only; newmark uses no map, and
  //                ignores one named in the scene after validating its name)
  //   [problem]    kind = "initial-value" | "boundary-value"
  //                q_final = [...], steps = K (boundary-value only; then [initial] takes
  //                q alone and [integrator] no steps/t_end)
  std::string form = "lagrangian";
  double newmark_gamma = 0.5, newmark_beta = 0.25;
  std::string problem = "initial-value";
  std::vector<double> q_final;
  // Added with written Lagrangians and the classic systems:
  int dim = 0;  // the number of coordinates (chain: params.n; nbody: 3 x bodies)
  std::shared_ptr<const WrittenSystem> written;  // system == "lagrangian": the parsed texts
  std::string written_where;                     // "file:line:col: key 'system.lagrangian'"
  std::string hamiltonian_where;                 // the same for 'system.hamiltonian'
  std::vector<double> masses;                    // system == "nbody"
  std::string npy;                               // [output] npy: empty for none
};

// Loads and validates a scene; overrides are "section.key=value" with value written
// as in TOML. Throws InputError.
Scene load_scene(const std::string& path, const std::vector<std::string>& overrides);
// The same for a scene given as text; `path` names it in messages.
Scene load_scene_text(const std::string& text, const std::string& path, const std::vector<std::string>& overrides);

// The most steps a run takes: t_k = k h is formed from k as a double, exact to 2^53.
constexpr std::int64_t kMaxSteps = std::int64_t(1) << 53;

}  // namespace dvm::cli
