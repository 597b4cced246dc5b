// dvm: simulate a mechanical system from its Lagrangian with a variational
// integrator derived from a discretization map.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"
#include "examples/dvm/scene.h"

using namespace dvm::cli;

namespace {

const char* kUsage =
    "usage: dvm <command> [options]\n"
    "\n"
    "commands:\n"
    "  run SCENE.toml     integrate a scene (a system, initial state and integrator)\n"
    "  maps               list the discretization maps with their properties\n"
    "  check-map NAME     check the identities of a discretization map, as JSON\n"
    "  methods            list the composition methods (order, stages, stability)\n"
    "\n"
    "'dvm <command> --help' describes a command. Exit status: 0 success, 1 a check\n"
    "that did not pass, 2 bad input or usage, 3 a numerical failure during a run.\n";

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
    "              overriding [output] csv; rows every [output] every steps\n"
    "  --json      print a JSON summary (steps, t_final, q_final, p_final,\n"
    "              energy_initial, energy_final, max_abs_energy_error, wall_seconds,\n"
    "              solver_iterations, status, and failure when a step fails)\n"
    "  --quiet     print nothing on success (errors still go to stderr)\n"
    "\n"
    "Scene keys:\n"
    "  [system]      builtin = \"harmonic\" | \"pendulum\" | \"kepler\" | \"chain\"  (on R^n)\n"
    "                        | \"spherical-pendulum\" | \"spherical-chain\"    (on S^2, (S^2)^n)\n"
    "                        | \"rigid-body\" | \"heavy-top\"                  (on SO(3))\n"
    "                params = { ... }   (harmonic: omega; pendulum, spherical-pendulum: m, l, g;\n"
    "                kepler: mu; chain: n, m, k, alpha, beta, fixed; rigid-body: I1, I2, I3;\n"
    "                heavy-top: I1, I2, I3, m, g, chi1..3; spherical-chain: n, m, l, g)\n"
    "  [initial]     q = [...]   and   p = [...] or v = [...]   (S^2: q a unit vector, v tangent)\n"
    "                SO(3): rotation = [w, x, y, z] or R = [[...], [...], [...]],\n"
    "                       and omega = [...] (body angular velocity) or pi = [...]\n"
    "  [integrator]  map = \"midpoint\" | \"explicit-euler\" | \"adjoint-euler\" | \"theta\"\n"
    "                    | \"retraction-theta\"                                (on R^n)\n"
    "                    | \"sphere-exp\" | \"sphere-projection\" and their \"-fixed\" forms (S^2)\n"
    "                    | \"so3-exp\" | \"so3-cayley\" and their \"-fixed\" forms     (SO(3))\n"
    "                theta = 0.5  (map theta only)   step = 0.01   steps = N  or  t_end = T\n"
    "                solver = \"newton\" (default) | \"tiny\" (ceres::TinySolver)\n"
    "                max_iterations = 25   tolerance = 2e-15  (relative residual)\n"
    "                composition = \"none\" (default) | \"stormer-verlet\" | \"triple-jump\"\n"
    "                    | \"suzuki5\" | \"mclachlan4\" | \"yoshida6a\" ... | \"kahan-li8\"\n"
    "                    | \"triple-jump:<even order>\"   (the map's step composed; a map\n"
    "                    that is not symmetric enters as Phi_{h/2} o Phi*_{h/2}; see\n"
    "                    'dvm methods')\n"
    "  [output]      csv = \"out.csv\"   every = 1\n"
    "  [integrator]  form = \"lagrangian\" (default) | \"hamiltonian\" (Eq. 5.1, cotangent lift)\n"
    "                    | \"sode1\" | \"sode2\" (Eq. 4.1 / 4.2, tangent lift of the map)\n"
    "                    | \"newmark\" (gamma = 0.5, beta = 0.25; uses no map)\n"
    "  [problem]     kind = \"initial-value\" (default) | \"boundary-value\"\n"
    "                q_final = [...]   steps = K   (boundary-value: [initial] q only,\n"
    "                no integrator steps/t_end; lagrangian form)\n"
    "  [system]      builtin = \"chain\"   params = { n, m, k, alpha, beta, fixed }\n"
    "                (FPU chain of n particles; lagrangian form, theta-family maps)\n"
    "\n"
    "Exit status: 0 complete run; 2 bad input (nothing is written); 3 a step did not\n"
    "converge (the CSV holds the converged steps, the JSON says \"failed\").\n"
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
    "coefficients.\n"
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

[[noreturn]] void usage_error(const std::string& msg, const char* help) {
  std::cerr << "dvm: " << msg << "\n\n" << help;
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
      std::cout << kRunHelp;
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
  if (json) {
    std::string out = "[\n";
    for (std::size_t i = 0; i < maps().size(); ++i) {
      const MapInfo& m = maps()[i];
      Json::Object j;
      j.str("name", m.name)
          .str("formula", m.formula)
          .boolean("symmetric", m.symmetric)
          .num("order", m.order)
          .boolean("closed_form_inverse", m.closed_inverse)
          .str("space", m.space)
          .str("note", m.note);
      out += "  " + j.dump(4) + (i + 1 < maps().size() ? ",\n" : "\n");
    }
    std::cout << out << "]\n";
  } else {
    std::printf("%-24s %-6s %-9s %-5s %-8s %s\n", "name", "space", "symmetric", "order", "inverse", "formula");
    for (const auto& m : maps())
      std::printf("%-24s %-6s %-9s %-5d %-8s %s   (%s)\n", m.name.c_str(), m.space.c_str(), m.symmetric ? "yes" : "no",
                  m.order, m.closed_inverse ? "closed" : "Newton", m.formula.c_str(), m.note.c_str());
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

int cmd_check_map(const std::vector<std::string>& args) {
  std::string name;
  double theta = 0.5, tol = 1e-12;
  int dim = 2;
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
    if (is_help(cmd) || cmd == "help") {
      std::cout << kUsage;
      return 0;
    }
    if (cmd == "run") return cmd_run(args);
    if (cmd == "maps") return cmd_maps(args);
    if (cmd == "check-map") return cmd_check_map(args);
    if (cmd == "methods") return cmd_methods(args);
    usage_error("unknown command '" + cmd + "'", kUsage);
  } catch (const InputError& e) {
    std::cerr << "dvm: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "dvm: internal error: " << e.what() << "\n";
    return 3;
  }
}
