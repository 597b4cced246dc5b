// The position-momentum step on a manifold, solved in local coordinates:
//
//   given (q_k, p_k), find xi in R^dim with q_{k+1} = chart(q_k, xi) and
//       p_k + D1 L_d(q_k, q_{k+1}) = 0         (in the chart centred at q_k),
//   then p_{k+1} = D2 L_d(q_k, q_{k+1})        (in the chart centred at q_{k+1}).
//
// Because q_{k+1} is produced by the chart (a retraction), iterates stay on the
// manifold up to round-off; `clean` removes that round-off each step (renormalising
// a unit vector, one Newton-Schulz step for a rotation), so it cannot accumulate. A
// chart result off the manifold by more than 1e-12 fails the step instead: cleaning
// never hides an error of the method.
//
// Round-off: formed from the stored points, the relative position of q1 from q0
// (q1 - q0 on S^2, q0^T q1 on SO(3)) would carry an absolute error of eps |q|, a
// relative error eps/h in the velocity and a noise of eps M/h in the momenta. The
// step instead takes the relative position from its unknown xi
// (M::relative_chart, no cancellation) and the maps invert from it
// (inverse_relative), as the R^n step does with inverse_increment.
// The starting guess for xi comes from the previous increment (second order in h).
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <cstdint>
#include <memory>
#include <stdexcept>

#include "mechanics/manifold_hamiltonian.h"
#include "mechanics/manifold_systems.h"
#include "solvers/integrate.h"
#include "solvers/newton.h"
#include "solvers/newton_driver.h"

namespace dvm {

// The point a step solved in the chart centred at q0 ends at, chart(q0, xi), into raw;
// false (s failed) where the chart left the manifold by more than round-off.
template <class M>
bool chart_end(const typename M::template Point<double>& q0, const Vec<double, M::dim>& xi, StepSummary& s,
               typename M::template Point<double>& raw) {
  raw = M::chart(q0, xi);
  const double defect = M::point_defect(raw);
  if (defect <= 1e-12) return true;
  s.fail("the chart left the manifold by " + std::to_string(defect) + " (more than round-off)");
  return false;
}

// The end of a step: q1 = raw cleaned and p1 from its chart components pi1 in the
// chart centred at raw (s fails where p1 is not finite).
template <class M>
void leave_at(const typename M::template Point<double>& raw, const Vec<double, M::dim>& pi1, StepSummary& s,
              typename M::template Point<double>& q1, typename M::template Tangent<double>& p1) {
  p1 = M::covector_from_local(raw, pi1);
  q1 = M::clean(raw);
  if (!std::isfinite(max_abs(p1))) s.fail("non-finite momentum");
}

// The end of a step solved in the chart centred at q0: the point q1 = chart(q0, xi)
// and the covector p1 with chart components pi1 there. The step s fails if the chart
// left the manifold by more than round-off or if p1 is not finite.
template <class M>
void leave_chart(const typename M::template Point<double>& q0, const Vec<double, M::dim>& xi,
                 const Vec<double, M::dim>& pi1, StepSummary& s, typename M::template Point<double>& q1,
                 typename M::template Tangent<double>& p1) {
  typename M::template Point<double> raw;
  if (!chart_end<M>(q0, xi, s, raw)) return;
  p1 = covector_from_chart_at<M>(q0, xi, pi1);
  q1 = M::clean(raw);
  if (!std::isfinite(max_abs(p1))) s.fail("non-finite momentum");
}

// Canonical coordinates of T*M around a point c, in which a manifold step's derivative
// (ManifoldStep::derivatives) is written: (eta, pi) is the point q = chart(c, eta) and
// the covector p at q with components pi_j = <p, d chart(c, eta)/d eta_j> (the cotangent
// lift of the chart, so these coordinates are canonical: a map that preserves the
// canonical symplectic form has a symplectic Jacobian in them). At eta = 0, pi is
// M::covector_to_local(c, p). K(eta) below maps d eta to the tangent coordinates at q.
template <class M>
Mat<double, M::dim, M::dim> chart_differential(const typename M::template Point<double>& c,
                                               const Vec<double, M::dim>& eta) {
  constexpr int n = M::dim;
  Mat<double, n, n> K;
  const typename M::template Point<double> q = M::chart(c, eta);
  for (int j = 0; j < n; ++j) {
    const Vec<double, n> e = Vec<double, n>::Unit(j);
    K.col(j) = M::tangent_coordinates(q, M::chart_and_tangent(c, eta, e).second);
  }
  return K;
}
// The state (q, p) with canonical coordinates (eta, pi) around c.
template <class M>
void canonical_state(const typename M::template Point<double>& c, const Vec<double, M::dim>& eta,
                     const Vec<double, M::dim>& pi, typename M::template Point<double>& q,
                     typename M::template Tangent<double>& p) {
  const Mat<double, M::dim, M::dim> K = chart_differential<M>(c, eta);
  q = M::chart(c, eta);
  p = M::covector_from_local(q, Vec<double, M::dim>(K.transpose().partialPivLu().solve(pi)));
}
// The canonical coordinates (eta, pi) around c of the state (q, p) (q in the chart's
// domain around c).
template <class M>
void canonical_coordinates(const typename M::template Point<double>& c, const typename M::template Point<double>& q,
                           const typename M::template Tangent<double>& p, Vec<double, M::dim>& eta,
                           Vec<double, M::dim>& pi) {
  eta = M::chart_inverse(c, q);
  pi = chart_differential<M>(c, eta).transpose() * M::covector_to_local(q, p);
}

// Force: a force on the manifold (ManifoldForce<M>, mechanics/written_manifold.h) or
// NoForce; a forced step needs the force object, and adds the discrete
// forces of the Lagrange-d'Alembert principle at the map's node, time t0 + theta h
// (ManifoldDiscreteLagrangian::D1_local, D2_local with the force):
//   p_k + D1 L_d + F_d^- = 0,   p_{k+1} = D2 L_d + F_d^+,
// and reports the force's work h <F, v> over the step (StepSummary::work).
template <class System, class Map, class Force = NoForce>
class ManifoldStep {
 public:
  using M = typename Map::Manifold;
  static constexpr int n = M::dim;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  using DL = ManifoldDiscreteLagrangian<System, Map>;
  static constexpr bool kForced = is_force_v<Force>;

