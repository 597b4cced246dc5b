// `dvm run` for a Lagrangian written in the scene: the number of coordinates is
// fixed at compile time (WrittenLagrangian<N>), so it is dispatched here, once per
// run, over N = 1..kMaxWrittenDim. The counts are split over two translation units
// (this one and run_written_high.cc) so that they compile in parallel.
#include "examples/dvm/run_with.h"

namespace dvm::cli {

int run_written(const Scene& s, const RunOptions& o) {
  switch (s.dim) {
    case 1: return run_system(s, WrittenLagrangian<1>(s.written), o);
    case 2: return run_system(s, WrittenLagrangian<2>(s.written), o);
    case 3: return run_system(s, WrittenLagrangian<3>(s.written), o);
    default: return run_written_high(s, o);
  }
}

}  // namespace dvm::cli
