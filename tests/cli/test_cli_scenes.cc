// End-to-end tests of the dvm program on its scenes: every shipped scene runs
// with its invariants checked, written Lagrangians agree with the built-in systems,
// expression errors point at the scene's line and column, .npy output, and the
// systems / methods / converge commands.
#define BOOST_TEST_MODULE cli_scenes
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"
#include "tests/scoped_env.h"

#include <fcntl.h>
#include <pty.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace cli_test;

double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return INFINITY;
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
  return d;
}

Output run_json(const std::string& s, std::vector<std::string> extra = {}) {
  std::vector<std::string> args = {"run", scene(s), "--json", "--csv", temp_dir() + "/" + s + ".csv"};
  args.insert(args.end(), extra.begin(), extra.end());
  return dvm(args);
}

}  // namespace

BOOST_AUTO_TEST_CASE(every_shipped_scene_runs_and_keeps_its_invariants) {
  struct Case {
    const char* scene;
    std::vector<std::string> sets;  // shortened where the full run is long
    double energy_bound;            // max |E - E0|
  };
  const std::vector<Case> cases = {
      {"harmonic.toml", {}, 1e-13},
      {"pendulum.toml", {}, 1e-4},
      {"pendulum_written.toml", {}, 1e-4},
      {"kepler.toml", {}, 1e-3},
      {"double_pendulum.toml", {}, 5e-3},
      {"double_pendulum_written.toml", {}, 5e-3},
      {"henon_heiles.toml", {}, 1e-4},
      {"fpu.toml", {"--set", "integrator.t_end=20.0"}, 1e-4},
      {"duffing.toml", {}, 1e-3},
      {"charged_particle.toml", {}, 1e-13},  // quadratic energy: the midpoint rule keeps it
      {"figure_eight.toml", {"--set", "integrator.t_end=6.0"}, 1e-5},
      {"outer_solar_system.toml", {"--set", "integrator.t_end=20000.0"}, 1e-12},
      {"nbody_written.toml", {"--set", "integrator.t_end=6.0"}, 1e-6},
      {"fpu_chain_written.toml", {"--set", "integrator.t_end=100.0"}, 1e-10},
  };
  for (const auto& c : cases) {
    const Output o = run_json(c.scene, c.sets);
    BOOST_TEST_CONTEXT(c.scene << "\n" << o.out << o.err) {
      BOOST_TEST(o.status == 0);
      BOOST_TEST(parse_json(o.out).value("status", "") == "ok");
      BOOST_TEST(o.err.empty());  // no progress when stderr is not a terminal
      BOOST_TEST(json_number(o.out, "max_abs_energy_error") <= c.energy_bound);
      const bool quadratic = std::string(c.scene) == "harmonic.toml" || std::string(c.scene) == "charged_particle.toml";
      BOOST_TEST((quadratic || json_number(o.out, "max_abs_energy_error") > 0.0));
    }
  }
  // momenta where a symmetry gives them: kept to round-off (discrete Noether)
  const Output cp = run_json("charged_particle.toml");
  BOOST_TEST(invariant_error(cp.out, "angular momentum") <= 1e-13);
  BOOST_TEST(invariant_initial(cp.out, "angular momentum").at(0) == 2.5);  // x p_y = 1 (v_y + B/2 x) = 0.5 + 2
  const Output f8 = run_json("figure_eight.toml", {"--set", "integrator.t_end=6.0"});
  for (const char* n : {"momentum x", "momentum y", "angular momentum z"})
    BOOST_TEST(invariant_error(f8.out, n) <= 1e-13, n);
  const Output os = run_json("outer_solar_system.toml", {"--set", "integrator.t_end=20000.0"});
  for (const char* n : {"momentum x", "momentum y", "momentum z"}) BOOST_TEST(invariant_error(os.out, n) <= 1e-18, n);
  for (const char* n : {"angular momentum x", "angular momentum y", "angular momentum z"})
    BOOST_TEST(invariant_error(os.out, n) <= 1e-15, n);
  // FPU: the oscillatory energy is an adiabatic invariant, O(1/omega) = 0.02, not exact
  const Output fpu = run_json("fpu.toml", {"--set", "integrator.t_end=20.0"});
  const double dI = invariant_error(fpu.out, "oscillatory energy (adiabatic, O(1/omega))");
  BOOST_TEST(dI < 0.1);
  BOOST_TEST(dI > 1e-3);
}

BOOST_AUTO_TEST_CASE(written_lagrangians_match_the_built_in_systems) {
  const Output a = run_json("pendulum.toml");
  const Output b = run_json("pendulum_written.toml");
  BOOST_TEST(max_diff(json_array(a.out, "q_final"), json_array(b.out, "q_final")) <= 1e-12);
  BOOST_TEST(max_diff(json_array(a.out, "p_final"), json_array(b.out, "p_final")) <= 1e-12);
  // the double pendulum is chaotic: compare before round-off has been amplified
  const Output c = run_json("double_pendulum.toml", {"--set", "integrator.t_end=10.0"});
  const Output d = run_json("double_pendulum_written.toml", {"--set", "integrator.t_end=10.0"});
  BOOST_TEST(max_diff(json_array(c.out, "q_final"), json_array(d.out, "q_final")) <= 1e-10);
  BOOST_TEST(max_diff(json_array(c.out, "p_final"), json_array(d.out, "p_final")) <= 1e-10);
  // six coordinates: the FPU chain written out against the built-in one
  const std::string fpu = write_scene(
      "fpu_written.toml",
      "[system]\ncoordinates = [\"a\", \"b\", \"c\", \"d\", \"e\", \"f\"]\nparams = { w = 50.0 }\n"
      "lagrangian = \"\"\"(a_dot^2 + b_dot^2 + c_dot^2 + d_dot^2 + e_dot^2 + f_dot^2)/2\n"
      "  - w^2/4*((b - a)^2 + (d - c)^2 + (f - e)^2)\n"
      "  - (a^4 + (c - b)^4 + (e - d)^4 + f^4)\"\"\"\n"
      "[initial]\nq = [0.6929646455628166, 0.7212489168102785, 0.0, 0.0, 0.0, 0.0]\n"
      "p = [0.0, 1.4142135623730951, 0.0, 0.0, 0.0, 0.0]\n"
      "[integrator]\nmap = \"midpoint\"\nstep = 0.002\nsteps = 2000\n");
  const Output fw = dvm({"run", fpu, "--json"});
  const Output fb = run_json("fpu.toml", {"--set", "integrator.t_end=4.0"});
  BOOST_TEST(fw.status == 0, fw.err);
  BOOST_TEST(max_diff(json_array(fw.out, "q_final"), json_array(fb.out, "q_final")) <= 1e-12);
  BOOST_TEST(max_diff(json_array(fw.out, "p_final"), json_array(fb.out, "p_final")) <= 1e-11);
  // a written Lagrangian with a cyclic coordinate reports its momentum as an invariant
  const std::string free2d = write_scene(
      "central.toml",
      "[system]\ncoordinates = [\"r\", \"phi\"]\n"
      "lagrangian = \"(r_dot^2 + r^2*phi_dot^2)/2 + 1/r\"\n"
      "[initial]\nq = [0.4, 0.0]\nv = [0.0, 5.0]\n"
      "[integrator]\nmap = \"midpoint\"\nstep = 0.001\nsteps = 2000\n");
  const Output e = dvm({"run", free2d, "--json"});
  BOOST_TEST(e.status == 0, e.err);
  BOOST_TEST(invariant_error(e.out, "p_phi (cyclic)") <= 1e-13, e.out);
  // polar Kepler against Cartesian Kepler: same energy
  const Output k = run_json("kepler.toml");
  BOOST_TEST(std::fabs(json_number(e.out, "energy_initial") - json_number(k.out, "energy_initial")) <= 1e-14);
}

// Boundary values of a Lagrangian written on R^n (the run-time-sized problem, its
// Jacobian written out from L's Hessian): the shipped written double pendulum solves and
// writes its nodes under the coordinates' names; the built-in double pendulum between
// the same ends (Jets of the three nodes) gives the same solved momenta to round-off,
// for the midpoint map, theta = 0.3 and retraction-theta; shooting from the solved
// (q_0, p_0) with the written initial-value run retraces the path; and what the
// run-time-sized problem does not take (forces, written maps) is refused naming a key.
BOOST_AUTO_TEST_CASE(written_lagrangians_solve_boundary_value_problems) {
  const std::string csv = temp_dir() + "/dpw_bvp.csv";
  const Output w = dvm({"run", scene("double_pendulum_written_bvp.toml"), "--json", "--csv", csv});
  BOOST_REQUIRE_MESSAGE(w.status == 0, w.err);
  BOOST_TEST(json_string(w.out, "problem") == "boundary-value");
  BOOST_TEST(json_number(w.out, "max_del_residual") <= 1e-14 * json_number(w.out, "residual_scale"), w.out);
  std::ifstream rows(csv);
  std::string header;
  std::getline(rows, header);
  BOOST_TEST(header == "t,a,b,p_a,p_b,energy");
  const std::string ends = "[initial]\nq = [0.5, 0.2]\n[problem]\nkind = \"boundary-value\"\nq_final = [0.1, -0.4]\n"
                           "steps = 1000\n[integrator]\nstep = 0.001\n";
  const std::string builtin = "[system]\nbuiltin = \"double-pendulum\"\n" + ends;
  std::string written;  // the shipped scene's [system]
  {
    std::ifstream f(scene("double_pendulum_written_bvp.toml"));
    std::stringstream text;
    text << f.rdbuf();
    written = text.str().substr(0, text.str().find("[initial]")) + ends;
  }
  for (const char* map : {"map = \"midpoint\"\n", "map = \"theta\"\ntheta = 0.3\n",
                          "map = \"retraction-theta\"\ntheta = 0.3\n"}) {
    const Output b = dvm({"run", write_scene("dp_bvp_builtin.toml", builtin + map), "--json", "--no-output"});
    const Output t = dvm({"run", write_scene("dp_bvp_written.toml", written + map), "--json", "--no-output"});
    BOOST_TEST_CONTEXT(map << b.err << t.err) {
      BOOST_REQUIRE(b.status == 0);
      BOOST_REQUIRE(t.status == 0);
      for (const char* key : {"p_initial", "p_final"}) {
        const std::vector<double> pb = json_array(b.out, key), pt = json_array(t.out, key);
        BOOST_TEST(max_diff(pb, pt) <= 1e-11 * std::fmax(1.0, max_diff(pb, std::vector<double>(pb.size(), 0.0))),
                   key << ": built-in " << b.out << "\nwritten " << t.out);
      }
      // the end as given, to the bit (not q_initial + (q_final - q_initial))
      BOOST_TEST(max_diff(json_array(b.out, "q_final"), {0.1, -0.4}) == 0.0, b.out);
      BOOST_TEST(max_diff(json_array(t.out, "q_final"), {0.1, -0.4}) == 0.0, t.out);
    }
  }
  // the solved path is a trajectory: the written midpoint run from (q_0, p_0) ends at q_final
  const std::vector<double> p0 = json_array(w.out, "p_initial");
  char p[96];
  std::snprintf(p, sizeof p, "p = [%.17g, %.17g]\n", p0.at(0), p0.at(1));
  const std::string ivp = written.substr(0, written.find("[initial]")) + "[initial]\nq = [0.5, 0.2]\n" + p +
                          "[integrator]\nmap = \"midpoint\"\nstep = 0.001\nsteps = 1000\n";
  const Output s = dvm({"run", write_scene("dp_shoot.toml", ivp), "--json", "--no-output"});
  BOOST_REQUIRE_MESSAGE(s.status == 0, s.err);
  BOOST_TEST(max_diff(json_array(s.out, "q_final"), {0.1, -0.4}) <= 1e-9, s.out);
  // refused: a force, a written map, the hamiltonian form, a Jacobian beyond 2^27 numbers
  const std::string forced = written.substr(0, written.find("[initial]")) + "forces = { a = \"-0.1*a_dot\" }\n" + ends +
                             "map = \"midpoint\"\n";
  const std::string wmap = written + "map = \"written\"\n[map]\nname = \"plain midpoint\"\nq0 = \"x - v/2\"\nq1 = \"x + v/2\"\n";
  const std::string ham = written + "map = \"midpoint\"\nform = \"hamiltonian\"\n";
  std::string huge = written + "map = \"midpoint\"\n";
  huge.replace(huge.find("steps = 1000"), 12, "steps = 20000000");
  for (const auto& [text, key] : std::vector<std::pair<std::string, std::string>>{
           {forced, "problem.kind"}, {wmap, "integrator.map"}, {ham, "integrator.form"}, {huge, "problem.steps"}}) {
    const Output o = dvm({"run", write_scene("dp_bvp_refused.toml", text), "--no-output"});
    BOOST_TEST(o.status == 2, o.err);
    BOOST_TEST(o.err.find(key) != std::string::npos, o.err);
  }
}

