// The commands of the dvm program. Exit statuses: 0 success, 1 a check that did not
// pass (check-map), 2 bad input or usage, 3 a numerical failure during a run.
#pragma once

#include <cstdint>
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

}  // namespace dvm::cli
