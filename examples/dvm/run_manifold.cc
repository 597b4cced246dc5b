// `dvm run` for systems on S^2 and SO(3): the step is solved in local coordinates
// (solvers/manifold_step.h; form = "hamiltonian": solvers/manifold_hamiltonian_step.h;
// method = "galerkin": solvers/manifold_galerkin_step.h; all with the same output). Output:
//   S^2    CSV  t, x, y, z, p0, p1, p2, energy, J3           (J3 = (x cross p)_3)
//   SO(3)  CSV  t, qw, qx, qy, qz, pi0, pi1, pi2, energy, m0, m1, m2
//               (unit quaternion of R, body momentum, spatial angular momentum R pi)
// and the same JSON fields as on R^n (q_final is the unit vector or the quaternion,
// p_final the momentum as stored), plus the largest distance from the manifold and the
// error of the conserved momentum. With `composition` the map's steps are composed by
// any table of solvers/composition_methods.h.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>

#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"
#include "examples/dvm/output.h"
#include "examples/dvm/report.h"
#include "examples/dvm/run_manifold.h"
#include "solvers/manifold_composition.h"
#include "solvers/manifold_hamiltonian_step.h"
#include "solvers/manifold_step.h"

namespace dvm::cli {

namespace {

using namespace manifold_run;
using V3 = Vec<double, 3>;
using M3 = Mat<double, 3, 3>;

template <class System, class Map>
int run_with(const Scene& s, const System& L, const Map& R, const RunOptions& o) {
  using M = typename Map::Manifold;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  Point q;
  if constexpr (std::is_same_v<M, SO3>)
    q = SO3::from_quaternion(Vec<double, 4>(s.q[0], s.q[1], s.q[2], s.q[3]));
  else
    q = Eigen::Map<const Point>(s.q.data());
  Covector p, v0;
  if (s.momentum_given) {
    p = Eigen::Map<const Covector>(s.p.data());
    v0 = manifold_legendre_inverse(L, q, p);
  } else {
    v0 = Eigen::Map<const Covector>(s.v.data());
    p = manifold_legendre(L, q, v0);
  }
  const double E0 = manifold_energy(L, q, v0);
  const std::vector<double> J0 = momentum_map(L, q, p);

  StepOptions opt;
  opt.solver = s.solver == "tiny" ? SolverKind::tiny : SolverKind::newton;
  opt.max_iterations = s.max_iterations;
  opt.residual_tolerance = s.tolerance;
  opt.accept_tolerance = std::fmax(opt.accept_tolerance, s.tolerance);
  // form = "hamiltonian": Eq. 5.1 solved in a chart (solvers/manifold_hamiltonian_step.h)
  // (written-out Hamiltonians of the S^2 and SO(3) systems; the chain has none yet)
  if (s.form == "hamiltonian") {
    if constexpr (std::is_same_v<M, Sphere> || std::is_same_v<M, SO3>)
      return run_stepper(s, L, R, o,
                         ManifoldHamiltonianStep<decltype(hamiltonian_of(L)), Map>(hamiltonian_of(L), R, s.step, opt),
                         q, p, v0, E0, J0);
    else
      throw InputError(s.path + ": key 'integrator.form': " + s.system +
                       " runs the lagrangian form only (form = \"hamiltonian\" is wired for S^2 and SO(3) systems)");
  }
  // method = "galerkin": the Galerkin discrete Lagrangian of L pulled back to the chart
  // centred at the current point (solvers/manifold_galerkin_step.h); the scene reader
  // has refused it with the chain, other forms, compositions and boundary values
  if (s.method == "galerkin") {
    if constexpr (std::is_same_v<M, Sphere> || std::is_same_v<M, SO3>)
      return run_manifold_galerkin(s, L, R, o, opt, q, p, v0, E0, J0);
    else
      throw InputError(s.path + ": key 'integrator.method': " + s.system + " takes no method = \"galerkin\"");
  }
  // the map's own step, or its steps composed (a non-symmetric map entering with its
  // adjoint, theta -> 1 - theta; solvers/manifold_composition.h)
  if (s.composition != "none")
    return run_stepper(s, L, R, o,
                       ComposedManifoldStep<System, Map>(
                           L, R, s.step, substeps(find_composition(s.composition), R.symmetric()), opt),
                       q, p, v0, E0, J0);
  return run_stepper(s, L, R, o, ManifoldStep<System, Map>(L, R, s.step, opt), q, p, v0, E0, J0);
}

SphereMap sphere_map(const std::string& name) {
  const bool exp = name.find("exp") != std::string::npos;
  const bool fixed = name.find("fixed") != std::string::npos;
  return SphereMap(exp ? RetractionKind::exp : RetractionKind::projection, fixed ? 0.0 : 0.5, name);
}
SO3Map so3_map(const std::string& name) {
  const bool exp = name.find("exp") != std::string::npos;
  const bool fixed = name.find("fixed") != std::string::npos;
  return SO3Map(exp ? RetractionKind::exp : RetractionKind::cayley, fixed ? 0.0 : 0.5, name);
}

}  // namespace

int run_manifold_scene(const Scene& s, const RunOptions& o) {
  const auto& P = s.params;
  if (s.system == "spherical-chain") {
    const int n = static_cast<int>(P.at("n"));
    auto chain = [&](auto k) {
      constexpr int K = decltype(k)::value;
      return run_with(s,
                      SphericalChain<K>(Vec<double, K>::Constant(P.at("m")), Vec<double, K>::Constant(P.at("l")),
                                        P.at("g")),
                      SpherePowerMap<K>(sphere_map(s.map)), o);
    };
    switch (n) {
      case 1: return chain(std::integral_constant<int, 1>{});
      case 2: return chain(std::integral_constant<int, 2>{});
      case 3: return chain(std::integral_constant<int, 3>{});
      default: return chain(std::integral_constant<int, 4>{});
    }
  }
  if (s.system == "spherical-pendulum")
    return run_with(s, SphericalPendulum(P.at("m"), P.at("l"), P.at("g")), sphere_map(s.map), o);
  const V3 I(P.at("I1"), P.at("I2"), P.at("I3"));
  if (s.system == "rigid-body") return run_with(s, RigidBody(I), so3_map(s.map), o);
  if (s.system == "heavy-top")
    return run_with(s, HeavyTop(I, P.at("m"), P.at("g"), V3(P.at("chi1"), P.at("chi2"), P.at("chi3"))), so3_map(s.map),
                    o);
  throw InputError(s.path + ": system \"" + s.system + "\" has no runner");
}

}  // namespace dvm::cli
