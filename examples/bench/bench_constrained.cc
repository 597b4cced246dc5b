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
// Then constraints on S^2 and SO(3) (solvers/manifold_constrained_step.h; no A_k there):
//
//   compound_pendulum_so3.toml       SO(3), R e1 = e1             against pendulum_written.toml (the angle)
//                                                                 and heavy_top_written.toml (SO(3), free)
//   bead_on_rotating_hoop.toml       S^2, a hoop turning in t     against spherical_pendulum_written.toml (free)
//
// Then chains of k rods in Cartesian coordinates (2k coordinates, k constraints; the
// scene written here), k = 1 .. 128: the dense ConstrainedThetaStep against the sparse
// SparseConstrainedThetaStep from the same state, ns a step and their ratio (where the
// runtime's line between them belongs), undamped, with a damping force on every
// coordinate, and undamped with each step's derivative A formed after it (both steps'
// derivative(): the dense one factors (3k) x (3k) matrices, the sparse one solves with
// its band for 4k right-hand sides).
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
#include <algorithm>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/written_constraints.h"
#include "solvers/constrained_step.h"
#include "solvers/runtime/recorder.h"
#include "solvers/runtime/run.h"
#include "solvers/runtime/scene.h"
#include "solvers/sparse_constrained_step.h"
#include "solvers/sparse_separable_step.h"

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

// A chain of k rods of length l with point masses m at their joints, hung from the
// origin in the plane, as a scene: 2k Cartesian coordinates (x1, y1, ..., xk, yk), k
// distance constraints, gravity; the joints at angles 0.4 sin(i) from the vertical,
// turning at rates 0.3 cos(2 i) (a state on the constraints and their hidden constraint).
// damped: a force -c v_i on every coordinate.
std::string chain_scene(int k, bool damped) {
  std::string coords, lagrangian, constraints, q, v, forces;
  double x = 0, y = 0, vx = 0, vy = 0;
  const double l = 0.5;
  char buf[160];
  for (int i = 1; i <= k; ++i) {
    const std::string a = std::to_string(i - 1), b = std::to_string(i);
    const double angle = 0.4 * std::sin(i), w = 0.3 * std::cos(2.0 * i);
    x += l * std::sin(angle);
    y -= l * std::cos(angle);
    vx += l * std::cos(angle) * w;
    vy += l * std::sin(angle) * w;
    const char* sep = i > 1 ? ", " : "";
    coords += std::string(sep) + "\"x" + b + "\", \"y" + b + "\"";
    lagrangian += std::string(i > 1 ? " + " : "") + "m/2*(x" + b + "_dot^2 + y" + b + "_dot^2) - m*g*y" + b;
    constraints += std::string(sep) + (i == 1 ? "\"x1^2 + y1^2 - l^2\""
                                              : "\"(x" + b + " - x" + a + ")^2 + (y" + b + " - y" + a + ")^2 - l^2\"");
    forces += std::string(sep) + "x" + b + " = \"-c*x" + b + "_dot\", y" + b + " = \"-c*y" + b + "_dot\"";
    std::snprintf(buf, sizeof buf, "%s%.17g, %.17g", sep, x, y);
    q += buf;
    std::snprintf(buf, sizeof buf, "%s%.17g, %.17g", sep, vx, vy);
    v += buf;
  }
  return "[system]\ncoordinates = [" + coords + "]\nparams = { m = 0.7, l = 0.5, g = 9.81, c = 0.2 }\nlagrangian = \"" +
         lagrangian + "\"\nconstraints = [" + constraints + "]\n" + (damped ? "forces = { " + forces + " }\n" : "") +
         "[initial]\nq = [" + q + "]\nv = [" + v + "]\n[integrator]\nmap = \"midpoint\"\nstep = 1e-3\nt_end = 1.0\n";
}

