// Run kernels of Lagrangians written in a scene on SO(3) (mechanics/written_manifold.h,
// solvers/runtime/kernels_manifold.h): the steps of the rigid body and the heavy top.
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

std::unique_ptr<Run> written_rotation(const Problem& pr, const Method& me) {
  using S = WrittenManifoldLagrangian<SO3>;
  const S L(pr.written);
  // (Galerkin takes no map: the map's type is only a template argument there)
  const SO3Map R = me.map ? kernels::so3_map(me) : SO3Map(RetractionKind::exp, 0.5, "so3-exp");
  return kernels::make_manifold_run<S, SO3Map, true, true, false>(L, R, pr, me);
}

}  // namespace dvm::factories
