// dvm: simulate a mechanical system from its Lagrangian with a variational
// integrator derived from a discretization map.
#include <cmath>
#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "examples/dvm/commands.h"
#include "examples/dvm/scene.h"
#include "solvers/runtime/converge.h"
#include "solvers/runtime/json.h"
#include "solvers/runtime/registry.h"
#include "solvers/runtime/run.h"

using namespace dvm::cli;
using dvm::Json;

namespace {

const char* kUsage =
    "usage: dvm <command> [options]\n"
    "\n"
    "commands:\n"
    "  run SCENE.toml     integrate a scene (a system, initial state and integrator)\n"
    "  maps               list the discretization maps with their properties\n"
    "  methods            list the composition methods (order, stages, stability)\n"
    "  systems            list the built-in systems, their parameters and defaults\n"
    "  check-map NAME     check the identities of a discretization map, as JSON\n"
    "  converge SCENE     run a scene at several step sizes: errors and observed order\n"
    "  version            print the version and the git revision it was built from\n"
    "  help [COMMAND]     print this list, or the help of COMMAND\n"
    "\n"
    "'dvm <command> --help' describes a command; 'dvm --version' is 'dvm version'.\n"
    "Exit status: 0 success, 1 a check that did not pass, 2 bad input or usage, 3 a\n"
    "numerical failure during a run.\n";

const char* kVersionHelp =
    "usage: dvm version   (or dvm --version)\n"
    "\n"
    "Prints 'dvm VERSION (git REVISION)': the project version of CMakeLists.txt and the\n"
    "git revision of the source tree when the build was configured ('unknown' when it\n"
    "was not a git checkout). Exit status 0.\n";

const char* kRunHelp =
    "usage: dvm run SCENE.toml [--set section.key=value]... [--csv PATH] [--json] [--quiet]\n"
    "\n"
    "Integrates the scene with the position-momentum form of the discrete Lagrangian\n"
    "L_d(q0, q1) = h L(R_d^{-1}(q0, q1) / h) of the scene's discretization map.\n"
    "\n"
    "  --set k=v   override any scene key; v is written as in TOML, e.g.\n"
    "              --set integrator.step=0.001  --set initial.q=[0.5]\n"
    "              --set integrator.map='\"theta\"'\n"
    "  --csv PATH  write the trajectory (columns t, q0.., p0.., energy) to PATH,\n"
    "              overriding [output] csv; rows every [output] every steps.\n"
    "              PATH - (or /dev/stdout) writes to standard output, and the\n"
    "              summary goes to standard error\n"
    "  --json      print a JSON summary (steps, t_final, q_final, p_final,\n"
    "              energy_initial, energy_final, max_abs_energy_error, wall_seconds,\n"
    "              solver_iterations, status, and failure when a step fails)\n"
    "  --npy PATH  also write the rows as a NumPy .npy file (float64, shape\n"
    "              rows x (2n+2), the CSV's columns), overriding [output] npy\n"
    "  --quiet     print nothing on success and no progress (errors still go to\n"
    "              stderr); progress (step, time, rate, time left) is shown on\n"
    "              stderr only when stderr is a terminal\n"
    "\n"
    "Scene keys:\n"
    "  [system]      builtin = NAME  (see 'dvm systems'; @SYSTEMS@)\n"
    "                params = { ... }   (the system's parameters; defaults otherwise)\n"
    "                or a Lagrangian written in the scene:\n"
    "                coordinates = [\"x\", \"y\"]   velocities are x_dot, y_dot\n"
    "                lagrangian = \"m/2*(x_dot^2 + y_dot^2) - k/2*(x^2 + y^2)\"\n"
    "                params = { m = 1.0, k = 2.0 }   (any names)\n"
    "                energy = \"...\"  (optional; may use x, x_dot, p_x; else E = <p,v> - L)\n"
    "                hamiltonian = \"...\"  (optional; in x and p_x; checked against L)\n"
    "                name = \"...\"  (optional)\n"
    "                Expressions: + - * / ^ (or **), parentheses, numbers, pi, and\n"
    "                sin cos tan asin acos atan exp log sqrt cbrt abs sinh cosh tanh\n"
    "                atan2(y, x) pow(x, y). Any number of coordinates.\n"
    "  [initial]     q = [...]   and   p = [...] or v = [...]   (S^2: q a unit vector, v tangent)\n"
    "                SO(3): rotation = [w, x, y, z] or R = [[...], [...], [...]],\n"
    "                       and omega = [...] (body angular velocity) or pi = [...]\n"
    "  [integrator]  map = NAME  (see 'dvm maps'; @MAPS@)\n"
    "                theta = 0.5  (map theta only)   step = 0.01   steps = N  or  t_end = T\n"
    "                solver = \"newton\" (default) | \"tiny\" (ceres::TinySolver)\n"
    "                max_iterations = 25   tolerance = 2e-15  (relative residual)\n"
    "                composition = \"none\" (default) | NAME  (see 'dvm methods'; @COMPOSITIONS@)\n"
    "                    | \"triple-jump:<even order>\"   (the basic method's step\n"
    "                    composed, in every form and on S^2/SO(3) too; one that is not\n"
    "                    symmetric enters as Phi_{h/2} o Phi*_{h/2}; see 'dvm methods')\n"
    "                method = \"map\" (default) | \"galerkin\"   stages = 1..6 (default 2)\n"
    "                quadrature = \"gauss\" (default, s points) | \"lobatto\" (s + 1 points)\n"
    "                    (Galerkin discrete Lagrangians of order 2 stages; R^n systems and\n"
    "                    the S^2/SO(3) systems but the spherical chain, lagrangian form;\n"
    "                    no map needed; see 'dvm methods')\n"
    "  [output]      csv = \"out.csv\"   npy = \"out.npy\"   every = 1\n"
    "  [integrator]  form = \"lagrangian\" (default) | \"hamiltonian\" (Eq. 5.1, cotangent lift)\n"
    "                    | \"sode1\" | \"sode2\" (Eq. 4.1 / 4.2, tangent lift of the map)\n"
    "                    | \"newmark\" (gamma = 0.5, beta = 0.25; uses no map)\n"
    "  [problem]     kind = \"initial-value\" (default) | \"boundary-value\"\n"
    "                q_final = [...]   steps = K   (boundary-value: [initial] q only,\n"
    "                no integrator steps/t_end; lagrangian form; R^n systems and\n"
    "                spherical-pendulum)\n"
    "  [system]      builtin = \"chain\"   params = { n, m, k, alpha, beta, fixed }\n"
    "                (FPU chain of n particles; lagrangian form, theta-family maps)\n"
    "\n"
    "Exit status: 0 complete run; 2 bad input, an unwritable output path or output\n"
    "that would not fit on its filesystem (refused before the run; nothing is written);\n"
    "3 a numerical failure (a step that did not converge, a non-finite state, a map or\n"
    "Legendre transform outside its domain: the message gives the step, the time and\n"
    "the residual) or an output write error. Output files are written under a\n"
    "temporary name and renamed when the run is complete: a failed run leaves the\n"
    "final path as it was and its rows in PATH.partial; the JSON says \"failed\".\n"
    "A path that exists and is not a regular file (a device, a FIFO) is written\n"
    "directly, never replaced; a write error there (/dev/full) exits 3. An output\n"
    "path naming the scene file, or the CSV and the .npy naming one file, is refused\n"
    "(exit 2). Limits: a scene file of at most 16 MiB; a written expression of at most\n"
    "1 MiB nesting at most 256 levels; at most 9e15 steps.\n"
    "\n"
    "example:\n"
    "  dvm run examples/scenes/pendulum.toml --set integrator.step=0.001 --json\n";

const char* kMapsHelp =
    "usage: dvm maps [--json]\n"
    "\n"
    "Lists the discretization maps R_d : TQ -> Q x Q on R^n, S^2 and SO(3): formula, whether the map\n"
    "is symmetric (equal to its adjoint), the order of its integrator, and whether its\n"
    "inverse is in closed form (else Newton's method).\n"
    "\n"
    "example:\n"
    "  dvm maps --json\n";

const char* kMethodsHelp =
    "usage: dvm methods [--json]\n"
    "\n"
    "Lists the composition methods usable as [integrator] composition: name, order,\n"
    "number of stages, symmetry, the largest stable h*omega on q'' = -omega^2 q when the\n"
    "basic method is Stormer-Verlet (map explicit-euler or adjoint-euler), whether the\n"
    "composition of midpoint steps is stable for every h*omega, and the source of the\n"
    "coefficients. Then the Galerkin discrete Lagrangians ([integrator] method =\n"
    "\"galerkin\"): quadrature, stages, quadrature points and order.\n"
    "\n"
    "example:\n"
    "  dvm methods --json\n";

const char* kCheckHelp =
    "usage: dvm check-map NAME [--theta T] [--dim N] [--tolerance TOL]\n"
    "\n"
    "Prints, as JSON, the largest residual over random sample points of each identity:\n"
    "zero_section (R_d(x,0) = (x,x)), tangent_identity (T R^2 - T R^1 = Id),\n"
    "inverse_round_trip, adjoint_involution ((R_d^*)^* = R_d), adjoint_difference\n"
    "(|R_d^* - R_d|: zero exactly when the map is symmetric), the same axioms for the\n"
    "tangent lift, cotangent_symplectic (the cotangent lift pulls Omega_12 back to\n"
    "d_T omega_Q) and cotangent_round_trip. On S^2 and SO(3) maps these are checked in\n"
    "local coordinates (the map in a chart), plus manifold_round_trip and\n"
    "closed_form_vs_newton for the closed-form inverse. N is 1 to 4 (default 2, R^n only), T in [0, 1]\n"
    "(default 0.5), TOL defaults to 1e-12. Exit status 0 when every identity holds\n"
    "and the symmetry claim matches, 1 otherwise, 2 for bad input.\n"
    "\n"
    "example:\n"
    "  dvm check-map theta --theta 0.3 --dim 3\n";

const char* kSystemsHelp =
    "usage: dvm systems [--json]\n"
    "\n"
    "Lists the built-in systems: name, number of coordinates, Lagrangian, and each\n"
    "parameter with its default (set in a scene with [system] params = { ... }).\n"
    "A scene may instead write its own Lagrangian (see 'dvm run --help').\n"
    "\n"
    "example:\n"
    "  dvm systems --json\n";

const char* kConvergeHelp =
    "usage: dvm converge SCENE.toml [--steps-list N1,N2,...] [--t-end T]\n"
    "                   [--max-steps M] [--set section.key=value]... [--json]\n"
    "\n"
    "Runs the scene to the time T (default: the scene's steps x step) with each step\n"
    "count N of the list (h = T/N; default: the scene's count times 1, 2, 4, 8), and\n"
    "prints the error max(|q - q_ref|, |p - p_ref|) at T, the observed order between\n"
    "neighbouring runs and a least-squares fitted order (points within 1e-12 of the\n"
    "solution's size are left out as round-off). The reference is the exact solution\n"
    "where the system has one (harmonic, kepler, duffing, charged-particle), else a\n"
    "classical Runge-Kutta run on Hamilton's equations with 16 times the largest N.\n"
    "Chaotic systems (double pendulum, Henon-Heiles at high energy) need a short T.\n"
    "A study whose runs take more than M steps together (default 1e8, the reference\n"
    "runs not counted) is refused with exit 2 before it starts; on a terminal, stderr\n"
    "shows which run is under way.\n"
    "\n"
    "example:\n"
    "  dvm converge examples/scenes/duffing.toml --steps-list 100,200,400,800 --t-end 10\n";

// The run help with the registries' names filled in, and what each system runs.
std::string run_help() {
  std::string h = kRunHelp;
  auto fill = [&](const std::string& tag, const std::string& text) {
    const auto at = h.find(tag);
    if (at != std::string::npos) h.replace(at, tag.size(), text);
  };
  std::string systems, maps, compositions;
  for (const auto& e : dvm::system_registry()) systems += (systems.empty() ? "" : ", ") + e.name;
  for (const auto& m : dvm::map_registry()) maps += (maps.empty() ? "" : ", ") + m.name;
  for (const auto& c : dvm::composition_schemes()) compositions += (compositions.empty() ? "" : ", ") + c.name;
  auto wrap = [](const std::string& list) {
    std::string out, line;
    std::size_t start = 0;
    while (start < list.size()) {
      auto end = list.find(", ", start);
      const std::string word = list.substr(start, end == std::string::npos ? std::string::npos : end - start + 1);
      if (line.size() + word.size() > 60) {
        out += line + "\n                  ";
        line.clear();
      }
      line += word + (end == std::string::npos ? "" : " ");
      start = end == std::string::npos ? list.size() : end + 2;
    }
    return out + line;
  };
  fill("@SYSTEMS@", wrap(systems));
  fill("@MAPS@", wrap(maps));
  fill("@COMPOSITIONS@", wrap(compositions));
  h += "\nWhat each system runs (any other combination is refused with exit 2):\n";
  char line[256];
  std::snprintf(line, sizeof line, "  %-18s %-6s %-38s %-5s %-8s %s\n", "system", "space", "forms", "comp.", "galerkin",
                "boundary-value");
  h += line;
  auto row = [&](const dvm::SystemEntry& e) {
    std::string forms;
    for (dvm::Form f : e.caps.forms) forms += (forms.empty() ? "" : ",") + std::string(dvm::to_string(f));
    std::snprintf(line, sizeof line, "  %-18s %-6s %-38s %-5s %-8s %s\n", e.name.c_str(), dvm::to_string(e.space),
                  forms.c_str(), e.caps.composition ? "yes" : "no", e.caps.galerkin ? "yes" : "no",
                  e.caps.boundary_value ? "yes" : "no");
    h += line;
  };
  for (const auto& e : dvm::system_registry()) row(e);
  row(dvm::written_system_entry());
  return h;
}

[[noreturn]] void usage_error(const std::string& msg, const char* help) {
  std::cerr << "dvm: " << msg << "\n\n" << (help == kRunHelp ? run_help() : std::string(help));
  std::exit(2);
}

bool is_help(const std::string& a) { return a == "--help" || a == "-h"; }

double parse_number(const std::string& opt, const std::string& text, const char* help) {
  char* end = nullptr;
  const double x = std::strtod(text.c_str(), &end);
  if (text.empty() || *end != '\0' || !std::isfinite(x))
    usage_error(opt + ": got '" + text + "', expected a finite number", help);
  return x;
}

int cmd_run(const std::vector<std::string>& args) {
  std::string scene;
  std::vector<std::string> sets;
  RunOptions o;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&](const char* name) -> std::string {
      if (i + 1 >= args.size()) usage_error(std::string(name) + " needs a value", kRunHelp);
      return args[++i];
    };
    if (is_help(a)) {
      std::cout << run_help();
      return 0;
    } else if (a == "--set") {
      sets.push_back(value("--set"));
    } else if (a.rfind("--set=", 0) == 0) {
      sets.push_back(a.substr(6));
    } else if (a == "--csv") {
      o.csv = value("--csv");
      if (o.csv.empty()) usage_error("--csv needs a file name", kRunHelp);
    } else if (a == "--json") {
      o.json = true;
    } else if (a == "--npy") {
      o.npy = value("--npy");
      if (o.npy.empty()) usage_error("--npy needs a file name", kRunHelp);
    } else if (a == "--quiet") {
      o.quiet = true;
    } else if (!a.empty() && a[0] == '-') {
      usage_error("unknown option " + a, kRunHelp);
    } else if (scene.empty()) {
      scene = a;
    } else {
      usage_error("more than one scene file given ('" + scene + "', '" + a + "')", kRunHelp);
    }
  }
  if (scene.empty()) usage_error("run needs a scene file", kRunHelp);
  return run_scene(load_scene(scene, sets), o);
}