// [system] invariants: quantities of the user's own, monitored like the energy. On
// Kepler's problem in Cartesian coordinates the angular momentum, written in momenta or
// in velocities, is kept to round-off by the midpoint map (discrete Noether); the
// radius, which is not conserved, is reported with its variation, so the expressions are
// evaluated along the run and not only at the start. Each is a CSV column after the
// energy, and its last row is the expression at the final state.
BOOST_AUTO_TEST_CASE(invariants_of_ones_own_are_monitored_like_the_energy) {
  const std::string kepler =
      "[system]\ncoordinates = [\"x\", \"y\"]\nparams = { mu = 1.0 }\n"
      "lagrangian = \"(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)\"\n"
      "invariants = { L = \"x*p_y - y*p_x\", Lv = \"x*y_dot - y*x_dot\", r = \"sqrt(x^2 + y^2)\" }\n"
      "[initial]\nq = [0.4, 0.0]\np = [0.0, 2.0]\n"
      "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 700\n";
  const std::string path = write_scene("kepler-invariants.toml", kepler), csv = temp_dir() + "/kinv.csv";
  const Output o = dvm({"run", path, "--json", "--csv", csv, "--set", "output.every=7"});
  BOOST_TEST_REQUIRE(o.status == 0, o.err);
  BOOST_TEST(invariant_initial(o.out, "L").at(0) == 0.8);
  BOOST_TEST(invariant_initial(o.out, "Lv").at(0) == 0.8);
  BOOST_TEST(invariant_initial(o.out, "r").at(0) == 0.4);
  BOOST_TEST(invariant_error(o.out, "L") <= 1e-13);
  BOOST_TEST(invariant_error(o.out, "Lv") <= 1e-12);  // v = p (unit mass), through the Legendre solve
  BOOST_TEST(invariant_error(o.out, "r") >= 1.0);       // from perihelion 0.4 to aphelion 1.6
  BOOST_TEST(invariant_error(o.out, "r") <= 1.2 + 1e-9);
  std::ifstream f(csv);
  std::string header, line, last;
  std::getline(f, header);
  BOOST_TEST(header == "t,x,y,p_x,p_y,energy,L,Lv,r");
  while (std::getline(f, line)) last = line;
  double t, x, y, px, py, E, L, Lv, r;
  BOOST_TEST_REQUIRE(std::sscanf(last.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &t, &x, &y, &px, &py, &E, &L,
                                 &Lv, &r) == 9);
  BOOST_TEST(t == 7.0, boost::test_tools::tolerance(1e-12));
  BOOST_TEST(L == x * py - y * px, boost::test_tools::tolerance(1e-12));
  BOOST_TEST(r == std::sqrt(x * x + y * y), boost::test_tools::tolerance(1e-12));

  // refused, naming the key: on a built-in system, on S^2, not a table, not a string, an
  // expression that does not parse, a name that is not there
  struct Bad {
    std::string text, expect;
  };
  const std::vector<Bad> bad = {
      {"[system]\nbuiltin = \"kepler\"\ninvariants = { L = \"q0\" }\n[initial]\nq = [0.4, 0.0]\np = [0.0, 2.0]\n"
       "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 7\n",
       "system.invariants"},
      {std::string(kepler).replace(kepler.find("invariants = {"), 14, "invariants = 3 #"), "system.invariants"},
      {std::string(kepler).replace(kepler.find("L = \"x*p_y"), 5, "L = 3, Q = \"x*p_y"), "system.invariants.L"},
      {std::string(kepler).replace(kepler.find("x*p_y - y*p_x"), 13, "x*p_y - y*"), "system.invariants.L"},
      {std::string(kepler).replace(kepler.find("x*p_y - y*p_x"), 13, "x*p_z"), "p_z"},
      {std::string(kepler).replace(kepler.find("Lv = "), 5, "p_x = "), "'p_x' names a column"},
      {std::string(kepler).replace(kepler.find("Lv = "), 5, "energy = "), "'energy' names a column"},
  };
  for (const Bad& b : bad) {
    const Output e = dvm({"run", write_scene("bad-invariants.toml", b.text)});
    BOOST_TEST(e.status == 2, b.text << e.err);
    BOOST_TEST(e.err.find(b.expect) != std::string::npos, e.err);
  }
  const Output s2 = dvm({"run", scene("spherical_pendulum_written.toml"), "--set",
                         "system.invariants={ J = \"x*p_y - y*p_x\" }"});
  BOOST_TEST(s2.status == 2);
  BOOST_TEST(s2.err.find("system.invariants") != std::string::npos, s2.err);
  BOOST_TEST(s2.err.find("R^n") != std::string::npos, s2.err);
}

BOOST_AUTO_TEST_CASE(expression_errors_point_at_line_and_column) {
  struct Case {
    std::string system;  // the [system] table, from line 2 on
    std::string expect;
  };
  const std::string rest = "[initial]\nq = [1.0]\np = [0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 10\n";
  const std::vector<Case> cases = {
      // line 3: lagrangian = "x_dot^2/2 - k*y^2": 'y' at column 29
      {"coordinates = [\"x\"]\nlagrangian = \"x_dot^2/2 - k*y^2\"\nparams = { k = 1.0 }\n",
       ":3:29: in system.lagrangian: unknown name 'y'; known names: x, x_dot, t, k, pi"},
      // multi-line string: the error is on line 5, column 9
      {"coordinates = [\"x\"]\nlagrangian = \"\"\"\n  x_dot^2\n  - 2 * * x\"\"\"\n",
       ":5:9: in system.lagrangian: expected a number, name or '(' after '*', got '*'"},
      {"coordinates = [\"x\"]\nlagrangian = \"sin(x\"\n", ":3:20: in system.lagrangian: expected ',' or ')'"},
      {"coordinates = [\"x\"]\nlagrangian = \"x_dot^2 + atan2(x)\"\n", ":3:25: in system.lagrangian: function 'atan2' takes 2"},
      {"coordinates = [\"x\"]\nlagrangian = \"x_dot^2\"\nenergy = \"x_dot^2 + p_y\"\n",
       ":4:21: in system.energy: unknown name 'p_y'; known names: x, x_dot, p_x, pi"},
      {"coordinates = [\"x\"]\nlagrangian = \"x_dot^2\"\nhamiltonian = \"x_dot^2\"\n",
       ":4:16: in system.hamiltonian: unknown name 'x_dot'; known names: x, p_x, pi"},
      {"lagrangian = \"x_dot^2\"\n", "missing key 'system.coordinates'"},
      {"coordinates = [\"x\", \"x\"]\nlagrangian = \"x_dot^2\"\n", "used twice"},
      {"coordinates = [\"x\"]\nbuiltin = \"harmonic\"\nlagrangian = \"x_dot^2\"\n", "not both"},
      // any number of coordinates, each given an initial value
      {"coordinates = [\"a\", \"b\", \"c\", \"d\", \"e\", \"f\", \"g\"]\nlagrangian = \"a_dot^2\"\n", "expected 7"},
      // degenerate: L = x x_dot has a zero velocity Hessian
      {"coordinates = [\"x\"]\nlagrangian = \"x*x_dot + x^2\"\n",
       "the Lagrangian is degenerate at the initial state: the velocity Hessian d2L/dv2 is singular"},
      // degenerate only where x = 1 (the initial state): x_dot^2 (x - 1)^2
      {"coordinates = [\"x\"]\nlagrangian = \"x_dot^2*(x - 1)^2 - x^2\"\n", "degenerate at the initial state"},
      // a Hamiltonian with the wrong sign of the potential disagrees with L
      {"coordinates = [\"x\"]\nlagrangian = \"x_dot^2/2 - x^2/2\"\nhamiltonian = \"p_x^2/2 - x^2/2\"\n",
       "system.hamiltonian does not match the Legendre transform"},
  };
  int i = 0;
  for (const auto& c : cases) {
    const std::string path = write_scene("expr" + std::to_string(i++) + ".toml", "[system]\n" + c.system + rest);
    const Output o = dvm({"run", path});
    BOOST_TEST_CONTEXT(c.system << " -> " << o.err) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.find(c.expect) != std::string::npos);
    }
  }
  // a consistent Hamiltonian and a written energy are accepted and the energy monitored
  const std::string ok = write_scene("ok.toml", "[system]\ncoordinates = [\"x\"]\nlagrangian = \"x_dot^2/2 - x^2/2\"\n"
                                                "hamiltonian = \"p_x^2/2 + x^2/2\"\nenergy = \"3*(x_dot^2 + x^2)\"\n" + rest);
  const Output o = dvm({"run", ok, "--json"});
  BOOST_TEST(o.status == 0, o.err);
  BOOST_TEST(json_number(o.out, "energy_initial") == 3.0);  // the written energy, not E_L = 1/2
}

BOOST_AUTO_TEST_CASE(npy_output_holds_the_csv_rows) {
  const std::string npy = temp_dir() + "/k.npy", csv = temp_dir() + "/k.csv";
  const Output o = dvm({"run", scene("kepler.toml"), "--json", "--npy", npy, "--csv", csv, "--set", "output.every=100"});
  BOOST_TEST(o.status == 0, o.err);
  // the column names beside it, in k.npy.json: the CSV's header
  const Json names = parse_json(slurp(npy + ".json"));
  std::string joined;
  for (const Json& c : names.at("columns")) joined += (joined.empty() ? "" : ",") + c.get<std::string>();
  const std::string text = slurp(csv);
  BOOST_TEST(joined == text.substr(0, text.find('\n')));
  BOOST_TEST(names.at("npy").get<std::string>() == "k.npy");
  const std::string bytes = slurp(npy);
  BOOST_REQUIRE(bytes.size() > 10);
  BOOST_TEST(bytes.compare(0, 6, "\x93NUMPY") == 0);
  BOOST_TEST(bytes[6] == 1);
  const std::size_t hlen = static_cast<unsigned char>(bytes[8]) + 256u * static_cast<unsigned char>(bytes[9]);
  BOOST_TEST((10 + hlen) % 16 == 0u);
  const std::string header = bytes.substr(10, hlen);
  BOOST_TEST(header.find("'descr': '<f8'") != std::string::npos);
  BOOST_TEST(header.back() == '\n');
  long long rows = 0;
  int cols = 0;
  BOOST_REQUIRE(std::sscanf(header.c_str() + header.find("'shape': (") + 10, "%lld, %d", &rows, &cols) == 2);
  BOOST_TEST(rows == 201);  // t = 0 and every 100th of 20000 steps
  BOOST_TEST(cols == 6);
  BOOST_TEST(bytes.size() == 10 + hlen + static_cast<std::size_t>(rows * cols) * 8);
  std::vector<double> last(6);
  std::memcpy(last.data(), bytes.data() + bytes.size() - 48, 48);
  BOOST_TEST(last[0] == 100.0);
  BOOST_TEST(max_diff({last[1], last[2]}, json_array(o.out, "q_final")) == 0.0);
  BOOST_TEST(max_diff({last[3], last[4]}, json_array(o.out, "p_final")) == 0.0);
}

BOOST_AUTO_TEST_CASE(systems_methods_converge_and_help) {
  const Output s = dvm({"systems", "--json"});
  BOOST_TEST(s.status == 0);
  // the array of the systems, each an object with its name and its parameters' defaults
  const Json systems = parse_json(s.out);
  std::vector<std::string> names;
  for (const Json& e : systems) names.push_back(e.value("name", ""));
  for (const char* n : {"harmonic", "pendulum", "kepler", "double-pendulum", "henon-heiles", "fpu", "duffing",
                        "charged-particle", "nbody"})
    BOOST_TEST((std::find(names.begin(), names.end(), n) != names.end()), n);
  const auto fpu = std::find(names.begin(), names.end(), "fpu");
  BOOST_REQUIRE(fpu != names.end());
  BOOST_TEST(json_double(systems.at(static_cast<std::size_t>(fpu - names.begin())).at("params").at("omega")) == 50.0);
  BOOST_TEST(dvm({"systems"}).out.find("stiff spring frequency") != std::string::npos);
  BOOST_TEST(dvm({"methods"}).status == 0);
  // converge against exact solutions: second order for the midpoint map, first for theta 0.3
  const Output c = dvm({"converge", scene("charged_particle.toml"), "--steps-list", "50,100,200,400", "--t-end", "1",
                        "--json"});
  BOOST_TEST(c.status == 0, c.err);
  BOOST_TEST(json_string(c.out, "reference") == "exact solution");
  BOOST_TEST(json_number(c.out, "fitted_order") == 2.0, boost::test_tools::tolerance(0.05));
  const Output d = dvm({"converge", scene("duffing.toml"), "--steps-list", "100,200,400,800", "--t-end", "1",
                        "--set", "integrator.map=theta", "--set", "integrator.theta=0.3", "--json"});
  BOOST_TEST(d.status == 0, d.err);
  BOOST_TEST(json_number(d.out, "fitted_order") == 1.0, boost::test_tools::tolerance(0.1));
  // without an exact solution: a run of Galerkin s = 6 (order 12), refined until it
  // reports an accuracy below the errors measured
  const Output h = dvm({"converge", scene("henon_heiles.toml"), "--steps-list", "20,40,80,160", "--t-end", "2",
                        "--json"});
  BOOST_TEST(h.status == 0, h.err);
  BOOST_TEST(json_string(h.out, "reference").rfind("galerkin gauss s=6", 0) == 0u, h.out);  // its name begins so
  BOOST_TEST(json_number(h.out, "reference_accuracy") <= 1e-12, h.out);
  BOOST_TEST(json_number(h.out, "fitted_order") == 2.0, boost::test_tools::tolerance(0.05));
  BOOST_TEST(dvm({"converge", scene("duffing.toml"), "--steps-list", "100"}).status == 2);
  BOOST_TEST(dvm({"converge"}).status == 2);
  for (const char* cmd : {"run", "maps", "methods", "systems", "check-map", "converge"}) {
    const Output o = dvm({cmd, "--help"});
    BOOST_TEST(o.status == 0, cmd);
    BOOST_TEST(o.out.find("example") != std::string::npos, cmd);
  }
  const Output top = dvm({"--help"});
  for (const char* cmd : {"run", "maps", "methods", "systems", "check-map", "converge"})
    BOOST_TEST(top.out.find(std::string("  ") + cmd) != std::string::npos, cmd);
}

