// The commands of the dvm program. Exit statuses: 0 success, 1 a check that did not
// pass (check-map), 2 bad input or usage, 3 a numerical failure during a run.
#pragma once

#include <cmath>
#include <cstdint>
#include <utility>
#include <string>
#include <vector>

#include "solvers/runtime/scene.h"
#include "solvers/runtime/converge.h"

namespace dvm::cli {

struct RunOptions {
  std::string csv;  // overrides [output] csv
  std::string npy;  // overrides [output] npy
  bool json = false;
  bool quiet = false;
  bool no_output = false;  // --no-output: the scene's [output] csv and npy are not written
  std::string linearize;   // --linearize PATH: the derivative of every step (.npy)
  bool converge = false;                 // `dvm converge`: a convergence study instead of a run
  std::vector<std::int64_t> steps_list;  // converge: the step counts (empty: the default)
  double t_end = 0.0;                    // converge: the time span (0: the scene's)
  double max_total_steps = ConvergeOptions::kDefaultMaxTotalSteps;  // converge: --max-steps
};

// `dvm run` and `dvm converge` on a loaded scene (run.cc). Throws InputError.
int run_scene(const Scene& scene, const RunOptions& options);

// Prints the identity residuals of a map as JSON; returns 0 if every identity holds
// to `tolerance`, 1 otherwise. Throws InputError for a bad name, theta or dimension.
// `written`: the retraction of a "sphere-written" or "so3-written" map (from a scene).
int check_map_command(const std::string& name, double theta, int dim, double tolerance,
                      const std::shared_ptr<const WrittenRetraction>& written = nullptr);
// `dvm check-map --scene FILE`: the map the scene runs (a written one from its [map]).
int check_scene_map_command(const std::string& path, const std::vector<std::string>& overrides, int dim,
                            double tolerance);

// Lists the composition methods (order, stages, symmetry, stability threshold) and the
// Galerkin methods as a table or JSON; returns 0.
int methods_command(bool json);

// `dvm chart` (chart.cc): a chart of a table of dvm sweep, drawn by gnuplot.
struct ChartOptions {
  std::string table;                     // PATH.csv or PATH.json of dvm sweep --out
  std::string kind = "work-precision";   // one of chart_kinds()
  std::string x, y, z;                   // columns ("": the kind's defaults)
  std::vector<std::string> by;           // the columns whose values make the lines
  bool by_given = false;                 // --by given (else: the varied keys not on an axis)
  std::vector<std::pair<std::string, std::string>> where;  // rows kept: column = value
  double max_energy_error = NAN;         // stability: unstable above it (NaN: status only)
  std::string log;                       // the logarithmic axes: "x", "y", "xy", "none" ("": the kind's)
  std::string out;                       // the chart, .png or .svg; .dat and .gp beside it
  std::string title;                     // "": one made from the kind and the columns
  bool data_only = false;                // write the data and the script, do not run gnuplot
};
const std::vector<std::string>& chart_kinds();
// Writes the data and the script, runs gnuplot (unless data_only); returns 0, or 3
// when gnuplot fails. Throws InputError for bad input (an unknown kind, a column the
// table lacks, nothing to draw, no gnuplot).
int chart_command(const ChartOptions& options);

}  // namespace dvm::cli
