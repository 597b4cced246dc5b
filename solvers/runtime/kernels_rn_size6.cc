// The kernels of the built-in systems of 6 coordinates on R^n compiled once for
// that size (solvers/runtime/kernels_rn_sized.h).
#include "solvers/runtime/kernels_rn_sized.h"

namespace dvm::kernels {

template std::unique_ptr<Run> make_sized_run<6>(const ErasedLagrangian<6>&, const ErasedRnView<6>&, const Problem&,
                                                const Method&, RunReport, const SizedStart<6>*);

}  // namespace dvm::kernels
