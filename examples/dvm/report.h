// Pieces of a run's report shared by every runner of the dvm program.
#pragma once

#include <cmath>
#include <cstdio>
#include <cstdlib>
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

// x with the fewest significant digits (up to 17) that read back as x: 0.21, not
// 0.20999999999999999, in messages.
inline std::string shortest(double x) {
  char buf[32];
  for (int digits = 15; digits <= 17; ++digits) {
    std::snprintf(buf, sizeof buf, "%.*g", digits, x);
    if (std::strtod(buf, nullptr) == x) break;
  }
  return buf;
}
inline std::string sci(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3e", x);
  return buf;
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
                 "dvm: step %lld (t = %s -> %s) did not converge: residual %.3e against scale %.3e after %d "
                 "iterations (%s)",
                 static_cast<long long>(run.failed_step), shortest(run.failed_time).c_str(),
                 shortest(run.failed_time + step).c_str(), f.residual, f.scale, f.iterations, f.message.c_str());
  else  // (a non-finite residual is named in the message already)
    std::fprintf(stderr, "dvm: step %lld (t = %s -> %s) failed: %s%s", static_cast<long long>(run.failed_step),
                 shortest(run.failed_time).c_str(), shortest(run.failed_time + step).c_str(), f.message.c_str(),
                 std::isfinite(f.residual) ? (" (residual " + sci(f.residual) + ")").c_str() : "");
  std::fprintf(stderr, "; stopped after %lld completed steps%s%s\n", static_cast<long long>(run.steps_done),
               kept.empty() ? "" : "; their rows are in ", kept.c_str());
}

}  // namespace dvm::cli
