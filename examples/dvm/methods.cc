// `dvm methods`: the composition methods, with their order, stages, symmetry and the
// linear stability threshold of each (solvers/runtime/listings.h: from the trace of the
// one-step matrix on q'' = -omega^2 q); then the Galerkin discrete Lagrangians
// ([integrator] method = "galerkin", solvers/galerkin_step.h) with their orders.
#include <cstdio>
#include <iostream>

#include "examples/dvm/commands.h"
#include "solvers/runtime/listings.h"
#include "solvers/runtime/registry.h"

namespace dvm::cli {

int methods_command(bool json) {
  if (json) {
    std::cout << methods_json();
    return 0;
  }
  const std::vector<CompositionListing> rows = composition_listings();
  const double euler = euler_threshold();
  const int euler_forces = euler_forces_per_step();
  std::printf("%-16s %-5s %-6s %-9s %-13s %-10s %-9s %s\n", "name", "order", "stages", "symmetric",
              "threshold(SV)", "forces(SV)", "midpoint", "source");
  std::printf("%-16s %-5s %-6d %-9s %-13.6f %-10d %-9s %s\n", "none", "map", 1, "as map", euler, euler_forces,
              "stable", "the map's own step (threshold and forces: explicit-euler)");
  for (const CompositionListing& r : rows)
    std::printf("%-16s %-5d %-6d %-9s %-13.6f %-10d %-9s %s\n", r.scheme.name.c_str(), r.scheme.order,
                r.scheme.stages, r.scheme.symmetric ? "yes" : "no", r.threshold_verlet, r.forces_verlet,
                r.splitting() ? "refused" : r.midpoint_unconditional ? "stable" : "LIMITED",
                r.scheme.citation.c_str());
  std::printf(
      "\nthreshold(SV): largest stable h*omega on q'' = -omega^2 q with map = \"explicit-euler\" (or\n"
      "\"adjoint-euler\"), whose symmetric basic method is Stormer-Verlet; found from |trace| < 2 of\n"
      "the one-step matrix. forces(SV): force evaluations (gradients of the potential) a step\n"
      "takes with that map on a separable system, kicks merged and the last force of a step\n"
      "reused by the next; the cost of a step in its units. midpoint: with map = \"midpoint\"\n"
      "every composition is stable for all h*omega (each stage is a Cayley transform); a step\n"
      "then solves one implicit equation per stage, each Newton iteration a gradient and a\n"
      "Hessian of L. triple-jump:<order> takes any even order 2..%d.\n"
      "blanes-moan4 and blanes-moan6 are splittings into kicks and drifts (stages: forces a step):\n"
      "their order holds on separable systems (L = v^T M v / 2 - V(q)) with map = \"explicit-euler\"\n"
      "or \"adjoint-euler\" (the same method), lagrangian or hamiltonian form; other maps, forms\n"
      "and systems are refused.\n"
      "composition = \"dirk\" with integrator.weights = [b1, ..., bs] (summing to 1) is the symplectic\n"
      "DIRK of those weights as a composition of steps of b_i h (paper Sec. 6.2): order 2, 3 when\n"
      "the cubes of the weights sum to 0, 4 when the weights are also symmetric. With\n"
      "integrator.thetas = [t1, ..., ts] stage i takes the map at theta_i: with the hamiltonian form\n"
      "(its default cotangent lift; lift = \"none\" makes each stage the theta method on T*Q, not\n"
      "symplectic) and map = \"theta\" the symplectic partitioned Runge-Kutta pair a_ij = a^_ij = b_j (j < i),\n"
      "a_ii = theta_i b_i, a^_ii = (1 - theta_i) b_i (Sec. 6.2); order 2 when\n"
      "sum (theta_i - 1/2) b_i^2 = 0, else 1 (the DIRK's order when every theta is 1/2).\n",
      RecursiveTripleJump::max_order);
  std::printf("\nLifts of the map to the form's bundle: [integrator] lift = \"NAME\"\n");
  for (const LiftEntry& l : lift_registry()) {
    std::string forms;
    for (Form f : l.forms) forms += (forms.empty() ? "" : ", ") + std::string(to_string(f));
    std::printf("  %-10s (%s) %s\n", l.name.c_str(), forms.c_str(), l.description.c_str());
  }
  std::printf(
      "\nGalerkin discrete Lagrangians: [integrator] method = \"galerkin\", stages = s, quadrature = q\n"
      "(curves of degree s through the step's end points; every system but the chains, lagrangian\n"
      "form; on S^2 and SO(3) in the chart centred at each step's first point)\n");
  std::printf("%-10s %-6s %-6s %-5s %-9s %s\n", "quadrature", "stages", "points", "order", "symmetric", "source");
  for (const GalerkinEntry& g : galerkin_registry())
    std::printf("%-10s %-6d %-6d %-5d %-9s %s\n", to_string(g.quadrature), g.stages, g.points, g.order, "yes",
                (g.note.empty() ? g.citation : g.note).c_str());
  return 0;
}

}  // namespace dvm::cli
