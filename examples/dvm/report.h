// Pieces of a run's report shared by every runner of the dvm program.
#pragma once

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "examples/dvm/json.h"
#include "solvers/integrate.h"

namespace dvm::cli {

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f) std::fclose(f);
  }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

// The "failure" object of the JSON summary.
inline std::string failure_json(const RunSummary& run) {
  Json::Object f;
  f.num("step", static_cast<double>(run.failed_step))
      .num("time", run.failed_time)
      .num("residual", run.failure.residual)
      .num("scale", run.failure.scale)
      .num("iterations", run.failure.iterations)
      .str("message", run.failure.message);
  return f.dump(4);
}

// The message on stderr for a run stopped by a failed step: a solve that did not
// converge (with its residual), a non-finite state, or a map or Legendre transform
// outside its domain. `kept` says where the rows of the completed steps are (empty:
// no output file).
inline void print_failure(const RunSummary& run, double step, const std::string& kept = "") {
  const auto& f = run.failure;
  const bool solve = f.iterations > 0 && std::isfinite(f.residual) && std::isfinite(f.scale);
  if (solve)
    std::fprintf(stderr,
                 "dvm: step %lld (t = %.17g -> %.17g) did not converge: residual %.3e against scale %.3e after %d "
                 "iterations (%s)",
                 static_cast<long long>(run.failed_step), run.failed_time, run.failed_time + step, f.residual, f.scale,
                 f.iterations, f.message.c_str());
  else
    std::fprintf(stderr, "dvm: step %lld (t = %.17g -> %.17g) failed: %s (residual %.3e)",
                 static_cast<long long>(run.failed_step), run.failed_time, run.failed_time + step, f.message.c_str(),
                 f.residual);
  std::fprintf(stderr, "; stopped after %lld completed steps%s%s\n", static_cast<long long>(run.steps_done),
               kept.empty() ? "" : "; their rows are in ", kept.c_str());
}

}  // namespace dvm::cli
