// Bad input, numerical faults and atomic output of the dvm program.
//
// Every bad input exits with status 2 before anything is written, with a message
// naming where the value came from (file:line:column and key, or the option), the
// value and what was expected. Numerical faults exit with 3 and say at which step and
// time, with the residual or the defect. A run that does not complete never leaves a
// file at the output's final path (its rows go to PATH.partial). Run with
// --log_level=message to see every case's message (the table of the closing note).
#define BOOST_TEST_MODULE cli_hardening
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace cli_test;

const char* kHarmonic =
    "[system]\nbuiltin = \"harmonic\"\nparams = { omega = 2.0 }\n"
    "[initial]\nq = [1.0]\np = [0.0]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 100\n";

const char* kSphere =
    "[system]\nbuiltin = \"spherical-pendulum\"\n[initial]\nq = [0.6, 0.0, -0.8]\nv = [0.0, 1.0, 0.0]\n"
    "[integrator]\nmap = \"sphere-exp\"\nstep = 0.01\nsteps = 10\n";

const char* kWritten =
    "[system]\ncoordinates = [\"x\"]\nparams = { k = 1.0 }\nlagrangian = \"x_dot^2/2 - k*x^2/2\"\n"
    "[initial]\nq = [1.0]\np = [0.0]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 10\n";

struct Case {
  std::string name;               // what is wrong
  std::vector<std::string> args;  // the dvm command line
  int status;                     // expected exit status
  std::vector<std::string> expect;  // fragments the message must contain
};

void check(const Case& c, const std::string& must_not_exist = "") {
  const Output o = dvm(c.args);
  BOOST_TEST_MESSAGE("| " << c.name << " | " << o.status << " | "
                          << o.err.substr(0, o.err.find('\n')) << " |");
  BOOST_TEST_CONTEXT(c.name << " -> " << o.err) {
    BOOST_TEST(o.status == c.status);
    for (const auto& e : c.expect) BOOST_TEST(o.err.find(e) != std::string::npos, "missing '" << e << "'");
    if (!must_not_exist.empty()) BOOST_TEST(!file_exists(must_not_exist));
  }
}

std::size_t count_lines(const std::string& path) {
  std::ifstream f(path);
  std::string line;
  std::size_t n = 0;
  while (std::getline(f, line)) ++n;
  return n;
}

}  // namespace

BOOST_AUTO_TEST_CASE(non_finite_numbers_are_refused_wherever_they_stand) {
  const std::string h = write_scene("h.toml", kHarmonic), w = write_scene("w.toml", kWritten);
  const std::string csv = temp_dir() + "/nonfinite.csv";
  const std::vector<Case> cases = {
      {"integrator.step = inf", {"run", h, "--csv", csv, "--set", "integrator.step=inf"}, 2,
       {"integrator.step", "inf", "finite"}},
      {"system.params.omega = nan", {"run", h, "--csv", csv, "--set", "system.params.omega=nan"}, 2,
       {"system.params.omega", "nan", "finite"}},
      {"initial.p = [-inf]", {"run", h, "--csv", csv, "--set", "initial.p=[-inf]"}, 2, {"initial.p[0]", "finite"}},
      {"integrator.tolerance = nan", {"run", h, "--csv", csv, "--set", "integrator.tolerance=nan"}, 2,
       {"integrator.tolerance", "finite"}},
      {"written params = { k = inf }", {"run", w, "--csv", csv, "--set", "system.params.k=inf"}, 2,
       {"system.params.k", "finite"}},
      {"a literal 1e999 (inf) in a written Lagrangian",
       {"run", w, "--csv", csv, "--set", "system.lagrangian=\"x_dot^2/2 - 1e999*x^2\""}, 2,
       {"system.lagrangian", "finite"}},
      {"--t-end nan", {"converge", h, "--t-end", "nan"}, 2, {"--t-end", "nan", "finite"}},
      {"--steps-list 10,inf", {"converge", h, "--steps-list", "10,inf"}, 2, {"--steps-list", "inf", "finite"}},
      {"check-map --theta nan", {"check-map", "theta", "--theta", "nan"}, 2, {"--theta", "finite"}},
      {"check-map --tolerance inf", {"check-map", "theta", "--tolerance", "inf"}, 2, {"--tolerance", "finite"}},
  };
  for (const auto& c : cases) check(c, csv);
  const std::string te = write_scene(
      "tnan.toml", "[system]\nbuiltin = \"harmonic\"\n[initial]\nq = [1.0]\np = [0.0]\n[integrator]\nmap = \"midpoint\"\n"
                   "step = 0.1\nt_end = nan\n");
  check({"t_end = nan in the file", {"run", te, "--csv", csv}, 2, {"tnan.toml:9:9", "integrator.t_end", "nan", "finite"}},
        csv);
}

