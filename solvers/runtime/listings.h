// The listings of the registries as the dvm program prints them with --json: the
// built-in systems (`dvm systems`), the maps (`dvm maps`) and the methods
// (`dvm methods`: the compositions with the linear stability threshold of each, the
// Galerkin discrete Lagrangians and the lifts). The program and the bindings print
// these same texts; nothing here lists a name the registries do not hold.
#pragma once

#include <string>
#include <vector>

#include "solvers/composition_methods.h"

namespace dvm {

// A composition as `dvm methods` lists it: its scheme, the largest stable h omega on
// q'' = -omega^2 q with the explicit Euler map (whose symmetric basic method is
// Stormer-Verlet, found from the trace of the one-step matrix, solvers/stability.h),
// whether every h omega is stable with the midpoint map, and the forces a step takes
// with the explicit Euler map on a separable system.
struct CompositionListing {
  CompositionScheme scheme;
  double threshold_verlet;
  bool midpoint_unconditional;
  int forces_verlet;
  // a splitting into kicks and drifts (no midpoint stages)
  bool splitting() const { return scheme.kind == CompositionKind::rkn_splitting; }
};
// Every composition of the registry, then the recursive triple jumps of order 6 up.
std::vector<CompositionListing> composition_listings();
// The basic method alone (composition "none") with the explicit Euler map: its
// stability threshold and its forces a step.
double euler_threshold();
int euler_forces_per_step();

// JSON arrays of objects, one per entry, ending in a newline.
std::string systems_json();
std::string maps_json();
std::string methods_json();

}  // namespace dvm
