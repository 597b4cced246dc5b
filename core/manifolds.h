// Curved configuration spaces: the sphere S^2 and the rotation group SO(3).
//
// Each manifold type M describes how its points and tangent vectors are stored and
// gives local coordinates around any point, for any scalar T:
//   static constexpr int dim;                 intrinsic dimension
//   Point<T>, Tangent<T>                      storage of points and tangent vectors
//   chart(c, eta)                             the point with coordinates eta (R^dim)
//                                             in the chart centred at c; chart(c, 0) = c
//   chart_inverse(c, y)                       the coordinates of y in that chart
//   tangent(x, nu)                            the tangent vector at x with coordinates nu
//                                             (the differential of chart(x, .) at 0)
//   tangent_coordinates(x, v)                 its inverse
//   covector_to_local / covector_from_local   momenta: stored form <-> chart coordinates
//   point_defect(x), tangent_defect(x, v)     distance from the manifold / tangent space
//   distance(x, y)                            an ambient distance, for checks
//   clean(x)                                  removes round-off (renormalise); a point
//                                             off the manifold by more than round-off is
//                                             an error of the caller, not cleaned
//
//   chart_and_tangent(c, eta, nu)             chart(c, eta) and the tangent vector
//                                             D chart(c, eta) nu there, in closed form
//                                             (so no extra Jet level is needed: Ceres'
//                                             functions stop at two nested levels)
//
// S^2 = { x in R^3 : |x| = 1 }; T_x S^2 = { v : x.v = 0 }, stored as 3-vectors, as in
// the paper. Chart: the central projection chart(c, eta) = (c + B eta)/|c + B eta|
// with B = B(c) an orthonormal basis of T_c S^2 (it covers the open hemisphere
// around c; its inverse is B^T (y/(c.y) - c)). Momenta are stored as tangent
// 3-vectors (the covector p acts by v -> p.v).
//
// SO(3) = { R : R^T R = I, det R = 1 }, stored as 3x3 matrices. Tangent vectors at R
// are left-trivialised: R hat(w) with w in R^3 (the body angular velocity); momenta
// likewise (body angular momentum). Chart: c exp(hat(eta)), whose differential in
// body form is the right Jacobian
//   J_r(eta) = I - (1 - cos t)/t^2 hat(eta) + (t - sin t)/t^3 hat(eta)^2,  t = |eta|.
//
// Small-angle branches are Taylor series in the squared angle, never constants, so
// that derivatives (Jets) survive at zero: a constant branch would give a zero
// derivative where the function has none.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/map_operations.h"
#include "core/scalar.h"

namespace dvm {

namespace detail {

// sin(t)/t and (1 - cos t)/t^2 and cos t as functions of t^2 (smooth at 0).
template <class T>
T sinc_sq(const T& t2) {
  using std::sin;
  using std::sqrt;
  if (value(t2) < 1e-4) return 1.0 - t2 / 6.0 + t2 * t2 / 120.0 - t2 * t2 * t2 / 5040.0;
  const T t = sqrt(t2);
  return sin(t) / t;
}
template <class T>
T cos_sq(const T& t2) {
  using std::cos;
  using std::sqrt;
  if (value(t2) < 1e-4) return 1.0 - t2 / 2.0 + t2 * t2 / 24.0 - t2 * t2 * t2 / 720.0;
  return cos(sqrt(t2));
}
template <class T>
T versine_sq(const T& t2) {  // (1 - cos t)/t^2
  using std::cos;
  using std::sqrt;
  if (value(t2) < 1e-4) return 0.5 - t2 / 24.0 + t2 * t2 / 720.0 - t2 * t2 * t2 / 40320.0;
  return (1.0 - cos(sqrt(t2))) / t2;
}
// phi / sin(phi) where sin(phi) = s (s^2 given) and cos(phi) = c: smooth at s = 0
// when c > 0; at s = 0 with c < 0 (phi = pi) the value is undefined (throws).
template <class T>
T angle_over_sin(const T& s2, const T& c) {
  using std::atan2;
  using std::sqrt;
  if (value(s2) < 1e-8 && value(c) > 0.0) {
    // asin(s)/s = 1 + s^2/6 + 3 s^4/40 + 5 s^6/112
    return 1.0 + s2 / 6.0 + 3.0 * s2 * s2 / 40.0 + 5.0 * s2 * s2 * s2 / 112.0;
  }
  if (value(s2) < 1e-24) throw MapDomainError("angle of pi: the logarithm is not defined there");
  const T s = sqrt(s2);
  return atan2(s, c) / s;
}

template <class T, int N>
T dot(const Vec<T, N>& a, const Vec<T, N>& b) {
  T s = a[0] * b[0];
  for (int i = 1; i < N; ++i) s = s + a[i] * b[i];
  return s;
}

}  // namespace detail

struct Sphere {
  static constexpr int dim = 2;
  static constexpr const char* name = "S^2";
  template <class T>
  using Point = Vec<T, 3>;
  template <class T>
  using Tangent = Vec<T, 3>;

