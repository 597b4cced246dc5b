// Run kernels of the double pendulum and the Henon-Heiles system
// (solvers/runtime/kernels_rn.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_rn.h"

namespace dvm::factories {

std::unique_ptr<Run> double_pendulum(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  return kernels::make_rn_run(DoublePendulum(P.at("m1"), P.at("m2"), P.at("l1"), P.at("l2"), P.at("g")), pr, me);
}
std::unique_ptr<Run> henon_heiles(const Problem& pr, const Method& me) {
  return kernels::make_rn_run(HenonHeiles(pr.params.at("lambda")), pr, me);
}

}  // namespace dvm::factories