  ManifoldStep(System L, Map R, double h, StepOptions options = {}, std::shared_ptr<const Force> force = nullptr)
      : dl_(std::move(L), std::move(R), h), options_(options), force_(std::move(force)) {
    if (kForced && !force_) throw std::invalid_argument("ManifoldStep: a forced step needs its force");
  }
  const DL& discrete_lagrangian() const { return dl_; }
  double step_size() const { return dl_.step(); }
  // The controls the force reads (0 without a force).
  int controls() const {
    if constexpr (kForced)
      return force_->controls();
    else
      return 0;
  }

  struct Residual {
    const DL* dl;
    Point q0;
    Vec<double, n> p0;  // momentum in the chart centred at q0
    const Force* force;
    double t;  // the node's time
    template <class T>
    bool operator()(const T* xi, T* r) const {
      Vec<T, n> x;
      for (int i = 0; i < n; ++i) x[i] = xi[i];
      Vec<T, n> d1;
      if constexpr (kForced)
        d1 = dl->D1_local(q0, M::chart(q0, x), M::relative_chart(q0, x), *force, t);
      else
        d1 = dl->D1_local(q0, M::chart(q0, x), M::relative_chart(q0, x));
      for (int i = 0; i < n; ++i) r[i] = p0[i] + d1[i];
      return true;
    }
  };

  // One step: xi holds the guess on entry and the chart coordinates of q1 on return.
  StepSummary step(double t, const Point& q0, const Covector& p0, Vec<double, n>& xi, Point& q1, Covector& p1) const {
    const Vec<double, n> p0l = M::covector_to_local(q0, p0);
    const double t_node = t + dl_.map().theta() * dl_.step();
    Residual f{&dl_, q0, p0l, force_.get(), t_node};
    const double pscale = max_abs(p0l);
    StepSummary s;
    try {
      s = solve_step_system<n>(f, xi, 1.0, options_, pscale);
      Point raw;
      if (s.converged && chart_end<M>(q0, xi, s, raw)) {
        const auto rel = M::relative_chart(q0, xi);
        Vec<double, n> pi1;
        if constexpr (kForced)
          pi1 = dl_.D2_local(q0, raw, rel, *force_, t_node, &s.work);
        else
          pi1 = dl_.D2_local(q0, raw, rel);
        leave_at<M>(raw, pi1, s, q1, p1);
      }
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    return s;
  }

  // The derivative of the step from (q0, p0) at time t to its solution q1 (the end of
  // step), by the implicit function theorem on the step's equation, in the canonical
  // coordinates (chart_differential above) around q0 before the step and around q1 after
  // it: A = d(zeta, pi1)/d(eta, pi0) (2n x 2n), and where B is given and the force reads
  // controls, B = d(zeta, pi1)/du (2n x controls(), u held over the step). False where
  // the step's solution does not give a derivative (g_zeta singular, a map undefined
  // there, a non-finite value). Defined in solvers/manifold_step_derivative.h, which a
  // file that calls it includes or that instantiates it for the step types others call
  // it on (runtime/kernels_manifold_derivatives.cc), so that a file compiling the step
  // alone does not compile it.
  bool derivatives(double t, const Point& q0, const Covector& p0, const Point& q1, Eigen::MatrixXd& A,
                   Eigen::MatrixXd* B = nullptr) const;

 private:
  DL dl_;
  StepOptions options_;
  std::shared_ptr<const Force> force_;
};

}  // namespace dvm
