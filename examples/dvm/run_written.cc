// `dvm run` for a Lagrangian written in the scene: the number of coordinates is
// fixed at compile time (WrittenLagrangian<N>), so it is dispatched here, once per
// run, over N = 1..kMaxWrittenDim.
#include "examples/dvm/run_with.h"

namespace dvm::cli {

namespace {

template <int N>
int run_dim(const Scene& s, const RunOptions& o) {
  if (s.dim == N) return run_system(s, WrittenLagrangian<N>(s.written), o);
  if constexpr (N < kMaxWrittenDim) {
    return run_dim<N + 1>(s, o);
  } else {
    throw InputError(s.path + ": a written Lagrangian takes 1 to " + std::to_string(kMaxWrittenDim) +
                     " coordinates, got " + std::to_string(s.dim));
  }
}

}  // namespace

int run_written(const Scene& s, const RunOptions& o) { return run_dim<1>(s, o); }

}  // namespace dvm::cli
