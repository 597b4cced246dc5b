// The run factories of the built-in systems, one per registry entry
// (solvers/runtime/registry.cc), each defined in a kernels_*.cc translation unit where
// the templated kernels of its system type are instantiated.
#pragma once

#include <memory>

#include "solvers/runtime/run.h"

namespace dvm::factories {

// What the kernels of a manifold group build besides the lagrangian form with every map
// and composition of its space: the one statement of it, read by the registry (its
// SystemCapabilities, hence validate(), listings and messages) and by the kernels
// (make_manifold_run instantiates exactly these parts).
struct KernelParts {
  bool hamiltonian;     // integrator.form = "hamiltonian"
  bool galerkin;        // integrator.method = "galerkin"
  bool boundary_value;  // problem.kind = "boundary-value"
};
inline constexpr KernelParts kSphereParts{true, true, true};          // S^2: spherical pendulum, written
inline constexpr KernelParts kRotationParts{true, true, false};       // SO(3): rigid body, heavy top, written
inline constexpr KernelParts kSpherePowerParts{false, false, false};  // (S^2)^K: spherical chain, written

std::unique_ptr<Run> harmonic(const Problem&, const Method&);
std::unique_ptr<Run> pendulum(const Problem&, const Method&);
std::unique_ptr<Run> duffing(const Problem&, const Method&);
std::unique_ptr<Run> kepler(const Problem&, const Method&);
std::unique_ptr<Run> double_pendulum(const Problem&, const Method&);
std::unique_ptr<Run> henon_heiles(const Problem&, const Method&);
std::unique_ptr<Run> charged_particle(const Problem&, const Method&);
std::unique_ptr<Run> fpu(const Problem&, const Method&);
std::unique_ptr<Run> nbody(const Problem&, const Method&);
std::unique_ptr<Run> chain(const Problem&, const Method&);
std::unique_ptr<Run> written(const Problem&, const Method&);
std::unique_ptr<Run> written_sphere(const Problem&, const Method&);
std::unique_ptr<Run> written_sphere_power(const Problem&, const Method&);
std::unique_ptr<Run> written_rotation(const Problem&, const Method&);
std::unique_ptr<Run> spherical_pendulum(const Problem&, const Method&);
std::unique_ptr<Run> spherical_chain(const Problem&, const Method&);
std::unique_ptr<Run> rigid_body(const Problem&, const Method&);
std::unique_ptr<Run> heavy_top(const Problem&, const Method&);

}  // namespace dvm::factories