BOOST_AUTO_TEST_CASE(sizes_points_and_steps_are_checked_against_the_system) {
  const std::string h = write_scene("h.toml", kHarmonic), s = write_scene("s.toml", kSphere);
  const std::string csv = temp_dir() + "/sizes.csv";
  const std::vector<Case> cases = {
      {"q of length 2 for a 1-dof system", {"run", h, "--csv", csv, "--set", "initial.q=[1.0, 2.0]"}, 2,
       {"initial.q", "got 2 numbers, expected 1"}},
      {"p of length 0", {"run", h, "--csv", csv, "--set", "initial.p=[]"}, 2, {"initial.p", "expected 1"}},
      {"q not a unit vector on S^2", {"run", s, "--csv", csv, "--set", "initial.q=[0.6, 0.0, -0.81]"}, 2,
       {"initial.q", "not a unit vector", "1e-12"}},
      {"v not tangent to S^2", {"run", s, "--csv", csv, "--set", "initial.v=[0.1, 1.0, 0.0]"}, 2,
       {"initial.v", "not tangent"}},
      {"step = 0", {"run", h, "--csv", csv, "--set", "integrator.step=0.0"}, 2, {"integrator.step", "positive"}},
      {"step = -0.01", {"run", h, "--csv", csv, "--set", "integrator.step=-0.01"}, 2,
       {"integrator.step", "-0.01", "positive"}},
      // the scene gives steps, so t_end on top is refused before its sign is read (a
      // negative t_end alone is the file case below)
      {"t_end given next to steps", {"run", h, "--csv", csv, "--set", "integrator.t_end=-1.0"}, 2,
       {"integrator.t_end", "not both"}},
      {"steps = -5", {"run", h, "--csv", csv, "--set", "integrator.steps=-5"}, 2, {"integrator.steps", "-5", ">= 1"}},
      {"steps = 2^63 - 1 (beyond 2^53)", {"run", h, "--csv", csv, "--set", "integrator.steps=9223372036854775807"}, 2,
       {"integrator.steps", "9223372036854775807", "2^53"}},
      {"steps = 10^20 (not a 64-bit integer)", {"run", h, "--csv", csv, "--set", "integrator.steps=100000000000000000000"},
       2, {"integrator.steps", "TOML"}},
      {"steps x step overflows the time", {"run", h, "--csv", csv, "--set", "integrator.step=1e300", "--set",
                                           "integrator.steps=10000000000"},
       2, {"integrator.steps", "overflow"}},
      {"--steps-list 0,10", {"converge", h, "--steps-list", "0,10"}, 2, {"--steps-list", "'0'"}},
  };
  for (const auto& c : cases) check(c, csv);
  // t_end read from the file: the message gives file, line and column
  const std::string bad = write_scene(
      "tend.toml", "[system]\nbuiltin = \"harmonic\"\n[initial]\nq = [1.0]\np = [0.0]\n[integrator]\nmap = \"midpoint\"\n"
                   "step = 0.1\nt_end = -2.5\n");
  check({"t_end = -2.5 in the file", {"run", bad, "--csv", csv}, 2, {"tend.toml:9:9", "integrator.t_end", "-2.5",
                                                                       "positive"}},
        csv);
}

