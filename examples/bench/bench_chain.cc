// Cost per step of the implicit midpoint (variational) step for the FPU chain against
// the number of particles n, and the fitted exponent of cost ~ n^a.
//
// The step solves p0 - m dq/h - (h/2) grad V(q0 + dq/2) = 0 by Newton's method with a
// tridiagonal Jacobian (solvers/chain_step.h), so the cost should grow linearly in n:
// a = 1 up to cache effects. Each size runs about the same total number of
// particle-steps; the best of several repetitions is kept. Prints ns/step, ns per
// particle-step, mean Newton iterations, and the least-squares exponent over the sizes.
//
//   bench_chain [--max-n N]      (default sizes 1e2, 1e3, 1e4, 1e5)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "solvers/chain_step.h"
#include "solvers/integrate.h"

using namespace dvm;

int main(int argc, char** argv) {
  int max_n = 100000;
  for (int i = 1; i < argc; ++i)
    if (!std::strcmp(argv[i], "--max-n") && i + 1 < argc) max_n = std::atoi(argv[++i]);
  const double h = 0.02;
  const double particle_steps = 4e6;  // per repetition
  std::vector<double> ns, costs;
  std::printf("FPU chain (k = 1, alpha = 0.25, beta = 1, fixed ends), implicit midpoint, h = %g\n", h);
  std::printf("%8s %8s %14s %22s %12s %14s\n", "n", "steps", "ns/step", "ns/(particle*step)", "iter/step",
              "max|E-E0|/E0");
  for (int n = 100; n <= max_n; n *= 10) {
    const FPUChain C(n, 1.0, 1.0, 0.25, 1.0, true);
    const ChainStep S(C, ThetaMap::midpoint(), h);
    const auto steps = static_cast<std::int64_t>(particle_steps / n);
    double best = INFINITY, iters = 0.0, drift = 0.0;
    for (int rep = 0; rep < 3; ++rep) {
      Eigen::VectorXd q(n), p = Eigen::VectorXd::Zero(n);
      for (int i = 0; i < n; ++i)
        q[i] = 0.3 * std::sin(M_PI * (i + 1) / (n + 1.0)) + 0.1 * std::sin(7.0 * M_PI * (i + 1) / (n + 1.0));
      const double E0 = C.energy(q, p);
      const auto t0 = std::chrono::steady_clock::now();
      const RunSummary run = integrate(S, 0.0, q, p, p, steps, [](auto&&...) {});
      const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (run.failed) {
        std::printf("n = %d: step %lld failed: %s\n", n, static_cast<long long>(run.failed_step),
                    run.failure.message.c_str());
        return 1;
      }
      best = std::fmin(best, dt / static_cast<double>(steps));
      iters = static_cast<double>(run.solver_iterations) / static_cast<double>(steps);
      drift = std::fabs(C.energy(q, p) - E0) / E0;
    }
    std::printf("%8d %8lld %14.0f %22.2f %12.2f %14.2e\n", n, static_cast<long long>(steps), best * 1e9,
                best * 1e9 / n, iters, drift);
    ns.push_back(std::log(static_cast<double>(n)));
    costs.push_back(std::log(best));
  }
  // least-squares slope of log(cost) against log(n)
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double k = static_cast<double>(ns.size());
  for (std::size_t i = 0; i < ns.size(); ++i) {
    sx += ns[i];
    sy += costs[i];
    sxx += ns[i] * ns[i];
    sxy += ns[i] * costs[i];
  }
  const double slope = (k * sxy - sx * sy) / (k * sxx - sx * sx);
  std::printf("fitted exponent of cost per step against n: %.3f (target <= 1.1)\n", slope);
  if (ns.size() >= 3) {
    const double s3 = (costs[2] - costs[0]) / (ns[2] - ns[0]);
    std::printf("exponent over n = 1e2 .. 1e4 alone: %.3f\n", s3);
  }
  return 0;
}