  // A right-handed orthonormal basis (e1, e2) of T_x S^2 that depends smoothly on x
  // away from one direction (built from the coordinate axis least aligned with x).
  static Mat<double, 3, 2> basis(const Vec<double, 3>& x) {
    int k = 0;
    for (int i = 1; i < 3; ++i)
      if (std::fabs(x[i]) < std::fabs(x[k])) k = i;
    Vec<double, 3> a = Vec<double, 3>::Zero();
    a[k] = 1.0;
    Vec<double, 3> e1 = a - x.dot(a) * x;
    e1.normalize();
    Mat<double, 3, 2> B;
    B.col(0) = e1;
    B.col(1) = x.cross(e1);
    return B;
  }

  template <class T>
  static Vec<T, 3> exp(const Vec<T, 3>& x, const Vec<T, 3>& v) {
    const T t2 = detail::dot(v, v);
    const T c = detail::cos_sq(t2), s = detail::sinc_sq(t2);
    return Vec<T, 3>(c * x[0] + s * v[0], c * x[1] + s * v[1], c * x[2] + s * v[2]);
  }
  // log_x(y): the tangent vector v at x with exp_x(v) = y (|v| < pi).
  template <class T>
  static Vec<T, 3> log(const Vec<T, 3>& x, const Vec<T, 3>& y) {
    const T c = detail::dot(x, y);
    const Vec<T, 3> w(y[0] - c * x[0], y[1] - c * x[1], y[2] - c * x[2]);
    const T k = detail::angle_over_sin(detail::dot(w, w), c);
    return Vec<T, 3>(k * w[0], k * w[1], k * w[2]);
  }
  // The projection retraction (x + v)/|x + v|.
  template <class T>
  static Vec<T, 3> projection(const Vec<T, 3>& x, const Vec<T, 3>& v) {
    using std::sqrt;
    const Vec<T, 3> y(x[0] + v[0], x[1] + v[1], x[2] + v[2]);
    const T n = sqrt(detail::dot(y, y));
    return Vec<T, 3>(y[0] / n, y[1] / n, y[2] / n);
  }