BOOST_AUTO_TEST_CASE(output_that_cannot_be_written_or_would_not_fit_is_refused_before_the_run) {
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::string dir = temp_dir();
  const std::vector<Case> cases = {
      {"--csv in a missing directory", {"run", h, "--csv", "/nonexistent/dir/out.csv"}, 2,
       {"--csv", "/nonexistent/dir", "does not exist"}},
      {"--csv naming a directory", {"run", h, "--csv", dir}, 2, {"--csv", "directory"}},
      {"--npy where no file can be created (/proc)", {"run", h, "--npy", "/proc/dvm-out.npy"}, 2,
       {"--npy", "/proc/dvm-out.npy"}},
      {"--csv inside a file (/dev/null/x.csv)", {"run", h, "--csv", "/dev/null/x.csv"}, 2, {"--csv", "/dev/null"}},
      {"output.csv = \"\"", {"run", h, "--set", "output.csv=\"\""}, 2, {"output.csv", "empty"}},
      // 2^53 steps, a row each: 4 columns x 25 bytes x 9.0e15 rows = 900.7 PB
      {"a CSV larger than the free space", {"run", h, "--csv", dir + "/huge.csv", "--set", "integrator.steps=9007199254740992"},
       2, {"--csv", "would write up to 900.7 PB", "free"}},
      {"an .npy larger than the free space",
       {"run", h, "--npy", dir + "/huge.npy", "--set", "integrator.steps=9007199254740992"}, 2,
       {"--npy", "would write up to", "free"}},
      {"the same from the scene's [output]",
       {"run", h, "--set", "output.csv=\"" + dir + "/huge2.csv\"", "--set", "integrator.steps=4000000000000000"}, 2,
       {"key 'output.csv'", "would write up to", "free"}},
      {"--csv without a value", {"run", h, "--csv"}, 2, {"--csv needs a value"}},
      {"an unknown option", {"run", h, "--cvs", "x.csv"}, 2, {"unknown option --cvs"}},
  };
  for (const auto& c : cases) check(c);
  BOOST_TEST(!file_exists(dir + "/huge.csv"));
  BOOST_TEST(!file_exists(dir + "/huge.npy"));
  BOOST_TEST(!file_exists(dir + "/huge2.csv"));
  // a directory without write permission (root may write anywhere: only as a user)
  if (geteuid() != 0) {
    const std::string ro = dir + "/readonly";
    mkdir(ro.c_str(), 0555);
    check({"--csv in a read-only directory", {"run", h, "--csv", ro + "/out.csv"}, 2, {"--csv", "cannot create"}},
          ro + "/out.csv");
  }
}

