// Run kernels of Lagrangians written in a scene, any number of coordinates (the
// run-time-sized kernels of solvers/runtime/kernels_dynamic.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_dynamic.h"

namespace dvm::factories {

std::unique_ptr<Run> written(const Problem& pr, const Method& me) {
  const WrittenDynamic L = kernels::compiled_or_not(
      [&](WrittenDerivatives mode) { return WrittenDynamic(pr.written, mode); }, pr);
  return kernels::make_dynamic_run(L, pr, me, pr.written->coordinates,
                                   L.has_hamiltonian() ? pr.written : std::shared_ptr<const WrittenSystem>());
}

}  // namespace dvm::factories