namespace {

// Runs dvm with its stderr (and stdin) on a new pseudo-terminal and stdout on
// /dev/null, DVM_PROGRESS_INTERVAL set to `interval` (solvers/runtime/recorder.h);
// returns what the terminal received and sets `status` to the exit status. forkpty is
// glibc's (libutil): no script(1) or other program is needed.
std::string on_terminal(const std::vector<std::string>& args, const char* interval, int& status) {
  std::vector<char*> argv = {const_cast<char*>(DVM_BINARY)};
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  BOOST_REQUIRE(setenv("DVM_PROGRESS_INTERVAL", interval, 1) == 0);
  int master = -1;
  const pid_t pid = forkpty(&master, nullptr, nullptr, nullptr);
  if (pid == 0) {  // the child: only async-signal-safe calls
    const int null = open("/dev/null", O_WRONLY);
    if (null < 0 || dup2(null, STDOUT_FILENO) < 0) _exit(126);
    execv(DVM_BINARY, argv.data());
    _exit(127);
  }
  const int fork_errno = errno;
  unsetenv("DVM_PROGRESS_INTERVAL");
  BOOST_REQUIRE_MESSAGE(pid > 0, "forkpty: " << std::strerror(fork_errno));
  std::string out;
  char buf[4096];
  for (;;) {  // until EIO: the child has closed the terminal
    const ssize_t n = read(master, buf, sizeof buf);
    if (n > 0)
      out.append(buf, static_cast<std::size_t>(n));
    else if (n < 0 && errno == EINTR)
      continue;
    else
      break;
  }
  close(master);
  int st = 0;
  BOOST_REQUIRE(waitpid(pid, &st, 0) == pid);
  status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return out;
}

}  // namespace

// Progress appears on a terminal and not with --quiet; without a terminal stderr stays
// empty (tested above). Deterministic: with DVM_PROGRESS_INTERVAL=0 a line is written
// at every 1024th step, whatever the speed of the machine; with a huge interval none.
BOOST_AUTO_TEST_CASE(progress_on_a_terminal_only) {
  const std::string path = write_scene(
      "progress.toml", "[system]\nbuiltin = \"harmonic\"\n[initial]\nq = [1.0]\np = [0.0]\n"
                       "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 4096\n");
  int status = -1;
  const std::string shown = on_terminal({"run", path}, "0", status);
  BOOST_TEST(status == 0, shown);
  // steps 1024, 2048, 3072 and 4096 at t = k h, then the line is cleared
  for (const char* line : {"\r  step 1024/4096  t = 10.24  ", "\r  step 2048/4096  t = 20.48  ",
                           "\r  step 3072/4096  t = 30.72  ", "\r  step 4096/4096  t = 40.96  "})
    BOOST_TEST(shown.find(line) != std::string::npos, "missing '" << line + 1 << "' in: " << shown);
  BOOST_TEST(shown.find("step 1023/") == std::string::npos, shown);  // only every 1024th step
  BOOST_TEST(shown.find("step 0/") == std::string::npos, shown);
  BOOST_TEST(shown.find(" steps/s  ") != std::string::npos, shown);
  BOOST_TEST(shown.find(" s left") != std::string::npos, shown);
  BOOST_TEST(shown.find("\r" + std::string(78, ' ') + "\r") != std::string::npos, shown);
  // --quiet: nothing at all on the terminal
  const std::string quiet = on_terminal({"run", path, "--quiet"}, "0", status);
  BOOST_TEST(status == 0);
  BOOST_TEST(quiet.empty(), quiet);
  // an interval longer than the run (1e9 s): no line
  const std::string none = on_terminal({"run", path}, "1e9", status);
  BOOST_TEST(status == 0);
  BOOST_TEST(none.find("step ") == std::string::npos, none);
}

BOOST_AUTO_TEST_CASE(written_hamiltonian_drives_the_hamiltonian_form) {
  // pendulum_written.toml writes H = p^2/(2 m l^2) - m g l cos(theta): its Hamiltonian
  // form (Eq. 5.1 with the scene's H) and the built-in pendulum's Hamiltonian form (H
  // from L by the Legendre transform) are the same method: same states to round-off.
  const std::vector<std::string> common = {"--set", "integrator.t_end=2.0", "--set", "integrator.form=hamiltonian"};
  std::vector<std::string> a = {"run", scene("pendulum_written.toml"), "--json", "--csv", temp_dir() + "/wh.csv"};
  std::vector<std::string> b = {"run", scene("pendulum.toml"), "--json", "--csv", temp_dir() + "/bh.csv"};
  a.insert(a.end(), common.begin(), common.end());
  b.insert(b.end(), common.begin(), common.end());
  const Output wa = dvm(a), wb = dvm(b);
  BOOST_TEST(wa.status == 0, wa.err);
  BOOST_TEST(wb.status == 0, wb.err);
  BOOST_TEST(json_string(wa.out, "form") == "hamiltonian");
  BOOST_TEST(max_diff(json_array(wa.out, "q_final"), json_array(wb.out, "q_final")) <= 1e-13);
  BOOST_TEST(max_diff(json_array(wa.out, "p_final"), json_array(wb.out, "p_final")) <= 1e-13);
  // (for this separable H the Lagrangian form with the midpoint map is the same
  // implicit midpoint rule; the form key says which equations were solved)
  // without a written H the Hamiltonian form takes H from L by the Legendre transform:
  // the same method as the built-in double pendulum's Hamiltonian form (whose H is the
  // same transform of the same L), the same states to round-off
  const std::vector<std::string> ham = {"--set", "integrator.t_end=2.0", "--set", "integrator.form=hamiltonian"};
  std::vector<std::string> c = {"run", scene("double_pendulum_written.toml"), "--json", "--csv", temp_dir() + "/dw.csv"};
  std::vector<std::string> d = {"run", scene("double_pendulum.toml"), "--json", "--csv", temp_dir() + "/db.csv"};
  c.insert(c.end(), ham.begin(), ham.end());
  d.insert(d.end(), ham.begin(), ham.end());
  const Output wc = dvm(c), wd = dvm(d);
  BOOST_TEST(wc.status == 0, wc.err);
  BOOST_TEST(wd.status == 0, wd.err);
  BOOST_TEST(max_diff(json_array(wc.out, "q_final"), json_array(wd.out, "q_final")) <= 1e-12);
  BOOST_TEST(max_diff(json_array(wc.out, "p_final"), json_array(wd.out, "p_final")) <= 1e-12);
}

// The SODE and Newmark forms of a written Lagrangian (DynamicSodeStep, on a separable
// text) are the built-in pendulum's (SodeStep, NewmarkStep of fixed size): the same
// equations, solved to the same rule, so the same states to round-off (1e-12 relative);
// composed too, with the adjoint stages (1 - theta, and Newmark's (1 - gamma,
// 1/2 - gamma + beta)), and through the Legendre lift. A wrong acceleration, map or
// adjoint moves the states by 1e-4 or more. A Lagrangian that is not separable is
// refused naming the keys, with nothing written.
BOOST_AUTO_TEST_CASE(written_lagrangians_run_the_sode_and_newmark_forms_of_the_built_ins) {
  const std::vector<std::vector<std::string>> methods = {
      {"integrator.form=sode1"},
      {"integrator.form=sode2"},
      {"integrator.form=sode1", "integrator.map=theta", "integrator.theta=0.3"},
      {"integrator.form=sode2", "integrator.map=theta", "integrator.theta=0.3", "integrator.composition=triple-jump"},
      {"integrator.form=newmark"},
      {"integrator.form=newmark", "integrator.gamma=0.6", "integrator.beta=0.3"},
      {"integrator.form=newmark", "integrator.composition=yoshida6a"},
      // the Legendre lift (Prop. 5.3) of the theta map, which for this separable L takes
      // the base point's velocity at 1 - theta
      {"integrator.form=sode1", "integrator.map=theta", "integrator.theta=0.3", "integrator.lift=legendre"},
      {"integrator.form=sode2", "integrator.map=theta", "integrator.theta=0.3", "integrator.lift=legendre"},
      {"integrator.form=sode2", "integrator.map=theta", "integrator.theta=0.3", "integrator.lift=legendre",
       "integrator.composition=triple-jump"},
  };
  for (const auto& m : methods) {
    // a mass m l^2 of 4.5, so that a confusion of velocity and momentum shows
    std::vector<std::string> common = {"--set", "integrator.t_end=2.0", "--set", "system.params.m=2.0",
                                       "--set", "system.params.l=1.5"};
    std::string what;
    for (const auto& kv : m) {
      common.push_back("--set");
      common.push_back(kv);
      what += kv + " ";
    }
    BOOST_TEST_CONTEXT(what) {
      const Output w = run_json("pendulum_written.toml", common), b = run_json("pendulum.toml", common);
      BOOST_TEST_REQUIRE(w.status == 0, w.err);
      BOOST_TEST_REQUIRE(b.status == 0, b.err);
      BOOST_TEST(json_string(w.out, "form") == json_string(b.out, "form"));
      BOOST_TEST(json_number(w.out, "order") == json_number(b.out, "order"));
      // relative to the state (measured: at most 1.4e-13, the compositions; the
      // fixed-size steps invert M and their Jacobians by other operations)
      const std::vector<double> qb = json_array(b.out, "q_final"), pb = json_array(b.out, "p_final");
      BOOST_TEST(max_diff(json_array(w.out, "q_final"), qb) <= 1e-12 * std::fabs(qb.at(0)));
      BOOST_TEST(max_diff(json_array(w.out, "p_final"), pb) <= 1e-12 * std::fabs(pb.at(0)));
    }
  }
  auto refused = [&](const std::string& s, const std::vector<std::string>& sets, const std::vector<std::string>& says) {
    const std::string csv = temp_dir() + "/sode_refused.csv";
    std::remove(csv.c_str());
    std::vector<std::string> args = {"run", scene(s), "--csv", csv};
    for (const auto& kv : sets) {
      args.push_back("--set");
      args.push_back(kv);
    }
    const Output o = dvm(args);
    BOOST_TEST_CONTEXT(s << " " << sets.front()) {
      BOOST_TEST(o.status == 2);
      for (const auto& key : says) BOOST_TEST(o.err.find(key) != std::string::npos, o.err);
      BOOST_TEST(!std::ifstream(csv).good());
    }
  };
  // the double pendulum's kinetic energy couples the angles: not separable
  refused("double_pendulum_written.toml", {"integrator.form=sode1"}, {"integrator.form", "system.lagrangian", "separable"});
  refused("double_pendulum_written.toml", {"integrator.form=newmark"}, {"integrator.form", "system.lagrangian"});
}

// Written systems of many coordinates (arrays, lists, sums; mechanics/expression.h)
// against the built-in ones, and the structure read off their text.
BOOST_AUTO_TEST_CASE(written_arrays_and_sums_match_the_built_in_systems) {
  // the written n-body Lagrangian (one array r[3n], a list of masses, a double sum) and
  // the built-in figure eight, with the same explicit method
  const std::vector<std::string> sv = {"--set", "integrator.map=adjoint-euler", "--set",
                                       "integrator.composition=stormer-verlet", "--set", "integrator.t_end=6.0"};
  const Output w = run_json("nbody_written.toml", sv);
  const Output b = run_json("figure_eight.toml", sv);
  BOOST_TEST(w.status == 0, w.err);
  BOOST_TEST(json_string(w.out, "structure") == "separable");
  BOOST_TEST(json_string(w.out, "structure_source") == "expression");
  BOOST_TEST(json_string(w.out, "step_path") == "explicit-splitting");
  BOOST_TEST(max_diff(json_array(w.out, "q_final"), json_array(b.out, "q_final")) <= 1e-13);
  BOOST_TEST(max_diff(json_array(w.out, "p_final"), json_array(b.out, "p_final")) <= 1e-13);
  // and with the implicit midpoint (Newton with the sparse Hessian of the written potential)
  const std::vector<std::string> mid = {"--set", "integrator.map=midpoint", "--set", "integrator.composition=none",
                                        "--set", "integrator.t_end=1.0"};
  const Output wm = run_json("nbody_written.toml", mid), bm = run_json("figure_eight.toml", mid);
  BOOST_TEST(json_string(wm.out, "step_path") == "separable-sparse-newton");
  BOOST_TEST(max_diff(json_array(wm.out, "q_final"), json_array(bm.out, "q_final")) <= 1e-13);
  // the written FPU chain against the built-in chain (walls, alpha = 0.25, beta = 1), at
  // 8 and 1000 particles, the initial state an expression in i for both
  for (const char* n : {"8", "1000"}) {
    const std::vector<std::string> sets = {"--set", std::string("system.params.n=") + n,
                                           "--set", "integrator.t_end=20.0",
                                           "--set", "initial.q=\"0.3*sin(pi*i/(n + 1)) + 0.1*cos(2*i)\"",
                                           "--set", "initial.p=\"0.05*i/n\""};
    std::vector<std::string> chain = sets;
    for (const char* k : {"system.params.alpha=0.25", "system.params.beta=1.0", "integrator.map=explicit-euler",
                          "integrator.composition=stormer-verlet", "integrator.step=0.05"}) {
      chain.push_back("--set");
      chain.push_back(k);
    }
    const Output cw = run_json("fpu_chain_written.toml", sets), cb = run_json("chain.toml", chain);
    BOOST_TEST_CONTEXT("n = " << n << "\n" << cw.err << cb.err) {
      BOOST_TEST(cw.status == 0);
      BOOST_TEST(cb.status == 0);
      BOOST_TEST(json_array(cw.out, "q_final").size() == std::stoul(n));
      BOOST_TEST(json_string(cw.out, "structure") == "separable");
      BOOST_TEST(max_diff(json_array(cw.out, "q_final"), json_array(cb.out, "q_final")) <= 1e-13);
      BOOST_TEST(max_diff(json_array(cw.out, "p_final"), json_array(cb.out, "p_final")) <= 1e-13);
      BOOST_TEST(std::fabs(json_number(cw.out, "energy_initial") - json_number(cb.out, "energy_initial")) <= 1e-14);
    }
  }
  // the structure of each shipped written scene on R^n, and of a charged particle written
  // with its magnetic term (linear in v)
  // and how each is differentiated: the small texts by programs of their gradient and
  // Hessian, the chain (sums as blocks) by a program of its gradient
  const Output pw = run_json("pendulum_written.toml");
  BOOST_TEST(json_string(pw.out, "structure") == "separable");
  BOOST_TEST(json_string(pw.out, "derivatives") == "program");
  const Output dw = run_json("double_pendulum_written.toml", {"--set", "integrator.t_end=1.0"});
  BOOST_TEST(json_string(dw.out, "structure") == "mechanical");
  BOOST_TEST(json_string(dw.out, "derivatives") == "program");
  BOOST_TEST(json_string(run_json("fpu_chain_written.toml", {"--set", "integrator.t_end=1.0"}).out, "derivatives") ==
             "gradient-program");
  const std::string charged = write_scene(
      "charged_written.toml",
      "[system]\ncoordinates = [\"x\", \"y\"]\nparams = { m = 1.0, B = 4.0 }\n"
      "lagrangian = \"m/2*(x_dot^2 + y_dot^2) + B/2*(x*y_dot - y*x_dot)\"\n"
      "[initial]\nq = [1.0, 0.0]\nv = [0.0, 0.5]\n[integrator]\nmap = \"explicit-euler\"\nstep = 0.01\nsteps = 10\n");
  const Output c = dvm({"run", charged, "--json"});
  BOOST_TEST(c.status == 0, c.err);
  BOOST_TEST(json_string(c.out, "structure") == "general");
  BOOST_TEST(json_string(c.out, "structure_source") == "expression");
  BOOST_TEST(json_string(c.out, "step_path") == "generic");
  BOOST_TEST(json_string(c.out, "derivatives") == "program");
  BOOST_TEST(json_string(b.out, "derivatives") == "");  // a built-in system: not reported
}

