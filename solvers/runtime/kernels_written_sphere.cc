// Run kernels of Lagrangians written in a scene on S^2 (mechanics/written_manifold.h,
// solvers/runtime/kernels_manifold.h): the steps of the spherical pendulum.
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

std::unique_ptr<Run> written_sphere(const Problem& pr, const Method& me) {
  using S = WrittenManifoldLagrangian<Sphere>;
  const S L(pr.written);
  // (Galerkin takes no map: the map's type is only a template argument there)
  const SphereMap R = me.map ? kernels::sphere_map(me) : SphereMap(RetractionKind::exp, 0.5, "sphere-exp");
  return kernels::make_manifold_run<S, SphereMap, true, true, true>(L, R, pr, me);
}

}  // namespace dvm::factories
