// Hamiltonians H : T*Q -> R on Q = R^n, and the Legendre transform that links them
// to Lagrangians (paper Sec. 5.1; Abraham-Marsden, Foundations of Mechanics, Sec. 3.6).
//
//   Hamiltonian vector field   X_H(q, p) = (dH/dp, -dH/dq)        (i_{X_H} w_Q = dH)
//   Legendre map               FL(q, v) = (q, dL/dv(q, v))
//   Hamiltonian of L           H(q, p) = <p, v> - L(q, v),   v = FL^{-1}(q, p)
//   regularity                 FL is a local diffeomorphism at (q, v) exactly when
//                              the velocity Hessian d2L/dv2(q, v) is invertible; a
//                              Lagrangian that is singular where it is used has no
//                              Hamiltonian there and is rejected, never integrated.
//
// A Hamiltonian type H provides
//   static constexpr int dim;   std::string name() const;
//   template <class T> T operator()(const Vec<T, dim>& q, const Vec<T, dim>& p) const;
// for any scalar T (double and nested ceres::Jet), exactly like a Lagrangian.
//
// LegendreHamiltonian<S> is the Hamiltonian of a regular Lagrangian S, scalar-generic:
// v is found in doubles (closed form or Newton), then, for Jet scalars, refined by
// fixed-point sweeps v <- v - (d2L/dv2)^{-1} (dL/dv(q, v) - p) with the double Hessian;
// as for the generic inverse of a map (core/map_operations.h), derivative parts of
// order k are exact after k + 1 sweeps (implicit function theorem).
#pragma once

#include <Eigen/LU>
#include <cmath>
#include <stdexcept>
#include <sstream>
#include <string>

#include "core/dense_solve.h"
#include "core/map_operations.h"
#include "mechanics/lagrangian.h"

