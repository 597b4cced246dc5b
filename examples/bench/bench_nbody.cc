// Cost per step of n bodies in `dvm run` against a hand-written velocity Verlet with the
// same force loop, for n = 100 and 1000 (or the sizes given).
//
// The problem: n equal masses (total 1, G = 1) on a jittered cubic lattice in the unit
// cube with small random velocities of zero total momentum, a fixed pseudo-random
// sequence. The method: Stormer-Verlet by composition of the adjoint Euler map
// (integrator.map = "adjoint-euler", composition = "stormer-verlet": Phi_{h/2} o
// Phi*_{h/2} is kick, drift, kick), which dvm steps by kicks and drifts on this separable
// Lagrangian (solvers/splitting_step.h), one force per step (the last kick's force is
// the next step's first). The run goes through the runtime API exactly as `dvm run` does (make_run,
// then execute with a Recorder and no output file); its loop time is the report's
// wall_seconds. The baseline is kick-drift-kick with the force of NBodyDynamic::gradient
// (the pair loop dvm uses) reused from the end of one step to the start of the next,
// plain sums, nothing monitored.
//
// Rows: dvm with the energy and invariants monitored every step (the default), and
// every 100 steps (`[output] monitor_every = 100`); each over the baseline's time in the
// same process, best of R repetitions. The last column is how far apart the positions
// of the two are after 20 steps (the same equations: round-off).
//
//   bench_nbody [--sizes 100,1000] [--steps K] [--repeats R]
//   bench_nbody --scene N > cluster.toml     writes the problem as a scene for `dvm run`
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/nbody_dynamic.h"
#include "solvers/runtime/problem.h"
#include "solvers/runtime/recorder.h"
#include "solvers/runtime/run.h"

using namespace dvm;

namespace {

struct Cluster {
  std::vector<double> masses, q, v;
};

// n bodies on a jittered lattice of side ceil(n^(1/3)) in the unit cube.
Cluster cluster(int n) {
  Cluster c;
  std::mt19937_64 rng(20261125);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int side = static_cast<int>(std::ceil(std::cbrt(static_cast<double>(n)) - 1e-9));
  const double a = 1.0 / side;
  double mv[3] = {0.0, 0.0, 0.0};
  for (int i = 0; i < n; ++i) {
    const int x = i % side, y = (i / side) % side, z = i / (side * side);
    const int cell[3] = {x, y, z};
    for (int k = 0; k < 3; ++k) {
      c.q.push_back(a * (cell[k] + 0.5 + 0.2 * u(rng)));
      c.v.push_back(0.1 * u(rng));
      mv[k] += c.v.back();
    }
    c.masses.push_back(1.0 / n);
  }
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) c.v[static_cast<std::size_t>(3 * i + k)] -= mv[k] / n;
  return c;
}

std::string join(const std::vector<double>& x, int per_line) {
  std::ostringstream s;
  s.precision(17);
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (i) s << (per_line > 0 && i % static_cast<std::size_t>(per_line) == 0 ? ",\n     " : ", ");
    s << x[i];
  }
  return s.str();
}

const double kStep = 1e-3;

Problem problem(const Cluster& c, std::int64_t steps) {
  Problem pr;
  pr.system = &find_system_entry("nbody", "bench_nbody");
  pr.params = {{"G", 1.0}};
  pr.masses = c.masses;
  pr.dim = static_cast<int>(c.q.size());
  pr.q = c.q;
  pr.v = c.v;
  pr.step = kStep;
  pr.steps = steps;
  return pr;
}

Method method() {
  Method me;
  me.map = &find_map_entry("adjoint-euler", "bench_nbody");
  me.theta = 1.0;
  me.composition = "stormer-verlet";
  return me;
}

