// dvm sweep: a table of runs of one scene over values of its keys.
//
// Each row must be the run `dvm run --json --set KEY=VALUE ...` gives, to the bit, on
// one thread or several; failed and refused runs are rows with their status; --error
// must be the distance of the final state from the exact solution (or from the
// reference of dvm converge); bad input of the sweep exits 2 naming the key, before
// anything runs or is written.
#define BOOST_TEST_MODULE cli_sweep
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"
#include "tests/cli/sweep_tables.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace cli_test;

// A pendulum released at 1 rad, 40 steps of 0.05 (t_end 2).
const char* kPendulum =
    "[system]\nbuiltin = \"pendulum\"\n"
    "[initial]\nq = [1.0]\np = [0.0]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.05\nt_end = 2.0\n"
    "[output]\ncsv = \"never-written.csv\"\n";

// A harmonic oscillator without parameters (a sweep may give them).
const char* kHarmonic =
    "[system]\nbuiltin = \"harmonic\"\n"
    "[initial]\nq = [1.0]\np = [0.5]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 30\n";

// The value of a row as --set takes it: strings quoted, numbers and arrays as JSON
// writes them (a JSON number is read back to the same double).
std::string set_value(const Json& v) {
  if (v.is_string()) return "\"" + v.get<std::string>() + "\"";
  return v.dump();
}

// `dvm run --json --no-output` of a row alone: the scene, the extra arguments, then
// --set KEY=VALUE for each of the row's values.
Output run_alone(const std::string& scene, const Json& row, std::vector<std::string> extra = {}) {
  std::vector<std::string> args = {"run", scene, "--json", "--no-output"};
  args.insert(args.end(), extra.begin(), extra.end());
  for (const auto& [key, value] : row.at("values").items()) {
    args.push_back("--set");
    args.push_back(key + "=" + set_value(value));
  }
  return dvm(args);
}

// Runs the sweep with --out and --json; returns the parsed JSON (stdout) and checks
// that PATH.json holds the same text.
Json sweep_json(std::vector<std::string> args, const std::string& out, int status) {
  args.push_back("--json");
  args.push_back("--out");
  args.push_back(out);
  const Output o = dvm(args);
  BOOST_TEST_REQUIRE(o.status == status, o.err);
  BOOST_TEST(slurp(out + ".json") == o.out);
  return parse_json(o.out);
}

// Starts dvm with the arguments (stdout and stderr to files in the temporary folder);
// returns its process id.
pid_t start_dvm(const std::vector<std::string>& args) {
  std::vector<std::string> all = {dvm_binary()};
  all.insert(all.end(), args.begin(), args.end());
  const std::string out = temp_dir() + "/started.out", err = temp_dir() + "/started.err";
  const pid_t pid = fork();
  BOOST_REQUIRE(pid >= 0);
  if (pid == 0) {
    const int o = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int e = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (o < 0 || e < 0) _exit(127);
    dup2(o, 1);
    dup2(e, 2);
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}

// The number of rows of the JSON table at `path` (-1 while there is none).
int table_rows(const std::string& path) {
  if (!file_exists(path)) return -1;
  const Json j = Json::parse(slurp(path), nullptr, false);
  BOOST_REQUIRE_MESSAGE(!j.is_discarded(), path << " is not JSON while the sweep runs: it must be replaced whole");
  return static_cast<int>(j.at("rows").size());
}

}  // namespace

