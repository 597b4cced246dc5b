// dvm chart: the data it writes for gnuplot must be what the sweep's table holds,
// recomputed here from the table's JSON (nlohmann) by the definitions of its help:
// the points of each line, the largest stable step and the smallest unstable one,
// the cells of a heat map and their edges. The stability boundary of the explicit
// compositions on a pendulum of small amplitude must bracket the linear-stability
// thresholds `dvm methods` gives. Bad input exits 2 naming the option or column, with
// nothing written; with gnuplot installed, PNG and SVG files are drawn.
#define BOOST_TEST_MODULE cli_chart
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"
#include "tests/cli/sweep_tables.h"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace cli_test;

// A block of a chart's data file: its title line (quoted, if any) and its rows of
// fields (a quoted field without its quotes).
struct Block {
  std::string title;
  std::vector<std::vector<std::string>> rows;
};

std::vector<std::string> fields(const std::string& line) {
  std::vector<std::string> out;
  std::size_t k = 0;
  while (k < line.size()) {
    if (line[k] == ' ') {
      ++k;
      continue;
    }
    if (line[k] == '"') {
      const std::size_t end = line.find('"', k + 1);
      BOOST_REQUIRE(end != std::string::npos);
      out.push_back(line.substr(k + 1, end - k - 1));
      k = end + 1;
    } else {
      const std::size_t end = std::min(line.find(' ', k), line.size());
      out.push_back(line.substr(k, end - k));
      k = end;
    }
  }
  return out;
}

// The blocks of a data file (separated by blank lines; comment lines skipped); a
// block's first line is its title when it is one quoted string.
std::vector<Block> blocks(const std::string& text, bool titled) {
  std::vector<Block> out;
  std::istringstream in(text);
  std::string line;
  bool open = false;
  while (std::getline(in, line)) {
    if (line.empty()) {
      open = false;
      continue;
    }
    if (line[0] == '#') continue;
    if (!open) {
      out.emplace_back();
      open = true;
      if (titled) {
        BOOST_REQUIRE_MESSAGE(line.front() == '"' && line.back() == '"', "not a title: " << line);
        out.back().title = line.substr(1, line.size() - 2);
        continue;
      }
    }
    out.back().rows.push_back(fields(line));
  }
  return out;
}

double number(const std::string& s) { return std::strtod(s.c_str(), nullptr); }

// Equal as the chart writes them: the same double, or both NaN.
bool same(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

// The lines of the data file that are not comments.
std::string data_lines(const std::string& text) {
  std::istringstream in(text);
  std::string line, out;
  while (std::getline(in, line))
    if (line.empty() || line[0] != '#') out += line + "\n";
  return out;
}

Output chart(std::vector<std::string> args) {
  args.insert(args.begin(), "chart");
  return dvm(args);
}

// Runs the sweep (--out PATH); returns its JSON table.
Json sweep(std::vector<std::string> args, const std::string& out, int status) {
  args.insert(args.end(), {"--out", out});
  const Output o = dvm(args);
  BOOST_TEST_REQUIRE(o.status == status, o.err);
  return parse_json(slurp(out + ".json"));
}

// A harmonic oscillator (exact solution) whose midpoint step fails with one Newton
// iteration.
const char* kHarmonic =
    "[system]\nbuiltin = \"harmonic\"\nparams = { omega = 1.0 }\n"
    "[initial]\nq = [1.0]\np = [0.5]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 40\n";

// A pendulum released at 0.01 rad, Stormer-Verlet as the basic method: a linear
// oscillator with omega = 1 to within 1e-5 of its frequency.
const char* kSmallPendulum =
    "[system]\nbuiltin = \"pendulum\"\nparams = { m = 1.0, l = 1.0, g = 1.0 }\n"
    "[initial]\nq = [0.01]\np = [0.0]\n"
    "[integrator]\nmap = \"explicit-euler\"\nstep = 0.1\nsteps = 4000\n";

// A pendulum whose midpoint solver fails at large steps (from q0 = 2 near h = 1.9),
// to t = 3.2, and for 50 steps.
const char* kPendulum =
    "[system]\nbuiltin = \"pendulum\"\nparams = { m = 1.0, l = 1.0, g = 1.0 }\n"
    "[initial]\nq = [2.0]\np = [0.0]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.1\nt_end = 3.2\n";
const char* kPendulum50 =
    "[system]\nbuiltin = \"pendulum\"\nparams = { m = 1.0, l = 1.0, g = 1.0 }\n"
    "[initial]\nq = [2.0]\np = [0.0]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.1\nsteps = 50\n";

bool has_gnuplot() {
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path ? path : "");
  std::string dir;
  while (std::getline(dirs, dir, ':'))
    if (access(((dir.empty() ? "." : dir) + "/gnuplot").c_str(), X_OK) == 0) return true;
  return false;
}

