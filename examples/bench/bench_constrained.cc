// Cost per step of a constrained system against the same system in minimal coordinates,
// both run as `dvm run` runs their shipped scenes (load_scene, make_run, execute; the
// energy and the constraint residuals monitored at the last step only, so that what is
// timed is the steps), in this process:
//
//   pendulum_cartesian.toml          (x, y), x^2 + y^2 = l^2      against pendulum_written.toml (the angle)
//   double_pendulum_cartesian.toml   (x1, y1, x2, y2), 2 rods     against double_pendulum_written.toml
//   four_bar.toml                    (th1, th2), the loop closed  against four_bar_one_coordinate.toml
//   spherical_pendulum_r3.toml       (x, y, z), |q| = l           against spherical_pendulum_written.toml (S^2)
//   scissor_lift.toml                9 coordinates, 8 constraints against scissor_lift_one_coordinate.toml
//
// Each pair runs the midpoint map (sphere-exp on S^2) with the same step from the same
// state; the table gives ns per step (the best of the repeats), the constrained run's
// Newton iterations per step, and the ratio constrained / minimal. The constrained scene
// is also timed with its step equations solved to a residual of 1e-10 (the tolerance
// trep's MidpointVI is usually run at; dvm's default, integrator.tolerance, is 2e-15),
// and with the derivative of every step, A_k (and B_k where it reads controls), written
// as `dvm run --linearize` writes it (to a .npy file in the system's temporary folder,
// whose writing is in the time). The two columns are
// different discretisations of one motion, so their states are not compared here
// (tests/cli/test_cli_constraints.cc and test_cli_constraints_long.cc compare them to the
// methods' accuracy).
//
// usage: bench_constrained [--steps N] [--repeats R] [--scenes DIR]
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "solvers/runtime/recorder.h"
#include "solvers/runtime/run.h"
#include "solvers/runtime/scene.h"

#include <unistd.h>

#ifndef DVM_SCENES
#define DVM_SCENES "examples/scenes"
#endif

using namespace dvm;

namespace {

struct Timing {
  double ns_per_step = INFINITY;
  double iterations_per_step = 0.0;
};

// The best of `repeats` runs of the scene for `steps` steps, or for its own steps where
// it has fewer and `bounded` (a motion that must stop where the scene does).
// tolerance > 0: the step equations solved to it (else the scene's); linearize not empty:
// each step's derivative written to that .npy file.
Timing measure(const std::string& dir, const std::string& file, std::int64_t steps, int repeats, bool bounded,
               double tolerance = 0.0, const std::string& linearize = "") {
  Scene sc = load_scene(dir + "/" + file, {});
  if (!bounded || steps < sc.problem.steps) sc.problem.steps = steps;
  steps = sc.problem.steps;
  if (tolerance > 0.0) sc.method.tolerance = tolerance;
  sc.method.linearize = !linearize.empty();
  Timing best;
  for (int r = 0; r < repeats; ++r) {
    OutputSpec out;
    out.monitor_every = steps;
    out.linearize = linearize;
    out.linearize_source = "bench_constrained";
    Recorder rec(out);
    auto run = make_run(sc.problem, sc.method);
    const auto t0 = std::chrono::steady_clock::now();
    const RunReport rep = run->execute(&rec);
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                      static_cast<double>(steps);
    if (rep.failed) {
      std::fprintf(stderr, "%s failed: %s\n", file.c_str(), rep.loop.failure.message.c_str());
      std::exit(3);
    }
    if (ns < best.ns_per_step) {
      best.ns_per_step = ns;
      best.iterations_per_step = static_cast<double>(rep.solver_iterations) / static_cast<double>(rep.steps);
    }
  }
  return best;
}

}  // namespace

int main(int argc, char** argv) {
  std::int64_t steps = 200000;
  int repeats = 5;
  std::string dir = DVM_SCENES;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--steps" && i + 1 < argc) {
      steps = std::atoll(argv[++i]);
    } else if (a == "--repeats" && i + 1 < argc) {
      repeats = std::atoi(argv[++i]);
    } else if (a == "--scenes" && i + 1 < argc) {
      dir = argv[++i];
    } else {
      std::fprintf(stderr, "usage: bench_constrained [--steps N] [--repeats R] [--scenes DIR]\n");
      return 2;
    }
  }
  if (steps < 1 || repeats < 1) {
    std::fprintf(stderr, "bench_constrained: --steps and --repeats must be at least 1\n");
    return 2;
  }
  // bounded: each run stops at the scene's t_end (the scissor lift, before its straight
  // position, where its constraints lose rank), repeated 100 times as often
  struct Pair {
    const char* constrained;
    const char* minimal;
    bool bounded = false;
  };
  const std::vector<Pair> pairs = {
      {"pendulum_cartesian.toml", "pendulum_written.toml"},
      {"double_pendulum_cartesian.toml", "double_pendulum_written.toml"},
      {"four_bar.toml", "four_bar_one_coordinate.toml"},
      {"spherical_pendulum_r3.toml", "spherical_pendulum_written.toml"},
      {"scissor_lift.toml", "scissor_lift_one_coordinate.toml", true},
  };
  std::printf("%lld steps, best of %d (a bounded scene: its own steps, best of 100 times as many runs; the energy\n"
              "and the residuals monitored at the last step only)\n\n",
              static_cast<long long>(steps), repeats);
  std::printf(
      "| constrained scene | ns/step | iterations/step | at 1e-10: ns/step | iterations/step | with A_k: ns/step "
      "| minimal-coordinate scene | ns/step | ratio |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|\n");
  const std::string npy =
      (std::filesystem::temp_directory_path() / ("bench_constrained_" + std::to_string(::getpid()) + ".npy")).string();
  int status = 0;
  try {
    for (const Pair& p : pairs) {
      const int r = p.bounded ? 100 * repeats : repeats;
      const Timing c = measure(dir, p.constrained, steps, r, p.bounded);
      const Timing loose = measure(dir, p.constrained, steps, r, p.bounded, 1e-10);
      const Timing derivatives = measure(dir, p.constrained, steps, r, p.bounded, 0.0, npy);
      const Timing m = measure(dir, p.minimal, steps, r, p.bounded);
      std::printf("| %s | %.0f | %.2f | %.0f | %.2f | %.0f | %s | %.0f | %.2f |\n", p.constrained, c.ns_per_step,
                  c.iterations_per_step, loose.ns_per_step, loose.iterations_per_step, derivatives.ns_per_step,
                  p.minimal, m.ns_per_step, c.ns_per_step / m.ns_per_step);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_constrained: %s\n", e.what());
    status = 2;
  }
  std::error_code ignored;
  std::filesystem::remove(npy, ignored);
  std::filesystem::remove(npy + ".json", ignored);
  return status;
}
