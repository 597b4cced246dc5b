// Run kernels of the one-degree-of-freedom systems on R^n (solvers/runtime/kernels_rn.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_rn.h"

namespace dvm::factories {

std::unique_ptr<Run> harmonic(const Problem& pr, const Method& me) {
  return kernels::make_rn_run(HarmonicOscillator(pr.params.at("omega")), pr, me);
}
std::unique_ptr<Run> pendulum(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  return kernels::make_rn_run(Pendulum(P.at("m"), P.at("l"), P.at("g")), pr, me);
}
std::unique_ptr<Run> duffing(const Problem& pr, const Method& me) {
  return kernels::make_rn_run(Duffing(pr.params.at("alpha"), pr.params.at("beta")), pr, me);
}

}  // namespace dvm::factories