// The stability boundary of a parameter value's runs, (step, stable) in any order,
// computed here from the table as a stability chart must draw it: the largest step
// whose run and the runs of every smaller step are stable, and the smallest unstable
// step (NaN where there is none).
std::pair<double, double> stability_boundary(std::vector<std::pair<double, bool>> runs) {
  std::sort(runs.begin(), runs.end());
  double stable = NAN, unstable = NAN;
  for (const auto& [h, ok] : runs) {
    if (!ok) {
      unstable = h;
      break;
    }
    stable = h;
  }
  return {stable, unstable};
}

}  // namespace

BOOST_AUTO_TEST_CASE(work_precision_and_error_h_draw_the_ok_rows_of_each_method) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const std::string t = temp_dir() + "/wp";
  const Json j = sweep({"sweep", s, "--error", "--vary", "integrator.composition=[none, suzuki5, kahan-li6]", "--vary",
                        "integrator.step=[0.2, 0.1, 0.05, 0.025]", "--vary", "integrator.max_iterations=[25, 1]"},
                       t, 3);
  BOOST_TEST_REQUIRE(j.at("rows").size() == 24u);
  for (const std::string kind : {"work-precision", "error-h"}) {
    const std::string x = kind == std::string("work-precision") ? "cpu_seconds" : "step";
    const std::string out = temp_dir() + "/" + kind;
    const Output a = chart({t + ".json", "--kind", kind, "--by", "integrator.composition", "--data-only", "--out",
                            out + ".svg"});
    BOOST_TEST_REQUIRE(a.status == 0, a.err);
    BOOST_TEST(!file_exists(out + ".svg"));  // --data-only: gnuplot not run
    const std::string data = slurp(out + ".dat");
    const auto bs = blocks(data, true);
    // expected: per composition, (x, error) of its rows with status ok, in the order
    // of their step
    std::vector<std::string> names;
    std::map<std::string, std::vector<std::array<double, 3>>> expected;
    int left_out = 0;
    for (const Json& row : j.at("rows")) {
      const std::string c = row.at("values").at("integrator.composition");
      if (std::find(names.begin(), names.end(), c) == names.end()) names.push_back(c);
      if (row.at("status") != "ok") {
        ++left_out;
        continue;
      }
      const double xv = x == "step" ? row.at("run").at("step").get<double>() : row.at("cpu_seconds").get<double>();
      expected[c].push_back({row.at("run").at("step").get<double>(), xv, row.at("error").get<double>()});
    }
    BOOST_TEST(left_out == 12);  // the runs with one Newton iteration failed
    BOOST_TEST(data.find("rows left out (not ok, or no finite value to draw): 12\n") != std::string::npos, data);
    BOOST_TEST_REQUIRE(bs.size() == names.size());
    for (std::size_t b = 0; b < bs.size(); ++b) {
      BOOST_TEST(bs[b].title == names[b]);
      auto e = expected[names[b]];
      std::sort(e.begin(), e.end(), [](const auto& p, const auto& q) { return p[0] < q[0]; });
      BOOST_TEST_REQUIRE(bs[b].rows.size() == e.size());
      for (std::size_t k = 0; k < e.size(); ++k) {
        BOOST_TEST(number(bs[b].rows[k][0]) == e[k][1]);
        BOOST_TEST(number(bs[b].rows[k][1]) == e[k][2]);
      }
    }
    // from the CSV table: the same data
    const Output c = chart({t + ".csv", "--kind", kind, "--by", "integrator.composition", "--data-only", "--out",
                            out + "_csv.png"});
    BOOST_TEST_REQUIRE(c.status == 0, c.err);
    BOOST_TEST(data_lines(slurp(out + "_csv.dat")) == data_lines(data));
    // the script draws the data file, by its name, to the chart
    const std::string gp = slurp(out + ".gp");
    BOOST_TEST(gp.find("set terminal svg") != std::string::npos, gp);
    BOOST_TEST(gp.find("set output \"" + kind + ".svg\"") != std::string::npos, gp);
    BOOST_TEST(gp.find("\"" + kind + ".dat\" index i using 1:2") != std::string::npos, gp);
    BOOST_TEST(slurp(out + "_csv.gp").find("set terminal pngcairo") != std::string::npos);
  }
  // without --by, every varied key but the step makes the lines: 6 of them
  const Output d = chart({t + ".json", "--data-only", "--out", temp_dir() + "/by.png"});
  BOOST_TEST_REQUIRE(d.status == 0, d.err);
  const auto bs = blocks(slurp(temp_dir() + "/by.dat"), true);
  BOOST_TEST_REQUIRE(bs.size() == 3u);  // the failed runs leave no points: their lines are not drawn
  BOOST_TEST(bs[0].title == "integrator.composition=none, integrator.max_iterations=25");
  // --where keeps the rows of one value
  const Output w = chart({t + ".json", "--where", "integrator.composition=suzuki5", "--data-only", "--out",
                          temp_dir() + "/where.png"});
  BOOST_TEST_REQUIRE(w.status == 0, w.err);
  const auto ws = blocks(slurp(temp_dir() + "/where.dat"), true);
  BOOST_TEST_REQUIRE(ws.size() == 1u);
  BOOST_TEST(ws[0].title == "25");
  BOOST_TEST(ws[0].rows.size() == 4u);
}

