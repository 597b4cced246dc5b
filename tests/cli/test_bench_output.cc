// The benchmark programs of `make charts` (where built: DVM_BUILD_BENCH=ON) run on a tiny size and write well-formed
// output: every CSV has its header and rows of the same width, with finite numbers
// wherever a run converged; the harmonic sweeps show each method's order, the two
// independent references of each problem agree to round-off, and the two ways
// bench_ratios steps the same composition end at the same state; the gnuplot data and
// the README tables are written. And bench_galerkin_kepler's smoke run (`make bench`):
// its tables parsed and held to what the methods are.
// (Benchmarks are not unit tests: nothing here judges a timing.)
#define BOOST_TEST_MODULE bench_output
#include <boost/test/unit_test.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "tests/cli/temp_files.h"

namespace {

using cli_test::slurp;
using cli_test::temp_dir;  // removed when the test exits

#ifdef DVM_CHARTS  // (the chart and ratio programs' checks)
std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') quoted = !quoted;
    if (c == sep && !quoted) {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

bool finite_number(const std::string& s) {
  char* end = nullptr;
  const double x = std::strtod(s.c_str(), &end);
  return end != s.c_str() && *end == '\0' && std::isfinite(x);
}

// The rows of a CSV under `header` (checked), each of the header's width.
std::vector<std::vector<std::string>> read_csv(const std::string& path, const std::string& header) {
  std::istringstream in(slurp(path));
  std::string line;
  BOOST_REQUIRE_MESSAGE(std::getline(in, line), path << " is empty");
  BOOST_REQUIRE_EQUAL(line, header);
  const std::size_t width = split(header, ',').size();
  std::vector<std::vector<std::string>> rows;
  while (std::getline(in, line)) {
    rows.push_back(split(line, ','));
    BOOST_REQUIRE_MESSAGE(rows.back().size() == width, path << ": row of width " << rows.back().size() << ": " << line);
  }
  BOOST_REQUIRE_MESSAGE(!rows.empty(), path << " has no rows");
  return rows;
}
#endif  // DVM_CHARTS

}  // namespace

// The chart and ratio programs are built where the benchmark programs are
// (DVM_BUILD_BENCH=ON: `make test TEST_BENCH=ON`), not by a plain `make test`.
#ifdef DVM_CHARTS
BOOST_AUTO_TEST_CASE(charts_program_writes_well_formed_csv) {
  const std::string dir = temp_dir();
  const std::string cmd = std::string(DVM_CHARTS) + " --tiny --out " + dir + " 2>" + dir + "/log.txt";
  BOOST_REQUIRE_EQUAL(std::system(cmd.c_str()), 0);

  const auto wp = read_csv(dir + "/work_precision.csv",
                           "problem,method,family,order,implicit,chart,h,steps,error,max_energy_error,cpu_seconds,"
                           "converged");
  int converged = 0;
  for (const auto& r : wp) {
    BOOST_TEST(finite_number(r[6]));  // h
    BOOST_TEST(finite_number(r[7]));  // steps
    if (r[11] == "1" && finite_number(r[8]) && std::strtod(r[8].c_str(), nullptr) <= 1.0) {
      ++converged;
      BOOST_TEST(finite_number(r[9]), r[0] << " " << r[1] << " energy " << r[9]);
      BOOST_TEST(finite_number(r[10]), r[0] << " " << r[1] << " cpu " << r[10]);
    }
  }
  BOOST_TEST(converged > 100);
  // The error slopes on the harmonic oscillator (exact solution) are the methods' orders:
  // between the coarsest and the finest step of each method's sweep whose errors lie in
  // [1e-13, 0.1], log(e1/e2)/log(h1/h2) is at least the order less 0.25 (at least 5.75
  // for orders above 6, which the tiny sweep's steps need not reach asymptotically) and
  // at most the order plus 0.5. A composition that lost a stage would fall to order 1 or 2.
  {
    std::map<std::string, std::vector<std::pair<double, double>>> sweeps;  // method -> (h, error)
    std::map<std::string, int> order;
    for (const auto& r : wp) {
      if (r[0] != "harmonic" || r[11] != "1") continue;
      const double e = std::strtod(r[8].c_str(), nullptr);
      if (!(e >= 1e-13 && e <= 0.1)) continue;
      sweeps[r[1]].emplace_back(std::strtod(r[6].c_str(), nullptr), e);
      order[r[1]] = std::atoi(r[3].c_str());
    }
    int fitted = 0;
    for (auto& [method, points] : sweeps) {
      if (points.size() < 2) continue;
      std::sort(points.begin(), points.end());
      const double slope = std::log(points.back().second / points.front().second) /
                           std::log(points.back().first / points.front().first);
      const int p = order[method];
      BOOST_TEST(slope >= std::min(p, 6) - 0.25, method << ": order " << p << ", slope " << slope);
      BOOST_TEST(slope <= p + 0.5, method << ": order " << p << ", slope " << slope);
      ++fitted;
    }
    BOOST_TEST(fitted >= 30);
  }
  for (const char* p : {"harmonic", "pendulum", "kepler", "henon-heiles", "fpu", "outer-solar-system", "rigid-body"}) {
    bool seen = false;
    for (const auto& r : wp) seen = seen || r[0] == p;
    BOOST_TEST(seen, p);
    BOOST_TEST(!slurp(dir + "/wp_" + p + ".dat").empty(), p);
  }
  // the Galerkin methods run on Kepler (tiny sweep: 40 and 80 steps to T = 2)
  for (const char* g : {"dvm galerkin gauss s=2", "dvm galerkin gauss s=4", "dvm galerkin gauss s=6"}) {
    bool ok = false;
    for (const auto& r : wp) ok = ok || (r[0] == "kepler" && r[1] == g && r[11] == "1");
    BOOST_TEST(ok, g);
  }
  // and on the rigid body (SO(3), generating functions in charts)
  for (const char* g : {"dvm galerkin gauss s=2", "dvm galerkin gauss s=4"}) {
    bool ok = false;
    for (const auto& r : wp) ok = ok || (r[0] == "rigid-body" && r[1] == g && r[11] == "1");
    BOOST_TEST(ok, "rigid-body " << g);
  }
  // references.csv: per problem, how the reference q(T) the errors are measured against
  // was obtained ("reference") and the max-norm difference of two independent
  // computations of it ("agreement"): an exact solution has nothing to disagree with
  // (0); otherwise dvm's kahan-li8 composition of the midpoint rule (order 8) against
  // Odeint's RKF78 (order 8) with 5 to 10 times as many steps. Both are converged to
  // round-off at these sizes (their truncation errors lie below it: the agreements are
  // 2e-15 .. 9e-14), so their difference is round-off, at most one rounding of q per
  // step or substep: (n_ref x 17 stages + n_check) eps |q|, largest for the outer solar
  // system (|q| ~ 30 au, 40 x 17 + 400 roundings): 7e-12. Asserted: at most 1e-11,
  // and above 0 (0 would mean the reference was compared with itself). The sweeps
  // stop fitting at 10 x the agreement, so a looser reference would hide the errors
  // they measure.
  std::vector<std::string> problems;
  for (const auto& r : wp)
    if (std::find(problems.begin(), problems.end(), r[0]) == problems.end()) problems.push_back(r[0]);
  const auto refs = read_csv(dir + "/references.csv", "problem,reference,agreement");
  BOOST_TEST(refs.size() == problems.size());
  for (const auto& r : refs) {
    BOOST_TEST_CONTEXT(r[0] << ": " << r[1] << ", agreement " << r[2]) {
      BOOST_TEST((std::find(problems.begin(), problems.end(), r[0]) != problems.end()));
      BOOST_REQUIRE(finite_number(r[2]));
      const double agreement = std::strtod(r[2].c_str(), nullptr);
      if (r[1] == "\"exact solution\"") {
        BOOST_TEST(agreement == 0.0);
        continue;
      }
      BOOST_TEST(r[1].find("kahan-li8") != std::string::npos);
      BOOST_TEST(r[1].find("RKF78") != std::string::npos);
      BOOST_TEST(agreement > 0.0);
      BOOST_TEST(agreement <= 1e-11);
      // the note quotes the same number (two significant digits)
      const std::size_t at = r[1].find("agrees to ");
      BOOST_REQUIRE(at != std::string::npos);
      const double quoted = std::strtod(r[1].c_str() + at + 10, nullptr);
      BOOST_TEST(std::fabs(quoted - agreement) <= 0.051 * agreement);
    }
  }
  for (const auto& r : read_csv(dir + "/energy_long.csv", "method,t,max_energy_error_in_block")) {
    BOOST_TEST(finite_number(r[1]));
    BOOST_TEST(finite_number(r[2]));
  }
  for (const auto& r : read_csv(dir + "/stability.csv", "method,family,kind,value"))
    BOOST_TEST((finite_number(r[3]) || r[3] == "inf"), r[0] << " " << r[3]);
  for (const char* t : {"/table_sweeps.md", "/table_long.md", "/table_stability.md"})
    BOOST_TEST(slurp(dir + t).find("| method |") != std::string::npos, t);
}

BOOST_AUTO_TEST_CASE(ratio_program_prints_the_ratios) {
  const std::string dir = temp_dir();
  const std::string cmd = std::string(BENCH_RATIOS) + " --steps 2000 --repeats 1 --out " + dir + " >" + dir +
                          "/ratios.txt 2>&1";
  BOOST_REQUIRE_EQUAL(std::system(cmd.c_str()), 0);
  const std::string md = slurp(dir + "/ratios.md");
  int rows = 0;
  std::istringstream in(md);
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("| ", 0) == 0 && line.find("<=") != std::string::npos) {
      ++rows;
      const auto cells = split(line, '|');
      BOOST_REQUIRE(cells.size() >= 6);
      const std::string ratio = cells[4].substr(1, cells[4].size() - 2);
      // an equal-error ratio is n/a when the tiny sweep does not reach the error
      const bool equal_error = line.find("best dvm") != std::string::npos;
      BOOST_TEST((finite_number(ratio) || (equal_error && ratio == "n/a")), line);
    }
  BOOST_TEST(rows == 6);
  // Stormer-Verlet composed from explicit Euler and its adjoint, stepped by kicks and
  // drifts and by Newton on each substep (use_structure = false), solves the same
  // equations: their final positions on Kepler after the run agree to round-off (a
  // splitting that dropped or misplaced a kick would be O(h) apart)
  const std::size_t at = md.find("(final positions ");
  BOOST_REQUIRE(at != std::string::npos);
  const double apart = std::strtod(md.c_str() + at + 17, nullptr);
  BOOST_TEST(apart <= 1e-11, "final positions " << apart << " apart");
}
#endif  // DVM_CHARTS

