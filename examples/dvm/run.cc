// `dvm run`: integrate a scene. The system and map named in the scene are resolved
// once, here, into one instantiation of the templated run of run_with.h; the loop
// itself has no runtime dispatch. The systems added with issue 6 have their own
// translation units (run_classic.cc, run_nbody.cc, run_written.cc).
#include "examples/dvm/commands.h"
#include "examples/dvm/run_with.h"

namespace dvm::cli {

int run_scene(const Scene& s, const RunOptions& o) {
  try {
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
