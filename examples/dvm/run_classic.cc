// `dvm run` for the classic systems of mechanics/systems_classic.h (one translation
// unit, so that the original run.cc stays small to compile).
#include "examples/dvm/run_with.h"

namespace dvm::cli {

int run_classic(const Scene& s, const RunOptions& o) {
  const auto& P = s.params;
  if (s.system == "double-pendulum")
    return run_system(s, DoublePendulum(P.at("m1"), P.at("m2"), P.at("l1"), P.at("l2"), P.at("g")), o);
  if (s.system == "henon-heiles") return run_system(s, HenonHeiles(P.at("lambda")), o);
  if (s.system == "fpu") return run_system(s, FermiPastaUlam(P.at("omega")), o);
  if (s.system == "duffing") return run_system(s, Duffing(P.at("alpha"), P.at("beta")), o);
  if (s.system == "charged-particle")
    return run_system(s, ChargedParticle(P.at("m"), P.at("c"), P.at("B"), P.at("k")), o);
  throw InputError(s.path + ": system \"" + s.system + "\" has no runner");
}

}  // namespace dvm::cli
