// Discretization maps on R^n (Barbero-Linan, Martin de Diego, "Retraction maps: a
// seed of geometric integrators", Sec. 2).
//
// A discretization map is a map R_d : TQ -> Q x Q, R_d(x, v) = (R^1_x(v), R^2_x(v)),
// defined near the zero section, such that (Def. 2.2)
//   (i)  R_d(x, 0) = (x, x) for every x;
//   (ii) T_{0_x} R^2_x - T_{0_x} R^1_x = Id on T_x Q.
// By (ii) R_d is a local diffeomorphism near the zero section, so it has a local
// inverse R_d^{-1} : Q x Q -> TQ. An integrator reads (q_k, q_{k+1}) as the image of
// a point x and the velocity h * xdot through R_d.
//
// Built-in maps on R^n:
//   explicit Euler   R_d(x, v) = (x, x + v)                 theta = 0
//   adjoint Euler    R_d(x, v) = (x - v, x)                 theta = 1
//   midpoint         R_d(x, v) = (x - v/2, x + v/2)         theta = 1/2
//   theta method     R_d(x, v) = (x - theta v, x + (1 - theta) v)
//   from a retraction R and theta (Prop. 2.3):
//                    R_d(x, v) = (R_x(-theta v), R_x((1 - theta) v))
// The adjoint of a map (Prop. 2.4) is R_d^*(x, v) = (R^2_x(-v), R^1_x(-v)); it is a
// discretization map again, (R_d^*)^* = R_d, and the theta map's adjoint is the
// (1 - theta) map. A map is symmetric when R_d^* = R_d; the integrator of a
// symmetric map is of order 2, that of any other map of order 1.
//
// The interface a map type M provides (every built-in does, a user's map must):
//   template <class T, int N>
//   PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const;
//   std::string name() const;   bool symmetric() const;   int order() const;
//   static constexpr bool provides_inverse;    // true if M has a member
//   template <class T, int N>
//   TangentPoint<T, N> inverse(const Vec<T, N>& q0, const Vec<T, N>& q1) const;
// and optionally, to avoid the cancellation in forming q1 - q0 when q1 = q0 + dq
// with dq much smaller than q0 (the step equations are solved for dq),
//   template <class T, int N>
//   TangentPoint<T, N> inverse_increment(const Vec<T, N>& q0, const Vec<T, N>& dq) const;
//   returning R_d^{-1}(q0, q0 + dq), and, for the same reason in equations that compare
//   points of two maps (the first SODE form, solvers/sode_step.h),
//   template <class T, int N>
//   PointPair<T, N> displacement(const Vec<T, N>& x, const Vec<T, N>& v) const;
//   returning R_d(x, v) - (x, x) without forming R_d(x, v).
// operator() must be written for any scalar T (double and nested ceres::Jet). A map
// that provides no inverse is inverted by Newton's method (see map_operations.h).
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

#include "core/scalar.h"

namespace dvm {

// A pair of points (q0, q1) in Q x Q.
template <class T, int N>
struct PointPair {
  Vec<T, N> q0, q1;
};

// A tangent vector v at the point x: an element (x, v) of TQ.
template <class T, int N>
struct TangentPoint {
  Vec<T, N> x, v;
};

// The theta map R_d(x, v) = (x - theta v, x + (1 - theta) v); explicit Euler,
// adjoint Euler and midpoint are its values 0, 1 and 1/2. Closed-form inverse:
//   v = q1 - q0,   x = (1 - theta) q0 + theta q1.
class ThetaMap {
 public:
  static constexpr bool provides_inverse = true;

  explicit ThetaMap(double theta, std::string name = "theta") : theta_(theta), name_(std::move(name)) {
    if (!(theta >= 0.0 && theta <= 1.0)) {
      std::ostringstream msg;
      msg << "theta must lie in [0, 1], got " << theta;
      throw std::invalid_argument(msg.str());
    }
  }
  static ThetaMap explicit_euler() { return ThetaMap(0.0, "explicit-euler"); }
  static ThetaMap adjoint_euler() { return ThetaMap(1.0, "adjoint-euler"); }
  static ThetaMap midpoint() { return ThetaMap(0.5, "midpoint"); }

  double theta() const { return theta_; }
  std::string name() const { return name_; }
  bool symmetric() const { return theta_ == 0.5; }
  int order() const { return symmetric() ? 2 : 1; }

  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    return {x - theta_ * v, x + (1.0 - theta_) * v};
  }

  template <class T, int N>
  TangentPoint<T, N> inverse(const Vec<T, N>& q0, const Vec<T, N>& q1) const {
    return {(1.0 - theta_) * q0 + theta_ * q1, q1 - q0};
  }
  template <class T, int N>
  TangentPoint<T, N> inverse_increment(const Vec<T, N>& q0, const Vec<T, N>& dq) const {
    return {q0 + theta_ * dq, dq};
  }
  template <class T, int N>
  PointPair<T, N> displacement(const Vec<T, N>&, const Vec<T, N>& v) const {
    return {-theta_ * v, (1.0 - theta_) * v};
  }

  // The adjoint of the theta map is the (1 - theta) map (Prop. 2.4).
  ThetaMap adjoint() const {
    if (name_ == "explicit-euler") return adjoint_euler();
    if (name_ == "adjoint-euler") return explicit_euler();
    if (name_ == "midpoint") return midpoint();
    return ThetaMap(1.0 - theta_, name_);
  }

 private:
  double theta_;
  std::string name_;
};

// The retraction R_x(v) = x + v of R^n (the exponential of the flat metric).
struct EuclideanRetraction {
  std::string name() const { return "euclidean"; }
  template <class T, int N>
  Vec<T, N> retract(const Vec<T, N>& x, const Vec<T, N>& v) const {
    return x + v;
  }
};

// The map built from a retraction R and theta in [0, 1] (Prop. 2.3):
//   R_d(x, v) = (R_x(-theta v), R_x((1 - theta) v)).
// It provides no inverse: the generic Newton inverse is used, so this map also
// exercises the generic path for any map a user writes.
template <class Retraction>
class RetractionMap {
 public:
  static constexpr bool provides_inverse = false;

  RetractionMap(Retraction retraction, double theta) : retraction_(std::move(retraction)), theta_(theta) {
    if (!(theta >= 0.0 && theta <= 1.0)) {
      std::ostringstream msg;
      msg << "theta must lie in [0, 1], got " << theta;
      throw std::invalid_argument(msg.str());
    }
  }

  double theta() const { return theta_; }
  std::string name() const { return "retraction-theta(" + retraction_.name() + ")"; }
  // (R_d)^* is the map of the same retraction with theta replaced by 1 - theta.
  bool symmetric() const { return theta_ == 0.5; }
  int order() const { return symmetric() ? 2 : 1; }
  const Retraction& retraction() const { return retraction_; }

  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    return {retraction_.retract(x, Vec<T, N>(-theta_ * v)),
            retraction_.retract(x, Vec<T, N>((1.0 - theta_) * v))};
  }

 private:
  Retraction retraction_;
  double theta_;
};

}  // namespace dvm
