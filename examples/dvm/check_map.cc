// `dvm check-map`: the identity checks of core/map_checks.h on a map of the registry.
#include <cmath>
#include <iostream>
#include <variant>

#include "core/manifold_checks.h"
#include "core/map_checks.h"
#include "examples/dvm/commands.h"
#include "solvers/runtime/scene.h"
#include "solvers/runtime/json.h"
#include "solvers/runtime/manifold_map_of.h"
#include "solvers/runtime/registry.h"

namespace dvm::cli {

namespace {

int print_report(const MapCheckReport& r, const std::string& space, double theta, double tolerance, bool ok) {
  Json::Object j;
  j.str("map", r.map_name)
      .str("space", space)
      .num("theta", theta)
      .num("dim", r.dimension)
      .boolean("claims_symmetric", r.claims_symmetric);
  Json::Object res;
  for (const auto& e : r.entries) res.num(e.name, e.residual);
  j.raw("residuals", res.dump(4)).num("tolerance", tolerance).boolean("passed", ok);
  std::cout << j.dump() << "\n";
  return ok ? 0 : 1;
}

// Manifold maps: the R^n identities on the local representation, plus the closed-form
// inverse on the manifold (round trip, and against Newton's method in coordinates).
template <class Map>
int report_manifold(const Map& map, double tolerance) {
  const MapCheckReport r = check_manifold_map(map);
  const bool ok = report_passes(r, tolerance) && r.residual("manifold_round_trip") <= tolerance &&
                  r.residual("closed_form_vs_newton") <= tolerance;
  return print_report(r, Map::Manifold::name, map.theta(), tolerance, ok);
}

// The maps on R^n run as ThetaMap or WrittenMap (retraction-theta is the written
// retraction x + v, as in the runtime: solvers/runtime/kernels.h).
template <int N>
int report_rn(const std::variant<ThetaMap, WrittenMap>& map, double theta, double tolerance) {
  return std::visit(
      [&](const auto& m) {
        const MapCheckReport r = check_map<N>(m);
        return print_report(r, "R^n", theta, tolerance, report_passes(r, tolerance));
      },
      map);
}

int report_rn_dim(const std::variant<ThetaMap, WrittenMap>& map, int dim, double theta, double tolerance) {
  switch (dim > 0 ? dim : 2) {
    case 1: return report_rn<1>(map, theta, tolerance);
    case 2: return report_rn<2>(map, theta, tolerance);
    case 3: return report_rn<3>(map, theta, tolerance);
    case 4: return report_rn<4>(map, theta, tolerance);
    default: break;
  }
  throw InputError("check-map: --dim " + std::to_string(dim) + " is not supported; expected 1, 2, 3 or 4");
}

}  // namespace

int check_map_command(const std::string& name, double theta, int dim, double tolerance,
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
    if (e.family == MapFamily::sphere) return report_manifold(sphere_map_of(e, theta, written), tolerance);
    return report_manifold(so3_map_of(e, theta, written), tolerance);
  }
  if (e.family == MapFamily::theta) return report_rn_dim(ThetaMap(theta, e.name), dim, theta, tolerance);
  if (e.family == MapFamily::retraction_theta)
    return report_rn_dim(WrittenMap::flat_retraction("retraction-theta(euclidean)", theta), dim, theta, tolerance);
  throw InputError("check-map: map \"written\" is read from a scene: dvm check-map --scene FILE");
}

int check_scene_map_command(const std::string& path, const std::vector<std::string>& overrides, int dim,
                            double tolerance) {
  // the scene's map (load_scene refuses a written map that breaks Def. 2.2, exit 2)
  const Scene s = load_scene(path, overrides);
  const Method& me = s.method;
  if (!me.map) throw InputError("check-map: " + path + " names no map (integrator.map)");
  if (me.map->family == MapFamily::written)
    return report_rn_dim(*me.written_map, dim, me.written_map->is_retraction() ? me.theta : NAN, tolerance);
  return check_map_command(me.map->name, me.theta, dim, tolerance, me.written_retraction);
}

}  // namespace dvm::cli
