// Run kernels of Kepler's problem and the charged particle (solvers/runtime/kernels_rn.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_rn.h"

namespace dvm::factories {

std::unique_ptr<Run> kepler(const Problem& pr, const Method& me) {
  return kernels::make_rn_run(Kepler(pr.params.at("mu")), pr, me);
}
std::unique_ptr<Run> charged_particle(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  return kernels::make_rn_run(ChargedParticle(P.at("m"), P.at("c"), P.at("B"), P.at("k")), pr, me);
}

}  // namespace dvm::factories