BOOST_AUTO_TEST_CASE(a_sweep_equals_the_runs_done_one_by_one_on_1_and_2_threads) {
  const std::string s = write_scene("pendulum.toml", kPendulum);
  const std::vector<std::string> args = {"sweep", s, "--vary", "integrator.step=log:0.025:0.1:3", "--vary",
                                         "integrator.composition=[none, suzuki5]", "--vary",
                                         "system.params.g=[1.0, 9.81]"};
  std::vector<std::string> one = args, two = args;
  one.insert(one.end(), {"--jobs", "1"});
  two.insert(two.end(), {"--jobs", "2"});
  const Json a = sweep_json(one, temp_dir() + "/one", 0);
  const Json b = sweep_json(two, temp_dir() + "/two", 0);
  BOOST_TEST_REQUIRE(a.at("rows").size() == 12u);
  BOOST_TEST(a.at("ok").get<int>() == 12);
  // the log range: both ends exact, equal ratios between
  const Json& steps = a.at("vary").at(0).at("values");
  BOOST_TEST(steps.at(0).get<double>() == 0.025);
  BOOST_TEST(steps.at(1).get<double>() == std::exp(std::log(0.025) + (std::log(0.1) - std::log(0.025)) * 0.5));
  BOOST_TEST(steps.at(2).get<double>() == 0.1);
  for (std::size_t i = 0; i < 12; ++i) {
    const Json& row = a.at("rows").at(i);
    BOOST_TEST(row.at("index").get<std::size_t>() == i);
    BOOST_TEST(row.at("status") == "ok");
    // the sweep's order: the last key varies fastest
    BOOST_TEST(row.at("values").at("system.params.g") == a.at("vary").at(2).at("values").at(i % 2));
    BOOST_TEST(row.at("values").at("integrator.step") == steps.at(i / 4));
    // the same row on two threads, to the bit
    BOOST_TEST(untimed(row.at("run")) == untimed(b.at("rows").at(i).at("run")));
    // and the same run done alone
    const Output r = run_alone(s, row);
    BOOST_TEST_REQUIRE(r.status == 0, r.err);
    BOOST_TEST(untimed(parse_json(r.out)) == untimed(row.at("run")), "row " << i);
  }
  // the CSV holds the same numbers (17 digits), in the same order
  const auto csv = csv_rows(slurp(temp_dir() + "/two.csv"));
  BOOST_TEST_REQUIRE(csv.size() == 13u);
  const std::vector<std::string>& head = csv.front();
  for (std::size_t i = 0; i < 12; ++i) {
    const std::vector<std::string>& c = csv[i + 1];
    BOOST_TEST_REQUIRE(c.size() == head.size());
    const Json& run = a.at("rows").at(i).at("run");
    BOOST_TEST(std::stod(c[column(head, "index")]) == static_cast<double>(i));
    BOOST_TEST(c[column(head, "status")] == "ok");
    BOOST_TEST(c[column(head, "integrator.composition")] == a.at("rows").at(i).at("values").at("integrator.composition"));
    BOOST_TEST(std::strtod(c[column(head, "q_final[0]")].c_str(), nullptr) == run.at("q_final").at(0).get<double>());
    BOOST_TEST(std::strtod(c[column(head, "p_final[0]")].c_str(), nullptr) == run.at("p_final").at(0).get<double>());
    BOOST_TEST(std::strtod(c[column(head, "max_abs_energy_error")].c_str(), nullptr) ==
               run.at("max_abs_energy_error").get<double>());
    BOOST_TEST(std::stoll(c[column(head, "solver_iterations")]) == run.at("solver_iterations").get<long long>());
    BOOST_TEST(c[column(head, "work")].empty());  // no forces
  }
  // the scene's [output] file is not written by a sweep
  BOOST_TEST(!file_exists("never-written.csv"));
}

BOOST_AUTO_TEST_CASE(linear_ranges_and_seeded_samples_follow_their_definitions) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const Json j = sweep_json({"sweep", s, "--zip", "--vary", "system.params.omega=uniform:0.5:2:5:42", "--vary",
                             "initial.p=[[0.0], [0.1], [0.2], [0.3], [0.4]]", "--vary", "integrator.steps=10:50:5"},
                            temp_dir() + "/samples", 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 5u);
  std::mt19937_64 engine(42);
  for (std::size_t i = 0; i < 5; ++i) {
    const double u = static_cast<double>(engine() >> 11) * std::ldexp(1.0, -53);
    const Json& v = j.at("rows").at(i).at("values");
    BOOST_TEST(v.at("system.params.omega").get<double>() == 0.5 + 1.5 * u);
    // ends written as whole numbers: whole-number points, as integrator.steps needs
    BOOST_TEST(v.at("integrator.steps").is_number_integer());
    BOOST_TEST(v.at("integrator.steps").get<int>() == 10 + 10 * static_cast<int>(i));
    BOOST_TEST(j.at("rows").at(i).at("run").at("steps").get<int>() == 10 + 10 * static_cast<int>(i));
  }
}

BOOST_AUTO_TEST_CASE(failed_runs_are_rows_and_the_sweep_exits_3) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const std::string out = temp_dir() + "/failing";
  // one Newton iteration cannot solve the midpoint step; 25 can
  const Json j = sweep_json({"sweep", s, "--jobs", "2", "--vary", "integrator.max_iterations=[1, 25, 1]"}, out, 3);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 3u);
  BOOST_TEST(j.at("failed").get<int>() == 2);
  BOOST_TEST(j.at("ok").get<int>() == 1);
  for (std::size_t i : {0u, 2u}) {
    const Json& row = j.at("rows").at(i);
    BOOST_TEST(row.at("status") == "failed");
    BOOST_TEST(row.at("code").get<int>() == 3);
    BOOST_TEST(row.at("message").get<std::string>().find("step 0 ") != std::string::npos, row.dump());
    BOOST_TEST(row.at("run").at("status") == "failed");
    BOOST_TEST(row.at("run").at("failure").at("step").get<int>() == 0);
  }
  BOOST_TEST(j.at("rows").at(1).at("status") == "ok");
  BOOST_TEST(j.at("rows").at(1).at("code").get<int>() == 0);
  const auto csv = csv_rows(slurp(out + ".csv"));
  BOOST_TEST_REQUIRE(csv.size() == 4u);
  BOOST_TEST(csv[1][column(csv[0], "status")] == "failed");
  BOOST_TEST(csv[1][column(csv[0], "failed_step")] == "0");
  BOOST_TEST(csv[2][column(csv[0], "status")] == "ok");
  BOOST_TEST(csv[2][column(csv[0], "failed_step")] == "");
}