namespace dvm {

// dH/dq and dH/dp at (q, p) by automatic differentiation, for any scalar T.
template <class H, class T>
void hamiltonian_gradient(const H& ham, const Vec<T, H::dim>& q, const Vec<T, H::dim>& p, Vec<T, H::dim>& dHdq,
                          Vec<T, H::dim>& dHdp) {
  constexpr int N = H::dim;
  using D = ceres::Jet<T, 2 * N>;
  Vec<D, N> qd, pd;
  for (int i = 0; i < N; ++i) {
    qd[i] = seed<T, 2 * N>(q[i], i);
    pd[i] = seed<T, 2 * N>(p[i], N + i);
  }
  const D e = ham(qd, pd);
  dHdq = e.v.template head<N>();
  dHdp = e.v.template tail<N>();
}

// The Hamiltonian vector field X_H(q, p) = (dH/dp, -dH/dq), as (qdot, pdot).
template <class H, class T>
void hamiltonian_vector_field(const H& ham, const Vec<T, H::dim>& q, const Vec<T, H::dim>& p,
                              Vec<T, H::dim>& qdot, Vec<T, H::dim>& pdot) {
  Vec<T, H::dim> dq, dp;
  hamiltonian_gradient(ham, q, p, dq, dp);
  qdot = dp;
  pdot = -dq;
}

// Reciprocal condition number (in the max norm) of the velocity Hessian at (q, v):
// 0 for a singular Hessian, 1 for a multiple of the identity.
// Winv is W^{-1} as computed by the caller (an exactly singular W gives an infinite
// or NaN inverse, hence 0).
template <int N>
double velocity_hessian_rcond(const Mat<double, N, N>& W, const Mat<double, N, N>& Winv) {
  const double norm = W.cwiseAbs().rowwise().sum().maxCoeff();
  if (!(norm > 0.0) || !std::isfinite(norm)) return 0.0;
  const double rc = 1.0 / (norm * Winv.cwiseAbs().rowwise().sum().maxCoeff());
  return std::isfinite(rc) ? rc : 0.0;
}
template <int N>
double velocity_hessian_rcond(const Mat<double, N, N>& W) {
  return velocity_hessian_rcond<N>(W, Mat<double, N, N>(W.partialPivLu().inverse()));
}
template <class S>
double velocity_hessian_rcond(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v) {
  return velocity_hessian_rcond<S::dim>(velocity_hessian(L, q, v));
}

// The scale of d2L/dv2 at (q, v): {|W|, 1/|W^{-1}|} in the max norm (W = d2L/dv2).
// They bound the largest and the smallest singular value within a factor sqrt(dim), and
// are |W| twice in one dimension; the second is 0 where W is singular.
template <class Derived>
Vec<double, 2> matrix_hessian_scale(const Eigen::MatrixBase<Derived>& W) {
  if (!W.allFinite()) return Vec<double, 2>(NAN, NAN);
  const Eigen::MatrixXd Wd = W;
  const double inv = Eigen::MatrixXd(Wd.partialPivLu().inverse()).cwiseAbs().rowwise().sum().maxCoeff();
  return Vec<double, 2>(Wd.cwiseAbs().rowwise().sum().maxCoeff(), std::isfinite(inv) ? 1.0 / inv : 0.0);
}
template <class S>
Vec<double, 2> velocity_hessian_scale(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v) {
  return matrix_hessian_scale(velocity_hessian(L, q, v));
}

// Throws DegenerateLagrangianError, naming the point, when d2L/dv2 is singular (to
// working precision, reciprocal condition below `rcond_floor`) at (q, v).
// W is d2L/dv2 at (q, v), when the caller has it already.
template <class S>
void require_regular(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v,
                     const Mat<double, S::dim, S::dim>& W, const Mat<double, S::dim, S::dim>& Winv,
                     double rcond_floor = 1e-12) {
  const double rc = velocity_hessian_rcond<S::dim>(W, Winv);
  if (!(rc > rcond_floor)) {
    std::ostringstream msg;
    msg << L.name() << " is not regular at q = [" << q.transpose() << "], v = [" << v.transpose()
        << "]: the velocity Hessian d2L/dv2 is singular (reciprocal condition " << rc
        << "), so the Legendre map cannot be inverted and there is no Hamiltonian there";
    throw DegenerateLagrangianError(msg.str());
  }
}
template <class S>
void require_regular(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v,
                     double rcond_floor = 1e-12) {
  const Mat<double, S::dim, S::dim> W = velocity_hessian(L, q, v);
  require_regular(L, q, v, W, Mat<double, S::dim, S::dim>(W.partialPivLu().inverse()), rcond_floor);
}

// What the Legendre transform looks like at (q, p), for the message of a step that
// did not converge: the scale of d2L/dv2 (velocity_hessian_scale) at v = FL^{-1}(q, p),
// set against its value at a reference state (the run's initial one). A step near a
// point where FL degenerates fails to converge (its Newton matrix contains d2L/dv2),
// and the smallest scale having collapsed relative to the start says so.
inline std::string legendre_scale_diagnosis(const Vec<double, 2>& scale, const Vec<double, 2>& scale_ref) {
  if (!scale.allFinite()) return "at the last completed state the velocity Hessian d2L/dv2 is not finite";
  std::ostringstream msg;
  msg.precision(3);
  msg << "at the last completed state the velocity Hessian W = d2L/dv2 has |W| = " << scale[0]
      << " and 1/|W^-1| = " << scale[1] << " (" << scale_ref[0] << " and " << scale_ref[1]
      << " at the initial state)";
  if (!(scale[1] > 1e-2 * scale_ref[1]))  // collapsed by two orders of magnitude
    msg << ": the Legendre transform is close to degenerate there, so the step equation is nearly singular";
  return msg.str();
}

template <class S>
std::string legendre_diagnosis(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& p,
                               const Vec<double, S::dim>& guess, const Vec<double, 2>& scale_ref) {
  Vec<double, S::dim> v;
  try {
    v = legendre_inverse(L, q, p, guess);
  } catch (const std::domain_error& e) {
    return std::string("at the last completed state the Legendre transform cannot be inverted: ") + e.what();
  }
  return legendre_scale_diagnosis(velocity_hessian_scale(L, q, v), scale_ref);
}


// The Legendre map FL(q, v) = (q, p) with the regularity check.
template <class S>
Vec<double, S::dim> legendre_checked(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v) {
  require_regular(L, q, v);
  return legendre(L, q, v);
}

// Its inverse v = FL^{-1}(q, p), with the regularity check at the solution.
template <class S>
Vec<double, S::dim> legendre_inverse_checked(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& p,
                                             const Vec<double, S::dim>& guess = Vec<double, S::dim>::Zero()) {
  // Newton needs an invertible Hessian from the start; check there first, so that a
  // degenerate Lagrangian is named as such rather than as a non-converging solve.
  require_regular(L, q, guess);
  const Vec<double, S::dim> v = legendre_inverse(L, q, p, guess);
  require_regular(L, q, v);
  return v;
}

// v = FL^{-1}(q, p) for any scalar, from its value v0 in doubles and the inverse Winv of
// d2L/dv2 at (values(q), v0): for Jet scalars, the fixed-point sweeps
// v <- v - Winv (dL/dv(q, v) - p) described at the top of this file.
template <class S, class T>
Vec<T, S::dim> legendre_inverse_sweeps(const S& L, const Vec<T, S::dim>& q, const Vec<T, S::dim>& p,
                                       const Vec<double, S::dim>& v0, const Mat<double, S::dim, S::dim>& Winv) {
  constexpr int N = S::dim;
  Vec<T, N> v = constants<T>(v0);
  if constexpr (is_jet_v<T>) {
    for (int sweep = 0; sweep <= jet_depth<T>::value; ++sweep) {
      Vec<T, N> a, b;
      lagrangian_gradient(L, q, v, a, b);
      const Vec<T, N> r = b - p;
      for (int i = 0; i < N; ++i) {
        T c = constant<T>(0.0);
        for (int j = 0; j < N; ++j) c = c + Winv(i, j) * r[j];
        v[i] = v[i] - c;
      }
    }
  } else {
    (void)L, (void)q, (void)p, (void)Winv;
  }
  return v;
}

// v = FL^{-1}(q, p) for any scalar, with the regularity check at (values(q), v): v in
// doubles (closed form or Newton), then the sweeps above.
template <class S, class T>
Vec<T, S::dim> legendre_inverse_regular(const S& L, const Vec<T, S::dim>& q, const Vec<T, S::dim>& p) {
  constexpr int N = S::dim;
  const Vec<double, N> q0 = values(q), p0 = values(p);
  // v0 = FL^{-1}(q0, p0), and the regularity check at (q0, v0) on the Hessian and
  // inverse the Jet sweeps use anyway: one Hessian and one inverse per evaluation
  // (legendre_inverse_checked forms three Hessians and two LU inverses). A Newton
  // inverse that fails on a singular Hessian is reported as legendre_inverse_checked
  // reports it, naming the point where it started.
  Vec<double, N> v0;
  try {
    v0 = legendre_inverse(L, q0, p0);
  } catch (const DegenerateLagrangianError&) {
    require_regular(L, q0, Vec<double, N>(Vec<double, N>::Zero()));
    throw;
  }
  const Mat<double, N, N> W = velocity_hessian(L, q0, v0);
  const Mat<double, N, N> Winv = W.inverse();
  require_regular(L, q0, v0, W, Winv);
  return legendre_inverse_sweeps(L, q, p, v0, Winv);
}

// The Hamiltonian H(q, p) = <p, v> - L(q, v), v = FL^{-1}(q, p), of a regular Lagrangian.
template <class S>
struct LegendreHamiltonian {
  static constexpr int dim = S::dim;
  S lagrangian;

  explicit LegendreHamiltonian(S L) : lagrangian(std::move(L)) {}
  std::string name() const { return lagrangian.name(); }

  template <class T>
  T operator()(const Vec<T, dim>& q, const Vec<T, dim>& p) const {
    const Vec<T, dim> v = legendre_inverse_regular(lagrangian, q, p);
    T pv = constant<T>(0.0);
    for (int i = 0; i < dim; ++i) pv = pv + p[i] * v[i];
    return pv - lagrangian(q, v);
  }
};

}  // namespace dvm
