// `dvm run` with method = "galerkin" on S^2 and SO(3): the stage count of the scene
// (1..6) dispatched to the fixed-size generating-function step
// (solvers/manifold_galerkin_step.h). Included by one translation unit per system,
// so that no single unit compiles all eighteen steps.
#pragma once

#include "examples/dvm/run_manifold.h"
#include "solvers/manifold_galerkin_step.h"

namespace dvm::cli::manifold_run {

template <class System, class Map>
int run_galerkin_stages(const Scene& s, const System& L, const Map& R, const RunOptions& o, const StepOptions& opt,
                        const typename Map::Manifold::template Point<double>& q,
                        const typename Map::Manifold::template Tangent<double>& p,
                        const typename Map::Manifold::template Tangent<double>& v0, double E0,
                        const std::vector<double>& J0) {
  const QuadratureKind kind = s.quadrature == "lobatto" ? QuadratureKind::lobatto : QuadratureKind::gauss;
  switch (s.stages) {
    case 1: return run_stepper(s, L, R, o, ManifoldGalerkinStep<System, 1>(L, kind, s.step, opt), q, p, v0, E0, J0);
    case 2: return run_stepper(s, L, R, o, ManifoldGalerkinStep<System, 2>(L, kind, s.step, opt), q, p, v0, E0, J0);
    case 3: return run_stepper(s, L, R, o, ManifoldGalerkinStep<System, 3>(L, kind, s.step, opt), q, p, v0, E0, J0);
    case 4: return run_stepper(s, L, R, o, ManifoldGalerkinStep<System, 4>(L, kind, s.step, opt), q, p, v0, E0, J0);
    case 5: return run_stepper(s, L, R, o, ManifoldGalerkinStep<System, 5>(L, kind, s.step, opt), q, p, v0, E0, J0);
    case 6: return run_stepper(s, L, R, o, ManifoldGalerkinStep<System, 6>(L, kind, s.step, opt), q, p, v0, E0, J0);
    default: throw InputError(s.path + ": key 'integrator.stages': expected a whole number from 1 to 6");
  }
}

}  // namespace dvm::cli::manifold_run