BOOST_AUTO_TEST_CASE(combinations_refused_in_some_rows_only_are_rows_refused) {
  // omega is a parameter of harmonic only, g of pendulum only: two of the four
  // combinations are refused, and every value runs in one of the others
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const std::string out = temp_dir() + "/refused";
  const Json j = sweep_json({"sweep", s, "--vary", "system.builtin=[harmonic, pendulum]", "--vary",
                             "system.params=[{ omega = 2.0 }, { g = 2.0 }]"},
                            out, 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 4u);
  BOOST_TEST(j.at("refused").get<int>() == 2);
  const std::vector<std::string> expected = {"ok", "refused", "refused", "ok"};
  for (std::size_t i = 0; i < 4; ++i) {
    const Json& row = j.at("rows").at(i);
    BOOST_TEST(row.at("status") == expected[i]);
    if (expected[i] != "refused") continue;
    BOOST_TEST(row.at("code").get<int>() == 2);
    BOOST_TEST(row.at("run").is_null());
    BOOST_TEST(row.at("message").get<std::string>().find("system.params.") != std::string::npos, row.dump());
  }
  BOOST_TEST(j.at("rows").at(0).at("values").at("system.params").at("omega").get<double>() == 2.0);
  const Output plain = dvm({"sweep", s, "--vary", "system.builtin=[harmonic, pendulum]", "--vary",
                            "system.params=[{ omega = 2.0 }, { g = 2.0 }]"});
  BOOST_TEST(plain.status == 0);
  BOOST_TEST(plain.err.find("2 of 4 runs refused") != std::string::npos, plain.err);
  // without --out, the CSV table on stdout: the same rows as the file
  const auto printed = csv_rows(plain.out), written = csv_rows(slurp(out + ".csv"));
  BOOST_TEST_REQUIRE(printed.size() == 5u);
  BOOST_TEST_REQUIRE(written.size() == 5u);
  BOOST_TEST(printed[0] == written[0]);
  for (std::size_t i = 1; i < 5; ++i)
    BOOST_TEST(printed[i][column(printed[0], "status")] == expected[i - 1]);
}

BOOST_AUTO_TEST_CASE(error_against_the_exact_solution_is_that_of_the_final_state) {
  // harmonic, omega = 2: q(t) = q0 cos(2t) + p0/2 sin(2t), p(t) = -2 q0 sin(2t) + p0 cos(2t)
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const Json j = sweep_json({"sweep", s, "--error", "--set", "system.params.omega=2.0", "--vary",
                             "integrator.composition=[none, suzuki5]", "--vary", "integrator.step=[0.1, 0.05]"},
                            temp_dir() + "/exact", 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 4u);
  BOOST_TEST_REQUIRE(j.at("references").size() == 2u);  // two time spans: 30 x 0.1 and 30 x 0.05
  BOOST_TEST(j.at("references").at(0).at("reference").get<std::string>().find("exact") != std::string::npos);
  for (std::size_t i = 0; i < 4; ++i) {
    const Json& row = j.at("rows").at(i);
    const Output r = run_alone(s, row, {"--set", "system.params.omega=2.0"});
    BOOST_TEST_REQUIRE(r.status == 0, r.err);
    const Json rj = parse_json(r.out);
    const double t = rj.at("t_final").get<double>();
    const double q = rj.at("q_final").at(0).get<double>(), p = rj.at("p_final").at(0).get<double>();
    const double qe = std::cos(2 * t) + 0.25 * std::sin(2 * t), pe = -2 * std::sin(2 * t) + 0.5 * std::cos(2 * t);
    const double error = std::fmax(std::fabs(q - qe), std::fabs(p - pe));
    // the closed form evaluated two ways differs by round-off only
    BOOST_TEST(std::fabs(row.at("error").get<double>() - error) <= 1e-14, row.at("error").get<double>() << " vs " << error);
    BOOST_TEST(error > 1e-10);  // a real error, not round-off
    BOOST_TEST(row.at("reference").get<int>() == (i % 2 == 0 ? 0 : 1));
  }
  // the CSV's error column is the JSON's
  const auto csv = csv_rows(slurp(temp_dir() + "/exact.csv"));
  for (std::size_t i = 0; i < 4; ++i)
    BOOST_TEST(std::strtod(csv[i + 1][column(csv[0], "error")].c_str(), nullptr) ==
               j.at("rows").at(i).at("error").get<double>());
}

