// Cost per step of the implicit midpoint (variational) step for the FPU chain against
// the number of particles n, and the fitted exponent of cost ~ n^a.
//
// The step solves p0 - m dq/h - (h/2) grad V(q0 + dq/2) = 0 by Newton's method with a
// tridiagonal Jacobian (solvers/chain_step.h), so the cost should grow linearly in n:
// a = 1 up to cache effects. Each size runs about the same total number of
// particle-steps; the best of several repetitions is kept. Prints ns/step, ns per
// particle-step, mean Newton iterations, and the least-squares exponent over the sizes.
//
// For comparison it also times the same step solved as a ceres::Problem built once
// per chain and reused for every step (one residual block per particle on the
// increments of it and its neighbours, SPARSE_NORMAL_CHOLESKY), the general-purpose
// alternative for large systems; the ratio is the measured reason for the
// tridiagonal Newton. Both solve to the same residual tolerance; the maximum
// difference of the end states is printed.
//
//   bench_chain [--max-n N]      (default sizes 1e2, 1e3, 1e4, 1e5)
#include <ceres/ceres.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "solvers/chain_step.h"
#include "solvers/integrate.h"

using namespace dvm;

namespace {

// The midpoint chain step as one ceres::Problem, built once. Nodes are padded with a
// constant zero increment at each wall.
class CeresChainStep {
 public:
  CeresChainStep(const FPUChain& C, double h) : C_(C), h_(h) {
    const int n = C.n;
    q0_.assign(static_cast<std::size_t>(n + 2), 0.0);
    p0_.assign(static_cast<std::size_t>(n + 2), 0.0);
    dq_.assign(static_cast<std::size_t>(n + 2), 0.0);
    for (int i = 1; i <= n; ++i) {
      auto* cost = new ceres::AutoDiffCostFunction<Residual, 1, 1, 1, 1>(new Residual{this, i});
      problem_.AddResidualBlock(cost, nullptr, &dq_[i - 1], &dq_[i], &dq_[i + 1]);
    }
    problem_.SetParameterBlockConstant(&dq_[0]);
    problem_.SetParameterBlockConstant(&dq_[n + 1]);
    options_.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    options_.max_num_iterations = 20;
    options_.function_tolerance = 1e-30;
    options_.gradient_tolerance = 1e-30;
    options_.parameter_tolerance = 1e-15;
    options_.initial_trust_region_radius = 1e12;
    options_.logging_type = ceres::SILENT;
  }
  // (q, p) -> one midpoint step, in place; returns Ceres' iteration count.
  int step(Eigen::VectorXd& q, Eigen::VectorXd& p) {
    const int n = C_.n;
    for (int i = 0; i < n; ++i) {
      q0_[i + 1] = q[i];
      p0_[i + 1] = p[i];
      dq_[i + 1] = h_ * p[i] / C_.m;
    }
    ceres::Solver::Summary summary;
    ceres::Solve(options_, &problem_, &summary);
    Eigen::VectorXd dq(n), x(n), g;
    for (int i = 0; i < n; ++i) dq[i] = dq_[i + 1];
    x = q + 0.5 * dq;
    C_.gradient(x, g);
    q += dq;
    p -= h_ * g;
    return static_cast<int>(summary.iterations.size());
  }

 private:
  struct Residual {
    const CeresChainStep* s;
    int i;  // padded index of the particle
    template <class T>
    bool operator()(const T* dl, const T* dc, const T* dr, T* r) const {
      const auto& S = *s;
      const T xl = S.q0_[i - 1] + 0.5 * dl[0], xc = S.q0_[i] + 0.5 * dc[0], xr = S.q0_[i + 1] + 0.5 * dr[0];
      auto force = [&](const T& d) { return d * (S.C_.k + d * (S.C_.alpha + S.C_.beta * d)); };
      const T g = force(T(xc - xl)) - force(T(xr - xc));
      r[0] = S.p0_[i] - (S.C_.m / S.h_) * dc[0] - (0.5 * S.h_) * g;
      return true;
    }
  };
  FPUChain C_;
  double h_;
  std::vector<double> q0_, p0_, dq_;
  ceres::Problem problem_;
  ceres::Solver::Options options_;
};

void initial_state(int n, Eigen::VectorXd& q, Eigen::VectorXd& p) {
  q.resize(n);
  p = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < n; ++i)
    q[i] = 0.3 * std::sin(M_PI * (i + 1) / (n + 1.0)) + 0.1 * std::sin(7.0 * M_PI * (i + 1) / (n + 1.0));
}

}  // namespace

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
      Eigen::VectorXd q, p;
      initial_state(n, q, p);
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

  // The same steps with a reused ceres::Problem (sparse normal Cholesky).
  std::printf("\nsame step as a ceres::Problem built once (SPARSE_NORMAL_CHOLESKY), 20 steps:\n");
  std::printf("%8s %14s %12s %16s %22s %24s\n", "n", "ns/step", "Ceres it.", "ns/iteration", "ratio to tridiagonal",
              "max |q_ceres - q_tri|");
  for (int n = 100; n <= std::min(max_n, 10000); n *= 10) {
    const FPUChain C(n, 1.0, 1.0, 0.25, 1.0, true);
    const int steps = 20;
    Eigen::VectorXd q, p, qt, pt;
    initial_state(n, q, p);
    initial_state(n, qt, pt);
    CeresChainStep cs(C, h);
    const auto t0 = std::chrono::steady_clock::now();
    int its = 0;
    for (int j = 0; j < steps; ++j) its += cs.step(q, p);
    const double dt = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / steps;
    const ChainStep S(C, ThetaMap::midpoint(), h);
    const auto t1 = std::chrono::steady_clock::now();
    const RunSummary run = integrate(S, 0.0, qt, pt, pt, steps, [](auto&&...) {});
    const double dt2 = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count() / steps;
    if (run.failed) return 1;
    std::printf("%8d %14.0f %12.1f %16.0f %22.1f %24.2e\n", n, dt * 1e9, static_cast<double>(its) / steps,
                dt * 1e9 * steps / its, dt / dt2, max_abs(Eigen::VectorXd(q - qt)));
  }
  return 0;
}
