// Sweep tables compared across runs of dvm sweep (test_cli_sweep, test_cli_sweep_mpi):
// the JSON and CSV without the fields that measure time, the CSV as cells; and long
// runs sized by the speed of the build under test, for the sweeps those suites stop.
#pragma once

#include <boost/test/unit_test.hpp>

#include <algorithm>
#include <sstream>
#include <string>
#include <vector>

#include "tests/cli/cli_harness.h"

namespace cli_test {

// A run's JSON without the fields that measure time.
inline Json untimed(Json j) {
  j.erase("wall_seconds");
  j.erase("compile_seconds");
  return j;
}

// The CSV as rows of cells (no cell in these tests holds a comma or a quote, except
// messages, which are compared through the JSON).
inline std::vector<std::vector<std::string>> csv_rows(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::string cell;
    bool quoted = false;
    for (char c : line) {
      if (c == '"') quoted = !quoted;
      else if (c == ',' && !quoted) cells.push_back(cell), cell.clear();
      else cell += c;
    }
    cells.push_back(cell);
    rows.push_back(cells);
  }
  return rows;
}

inline std::size_t column(const std::vector<std::string>& head, const std::string& name) {
  for (std::size_t k = 0; k < head.size(); ++k)
    if (head[k] == name) return k;
  BOOST_FAIL("no column " << name);
  return 0;
}

// A table without the fields that measure time: the JSON's rows' cpu_seconds and their
// runs' wall_seconds and compile_seconds.
inline Json untimed_table(Json j) {
  for (Json& row : j.at("rows")) {
    row.erase("cpu_seconds");
    if (row.at("run").is_object()) row["run"] = untimed(row.at("run"));
  }
  return j;
}

// The CSV's rows with the cells of the columns that measure time emptied.
inline std::vector<std::vector<std::string>> untimed_csv(const std::string& text) {
  auto rows = csv_rows(text);
  BOOST_TEST_REQUIRE(!rows.empty());
  const std::size_t wall = column(rows[0], "wall_seconds"), cpu = column(rows[0], "cpu_seconds");
  for (std::size_t i = 1; i < rows.size(); ++i)
    for (std::size_t k : {wall, cpu})
      if (k < rows[i].size()) rows[i][k].clear();
  return rows;
}

// A scene of the midpoint pendulum whose run lasts about `seconds` on the machine and
// build running the test, written as `name`: its step count measured by the fastest of
// three runs of a probe (a probe slowed by the machine's other work would size the run
// too short for a quieter moment after it), never fewer than the probe's. A fixed count
// is not enough for a test that must stop a sweep midway: the same count runs many times
// faster in one build (or machine) than in another.
inline std::string write_long_pendulum(const std::string& name, double seconds) {
  const std::string head =
      "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [1.0]\np = [0.0]\n"
      "[integrator]\nmap = \"midpoint\"\nstep = 0.001\nsteps = ";
  const long probe_steps = 200000;
  const std::string probe = write_scene("probe.toml", head + std::to_string(probe_steps) + "\n");
  double probe_seconds = 1e30;
  for (int i = 0; i < 3; ++i) {
    const Output timed = dvm({"run", probe, "--json", "--no-output"});
    BOOST_TEST_REQUIRE(timed.status == 0, timed.err);
    probe_seconds = std::min(probe_seconds, parse_json(timed.out).at("wall_seconds").get<double>());
  }
  probe_seconds = std::max(probe_seconds, 1e-3);
  const long steps = std::max(probe_steps, static_cast<long>(seconds * static_cast<double>(probe_steps) / probe_seconds));
  BOOST_TEST_MESSAGE("runs of " << steps << " steps");
  return write_scene(name, head + std::to_string(steps) + "\n");
}

}  // namespace cli_test