BOOST_AUTO_TEST_CASE(error_without_an_exact_solution_is_that_of_dvm_converge) {
  // the pendulum to t = 2 with 40 and 80 steps: the runs and the reference of dvm
  // converge --steps-list 40,80, so the same errors to the bit
  const std::string s = write_scene("pendulum.toml", kPendulum);
  const Json j = sweep_json({"sweep", s, "--error", "--jobs", "2", "--vary", "integrator.step=[0.05, 0.025]"},
                            temp_dir() + "/converge", 0);
  const Output c = dvm({"converge", s, "--json", "--steps-list", "40,80", "--t-end", "2"});
  BOOST_TEST_REQUIRE(c.status == 0, c.err);
  const Json cj = parse_json(c.out);
  BOOST_TEST_REQUIRE(j.at("references").size() == 1u);
  BOOST_TEST(j.at("references").at(0).at("reference") == cj.at("reference"));
  BOOST_TEST(j.at("references").at(0).at("accuracy").get<double>() == cj.at("reference_accuracy").get<double>());
  for (std::size_t i = 0; i < 2; ++i)
    BOOST_TEST(j.at("rows").at(i).at("error").get<double>() == cj.at("runs").at(i).at("error").get<double>());
}

BOOST_AUTO_TEST_CASE(bad_input_exits_2_naming_the_key_and_runs_nothing) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  struct Case {
    std::vector<std::string> vary;
    std::vector<std::string> expect;
  };
  const std::vector<Case> cases = {
      {{"--vary", "integrator.step=0.1:0.2:0"}, {"integrator.step", "empty range"}},
      {{"--vary", "integrator.step=[]"}, {"integrator.step", "empty list"}},
      {{"--vary", "integrator.step=0.01:0.1:1000000000"}, {"integrator.step", "1000000", "--max-runs"}},
      {{"--vary", "integrator.step=0.01:0.1:1000", "--vary", "system.params.omega=1:2:1001"},
       {"1001000 runs", "limit of 1000000", "--max-runs"}},
      {{"--vary", "integrator.stpe=[0.1, 0.2]"}, {"integrator.stpe", "unknown key", "did you mean \"step\""}},
      {{"--vary", "integrator.step=[0.1, \"fast\"]"}, {"integrator.step", "\"fast\"", "expected a number"}},
      {{"--vary", "integrator.steps=[10, 2.5]"}, {"integrator.steps", "2.5", "whole number"}},
      {{"--vary", "integrator.step=log:0:1:3"}, {"integrator.step", "ends > 0"}},
      {{"--vary", "integrator.step=0.1:0.2"}, {"integrator.step", "a:b:n"}},
      {{"--zip", "--vary", "integrator.step=[0.1, 0.2]", "--vary", "integrator.steps=[1, 2, 3]"},
       {"integrator.steps", "equal lengths"}},
      {{"--vary", "integrator.step=[0.1]", "--vary", "integrator.step=[0.2]"}, {"integrator.step", "twice"}},
      {{"--vary", "output.csv=[\"a.csv\"]"}, {"output.csv", "no trajectories"}},
  };
  for (const Case& c : cases) {
    const std::string out = temp_dir() + "/bad";
    std::vector<std::string> args = {"sweep", s, "--out", out};
    args.insert(args.end(), c.vary.begin(), c.vary.end());
    const Output o = dvm(args);
    BOOST_TEST(o.status == 2, c.vary.back() << ": " << o.err);
    for (const std::string& e : c.expect) BOOST_TEST(o.err.find(e) != std::string::npos, c.vary.back() << ": " << o.err);
    BOOST_TEST(o.out.empty(), o.out);
    BOOST_TEST(!file_exists(out + ".csv"));
    BOOST_TEST(!file_exists(out + ".json"));
  }
  // a raised limit admits the sweep the default refuses
  const Output raised = dvm({"sweep", s, "--max-runs", "3", "--vary", "integrator.step=[0.1, 0.2, 0.3, 0.4]"});
  BOOST_TEST(raised.status == 2);
  BOOST_TEST(raised.err.find("limit of 3") != std::string::npos, raised.err);
  BOOST_TEST(dvm({"sweep", s, "--max-runs", "4", "--vary", "integrator.step=[0.1, 0.2, 0.3, 0.4]"}).status == 0);
}

