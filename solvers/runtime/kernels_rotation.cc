// Run kernels of the systems on SO(3): the heavy top, the free rigid body and
// Lagrangians written on SO(3), through one set of steps (BuiltinOrWritten<HeavyTop>,
// solvers/runtime/kernels_manifold.h). The free rigid body is the heavy top with
// m g = 0: its Lagrangian and Hamiltonian are the top's minus a zero term, the same
// numbers to the bit; the run is reported as the rigid body's (its columns, energy and
// spatial angular momentum).
#include "solvers/manifold_hamiltonian_step_derivative.h"
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

namespace {
using TopSystem = kernels::BuiltinOrWritten<HeavyTop>;
}  // namespace

std::unique_ptr<Run> heavy_top(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const HeavyTop L(kernels::V3(P.at("I1"), P.at("I2"), P.at("I3")), P.at("m"), P.at("g"),
                   kernels::V3(P.at("chi1"), P.at("chi2"), P.at("chi3")));
  return kernels::make_manifold_run<kRotationParts, TopSystem, SO3Map, HeavyTop>(kernels::as_builtin(L),
                                                                              kernels::so3_map(me), pr, me, L);
}

std::unique_ptr<Run> rigid_body(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const RigidBody body(kernels::V3(P.at("I1"), P.at("I2"), P.at("I3")));  // checks the moments
  const HeavyTop top(body.inertia, 1.0, 0.0, kernels::V3::Zero());
  return kernels::make_manifold_run<kRotationParts, TopSystem, SO3Map, RigidBody>(kernels::as_builtin(top),
                                                                               kernels::so3_map(me), pr, me, body);
}

std::unique_ptr<Run> written_rotation(const Problem& pr, const Method& me) {
  const WrittenManifoldLagrangian<SO3> L(pr.written);
  return kernels::make_manifold_run<kRotationParts, TopSystem, SO3Map, WrittenManifoldLagrangian<SO3>>(
      kernels::as_written<HeavyTop>(L), kernels::so3_map(me), pr, me, L);
}

}  // namespace dvm::factories

namespace dvm {

// the derivative of the unforced Hamiltonian step (dvm run --linearize), here where the
// step itself is compiled
template bool ManifoldHamiltonianStep<kernels::BuiltinOrWrittenHamiltonian<HeavyTop>, SO3Map>::derivatives(
    double, const Point&, const Covector&, const Point&, Eigen::MatrixXd&, Eigen::MatrixXd*) const;

}  // namespace dvm