int cmd_maps(const std::vector<std::string>& args) {
  bool json = false;
  for (const auto& a : args) {
    if (is_help(a)) {
      std::cout << kMapsHelp;
      return 0;
    } else if (a == "--json") {
      json = true;
    } else {
      usage_error("unknown argument " + a, kMapsHelp);
    }
  }
  const auto& maps = dvm::map_registry();
  if (json) {
    std::string out = "[\n";
    for (std::size_t i = 0; i < maps.size(); ++i) {
      const dvm::MapEntry& m = maps[i];
      Json::Object j;
      j.str("name", m.name)
          .str("formula", m.formula)
          .boolean("symmetric", m.symmetric(m.theta) && !m.takes_theta)
          .num("order", m.takes_theta ? 1 : m.order(m.theta))
          .boolean("closed_form_inverse", m.closed_inverse)
          .str("space", dvm::to_string(m.space))
          .str("note", m.note)
          .boolean("takes_theta", m.takes_theta);
      out += "  " + j.dump(4) + (i + 1 < maps.size() ? ",\n" : "\n");
    }
    std::cout << out << "]\n";
  } else {
    std::printf("%-24s %-6s %-9s %-5s %-8s %s\n", "name", "space", "symmetric", "order", "inverse", "formula");
    for (const auto& m : maps)
      std::printf("%-24s %-6s %-9s %-5d %-8s %s   (%s)\n", m.name.c_str(), dvm::to_string(m.space),
                  m.symmetric(m.theta) && !m.takes_theta ? "yes" : "no", m.takes_theta ? 1 : m.order(m.theta),
                  m.closed_inverse ? "closed" : "Newton", m.formula.c_str(), m.note.c_str());
  }
  return 0;
}

