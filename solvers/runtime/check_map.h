// The identity checks of a discretization map (core/map_checks.h; on S^2 and SO(3) also
// core/manifold_checks.h) on a map of the registry, or on the map a scene runs: what
// `dvm check-map` prints, and what the Python module's check_map returns.
//
// Each identity's residual is the largest over random sample points (a fixed seed: the
// same numbers every time). The check passes when every identity holds to `tolerance`
// and adjoint_difference matches the map's symmetry claim (zero for a symmetric map,
// clearly non-zero otherwise); on S^2 and SO(3) also the closed-form inverse
// (manifold_round_trip, closed_form_vs_newton).
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "solvers/runtime/scene.h"

namespace dvm {

struct MapCheck {
  std::string map;    // the map's name ("midpoint", "sphere-exp", "written", ...)
  std::string space;  // "R^n", "S^2", "SO(3)"
  double theta = 0.0;  // the map's theta (NaN for a written map that is not a retraction form)
  int dim = 0;         // the dimension the identities were checked in (on a manifold, its chart's)
  bool claims_symmetric = false;
  std::vector<std::pair<std::string, double>> residuals;  // identity name, largest residual
  double tolerance = 1e-12;
  bool passed = false;
};

// The map `name` of the registry. theta < 0: the map's own; dim 0: the default (2 on
// R^n; maps on a manifold take none). `written`: the retraction of a "sphere-written"
// or "so3-written" map (from a scene). Throws InputError (messages start "check-map: ")
// for an unknown name, a theta outside [0, 1] or given to a map without one, a dim
// other than 1 to 4 or given to a map on a manifold, a written map without its scene.
MapCheck check_map(const std::string& name, double theta, int dim, double tolerance,
                   const std::shared_ptr<const WrittenRetraction>& written = nullptr);

// The map a scene runs: with map = "written", "sphere-written" or "so3-written" the map
// of its [map] section (the scene reader has refused one that breaks Def. 2.2).
MapCheck check_scene_map(const Scene& scene, int dim, double tolerance);

// The JSON `dvm check-map` prints (one object: map, space, theta, dim,
// claims_symmetric, residuals, tolerance, passed).
std::string map_check_json(const MapCheck& c);

}  // namespace dvm
