// Pieces of a run's report shared by every runner of the dvm program.
#pragma once

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

// The message on stderr for a run stopped by a step that did not converge.
inline void print_failure(const RunSummary& run, double step) {
  std::fprintf(stderr,
               "dvm: step %lld (t = %.17g -> %.17g) did not converge: residual %.3e against scale %.3e after %d "
               "iterations (%s); stopped, output holds the %lld converged steps\n",
               static_cast<long long>(run.failed_step), run.failed_time, run.failed_time + step, run.failure.residual,
               run.failure.scale, run.failure.iterations, run.failure.message.c_str(),
               static_cast<long long>(run.steps_done));
}

}  // namespace dvm::cli