  template <class T, class U>
  static Vec<T, 3> tangent(const Vec<U, 3>& x, const Vec<T, 2>& nu) {
    const Mat<double, 3, 2> B = basis(values(x));
    Vec<T, 3> v;
    for (int i = 0; i < 3; ++i) v[i] = B(i, 0) * nu[0] + B(i, 1) * nu[1];
    return v;
  }
  template <class T>
  static Vec<T, 2> tangent_coordinates(const Vec<double, 3>& x, const Vec<T, 3>& v) {
    const Mat<double, 3, 2> B = basis(x);
    Vec<T, 2> nu;
    for (int j = 0; j < 2; ++j) nu[j] = B(0, j) * v[0] + B(1, j) * v[1] + B(2, j) * v[2];
    return nu;
  }
  template <class T>
  static Vec<T, 3> chart(const Vec<double, 3>& c, const Vec<T, 2>& eta) {
    return projection(constants<T>(c), tangent(c, eta));
  }
  template <class T>
  static Vec<T, 2> chart_inverse(const Vec<double, 3>& c, const Vec<T, 3>& y) {
    const T d = c[0] * y[0] + c[1] * y[1] + c[2] * y[2];
    if (!(value(d) > 1e-12)) throw MapDomainError("S^2 chart: the point is not in the hemisphere of the chart");
    return tangent_coordinates(c, Vec<T, 3>(y[0] / d - c[0], y[1] / d - c[1], y[2] / d - c[2]));
  }
  template <class T>
  static std::pair<Vec<T, 3>, Vec<T, 3>> chart_and_tangent(const Vec<double, 3>& c, const Vec<T, 2>& eta,
                                                           const Vec<T, 2>& nu) {
    using std::sqrt;
    const Vec<T, 3> u = tangent(c, eta), w = tangent(c, nu);
    const Vec<T, 3> y(c[0] + u[0], c[1] + u[1], c[2] + u[2]);
    const T n2 = detail::dot(y, y);
    const T n = sqrt(n2);
    const T k = detail::dot(y, w) / (n2 * n);
    Vec<T, 3> x, v;
    for (int i = 0; i < 3; ++i) {
      x[i] = y[i] / n;
      v[i] = w[i] / n - k * y[i];
    }
    return {x, v};
  }
  static Vec<double, 2> covector_to_local(const Vec<double, 3>& x, const Vec<double, 3>& p) {
    return tangent_coordinates(x, p);
  }
  static Vec<double, 3> covector_from_local(const Vec<double, 3>& x, const Vec<double, 2>& p) {
    return tangent(x, p);
  }
  static double point_defect(const Vec<double, 3>& x) { return std::fabs(x.norm() - 1.0); }
  static double tangent_defect(const Vec<double, 3>& x, const Vec<double, 3>& v) { return std::fabs(x.dot(v)); }
  static double distance(const Vec<double, 3>& x, const Vec<double, 3>& y) { return (x - y).cwiseAbs().maxCoeff(); }
  // The chart already returns a normalised vector; renormalising once more would move
  // the point after its step was solved and break the exact momentum balance (it
  // showed as a drift of the vertical angular momentum), so nothing is done.
  static Vec<double, 3> clean(const Vec<double, 3>& x) { return x; }
  // A generic point, for checks.
  static Vec<double, 3> sample_point() { return Vec<double, 3>(0.48, -0.6, 0.64); }

  // The relative position of q1 with respect to q0 that the maps' inverses take: the
  // difference d = q1 - q0. `relative` forms it from stored points (absolute error
  // eps, i.e. relative error eps/|d| ~ eps/h); `relative_chart` forms it for
  // q1 = chart(q0, xi) from xi, without cancellation:
  //   d = (u - q0 (n - 1))/n,  u = B xi,  n = |q0 + u|,  n - 1 = |u|^2/(1 + n).
  template <class T, class U>
  static Vec<T, 3> relative(const Vec<U, 3>& q0, const Vec<T, 3>& q1) {
    return Vec<T, 3>(q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2]);
  }
  template <class T>
  static Vec<T, 3> relative_chart(const Vec<double, 3>& q0, const Vec<T, 2>& xi) {
    using std::sqrt;
    const Vec<T, 3> u = tangent(q0, xi);
    const T u2 = detail::dot(u, u);
    const T n = sqrt(1.0 + u2);
    const T nm1 = u2 / (1.0 + n);
    return Vec<T, 3>((u[0] - q0[0] * nm1) / n, (u[1] - q0[1] * nm1) / n, (u[2] - q0[2] * nm1) / n);
  }
  // Chart coordinates at q of a second-order guess for the next point: the
  // reflection 2 q - q_prev, renormalised.
  static Vec<double, 2> next_guess(const Vec<double, 3>& q_prev, const Vec<double, 3>& q) {
    return chart_inverse(q, Vec<double, 3>((2.0 * q - q_prev).normalized()));
  }
};

