// `dvm check-map`: the identity checks of core/map_checks.h on a named map.
#include <iostream>

#include "core/manifold_checks.h"
#include "core/map_checks.h"
#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"

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

template <int N, class M>
int report(const M& map, double theta, double tolerance) {
  const MapCheckReport r = check_map<N>(map);
  const bool ok = report_passes(r, tolerance);
  return print_report(r, "R^n", theta, tolerance, ok);
}

template <int N>
int dispatch(const std::string& name, double theta, double tolerance) {
  if (name == "explicit-euler") return report<N>(ThetaMap::explicit_euler(), 0.0, tolerance);
  if (name == "adjoint-euler") return report<N>(ThetaMap::adjoint_euler(), 1.0, tolerance);
  if (name == "midpoint") return report<N>(ThetaMap::midpoint(), 0.5, tolerance);
  if (name == "theta") return report<N>(ThetaMap(theta), theta, tolerance);
  return report<N>(RetractionMap<EuclideanRetraction>({}, theta), theta, tolerance);
}

}  // namespace

int check_map_command(const std::string& name, double theta, int dim, double tolerance) {
  const MapInfo& info = find_map(name, "check-map");
  if (info.space != "R^n") {
    const bool exp = name.find("exp") != std::string::npos, fixed = name.find("fixed") != std::string::npos;
    const double th = fixed ? 0.0 : 0.5;
    if (info.space == "S^2")
      return report_manifold(SphereMap(exp ? RetractionKind::exp : RetractionKind::projection, th, name), tolerance);
    return report_manifold(SO3Map(exp ? RetractionKind::exp : RetractionKind::cayley, th, name), tolerance);
  }
  if (!(theta >= 0.0 && theta <= 1.0))
    throw InputError("check-map: --theta " + std::to_string(theta) + " is outside [0, 1]");
  switch (dim) {
    case 1: return dispatch<1>(name, theta, tolerance);
    case 2: return dispatch<2>(name, theta, tolerance);
    case 3: return dispatch<3>(name, theta, tolerance);
    case 4: return dispatch<4>(name, theta, tolerance);
    default:
      throw InputError("check-map: --dim " + std::to_string(dim) + " is not supported; expected 1, 2, 3 or 4");
  }
}

}  // namespace dvm::cli
