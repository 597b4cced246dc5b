// Cost per step of the spherical chain (Q = (S^2)^K) with the midpoint map sphere-exp:
//   - at K = 4, the banded step of any number of links (solvers/sphere_chain_step.h)
//     against the compiled step ManifoldStep<SphericalChain<4>, SpherePowerMap<4>>
//     (Newton with the Jacobian from nested Jets), and the largest difference of their
//     end states;
//   - the banded step at K = 10 ... 10^4: ns per link-step, its ratio to K = 100's, and
//     the least-squares exponent a of cost ~ K^a (1 for a cost linear in K).
// The chain hangs with total length and mass 1 (links of length and mass 1/K), bent and
// swinging; h = 2e-4 keeps h omega below 1 for every mode up to K = 10^4. Each size runs
// about the same number of link-steps; the best of three repetitions is kept. The loop
// is `integrate` with no observer work (no energy monitor: a `dvm run` also evaluates
// the energy, one more banded factorisation a step).
//
//   bench_sphere_chain [--max-links K]      (default 10000)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "mechanics/manifold_systems.h"
#include "solvers/integrate.h"
#include "solvers/manifold_step.h"
#include "solvers/sphere_chain_step.h"

using namespace dvm;

namespace {

constexpr double kStep = 2e-4;

// The state of a chain of K links: bent, swinging about the vertical.
void chain_state(int K, Eigen::VectorXd& x, Eigen::VectorXd& v) {
  x.resize(3 * K);
  v.resize(3 * K);
  for (int k = 1; k <= K; ++k) {
    const double f = static_cast<double>(k) / K, a = 0.6 * std::sin(M_PI * f) + 0.2 * f, b = 1.2 * f;
    const Vec<double, 3> xk(std::sin(a) * std::cos(b), std::sin(a) * std::sin(b), -std::cos(a));
    x.segment<3>(3 * (k - 1)) = xk;
    v.segment<3>(3 * (k - 1)) = (0.5 + 0.5 * f) * Vec<double, 3>(0, 0, 1).cross(xk);
  }
}

template <class Step, class Point, class Covector>
double seconds_per_step(const Step& S, Point q, Covector p, const Covector& v0, std::int64_t steps, int& failures,
                        Point* end = nullptr) {
  double best = INFINITY;
  for (int rep = 0; rep < 3; ++rep) {
    Point qk = q;
    Covector pk = p;
    const auto t0 = std::chrono::steady_clock::now();
    const RunSummary r = integrate(S, 0.0, qk, pk, v0, steps, [](auto&&...) {});
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (r.failed) ++failures;
    best = std::fmin(best, s / static_cast<double>(steps));
    if (end) *end = qk;
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  int max_links = 10000;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--max-links") == 0 && i + 1 < argc) {
      max_links = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_sphere_chain [--max-links K]\n");
      return 2;
    }
  }
  const SphereMap f(RetractionKind::exp, 0.5, "sphere-exp");
  int failures = 0;

  // K = 4: compiled against banded
  {
    constexpr int K = 4;
    Eigen::VectorXd x, v;
    chain_state(K, x, v);
    const SphericalChain<K> C(Vec<double, K>::Constant(1.0 / K), Vec<double, K>::Constant(1.0 / K), 9.81);
    const DynamicSphericalChain D(Eigen::VectorXd::Constant(K, 1.0 / K), Eigen::VectorXd::Constant(K, 1.0 / K), 9.81);
    const Vec<double, 3 * K> xs = x, vs = v;
    const Vec<double, 3 * K> ps = manifold_legendre(C, xs, vs);
    const std::int64_t steps = 20000;
    Vec<double, 3 * K> end_compiled;
    Eigen::VectorXd end_banded;
    const double compiled = seconds_per_step(ManifoldStep<SphericalChain<K>, SpherePowerMap<K>>(C, SpherePowerMap<K>(f), kStep),
                                             xs, ps, vs, steps, failures, &end_compiled);
    const double banded = seconds_per_step(SphereChainStep(D, f, kStep), x, chain_legendre(D, x, v), v, steps, failures,
                                           &end_banded);
    std::printf("spherical chain, sphere-exp midpoint, h = %g\n\n", kStep);
    std::printf("K = 4, %lld steps            ns/step\n", static_cast<long long>(steps));
    std::printf("  compiled ManifoldStep   %10.0f\n", 1e9 * compiled);
    std::printf("  banded SphereChainStep  %10.0f   ratio banded/compiled %.2f\n", 1e9 * banded, banded / compiled);
    std::printf("  end states differ by %.1e\n\n", (end_banded - Eigen::VectorXd(end_compiled)).cwiseAbs().maxCoeff());
  }

  // the banded step against K
  std::vector<double> lk, lc;
  std::vector<int> sizes;
  for (int K : {10, 100, 1000, 10000})
    if (K <= max_links) sizes.push_back(K);
  for (int K : sizes) {
    Eigen::VectorXd x, v;
    chain_state(K, x, v);
    const DynamicSphericalChain D(Eigen::VectorXd::Constant(K, 1.0 / K), Eigen::VectorXd::Constant(K, 1.0 / K), 9.81);
    const std::int64_t steps = std::max<std::int64_t>(5, 200000 / K);
    const double s = seconds_per_step(SphereChainStep(D, f, kStep), x, chain_legendre(D, x, v), v, steps, failures);
    lk.push_back(std::log(static_cast<double>(K)));
    lc.push_back(std::log(s));
  }
  std::printf("K         ns/step   ns/link-step   ratio to K = 100\n");
  double per_link_100 = NAN;
  for (std::size_t i = 0; i < sizes.size(); ++i)
    if (sizes[i] == 100) per_link_100 = std::exp(lc[i]) / 100.0;
  for (std::size_t i = 0; i < sizes.size(); ++i) {
    const double s = std::exp(lc[i]), per_link = s / sizes[i];
    std::printf("%-7d %10.0f %14.1f %18.2f\n", sizes[i], 1e9 * s, 1e9 * per_link, per_link / per_link_100);
  }
  if (lk.size() >= 2) {
    double mk = 0, mc = 0;
    for (std::size_t i = 0; i < lk.size(); ++i) {
      mk += lk[i] / lk.size();
      mc += lc[i] / lc.size();
    }
    double num = 0, den = 0;
    for (std::size_t i = 0; i < lk.size(); ++i) {
      num += (lk[i] - mk) * (lc[i] - mc);
      den += (lk[i] - mk) * (lk[i] - mk);
    }
    std::printf("fitted exponent of cost ~ K^a: a = %.2f\n", num / den);
  }
  if (failures > 0) {
    std::printf("%d timed runs failed a step\n", failures);
    return 1;
  }
  return 0;
}