int cmd_systems(const std::vector<std::string>& args) {
  bool json = false;
  for (const auto& a : args) {
    if (is_help(a)) {
      std::cout << kSystemsHelp;
      return 0;
    } else if (a == "--json") {
      json = true;
    } else {
      usage_error("unknown argument " + a, kSystemsHelp);
    }
  }
  const auto& systems = dvm::system_registry();
  if (json) {
    std::string out = "[\n";
    for (std::size_t i = 0; i < systems.size(); ++i) {
      const dvm::SystemEntry& sy = systems[i];
      Json::Object j;
      j.str("name", sy.name).num("dim", sy.dim).str("lagrangian", sy.lagrangian).str("space", dvm::to_string(sy.space));
      Json::Object ps;
      for (const auto& p : sy.params) ps.num(p.name, p.default_value);
      j.raw("params", ps.dump(6));
      std::string forms = "[";
      for (std::size_t k = 0; k < sy.caps.forms.size(); ++k)
        forms += (k ? ", " : "") + Json::string(dvm::to_string(sy.caps.forms[k]));
      j.raw("forms", forms + "]")
          .boolean("retraction_maps", sy.caps.retraction_maps)
          .boolean("composition", sy.caps.composition)
          .boolean("galerkin", sy.caps.galerkin)
          .boolean("boundary_value", sy.caps.boundary_value);
      out += "  " + j.dump(4) + (i + 1 < systems.size() ? ",\n" : "\n");
    }
    std::cout << out << "]\n";
  } else {
    for (const auto& sy : systems) {
      std::printf("%-17s %s coordinates on %s\n  %s\n", sy.name.c_str(),
                  sy.dim > 0 ? std::to_string(sy.dim).c_str() : sy.dim_note.c_str(), dvm::to_string(sy.space),
                  sy.lagrangian.c_str());
      for (const auto& p : sy.params)
        std::printf("  %-8s = %-10g %s\n", p.name.c_str(), p.default_value, p.meaning.c_str());
    }
  }
  return 0;
}