// The cost of a step of the chain of k rods by the dense constrained step (an LU of
// the (3k) x (3k) saddle-point matrix) and by the sparse one, from the same state, in
// this process: ns per step, the best of `repeats` runs of `steps` steps each; then the
// same with the damping force; then undamped with each step's derivative A (4k x 4k)
// formed after it, as `dvm run --linearize` forms it (not written).
void chain_row(int k, std::int64_t steps, int repeats) {
  const Scene sc = load_scene_text(chain_scene(k, false), "chain", {});
  const Problem& pr = sc.problem;
  const WrittenDynamic L(pr.written);
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  const int n = L.dim();
  const Eigen::VectorXd q0 = Eigen::Map<const Eigen::VectorXd>(pr.q.data(), n);
  Eigen::VectorXd p0(n), v0 = Eigen::Map<const Eigen::VectorXd>(pr.v.data(), n);
  p0 = L.parts().mass_diagonal.cwiseProduct(v0);
  const double h = pr.step;
  auto time = [&](const auto& step, bool derivative = false) {
    double best = INFINITY;
    Eigen::MatrixXd A;
    for (int r = 0; r < repeats; ++r) {
      Eigen::VectorXd q = q0, p = p0, dq = Eigen::VectorXd::Zero(n), dp(n);
      const auto t0 = std::chrono::steady_clock::now();
      for (std::int64_t j = 0; j < steps; ++j) {
        const double t = static_cast<double>(j) * h;
        const StepSummary s = step.step(t, q, p, dq, dp);
        if (!s.converged) throw std::runtime_error("chain of " + std::to_string(k) + ": " + s.message);
        if (derivative && !step.derivative(t, q, p, dq, A))
          throw std::runtime_error("chain of " + std::to_string(k) + ": no derivative");
        q += dq;
        p += dp;
      }
      best = std::fmin(best, std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                                 static_cast<double>(steps));
    }
    return best;
  };
  const auto H = SparseSeparableThetaStep::hessian_of(L, q0);
  const SparseConstrainedThetaStep sparse_step(L, H, con, 0.5, h);
  const ConstrainedThetaStep<WrittenDynamic, WrittenConstraints> dense_step(L, ThetaMap(0.5), h, con, {},
                                                                            MomentumMap::constant);
  const double sparse = time(sparse_step), dense = time(dense_step);
  const double sparse_a = time(sparse_step, true), dense_a = time(dense_step, true);
  const Scene damped = load_scene_text(chain_scene(k, true), "damped chain", {});
  const auto force = std::make_shared<const WrittenForce>(damped.problem.written);
  const WrittenDynamic Ld(damped.problem.written);
  const auto cond = std::make_shared<const WrittenConstraints>(damped.problem.written);
  const double sparse_f =
      time(SparseConstrainedThetaStep(Ld, SparseSeparableThetaStep::hessian_of(Ld, q0), cond, 0.5, h, {}, force));
  const double dense_f = time(ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, WrittenForce>(
      Ld, ThetaMap(0.5), h, cond, {}, MomentumMap::constant, force));
  std::printf("| %d | %d | %.0f | %.0f | %.2f | %.0f | %.0f | %.2f | %.0f | %.0f | %.2f |\n", k, n, dense, sparse,
              dense / sparse, dense_f, sparse_f, dense_f / sparse_f, dense_a, sparse_a, dense_a / sparse_a);
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
    // constraints on S^2 and SO(3): the constrained step in the chart against the same
    // motion in one coordinate, and against an unconstrained system on the same space
    std::printf("\nconstraints on S^2 and SO(3) (ConstrainedManifoldStep; --linearize is for R^n, so no A_k): against "
                "the minimal\ncoordinate, and against an unconstrained system on the same space (another motion)\n\n");
    std::printf("| constrained scene | ns/step | iterations/step | at 1e-10: ns/step | iterations/step | twin scene "
                "| ns/step | ratio |\n|---|---|---|---|---|---|---|---|\n");
    const std::vector<Pair> manifold_pairs = {
        {"compound_pendulum_so3.toml", "pendulum_written.toml"},
        {"compound_pendulum_so3.toml", "heavy_top_written.toml"},
        {"bead_on_rotating_hoop.toml", "spherical_pendulum_written.toml"},
    };
    for (const Pair& p : manifold_pairs) {
      const Timing c = measure(dir, p.constrained, steps, repeats, false);
      const Timing loose = measure(dir, p.constrained, steps, repeats, false, 1e-10);
      const Timing m = measure(dir, p.minimal, steps, repeats, false);
      std::printf("| %s | %.0f | %.2f | %.0f | %.2f | %s | %.0f | %.2f |\n", p.constrained, c.ns_per_step,
                  c.iterations_per_step, loose.ns_per_step, loose.iterations_per_step, p.minimal, m.ns_per_step,
                  c.ns_per_step / m.ns_per_step);
    }
    // chains of k rods: the dense step against the sparse one, the steps of a cell in
    // proportion to 1 / k^3 (the dense step's cost), at least 10
    std::printf("\nchains of k rods (midpoint, h = 1e-3): the dense constrained step against the sparse one, ns a step"
                "\n(dvm run takes the sparse one from kSparseConstrainedMinDim coordinates, kernels_dynamic.h)\n\n");
    std::printf(
        "| links k | coordinates | dense: ns/step | sparse: ns/step | dense / sparse | damped, dense: ns/step "
        "| damped, sparse: ns/step | dense / sparse | with A: dense ns/step | with A: sparse ns/step "
        "| dense / sparse |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int k : {1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128}) {
      const std::int64_t n = std::max<std::int64_t>(10, std::min<std::int64_t>(steps / 20, 2000000 / (k * k * k)));
      chain_row(k, n, repeats);
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