namespace {

// A row of bench_galerkin_kepler's tables: the method (text before a run of two or more
// spaces) and the numbers after it ("nan" where there is none).
struct BenchRow {
  std::string method;
  std::vector<double> numbers;
};
std::vector<BenchRow> bench_rows(const std::string& text, const std::string& header) {
  std::vector<BenchRow> rows;
  std::istringstream in(text.substr(text.find(header) + header.size()));
  std::string line;
  std::getline(in, line);  // the rest of the header line
  while (std::getline(in, line) && !line.empty()) {
    const std::size_t gap = line.find("  ");
    if (gap == std::string::npos) break;
    BenchRow r{line.substr(0, gap), {}};
    std::istringstream nums(line.substr(gap));
    std::string w;
    while (nums >> w) r.numbers.push_back(w == "nan" ? NAN : std::strtod(w.c_str(), nullptr));
    rows.push_back(r);
  }
  return rows;
}
const BenchRow* find_row(const std::vector<BenchRow>& rows, const std::string& method) {
  for (const BenchRow& r : rows)
    if (r.method == method) return &r;
  return nullptr;
}

}  // namespace

// bench_galerkin_kepler --smoke: its sweeps are parsed and checked against what the
// methods are (no timing): the fitted orders 2s of Gauss and Lobatto with s stages and
// 4 of Odeint's RKN steppers, s = 6 at round-off, the stage count at run time and the
// runtime's `dvm run` row giving the step's error to the bit, and the ratio lines there.
BOOST_AUTO_TEST_CASE(the_galerkin_benchmark_measures_what_the_methods_are) {
  const std::string dir = temp_dir();
  const std::string cmd = std::string(BENCH_GALERKIN_KEPLER) + " --smoke >" + dir + "/out.txt 2>" + dir + "/log.txt";
  BOOST_REQUIRE_MESSAGE(std::system(cmd.c_str()) == 0, slurp(dir + "/log.txt"));
  const std::string out = slurp(dir + "/out.txt");
  const std::vector<BenchRow> sweep = bench_rows(out, "jac/st");
  const std::vector<BenchRow> summary = bench_rows(out, "min_error");
  BOOST_TEST_REQUIRE(sweep.size() >= 20u, out);
  for (const BenchRow& r : sweep) {
    BOOST_TEST_REQUIRE(r.numbers.size() == 5u, r.method);
    BOOST_TEST(std::isfinite(r.numbers[1]), r.method << ": error");
  }
  const std::vector<std::pair<std::string, double>> orders = {
      {"galerkin gauss s=2", 4}, {"galerkin gauss s=3", 6}, {"galerkin gauss s=4", 8},
      {"galerkin lobatto s=3", 6}, {"odeint rkn_sb3a_mclachlan", 4}, {"odeint rkn_sb3a_m4_mclachlan", 4}};
  for (const auto& [method, order] : orders) {
    const BenchRow* r = find_row(summary, method);
    BOOST_TEST_REQUIRE(r != nullptr, method);
    BOOST_TEST(std::fabs(r->numbers.at(0) - order) <= 0.25, method << ": fitted order " << r->numbers.at(0));
  }
  const BenchRow* s6 = find_row(sweep, "galerkin gauss s=6");
  const BenchRow* run_time = find_row(sweep, "galerkin gauss s=6 (run-time s)");
  const BenchRow* through_run = find_row(sweep, "dvm run gauss s=6");
  BOOST_TEST_REQUIRE((s6 && run_time && through_run));
  BOOST_TEST(s6->numbers[1] <= 1e-13);  // order 12 at 200 steps: round-off
  BOOST_TEST(run_time->numbers[1] == s6->numbers[1]);
  BOOST_TEST(through_run->numbers[1] == s6->numbers[1]);
  BOOST_TEST(through_run->numbers[0] == s6->numbers[0]);
  for (const char* ratio : {"ratio best-odeint / best-galerkin = ", "ratio dvm run / galerkin gauss s=6 at equal steps = "}) {
    const std::size_t at = out.find(ratio);
    BOOST_TEST_REQUIRE(at != std::string::npos, ratio);
    const double x = std::strtod(out.c_str() + at + std::string(ratio).size(), nullptr);
    BOOST_TEST((std::isfinite(x) && x > 0.0), ratio << x);
  }
}