BOOST_AUTO_TEST_CASE(system_compile_runs_compiled_derivatives_or_is_refused) {
  // system.compile = true: the same run to the bit (Newton's midpoint step on the
  // pendulum and the double pendulum, Stormer-Verlet on the pendulum), reported as
  // "compiled" with the compiler's time
  const std::vector<std::vector<std::string>> runs = {
      {"pendulum_written.toml"},
      {"pendulum_written.toml", "--set", "integrator.map=\"explicit-euler\"", "--set",
       "integrator.composition=\"stormer-verlet\""},
      {"double_pendulum_written.toml", "--set", "integrator.t_end=1.0"}};
  for (const auto& r : runs) {
    std::vector<std::string> extra(r.begin() + 1, r.end()), compiled = extra;
    compiled.insert(compiled.end(), {"--set", "system.compile=true"});
    const Output a = run_json(r[0], extra), b = run_json(r[0], compiled);
    BOOST_TEST_CONTEXT(r[0] << " " << extra.size() << "\n" << a.err << b.err) {
      BOOST_TEST_REQUIRE(a.status == 0);
      BOOST_TEST_REQUIRE(b.status == 0);
      const Json ja = parse_json(a.out), jb = parse_json(b.out);
      BOOST_TEST((ja.contains("compiled") && ja.at("compiled") == false));
      BOOST_TEST((jb.contains("compiled") && jb.at("compiled") == true));
      BOOST_TEST(json_double(jb.at("compile_seconds")) > 0.0);
      BOOST_TEST(jb.value("derivatives", "") == "program");
      BOOST_TEST((jb.contains("interpreted") && jb.at("interpreted") == ""));  // nothing left interpreted
      BOOST_TEST(max_diff(json_array(a.out, "q_final"), json_array(b.out, "q_final")) == 0.0);
      BOOST_TEST(max_diff(json_array(a.out, "p_final"), json_array(b.out, "p_final")) == 0.0);
    }
  }
  // the sparse step of a separable text of 3 coordinates evaluates U's sparse Hessian
  // interpreted: the report says so (the force is compiled)
  {
    const std::string chain = write_scene(
        "chain3.toml", "[system]\ncoordinates = [\"a\", \"b\", \"c\"]\nlagrangian = \"(a_dot^2 + b_dot^2 + "
                       "c_dot^2)/2 - (b - a)^4/4 - (c - b)^4/4 - a^2/2 - c^2/2\"\n[initial]\nq = [0.5, 0.0, -0.2]\n"
                       "p = [0.0, 0.1, 0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 50\n");
    const Output a = dvm({"run", chain, "--json", "--quiet"}),
                 b = dvm({"run", chain, "--json", "--quiet", "--set", "system.compile=true"});
    BOOST_TEST_REQUIRE(a.status == 0, a.err);
    BOOST_TEST_REQUIRE(b.status == 0, b.err);
    BOOST_TEST(json_string(b.out, "step_path") == "separable-sparse-newton");
    BOOST_TEST(json_string(b.out, "interpreted").find("sparse Hessian of U") != std::string::npos, b.out);
    BOOST_TEST(max_diff(json_array(a.out, "q_final"), json_array(b.out, "q_final")) == 0.0);
    const Output c = dvm({"run", chain, "--set", "system.compile=true"});
    BOOST_TEST((c.err + c.out).find("(interpreted: the sparse Hessian of U") != std::string::npos, c.err + c.out);
  }
  // refused, exit 2, naming the key: a built-in system, a Lagrangian written on S^2, a
  // text with sums over arrays, a compiler that fails ($DVM_CC)
  const std::vector<std::pair<std::string, std::string>> refused = {
      {"pendulum.toml", "system.compile"},
      {"spherical_pendulum_written.toml", "on S^2 and SO(3)"},
      {"fpu_chain_written.toml", "blocks"}};
  for (const auto& [name, says] : refused) {
    const Output o = run_json(name, {"--set", "system.compile=true"});
    BOOST_TEST_CONTEXT(name << ": " << o.err) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.find("system.compile") != std::string::npos);
      BOOST_TEST(o.err.find(says) != std::string::npos);
    }
  }
  const Output f = [&] {
    const dvm_test::ScopedEnv cc("DVM_CC", "false");
    return run_json("pendulum_written.toml", {"--set", "system.compile=true"});
  }();
  BOOST_TEST(f.status == 2);
  BOOST_TEST(f.err.find("system.compile") != std::string::npos, f.err);
  BOOST_TEST(f.err.find("exited with status 1") != std::string::npos, f.err);
  const Output n = run_json("pendulum_written.toml", {"--set", "system.compile=1"});
  BOOST_TEST(n.status == 2);
  BOOST_TEST(n.err.find("system.compile") != std::string::npos, n.err);
}

BOOST_AUTO_TEST_CASE(written_arrays_are_refused_with_the_key_and_the_place) {
  const std::string base =
      "[system]\ncoordinates = [\"q[n]\"]\nparams = { n = 4 }\n"
      "lagrangian = \"sum(i, 1, n, q_dot[i]^2/2) - sum(i, 2, n, (q[i] - q[i-1])^2/2)\"\n"
      "[initial]\nq = \"0.1*i\"\np = \"0\"\n[integrator]\nmap = \"explicit-euler\"\nstep = 0.01\nsteps = 10\n";
  const std::string path = write_scene("array.toml", base);
  BOOST_TEST(dvm({"run", path}).status == 0);
  auto refused = [&](std::vector<std::string> sets, const std::string& says) {
    std::vector<std::string> args = {"run", path};
    for (const auto& s : sets) {
      args.push_back("--set");
      args.push_back(s);
    }
    const Output o = dvm(args);
    BOOST_TEST_CONTEXT(sets.front()) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.find(says) != std::string::npos, o.err);
    }
  };
  refused({"system.coordinates=[\"q[m]\"]"}, "in system.coordinates[0], the size of 'q': unknown name 'm'");
  refused({"system.coordinates=[\"q[0]\"]"}, "is not a coordinate array");
  refused({"system.coordinates=[\"q[n/3]\"]"}, "is not a coordinate array");
  refused({"system.ends={ q = \"walls\" }"}, "system.ends.q': expected \"none\", \"fixed\" or \"periodic\"");
  refused({"system.ends={ x = \"fixed\" }"}, "'x' is not an array of coordinates");
  refused({"system.lagrangian=\"q_dot[5]^2\""}, "index 5 of 'q_dot' is outside 1 to 4");
  refused({"system.lagrangian=\"q_dot^2\""}, "'q_dot' is an array of 4 entries");
  refused({"system.invariants={ I = \"q[1]*t\" }"}, "an energy, a Hamiltonian, an invariant or a Lagrangian on S^2 or SO(3) does not depend on it");
  refused({"system.params={ n = 4, k = [] }"}, "expected a non-empty list of numbers");
  refused({"initial.q=\"1/(i - 2)\""}, "the expression is not finite at i = 2");
  refused({"initial.q=\"x*i\""}, "in initial.q (an expression in i = 1 ... 4 and the parameters): unknown name 'x'");
  refused({"system.params={ n = 4, i = 1 }", "system.lagrangian=\"sum(j, 1, n, q_dot[j]^2/2)\""},
          "the parameter 'i' would hide the index i");
  // a dense implicit step beyond the size the run-time-sized steps take (the generic
  // path; the structured one of a separable text is sparse, below)
  refused({"system.params={ n = 5000 }", "integrator.map=midpoint", "integrator.use_structure=false"},
          "integrator.map: map = \"midpoint\" in the lagrangian form needs dense 5000 x 5000 matrices, beyond the 4096 "
          "coordinates");
  refused({"system.params={ n = 5000 }", "integrator.method=galerkin", "integrator.quadrature=lobatto"},
          "integrator.method: method = \"galerkin\" needs dense 5000 x 5000 matrices");
  // (and a text that is not separable: d below)
  // ... while the explicit steps, the implicit theta maps by Newton with the sparse
  // Hessian of the potential, and Gauss collocation (Galerkin Gauss on a separable text:
  // a fixed point on the stage forces, no matrix) take it
  // (the chain is free: its total momentum, asked for as an invariant, is conserved by
  // every variational step; stretched evenly, only its two end particles feel a force,
  // 0.1 inward, and move by about 0.1 t^2/2 = 5e-4 by t = 0.1: explicit Euler 10% more)
  // None of them, nor the refusal of a text that is not separable (d), forms an n x n
  // matrix: each runs in less address space than one of 5000 x 5000 doubles (190 MiB)
  const long dense = 190;
  const std::string total = "system.invariants={ P = \"sum(i, 1, n, p_q[i])\" }";
  const Output e = dvm_within(dense, {"run", path, "--json", "--set", "system.params={ n = 5000 }", "--set", total});
  BOOST_TEST(e.status == 0, e.err);
  const Output m = dvm_within(dense, {"run", path, "--json", "--set", "system.params={ n = 5000 }", "--set",
                                      "integrator.map=midpoint", "--set", total});
  BOOST_TEST(m.status == 0, m.err);
  BOOST_TEST(json_string(m.out, "step_path") == "separable-sparse-newton");
  const Output g = dvm_within(dense, {"run", path, "--json", "--set", "system.params={ n = 5000 }", "--set",
                                      "integrator.method=galerkin", "--set", total});
  BOOST_TEST(g.status == 0, g.err);
  BOOST_TEST(json_string(g.out, "step_path") == "gauss-collocation", g.out);
  const Output d = dvm_within(dense, {"run", path, "--set", "system.params={ n = 5000 }", "--set",
                                      "system.lagrangian=\"sum(i, 1, n, (1 + q[i]^2)*q_dot[i]^2)\""});
  BOOST_TEST(d.status == 2, d.err);
  BOOST_TEST(d.err.find("system: a Lagrangian that is not separable (its velocity Hessian, checked at the start) "
                        "needs dense") != std::string::npos,
             d.err);
  for (const Output* o : {&e, &m, &g}) {
    BOOST_TEST(invariant_error(o->out, "P") <= 1e-13);
    const std::vector<double> q = json_array(o->out, "q_final");
    BOOST_TEST_REQUIRE(q.size() == 5000u);
    BOOST_TEST(500.0 - q[4999] == 5e-4, boost::test_tools::tolerance(0.12));  // pulled in
    BOOST_TEST(q[0] - 0.1 == 5e-4, boost::test_tools::tolerance(0.12));
    BOOST_TEST(q[2500] == 250.1, boost::test_tools::tolerance(1e-14));  // no force inside
  }
  // the midpoint map and Galerkin (orders 2 and 2s) agree to their errors at h = 0.01
  BOOST_TEST(500.0 - json_array(m.out, "q_final")[4999] == 500.0 - json_array(g.out, "q_final")[4999],
             boost::test_tools::tolerance(1e-3));
}