struct SO3 {
  static constexpr int dim = 3;
  static constexpr const char* name = "SO(3)";
  template <class T>
  using Point = Mat<T, 3, 3>;
  template <class T>
  using Tangent = Vec<T, 3>;

  template <class T>
  static Mat<T, 3, 3> hat(const Vec<T, 3>& w) {
    Mat<T, 3, 3> W;
    const T z = constant<T>(0.0);
    W << z, -w[2], w[1], w[2], z, -w[0], -w[1], w[0], z;
    return W;
  }
  template <class T>
  static Vec<T, 3> vee(const Mat<T, 3, 3>& W) {
    return Vec<T, 3>(W(2, 1), W(0, 2), W(1, 0));
  }
  template <class T>
  static Mat<T, 3, 3> identity() {
    Mat<T, 3, 3> I;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) I(i, j) = constant<T>(i == j ? 1.0 : 0.0);
    return I;
  }
  template <class T>
  static Mat<T, 3, 3> mul(const Mat<T, 3, 3>& A, const Mat<T, 3, 3>& B) {
    Mat<T, 3, 3> C;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) C(i, j) = A(i, 0) * B(0, j) + A(i, 1) * B(1, j) + A(i, 2) * B(2, j);
    return C;
  }
  template <class T>
  static Mat<T, 3, 3> transpose_mul(const Mat<T, 3, 3>& A, const Mat<T, 3, 3>& B) {
    Mat<T, 3, 3> C;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) C(i, j) = A(0, i) * B(0, j) + A(1, i) * B(1, j) + A(2, i) * B(2, j);
    return C;
  }

  // Rodrigues: exp(hat(w)) = I + sinc W + versine W^2.
  template <class T>
  static Mat<T, 3, 3> exp(const Vec<T, 3>& w) {
    const T t2 = detail::dot(w, w);
    const T a = detail::sinc_sq(t2), b = detail::versine_sq(t2);
    const Mat<T, 3, 3> W = hat(w);
    const Mat<T, 3, 3> W2 = mul(W, W);
    Mat<T, 3, 3> R = identity<T>();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) R(i, j) = R(i, j) + a * W(i, j) + b * W2(i, j);
    return R;
  }
  // The principal logarithm (rotation angle < pi).
  template <class T>
  static Vec<T, 3> log(const Mat<T, 3, 3>& R) {
    const Vec<T, 3> a = 0.5 * Vec<T, 3>(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
    const T c = 0.5 * (R(0, 0) + R(1, 1) + R(2, 2) - 1.0);
    const T k = detail::angle_over_sin(detail::dot(a, a), c);
    return Vec<T, 3>(k * a[0], k * a[1], k * a[2]);
  }
  // Cayley map cay(w) = (I - W/2)^{-1} (I + W/2) = I + 4/(4 + |w|^2) (W + W^2/2):
  // the rotation about w by 2 atan(|w|/2).
  template <class T>
  static Mat<T, 3, 3> cay(const Vec<T, 3>& w) {
    const T f = 4.0 / (4.0 + detail::dot(w, w));
    const Mat<T, 3, 3> W = hat(w);
    const Mat<T, 3, 3> W2 = mul(W, W);
    Mat<T, 3, 3> R = identity<T>();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) R(i, j) = R(i, j) + f * (W(i, j) + 0.5 * W2(i, j));
    return R;
  }
  // cay^{-1}(R) = 2 vee(R - R^T)/(1 + tr R); defined for rotation angles below pi.
  template <class T>
  static Vec<T, 3> cay_inverse(const Mat<T, 3, 3>& R) {
    const T d = 1.0 + R(0, 0) + R(1, 1) + R(2, 2);
    if (!(value(d) > 1e-10)) throw MapDomainError("Cayley inverse: rotation by pi is outside the Cayley map's domain");
    const T k = 2.0 / d;
    return Vec<T, 3>(k * (R(2, 1) - R(1, 2)), k * (R(0, 2) - R(2, 0)), k * (R(1, 0) - R(0, 1)));
  }

  template <class T, class U>
  static Vec<T, 3> tangent(const Mat<U, 3, 3>&, const Vec<T, 3>& nu) {
    return nu;
  }
  template <class T>
  static Vec<T, 3> tangent_coordinates(const Mat<double, 3, 3>&, const Vec<T, 3>& v) {
    return v;
  }
  template <class T>
  static Mat<T, 3, 3> chart(const Mat<double, 3, 3>& c, const Vec<T, 3>& eta) {
    return mul(constants3<T>(c), exp(eta));
  }
  // d/ds exp(eta + s nu) = exp(eta) hat(J_r(eta) nu).
  template <class T>
  static Vec<T, 3> right_jacobian_times(const Vec<T, 3>& eta, const Vec<T, 3>& nu) {
    const T t2 = detail::dot(eta, eta);
    const T a = detail::versine_sq(t2);
    T b;  // (t - sin t)/t^3
    if (value(t2) < 1e-4) {
      b = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0 - t2 * t2 * t2 / 362880.0;
    } else {
      using std::sin;
      using std::sqrt;
      const T t = sqrt(t2);
      b = (t - sin(t)) / (t2 * t);
    }
    const Vec<T, 3> e1 = eta.cross(nu);
    const Vec<T, 3> e2 = eta.cross(e1);
    return Vec<T, 3>(nu[0] - a * e1[0] + b * e2[0], nu[1] - a * e1[1] + b * e2[1], nu[2] - a * e1[2] + b * e2[2]);
  }
  template <class T>
  static std::pair<Mat<T, 3, 3>, Vec<T, 3>> chart_and_tangent(const Mat<double, 3, 3>& c, const Vec<T, 3>& eta,
                                                              const Vec<T, 3>& nu) {
    return {chart(c, eta), right_jacobian_times(eta, nu)};
  }
  template <class T>
  static Vec<T, 3> chart_inverse(const Mat<double, 3, 3>& c, const Mat<T, 3, 3>& y) {
    return log(transpose_mul(constants3<T>(c), y));
  }
  static Vec<double, 3> covector_to_local(const Mat<double, 3, 3>&, const Vec<double, 3>& p) { return p; }
  static Vec<double, 3> covector_from_local(const Mat<double, 3, 3>&, const Vec<double, 3>& p) { return p; }
  static double point_defect(const Mat<double, 3, 3>& R) {
    return std::fmax((R.transpose() * R - Mat<double, 3, 3>::Identity()).cwiseAbs().maxCoeff(),
                     std::fabs(R.determinant() - 1.0));
  }
  static double tangent_defect(const Mat<double, 3, 3>&, const Vec<double, 3>&) { return 0.0; }
  static double distance(const Mat<double, 3, 3>& A, const Mat<double, 3, 3>& B) {
    return (A - B).cwiseAbs().maxCoeff();
  }
  // One Newton-Schulz step R (3I - R^T R)/2: removes round-off drift from R^T R = I.
  static Mat<double, 3, 3> clean(const Mat<double, 3, 3>& R) {
    return 0.5 * R * (3.0 * Mat<double, 3, 3>::Identity() - R.transpose() * R);
  }
  static Mat<double, 3, 3> sample_point() { return exp(Vec<double, 3>(0.3, -0.7, 1.1)); }

  // The relative rotation W = q0^T q1 that the maps' inverses take: from stored
  // rotations (`relative`, absolute error eps in entries of size |w| ~ h), or for
  // q1 = q0 exp(xi) exactly as exp(xi) (`relative_chart`).
  template <class T, class U>
  static Mat<T, 3, 3> relative(const Mat<U, 3, 3>& q0, const Mat<T, 3, 3>& q1) {
    if constexpr (std::is_same_v<T, U>) {
      return transpose_mul(q0, q1);
    } else {
      Mat<T, 3, 3> a;
      for (int i = 0; i < 9; ++i) a(i) = T(q0(i));
      return transpose_mul(a, q1);
    }
  }
  template <class T>
  static Mat<T, 3, 3> relative_chart(const Mat<double, 3, 3>&, const Vec<T, 3>& xi) {
    return exp(xi);
  }
  // The last body increment log(q_prev^T q), a second-order guess for the next one.
  static Vec<double, 3> next_guess(const Mat<double, 3, 3>& q_prev, const Mat<double, 3, 3>& q) {
    return log(Mat<double, 3, 3>(q_prev.transpose() * q));
  }

  template <class T>
  static Mat<T, 3, 3> constants3(const Mat<double, 3, 3>& c) {
    Mat<T, 3, 3> out;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) out(i, j) = constant<T>(c(i, j));
    return out;
  }

  // Rotation matrix of a unit quaternion (w, x, y, z) and back (w >= 0).
  static Mat<double, 3, 3> from_quaternion(const Vec<double, 4>& q) {
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    Mat<double, 3, 3> R;
    R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y), 2 * (x * y + w * z),
        1 - 2 * (x * x + z * z), 2 * (y * z - w * x), 2 * (x * z - w * y), 2 * (y * z + w * x),
        1 - 2 * (x * x + y * y);
    return R;
  }
  static Vec<double, 4> to_quaternion(const Mat<double, 3, 3>& R) {
    Eigen::Quaterniond q(R);
    Vec<double, 4> out(q.w(), q.x(), q.y(), q.z());
    if (out[0] < 0) out = -out;
    return out;
  }
};

}  // namespace dvm