int cmd_methods(const std::vector<std::string>& args) {
  bool json = false;
  for (const auto& a : args) {
    if (is_help(a)) {
      std::cout << kMethodsHelp;
      return 0;
    } else if (a == "--json") {
      json = true;
    } else {
      usage_error("unknown argument " + a, kMethodsHelp);
    }
  }
  return methods_command(json);
}

int cmd_converge(const std::vector<std::string>& args) {
  std::string scene;
  std::vector<std::string> sets;
  RunOptions o;
  o.converge = true;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&](const char* name) -> std::string {
      if (i + 1 >= args.size()) usage_error(std::string(name) + " needs a value", kConvergeHelp);
      return args[++i];
    };
    if (is_help(a)) {
      std::cout << kConvergeHelp;
      return 0;
    } else if (a == "--set") {
      sets.push_back(value("--set"));
    } else if (a == "--steps-list") {
      const std::string list = value("--steps-list");
      std::size_t start = 0;
      while (start <= list.size()) {
        const std::size_t comma = std::min(list.find(',', start), list.size());
        const std::string item = list.substr(start, comma - start);
        const double n = parse_number("--steps-list", item, kConvergeHelp);
        if (n != std::floor(n) || n < 1)
          usage_error("--steps-list: '" + item + "' is not a whole number of steps >= 1", kConvergeHelp);
        if (n > 9e15)
          usage_error("--steps-list: '" + item + "' is more steps than a run can count (at most 9e15)", kConvergeHelp);
        o.steps_list.push_back(static_cast<std::int64_t>(n));
        start = comma + 1;
      }
      if (o.steps_list.size() < 2) usage_error("--steps-list needs at least two step counts", kConvergeHelp);
    } else if (a == "--max-steps") {
      const std::string text = value("--max-steps");
      o.max_total_steps = parse_number("--max-steps", text, kConvergeHelp);
      if (o.max_total_steps != std::floor(o.max_total_steps) || o.max_total_steps < 1)
        usage_error("--max-steps: got '" + text + "', expected a whole number >= 1", kConvergeHelp);
    } else if (a == "--t-end") {
      o.t_end = parse_number("--t-end", value("--t-end"), kConvergeHelp);
      if (!(o.t_end > 0)) usage_error("--t-end: expected a positive number", kConvergeHelp);
    } else if (a == "--json") {
      o.json = true;
    } else if (!a.empty() && a[0] == '-') {
      usage_error("unknown option " + a, kConvergeHelp);
    } else if (scene.empty()) {
      scene = a;
    } else {
      usage_error("more than one scene file given", kConvergeHelp);
    }
  }
  if (scene.empty()) usage_error("converge needs a scene file", kConvergeHelp);
  return run_scene(load_scene(scene, sets), o);
}