BOOST_AUTO_TEST_CASE(written_definitions_match_the_built_in_system) {
  // Kepler written with definitions (r evaluated once), against the built-in
  const std::string kepler = write_scene(
      "kepler_defs.toml",
      "[system]\ncoordinates = [\"x\", \"y\"]\nparams = { mu = 1.0 }\n"
      "definitions = [\"r = sqrt(x^2 + y^2)\", \"T = (x_dot^2 + y_dot^2)/2\"]\n"
      "lagrangian = \"T + mu/r\"\nhamiltonian = \"(p_x^2 + p_y^2)/2 - mu/r\"\n"
      "[initial]\nq = [0.4, 0.0]\np = [0.0, 2.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.005\nt_end = 10.0\n");
  for (const char* form : {"lagrangian", "hamiltonian"}) {
    const std::vector<std::string> sets = {"--set", std::string("integrator.form=") + form, "--set",
                                           "integrator.t_end=10.0"};
    std::vector<std::string> args = {"run", kepler, "--json"};
    args.insert(args.end(), sets.begin(), sets.end());
    const Output w = dvm(args), b = run_json("kepler.toml", sets);
    BOOST_TEST_CONTEXT(form << "\n" << w.err) {
      BOOST_TEST(w.status == 0);
      BOOST_TEST(json_string(w.out, "structure") == "separable");
      BOOST_TEST(max_diff(json_array(w.out, "q_final"), json_array(b.out, "q_final")) <= 1e-12);
      BOOST_TEST(max_diff(json_array(w.out, "p_final"), json_array(b.out, "p_final")) <= 1e-12);
    }
  }
  // an error inside a definition is reported where it is written; a definition may not
  // use a later one, nor take a name already taken
  const Output e = dvm({"run", kepler, "--set", "system.definitions=[\"r = sqrt(x^2 + * y^2)\"]"});
  BOOST_TEST(e.status == 2);
  BOOST_TEST(e.err.find("in system.definitions[0] ('r'): expected a number, name or '(' after '+'") != std::string::npos,
             e.err);
  const Output f = dvm({"run", kepler, "--set", "system.definitions=[\"T = (x_dot^2 + y_dot^2)/2 + r\", \"r = 1\"]"});
  BOOST_TEST(f.status == 2);
  BOOST_TEST(f.err.find("unknown name 'r'") != std::string::npos, f.err);
  const Output g = dvm({"run", kepler, "--set", "system.definitions=[\"mu = 2\"]"});
  BOOST_TEST(g.status == 2);
  BOOST_TEST(g.err.find("the name 'mu' is used twice") != std::string::npos, g.err);
  const Output h = dvm({"run", kepler, "--set", "system.definitions=[\"just text\"]"});
  BOOST_TEST(h.status == 2);
  BOOST_TEST(h.err.find("expected a string \"name = expression\"") != std::string::npos, h.err);
}

// The spherical chain of many links (its banded step) from an initial state written per
// link: three expressions in the link index i (examples/scenes/rope.toml), the same run
// to the bit as the numbers they give, and refused where the form does not apply.
BOOST_AUTO_TEST_CASE(spherical_chain_of_many_links_from_expressions) {
  const std::vector<std::string> brief = {"--set", "integrator.t_end=0.05"};
  const Output e = run_json("rope.toml", brief);
  BOOST_TEST_REQUIRE(e.status == 0, e.err);
  BOOST_TEST(json_string(e.out, "step_path") == "sphere-chain-banded-newton");
  BOOST_TEST(json_array(e.out, "q_final").size() == 300u);
  BOOST_TEST(invariant_error(e.out, "vertical angular momentum") <= 1e-16);
  BOOST_TEST(json_number(e.out, "max_abs_energy_error") <= 1e-6);
  // the numbers of those expressions (the same libm functions), link by link
  const int n = 100;
  std::ostringstream q, v;
  q.precision(17);
  v.precision(17);
  for (int i = 1; i <= n; ++i) {
    const double a = 0.6 * std::sin(M_PI * i / (n + 1.0));
    q << (i > 1 ? ", " : "") << std::sin(a) << ", 0, " << -std::cos(a);
    v << (i > 1 ? ", " : "") << "0, " << 0.5 * i / n << ", 0";
  }
  const std::string numbers = write_scene(
      "rope_numbers.toml", "[system]\nbuiltin = \"spherical-chain\"\nparams = { n = 100, m = 0.01, l = 0.01, g = 9.81 }\n"
                           "[initial]\nq = [" + q.str() + "]\nv = [" + v.str() + "]\n[integrator]\nmap = \"sphere-exp\"\n"
                           "step = 5e-4\nt_end = 0.05\n");
  const Output b = dvm({"run", numbers, "--json"});
  BOOST_TEST_REQUIRE(b.status == 0, b.err);
  BOOST_TEST(max_diff(json_array(e.out, "q_final"), json_array(b.out, "q_final")) == 0.0);
  BOOST_TEST(max_diff(json_array(e.out, "p_final"), json_array(b.out, "p_final")) == 0.0);
  auto refused = [&](const std::string& set, const std::string& says) {
    const Output o = run_json("rope.toml", {"--set", set});
    BOOST_TEST_CONTEXT(set) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.find(says) != std::string::npos, o.err);
    }
  };
  refused("initial.q=\"0.1*i\"", "one expression in i is taken on R^n; on (S^2)^n give three");
  refused("initial.q=[\"1\", \"0\"]", "three of them (x, y and z of link i); got 2");
  refused("initial.q=[\"x\", \"0\", \"1\"]", "in initial.q (an expression in i = 1 ... 100 and the parameters): unknown name 'x'");
  refused("initial.q=[\"1\", \"0\", \"0.5\"]", "key 'initial.q' (link 1): not a unit vector");
  refused("initial.v=[\"0\", \"0\", \"1\"]", "(link 1): not tangent to S^2 at q");
  // and on R^n a list of expressions is not taken
  const Output r = run_json("chain.toml", {"--set", "initial.q=[\"1\", \"0\", \"0\"]"});
  BOOST_TEST(r.status == 2);
  BOOST_TEST(r.err.find("a list of expressions is taken on S^2 and (S^2)^n") != std::string::npos, r.err);
}

// [system] forces (discrete Lagrange-d'Alembert, solvers/dynamic_step.h) end to end: the
// shipped damped oscillator near its exact solution, its energy balance E - E_0 - W to
// round-off (a quadratic L, the midpoint map), the work in the JSON and as the CSV's last
// column, compositions and `dvm converge` with a force; every form, method and key the
// forced step does not take refused with exit 2, naming the keys.
BOOST_AUTO_TEST_CASE(forces_enter_by_lagrange_dalembert_or_are_refused_naming_the_keys) {
  const std::string csv = temp_dir() + "/damped.csv";
  const Output o = dvm({"run", scene("damped_oscillator.toml"), "--json", "--csv", csv});
  BOOST_TEST_REQUIRE(o.status == 0, o.err);
  const Json j = parse_json(o.out);
  BOOST_TEST(j.at("forced").get<bool>());
  const double W = j.at("work").get<double>(), E0 = j.at("energy_initial").get<double>(),
               E = j.at("energy_final").get<double>();
  BOOST_TEST(W < -0.4);  // the damping takes most of the energy 1/2 by t = 50
  BOOST_TEST(std::fabs(E - E0 - W) <= 1e-14);
  BOOST_TEST(std::fabs(j.at("energy_balance_final").get<double>()) <= 1e-14);
  BOOST_TEST(j.at("max_abs_energy_balance").get<double>() <= 1e-14);
  // x(50) = exp(-2.5) (cos(50 w) + 0.05/w sin(50 w)), w = sqrt(1 - 0.05^2)
  const double w = std::sqrt(1.0 - 0.0025), x = std::exp(-2.5) * (std::cos(50 * w) + 0.05 / w * std::sin(50 * w));
  const double x_final = json_array(o.out, "q_final").at(0);
  BOOST_TEST(std::fabs(x_final - x) <= 2e-5);
  BOOST_TEST(std::fabs(x_final - x) > 1e-7);  // second order at h = 0.01, not exact
  // the CSV: t, x, p_x, energy, work; its last row the report's
  std::ifstream in(csv);
  std::string header, line, last;
  std::getline(in, header);
  BOOST_TEST(header == "t,x,p_x,energy,work");
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  BOOST_TEST_REQUIRE(last.rfind(',') != std::string::npos);
  BOOST_TEST(std::stod(last.substr(last.rfind(',') + 1)) == W);
  // composed: order 4 brings it to the solution (1e-9 at h = 0.01)
  const Output c = dvm({"run", scene("damped_oscillator.toml"), "--json", "--no-output", "--set",
                        "integrator.composition=\"triple-jump:4\""});
  BOOST_TEST_REQUIRE(c.status == 0, c.err);
  BOOST_TEST(std::fabs(json_array(c.out, "q_final").at(0) - x) <= 1e-9);
  BOOST_TEST(std::fabs(json_number(c.out, "energy_balance_final")) <= 1e-14);
  // Galerkin: forces at its quadrature nodes (order 2s: Gauss s = 3 at h = 0.01 is exact
  // to 1e-12 here); the energy balance to round-off, since F.v = -c v^2 along the
  // collocation polynomial is integrated exactly by the Gauss rule
  const Output g = dvm({"run", scene("damped_oscillator.toml"), "--json", "--no-output", "--set",
                        "integrator.method=galerkin", "--set", "integrator.stages=3"});
  BOOST_TEST_REQUIRE(g.status == 0, g.err);
  BOOST_TEST(std::fabs(json_array(g.out, "q_final").at(0) - x) <= 1e-12);
  BOOST_TEST(std::fabs(json_number(g.out, "max_abs_energy_balance")) <= 1e-14);
  // the Hamiltonian form (H from L): the implicit midpoint rule of the forced equations,
  // as the lagrangian form's midpoint for this quadratic L
  const Output hm = dvm({"run", scene("damped_oscillator.toml"), "--json", "--no-output", "--set",
                         "integrator.form=hamiltonian"});
  BOOST_TEST_REQUIRE(hm.status == 0, hm.err);
  BOOST_TEST(std::fabs(json_array(hm.out, "q_final").at(0) - x_final) <= 1e-13);
  BOOST_TEST(std::fabs(json_number(hm.out, "work") - W) <= 1e-13);
  // the SODE and Newmark forms (a = M^{-1}(L_q + F), solvers/dynamic_sode_step.h): on this
  // linear system sode2 at the midpoint, sode1 at the midpoint and Newmark (1/2, 1/4) are
  // all the implicit midpoint rule of the forced equations, so the same states, work and
  // balance to round-off
  for (const char* form : {"sode2", "sode1", "newmark"}) {
    BOOST_TEST_CONTEXT(form) {
      const Output sf = dvm({"run", scene("damped_oscillator.toml"), "--json", "--no-output", "--set",
                             "integrator.form=" + std::string(form)});
      BOOST_TEST_REQUIRE(sf.status == 0, sf.err);
      const Json js = parse_json(sf.out);
      BOOST_TEST(js.at("form").get<std::string>() == form);
      BOOST_TEST(js.at("forced").get<bool>());
      BOOST_TEST(std::fabs(json_array(sf.out, "q_final").at(0) - x_final) <= 1e-13);
      BOOST_TEST(std::fabs(js.at("work").get<double>() - W) <= 1e-13);
      BOOST_TEST(js.at("max_abs_energy_balance").get<double>() <= 1e-14);
    }
  }
  // converge: against Galerkin Gauss s = 6 with the force
  const Output v = dvm({"converge", scene("damped_oscillator.toml"), "--t-end", "10", "--steps-list", "100,200,400",
                        "--json"});
  BOOST_TEST_REQUIRE(v.status == 0, v.err);
  BOOST_TEST(std::fabs(parse_json(v.out).at("fitted_order").get<double>() - 2.0) <= 0.05, v.out);
  // a drive in t: the driven Duffing oscillator runs, and `dvm converge` (its reference
  // Galerkin Gauss s = 6 with the force) measures the orders with a nonlinear force in
  // t: Galerkin Gauss s = 2 4, Lobatto s = 2 4, Gauss s = 3 6, kahan-li8 8
  const Output d = dvm({"run", scene("driven_duffing.toml"), "--json", "--no-output", "--set", "integrator.t_end=20"});
  BOOST_TEST(d.status == 0, d.err);
  BOOST_TEST(parse_json(d.out).at("forced").get<bool>());
  // sode2 at the midpoint is the forced midpoint step on a separable L, a nonlinear one
  // and a force in t included: the same states and work, alone and in the triple jump
  // (each stage's drive at its own time); 1e-12 relative (measured 4e-14)
  for (const char* composition : {"none", "triple-jump"}) {
    BOOST_TEST_CONTEXT(composition) {
      const std::string set = std::string("integrator.composition=\"") + composition + "\"";
      const Output lm = dvm({"run", scene("driven_duffing.toml"), "--json", "--no-output", "--set", "integrator.t_end=20",
                             "--set", set});
      const Output sm = dvm({"run", scene("driven_duffing.toml"), "--json", "--no-output", "--set", "integrator.t_end=20",
                             "--set", set, "--set", "integrator.form=sode2"});
      BOOST_TEST_REQUIRE((lm.status == 0 && sm.status == 0), lm.err + sm.err);
      for (const char* key : {"q_final", "p_final"})
        BOOST_TEST(max_diff(json_array(sm.out, key), json_array(lm.out, key)) <=
                   1e-12 * std::fmax(1.0, json_array(lm.out, key).at(0)));
      BOOST_TEST(std::fabs(json_number(sm.out, "work") - json_number(lm.out, "work")) <= 1e-12);
    }
  }
  struct Order {
    std::vector<std::string> sets;
    std::string steps;
    double order;
  };
  for (const Order& want : {Order{{"integrator.method=\"galerkin\"", "integrator.stages=2"}, "50,100,200,400", 4.0},
                         Order{{"integrator.method=\"galerkin\"", "integrator.quadrature=\"lobatto\"",
                                "integrator.stages=2"},
                               "50,100,200,400", 4.0},
                         Order{{"integrator.method=\"galerkin\"", "integrator.stages=3"}, "25,50,100,200", 6.0},
                         Order{{"integrator.composition=\"kahan-li8\""}, "10,20,40", 8.0},
                         Order{{"integrator.form=newmark"}, "50,100,200,400", 2.0},
                         Order{{"integrator.form=sode1", "integrator.map=theta", "integrator.theta=0.3"},
                               "800,1600,3200", 1.0},
                         Order{{"integrator.form=sode2", "integrator.lift=legendre", "integrator.map=theta",
                                "integrator.theta=0.3", "integrator.composition=\"triple-jump\""},
                               "50,100,200,400", 4.0}}) {
    const double fitted =
        fitted_order({"converge", scene("driven_duffing.toml"), "--t-end", "5", "--steps-list", want.steps}, want.sets);
    BOOST_TEST_MESSAGE("driven Duffing " << want.sets.back() << ": order " << fitted);
    BOOST_TEST(std::fabs(fitted - want.order) <= 0.05 * want.order, want.sets.back());
  }

  // refused: exit 2, the keys named, nothing on stdout and no file written
  const std::string refused_csv = temp_dir() + "/refused_force.csv";
  auto refused = [&](const std::string& scene_name, std::vector<std::string> sets, std::vector<std::string> says) {
    std::remove(refused_csv.c_str());
    std::vector<std::string> args = {"run", scene(scene_name), "--csv", refused_csv};
    for (const auto& s : sets) {
      args.push_back("--set");
      args.push_back(s);
    }
    const Output r = dvm(args);
    BOOST_TEST_CONTEXT(sets.front()) {
      BOOST_TEST(r.status == 2);
      BOOST_TEST(r.out.empty());
      BOOST_TEST(!file_exists(refused_csv));
      for (const std::string& s : says) BOOST_TEST(r.err.find(s) != std::string::npos, r.err);
    }
  };
  // the SODE forms with a force on a Lagrangian that is not separable (the forced double
  // pendulum): its acceleration's Jacobian would need third derivatives
  refused("double_pendulum_written.toml", {"system.forces={ a = \"-0.1*a_dot\" }", "integrator.form=sode1"},
          {"integrator.form", "system.lagrangian", "separable"});
  refused("damped_oscillator.toml", {"integrator.map=explicit-euler", "integrator.composition=blanes-moan4"},
          {"integrator.composition", "system.forces"});
  refused("damped_oscillator.toml", {"system.forces={ y = \"-x_dot\" }"},
          {"system.forces.y", "'y' is not a coordinate", "(x)"});
  refused("damped_oscillator.toml", {"system.forces={ x = \"-c*\" }"}, {"in system.forces.x", "after '*'"});
  refused("damped_oscillator.toml", {"system.forces={ x = \"-p_x\" }"}, {"in system.forces.x", "unknown name 'p_x'"});
  refused("damped_oscillator.toml", {"system.forces={ x = 1.0 }"}, {"system.forces.x", "expected a string"});
  refused("damped_oscillator.toml", {"system.forces=\"-c*x_dot\""}, {"system.forces", "expected a table"});
  refused("damped_oscillator.toml", {"system.forces={ x = \"log(x - 1)\" }"},
          {"system.forces", "not finite at the initial state"});
  refused("pendulum.toml", {"system.forces={ theta = \"0\" }"}, {"system.forces", "belongs to a written system"});
  refused("spherical_double_pendulum_written.toml", {"system.forces={ x1 = \"0\" }"},
          {"system.forces", "on R^n, S^2 and SO(3)"});
  refused("spherical_pendulum_written.toml", {"system.forces={ x = \"log(x - 1)\" }"},
          {"system.forces", "not finite at the initial state"});
}