// The largest stable step of each composition of Stormer-Verlet on a pendulum of
// amplitude 0.01 (a linear oscillator with omega = 1 to within 1e-5): each
// composition is run at steps from 0.9 to 1.1 times its threshold h* of `dvm methods`,
// 0.5% apart (--zip), and a run is unstable when its energy error exceeds 1e-2 (200
// times the energy above the minimum). The boundary the chart draws lies within 4% of
// h*: the criterion is not sharp there (on the stable side the energy error of
// Stormer-Verlet grows like 1/(1 - (h omega / 2)^2); on the unstable side a run grows
// slowly), and the slowest, yoshida8b, crosses the bound at 1.035 h*. blanes-moan4
// and blanes-moan6 are left out: their first unstable band is too narrow (|trace| - 2
// < 3e-7) for a run to grow in, and a run past it is stable again.
BOOST_AUTO_TEST_CASE(the_stability_map_of_the_compositions_brackets_the_thresholds_of_dvm_methods) {
  const Output m = dvm({"methods", "--json"});
  BOOST_TEST_REQUIRE(m.status == 0, m.err);
  std::map<std::string, double> threshold;
  std::string compositions = "[", steps = "[";
  char buf[40];
  for (const Json& e : parse_json(m.out)) {
    if (!e.contains("stability_threshold_explicit_euler")) continue;
    const std::string name = e.at("name");
    if (name.rfind("blanes-moan", 0) == 0 || name == "triple-jump:10" || name == "triple-jump:12") continue;
    const double h = e.at("stability_threshold_explicit_euler").get<double>();
    threshold[name] = h;
    for (int k = -20; k <= 20; ++k) {
      std::snprintf(buf, sizeof buf, "%.17g", h * (1 + 0.005 * k));
      compositions += (steps.size() > 1 ? ", \"" : "\"") + name + "\"";
      steps += (steps.size() > 1 ? ", " : "") + std::string(buf);
    }
  }
  BOOST_TEST_REQUIRE(threshold.size() >= 15u);
  const std::string s = write_scene("small.toml", kSmallPendulum);
  const std::string t = temp_dir() + "/stability";
  const Json j = sweep({"sweep", s, "--jobs", "2", "--zip", "--vary", "integrator.composition=" + compositions + "]",
                        "--vary", "integrator.step=" + steps + "]"},
                       t, 0);
  const double bound = 1e-2;
  const Output a = chart({t + ".json", "--kind", "stability", "--max-energy-error", "1e-2", "--data-only", "--out",
                          temp_dir() + "/stability.png"});
  BOOST_TEST_REQUIRE(a.status == 0, a.err);
  const std::string data = slurp(temp_dir() + "/stability.dat");
  const auto bs = blocks(data, true);
  BOOST_TEST_REQUIRE(bs.size() == 1u);  // no other varied key: one line
  // recomputed from the table: per composition, the steps in order and whether stable
  std::vector<std::string> order;
  std::map<std::string, std::vector<std::pair<double, bool>>> runs;
  for (const Json& row : j.at("rows")) {
    const std::string c = row.at("values").at("integrator.composition");
    if (!runs.count(c)) order.push_back(c);
    const double e = json_double(row.at("run").at("max_abs_energy_error"));
    runs[c].emplace_back(row.at("run").at("step").get<double>(),
                         row.at("status") == "ok" && std::isfinite(e) && e <= bound);
  }
  const auto& rows = bs[0].rows;
  BOOST_TEST_REQUIRE(rows.size() == order.size());
  for (std::size_t k = 0; k < order.size(); ++k) {
    const std::string& c = order[k];
    auto r = runs[c];
    const auto [stable, unstable] = stability_boundary(r);
    BOOST_TEST_CONTEXT(c << ": threshold " << threshold[c] << ", stable to " << stable / threshold[c]
                         << " of it, unstable from " << unstable / threshold[c]) {
      BOOST_TEST_REQUIRE(rows[k].size() == 5u);
      BOOST_TEST(number(rows[k][0]) == static_cast<double>(k));
      BOOST_TEST(rows[k][4] == c);
      BOOST_TEST(same(number(rows[k][1]), stable));
      BOOST_TEST(same(number(rows[k][2]), unstable));
      BOOST_TEST(number(rows[k][3]) == r.back().first);
      // against the linear-stability threshold of dvm methods
      BOOST_TEST(std::fabs(stable / threshold[c] - 1) <= 0.04);
      BOOST_TEST(std::fabs(unstable / threshold[c] - 1) <= 0.04);
    }
  }
  // the CSV table gives the same data
  const Output b = chart({t + ".csv", "--kind", "stability", "--x", "integrator.composition", "--max-energy-error",
                          "1e-2", "--data-only", "--out", temp_dir() + "/stability_csv.png"});
  BOOST_TEST_REQUIRE(b.status == 0, b.err);
  BOOST_TEST(data_lines(slurp(temp_dir() + "/stability_csv.dat")) == data_lines(data));
  // without the energy bound only failed runs are unstable, and explicit runs do not fail
  const Output c = chart({t + ".json", "--kind", "stability", "--data-only", "--out", temp_dir() + "/nobound.png"});
  BOOST_TEST_REQUIRE(c.status == 0, c.err);
  const auto nobound = blocks(slurp(temp_dir() + "/nobound.dat"), true);
  BOOST_TEST_REQUIRE(nobound.size() == 1u);
  for (std::size_t k = 0; k < order.size(); ++k) {
    BOOST_TEST(number(nobound[0].rows[k][1]) == runs[order[k]].back().first);
    BOOST_TEST(nobound[0].rows[k][2] == "NaN");
  }
}

