// Run kernels of the heavy top on SO(3) (solvers/runtime/kernels_manifold.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

std::unique_ptr<Run> heavy_top(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const HeavyTop L(kernels::V3(P.at("I1"), P.at("I2"), P.at("I3")), P.at("m"), P.at("g"),
                   kernels::V3(P.at("chi1"), P.at("chi2"), P.at("chi3")));
  const SO3Map R = me.map ? kernels::so3_map(me) : SO3Map(RetractionKind::exp, 0.5, "so3-exp");
  return kernels::make_manifold_run<HeavyTop, SO3Map, true, true, false>(L, R, pr, me);
}

}  // namespace dvm::factories
