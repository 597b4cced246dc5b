// The identity checks of a map of the registry (check_map.h), instantiated for every
// map family and space; compiled at -O1 in optimized builds (solvers/CMakeLists.txt).
#include "solvers/runtime/check_map.h"

#include <cmath>
#include <variant>

#include "core/manifold_checks.h"
#include "core/map_checks.h"
#include "solvers/runtime/errors.h"
#include "solvers/runtime/json.h"
#include "solvers/runtime/manifold_map_of.h"
#include "solvers/runtime/registry.h"

namespace dvm {

namespace {

MapCheck outcome(const MapCheckReport& r, const std::string& space, double theta, double tolerance, bool ok) {
  MapCheck c;
  c.map = r.map_name;
  c.space = space;
  c.theta = theta;
  c.dim = r.dimension;
  c.claims_symmetric = r.claims_symmetric;
  for (const auto& e : r.entries) c.residuals.emplace_back(e.name, e.residual);
  c.tolerance = tolerance;
  c.passed = ok;
  return c;
}

// Manifold maps: the R^n identities on the local representation, plus the closed-form
// inverse on the manifold (round trip, and against Newton's method in coordinates).
template <class Map>
MapCheck check_manifold(const Map& map, double tolerance) {
  const MapCheckReport r = check_manifold_map(map);
  const bool ok = report_passes(r, tolerance) && r.residual("manifold_round_trip") <= tolerance &&
                  r.residual("closed_form_vs_newton") <= tolerance;
  return outcome(r, Map::Manifold::name, map.theta(), tolerance, ok);
}

// The maps on R^n run as ThetaMap or WrittenMap (retraction-theta is the written
// retraction x + v, as in the runtime: solvers/runtime/kernels.h).
template <int N>
MapCheck check_rn(const std::variant<ThetaMap, WrittenMap>& map, double theta, double tolerance) {
  return std::visit(
      [&](const auto& m) {
        const MapCheckReport r = check_map<N>(m);
        return outcome(r, "R^n", theta, tolerance, report_passes(r, tolerance));
      },
      map);
}

MapCheck check_rn_dim(const std::variant<ThetaMap, WrittenMap>& map, int dim, double theta, double tolerance) {
  switch (dim > 0 ? dim : 2) {
    case 1: return check_rn<1>(map, theta, tolerance);
    case 2: return check_rn<2>(map, theta, tolerance);
    case 3: return check_rn<3>(map, theta, tolerance);
    case 4: return check_rn<4>(map, theta, tolerance);
    default: break;
  }
  throw InputError("check-map: --dim " + std::to_string(dim) + " is not supported; expected 1, 2, 3 or 4");
}

}  // namespace

MapCheck check_map(const std::string& name, double theta, int dim, double tolerance,
                   const std::shared_ptr<const WrittenRetraction>& written) {
  const MapEntry& e = find_map_entry(name, "check-map");
  if (e.retraction == MapRetraction::written && !written)
    throw InputError("check-map: map \"" + e.name + "\" is read from a scene: dvm check-map --scene FILE");
  if (theta < 0.0) theta = e.theta;  // not given: the map's own
  if (!(theta >= 0.0 && theta <= 1.0))
    throw InputError("check-map: --theta " + std::to_string(theta) + " is outside [0, 1]");
  if (!e.takes_theta && theta != e.theta)
    throw InputError("check-map: --theta applies only to " + theta_map_names() + ", not \"" + e.name + "\"");
  if (e.space != Space::euclidean) {
    if (dim > 0)
      throw InputError("check-map: --dim applies only to maps on R^n; \"" + e.name + "\" lives on " +
                       to_string(e.space));
    if (e.family == MapFamily::sphere) return check_manifold(sphere_map_of(e, theta, written), tolerance);
    return check_manifold(so3_map_of(e, theta, written), tolerance);
  }
  if (e.family == MapFamily::theta) return check_rn_dim(ThetaMap(theta, e.name), dim, theta, tolerance);
  if (e.family == MapFamily::retraction_theta)
    return check_rn_dim(WrittenMap::flat_retraction("retraction-theta(euclidean)", theta), dim, theta, tolerance);
  throw InputError("check-map: map \"written\" is read from a scene: dvm check-map --scene FILE");
}

MapCheck check_scene_map(const Scene& s, int dim, double tolerance) {
  const Method& me = s.method;
  if (!me.map) throw InputError("check-map: " + s.path + " names no map (integrator.map)");
  if (me.map->family == MapFamily::written)
    return check_rn_dim(*me.written_map, dim, me.written_map->is_retraction() ? me.theta : NAN, tolerance);
  return check_map(me.map->name, me.theta, dim, tolerance, me.written_retraction);
}

std::string map_check_json(const MapCheck& c) {
  Json::Object j;
  j.str("map", c.map).str("space", c.space).num("theta", c.theta).num("dim", c.dim).boolean("claims_symmetric",
                                                                                              c.claims_symmetric);
  Json::Object res;
  for (const auto& [name, residual] : c.residuals) res.num(name, residual);
  j.raw("residuals", res.dump(4)).num("tolerance", c.tolerance).boolean("passed", c.passed);
  return j.dump();
}

}  // namespace dvm