// Over a numeric parameter (the amplitude, a list of one number), one line per
// composition: a run is unstable when its solver failed.
BOOST_AUTO_TEST_CASE(the_solver_failure_boundary_over_the_amplitude) {
  const std::string s = write_scene("pendulum50.toml", kPendulum50);
  const std::string t = temp_dir() + "/failure";
  const Json j = sweep({"sweep", s, "--jobs", "2", "--vary", "initial.q=[[0.5], [1.5], [2.5]]", "--vary",
                        "integrator.step=log:0.2:6.4:11", "--vary", "integrator.composition=[none, suzuki5]"},
                       t, 3);
  const Output a = chart({t + ".json", "--kind", "stability", "--x", "initial.q", "--data-only", "--out",
                          temp_dir() + "/failure.png"});
  BOOST_TEST_REQUIRE(a.status == 0, a.err);
  const std::string data = slurp(temp_dir() + "/failure.dat");
  const auto bs = blocks(data, true);
  BOOST_TEST_REQUIRE(bs.size() == 2u);
  int failures = 0;
  for (std::size_t b = 0; b < 2; ++b) {
    const std::string c = b == 0 ? "none" : "suzuki5";
    BOOST_TEST(bs[b].title == c);
    BOOST_TEST_REQUIRE(bs[b].rows.size() == 3u);
    for (std::size_t k = 0; k < 3; ++k) {
      const double q0 = 0.5 + static_cast<double>(k);
      std::vector<std::pair<double, bool>> r;
      for (const Json& row : j.at("rows"))
        if (row.at("values").at("integrator.composition") == c &&
            row.at("values").at("initial.q").at(0).get<double>() == q0)
          r.emplace_back(row.at("values").at("integrator.step").get<double>(), row.at("status") == "ok");
      const auto [stable, unstable] = stability_boundary(r);
      failures += !std::isnan(unstable);
      BOOST_TEST(number(bs[b].rows[k][0]) == q0);
      BOOST_TEST(same(number(bs[b].rows[k][1]), stable), c << " q0 = " << q0);
      BOOST_TEST(same(number(bs[b].rows[k][2]), unstable), c << " q0 = " << q0);
      BOOST_TEST(number(bs[b].rows[k][3]) == 6.4);
    }
  }
  BOOST_TEST(failures >= 2, data);  // the chart shows a boundary
  BOOST_TEST(j.at("failed").get<int>() >= 2);
}

