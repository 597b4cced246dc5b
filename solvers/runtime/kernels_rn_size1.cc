// The kernels of the built-in systems of 1 coordinate on R^n compiled once for
// that size (solvers/runtime/kernels_rn_sized.h).
#include "solvers/runtime/kernels_rn_sized.h"

namespace dvm::kernels {

template std::unique_ptr<Run> make_sized_run<1>(const ErasedLagrangian<1>&, const ErasedRnView<1>&, const Problem&,
                                                const Method&, RunReport, const SizedStart<1>*);

}  // namespace dvm::kernels
