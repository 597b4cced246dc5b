// ceres::TinySolver on the systems of the steps, compiled once for the sizes
// DVM_TINY_SOLVER_SIZES lists (solvers/newton.h declares them extern).
#include "solvers/newton.h"

namespace dvm {

#define DVM_TINY_SOLVER_INSTANTIATE(N)                                                                        \
  template StepSummary solve_tiny_residual<N>(const TinyResidual<N>&, Vec<double, N>&, double, const StepOptions&, \
                                              double);
DVM_TINY_SOLVER_SIZES(DVM_TINY_SOLVER_INSTANTIATE)
#undef DVM_TINY_SOLVER_INSTANTIATE

}  // namespace dvm
