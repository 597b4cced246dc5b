// `dvm check-map`: the identity checks of core/map_checks.h on a named map.
#include <iostream>

#include "core/map_checks.h"
#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"

namespace dvm::cli {

namespace {

template <int N, class M>
int report(const M& map, double theta, double tolerance) {
  const MapCheckReport r = check_map<N>(map);
  const bool ok = report_passes(r, tolerance);
  Json::Object j;
  j.str("map", r.map_name).num("theta", theta).num("dim", N).boolean("claims_symmetric", r.claims_symmetric);
  Json::Object res;
  for (const auto& e : r.entries) res.num(e.name, e.residual);
  j.raw("residuals", res.dump(4)).num("tolerance", tolerance).boolean("passed", ok);
  std::cout << j.dump() << "\n";
  return ok ? 0 : 1;
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
  find_map(name, "check-map");
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
