// The parallel efficiency of dvm sweep on one machine: one sweep of mixed cost run on
// 1 thread and on J threads (default 2) in the same process, wall time of each, and
// the efficiency T_1 / (J T_J) (1: perfect). The rows differ in cost by two orders
// of magnitude: the pendulum with h = 0.01 over 20 step counts from 500 to 10^4,
// times 10 compositions of the midpoint map (1 to 17 substeps), so a static split of
// the rows would leave a thread idle; the sweep schedules them dynamically. Also
// checks that the two tables hold the same final states, to the bit.
//
// usage: bench_sweep [--jobs J] [--repeats R]   (best of R per job count, default 3)
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "solvers/runtime/sweep.h"

namespace {

const char* kScene =
    "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [2.0]\np = [0.0]\n"
    "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nsteps = 100\n";

double wall(const dvm::SweepOptions& o, dvm::SweepReport& rep) {
  const auto t0 = std::chrono::steady_clock::now();
  rep = dvm::run_sweep(o);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  int jobs = 2, repeats = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--jobs" && i + 1 < argc) {
      jobs = std::atoi(argv[++i]);
    } else if (a == "--repeats" && i + 1 < argc) {
      repeats = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_sweep [--jobs J] [--repeats R]\n");
      return 2;
    }
  }
  if (jobs < 2 || repeats < 1) {
    std::fprintf(stderr, "bench_sweep: --jobs >= 2 and --repeats >= 1 required\n");
    return 2;
  }
  dvm::SweepOptions o;
  o.scene_path = "bench_sweep.toml";
  o.scene_text = kScene;
  o.axes.push_back(dvm::parse_vary("integrator.steps=500:10000:20", o.max_runs));
  o.axes.push_back(dvm::parse_vary("integrator.composition=[none, triple-jump, suzuki5, kahan-li6, kahan-li8, "
                                   "mclachlan4, yoshida6a, yoshida6b, yoshida8a, suzuki-umeno8]",
                                   o.max_runs));
  const std::size_t n = dvm::sweep_size(o);
  double t1 = INFINITY, tj = INFINITY;
  dvm::SweepReport one, many;
  for (int r = 0; r < repeats; ++r) {
    o.jobs = 1;
    t1 = std::fmin(t1, wall(o, one));
    o.jobs = jobs;
    tj = std::fmin(tj, wall(o, many));
  }
  bool same = one.rows.size() == many.rows.size() && one.ok == many.ok;
  for (std::size_t i = 0; same && i < one.rows.size(); ++i)
    same = one.rows[i].status == many.rows[i].status && one.rows[i].report.q_final == many.rows[i].report.q_final &&
           one.rows[i].report.p_final == many.rows[i].report.p_final;
  std::printf("sweep of %zu runs (%zu ok, %zu failed, %zu refused), best of %d\n", n, one.ok, one.failed, one.refused,
              repeats);
  std::printf("  1 thread   %8.3f s\n  %d threads  %8.3f s\n  speed-up %.2f, parallel efficiency %.2f\n", t1, jobs, tj,
              t1 / tj, t1 / (jobs * tj));
  std::printf("  final states on 1 and %d threads: %s\n", jobs, same ? "identical" : "DIFFERENT");
  return same ? 0 : 1;
}
