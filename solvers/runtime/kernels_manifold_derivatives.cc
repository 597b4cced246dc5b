// The derivatives of the position-momentum steps the runtime takes on S^2 and SO(3)
// (ManifoldStep::derivatives, solvers/manifold_step_derivative.h; dvm run --linearize),
// instantiated here for the step types of kernels_sphere.cc and kernels_rotation.cc, with
// and without a force, so that those files compile the steps without their derivatives.
// (The Hamiltonian steps' derivatives are instantiated in those files themselves: they
// solve the chart step again, whose code a file here would compile a second time.)
#include "solvers/manifold_step_derivative.h"
#include "solvers/runtime/kernels_manifold.h"

namespace dvm {

template bool ManifoldStep<kernels::BuiltinOrWritten<SphericalPendulum>, SphereMap>::derivatives(
    double, const Point&, const Covector&, const Point&, Eigen::MatrixXd&, Eigen::MatrixXd*) const;
template bool ManifoldStep<kernels::BuiltinOrWritten<SphericalPendulum>, SphereMap, ManifoldForce<Sphere>>::derivatives(
    double, const Point&, const Covector&, const Point&, Eigen::MatrixXd&, Eigen::MatrixXd*) const;
template bool ManifoldStep<kernels::BuiltinOrWritten<HeavyTop>, SO3Map>::derivatives(
    double, const Point&, const Covector&, const Point&, Eigen::MatrixXd&, Eigen::MatrixXd*) const;
template bool ManifoldStep<kernels::BuiltinOrWritten<HeavyTop>, SO3Map, ManifoldForce<SO3>>::derivatives(
    double, const Point&, const Covector&, const Point&, Eigen::MatrixXd&, Eigen::MatrixXd*) const;

}  // namespace dvm
