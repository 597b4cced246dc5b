// Run kernels of the Fermi-Pasta-Ulam problem of GNI (solvers/runtime/kernels_rn.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_rn.h"

namespace dvm::factories {

std::unique_ptr<Run> fpu(const Problem& pr, const Method& me) {
  return kernels::make_rn_run(FermiPastaUlam(pr.params.at("omega")), pr, me);
}

}  // namespace dvm::factories
