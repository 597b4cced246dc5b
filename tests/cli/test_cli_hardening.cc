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
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
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
      {"output.csv = \"\"", {"run", h, "--set", "output.csv=\"\""}, 2, {"output.csv", "empty", "--no-output"}},
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
}

// Whether this process lacks the power to write anywhere (root has it): the case below
// is reported as skipped under root.
boost::test_tools::assertion_result not_root(boost::unit_test::test_unit_id) {
  boost::test_tools::assertion_result r(geteuid() != 0);
  r.message() << "run as root, who may write into a directory without write permission";
  return r;
}

BOOST_AUTO_TEST_CASE(output_into_a_read_only_directory_is_refused_before_the_run,
                     *boost::unit_test::precondition(not_root)) {
  const std::string h = write_scene("h-ro.toml", kHarmonic), ro = temp_dir() + "/readonly";
  mkdir(ro.c_str(), 0555);
  check({"--csv in a read-only directory", {"run", h, "--csv", ro + "/out.csv"}, 2, {"--csv", "cannot create"}},
        ro + "/out.csv");
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
  BOOST_TEST(!file_exists(npy + ".json"));  // the column names go with the rows
  BOOST_TEST(file_exists(npy + ".json.partial"));
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
  BOOST_TEST(slurp(npy + ".json").find("\"columns\": [\"t\", \"q0\", \"p0\", \"energy\"]") != std::string::npos,
             slurp(npy + ".json"));
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
  const Json jb = parse_json(b.out);
  BOOST_TEST(jb.value("status", "") == "failed");
  // the growth factor of symplectic Euler at h omega = 3 is the larger root of
  // l^2 - (2 - 9) l + 1 = 0, |l| = 6.85: overflow (1e308) after about 365 steps
  const double steps = json_double(jb.at("steps"));
  BOOST_TEST(steps > 300);
  BOOST_TEST(steps < 400);
  BOOST_TEST(!file_exists(csv));
  // q_final is the last finite state: numbers, none null (how the program writes a NaN)
  BOOST_TEST(jb.at("q_final").is_array());
  for (const Json& x : jb.at("q_final")) BOOST_TEST(x.is_number(), b.out);

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
  const Json failure = parse_json(g.out).at("failure");  // the failed step
  const double t_fail = json_double(failure.at("time"));
  BOOST_TEST(t_fail <= 0.5 + 1e-9);
  BOOST_TEST(t_fail > 0.45);
  // the message names the cause, on stderr and in the JSON failure: d2L/dv2 = x^2 has
  // fallen from 1 to below 1e-2 of that (measured: 2e-17 at the last state, t = 0.5)
  BOOST_TEST(g.err.find("close to degenerate") != std::string::npos, g.err);
  BOOST_TEST(failure.value("message", "").find("close to degenerate") != std::string::npos, g.out);
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
  BOOST_TEST(parse_json(j.out).value("status", "") == "failed", j.out);
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

// A long run (10^8 pendulum steps, every 10^6-th written to dir/killed.csv) in a child
// process whose output goes nowhere.
pid_t start_long_run(const std::string& dir) {
  const std::string csv = dir + "/killed.csv";
  const std::string sc = scene("pendulum.toml");
  const pid_t pid = fork();
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    dup2(null, 1);
    dup2(null, 2);
    execl(DVM_BINARY, DVM_BINARY, "run", sc.c_str(), "--quiet", "--csv", csv.c_str(), "--set",
          "integrator.t_end=1e6", "--set", "output.every=1000000", static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

// The hidden temporaries of dir/killed.csv.
int hidden_temporaries(const std::string& dir) {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().rfind(".killed.csv.", 0) == 0) ++n;
  return n;
}

// Stops the run by `sig` and checks that it ended by that signal and left no file.
void stop_and_check(pid_t pid, int sig, const std::string& dir) {
  BOOST_REQUIRE(kill(pid, sig) == 0);
  int status = 0;
  BOOST_REQUIRE(waitpid(pid, &status, 0) == pid);
  BOOST_TEST(WIFSIGNALED(status));
  BOOST_TEST((WIFSIGNALED(status) ? WTERMSIG(status) : 0) == sig);
  BOOST_TEST(hidden_temporaries(dir) == 0);
  BOOST_TEST(!file_exists(dir + "/killed.csv"));
  BOOST_TEST(!file_exists(dir + "/killed.csv.partial"));
}

BOOST_AUTO_TEST_CASE(a_run_stopped_by_sigint_or_sigterm_removes_its_temporary) {
  // The run is stopped once its hidden temporary exists: the process still ends by the
  // signal, and neither the final path nor a temporary is left.
  const std::string dir = temp_dir();
  for (int sig : {SIGTERM, SIGINT}) {
    const pid_t pid = start_long_run(dir);
    BOOST_REQUIRE(pid >= 0);
    int status = 0;
    bool exited = false;
    for (int i = 0; i < 6000 && hidden_temporaries(dir) == 0 && !exited; ++i) {  // up to 60 s (a sanitized build starts slowly)
      exited = waitpid(pid, &status, WNOHANG) == pid;
      usleep(10000);
    }
    BOOST_REQUIRE_MESSAGE(!exited, "the run ended before it could be stopped");
    BOOST_REQUIRE_EQUAL(hidden_temporaries(dir), 1);
    BOOST_TEST_CONTEXT("signal " << sig) { stop_and_check(pid, sig, dir); }
  }
}

BOOST_AUTO_TEST_CASE(a_signal_at_any_moment_of_the_start_leaves_no_temporary) {
  // The temporary is created while the program starts; a signal can come before, during
  // or after. Runs are stopped, each by SIGTERM or SIGINT, at random moments spread over
  // twice the measured time from start to temporary (seeded, so a failure repeats) and,
  // to aim at the moment the file appears, by a watcher that polls the directory without
  // pause and signals as soon as it sees the temporary, which may be before the program
  // has registered it for removal. Two busy processes run beside it, as other suites do
  // under ctest -j2: a program that loses its core between creating the file and
  // registering it widens any window between the two. No run may leave a file.
  const std::string dir = temp_dir();
  struct BusyLoops {
    std::vector<pid_t> pids;
    BusyLoops() {
      for (int i = 0; i < 2; ++i) {
        const pid_t pid = fork();
        if (pid == 0)
          for (volatile unsigned long n = 0;; n = n + 1) {
          }
        pids.push_back(pid);
      }
    }
    ~BusyLoops() {
      for (pid_t pid : pids)
        if (pid > 0) kill(pid, SIGKILL), waitpid(pid, nullptr, 0);
    }
  } load;
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t first = start_long_run(dir);
  BOOST_REQUIRE(first >= 0);
  for (int i = 0; i < 60000 && hidden_temporaries(dir) == 0; ++i) usleep(1000);
  const double created_us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
  BOOST_REQUIRE_EQUAL(hidden_temporaries(dir), 1);
  stop_and_check(first, SIGTERM, dir);
  BOOST_TEST_MESSAGE("temporary created " << created_us / 1000.0 << " ms after the start");

  std::mt19937 rng(20261127);
  std::uniform_real_distribution<double> moment(0.0, 2.0 * created_us);
  int with_temporary = 0;
  const int runs = 60;
  for (int k = 0; k < runs; ++k) {
    const int sig = k % 2 ? SIGINT : SIGTERM;
    const bool watch = k % 3 != 0;
    const auto wait = static_cast<useconds_t>(moment(rng));
    const pid_t pid = start_long_run(dir);
    BOOST_REQUIRE(pid >= 0);
    if (watch) {
      const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
      while (hidden_temporaries(dir) == 0 && std::chrono::steady_clock::now() < give_up) {
      }
    } else {
      usleep(wait);
    }
    with_temporary += hidden_temporaries(dir);
    BOOST_TEST_CONTEXT("run " << k << ", signal " << sig << (watch ? " when the temporary appeared" : " after ")
                              << (watch ? 0 : wait) << " us") {
      stop_and_check(pid, sig, dir);
    }
  }
  BOOST_TEST_MESSAGE(with_temporary << " of " << runs << " runs had their temporary when stopped");
}

// A written Lagrangian "L" in a one-coordinate scene (x, x_dot), initial q = [q0].
std::string written_scene(const std::string& name, const std::string& L, double q0 = 1.0) {
  std::ostringstream s;
  s << "[system]\ncoordinates = [\"x\"]\nparams = { a = 0.0 }\nlagrangian = \"" << L << "\"\n"
    << "[initial]\nq = [" << q0 << "]\np = [0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 10\n";
  return write_scene(name, s.str());
}

BOOST_AUTO_TEST_CASE(expressions_that_grow_are_refused_with_the_position_never_a_crash) {
  // the parser recurses once per nesting level (at most 256) and walks everything else
  // without recursion: each of these crashed the program (stack overflow) before
  const std::string deep(15000, '('), shut(15000, ')');
  std::string signs(60000, '-'), powers;
  for (int i = 0; i < 60000; ++i) powers += "^1";
  std::string calls;
  for (int i = 0; i < 15000; ++i) calls += "sin(";
  // "lagrangian = \"" is 14 bytes: the expression starts at column 15 of line 4
  const std::vector<std::pair<std::string, std::string>> nested = {
      {"15000 parentheses", "x_dot^2 + " + deep + "x" + shut},        // level 257 opens at offset 10 + 256
      {"60000 unary minus signs", "x_dot^2 + " + signs + "x"},
      {"60000 chained ^1", "x_dot^2 + x" + powers},
      {"15000 nested calls", "x_dot^2 + " + calls + "x" + shut},
  };
  int i = 0;
  for (const auto& [name, L] : nested) {
    const std::string path = written_scene("grow" + std::to_string(i++) + ".toml", L);
    check({name, {"run", path, "--quiet"}, 2, {":4:", "system.lagrangian", "nests deeper than 256 levels"}});
  }
  check({"the position of the 257th level", {"run", written_scene("g.toml", "x_dot^2 + " + deep + "x" + shut), "--quiet"},
         2, {"g.toml:4:281:"}});
  // longer than 1 MiB: refused at the limit
  std::string huge = "x_dot^2";
  while (huge.size() <= (1u << 20)) huge += "+x_dot^2";
  check({"an expression over 1 MiB", {"run", written_scene("huge.toml", huge), "--quiet"}, 2,
         {"system.lagrangian", "at most 1048576 are accepted"}});
  // a flat sum of 60000 terms (a tree 60000 deep) within the limit runs: the harmonic
  // oscillator plus 59998 times the parameter a = 0, E = q0^2 / 2 with q0 = 1, p0 = 0
  std::string sum = "x_dot^2/2 - x^2/2";
  for (int k = 0; k < 59998; ++k) sum += " + a";
  const Output o = dvm({"run", written_scene("sum.toml", sum), "--json"});
  BOOST_TEST(o.status == 0, o.err);
  BOOST_TEST(json_number(o.out, "energy_initial") == 0.5);
}

BOOST_AUTO_TEST_CASE(values_that_are_not_finite_at_the_initial_state_are_named) {
  const std::vector<Case> cases = {
      {"a constant that overflows", {"run", written_scene("o1.toml", "x_dot^2/2 * 2^2^2^2^2^2"), "--quiet"}, 2,
       {"o1.toml:4:", "system.lagrangian", "gives inf"}},
      {"a division by a parameter that is 0", {"run", written_scene("o2.toml", "x_dot^2/2 + 1/a"), "--quiet"}, 2,
       {"o2.toml:4:", "gives inf"}},
      {"a velocity Hessian that divides by q = 0",
       {"run", written_scene("o3.toml", "x_dot^2/(2*x)", 0.0), "--quiet"}, 2,
       {"o3.toml:4:", "not finite at the initial state"}},
      {"an energy that divides by q = 0", {"run", written_scene("o4.toml", "x_dot^2/2 + 1/x", 0.0), "--quiet"}, 2,
       {"o4.toml:4:", "energy is not finite at the initial state", "initial.q and initial.p"}},
  };
  for (const auto& c : cases) check(c);
}

BOOST_AUTO_TEST_CASE(outputs_that_are_not_regular_files_are_written_directly) {
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::string dir = temp_dir();
  // device nodes of our own (as root; renaming over them would replace them), else the
  // system's, which a user cannot replace anyway
  std::string null_dev = "/dev/null", full_dev = "/dev/full";
  if (geteuid() == 0) {
    null_dev = dir + "/null";
    full_dev = dir + "/full";
    BOOST_REQUIRE(mknod(null_dev.c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0);
    BOOST_REQUIRE(mknod(full_dev.c_str(), S_IFCHR | 0666, makedev(1, 7)) == 0);
  }
  auto is_char_device = [](const std::string& p) {
    struct stat st {};
    return lstat(p.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
  };
  const Output to_null = dvm({"run", h, "--quiet", "--csv", null_dev, "--npy", dir + "/side.npy"});
  BOOST_TEST(to_null.status == 0, to_null.err);
  BOOST_TEST(is_char_device(null_dev));
  const Output to_full = dvm({"run", h, "--quiet", "--csv", full_dev});
  BOOST_TEST(to_full.status == 3, to_full.err);
  BOOST_TEST(to_full.err.find("error writing '" + full_dev + "' (No space left on device)") != std::string::npos,
             to_full.err);
  BOOST_TEST(is_char_device(full_dev));
  // a FIFO: the rows reach the reader, and the FIFO stays a FIFO
  const std::string fifo = dir + "/rows.fifo";
  BOOST_REQUIRE(mkfifo(fifo.c_str(), 0600) == 0);
  const pid_t reader = fork();
  BOOST_REQUIRE(reader >= 0);
  if (reader == 0) {
    std::ifstream in(fifo);
    std::ofstream(dir + "/from_fifo.csv") << in.rdbuf();
    _exit(0);
  }
  const Output to_fifo = dvm({"run", h, "--quiet", "--csv", fifo});
  int st = 0;
  waitpid(reader, &st, 0);
  BOOST_TEST(to_fifo.status == 0, to_fifo.err);
  BOOST_TEST(count_lines(dir + "/from_fifo.csv") == 102u);  // header, t = 0 and 100 steps
  struct stat fs {};
  BOOST_TEST((lstat(fifo.c_str(), &fs) == 0 && S_ISFIFO(fs.st_mode)));
  // "-" and /dev/stdout: the rows on standard output, the summary on standard error
  for (const std::string path : {"-", "/dev/stdout"}) {
    const Output o = dvm({"run", h, "--csv", path});
    BOOST_TEST_CONTEXT(path) {
      BOOST_TEST(o.status == 0, o.err);
      BOOST_TEST(o.out.rfind("t,q0,p0,energy\n0,1,0,", 0) == 0u, o.out.substr(0, 80));
      BOOST_TEST(std::count(o.out.begin(), o.out.end(), '\n') == 102);
      BOOST_TEST(o.err.find("harmonic with midpoint") != std::string::npos, o.err);
    }
  }
  BOOST_TEST(!file_exists("-"));
  // a .npy needs a file it can rewind: a pipe is refused, and nothing is written
  check({"--npy - on a pipe", {"run", h, "--npy", "-"}, 2, {"--npy '-'", "cannot be rewound"}});
}

BOOST_AUTO_TEST_CASE(outputs_never_overwrite_the_scene_or_each_other) {
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::string dir = temp_dir(), text = slurp(h);
  std::filesystem::create_symlink(h, dir + "/link.toml");
  const std::vector<Case> cases = {
      {"--csv naming the scene", {"run", h, "--csv", h}, 2, {"--csv", "is the scene file"}},
      {"output.npy naming the scene", {"run", h, "--set", "output.npy=\"" + h + "\""}, 2,
       {"key 'output.npy'", "is the scene file"}},
      {"--csv naming a link to the scene", {"run", h, "--csv", dir + "/link.toml"}, 2, {"is the scene file"}},
      {"--csv and --npy naming one file", {"run", h, "--csv", dir + "/same.out", "--npy", dir + "/./same.out"}, 2,
       {"--csv", "--npy", "name the same file"}},
      {"--csv - and --npy /dev/stdout", {"run", h, "--csv", "-", "--npy", "/dev/stdout"}, 2, {"name the same file"}},
  };
  for (const auto& c : cases) check(c);
  BOOST_TEST(slurp(h) == text);
  BOOST_TEST(!file_exists(dir + "/same.out"));
}

BOOST_AUTO_TEST_CASE(inputs_beyond_the_limits_are_refused_with_what_was_wrong) {
  const std::string h = write_scene("h.toml", kHarmonic), dir = temp_dir();
  // a scene larger than 16 MiB (a regular file, and /dev/zero), read without loading it
  {
    std::ofstream big(dir + "/big.toml");
    big << kHarmonic << "# " << std::string((16u << 20), 'x') << "\n";
  }
  // a chain scene for the position of system.params.n
  const std::string chain = write_scene("c.toml", "[system]\nbuiltin = \"chain\"\nparams = { n = 2.5 }\n");
  const std::string sphere_bvp = write_scene(
      "s.toml", "[system]\nbuiltin = \"spherical-pendulum\"\n[problem]\nkind = \"boundary-value\"\n"
                "q_final = [0.0, 0.6, -0.9]\nsteps = 10\n[initial]\nq = [0.6, 0.0, -0.8]\n"
                "[integrator]\nmap = \"sphere-exp\"\nstep = 0.01\n");
  const std::string million(1000000, 'a');
  std::string parts = "a", many_parts = "integrator";
  for (int k = 1; k < 100000; ++k) parts += ".a";
  for (int k = 1; k < 100; ++k) many_parts += ".a";
  const std::string dotted = write_scene("d.toml", std::string(kHarmonic) + "[output]\n" + parts + " = 1\n");
  const std::string header = write_scene("e.toml", "[system]\nbuiltin = \"harmonic\"\n[" + parts + "]\n");
  // 64 parts are accepted by the scan (and refused by the reader as an unknown key)
  std::string sixty_four = "a";
  for (int k = 1; k < 64; ++k) sixty_four += ".a";
  const Output ok64 = dvm({"run", write_scene("f.toml", std::string(kHarmonic) + "[output]\n" + sixty_four + " = 1\n")});
  BOOST_TEST(ok64.status == 2);
  BOOST_TEST(ok64.err.find("unknown key") != std::string::npos, ok64.err);
  // dots inside a string are not key parts
  const Output quoted = dvm({"run", write_scene("g.toml", std::string(kHarmonic) +
                                                              "[output]\ncsv = \"" + std::string(200, '.') + "x.csv\"\n"),
                             "--quiet", "--csv", temp_dir() + "/floats.csv"});
  BOOST_TEST(quoted.status == 0, quoted.err);
  const std::string long_csv = write_scene("m.toml", std::string(kHarmonic) + "[output]\ncsv = \"" + million + "\"\n");
  const std::vector<Case> cases = {
      {"a scene over 16 MiB", {"run", dir + "/big.toml"}, 2, {"larger than 16777216 bytes"}},
      {"/dev/zero as the scene", {"run", "/dev/zero"}, 2, {"/dev/zero", "larger than 16777216 bytes"}},
      {"a directory as the scene", {"run", dir}, 2, {"is a directory; expected a scene file"}},
      {"--set with a second line", {"run", h, "--set", "integrator.step=0.5\njunk = 1"}, 2,
       {"--set integrator.step", "not one TOML value"}},
      {"--set with a second table", {"run", h, "--set", "integrator.step=0.5\n[output]\nevery = 2"}, 2,
       {"not one TOML value"}},
      {"a NUL in an output path", {"run", h, "--set", "output.csv=\"a\\u0000b.csv\""}, 2,
       {"output.csv", "NUL character"}},
      {"a control character echoed", {"run", h, "--set", "integrator.map=\"mid\\u0001point\""}, 2,
       {"unknown map \"mid\\x01point\""}},
      {"system.params.n with its position", {"run", chain}, 2, {"c.toml:3:16: key 'system.params.n': got 2.5"}},
      {"problem.q_final off the sphere with its position", {"run", sphere_bvp}, 2,
       {"s.toml:5:11: key 'problem.q_final': not a unit vector"}},
      {"check-map --dim on S^2", {"check-map", "sphere-exp", "--dim", "3"}, 2, {"--dim applies only to maps on R^n"}},
      // toml++ recurses once per part of a dotted key: found by fuzzing as a stack overflow
      {"a dotted key of 100000 parts", {"run", dotted}, 2, {"d.toml:12:128: a dotted key of more than 64 parts"}},
      {"a table header of 100000 parts", {"run", header}, 2, {"e.toml:3:129: a dotted key of more than 64 parts"}},
      {"a --set key of 100 parts", {"run", h, "--set", many_parts + "=1"}, 2, {"--set", "has 100 parts; at most 64"}},
  };
  for (const auto& c : cases) check(c);
  // a scene of exactly 16 MiB (a whole number of the reader's chunks) is read whole and
  // runs: only what is over the limit is refused
  {
    const std::string head = kHarmonic + std::string("# ");
    std::ofstream(dir + "/exact.toml") << head << std::string((16u << 20) - head.size() - 1, 'x') << "\n";
    BOOST_REQUIRE(std::filesystem::file_size(dir + "/exact.toml") == (16u << 20));
    const Output o = dvm({"run", dir + "/exact.toml", "--quiet"});
    BOOST_TEST(o.status == 0, o.err.substr(0, 300));
  }
  // a 1 MB value is echoed in 80 bytes with its length, not whole
  for (const std::string key : {"integrator.map", "integrator.form", "integrator.composition", "integrator.method",
                                "integrator.solver", "problem.kind", "system.builtin", "integrator.step"}) {
    // the harmonic scene with the key set to a string of 10^6 bytes
    std::map<std::string, std::vector<std::string>> sections = {
        {"system", {"builtin = \"harmonic\""}},
        {"initial", {"q = [1.0]", "p = [0.0]"}},
        {"integrator", {"map = \"midpoint\"", "step = 0.01", "steps = 100"}}};
    const std::string section = key.substr(0, key.find('.')), name = key.substr(key.find('.') + 1);
    auto& lines = sections[section];
    lines.erase(std::remove_if(lines.begin(), lines.end(),
                               [&](const std::string& l) { return l.rfind(name + " ", 0) == 0; }),
                lines.end());
    lines.push_back(name + " = \"" + million + "\"");
    std::string text;
    for (const auto& [sec, ls] : sections) {
      text += "[" + sec + "]\n";
      for (const auto& l : ls) text += l + "\n";
    }
    const std::string path = write_scene("v.toml", text);
    const Output o = dvm({"run", path, "--quiet"});
    BOOST_TEST_CONTEXT(key << " -> " << o.err.substr(0, 300)) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.size() < 1000u);
      BOOST_TEST(o.err.find("(1000000 bytes)") != std::string::npos);
    }
  }
  const Output lm = dvm({"run", long_csv, "--quiet"});
  BOOST_TEST(lm.status == 2);
  BOOST_TEST(lm.err.size() < 1000u, lm.err.substr(0, 300));
}

BOOST_AUTO_TEST_CASE(a_convergence_study_beyond_its_work_limit_is_refused_before_it_starts) {
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::vector<Case> cases = {
      {"10^12 steps", {"converge", h, "--steps-list", "999999999999,1000000000000"}, 2,
       {"--steps-list", "2e+12 steps in all", "limit of 1e+08", "--max-steps"}},
      {"1e13: the limit, not the form of the number", {"converge", h, "--steps-list", "1e13,2e13"}, 2,
       {"limit of 1e+08"}},
      {"the scene's own count", {"converge", h, "--set", "integrator.steps=100000000"}, 2,
       {"integrator.steps", "1.5e+09 steps in all"}},
      {"a lower --max-steps", {"converge", h, "--steps-list", "100,200", "--max-steps", "299"}, 2,
       {"300 steps in all", "limit of 299"}},
      {"equal step counts", {"converge", h, "--steps-list", "100,100"}, 2, {"appears twice"}},
      {"--max-steps not a whole number", {"converge", h, "--max-steps", "1.5"}, 2, {"--max-steps"}},
  };
  for (const auto& c : cases) check(c);
  BOOST_TEST(dvm({"converge", h, "--steps-list", "100,200", "--max-steps", "300"}).status == 0);
}

// A key that the method or problem chosen does not use is refused, naming it, rather
// than run without it: method = "galerkin" and form = "newmark" take no map, so a map
// or theta given with --set beside them (or a theta written in the same file as the
// method) would change nothing; use_structure does not shape a boundary-value solve;
// a convergence study writes no rows. The scene's own map stays allowed when --set
// switches the method (it is set aside, and the report says so: map "none").
BOOST_AUTO_TEST_CASE(a_key_the_chosen_method_does_not_use_is_refused) {
  const std::string p = scene("pendulum.toml"), kg = scene("kepler-galerkin.toml");
  const std::string in_file = write_scene(
      "galerkin_theta.toml",
      "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [1.0]\np = [0.0]\n"
      "[integrator]\nmethod = \"galerkin\"\nmap = \"theta\"\ntheta = 0.2\nstep = 0.1\nsteps = 10\n");
  const std::string bvp = scene("pendulum_bvp.toml");
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::vector<Case> cases = {
      {"galerkin with a map and theta from --set",
       {"run", p, "--set", "integrator.method=galerkin", "--set", "integrator.map=theta", "--set",
        "integrator.theta=0.2"},
       2,
       {"(from --set): key 'integrator.map'", "integrator.map and integrator.theta", "method = \"galerkin\"",
        "would change nothing"}},
      {"a map from --set on a Galerkin scene", {"run", kg, "--set", "integrator.map=midpoint"}, 2,
       {"key 'integrator.map'", "method = \"galerkin\" takes no map"}},
      {"theta written in the file beside method = galerkin", {"run", in_file}, 2,
       {"galerkin_theta.toml:9:9: key 'integrator.theta'", "method = \"galerkin\""}},
      {"newmark with a map and theta from --set",
       {"run", p, "--set", "integrator.form=newmark", "--set", "integrator.map=theta", "--set",
        "integrator.theta=0.2"},
       2, {"key 'integrator.map'", "integrator.map and integrator.theta", "form = \"newmark\""}},
      {"use_structure on a boundary-value problem", {"run", bvp, "--set", "integrator.use_structure=false"}, 2,
       {"key 'integrator.use_structure'", "boundary-value"}},
      {"[output] keys given to converge", {"converge", p, "--set", "output.csv=x.csv", "--steps-list", "10,20"}, 2,
       {"--set output.csv", "writes no rows"}},
      {"monitor_every on a boundary-value problem", {"run", bvp, "--set", "output.monitor_every=2"}, 2,
       {"key 'output.monitor_every'", "boundary-value"}},
      {"a row interval for a run that writes no rows", {"run", h, "--set", "output.every=5"}, 2,
       {"output.every", "writes no rows"}},
  };
  for (const auto& c : cases) check(c);
  // --set switching the method of a scene written for a map still works: the scene's
  // map (and its theta and [map] section) are set aside, and the report says so
  const std::string csv = temp_dir() + "/switched.csv";
  const Output g = dvm({"run", p, "--json", "--csv", csv, "--set", "integrator.method=galerkin", "--set",
                        "integrator.t_end=1"});
  BOOST_TEST(g.status == 0, g.err);
  BOOST_TEST(json_string(g.out, "map") == "none");
  const Output w = dvm({"run", scene("spherical_pendulum_written_map.toml"), "--json", "--csv", csv, "--set",
                        "integrator.method=galerkin", "--set", "integrator.t_end=1"});
  BOOST_TEST(w.status == 0, w.err);
  BOOST_TEST(json_string(w.out, "map") == "none");
  const Output n = dvm({"run", p, "--json", "--csv", csv, "--set", "integrator.form=newmark", "--set",
                        "integrator.t_end=1"});
  BOOST_TEST(n.status == 0, n.err);
  BOOST_TEST(json_string(n.out, "map") == "newmark");
}

// Messages that point at the cause: a reserved name used as a parameter is blamed on
// that parameter's key and line (not on the coordinates); end points on S^2 that are
// antipodal are bad input (every great circle joins them), not an internal error;
// check-map refuses a theta below 0 as it does one above 1; a degenerate Lagrangian
// names the velocities it lacks, a vector of the wrong length the coordinates; a
// mistyped option costs one line and where the help is, not the whole help; a
// misspelt key or name gets the nearest known one.
BOOST_AUTO_TEST_CASE(messages_point_at_the_cause_and_suggest_the_name_meant) {
  auto written = [](const std::string& params) {
    return "[system]\ncoordinates = [\"x\"]\nparams = { " + params +
           " }\nlagrangian = \"m/2*x_dot^2 - x^2/2\"\n"
           "[initial]\nq = [1.0]\nv = [0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 10\n";
  };
  const std::string t = write_scene("param_t.toml", written("m = 1.0, t = 0.0"));
  const std::string s = write_scene("param_sum.toml", written("m = 1.0, sum = 2.0"));
  const std::string pi = write_scene("param_pi.toml", written("m = 1.0, pi = 3.0"));
  const std::string twice = write_scene("param_x.toml", written("m = 1.0, x_dot = 3.0"));
  const std::string antipodal = write_scene(
      "antipodal.toml",
      "[system]\nbuiltin = \"spherical-pendulum\"\n[problem]\nkind = \"boundary-value\"\n"
      "q_final = [-0.6, 0.0, 0.8]\nsteps = 20\n[initial]\nq = [0.6, 0.0, -0.8]\n"
      "[integrator]\nmap = \"sphere-exp\"\nstep = 0.05\n");
  const std::string h = write_scene("h.toml", kHarmonic);
  const std::string misspelt_key = write_scene(
      "lagrangain.toml", "[system]\ncoordinates = [\"x\"]\nlagrangain = \"x_dot^2/2 - x^2/2\"\n"
                         "[initial]\nq = [1.0]\nv = [0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 10\n");
  const std::vector<Case> cases = {
      {"parameter t", {"run", t}, 2, {"param_t.toml:3:25: key 'system.params.t'", "reserved (time)"}},
      {"parameter sum", {"run", s}, 2, {"param_sum.toml:3:27: key 'system.params.sum'", "reserved"}},
      {"parameter pi", {"run", pi}, 2, {"key 'system.params.pi'", "reserved for the constant"}},
      {"parameter named as a velocity", {"run", twice}, 2, {"key 'system.params.x_dot'", "used twice"}},
      {"map parameter named as the map's variable",
       {"run", scene("pendulum_written_map.toml"), "--set", "map.params.x=1.0"}, 2,
       {"key 'map.params.x'", "a variable of the map's expressions"}},
      {"map parameter named as a function",
       {"run", scene("spherical_pendulum_written_map.toml"), "--set", "map.params.sin=1.0"}, 2,
       {"key 'map.params.sin'", "a function name"}},
      {"antipodal end points on S^2", {"run", antipodal}, 2,
       {"antipodal.toml:5:11: key 'problem.q_final'", "antipodal to initial.q", "great circle"}},
      {"check-map --theta below 0", {"check-map", "theta", "--theta", "-0.5"}, 2, {"--theta", "[0, 1]"}},
      {"check-map --theta above 1", {"check-map", "theta", "--theta", "2"}, 2, {"--theta", "[0, 1]"}},
      {"t_ned", {"run", h, "--set", "integrator.t_ned=1.0"}, 2, {"integrator.t_ned", "did you mean \"t_end\"?"}},
      {"lagrangain", {"run", misspelt_key}, 2, {"system.lagrangain", "did you mean \"lagrangian\"?"}},
      {"mid-point", {"run", h, "--set", "integrator.map=mid-point"}, 2, {"did you mean \"midpoint\"?"}},
      {"kahan_li8", {"run", h, "--set", "integrator.composition=kahan_li8"}, 2, {"did you mean \"kahan-li8\"?"}},
      {"builtin pendulm", {"run", h, "--set", "system.builtin=pendulm"}, 2, {"did you mean \"pendulum\"?"}},
      {"form hamiltonan", {"run", h, "--set", "integrator.form=hamiltonan"}, 2, {"did you mean \"hamiltonian\"?"}},
  };
  for (const auto& c : cases) {
    check(c);
    BOOST_TEST(dvm(c.args).err.find("internal error") == std::string::npos, c.name);
  }
  // a name far from every known one gets no guess
  BOOST_TEST(dvm({"run", h, "--set", "integrator.map=zzzzzz"}).err.find("did you mean") == std::string::npos);
  // the antipodal problem nearly: 1e-6 apart from antipodal, it solves
  const Output near = dvm({"run", antipodal, "--set", "problem.q_final=[-0.6, 0.000001, 0.7999999999993750]"});
  BOOST_TEST(near.status == 0, near.err);

  // a degenerate Lagrangian names the velocities along which d2L/dv2 vanishes
  auto degenerate = [](const std::string& name, const std::string& lagrangian) {
    return write_scene(name, "[system]\ncoordinates = [\"x\", \"y\"]\nlagrangian = \"" + lagrangian +
                                 "\"\n[initial]\nq = [1.0, 0.5]\nv = [0.0, 0.0]\n"
                                 "[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 10\n");
  };
  check({"no y_dot in L", {"run", degenerate("no_y_dot.toml", "x_dot^2/2 - x^2/2 - y^2/2")}, 2,
         {"degenerate at the initial state", "no term of second order in y_dot"}});
  check({"only x_dot + y_dot in L", {"run", degenerate("sum_dot.toml", "(x_dot + y_dot)^2/2 - x^2/2 - y^2/2")}, 2,
         {"degenerate at the initial state", "a combination of x_dot and y_dot"}});
  // a vector of the wrong length is described by the coordinates' names
  check({"q of the wrong length", {"run", degenerate("short_q.toml", "x_dot^2/2 + y_dot^2/2"), "--set",
                                   "initial.q=[1.0]"},
         2, {"expected 2 (one per coordinate: x, y)"}});

  // a mistyped option: the message, the nearest option and where the help is
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"run", h, "--cvs", "x.csv"}, std::vector<std::string>{"converge", h, "--t_end", "1"},
        std::vector<std::string>{"check-map", "theta", "--thetta", "0.3"}}) {
    const Output o = dvm(args);
    const std::string command = args[0];
    BOOST_TEST_CONTEXT(command << " -> " << o.err) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(std::count(o.err.begin(), o.err.end(), '\n') == 2);
      BOOST_TEST(o.err.find("unknown option") != std::string::npos);
      BOOST_TEST(o.err.find("did you mean") != std::string::npos);
      BOOST_TEST(o.err.find("see 'dvm " + command + " --help'") != std::string::npos);
    }
  }
}