BOOST_AUTO_TEST_CASE(a_heat_map_has_a_cell_per_run_and_marks_the_failed_runs) {
  const std::string s = write_scene("pendulum.toml", kPendulum);
  const std::string t = temp_dir() + "/heat";
  const Json j = sweep({"sweep", s, "--error", "--jobs", "2", "--vary", "integrator.step=[0.1, 0.2, 0.4, 0.8, 1.6, 3.2]",
                        "--vary", "system.params.g=[0.5, 1.0, 2.0, 4.0]"},
                       t, 3);
  const Output a = chart({t + ".json", "--kind", "heat", "--data-only", "--out", temp_dir() + "/heat.png"});
  BOOST_TEST_REQUIRE(a.status == 0, a.err);
  const auto bs = blocks(slurp(temp_dir() + "/heat.dat"), false);
  BOOST_TEST_REQUIRE(bs.size() == 2u);
  std::size_t ok = 0, failed = 0;
  // edges: geometric midpoints along the (logarithmic) step, arithmetic along g
  const std::vector<double> hs = {0.1, 0.2, 0.4, 0.8, 1.6, 3.2}, gs = {0.5, 1.0, 2.0, 4.0};
  auto edge = [](const std::vector<double>& v, std::size_t k, bool log, bool high) {
    auto mid = [&](double a, double b) { return log ? std::sqrt(a * b) : (a + b) / 2; };
    if (high) return k + 1 < v.size() ? mid(v[k], v[k + 1]) : (log ? v[k] * v[k] / mid(v[k - 1], v[k]) : 2 * v[k] - mid(v[k - 1], v[k]));
    return k > 0 ? mid(v[k - 1], v[k]) : (log ? v[0] * v[0] / mid(v[0], v[1]) : 2 * v[0] - mid(v[0], v[1]));
  };
  for (const Json& row : j.at("rows")) {
    const double h = row.at("values").at("integrator.step"), g = row.at("values").at("system.params.g");
    const std::size_t hk = std::find(hs.begin(), hs.end(), h) - hs.begin(), gk = std::find(gs.begin(), gs.end(), g) - gs.begin();
    if (row.at("status") == "ok") {
      const auto& cells = bs[0].rows;
      const auto it = std::find_if(cells.begin(), cells.end(),
                                   [&](const auto& c) { return number(c[0]) == row.at("run").at("step").get<double>() && number(c[1]) == g; });
      BOOST_TEST_REQUIRE((it != cells.end()), "no cell for row " << row.at("index"));
      BOOST_TEST(same(number((*it)[6]), json_double(row.at("error"))));
      BOOST_TEST(number((*it)[2]) == edge(hs, hk, true, false));
      BOOST_TEST(number((*it)[3]) == edge(hs, hk, true, true));
      BOOST_TEST(number((*it)[4]) == edge(gs, gk, false, false));
      BOOST_TEST(number((*it)[5]) == edge(gs, gk, false, true));
      ++ok;
    } else {
      const auto& marks = bs[1].rows;
      BOOST_TEST((std::find_if(marks.begin(), marks.end(), [&](const auto& c) {
                    return number(c[0]) == h && number(c[1]) == g;
                  }) != marks.end()),
                 "failed row " << row.at("index") << " not marked");
      ++failed;
    }
  }
  BOOST_TEST(bs[0].rows.size() == ok);
  BOOST_TEST(bs[1].rows.size() == failed);
  BOOST_TEST(failed >= 1u);
  BOOST_TEST(ok >= 9u);
}

