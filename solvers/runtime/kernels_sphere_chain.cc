// Run kernels on (S^2)^n, n = 1..4: the chain of spherical pendulums and Lagrangians
// written on (S^2)^K, K = 2..4, through one set of steps per n
// (BuiltinOrWritten<SphericalChain<K>>, solvers/runtime/kernels_manifold.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm::factories {

namespace {

// Calls run(std::integral_constant<int, n>) for n in K..4, instantiating run for
// those sizes only; throws InputError(what) for any other n.
template <int K, class F>
std::unique_ptr<Run> for_factors(int n, F&& run, const char* what) {
  if (n == K) return run(std::integral_constant<int, K>{});
  if constexpr (K < 4)
    return for_factors<K + 1>(n, run, what);
  else
    throw InputError(what);
}

}  // namespace

std::unique_ptr<Run> spherical_chain(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const SphereMap f = kernels::sphere_map(me);
  auto run = [&](auto k) {
    constexpr int K = decltype(k)::value;
    const SphericalChain<K> L(Vec<double, K>::Constant(P.at("m")), Vec<double, K>::Constant(P.at("l")), P.at("g"));
    if constexpr (K == 1) {  // (S^2)^1 is written as S^2 (kernels_sphere.cc): no written branch
      return kernels::make_manifold_run<SphericalChain<1>, SpherePowerMap<1>, false, false, false>(
          L, SpherePowerMap<1>(f), pr, me);
    } else {
      using Sys = kernels::BuiltinOrWritten<SphericalChain<K>>;
      return kernels::make_manifold_run<Sys, SpherePowerMap<K>, false, false, false, SphericalChain<K>>(
          kernels::as_builtin(L), SpherePowerMap<K>(f), pr, me, L);
    }
  };
  return for_factors<1>(static_cast<int>(P.at("n")), run, "system.params.n: the spherical chain takes 1 to 4 links");
}

std::unique_ptr<Run> written_sphere_power(const Problem& pr, const Method& me) {
  const SphereMap f = kernels::sphere_map(me);
  auto run = [&](auto k) {
    constexpr int K = decltype(k)::value;
    using Sys = kernels::BuiltinOrWritten<SphericalChain<K>>;
    const WrittenManifoldLagrangian<SpherePower<K>> L(pr.written);
    return kernels::make_manifold_run<Sys, SpherePowerMap<K>, false, false, false,
                                      WrittenManifoldLagrangian<SpherePower<K>>>(
        kernels::as_written<SphericalChain<K>>(L), SpherePowerMap<K>(f), pr, me, L);
  };
  return for_factors<2>(pr.written->factors, run, "system.space: Lagrangians are written on (S^2)^K for K = 2 to 4");
}

}  // namespace dvm::factories
