// What the step benchmarks share: the best of several timed runs of one step, and their
// options --steps N and --repeats R.
#pragma once

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "solvers/integrate.h"

namespace dvm::bench {

struct Result {
  double ns_per_step = INFINITY;
  std::vector<double> state;  // (q, p) at the end of the best run
};

// The best of `repeats` runs of `steps` steps of `step` from (q0, p0) with velocity v0
// (wall time): ns per step and the final state; a failed run ends the program with
// status 3.
template <class Step, class V>
Result time_steps(const Step& step, const V& q0, const V& p0, const V& v0, std::int64_t steps, int repeats,
                  const std::string& what) {
  Result best;
  for (int r = 0; r < repeats; ++r) {
    V q = q0, p = p0;
    const auto t0 = std::chrono::steady_clock::now();
    const RunSummary run = integrate(step, 0.0, q, p, v0, steps, [](auto&&...) {});
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                      static_cast<double>(steps);
    if (run.failed) {
      std::fprintf(stderr, "%s: run failed at step %lld: %s\n", what.c_str(), static_cast<long long>(run.failed_step),
                   run.failure.message.c_str());
      std::exit(3);
    }
    if (ns < best.ns_per_step) {
      best.ns_per_step = ns;
      best.state.assign(q.data(), q.data() + q.size());
      best.state.insert(best.state.end(), p.data(), p.data() + p.size());
    }
  }
  return best;
}

// The largest difference between two final states.
inline double state_diff(const Result& a, const Result& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.state.size(); ++i) m = std::fmax(m, std::fabs(a.state[i] - b.state[i]));
  return m;
}

// Reads --steps N and --repeats R (steps and repeats hold their defaults on entry); any
// other argument, or a value below 1, prints the usage and exits with status 2.
inline void parse_steps_and_repeats(int argc, char** argv, const char* program, std::int64_t& steps, int& repeats) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--steps" && i + 1 < argc)
      steps = std::atoll(argv[++i]);
    else if (a == "--repeats" && i + 1 < argc)
      repeats = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr, "usage: %s [--steps N] [--repeats R]\n", program);
      std::exit(2);
    }
  }
  if (steps < 1 || repeats < 1) {
    std::fprintf(stderr, "%s: --steps and --repeats must be positive\n", program);
    std::exit(2);
  }
}

}  // namespace dvm::bench