// The linear stability thresholds that `dvm methods` lists for the compositions of
// the explicit Euler maps (stability_threshold_explicit_euler: h omega below which
// the splitting is stable on q'' = -omega^2 q, from the trace of a product of 2 x 2
// matrices, solvers/stability.h) are where the steps dvm takes lose stability. One
// sweep takes one step of each composition from (q, p) = (1, 0) and (0, 1) on the
// harmonic oscillator (omega = 1), so that the two final states are the columns of
// the one-step matrix M of the step dvm runs (kicks and drifts); at the listed
// threshold h* its trace is +-2 (|tr M| / 2 = 1 to round-off), and at every h of a
// grid below it (20 points from h*/20, and 0.99 h*, 0.999 h*) |tr M| / 2 < 1: h* is
// the first h where the step stops being stable. A threshold listed 0.1 % too low or
// too high fails it.
BOOST_AUTO_TEST_CASE(the_stability_thresholds_of_dvm_methods_are_those_of_the_steps_dvm_takes) {
  const Output m = dvm({"methods", "--json"});
  BOOST_TEST_REQUIRE(m.status == 0, m.err);
  struct Point {
    std::string composition;
    double threshold, h;
  };
  std::vector<Point> points;
  for (const Json& r : parse_json(m.out)) {
    if (!r.contains("stability_threshold_explicit_euler")) continue;
    const double t = json_double(r.at("stability_threshold_explicit_euler"));
    BOOST_TEST_REQUIRE((std::isfinite(t) && t > 0.0), r.dump());
    const std::string c = r.at("name").get<std::string>();
    for (int k = 1; k <= 20; ++k) points.push_back({c, t, t * k / 20.0});
    for (double f : {0.99, 0.999}) points.push_back({c, t, t * f});
  }
  BOOST_TEST_REQUIRE(points.size() >= 20u * 22u);  // none, stormer-verlet and the 20 compositions
  // zipped lists: each point twice, from (1, 0) and from (0, 1)
  std::ostringstream comps, steps, qs, ps;
  for (std::size_t i = 0; i < points.size(); ++i)
    for (int unit = 0; unit < 2; ++unit) {
      const char* sep = i + unit == 0 ? "[" : ", ";
      comps << sep << '"' << points[i].composition << '"';
      steps << sep << Json(points[i].h).dump();
      qs << sep << (unit == 0 ? "[1.0]" : "[0.0]");
      ps << sep << (unit == 0 ? "[0.0]" : "[1.0]");
    }
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const Json j = sweep_json({"sweep", s, "--zip", "--set", "integrator.map=explicit-euler", "--set", "integrator.steps=1",
                             "--set", "system.params={ omega = 1.0 }", "--vary", "integrator.composition=" + comps.str() + "]",
                             "--vary", "integrator.step=" + steps.str() + "]", "--vary", "initial.q=" + qs.str() + "]",
                             "--vary", "initial.p=" + ps.str() + "]"},
                            temp_dir() + "/trace", 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 2 * points.size());
  int at_threshold = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Json& a = j.at("rows").at(2 * i);
    const Json& b = j.at("rows").at(2 * i + 1);
    BOOST_TEST_REQUIRE(a.at("status") == "ok", a.dump());
    BOOST_TEST_REQUIRE(b.at("status") == "ok", b.dump());
    // tr M = dq1/dq0 + dp1/dp0
    const double tr = json_double(a.at("run").at("q_final")[0]) + json_double(b.at("run").at("p_final")[0]);
    const Point& pt = points[i];
    BOOST_TEST_CONTEXT(pt.composition << ": h = " << pt.h << " = " << pt.h / pt.threshold << " h*, |tr M| / 2 = "
                                      << std::fabs(tr) / 2) {
      if (pt.h == pt.threshold) {
        ++at_threshold;
        BOOST_TEST(std::fabs(std::fabs(tr) / 2 - 1.0) <= 1e-9);
      } else {
        BOOST_TEST(std::fabs(tr) / 2 < 1.0 - 1e-12);
      }
    }
  }
  BOOST_TEST(at_threshold >= 22);
}