namespace dvm {

// The product (S^2)^K: K unit vectors stacked in one 3K-vector (a chain of K
// spherical pendulums). Everything acts block by block with the S^2 operations.
template <int K>
struct SpherePower {
  static_assert(K >= 1, "(S^2)^K needs K >= 1");
  static constexpr int dim = 2 * K;
  static constexpr const char* name = "(S^2)^n";
  template <class T>
  using Point = Vec<T, 3 * K>;
  template <class T>
  using Tangent = Vec<T, 3 * K>;

  template <class T>
  static Vec<T, 3> block(const Vec<T, 3 * K>& x, int i) {
    return Vec<T, 3>(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
  }
  template <class T>
  static Vec<T, 2> block2(const Vec<T, 2 * K>& x, int i) {
    return Vec<T, 2>(x[2 * i], x[2 * i + 1]);
  }
  template <class T, int N>
  static void put(Vec<T, N>& x, int i, const Vec<T, N / K>& b) {
    for (int j = 0; j < N / K; ++j) x[(N / K) * i + j] = b[j];
  }

  template <class T, class U>
  static Vec<T, 3 * K> tangent(const Vec<U, 3 * K>& x, const Vec<T, 2 * K>& nu) {
    Vec<T, 3 * K> v;
    for (int i = 0; i < K; ++i) put<T, 3 * K>(v, i, Sphere::tangent(block(x, i), block2(nu, i)));
    return v;
  }
  template <class T>
  static Vec<T, 2 * K> tangent_coordinates(const Vec<double, 3 * K>& x, const Vec<T, 3 * K>& v) {
    Vec<T, 2 * K> nu;
    for (int i = 0; i < K; ++i) put<T, 2 * K>(nu, i, Sphere::tangent_coordinates(block(x, i), block(v, i)));
    return nu;
  }
  template <class T>
  static Vec<T, 3 * K> chart(const Vec<double, 3 * K>& c, const Vec<T, 2 * K>& eta) {
    Vec<T, 3 * K> x;
    for (int i = 0; i < K; ++i) put<T, 3 * K>(x, i, Sphere::chart(block(c, i), block2(eta, i)));
    return x;
  }
  template <class T>
  static Vec<T, 2 * K> chart_inverse(const Vec<double, 3 * K>& c, const Vec<T, 3 * K>& y) {
    Vec<T, 2 * K> eta;
    for (int i = 0; i < K; ++i) put<T, 2 * K>(eta, i, Sphere::chart_inverse(block(c, i), block(y, i)));
    return eta;
  }
  template <class T>
  static std::pair<Vec<T, 3 * K>, Vec<T, 3 * K>> chart_and_tangent(const Vec<double, 3 * K>& c,
                                                                   const Vec<T, 2 * K>& eta, const Vec<T, 2 * K>& nu) {
    Vec<T, 3 * K> x, v;
    for (int i = 0; i < K; ++i) {
      const auto xv = Sphere::chart_and_tangent(block(c, i), block2(eta, i), block2(nu, i));
      put<T, 3 * K>(x, i, xv.first);
      put<T, 3 * K>(v, i, xv.second);
    }
    return {x, v};
  }
  static Vec<double, 2 * K> covector_to_local(const Vec<double, 3 * K>& x, const Vec<double, 3 * K>& p) {
    return tangent_coordinates(x, p);
  }
  static Vec<double, 3 * K> covector_from_local(const Vec<double, 3 * K>& x, const Vec<double, 2 * K>& p) {
    return tangent(x, p);
  }
  static double point_defect(const Vec<double, 3 * K>& x) {
    double d = 0.0;
    for (int i = 0; i < K; ++i) d = std::fmax(d, Sphere::point_defect(block(x, i)));
    return d;
  }
  static double tangent_defect(const Vec<double, 3 * K>& x, const Vec<double, 3 * K>& v) {
    double d = 0.0;
    for (int i = 0; i < K; ++i) d = std::fmax(d, Sphere::tangent_defect(block(x, i), block(v, i)));
    return d;
  }
  static double distance(const Vec<double, 3 * K>& x, const Vec<double, 3 * K>& y) {
    return (x - y).cwiseAbs().maxCoeff();
  }
  static Vec<double, 3 * K> clean(const Vec<double, 3 * K>& x) {
    Vec<double, 3 * K> y;
    for (int i = 0; i < K; ++i) put<double, 3 * K>(y, i, Sphere::clean(block(x, i)));
    return y;
  }
  template <class T, class U>
  static Vec<T, 3 * K> relative(const Vec<U, 3 * K>& q0, const Vec<T, 3 * K>& q1) {
    Vec<T, 3 * K> d;
    for (int i = 0; i < 3 * K; ++i) d[i] = q1[i] - q0[i];
    return d;
  }
  template <class T>
  static Vec<T, 3 * K> relative_chart(const Vec<double, 3 * K>& q0, const Vec<T, 2 * K>& xi) {
    Vec<T, 3 * K> d;
    for (int i = 0; i < K; ++i) put<T, 3 * K>(d, i, Sphere::relative_chart(block(q0, i), block2(xi, i)));
    return d;
  }
  static Vec<double, 3 * K> sample_point() {
    Vec<double, 3 * K> x;
    for (int i = 0; i < K; ++i) {
      const double a = 0.4 + 0.3 * i;
      put<double, 3 * K>(x, i, Vec<double, 3>(std::sin(a) * 0.6, std::sin(a) * 0.8, -std::cos(a)));
    }
    return x;
  }
  static Vec<double, 2 * K> next_guess(const Vec<double, 3 * K>& q_prev, const Vec<double, 3 * K>& q) {
    Vec<double, 2 * K> g;
    for (int i = 0; i < K; ++i) put<double, 2 * K>(g, i, Sphere::next_guess(block(q_prev, i), block(q, i)));
    return g;
  }
};

}  // namespace dvm
