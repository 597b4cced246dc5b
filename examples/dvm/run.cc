// `dvm run`: integrate a scene. The system and map named in the scene are resolved
// once, here, into one instantiation of the templated run of run_with.h; the loop
// itself has no runtime dispatch. Other systems and forms have their own translation
// units: run_manifold.cc (S^2, SO(3)), run_forms.cc (Hamiltonian, SODE and Newmark
// forms, the chain, boundary-value problems), run_classic.cc, run_nbody.cc and
// run_written.cc (the classic systems and Lagrangians written in the scene).
#include "examples/dvm/commands.h"
#include "examples/dvm/run_forms.h"
#include "examples/dvm/run_with.h"

namespace dvm::cli {

// [problem] kind = "boundary-value" on S^2 (run_manifold_bvp.cc; declared here rather
// than in commands.h so that adding it recompiles no other runner).
int run_manifold_boundary_value(const Scene& scene, const RunOptions& options);

int run_scene(const Scene& s, const RunOptions& o) {
  try {
    if (s.space != "R^n")
      return s.problem == "boundary-value" ? run_manifold_boundary_value(s, o) : run_manifold_scene(s, o);
    // boundary-value problems, the dynamic-size chain, the other forms
    if (s.problem == "boundary-value") return run_boundary_value(s, o);
    if (s.system == "chain") return run_chain(s, o);
    if (s.form != "lagrangian") return run_form(s, o);
    const auto& P = s.params;
    if (s.system == "harmonic") return run_system(s, HarmonicOscillator(P.at("omega")), o);
    if (s.system == "pendulum") return run_system(s, Pendulum(P.at("m"), P.at("l"), P.at("g")), o);
    if (s.system == "kepler") return run_system(s, Kepler(P.at("mu")), o);
    if (s.system == "lagrangian") return run_written(s, o);
    if (s.system == "nbody") return run_nbody(s, o);
    return run_classic(s, o);
  } catch (const std::invalid_argument& e) {
    throw InputError(s.path + ": " + e.what());
  } catch (const DegenerateLagrangianError& e) {
    throw InputError(s.path + ": " + e.what());
  }
}

}  // namespace dvm::cli