BOOST_AUTO_TEST_CASE(unknown_keys_and_malformed_text_are_refused) {
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::vector<Case> cases = {
      {"unknown key in [integrator]", {"run", h, "--set", "integrator.stpe=0.1"}, 2,
       {"integrator.stpe", "unknown key", "takes:"}},
      {"unknown section", {"run", h, "--set", "intgrator.step=0.1"}, 2, {"intgrator", "unknown section"}},
      {"unknown key in [output]", {"run", h, "--set", "output.evry=2"}, 2, {"output.evry", "unknown key"}},
      {"a number where a string belongs", {"run", h, "--set", "integrator.map=3"}, 2,
       {"integrator.map", "got 3", "expected a string"}},
      {"--set without a section", {"run", h, "--set", "step=0.1"}, 2, {"--set", "section"}},
  };
  for (const auto& c : cases) check(c);
  // found by fuzzing (tests/fuzz/corpus/scene): toml++ 3.3 reaches an internal
  // assertion or undefined behaviour on these; each is refused cleanly, with the
  // position (run under `make sanitize` these would abort without the fix)
  struct Text {
    std::string name, text, expect;
  };
  const std::vector<Text> texts = {
      {"NUL after '['", std::string("[\0", 2), "t0.toml:1:2: a NUL character"},
      {"'[+' table header", "[+", "t1.toml:1:2"},
      {"array closed by '}'", "q=[}", "t2.toml:1:"},
      {"U+FD7F after a value", "v=0\"\xef\xb5\xbf", "t3.toml:1:5: the character U+FD7F"},
      {"U+FCBF at the start", "\xef\xb2\xbf", "t4.toml:1:1: the character U+FCBF"},
      {"U+00E9 at a line start", "a = 1\n\xc3\xa9 = 2\n", "t5.toml:2:1: the character U+00E9"},
  };
  int i = 0;
  for (const auto& t : texts) {
    const std::string path = temp_dir() + "/t" + std::to_string(i++) + ".toml";
    std::ofstream(path, std::ios::binary) << t.text;
    check({t.name, {"run", path}, 2, {t.expect}});
  }
  // non-ASCII text the parser reads safely stays allowed in comments and strings
  const std::string ok = write_scene("ok.toml", std::string("# Barbero-Lin\xe2\x80\x93" "an \xe2\x88\x82L/\xe2\x88\x82v\n") +
                                                    kHarmonic);
  BOOST_TEST(dvm({"run", ok, "--quiet"}).status == 0);
}

BOOST_AUTO_TEST_CASE(a_failed_run_leaves_no_file_at_the_final_path) {
  // The pendulum with h = 4: Newton's method fails on some step (see test_cli).
  const std::string dir = temp_dir();
  const std::string csv = dir + "/atomic.csv", npy = dir + "/atomic.npy";
  std::remove((csv + ".partial").c_str());
  const Output o = dvm({"run", scene("pendulum.toml"), "--json", "--csv", csv, "--npy", npy, "--set",
                        "integrator.step=4.0", "--set", "integrator.t_end=400.0", "--set", "output.every=1"});
  BOOST_TEST_MESSAGE("| pendulum, h = 4 (Newton fails) | " << o.status << " | " << o.err.substr(0, o.err.find('\n'))
                                                           << " |");
  BOOST_TEST(o.status == 3, o.err);
  BOOST_TEST(!file_exists(csv));
  BOOST_TEST(!file_exists(npy));
  const double steps = json_number(o.out, "steps");
  BOOST_TEST(steps >= 1);
  // the rows of the completed steps are kept under a name that says so
  BOOST_TEST(count_lines(csv + ".partial") == 2 + static_cast<std::size_t>(steps));  // header, t = 0, each step
  BOOST_TEST(file_exists(npy + ".partial"));
  BOOST_TEST(o.err.find(csv + ".partial") != std::string::npos, o.err);
  // an older complete file at the final path is kept as it was
  std::ofstream(csv) << "old\n";
  const Output again = dvm({"run", scene("pendulum.toml"), "--quiet", "--csv", csv, "--set", "integrator.step=4.0",
                            "--set", "integrator.t_end=400.0"});
  BOOST_TEST(again.status == 3);
  BOOST_TEST(slurp(csv) == "old\n");
  // no temporary is left behind, and a complete run replaces the file
  const Output good = dvm({"run", scene("pendulum.toml"), "--quiet", "--csv", csv, "--npy", npy});
  BOOST_TEST(good.status == 0, good.err);
  BOOST_TEST(count_lines(csv) > 2);
  int hidden = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().rfind(".atomic.", 0) == 0) ++hidden;
  BOOST_TEST(hidden == 0);
  // the .npy header carries the final row count
  const std::string bytes = slurp(npy);
  BOOST_TEST(bytes.size() > 128u);
  BOOST_TEST(bytes.find("'shape': (") != std::string::npos);
  // permissions as a plain file (not mkstemp's 0600)
  struct stat st {};
  BOOST_TEST(stat(csv.c_str(), &st) == 0);
  BOOST_TEST((st.st_mode & 0044) != 0u);
}

