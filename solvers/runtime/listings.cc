#include "solvers/runtime/listings.h"

#include <cmath>

#include "solvers/runtime/json.h"
#include "solvers/runtime/registry.h"
#include "solvers/splitting_step.h"
#include "solvers/stability.h"

namespace dvm {

std::vector<CompositionListing> composition_listings() {
  std::vector<CompositionScheme> list = composition_schemes();
  for (int p = 6; p <= RecursiveTripleJump::max_order; p += 2)
    list.push_back(find_composition("triple-jump:" + std::to_string(p)));
  std::vector<CompositionListing> rows;
  for (const CompositionScheme& s : list) {
    const bool splitting = s.kind == CompositionKind::rkn_splitting;  // kicks and drifts: no midpoint stages
    rows.push_back({s, composition_threshold(0.0, substeps(s, false)),
                    !splitting && std::isinf(composition_threshold(0.5, substeps(s, true))),
                    splitting_forces_per_step(splitting_sequence(0.0, substeps(s, false), 1.0))});
  }
  return rows;
}

double euler_threshold() { return composition_threshold(0.0, {{1.0, false}}); }

int euler_forces_per_step() { return splitting_forces_per_step(splitting_sequence(0.0, {{1.0, false}}, 1.0)); }

std::string systems_json() {
  const auto& systems = system_registry();
  std::string out = "[\n";
  for (std::size_t i = 0; i < systems.size(); ++i) {
    const SystemEntry& sy = systems[i];
    Json::Object j;
    j.str("name", sy.name).num("dim", sy.dim).str("lagrangian", sy.lagrangian).str("space", to_string(sy.space));
    Json::Object ps;
    for (const auto& p : sy.params) ps.num(p.name, p.default_value);
    j.raw("params", ps.dump(6));
    std::string forms = "[";
    for (std::size_t k = 0; k < sy.caps.forms.size(); ++k)
      forms += (k ? ", " : "") + Json::string(to_string(sy.caps.forms[k]));
    j.raw("forms", forms + "]")
        .boolean("retraction_maps", sy.caps.retraction_maps)
        .boolean("written_maps", sy.caps.written_maps)
        .boolean("composition", sy.caps.composition)
        .boolean("galerkin", sy.caps.galerkin)
        .boolean("boundary_value", sy.caps.boundary_value);
    out += "  " + j.dump(4) + (i + 1 < systems.size() ? ",\n" : "\n");
  }
  return out + "]\n";
}

std::string maps_json() {
  const auto& maps = map_registry();
  std::string out = "[\n";
  for (std::size_t i = 0; i < maps.size(); ++i) {
    const MapEntry& m = maps[i];
    Json::Object j;
    j.str("name", m.name)
        .str("formula", m.formula)
        .boolean("symmetric", m.symmetric(m.theta) && !m.takes_theta)
        .num("order", m.takes_theta ? 1 : m.order(m.theta))
        .boolean("closed_form_inverse", m.closed_inverse)
        .str("space", to_string(m.space))
        .str("note", m.note)
        .boolean("takes_theta", m.takes_theta);
    out += "  " + j.dump(4) + (i + 1 < maps.size() ? ",\n" : "\n");
  }
  return out + "]\n";
}

std::string methods_json() {
  std::string out = "[\n";
  {
    Json::Object j;
    j.str("name", "none")
        .str("order", "that of the map")
        .num("stages", 1)
        .str("symmetric", "as the map")
        .num("stability_threshold_explicit_euler", euler_threshold())
        .num("forces_per_step_explicit_euler", euler_forces_per_step())
        .boolean("midpoint_unconditionally_stable", true)
        .str("citation", NoComposition::citation);
    out += "  " + j.dump(4) + ",\n";
  }
  for (const CompositionListing& r : composition_listings()) {
    Json::Object j;
    j.str("name", r.scheme.name)
        .num("order", r.scheme.order)
        .num("stages", r.scheme.stages)
        .boolean("symmetric", r.scheme.symmetric)
        .num("stability_threshold_explicit_euler", r.threshold_verlet)
        .num("forces_per_step_explicit_euler", r.forces_verlet);
    if (r.splitting())  // refused with map = "midpoint"; stages count the forces of a step
      j.raw("midpoint_unconditionally_stable", "null")
          .str("applies_to", "separable systems, map explicit-euler or adjoint-euler");
    else
      j.boolean("midpoint_unconditionally_stable", r.midpoint_unconditional);
    j.str("citation", r.scheme.citation);
    out += "  " + j.dump(4) + ",\n";
  }
  for (const GalerkinEntry& g : galerkin_registry()) {
    Json::Object j;
    j.str("name", "galerkin")
        .str("quadrature", to_string(g.quadrature))
        .num("stages", g.stages)
        .num("points", g.points)
        .num("order", g.order)
        .boolean("symmetric", true)
        .str("citation", g.citation);
    out += "  " + j.dump(4) + ",\n";
  }
  // the lifts of the map (integrator.lift), named "lift <name>" apart from the compositions
  const auto& lifts = lift_registry();
  for (std::size_t i = 0; i < lifts.size(); ++i) {
    const LiftEntry& l = lifts[i];
    std::string forms;
    for (Form f : l.forms) forms += (forms.empty() ? "" : ", ") + std::string(to_string(f));
    Json::Object j;
    j.str("name", "lift " + l.name).str("lift", l.name).str("forms", forms).str("description", l.description);
    out += "  " + j.dump(4) + (i + 1 < lifts.size() ? ",\n" : "\n");
  }
  return out + "]\n";
}

}  // namespace dvm
