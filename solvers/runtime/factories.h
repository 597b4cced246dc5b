// The run factories of the built-in systems, one per registry entry
// (solvers/runtime/registry.cc), each defined in a kernels_*.cc translation unit where
// the templated kernels of its system type are instantiated.
#pragma once

#include <memory>

#include "solvers/runtime/run.h"

namespace dvm::factories {

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
