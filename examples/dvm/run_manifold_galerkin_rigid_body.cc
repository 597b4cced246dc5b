// `dvm run` with method = "galerkin" for the free rigid body (run_manifold_galerkin.h).
#include "examples/dvm/run_manifold_galerkin.h"

namespace dvm::cli::manifold_run {

int run_manifold_galerkin(const Scene& s, const RigidBody& L, const SO3Map& R, const RunOptions& o, const StepOptions& opt,
                          const M3& q, const V3& p, const V3& v0, double E0, const std::vector<double>& J0) {
  return run_galerkin_stages(s, L, R, o, opt, q, p, v0, E0, J0);
}

}  // namespace dvm::cli::manifold_run
