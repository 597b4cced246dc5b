// Sweep tables compared across runs of dvm sweep (test_cli_sweep, test_cli_sweep_mpi):
// the JSON and CSV without the fields that measure time, the CSV as cells.
#pragma once

#include <boost/test/unit_test.hpp>

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

}  // namespace cli_test