// A sweep killed (SIGKILL) once its table holds some rows, then resumed: the rows the
// killed sweep wrote are kept as they are (a failed row too: it is not run again, so
// its timings are those of the killed sweep), the others run, and the table equals
// the one of the same sweep never stopped, row for row, but for the timings.
BOOST_AUTO_TEST_CASE(a_sweep_killed_midway_and_resumed_equals_the_uninterrupted_one) {
  // 16 runs of the pendulum, each long beside the poll interval below in the build
  // under test, so that the polls see the table grow row by row; those with one Newton
  // iteration fail at step 0
  const std::string s = write_long_pendulum("long.toml", 0.05);
  const std::vector<std::string> args = {"sweep", s, "--jobs", "1", "--vary", "integrator.step=log:0.0005:0.002:8",
                                         "--vary", "integrator.max_iterations=[25, 1]"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> a = args;
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  };
  const std::string whole = temp_dir() + "/whole", cut = temp_dir() + "/cut";
  const Output w = dvm(with({"--out", whole}));
  BOOST_TEST_REQUIRE(w.status == 3, w.err);  // the failed runs
  const Json expected = parse_json(slurp(whole + ".json"));
  BOOST_TEST_REQUIRE(expected.at("rows").size() == 16u);
  BOOST_TEST(expected.at("failed").get<int>() == 8);

  // killed once the table has at least one row and not all
  const pid_t pid = start_dvm(with({"--out", cut}));
  int rows = -1;
  for (int tries = 0; tries < 200000; ++tries) {
    rows = table_rows(cut + ".json");
    if (rows >= 2 && rows < 16) break;
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == pid) BOOST_FAIL("the sweep ended before it could be killed: " << rows);
    const timespec pause{0, 1000000};
    nanosleep(&pause, nullptr);
  }
  BOOST_TEST_REQUIRE(kill(pid, SIGKILL) == 0);
  int status = 0;
  BOOST_TEST_REQUIRE(waitpid(pid, &status, 0) == pid);
  BOOST_TEST_REQUIRE(WIFSIGNALED(status));
  const Json killed = parse_json(slurp(cut + ".json"));
  const std::size_t kept = killed.at("rows").size();
  BOOST_TEST_MESSAGE("killed with " << kept << " of 16 rows in the table");
  BOOST_TEST_REQUIRE(kept >= 2u);
  BOOST_TEST_REQUIRE(kept < 16u);
  // a table of the rows finished so far, each the uninterrupted sweep's row
  BOOST_TEST(killed.at("runs").get<int>() == 16);
  bool failed_kept = false;
  for (const Json& row : killed.at("rows")) {
    const std::size_t i = row.at("index").get<std::size_t>();
    Json a = row, b = expected.at("rows").at(i);
    a.erase("cpu_seconds"), b.erase("cpu_seconds");
    if (a.at("run").is_object()) a["run"] = untimed(a.at("run")), b["run"] = untimed(b.at("run"));
    BOOST_TEST(a == b, "row " << i);
    failed_kept = failed_kept || row.at("status") == "failed";
  }
  BOOST_TEST_REQUIRE(failed_kept);  // rows run in order: the failed row 1 is among them

  const Output r = dvm(with({"--out", cut, "--resume"}));
  BOOST_TEST(r.status == 3, r.err);
  const Json resumed = parse_json(slurp(cut + ".json"));
  BOOST_TEST(untimed_table(resumed) == untimed_table(expected));
  BOOST_TEST(untimed_csv(slurp(cut + ".csv")) == untimed_csv(slurp(whole + ".csv")));
  // the kept rows, failed ones included, were not run again: the same timings
  for (const Json& row : killed.at("rows")) {
    const Json& again = resumed.at("rows").at(row.at("index").get<std::size_t>());
    BOOST_TEST(again.at("cpu_seconds") == row.at("cpu_seconds"));
    BOOST_TEST(again.at("run").at("wall_seconds") == row.at("run").at("wall_seconds"));
  }
  // a complete table resumed runs nothing and is written again as it was
  const std::string before = slurp(cut + ".json");
  const Output again = dvm(with({"--out", cut, "--resume"}));
  BOOST_TEST(again.status == 3, again.err);
  BOOST_TEST(slurp(cut + ".json") == before);
}

