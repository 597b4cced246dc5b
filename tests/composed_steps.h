// The position-momentum steps of a map and of its adjoint map, composed (paper Sec. 6,
// route 1 of solvers/composition.h), on R^n and on S^2, (S^2)^n or SO(3): the
// compositions the suites build by hand from a system, a map and substeps. The runtime
// builds the same steps through ComposedStep and ComposedPointStep
// (solvers/runtime/kernels.h, kernels_manifold.h).
#pragma once

#include <utility>
#include <vector>

#include "core/map_operations.h"
#include "solvers/composition.h"
#include "solvers/manifold_composition.h"
#include "solvers/manifold_step.h"
#include "solvers/position_momentum_step.h"

namespace dvm {

// On R^n: the position-momentum steps of R_d and of its adjoint R_d^* (Prop. 2.4).
template <class System, class Map>
class CompositionStep
    : public ComposedStep<PositionMomentumStep<System, Map>, PositionMomentumStep<System, Adjoint<Map>>> {
 public:
  using Plain = PositionMomentumStep<System, Map>;
  using Dual = PositionMomentumStep<System, Adjoint<Map>>;
  using Base = ComposedStep<Plain, Dual>;

  CompositionStep(const System& L, const Map& R, double h, std::vector<Substep> substeps, StepOptions options = {})
      : Base(
            h, std::move(substeps), [&](double hk) { return Plain(L, R, hk, options); },
            [&](double hk) { return Dual(L, adjoint(R), hk, options); }) {}
};

// On a manifold: the position-momentum steps of a map; one that is not symmetric enters
// with its adjoint (theta -> 1 - theta).
template <class System, class Map>
class ComposedManifoldStep : public ComposedPointStep<ManifoldStep<System, Map>> {
 public:
  using Stage = ManifoldStep<System, Map>;
  ComposedManifoldStep(const System& L, const Map& R, double h, const std::vector<Substep>& substeps,
                       StepOptions options = {})
      : ComposedPointStep<Stage>(
            h, substeps, [&](double hk) { return Stage(L, R, hk, options); },
            [&](double hk) { return Stage(L, adjoint_map(R), hk, options); }) {}
};

}  // namespace dvm