BOOST_AUTO_TEST_CASE(bad_input_exits_2_naming_the_option_or_column_and_writes_nothing) {
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const std::string t = temp_dir() + "/plain";
  sweep({"sweep", s, "--vary", "integrator.composition=[none, suzuki5]", "--vary", "integrator.step=[0.1, 0.05]",
         "--vary", "system.params.omega=[1.0, 2.0]"},
        t, 0);
  const std::string out = temp_dir() + "/refused.png";
  struct Case {
    std::vector<std::string> args;
    std::vector<std::string> expect;
  };
  const std::vector<Case> cases = {
      {{t + ".json", "--kind", "scatter"}, {"--kind", "scatter", "work-precision"}},
      {{t + ".json", "--kind", "work-precison"}, {"--kind", "work-precision"}},
      {{t + ".json"}, {"column 'error'", "dvm sweep --error"}},
      {{t + ".csv", "--kind", "error-h"}, {"column 'error'", "dvm sweep --error"}},
      {{t + ".json", "--kind", "heat", "--z", "max_abs_energy_error"}, {"integrator.composition", "--where"}},
      {{t + ".json", "--kind", "heat", "--y", "system.params.omega"}, {"error", "--error"}},
      {{t + ".json", "--kind", "error-h", "--y", "max_abs_energy_error", "--x", "no_such"}, {"--x", "no_such"}},
      {{t + ".json", "--kind", "error-h", "--y", "max_abs_energy_error", "--by", "nope"}, {"--by", "nope"}},
      {{t + ".json", "--kind", "stability"}, {"--x", "integrator.composition", "system.params.omega"}},
      {{t + ".json", "--kind", "stability", "--x", "system.params.omega", "--where", "system.params.omega=3"},
       {"--where"}},
      {{s, "--kind", "error-h"}, {"not a CSV table of dvm sweep"}},
      {{temp_dir() + "/missing.json"}, {"cannot read"}},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = c.args;
    args.insert(args.end(), {"--data-only", "--out", out});
    const Output o = chart(args);
    BOOST_TEST(o.status == 2, o.err);
    for (const std::string& e : c.expect) BOOST_TEST(o.err.find(e) != std::string::npos, e << " in: " << o.err);
    BOOST_TEST(!file_exists(temp_dir() + "/refused.dat"));
    BOOST_TEST(!file_exists(temp_dir() + "/refused.gp"));
  }
  // the chart's format by the extension
  const Output pdf = chart({t + ".json", "--kind", "error-h", "--y", "max_abs_energy_error", "--out", temp_dir() + "/c.pdf"});
  BOOST_TEST(pdf.status == 2, pdf.err);
  BOOST_TEST(pdf.err.find("--out") != std::string::npos, pdf.err);
  BOOST_TEST(pdf.err.find(".svg") != std::string::npos, pdf.err);
  // no gnuplot: refused before anything is written, unless --data-only
  const std::vector<std::string> draw = {dvm_binary(), "chart", t + ".json", "--kind", "error-h", "--y",
                                         "max_abs_energy_error", "--out", out};
  std::vector<std::string> missing = {"DVM_GNUPLOT=" + temp_dir() + "/no-gnuplot"};
  missing.insert(missing.end(), draw.begin(), draw.end());
  const Output g = run_program("/usr/bin/env", missing);
  BOOST_TEST(g.status == 2, g.err);
  BOOST_TEST(g.err.find("gnuplot not found") != std::string::npos, g.err);
  BOOST_TEST(g.err.find("DVM_GNUPLOT") != std::string::npos, g.err);
  BOOST_TEST(g.err.find("--data-only") != std::string::npos, g.err);
  BOOST_TEST(!file_exists(temp_dir() + "/refused.dat"));
  missing.push_back("--data-only");
  const Output d = run_program("/usr/bin/env", missing);
  BOOST_TEST(d.status == 0, d.err);
  BOOST_TEST(file_exists(temp_dir() + "/refused.dat"));
  BOOST_TEST(!file_exists(out));
}

