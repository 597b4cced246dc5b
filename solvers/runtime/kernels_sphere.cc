// Run kernels of the systems on S^2: the spherical pendulum and Lagrangians written on
// S^2, through one set of steps (BuiltinOrWritten, solvers/runtime/kernels_manifold.h).
#include "solvers/manifold_hamiltonian_step_derivative.h"
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

namespace {
using SphereSystem = kernels::BuiltinOrWritten<SphericalPendulum>;
}  // namespace

std::unique_ptr<Run> spherical_pendulum(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const SphericalPendulum L(P.at("m"), P.at("l"), P.at("g"));
  return kernels::make_manifold_run<kSphereParts, SphereSystem, SphereMap, SphericalPendulum>(
      kernels::as_builtin(L), kernels::sphere_map(me), pr, me, L);
}

std::unique_ptr<Run> written_sphere(const Problem& pr, const Method& me) {
  const WrittenManifoldLagrangian<Sphere> L(pr.written);
  return kernels::make_manifold_run<kSphereParts, SphereSystem, SphereMap, WrittenManifoldLagrangian<Sphere>>(
      kernels::as_written<SphericalPendulum>(L), kernels::sphere_map(me), pr, me, L);
}

}  // namespace dvm::factories

namespace dvm {

// the derivative of the unforced Hamiltonian step (dvm run --linearize), here where the
// step itself is compiled
template bool ManifoldHamiltonianStep<kernels::BuiltinOrWrittenHamiltonian<SphericalPendulum>, SphereMap>::derivatives(
    double, const Point&, const Covector&, const Point&, Eigen::MatrixXd&, Eigen::MatrixXd*) const;

}  // namespace dvm