BOOST_AUTO_TEST_CASE(resume_refuses_the_table_of_another_sweep_and_needs_out) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const std::string other = write_scene("other.toml", std::string(kHarmonic) + "# another text\n");
  const std::string out = temp_dir() + "/resumed";
  const std::vector<std::string> vary = {"--vary", "integrator.step=[0.1, 0.05]", "--vary",
                                         "integrator.composition=[none, suzuki5]"};
  std::vector<std::string> args = {"sweep", s, "--out", out};
  args.insert(args.end(), vary.begin(), vary.end());
  BOOST_TEST_REQUIRE(dvm(args).status == 0);
  const std::string json = slurp(out + ".json"), csv = slurp(out + ".csv");
  struct Case {
    std::vector<std::string> args;
    std::vector<std::string> expect;
  };
  const std::vector<Case> cases = {
      {{"sweep", other, "--out", out, "--resume", "--vary", "integrator.step=[0.1, 0.05]", "--vary",
        "integrator.composition=[none, suzuki5]"},
       {"another sweep", "the scene file is", other}},
      {{"sweep", s, "--out", out, "--resume", "--vary", "integrator.step=[0.1, 0.05]", "--vary",
        "integrator.map=[midpoint, theta]"},
       {"another sweep", "varied keys", "integrator.composition", "integrator.map"}},
      {{"sweep", s, "--out", out, "--resume", "--vary", "integrator.step=[0.1, 0.025]", "--vary",
        "integrator.composition=[none, suzuki5]"},
       {"another sweep", "--vary integrator.step", "0.025"}},
      {{"sweep", s, "--out", out, "--resume", "--zip", "--vary", "integrator.step=[0.1, 0.05]", "--vary",
        "integrator.composition=[none, suzuki5]"},
       {"another sweep", "--zip", "product"}},
      {{"sweep", s, "--out", out, "--resume", "--error", "--vary", "integrator.step=[0.1, 0.05]", "--vary",
        "integrator.composition=[none, suzuki5]"},
       {"another sweep", "--error"}},
      {{"sweep", s, "--out", out, "--resume", "--set", "initial.q=[2.0]", "--vary", "integrator.step=[0.1, 0.05]",
        "--vary", "integrator.composition=[none, suzuki5]"},
       {"another sweep", "--set", "initial.q"}},
      {{"sweep", s, "--resume", "--vary", "integrator.step=[0.1, 0.05]"}, {"--resume needs --out"}},
  };
  for (const Case& c : cases) {
    const Output o = dvm(c.args);
    BOOST_TEST(o.status == 2, o.err);
    for (const std::string& e : c.expect) BOOST_TEST(o.err.find(e) != std::string::npos, e << " in: " << o.err);
    // the table is left as it was
    BOOST_TEST(slurp(out + ".json") == json);
    BOOST_TEST(slurp(out + ".csv") == csv);
  }
  // the scene's text changed under the same path
  write_scene("harmonic.toml", std::string(kHarmonic) + "# edited\n");
  args.push_back("--resume");
  const Output edited = dvm(args);
  BOOST_TEST(edited.status == 2, edited.err);
  BOOST_TEST(edited.err.find("the scene's text") != std::string::npos, edited.err);
  BOOST_TEST(slurp(out + ".json") == json);
  // a table that is not one
  std::ofstream(out + ".json") << "{\"json_version\": 1, \"rows\": [";
  const Output broken = dvm(args);
  BOOST_TEST(broken.status == 2, broken.err);
  BOOST_TEST(broken.err.find("not a JSON table of dvm sweep") != std::string::npos, broken.err);
  // with no table yet, every run runs (and stderr says so)
  std::vector<std::string> fresh = {"sweep", s, "--out", temp_dir() + "/fresh", "--resume"};
  fresh.insert(fresh.end(), vary.begin(), vary.end());
  const Output f = dvm(fresh);
  BOOST_TEST(f.status == 0, f.err);
  BOOST_TEST(f.err.find("no table") != std::string::npos, f.err);
  BOOST_TEST(parse_json(slurp(temp_dir() + "/fresh.json")).at("ok").get<int>() == 4);
}

// --max-error: the largest distance from the exact solution over the steps, which is
// what the trajectory `dvm run` writes gives, row by row, against the closed form.
BOOST_AUTO_TEST_CASE(max_error_along_the_run_is_that_of_the_written_trajectory) {
  // harmonic, omega = 2: q(t) = q0 cos(2t) + p0/2 sin(2t), p(t) = -2 q0 sin(2t) + p0 cos(2t);
  // 100 steps, over which the largest error is not the last
  std::string text = kHarmonic;
  text.replace(text.find("steps = 30"), 10, "steps = 100");
  const std::string s = write_scene("harmonic100.toml", text);
  const Json j = sweep_json({"sweep", s, "--max-error", "--set", "system.params.omega=2.0", "--vary",
                             "integrator.composition=[none, suzuki5]", "--vary", "integrator.step=[0.1, 0.05]"},
                            temp_dir() + "/max", 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 4u);
  BOOST_TEST(j.at("errors") == Json::parse(R"(["error", "max_error"])"));
  int larger = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    const Json& row = j.at("rows").at(i);
    const std::string csv = temp_dir() + "/trajectory.csv";
    const Output r = run_alone(s, row, {"--set", "system.params.omega=2.0"});
    BOOST_TEST_REQUIRE(r.status == 0, r.err);
    std::vector<std::string> args = {"run", s, "--csv", csv, "--set", "system.params.omega=2.0"};
    for (const auto& [key, value] : row.at("values").items()) args.insert(args.end(), {"--set", key + "=" + set_value(value)});
    const Output written = dvm(args);
    BOOST_TEST_REQUIRE(written.status == 0, written.err);
    const auto rows = csv_rows(slurp(csv));
    BOOST_TEST_REQUIRE(rows.size() == 102u);  // the header, t = 0 and 100 steps
    const std::size_t tc = column(rows[0], "t"), qc = column(rows[0], "q0"), pc = column(rows[0], "p0");
    double most = 0.0;
    for (std::size_t k = 1; k < rows.size(); ++k) {
      const double t = std::stod(rows[k][tc]), q = std::stod(rows[k][qc]), p = std::stod(rows[k][pc]);
      const double qe = std::cos(2 * t) + 0.25 * std::sin(2 * t), pe = -2 * std::sin(2 * t) + 0.5 * std::cos(2 * t);
      most = std::fmax(most, std::fmax(std::fabs(q - qe), std::fabs(p - pe)));
    }
    const double max_error = row.at("max_error").get<double>(), error = row.at("error").get<double>();
    // the closed form evaluated two ways differs by round-off only
    BOOST_TEST(std::fabs(max_error - most) <= 1e-14, max_error << " vs " << most);
    BOOST_TEST(max_error >= error);
    larger += max_error > error * (1 + 1e-9);
    // the run itself is the one without --max-error (monitor_every is 1)
    BOOST_TEST(untimed(parse_json(r.out)) == untimed(row.at("run")));
  }
  BOOST_TEST(larger >= 2);  // the largest error is not always the final one
  // the CSV's max_error column, after error
  const auto csv = csv_rows(slurp(temp_dir() + "/max.csv"));
  BOOST_TEST(column(csv[0], "max_error") == column(csv[0], "error") + 1);
  for (std::size_t i = 0; i < 4; ++i)
    BOOST_TEST(std::strtod(csv[i + 1][column(csv[0], "max_error")].c_str(), nullptr) ==
               j.at("rows").at(i).at("max_error").get<double>());
  // a system without an exact solution: refused, naming the flag
  const std::string pendulum = write_scene("pendulum.toml", kPendulum);
  const Output o = dvm({"sweep", pendulum, "--max-error", "--vary", "integrator.step=[0.05, 0.025]"});
  BOOST_TEST(o.status == 2, o.err);
  BOOST_TEST(o.err.find("--max-error") != std::string::npos, o.err);
  BOOST_TEST(o.err.find("no exact solution") != std::string::npos, o.err);
}

