// Run kernels of N bodies in R^3, any number of bodies (the run-time-sized kernels of
// solvers/runtime/kernels_dynamic.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_dynamic.h"

namespace dvm::factories {

std::unique_ptr<Run> nbody(const Problem& pr, const Method& me) {
  return kernels::make_dynamic_run(NBodyDynamic(pr.params.at("G"), pr.masses), pr, me, {}, nullptr);
}

}  // namespace dvm::factories