BOOST_AUTO_TEST_CASE(gnuplot_draws_png_and_svg) {
  if (!has_gnuplot()) {
    BOOST_TEST_MESSAGE("skipped: no gnuplot on PATH (Debian: gnuplot-nox)");
    return;
  }
  const std::string s = write_scene("harmonic.toml", kHarmonic);
  const std::string t = temp_dir() + "/drawn";
  sweep({"sweep", s, "--error", "--vary", "integrator.composition=[none, suzuki5]", "--vary",
         "integrator.step=[0.2, 0.1, 0.05]", "--vary", "system.params.omega=[1.0, 2.0]"},
        t, 0);
  struct Case {
    std::vector<std::string> args;
    std::string out;
  };
  const std::vector<Case> cases = {
      {{"--by", "integrator.composition", "--where", "system.params.omega=1"}, "wp.png"},
      {{"--kind", "error-h"}, "eh.svg"},
      {{"--kind", "stability", "--x", "system.params.omega"}, "st.png"},
      {{"--kind", "stability", "--x", "integrator.composition", "--where", "system.params.omega=2"}, "st.svg"},
      {{"--kind", "heat", "--y", "system.params.omega", "--where", "integrator.composition=suzuki5"}, "heat.png"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = {t + ".json"};
    args.insert(args.end(), c.args.begin(), c.args.end());
    args.insert(args.end(), {"--out", temp_dir() + "/" + c.out});
    const Output o = chart(args);
    BOOST_TEST(o.status == 0, c.out << ": " << o.err);
    BOOST_TEST(o.err.empty(), c.out << ": gnuplot said: " << o.err);
    const std::string drawn = slurp(temp_dir() + "/" + c.out);
    if (c.out.size() > 4 && c.out.substr(c.out.size() - 4) == ".png")
      BOOST_TEST(drawn.substr(0, 4) == "\x89PNG", c.out);
    else
      BOOST_TEST(drawn.find("<svg") != std::string::npos, c.out);
  }
}