// [system] controls: the shipped cart-pole pushed by a tabulated control; a table of
// constant values gives the run of the same constant written as an expression, alone
// and composed (every substep of a step reads u_k); --linearize adds the columns of
// B_k; bad tables and controls are refused with exit 2, naming the key, the file and
// the line, and writing nothing.
BOOST_AUTO_TEST_CASE(controls_from_a_table_or_an_expression) {
  const Output o = dvm({"run", scene("cart_pole.toml"), "--json", "--no-output"});
  BOOST_TEST_REQUIRE(o.status == 0, o.err);
  BOOST_TEST(parse_json(o.out).at("forced").get<bool>());
  BOOST_TEST(std::fabs(json_array(o.out, "q_final").at(0)) > 0.05);  // the cart moved
  // a table of 0.7 against u = "0.7": the same numbers, with and without a composition
  std::string table = "u\n";
  for (int k = 0; k < 200; ++k) table += "0.7\n";
  std::ofstream(temp_dir() + "/const_u.csv") << table;
  auto head = [](const std::string& control) {
    return "[system]\ncoordinates = [\"x\", \"th\"]\nparams = { m = 0.2, l = 0.5, g = 9.81 }\n"
           "lagrangian = \"0.6*x_dot^2 + m*l*cos(th)*x_dot*th_dot + 0.5*m*l^2*th_dot^2 + m*g*l*cos(th)\"\n"
           "controls = { u = " + control + " }\nforces = { x = \"u - 0.1*x_dot\" }\n"
           "[initial]\nq = [0.0, 0.3]\nv = [0.0, 0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 200\n";
  };
  const std::string tab = write_scene("u_table.toml", head("{ csv = \"const_u.csv\" }"));
  const std::string expr = write_scene("u_expr.toml", head("\"0.7\""));
  for (const std::string comp : {"none", "triple-jump:4"}) {
    const Output a = dvm({"run", tab, "--json", "--set", "integrator.composition=\"" + comp + "\""});
    const Output b = dvm({"run", expr, "--json", "--set", "integrator.composition=\"" + comp + "\""});
    BOOST_TEST_REQUIRE(a.status == 0, a.err);
    BOOST_TEST_REQUIRE(b.status == 0, b.err);
    BOOST_TEST(json_array(a.out, "q_final") == json_array(b.out, "q_final"), comp);
    BOOST_TEST(json_array(a.out, "p_final") == json_array(b.out, "p_final"), comp);
  }
  // --linearize: A_k then B_k (2n x 1), named in PATH.json
  const std::string npy = temp_dir() + "/cart_pole_A.npy";
  const Output l = dvm({"run", scene("cart_pole.toml"), "--no-output", "--quiet", "--linearize", npy});
  BOOST_TEST_REQUIRE(l.status == 0, l.err);
  const std::string names = slurp(npy + ".json");
  BOOST_TEST(names.find("\"A[3,3]\", \"B[0,0]\", \"B[1,0]\", \"B[2,0]\", \"B[3,0]\"]") != std::string::npos, names);

  const std::string csv = temp_dir() + "/refused_control.csv";
  auto refused = [&](const std::string& path, std::vector<std::string> sets, std::vector<std::string> says) {
    std::remove(csv.c_str());
    std::vector<std::string> args = {"run", path, "--csv", csv};
    for (const auto& x : sets) {
      args.push_back("--set");
      args.push_back(x);
    }
    const Output r = dvm(args);
    BOOST_TEST_CONTEXT((sets.empty() ? path : sets.front())) {
      BOOST_TEST(r.status == 2);
      BOOST_TEST(r.out.empty());
      BOOST_TEST(!file_exists(csv));
      for (const std::string& x : says) BOOST_TEST(r.err.find(x) != std::string::npos, r.err);
    }
  };
  refused(tab, {"integrator.steps=150"}, {"system.controls.u", "const_u.csv holds 200 values", "one per step: 150"});
  std::ofstream(temp_dir() + "/bad_u.csv") << "u\n0.1\n0.2\nabc\n";
  refused(tab, {"system.controls.u={ csv = \"bad_u.csv\" }"}, {"system.controls.u.csv", "bad_u.csv:4", "'abc'"});
  refused(tab, {"system.controls.u={ csv = \"no_such.csv\" }"}, {"system.controls.u.csv", "cannot read"});
  refused(tab, {"system.controls.u={ csv = \"/dev/zero\" }"}, {"system.controls.u.csv", "not a regular file"});
  refused(tab, {"system.controls.u={ file = \"x.csv\" }"}, {"system.controls.u", "{ csv = \"file\" }"});
  refused(tab, {"system.controls.u=\"sin(\""}, {"in system.controls.u", "u(t)"});
  refused(tab, {"system.controls.u=\"x\""}, {"in system.controls.u", "unknown name 'x'"});
  refused(tab, {"system.forces={ x = \"-0.1*x_dot\" }"}, {"system.controls.u", "no force reads"});
  refused(tab, {"system.controls.th=\"1\""}, {"system.controls.th", "'th' is used twice"});
  refused(scene("pendulum.toml"), {"system.controls={ u = \"1\" }"}, {"system.controls", "belongs to a written system"});
  refused(scene("spherical_pendulum_written.toml"), {"system.controls={ u = \"1\" }"},
          {"system.controls.u", "no force reads the control 'u'"});
  refused(scene("spherical_double_pendulum_written.toml"), {"system.controls={ u = \"1\" }"},
          {"system.controls", "on (S^2)^2 a written system is conservative"});
}

namespace {
// The rows of a .npy file dvm wrote (float64, two dimensions): shape and values.
struct NpyRows {
  long long rows = 0;
  int cols = 0;
  std::vector<double> values;
  double at(long long r, int c) const { return values.at(static_cast<std::size_t>(r * cols + c)); }
};
NpyRows read_npy(const std::string& path) {
  const std::string bytes = slurp(path);
  NpyRows out;
  BOOST_REQUIRE(bytes.size() > 10 && bytes.compare(0, 6, "\x93NUMPY") == 0);
  const std::size_t hlen = static_cast<unsigned char>(bytes[8]) + 256u * static_cast<unsigned char>(bytes[9]);
  const std::string header = bytes.substr(10, hlen);
  BOOST_REQUIRE(std::sscanf(header.c_str() + header.find("'shape': (") + 10, "%lld, %d", &out.rows, &out.cols) == 2);
  BOOST_REQUIRE(bytes.size() == 10 + hlen + static_cast<std::size_t>(out.rows * out.cols) * 8);
  out.values.resize(static_cast<std::size_t>(out.rows * out.cols));
  std::memcpy(out.values.data(), bytes.data() + 10 + hlen, out.values.size() * 8);
  return out;
}
}  // namespace

namespace {
// max |A^T J A - J| of row k of a --linearize file, A (m x m) in columns 1 .. m^2 row by
// row, J = [0 I; -I 0]
double symplectic_defect(const NpyRows& a, long long k, int m) {
  double d = 0.0;
  const int n = m / 2;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      // (A^T J A)(i, j) = sum_r A(r, i) (J A)(r, j)
      double s = 0.0;
      for (int r = 0; r < m; ++r) {
        const double JA = r < n ? a.at(k, 1 + m * (r + n) + j) : -a.at(k, 1 + m * (r - n) + j);
        s += a.at(k, 1 + m * r + i) * JA;
      }
      const double J = (i < n && j == i + n) ? 1.0 : (i >= n && j == i - n) ? -1.0 : 0.0;
      d = std::fmax(d, std::fabs(s - J));
    }
  return d;
}
// A built-in system's A_k (2n x 2n) against its written twin's, every row: each
// symplectic, and all of them the twin's to 1e-11.
void check_against_written_twin(const NpyRows& B, const NpyRows& W, long long rows, int n) {
  BOOST_TEST_REQUIRE(B.rows == rows);
  BOOST_TEST_REQUIRE(W.rows == rows);
  BOOST_TEST_REQUIRE(B.cols == 1 + 4 * n * n);
  BOOST_TEST_REQUIRE(W.cols == B.cols);
  double apart = 0.0;
  for (long long k = 0; k < B.rows; ++k) {
    BOOST_TEST(symplectic_defect(B, k, 2 * n) <= 1e-12);
    for (long long c = 0; c < B.cols; ++c) apart = std::fmax(apart, std::fabs(B.at(k, c) - W.at(k, c)));
  }
  BOOST_TEST(apart <= 1e-11, "built-in and written A_k apart by " << apart);
}
}  // namespace