// A sweep of a scene with [system] forces: its work and energy balance in the table,
// each row's as its run reports them; the work grows with the damping (none at c = 0).
BOOST_AUTO_TEST_CASE(a_sweep_of_a_forced_scene_tabulates_the_work_and_the_energy_balance) {
  const Json j = sweep_json({"sweep", scene("damped_oscillator.toml"), "--vary", "system.params.c=[0.0, 0.1, 0.5]",
                             "--vary", "integrator.t_end=[10.0]"},
                            temp_dir() + "/forced", 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 3u);
  const auto csv = csv_rows(slurp(temp_dir() + "/forced.csv"));
  BOOST_TEST_REQUIRE(csv.size() == 4u);
  const std::vector<std::string>& head = csv.front();
  double previous = 1.0;
  for (std::size_t i = 0; i < 3; ++i) {
    const Json& run = j.at("rows").at(i).at("run");
    BOOST_TEST(run.at("forced").get<bool>());
    const double W = std::strtod(csv[i + 1][column(head, "work")].c_str(), nullptr);
    BOOST_TEST(W == run.at("work").get<double>());
    BOOST_TEST(std::strtod(csv[i + 1][column(head, "max_abs_energy_balance")].c_str(), nullptr) ==
               run.at("max_abs_energy_balance").get<double>());
    BOOST_TEST(run.at("max_abs_energy_balance").get<double>() <= 1e-14);
    BOOST_TEST(W < previous);
    previous = W;
  }
  BOOST_TEST(j.at("rows").at(0).at("run").at("work").get<double>() == 0.0);
}

// A sweep of a constrained scene tabulates the constraint residuals (the run's own;
// the columns are empty for unconstrained rows), here over the step of the Cartesian
// pendulum.
BOOST_AUTO_TEST_CASE(a_sweep_of_a_constrained_scene_tabulates_the_constraint_residuals) {
  const Json j = sweep_json({"sweep", scene("pendulum_cartesian.toml"), "--vary", "integrator.step=[0.01, 0.02]",
                             "--vary", "integrator.t_end=[5.0]"},
                            temp_dir() + "/constrained", 0);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 2u);
  const auto csv = csv_rows(slurp(temp_dir() + "/constrained.csv"));
  BOOST_TEST_REQUIRE(csv.size() == 3u);
  const std::vector<std::string>& head = csv.front();
  for (std::size_t i = 0; i < 2; ++i) {
    const Json& run = j.at("rows").at(i).at("run");
    BOOST_TEST(run.at("constrained").get<bool>());
    for (const char* k : {"max_constraint_residual", "max_hidden_constraint_residual"}) {
      BOOST_TEST(std::strtod(csv[i + 1][column(head, k)].c_str(), nullptr) == run.at(k).get<double>());
      BOOST_TEST(run.at(k).get<double>() <= 1e-13);
    }
  }
}
