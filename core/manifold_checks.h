// Identity checks for discretization maps on manifolds.
//
// Every R^n identity of core/map_checks.h is checked on the map's local
// representation (the map in the chart centred at a base point), where it is the
// same identity written in coordinates; in addition the closed-form inverse is
// checked on the manifold itself (round trip with the stored points and vectors) and
// against Newton's method in local coordinates.
#pragma once

#include <random>

#include "core/manifold_maps.h"
#include "core/map_checks.h"

namespace dvm {

template <class Map>
MapCheckReport check_manifold_map(const Map& map, int samples = 16, double velocity_scale = 0.5,
                                  unsigned seed = 2024) {
  using M = typename Map::Manifold;
  constexpr int n = M::dim;
  const auto c = base_point<M>();
  MapCheckReport r = check_map<n>(LocalRepresentation<Map>(map, c), samples, velocity_scale, seed);
  r.map_name = map.name();
  std::mt19937 rng(seed + 1);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double rt = 0.0, cn = 0.0;
  for (int s = 0; s < samples; ++s) {
    Vec<double, n> eta, nu;
    for (int i = 0; i < n; ++i) {
      eta[i] = U(rng);
      nu[i] = velocity_scale * U(rng);
    }
    const auto x = M::chart(c, eta);
    const auto v = M::tangent(x, nu);
    const ManifoldPair<M, double> q = map(x, v);
    const ManifoldTangent<M, double> t = map.inverse(q.q0, q.q1);
    rt = std::fmax(rt, std::fmax(M::distance(t.x, x), max_abs(t.v - v)));
    const ManifoldTangent<M, double> u = newton_manifold_inverse_values(map, q.q0, q.q1);
    cn = std::fmax(cn, std::fmax(M::distance(t.x, u.x), max_abs(t.v - u.v)));
  }
  r.entries.push_back({"manifold_round_trip", rt});
  r.entries.push_back({"closed_form_vs_newton", cn});
  return r;
}

}  // namespace dvm
