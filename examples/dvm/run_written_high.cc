// `dvm run` for written Lagrangians with 4 to kMaxWrittenDim coordinates (see
// run_written.cc).
#include "examples/dvm/run_with.h"

namespace dvm::cli {

static_assert(kMaxWrittenDim == 6, "run_written_high.cc instantiates 4, 5 and 6 coordinates");

int run_written_high(const Scene& s, const RunOptions& o) {
  switch (s.dim) {
    case 4: return run_system(s, WrittenLagrangian<4>(s.written), o);
    case 5: return run_system(s, WrittenLagrangian<5>(s.written), o);
    case 6: return run_system(s, WrittenLagrangian<6>(s.written), o);
    default:
      throw InputError(s.path + ": a written Lagrangian takes 1 to " + std::to_string(kMaxWrittenDim) +
                       " coordinates, got " + std::to_string(s.dim));
  }
}

}  // namespace dvm::cli