BOOST_AUTO_TEST_CASE(numerical_faults_stop_the_run_with_step_time_and_residual) {
  const std::string dir = temp_dir();
  // symplectic Euler (explicit-euler map) on the harmonic oscillator with h omega = 3,
  // beyond its stability bound 2: |q| grows by about 7 per step until it overflows
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::string csv = dir + "/blowup.csv";
  const Output b = dvm({"run", h, "--json", "--csv", csv, "--set", "integrator.map=explicit-euler", "--set",
                        "integrator.step=1.5", "--set", "integrator.steps=100000"});
  BOOST_TEST_MESSAGE("| harmonic, explicit-euler, h omega = 3 (overflow) | " << b.status << " | "
                                                                               << b.err.substr(0, b.err.find('\n'))
                                                                               << " |");
  BOOST_TEST(b.status == 3, b.err);
  BOOST_TEST(b.err.find("step ") != std::string::npos);
  BOOST_TEST(b.err.find("t = ") != std::string::npos);
  BOOST_TEST((b.err.find("non-finite") != std::string::npos || b.err.find("not finite") != std::string::npos), b.err);
  BOOST_TEST(b.out.find("\"status\": \"failed\"") != std::string::npos);
  // the growth factor of symplectic Euler at h omega = 3 is the larger root of
  // l^2 - (2 - 9) l + 1 = 0, |l| = 6.85: overflow (1e308) after about 365 steps
  const double steps = json_number(b.out, "steps");
  BOOST_TEST(steps > 300);
  BOOST_TEST(steps < 400);
  BOOST_TEST(!file_exists(csv));
  // q_final is the last finite state
  BOOST_TEST(b.out.find("\"q_final\": [null") == std::string::npos, b.out);

  // a map outside its domain: sphere-exp, R_d(x, v) = (exp_x(-v/2), exp_x(v/2)), with
  // |v| = h |x_dot| = 2 pi sends both points half way round, to antipodal points, where
  // its inverse is undefined (the first Newton iterate starts from v = h x_dot)
  const std::string s = write_scene("s.toml", kSphere);
  const Output m = dvm({"run", s, "--set", "integrator.step=6.283185307179586"});
  BOOST_TEST_MESSAGE("| S^2, sphere-exp, h |v| = 2 pi (map outside its domain) | "
                     << m.status << " | " << m.err.substr(0, m.err.find('\n')) << " |");
  BOOST_TEST(m.status == 3, m.err);
  BOOST_TEST(m.err.find("step 0 (t = 0") != std::string::npos, m.err);
  BOOST_TEST(m.err.find("antipodal") != std::string::npos, m.err);

  // a degenerate Legendre transform along the way: L = x^2 x_dot^2/2 has the velocity
  // Hessian x^2, singular at x = 0, which the exact motion x^2 = 1 - 2t reaches at
  // t = 1/2 (with infinite speed): the run must stop there with exit 3 (measured: the
  // step from t = 0.5 fails to converge, the Newton matrix becoming singular)
  const std::string d = write_scene(
      "degenerate.toml",
      "[system]\ncoordinates = [\"x\"]\nlagrangian = \"x^2*x_dot^2/2\"\n[initial]\nq = [1.0]\nv = [-1.0]\n"
      "[integrator]\nmap = \"midpoint\"\nstep = 0.001\nsteps = 2000\n");
  const Output g = dvm({"run", d, "--json"});
  BOOST_TEST_MESSAGE("| L = x^2 x_dot^2/2 through x = 0 (degenerate Legendre) | "
                     << g.status << " | " << g.err.substr(0, g.err.find('\n')) << " |");
  BOOST_TEST(g.status == 3, g.err);
  const double t_fail = json_number(g.out, "time");
  BOOST_TEST(t_fail <= 0.5 + 1e-9);
  BOOST_TEST(t_fail > 0.45);
  // the message names the cause, on stderr and in the JSON failure: d2L/dv2 = x^2 has
  // fallen from 1 to below 1e-2 of that (measured: 2e-17 at the last state, t = 0.5)
  BOOST_TEST(g.err.find("close to degenerate") != std::string::npos, g.err);
  BOOST_TEST(g.out.find("close to degenerate") != std::string::npos, g.out);
  // and only then: a regular Lagrangian whose solve is cut short is not called degenerate
  const Output r = dvm({"run", d, "--set", "system.lagrangian=\"x_dot^2/2 + cos(x)\"", "--set",
                           "integrator.max_iterations=1"});
  BOOST_TEST(r.status == 3, r.err);
  BOOST_TEST(r.err.find("d2L/dv2") != std::string::npos, r.err);
  BOOST_TEST(r.err.find("degenerate") == std::string::npos, r.err);
}

