// The benchmark programs of `make charts` run on a tiny size and write well-formed
// output: every CSV has its header and rows of the same width, with finite numbers
// wherever a run converged; the gnuplot data and the README tables are written.
// (Benchmarks are not unit tests: nothing here judges a timing.)
#define BOOST_TEST_MODULE bench_output
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tests/cli/temp_files.h"

namespace {

using cli_test::slurp;
using cli_test::temp_dir;  // removed when the test exits

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

}  // namespace

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
  for (const auto& r : read_csv(dir + "/references.csv", "problem,reference,agreement")) BOOST_TEST(finite_number(r[2]));
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
}
