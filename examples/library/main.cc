// Using dvm as a library, from a project of its own (find_package(dvm), target
// dvm::dvm): Kepler's problem integrated by the composition kahan-li8 of the
// Stormer-Verlet method that the two Euler maps make (paper Sec. 6), once through the
// runtime layer (a Problem and a Method, as a scene gives them), once from a scene read
// by the program's own reader, and once through the templated steps directly. All must
// agree with the exact solution to the method's accuracy (the first two to the bit);
// the program says so and exits 0, else 1.
#include <cmath>
#include <cstdio>

#include "mechanics/systems.h"
#include "solvers/composition.h"
#include "solvers/runtime/run.h"
#include "solvers/runtime/scene.h"

int main() {
  // The runtime layer: names from the registries, one Run built once.
  dvm::Problem problem;
  problem.system = &dvm::find_system_entry("kepler", "example");
  problem.params = {{"mu", 1.0}};
  problem.dim = 2;
  problem.q = {0.4, 0.0};
  problem.p = {0.0, 2.0};
  problem.momentum_given = true;
  problem.step = 0.05;
  problem.steps = 200;  // t = 10
  dvm::Method method;
  method.map = &dvm::find_map_entry("explicit-euler", "example");
  method.theta = method.map->theta;
  method.composition = "kahan-li8";
  const auto run = dvm::make_run(problem, method);
  const dvm::RunReport report = run->execute(nullptr);
  std::vector<double> q_exact, p_exact;
  run->exact(10.0, q_exact, p_exact);
  const double err = std::fmax(std::fabs(report.q_final[0] - q_exact[0]), std::fabs(report.q_final[1] - q_exact[1]));

  // The same run from a scene, with an override as `dvm run --set` gives it.
  const dvm::Scene scene = dvm::load_scene_text(
      "[system]\nbuiltin = \"kepler\"\n[initial]\nq = [0.4, 0.0]\np = [0.0, 2.0]\n"
      "[integrator]\nmap = \"explicit-euler\"\ncomposition = \"kahan-li8\"\nstep = 0.05\nsteps = 100\n",
      "kepler.toml", {"integrator.steps=200"});
  const dvm::RunReport from_scene = dvm::make_run(scene.problem, scene.method)->execute(nullptr);
  const bool same = from_scene.q_final == report.q_final && from_scene.p_final == report.p_final;

  // The same method from the templated steps.
  using Step = dvm::PositionMomentumStep<dvm::Kepler, dvm::ThetaMap>;
  const dvm::Kepler kepler(1.0);
  const dvm::ThetaMap euler = dvm::ThetaMap::explicit_euler();
  const dvm::ComposedStep<Step> step(
      0.05, dvm::substeps(dvm::find_composition("kahan-li8"), false),
      [&](double h) { return Step(kepler, euler, h); }, [&](double h) { return Step(kepler, euler.adjoint(), h); });
  dvm::Vec<double, 2> q(0.4, 0.0), p(0.0, 2.0);
  const dvm::RunSummary summary = dvm::integrate(step, 0.0, q, p, p, 200, [](auto&&...) {});
  const double diff = std::fmax(std::fabs(q[0] - report.q_final[0]), std::fabs(q[1] - report.q_final[1]));

  std::printf("kepler, kahan-li8 of the Euler maps, h = 0.05, t = 10: |q - q_exact| = %.3e, energy error %.3e\n", err,
              report.max_abs_energy_error);
  std::printf("templated steps and runtime layer differ by %.3e\n", diff);
  std::printf("the scene's run %s the runtime layer's\n", same ? "equals" : "DIFFERS FROM");
  const bool ok = !report.failed && !summary.failed && !from_scene.failed && same && err < 1e-6 && diff < 1e-12;
  std::printf("%s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
