// `dvm run` for N bodies in R^3 (builtin = "nbody", 2 to 6 bodies): the number of
// bodies is fixed at compile time, so each count is its own instantiation.
#include "examples/dvm/run_with.h"

namespace dvm::cli {

int run_nbody(const Scene& s, const RunOptions& o) {
  const double G = s.params.at("G");
  switch (s.masses.size()) {
    case 2: return run_system(s, NBody<2>(G, s.masses), o);
    case 3: return run_system(s, NBody<3>(G, s.masses), o);
    case 4: return run_system(s, NBody<4>(G, s.masses), o);
    case 5: return run_system(s, NBody<5>(G, s.masses), o);
    case 6: return run_system(s, NBody<6>(G, s.masses), o);
    default: throw InputError(s.path + ": nbody takes 2 to 6 bodies");
  }
}

}  // namespace dvm::cli