// The hand-written velocity Verlet; returns seconds for `steps` steps, q and p in place.
double hand_verlet(const NBodyDynamic& L, Eigen::VectorXd& q, Eigen::VectorXd& p, std::int64_t steps) {
  const int n = L.dim();
  Eigen::VectorXd F(n), Lv(n), zero = Eigen::VectorXd::Zero(n), inv_m(n);
  for (int i = 0; i < n; ++i) inv_m[i] = 1.0 / L.m(i / 3);
  const auto t0 = std::chrono::steady_clock::now();
  L.gradient(q, zero, F, Lv);
  for (std::int64_t k = 0; k < steps; ++k) {
    p.noalias() += (0.5 * kStep) * F;
    q.noalias() += kStep * inv_m.cwiseProduct(p);
    L.gradient(q, zero, F, Lv);
    p.noalias() += (0.5 * kStep) * F;
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {100, 1000};
  std::int64_t steps = 0;  // 0: about 2e8 pair evaluations per run
  int repeats = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--scene" && i + 1 < argc) {
      const int n = std::atoi(argv[++i]);
      if (n < 2) return std::fprintf(stderr, "bench_nbody: --scene N needs N >= 2\n"), 2;
      const Cluster c = cluster(n);
      std::printf(
          "# %d equal masses (total 1, G = 1) on a jittered cubic lattice in the unit cube, small random\n"
          "# velocities of zero total momentum: written by `bench_nbody --scene %d`.\n"
          "[system]\nbuiltin = \"nbody\"\nparams = { G = 1.0 }\nmasses = [%s]\n\n[initial]\nq = [%s]\nv = [%s]\n\n"
          "[integrator]\nmap = \"adjoint-euler\"\ncomposition = \"stormer-verlet\"\nstep = %g\nsteps = 1000\n\n"
          "[output]\nmonitor_every = 100\n",
          n, n, join(c.masses, 8).c_str(), join(c.q, 6).c_str(), join(c.v, 6).c_str(), kStep);
      return 0;
    } else if (a == "--sizes" && i + 1 < argc) {
      sizes.clear();
      std::stringstream s(argv[++i]);
      for (std::string t; std::getline(s, t, ',');) sizes.push_back(std::atoi(t.c_str()));
    } else if (a == "--steps" && i + 1 < argc) {
      steps = std::atoll(argv[++i]);
    } else if (a == "--repeats" && i + 1 < argc) {
      repeats = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_nbody [--sizes N,N..] [--steps K] [--repeats R] | --scene N\n");
      return 2;
    }
  }
  std::printf("n bodies, velocity Verlet (adjoint-euler composed by stormer-verlet), h = %g; us per step, best of %d\n\n", kStep,
              repeats);
  std::printf("| bodies | steps | hand velocity Verlet | dvm run, monitor_every = 1 | ratio | monitor_every = 100 | ratio "
              "| q apart after 20 steps |\n|---|---|---|---|---|---|---|---|\n");
  for (int n : sizes) {
    if (n < 2) return std::fprintf(stderr, "bench_nbody: sizes must be >= 2\n"), 2;
    const Cluster c = cluster(n);
    const std::int64_t K = steps > 0 ? steps : std::max<std::int64_t>(10, static_cast<std::int64_t>(4e8 / (double(n) * n)));
    const NBodyDynamic L(1.0, c.masses);
    double hand = INFINITY, dvm1 = INFINITY, dvm100 = INFINITY, apart = 0.0;
    for (int r = 0; r < repeats; ++r) {
      Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(c.q.data(), 3 * n), p(3 * n);
      for (int i = 0; i < 3 * n; ++i) p[i] = L.m(i / 3) * c.v[static_cast<std::size_t>(i)];
      hand = std::fmin(hand, hand_verlet(L, q, p, K));
      for (std::int64_t every : {std::int64_t(1), std::int64_t(100)}) {
        const auto run = make_run(problem(c, K), method());
        OutputSpec out;
        out.monitor_every = every;
        Recorder rec(out);
        const RunReport rep = run->execute(&rec);
        if (rep.failed || rep.step_path != StepPath::explicit_splitting) {
          std::fprintf(stderr, "bench_nbody: the dvm run failed or did not take the explicit steps (%s)\n",
                       to_string(rep.step_path));
          return 3;
        }
        (every == 1 ? dvm1 : dvm100) = std::fmin(every == 1 ? dvm1 : dvm100, rep.wall_seconds);
      }
    }
    {
      // the same equations: 20 steps of each (over long runs close encounters amplify
      // the round-off differences of the two, compensated sums against plain ones)
      Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(c.q.data(), 3 * n), p(3 * n);
      for (int i = 0; i < 3 * n; ++i) p[i] = L.m(i / 3) * c.v[static_cast<std::size_t>(i)];
      hand_verlet(L, q, p, 20);
      Recorder rec(OutputSpec{});
      const RunReport rep = make_run(problem(c, 20), method())->execute(&rec);
      for (int i = 0; i < 3 * n; ++i) apart = std::fmax(apart, std::fabs(rep.q_final[static_cast<std::size_t>(i)] - q[i]));
    }
    const double us = 1e6 / static_cast<double>(K);
    std::printf("| %d | %lld | %.1f | %.1f | %.2f | %.1f | %.2f | %.1e |\n", n, static_cast<long long>(K), hand * us,
                dvm1 * us, dvm1 / hand, dvm100 * us, dvm100 / hand, apart);
  }
  return 0;
}
