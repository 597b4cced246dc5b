// Run kernels of the chain of spherical pendulums on (S^2)^n, n = 1..4
// (solvers/runtime/kernels_manifold.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

std::unique_ptr<Run> spherical_chain(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const int n = static_cast<int>(P.at("n"));
  const SphereMap f = kernels::sphere_map(me);
  auto run = [&](auto k) {
    constexpr int K = decltype(k)::value;
    const SphericalChain<K> L(Vec<double, K>::Constant(P.at("m")), Vec<double, K>::Constant(P.at("l")), P.at("g"));
    return kernels::make_manifold_run<SphericalChain<K>, SpherePowerMap<K>, false, false, false>(
        L, SpherePowerMap<K>(f), pr, me);
  };
  switch (n) {
    case 1: return run(std::integral_constant<int, 1>{});
    case 2: return run(std::integral_constant<int, 2>{});
    case 3: return run(std::integral_constant<int, 3>{});
    case 4: return run(std::integral_constant<int, 4>{});
    default: break;
  }
  throw InputError("system.params.n: the spherical chain takes 1 to 4 links");
}

}  // namespace dvm::factories
