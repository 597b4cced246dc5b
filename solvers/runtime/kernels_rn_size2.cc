// The kernels of the built-in systems of 2 coordinates on R^n compiled once for
// that size (solvers/runtime/kernels_rn_sized.h).
#include "solvers/runtime/kernels_rn_sized.h"

namespace dvm::kernels {

template std::unique_ptr<Run> make_sized_run<2>(const ErasedLagrangian<2>&, const ErasedRnView<2>&, const Problem&,
                                                const Method&, RunReport, const SizedStart<2>*);

}  // namespace dvm::kernels