#ifndef DVM_VERSION
#define DVM_VERSION "unknown"
#endif
#ifndef DVM_GIT_REVISION
#define DVM_GIT_REVISION "unknown"
#endif

int cmd_version(const std::vector<std::string>& args) {
  for (const auto& a : args) {
    if (is_help(a)) {
      std::cout << kVersionHelp;
      return 0;
    }
    usage_error("unknown argument " + a, kVersionHelp);
  }
  std::cout << "dvm " << DVM_VERSION << " (git " << DVM_GIT_REVISION << ")\n";
  return 0;
}

int cmd_check_map(const std::vector<std::string>& args) {
  std::string name;
  double theta = -1.0, tol = 1e-12;  // theta < 0, dim 0: not given
  int dim = 0;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&](const char* opt) -> std::string {
      if (i + 1 >= args.size()) usage_error(std::string(opt) + " needs a value", kCheckHelp);
      return args[++i];
    };
    if (is_help(a)) {
      std::cout << kCheckHelp;
      return 0;
    } else if (a == "--theta") {
      theta = parse_number("--theta", value("--theta"), kCheckHelp);
    } else if (a == "--dim") {
      const double d = parse_number("--dim", value("--dim"), kCheckHelp);
      if (d != std::floor(d) || d < 1 || d > 4) usage_error("--dim: expected 1, 2, 3 or 4", kCheckHelp);
      dim = static_cast<int>(d);
    } else if (a == "--tolerance") {
      tol = parse_number("--tolerance", value("--tolerance"), kCheckHelp);
      if (!(tol > 0)) usage_error("--tolerance: expected a positive number", kCheckHelp);
    } else if (!a.empty() && a[0] == '-') {
      usage_error("unknown option " + a, kCheckHelp);
    } else if (name.empty()) {
      name = a;
    } else {
      usage_error("more than one map name given", kCheckHelp);
    }
  }
  if (name.empty()) usage_error("check-map needs a map name (see 'dvm maps')", kCheckHelp);
  return check_map_command(name, theta, dim, tol);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.empty()) {
    std::cerr << kUsage;
    return 2;
  }
  const std::string cmd = args[0];
  args.erase(args.begin());
  try {
    if (is_help(cmd) || (cmd == "help" && (args.empty() || is_help(args[0])))) {
      std::cout << kUsage;
      return 0;
    }
    std::string command = cmd;
    if (cmd == "help") {  // dvm help COMMAND = dvm COMMAND --help
      if (args.size() > 1) usage_error("help takes one command name", kUsage);
      command = args[0];
      args = {"--help"};
      if (command == "help") {
        std::cout << kUsage;
        return 0;
      }
    }
    if (command == "version" || command == "--version") return cmd_version(args);
    if (command == "run") return cmd_run(args);
    if (command == "maps") return cmd_maps(args);
    if (command == "check-map") return cmd_check_map(args);
    if (command == "systems") return cmd_systems(args);
    if (command == "methods") return cmd_methods(args);
    if (command == "converge") return cmd_converge(args);
    usage_error("unknown command '" + command + "'", kUsage);
  } catch (const InputError& e) {
    std::cerr << "dvm: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "dvm: internal error: " << e.what() << "\n";
    return 3;
  }
}