// dvm run --linearize: the Jacobian of every step in a .npy file, row k = (t_k, A_k row
// by row). A_0 against central differences of one-step runs of dvm itself (relative
// 1e-7), for the written pendulum (symplectic: det A = 1 at every step) and the damped
// oscillator (a force: det A < 1); the double pendulum's A_k symplectic, A^T J A = J;
// compositions and Galerkin the same; the steps that give no derivative refused with
// exit 2 and nothing written.
BOOST_AUTO_TEST_CASE(linearize_writes_the_derivative_of_every_step) {
  const std::string dir = temp_dir();
  // (q1, p1) after one step of h from the scene's start moved by (dq, dp); `momentum`:
  // the scene's key of the initial momentum (initial.v where the mass is 1)
  auto one_step = [&](const std::string& name, const std::string& momentum, int n, double q0, double p0, int j,
                      double e) {
    std::vector<double> q(static_cast<std::size_t>(n), 0.0), p(q);
    q[0] = q0;
    p[0] = p0;
    (j < n ? q : p)[static_cast<std::size_t>(j % n)] += e;
    auto list = [](const std::vector<double>& x) {
      std::ostringstream s;
      s.precision(17);
      s << "[";
      for (std::size_t i = 0; i < x.size(); ++i) s << (i ? ", " : "") << x[i];
      return s.str() + "]";
    };
    const Output o = dvm({"run", scene(name), "--json", "--no-output", "--set", "integrator.t_end=0.01", "--set",
                          "initial.q=" + list(q), "--set", momentum + "=" + list(p)});
    BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
    std::vector<double> y = json_array(o.out, "q_final"), pf = json_array(o.out, "p_final");
    y.insert(y.end(), pf.begin(), pf.end());
    return y;
  };
  struct Case {
    std::string scene, momentum;
    double q0, p0;
    bool forced;
  };
  for (const Case& c : {Case{"pendulum_written.toml", "initial.p", 2.0, 0.3, false},
                        Case{"damped_oscillator.toml", "initial.v", 1.0, 0.2, true}}) {
    BOOST_TEST_CONTEXT(c.scene) {
      const std::string path = dir + "/A_" + c.scene + ".npy";
      const Output o = dvm({"run", scene(c.scene), "--json", "--no-output", "--linearize", path, "--set",
                            "integrator.t_end=0.05", "--set", "initial.q=[" + std::to_string(c.q0) + "]", "--set",
                            c.momentum + "=[" + std::to_string(c.p0) + "]"});
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      BOOST_TEST(json_string(o.out, "step_path") == "generic");
      const NpyRows A = read_npy(path);
      BOOST_TEST(A.rows == 5);
      BOOST_TEST(A.cols == 5);
      const Json names = parse_json(slurp(path + ".json"));
      BOOST_TEST(names.at("columns").at(0).get<std::string>() == "t");
      BOOST_TEST(names.at("columns").at(2).get<std::string>() == "A[0,1]");
      for (long long k = 0; k < A.rows; ++k) {
        BOOST_TEST(A.at(k, 0) == 0.01 * static_cast<double>(k), boost::test_tools::tolerance(1e-15));
        const double det = A.at(k, 1) * A.at(k, 4) - A.at(k, 2) * A.at(k, 3);
        if (c.forced)
          BOOST_TEST(det < 1.0 - 1e-4);  // the damping contracts areas
        else
          BOOST_TEST(std::fabs(det - 1.0) <= 1e-13);
      }
      const double eps = 1e-5;
      for (int j = 0; j < 2; ++j) {
        const std::vector<double> a = one_step(c.scene, c.momentum, 1, c.q0, c.p0, j, eps),
                                  b = one_step(c.scene, c.momentum, 1, c.q0, c.p0, j, -eps);
        for (int i = 0; i < 2; ++i) {
          const double central = (a[static_cast<std::size_t>(i)] - b[static_cast<std::size_t>(i)]) / (2 * eps);
          BOOST_TEST(std::fabs(A.at(0, 1 + 2 * i + j) - central) <= 1e-7 * std::fmax(1.0, std::fabs(central)),
                     "A(" << i << "," << j << ") = " << A.at(0, 1 + 2 * i + j) << ", central differences " << central);
        }
      }
    }
  }
  // two coordinates: A_k^T J A_k = J at every step
  const std::string path2 = dir + "/A2.npy";
  const Output d = dvm({"run", scene("double_pendulum_written.toml"), "--no-output", "--quiet", "--linearize", path2,
                        "--set", "integrator.t_end=0.03"});
  BOOST_TEST_REQUIRE(d.status == 0, d.err);
  const NpyRows A2 = read_npy(path2);
  BOOST_TEST(A2.rows == 3);
  BOOST_TEST(A2.cols == 17);
  for (long long k = 0; k < A2.rows; ++k) BOOST_TEST(symplectic_defect(A2, k, 4) <= 1e-12);

  auto refused = [&](const std::string& scene_name, std::vector<std::string> extra, const std::string& says) {
    const std::string path = dir + "/refused.npy";
    std::vector<std::string> args = {"run", scene(scene_name), "--linearize", path};
    args.insert(args.end(), extra.begin(), extra.end());
    if (std::find(extra.begin(), extra.end(), "--npy") == extra.end()) args.push_back("--no-output");
    const Output r = dvm(args);
    BOOST_TEST_CONTEXT(scene_name << (extra.empty() ? "" : " " + extra.back())) {
      BOOST_TEST(r.status == 2);
      BOOST_TEST(r.err.find(says) != std::string::npos, r.err);
      BOOST_TEST(!file_exists(path));
    }
  };
  // the built-in systems of fixed size on R^n: the run-time-sized steps, which give their
  // derivative, on the built-in (make_run_time_sized_run); below
  refused("chain.toml",
          {"--set", "system.params.n=5000", "--set", "initial.q=\"0.1*sin(i)\"", "--set", "initial.p=\"0\""},
          "key 'system.params.n': got 5000");
  refused("pendulum.toml", {"--set", "integrator.solver=\"tiny\""}, "integrator.solver");
  refused("pendulum_written_map.toml", {}, "integrator.map");
  refused("pendulum_written.toml",
          {"--set", "integrator.map=\"explicit-euler\"", "--set", "integrator.composition=\"blanes-moan4\""},
          "integrator.composition");
  // a composition: the chain rule over its substeps (ComposedStep::derivative); the
  // triple jump of the midpoint on the pendulum, written or built in, is symplectic,
  // det A_k = 1
  for (const std::string& name : {"pendulum_written.toml", "pendulum.toml"}) {
    const std::string path = dir + "/composed.npy";
    const Output o = dvm({"run", scene(name), "--no-output", "--quiet", "--linearize", path, "--set",
                          "integrator.composition=\"triple-jump:4\"", "--set", "integrator.t_end=0.1"});
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const NpyRows a = read_npy(path);
    BOOST_TEST(a.rows == 10);
    BOOST_TEST(a.cols == 5);
    for (long long k = 0; k < a.rows; ++k)
      BOOST_TEST(std::fabs(a.at(k, 1) * a.at(k, 4) - a.at(k, 2) * a.at(k, 3) - 1.0) <= 1e-12, name);
  }
  // Galerkin (DynamicGalerkinStep::derivative), Gauss on a separable text (the Newton
  // step, not collocation, which gives none) and Lobatto: symplectic, det A_k = 1; with
  // the damping force, det A_k < 1
  for (const std::string& quadrature : {"gauss", "lobatto"}) {
    const std::string path = dir + "/galerkin.npy";
    const Output o = dvm({"run", scene("pendulum_written.toml"), "--no-output", "--quiet", "--linearize", path, "--set",
                          "integrator.method=\"galerkin\"", "--set", "integrator.quadrature=\"" + quadrature + "\"",
                          "--set", "integrator.stages=3", "--set", "integrator.t_end=0.1"});
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const NpyRows a = read_npy(path);
    BOOST_TEST(a.rows == 10);
    for (long long k = 0; k < a.rows; ++k)
      BOOST_TEST(std::fabs(a.at(k, 1) * a.at(k, 4) - a.at(k, 2) * a.at(k, 3) - 1.0) <= 1e-12, quadrature);
    const Output f = dvm({"run", scene("damped_oscillator.toml"), "--no-output", "--quiet", "--linearize", path,
                          "--set", "integrator.method=\"galerkin\"", "--set",
                          "integrator.quadrature=\"" + quadrature + "\"", "--set", "integrator.t_end=0.1"});
    BOOST_TEST_REQUIRE(f.status == 0, f.err);
    const NpyRows b = read_npy(path);
    for (long long k = 0; k < b.rows; ++k)
      BOOST_TEST(b.at(k, 1) * b.at(k, 4) - b.at(k, 2) * b.at(k, 3) < 1.0 - 1e-4, quadrature);
  }
  refused("pendulum_written.toml", {"--set", "integrator.form=sode1"}, "not integrator.form = \"sode1\"");
  // on S^2 and SO(3): the lagrangian form of the maps, forced or not, and their
  // hamiltonian form unforced; not constrained, not Galerkin, not on (S^2)^K
  // (linearize_on_the_sphere_and_the_rotation_group below)
  refused("spherical_pendulum_written.toml", {"--set", "integrator.form=sode1"}, "integrator.form");
  refused("spherical_pendulum_written.toml",
          {"--set", "integrator.form=hamiltonian", "--set", "system.forces={ x = \"-0.1*x_dot\" }"},
          "not integrator.form = \"hamiltonian\" with forces on S^2");
  refused("spherical-pendulum-galerkin.toml", {}, "not integrator.method = \"galerkin\" on S^2");
  refused("bead_on_rotating_hoop.toml", {}, "system.constraints");
  refused("spherical_double_pendulum_written.toml", {}, "not on (S^2)^K");
  refused("spherical-chain.toml", {}, "not on (S^2)^K");
  refused("pendulum_written.toml", {"--npy", dir + "/refused.npy"}, "the same file as the run's rows");
}

// dvm run --linearize on the built-in systems of fixed size on R^n: the run-time-sized
// steps on the built-in system erased (make_run_time_sized_run). The run is the one without
// --linearize (the same equation, solved to its tolerance); A_0 of the pendulum against
// central differences of one-step runs (relative 1e-7), det A_k = 1; the double
// pendulum's A_k symplectic and the same as its written twin's, whose Lagrangian is the
// same text (the built-in's closed-form derivatives against the text's program), in the
// lagrangian and the hamiltonian form; n bodies and Kepler by Gauss Galerkin symplectic
// (compositions: the test above).
BOOST_AUTO_TEST_CASE(linearize_the_built_in_systems_on_rn) {
  const std::string dir = temp_dir();
  // the pendulum: one step of h = 0.01 from (q0 + dq, p0 + dp)
  const double q0 = 2.0, p0 = 0.3;
  auto state_after = [&](double dq, double dp, const std::string& t_end) {
    std::ostringstream q, p;
    q.precision(17);
    p.precision(17);
    q << "initial.q=[" << q0 + dq << "]";
    p << "initial.p=[" << p0 + dp << "]";
    const Output o = dvm({"run", scene("pendulum.toml"), "--json", "--no-output", "--set", "integrator.t_end=" + t_end,
                          "--set", q.str(), "--set", p.str()});
    BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
    std::vector<double> y = json_array(o.out, "q_final"), pf = json_array(o.out, "p_final");
    y.insert(y.end(), pf.begin(), pf.end());
    return y;
  };
  const std::string path = dir + "/pendulum.npy";
  const Output o = dvm({"run", scene("pendulum.toml"), "--json", "--no-output", "--linearize", path, "--set",
                        "integrator.t_end=0.5", "--set", "initial.p=[0.3]"});
  BOOST_TEST_REQUIRE(o.status == 0, o.err);
  BOOST_TEST(json_string(o.out, "step_path") == "generic");
  // the same run as without --linearize (the fixed-size step of the same equation)
  const std::vector<double> pendulum_end = state_after(0.0, 0.0, "0.5");
  const std::vector<double> pendulum_q = json_array(o.out, "q_final"), pendulum_p = json_array(o.out, "p_final");
  BOOST_TEST(std::fabs(pendulum_q[0] - pendulum_end[0]) <= 1e-12);
  BOOST_TEST(std::fabs(pendulum_p[0] - pendulum_end[1]) <= 1e-12);
  const NpyRows A = read_npy(path);
  BOOST_TEST(A.rows == 50);
  BOOST_TEST(A.cols == 5);
  for (long long k = 0; k < A.rows; ++k)
    BOOST_TEST(std::fabs(A.at(k, 1) * A.at(k, 4) - A.at(k, 2) * A.at(k, 3) - 1.0) <= 1e-13);
  const double eps = 1e-5;
  for (int j = 0; j < 2; ++j) {
    const std::vector<double> a = state_after(j == 0 ? eps : 0.0, j == 1 ? eps : 0.0, "0.01"),
                              b = state_after(j == 0 ? -eps : 0.0, j == 1 ? -eps : 0.0, "0.01");
    for (int i = 0; i < 2; ++i) {
      const double central = (a[static_cast<std::size_t>(i)] - b[static_cast<std::size_t>(i)]) / (2 * eps);
      BOOST_TEST(std::fabs(A.at(0, 1 + 2 * i + j) - central) <= 1e-7 * std::fmax(1.0, std::fabs(central)),
                 "A(" << i << "," << j << ") = " << A.at(0, 1 + 2 * i + j) << ", central differences " << central);
    }
  }
  // the double pendulum against its written twin, step by step
  const std::string builtin = dir + "/double.npy", written = dir + "/double_written.npy";
  for (const auto& [scene_name, file] : {std::pair<std::string, std::string>{"double_pendulum.toml", builtin},
                                         {"double_pendulum_written.toml", written}}) {
    const Output d = dvm({"run", scene(scene_name), "--no-output", "--quiet", "--linearize", file, "--set",
                          "integrator.t_end=0.2"});
    BOOST_TEST_REQUIRE(d.status == 0, d.err);
  }
  check_against_written_twin(read_npy(builtin), read_npy(written), 20, 2);
  // the hamiltonian form (DynamicHamiltonianThetaStep of H from L by the Legendre
  // transform), for the cotangent lift of the midpoint map, its triple jump and the
  // midpoint map on T*Q (lift none): A_k equal to the written twin's, and the run the one
  // without --linearize to the last digit, which from two coordinates on takes the same
  // run-time-sized step (kernels_rn.h; the regression record of test_cli_combinations
  // holds where the fixed-size step ended)
  for (const auto& [composition, lift] : {std::pair<std::string, std::string>{"none", "cotangent"},
                                          {"triple-jump", "cotangent"},
                                          {"none", "none"}}) {
    const std::vector<std::string> sets = {"--set", "integrator.form=\"hamiltonian\"", "--set",
                                           "integrator.lift=\"" + lift + "\"", "--set",
                                           "integrator.composition=\"" + composition + "\"", "--set",
                                           "integrator.t_end=0.2"};
    std::vector<std::string> lin_builtin = sets, lin_written = sets;
    lin_builtin.insert(lin_builtin.end(), {"--linearize", builtin});
    lin_written.insert(lin_written.end(), {"--linearize", written});
    const Output plain = run_json("double_pendulum.toml", sets), b = run_json("double_pendulum.toml", lin_builtin),
                 w = run_json("double_pendulum_written.toml", lin_written);
    BOOST_TEST_CONTEXT(composition << ", lift " << lift << "\n" << plain.err << b.err << w.err) {
      BOOST_TEST_REQUIRE(plain.status == 0);
      BOOST_TEST_REQUIRE(b.status == 0);
      BOOST_TEST_REQUIRE(w.status == 0);
      BOOST_TEST(json_array(b.out, "q_final") == json_array(plain.out, "q_final"), boost::test_tools::per_element());
      BOOST_TEST(json_array(b.out, "p_final") == json_array(plain.out, "p_final"), boost::test_tools::per_element());
      check_against_written_twin(read_npy(builtin), read_npy(written), 20, 2);
    }
  }
  // n bodies (make_dynamic_run, the generic theta step where the structured one would
  // run): three bodies in the plane z = 0, A_k symplectic (18 x 18)
  {
    const std::string nb = dir + "/nbody.npy";
    const Output b = dvm({"run", scene("outer_solar_system.toml"), "--no-output", "--quiet", "--linearize", nb, "--set",
                          "system.masses=[1.0, 0.5, 0.25]", "--set", "system.params.G=1.0", "--set",
                          "initial.q=[0, 0, 0, 1, 0, 0, 0, 2, 0]", "--set", "initial.v=[0, 0, 0, 0, 1, 0, -0.7, 0, 0]",
                          "--set", "integrator.step=0.01", "--set", "integrator.t_end=0.05"});
    BOOST_TEST_REQUIRE(b.status == 0, b.err);
    const NpyRows N = read_npy(nb);
    BOOST_TEST_REQUIRE(N.rows == 5);
    BOOST_TEST_REQUIRE(N.cols == 1 + 18 * 18);
    for (long long r = 0; r < N.rows; ++r) BOOST_TEST(symplectic_defect(N, r, 18) <= 1e-12);
  }
  // Kepler by Gauss Galerkin (not collocation, which gives no derivative), the pendulum
  // by the triple jump of the midpoint map: symplectic
  {
    const std::string k = dir + "/kepler.npy";
    const Output g = dvm({"run", scene("kepler.toml"), "--no-output", "--quiet", "--linearize", k, "--set",
                          "integrator.method=\"galerkin\"", "--set", "integrator.stages=2", "--set",
                          "integrator.t_end=0.05"});
    BOOST_TEST_REQUIRE(g.status == 0, g.err);
    const NpyRows K = read_npy(k);
    BOOST_TEST_REQUIRE(K.rows == 10);
    for (long long r = 0; r < K.rows; ++r) BOOST_TEST(symplectic_defect(K, r, 4) <= 1e-12);
  }
  // the chain (ChainDynamic: its Hessian dense in the generic theta step): the run where
  // its tridiagonal step ends, and A_k equal to its written twin's, midpoint and the
  // triple jump of it; free ends (total momentum conserved) too
  for (const char* composition : {"none", "triple-jump"}) {
    const std::vector<std::string> sets = {"--set", "system.params.n=6",
                                           "--set", "integrator.map=\"midpoint\"",
                                           "--set", "integrator.step=0.02",
                                           "--set", "integrator.t_end=0.2",
                                           "--set", std::string("integrator.composition=\"") + composition + "\"",
                                           "--set", "initial.q=\"0.3*sin(pi*i/(n + 1)) + 0.1*cos(2*i)\"",
                                           "--set", "initial.p=\"0.05*i/n\""};
    std::vector<std::string> chain = sets;
    for (const char* k : {"system.params.alpha=0.25", "system.params.beta=1.0"}) chain.insert(chain.end(), {"--set", k});
    const std::string cb = dir + "/chain.npy", cw = dir + "/chain_written.npy";
    const Output plain = run_json("chain.toml", chain);
    std::vector<std::string> lin = chain, lin_written = sets;
    lin.insert(lin.end(), {"--linearize", cb});
    lin_written.insert(lin_written.end(), {"--linearize", cw});
    const Output b = run_json("chain.toml", lin), w = run_json("fpu_chain_written.toml", lin_written);
    BOOST_TEST_CONTEXT(composition << "\n" << plain.err << b.err << w.err) {
      BOOST_TEST_REQUIRE(plain.status == 0);
      BOOST_TEST_REQUIRE(b.status == 0);
      BOOST_TEST_REQUIRE(w.status == 0);
      BOOST_TEST(json_string(b.out, "step_path") == "generic");
      BOOST_TEST(max_diff(json_array(b.out, "q_final"), json_array(plain.out, "q_final")) <= 1e-13);
      BOOST_TEST(max_diff(json_array(b.out, "p_final"), json_array(plain.out, "p_final")) <= 1e-13);
      check_against_written_twin(read_npy(cb), read_npy(cw), 10, 6);
    }
  }
  {
    const std::string free_ends = dir + "/chain_free.npy";
    const Output f = run_json("chain.toml", {"--set", "system.params.fixed=0", "--set", "integrator.t_end=0.1",
                                             "--set", "initial.p=[0.1, 0, 0, 0, 0, 0, 0, -0.3]", "--linearize",
                                             free_ends});
    BOOST_TEST_REQUIRE(f.status == 0, f.err);
    const NpyRows F = read_npy(free_ends);
    BOOST_TEST_REQUIRE(F.rows == 10);
    for (long long r = 0; r < F.rows; ++r) BOOST_TEST(symplectic_defect(F, r, 16) <= 1e-12);
    // total momentum (-0.2) kept by the generic step
    const std::vector<double> pf = json_array(f.out, "p_final");
    double total = 0.0;
    for (double x : pf) total += x;
    BOOST_TEST(std::fabs(total + 0.2) <= 1e-13);
  }
}