BOOST_AUTO_TEST_CASE(a_boundary_value_problem_without_a_solution_exits_3) {
  // The midpoint discretization of the harmonic oscillator (omega = 1) turns each
  // step by the angle theta with tan(theta/2) = h/2, so every discrete solution is
  // q_k = A cos(k theta) + B sin(k theta). With h = 2 tan(pi/(2K)) the K steps turn
  // by exactly pi: every solution ends at q_K = -q_0 (a conjugate point), and the
  // problem q_0 = 1, q_K = 0.5 has none. Ceres then stops at the least-squares point
  // with a discrete Euler-Lagrange residual of order one, which must be reported as a
  // numerical failure (exit 3), with the completed nodes in PATH.partial only; the
  // consistent problem q_K = -1 (a one-parameter family) solves.
  const int K = 10;
  const double h = 2.0 * std::tan(std::acos(-1.0) / (2.0 * K));
  std::ostringstream scene;
  scene.precision(17);
  scene << "[system]\nbuiltin = \"harmonic\"\nparams = { omega = 1.0 }\n[initial]\nq = [1.0]\n"
        << "[problem]\nkind = \"boundary-value\"\nq_final = [0.5]\nsteps = " << K << "\n"
        << "[integrator]\nmap = \"midpoint\"\nstep = " << h << "\n";
  const std::string b = write_scene("conjugate.toml", scene.str());
  const std::string csv = temp_dir() + "/conjugate.csv";
  const Output f = dvm({"run", b, "--csv", csv});
  BOOST_TEST_MESSAGE("| boundary-value problem at a conjugate point (no solution) | " << f.status << " | "
                     << f.err.substr(0, f.err.find('\n')) << " |");
  BOOST_TEST(f.status == 3, f.err);
  BOOST_TEST(f.err.find("did not converge") != std::string::npos, f.err);
  BOOST_TEST(f.err.find("residual") != std::string::npos, f.err);
  BOOST_TEST(!file_exists(csv));
  BOOST_TEST(file_exists(csv + ".partial"));
  const Output j = dvm({"run", b, "--json"});
  BOOST_TEST(j.status == 3, j.err);
  BOOST_TEST(j.out.find("\"status\": \"failed\"") != std::string::npos, j.out);
  BOOST_TEST(json_number(j.out, "max_del_residual") > 1e-3);

  const Output ok = dvm({"run", b, "--csv", csv, "--set", "problem.q_final=[-1.0]"});
  BOOST_TEST(ok.status == 0, ok.err);
  BOOST_TEST(file_exists(csv));
}

