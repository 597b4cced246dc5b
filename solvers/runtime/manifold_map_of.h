// The S^2 and SO(3) map a registry entry names (solvers/runtime/registry.h), at a
// theta: SphereMap or SO3Map of its retraction, or of the retraction the scene writes
// (map = "sphere-written", "so3-written"). Used by the kernels and by `dvm check-map`.
#pragma once

#include <memory>
#include <string>

#include "core/manifold_maps.h"
#include "mechanics/written_retraction.h"
#include "solvers/runtime/errors.h"
#include "solvers/runtime/registry.h"

namespace dvm {

inline RetractionKind retraction_kind(const MapEntry& e) {
  switch (e.retraction) {
    case MapRetraction::exp: return RetractionKind::exp;
    case MapRetraction::projection: return RetractionKind::projection;
    case MapRetraction::cayley: return RetractionKind::cayley;
    case MapRetraction::written: return RetractionKind::written;
    case MapRetraction::none: break;
  }
  throw InputError("integrator.map: map \"" + e.name + "\" is not built from a retraction of S^2 or SO(3)");
}

// The written retraction of a "-written" entry, checked to be there and on the entry's space.
inline std::shared_ptr<const WrittenRetraction> written_retraction_for(
    const MapEntry& e, const std::shared_ptr<const WrittenRetraction>& f) {
  if (!f)
    throw InputError("integrator.map: map = \"" + e.name + "\" needs the scene's [map] section (retraction = [...])");
  const auto space = e.family == MapFamily::sphere ? WrittenRetraction::Space::sphere : WrittenRetraction::Space::rotation;
  if (f->space() != space)
    throw InputError("integrator.map: the [map] retraction is written on " +
                     std::string(f->space() == WrittenRetraction::Space::sphere ? "S^2" : "SO(3)") +
                     ", map \"" + e.name + "\" lives on " + (space == WrittenRetraction::Space::sphere ? "S^2" : "SO(3)"));
  return f;
}

inline SphereMap sphere_map_of(const MapEntry& e, double theta, const std::shared_ptr<const WrittenRetraction>& f) {
  if (e.family != MapFamily::sphere) throw InputError("integrator.map: map \"" + e.name + "\" does not live on S^2");
  if (e.retraction == MapRetraction::written) return SphereMap(written_retraction_for(e, f), theta, e.name);
  return SphereMap(retraction_kind(e), theta, e.name);
}

inline SO3Map so3_map_of(const MapEntry& e, double theta, const std::shared_ptr<const WrittenRetraction>& f) {
  if (e.family != MapFamily::rotation) throw InputError("integrator.map: map \"" + e.name + "\" does not live on SO(3)");
  if (e.retraction == MapRetraction::written) return SO3Map(written_retraction_for(e, f), theta, e.name);
  return SO3Map(retraction_kind(e), theta, e.name);
}

}  // namespace dvm