// dvm run --linearize on S^2 and SO(3): A_k in the canonical coordinates around q_k and
// q_{k+1} (the chart of S^2 centred at c, chart(c, eta) = (c + e1 eta1 + e2 eta2)/|...|,
// e1 from the coordinate axis least aligned with c made orthogonal to c, e2 = c x e1; the
// momentum's components pi_j = <p, d chart/d eta_j>), as `dvm run --help` states them.
// A_0 of the written spherical pendulum against central differences of one-step runs of
// dvm, moved in those coordinates (1e-7); A_k symplectic at every step on S^2 and for the
// heavy top composed; the lagrangian and the hamiltonian form; the satellite's control
// adds B_k (6 x 1).
BOOST_AUTO_TEST_CASE(linearize_on_the_sphere_and_the_rotation_group) {
  const std::string dir = temp_dir();
  using V3 = std::array<double, 3>;
  auto dot = [](const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
  // the chart's basis at c, as documented
  auto basis = [&](const V3& c) {
    int k = 0;
    for (int i = 1; i < 3; ++i)
      if (std::fabs(c[i]) < std::fabs(c[k])) k = i;
    V3 a{0, 0, 0};
    a[k] = 1.0;
    V3 e1;
    for (int i = 0; i < 3; ++i) e1[i] = a[i] - dot(c, a) * c[i];
    const double n = std::sqrt(dot(e1, e1));
    for (double& x : e1) x /= n;
    const V3 e2{c[1] * e1[2] - c[2] * e1[1], c[2] * e1[0] - c[0] * e1[2], c[0] * e1[1] - c[1] * e1[0]};
    return std::array<V3, 2>{e1, e2};
  };
  auto list = [](const V3& x) {
    std::ostringstream s;
    s.precision(17);
    s << "[" << x[0] << ", " << x[1] << ", " << x[2] << "]";
    return s.str();
  };
  const double h = 0.005;
  // the lagrangian form (ManifoldStep::derivatives) and the hamiltonian form
  // (ManifoldHamiltonianStep::derivatives)
  for (const std::string form : {"lagrangian", "hamiltonian"}) {
    BOOST_TEST_CONTEXT("integrator.form = " << form) {
      const std::string form_set = "integrator.form=\"" + form + "\"";
      auto step_from = [&](const V3& q, const V3& p) {
        const Output o = dvm({"run", scene("spherical_pendulum_written.toml"), "--json", "--no-output", "--set",
                              "integrator.t_end=0.005", "--set", "initial.q=" + list(q), "--set",
                              "initial.v=" + list(p), "--set", form_set});
        BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
        const std::vector<double> qf = json_array(o.out, "q_final"), pf = json_array(o.out, "p_final");
        BOOST_REQUIRE(qf.size() == 3 && pf.size() == 3);
        return std::pair<V3, V3>{V3{qf[0], qf[1], qf[2]}, V3{pf[0], pf[1], pf[2]}};
      };
      // the scene's start: q = (0.6, 0, -0.8), v = (0, 1.5, 0); m = l = 1, so p = v (the
      // runs below give the momentum as initial.v)
      const V3 c{0.6, 0.0, -0.8}, p0{0.0, 1.5, 0.0};
      const auto E0 = basis(c);
      const double pi0[2] = {dot(p0, E0[0]), dot(p0, E0[1])};
      const auto [c1, p1] = step_from(c, p0);
      const auto E1 = basis(c1);
      const std::string path = dir + "/sphere.npy";
      const Output o = dvm({"run", scene("spherical_pendulum_written.toml"), "--no-output", "--quiet", "--linearize",
                            path, "--set", "integrator.t_end=0.05", "--set", form_set});
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      const NpyRows A = read_npy(path);
      BOOST_TEST(A.rows == 10);
      BOOST_TEST(A.cols == 17);
      const double eps = 1e-5;
      double worst = 0.0;
      for (int j = 0; j < 4; ++j) {
        double col[2][4];
        for (int s = 0; s < 2; ++s) {
          double eta[2] = {0, 0}, pi[2] = {pi0[0], pi0[1]};
          (j < 2 ? eta : pi)[j % 2] += s == 0 ? eps : -eps;
          // the state (q, p) with canonical coordinates (eta, pi) around c
          V3 y;
          for (int i = 0; i < 3; ++i) y[i] = c[i] + E0[0][i] * eta[0] + E0[1][i] * eta[1];
          const double ny = std::sqrt(dot(y, y));
          V3 q;
          for (int i = 0; i < 3; ++i) q[i] = y[i] / ny;
          // p tangent at q with p . e_j = |y| pi_j (d chart/d eta_j = (e_j - (q . e_j) q)/|y|):
          // p = |y| (pi_1 f1 + pi_2 f2) with (f1, f2) dual to (e1, e2) in the tangent plane
          V3 t1, t2;
          for (int i = 0; i < 3; ++i) {
            t1[i] = E0[0][i] - dot(q, E0[0]) * q[i];
            t2[i] = E0[1][i] - dot(q, E0[1]) * q[i];
          }
          const double g11 = dot(t1, E0[0]), g12 = dot(t2, E0[0]), g21 = dot(t1, E0[1]), g22 = dot(t2, E0[1]);
          const double det = g11 * g22 - g12 * g21;
          const double a1 = (g22 * pi[0] - g12 * pi[1]) / det * ny, a2 = (-g21 * pi[0] + g11 * pi[1]) / det * ny;
          V3 p;
          for (int i = 0; i < 3; ++i) p[i] = a1 * t1[i] + a2 * t2[i];
          const auto [qe, pe] = step_from(q, p);
          // its end in the canonical coordinates around c1: zeta = E1^T (qe/(c1.qe) - c1),
          // pi_j = (c1 . qe) pe . e_j(c1)
          const double d = dot(c1, qe);
          for (int k = 0; k < 2; ++k) {
            double z = 0.0;
            for (int i = 0; i < 3; ++i) z += E1[k][i] * (qe[i] / d - c1[i]);
            col[s][k] = z;
            col[s][2 + k] = d * dot(pe, E1[k]);
          }
        }
        for (int i = 0; i < 4; ++i) {
          const double central = (col[0][i] - col[1][i]) / (2 * eps);
          worst = std::fmax(worst, std::fabs(A.at(0, 1 + 4 * i + j) - central) / std::fmax(1.0, std::fabs(central)));
        }
      }
      BOOST_TEST_MESSAGE("S^2: A_0 against central differences of dvm's steps " << worst);
      BOOST_TEST(worst <= 1e-7);
      // A_k^T J A_k = J at every step (n = 2, and n = 3 for the heavy top composed)
      for (long long k = 0; k < A.rows; ++k) {
        BOOST_TEST(A.at(k, 0) == h * static_cast<double>(k), boost::test_tools::tolerance(1e-15));
        BOOST_TEST(symplectic_defect(A, k, 4) <= 1e-12);
      }
      const std::string top = dir + "/top.npy";
      const Output t = dvm({"run", scene("heavy-top.toml"), "--no-output", "--quiet", "--linearize", top, "--set",
                            "integrator.composition=\"suzuki5\"", "--set", "integrator.t_end=0.02", "--set", form_set});
      BOOST_TEST_REQUIRE(t.status == 0, t.err);
      const NpyRows T = read_npy(top);
      BOOST_TEST(T.rows == 4);
      BOOST_TEST(T.cols == 37);
      for (long long k = 0; k < T.rows; ++k) BOOST_TEST(symplectic_defect(T, k, 6) <= 1e-11);
    }
  }
  // a control torque: B_k after A_k, named B[i,0]; the torque u about e3 moves the
  // third angular momentum component by h u: dpi_3/du = h at every step
  const std::string sat = dir + "/satellite.npy";
  const Output u = dvm({"run", scene("satellite_control.toml"), "--no-output", "--quiet", "--linearize", sat});
  BOOST_TEST_REQUIRE(u.status == 0, u.err);
  const NpyRows S = read_npy(sat);
  BOOST_TEST(S.rows == 200);
  BOOST_TEST(S.cols == 43);
  const Json names = parse_json(slurp(sat + ".json"));
  BOOST_TEST(names.at("columns").at(37).get<std::string>() == "B[0,0]");
  for (long long k = 0; k < S.rows; ++k) BOOST_TEST(S.at(k, 37 + 5) == 0.01, boost::test_tools::tolerance(1e-12));
}