BOOST_AUTO_TEST_CASE(every_run_path_reports_a_failed_step_with_exit_3) {
  // the same non-convergence (one Newton iteration cannot converge) through each
  // runner: forms, composition, chain, written Lagrangian, n-body, manifolds (the
  // boundary-value problem has its own test)
  const std::string dir = temp_dir();
  struct Path {
    std::string name, scene;
    std::vector<std::string> sets;
  };
  const std::vector<Path> paths = {
      {"R^n, lagrangian form", scene("pendulum.toml"), {}},
      {"hamiltonian form", scene("pendulum.toml"), {"integrator.form=hamiltonian"}},
      {"sode2 form", scene("pendulum.toml"), {"integrator.form=sode2"}},
      {"composition", scene("kepler.toml"), {"integrator.composition=triple-jump"}},
      {"chain", scene("chain.toml"), {}},
      {"written Lagrangian", scene("pendulum_written.toml"), {}},
      {"n-body", scene("figure_eight.toml"), {}},
      {"S^2", scene("spherical-pendulum.toml"), {}},
      {"SO(3)", scene("heavy-top.toml"), {}},
  };
  for (const auto& p : paths) {
    const std::string csv = dir + "/path.csv";
    std::vector<std::string> args = {"run", p.scene, "--quiet", "--csv", csv, "--set", "integrator.max_iterations=1"};
    for (const auto& s : p.sets) args.push_back("--set"), args.push_back(s);
    const Output o = dvm(args);
    BOOST_TEST_MESSAGE("| " << p.name << ", max_iterations = 1 | " << o.status << " | "
                            << o.err.substr(0, o.err.find('\n')) << " |");
    BOOST_TEST_CONTEXT(p.name << " -> " << o.err) {
      BOOST_TEST(o.status == 3);
      BOOST_TEST(o.err.find("residual") != std::string::npos);
      BOOST_TEST(!file_exists(csv));
    }
    std::remove((csv + ".partial").c_str());
  }
}

BOOST_AUTO_TEST_CASE(a_run_stopped_by_sigint_or_sigterm_removes_its_temporary) {
  // A long run (10^8 pendulum steps, every 10^6-th written) is stopped once its hidden
  // temporary exists: the process still ends by the signal, and neither the final
  // path nor a temporary is left.
  const std::string dir = temp_dir();
  for (int sig : {SIGTERM, SIGINT}) {
    const std::string csv = dir + "/killed.csv";
    const pid_t pid = fork();
    BOOST_REQUIRE(pid >= 0);
    if (pid == 0) {
      const int null = ::open("/dev/null", O_WRONLY);
      dup2(null, 1);
      dup2(null, 2);
      const std::string sc = scene("pendulum.toml");
      execl(DVM_BINARY, DVM_BINARY, "run", sc.c_str(), "--quiet", "--csv", csv.c_str(), "--set",
            "integrator.t_end=1e6", "--set", "output.every=1000000", static_cast<char*>(nullptr));
      _exit(127);
    }
    auto hidden = [&] {
      int n = 0;
      for (const auto& e : std::filesystem::directory_iterator(dir))
        if (e.path().filename().string().rfind(".killed.csv.", 0) == 0) ++n;
      return n;
    };
    int status = 0;
    bool exited = false;
    for (int i = 0; i < 6000 && hidden() == 0 && !exited; ++i) {  // up to 60 s (a sanitized build starts slowly)
      exited = waitpid(pid, &status, WNOHANG) == pid;
      usleep(10000);
    }
    BOOST_REQUIRE_MESSAGE(!exited, "the run ended before it could be stopped");
    BOOST_REQUIRE_EQUAL(hidden(), 1);
    BOOST_REQUIRE(kill(pid, sig) == 0);
    BOOST_REQUIRE(waitpid(pid, &status, 0) == pid);
    BOOST_TEST_CONTEXT("signal " << sig) {
      BOOST_TEST(WIFSIGNALED(status));
      BOOST_TEST((WIFSIGNALED(status) ? WTERMSIG(status) : 0) == sig);
      BOOST_TEST(hidden() == 0);
      BOOST_TEST(!file_exists(csv));
      BOOST_TEST(!file_exists(csv + ".partial"));
    }
  }
}

BOOST_AUTO_TEST_CASE(the_harness_removes_its_temporary_folder) {
  std::string path;
  {
    const TempDir t;
    path = t.path();
    std::filesystem::create_directory(path + "/sub");
    std::ofstream(path + "/sub/file.txt") << "x\n";
    BOOST_TEST(std::filesystem::is_directory(path));
  }
  BOOST_TEST(!std::filesystem::exists(path));
}
