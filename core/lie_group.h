// A general matrix Lie group G in GL(n), its exponential and logarithm, and the
// discretization maps of its group exponential (paper Ex. 2.8 with tau = exp, and the
// fixed-first-point form of Ex. 3.6), for any scalar.
//
// A Lie algebra type A describes g in gl(n) by a basis E_1..E_d:
//   static constexpr int n, dim;            matrix size, d = dim g
//   hat(xi) = sum_i xi_i E_i,  vee(X)       coordinates of X in g (vee(hat(xi)) = xi)
//   point_defect(g)                         distance of a matrix from G
//   sample_point()                          a generic element, for checks
// Built-ins: so(3) (SO(3) as a matrix group), se(3) (rigid motions, 4x4,
// xi = (omega, u)), sl(2) (2x2, trace zero).
//
// Exponential by scaling and squaring (Higham, Functions of Matrices, SIAM 2008,
// Sec. 10.3): with s >= 0 the least integer such that |X|_1 / 2^s <= 1/2,
//   exp(X) = (T_m(X / 2^s))^(2^s),   T_m(A) = sum_{k <= m} A^k / k!,   m = 18,
// the Taylor remainder being below |A|^19/19! < 2e-23 relative. Each branch (each
// value of s, chosen from the double values) is a polynomial in X, so derivatives
// carried by Jets are those of the polynomial: exact to the same accuracy, including
// at X = 0 (the branch s = 0 is the Taylor series itself, never a constant).
//
// Logarithm: xi = log(W) solves exp(hat(xi)) = W by Gauss-Newton in algebra
// coordinates (Jacobian of exp by automatic differentiation), from the series of
// log(I + Y), Y = W - I; for Jet arguments the derivative parts are then fixed by
// sweeps xi <- xi - P (exp(hat xi) - W), P the Gauss-Newton pseudo-inverse at the
// solution (implicit function theorem). W far from the identity (no convergence)
// raises MapDomainError.
//
// Tangent vectors at g are left-trivialised: g hat(xi). The chart centred at c is
// c exp(hat(eta)); its differential in body form is vee(exp(-X) L(X, Y)), with
// L(X, Y) = d/ds exp(X + s Y) at s = 0 the Frechet derivative (matrix_exp_frechet).
#pragma once

#include <cmath>
#include <string>

#include "core/dense_solve.h"
#include "core/manifold_maps.h"
#include "core/manifolds.h"

namespace dvm {

namespace detail {

template <class T, int N>
Mat<T, N, N> mat_mul(const Mat<T, N, N>& A, const Mat<T, N, N>& B) {
  Mat<T, N, N> C;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      T s = A(i, 0) * B(0, j);
      for (int k = 1; k < N; ++k) s = s + A(i, k) * B(k, j);
      C(i, j) = s;
    }
  return C;
}

template <class T, int N>
Mat<T, N, N> mat_identity() {
  Mat<T, N, N> I;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) I(i, j) = constant<T>(i == j ? 1.0 : 0.0);
  return I;
}

// A^{-1} B by Gaussian elimination column by column (any scalar).
template <class T, int N>
Mat<T, N, N> mat_solve(const Mat<T, N, N>& A, const Mat<T, N, N>& B) {
  Mat<T, N, N> X;
  for (int j = 0; j < N; ++j) X.col(j) = solve_dense<T, N, N>(A, Vec<T, N>(B.col(j)));
  return X;
}

}  // namespace detail

// exp(X) by scaling and squaring with the degree-18 Taylor polynomial.
template <class T, int N>
Mat<T, N, N> matrix_exp(const Mat<T, N, N>& X) {
  double norm = 0.0;  // the 1-norm of the values
  for (int j = 0; j < N; ++j) {
    double c = 0.0;
    for (int i = 0; i < N; ++i) c += std::fabs(value(X(i, j)));
    norm = std::fmax(norm, c);
  }
  if (!std::isfinite(norm)) throw MapDomainError("matrix exponential of a non-finite matrix");
  int s = 0;
  while (norm > 0.5) {
    norm *= 0.5;
    ++s;
  }
  const double scale = std::ldexp(1.0, -s);
  Mat<T, N, N> A;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) A(i, j) = X(i, j) * scale;
  // Horner: T_m(A) = I + A (I + A/2 (I + A/3 (... (I + A/m))))
  const Mat<T, N, N> I = detail::mat_identity<T, N>();
  Mat<T, N, N> E = I;
  for (int k = 18; k >= 1; --k) {
    const Mat<T, N, N> AE = detail::mat_mul(A, E);
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) E(i, j) = I(i, j) + AE(i, j) * (1.0 / k);
  }
  for (int k = 0; k < s; ++k) E = detail::mat_mul(E, E);
  return E;
}

// exp(X) and its Frechet derivative L(X, Y) = d/ds exp(X + s Y) at s = 0, by the same
// scaling and squaring applied to both (Higham, Functions of Matrices, Sec. 10.6):
// differentiate the Horner recursion, then each squaring E <- E E gives L <- E L + L E.
// L is the exact derivative of the approximant that matrix_exp returns.
template <class T, int N>
void matrix_exp_frechet(const Mat<T, N, N>& X, const Mat<T, N, N>& Y, Mat<T, N, N>& E, Mat<T, N, N>& L) {
  double norm = 0.0;
  for (int j = 0; j < N; ++j) {
    double c = 0.0;
    for (int i = 0; i < N; ++i) c += std::fabs(value(X(i, j)));
    norm = std::fmax(norm, c);
  }
  if (!std::isfinite(norm)) throw MapDomainError("matrix exponential of a non-finite matrix");
  int s = 0;
  while (norm > 0.5) {
    norm *= 0.5;
    ++s;
  }
  const double scale = std::ldexp(1.0, -s);
  Mat<T, N, N> A, B;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      A(i, j) = X(i, j) * scale;
      B(i, j) = Y(i, j) * scale;
    }
  const Mat<T, N, N> I = detail::mat_identity<T, N>();
  E = I;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) L(i, j) = constant<T>(0.0);
  for (int k = 18; k >= 1; --k) {
    const Mat<T, N, N> AE = detail::mat_mul(A, E), BE = detail::mat_mul(B, E), AL = detail::mat_mul(A, L);
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) {
        E(i, j) = I(i, j) + AE(i, j) * (1.0 / k);
        L(i, j) = (BE(i, j) + AL(i, j)) * (1.0 / k);
      }
  }
  for (int k = 0; k < s; ++k) {
    const Mat<T, N, N> EL = detail::mat_mul(E, L), LE = detail::mat_mul(L, E);
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < N; ++j) L(i, j) = EL(i, j) + LE(i, j);
    E = detail::mat_mul(E, E);
  }
  // L was built for the scaled direction B = Y / 2^s; the derivative in Y is L itself
  // (d/ds of (T_m((X + s Y)/2^s))^(2^s) carries the 1/2^s inside B).
}

// The Lie algebra so(3): SO(3) as a matrix group (n = 3, d = 3, E_i = hat(e_i)).
struct so3_algebra {
  static constexpr int n = 3, dim = 3;
  static constexpr const char* name = "SO(3) (matrix group)";
  template <class T>
  static Mat<T, 3, 3> hat(const Vec<T, 3>& w) {
    return SO3::hat(w);
  }
  template <class T>
  static Vec<T, 3> vee(const Mat<T, 3, 3>& X) {
    return Vec<T, 3>(0.5 * (X(2, 1) - X(1, 2)), 0.5 * (X(0, 2) - X(2, 0)), 0.5 * (X(1, 0) - X(0, 1)));
  }
  static double point_defect(const Mat<double, 3, 3>& R) { return SO3::point_defect(R); }
  static Mat<double, 3, 3> sample_point() { return SO3::sample_point(); }
};

// se(3): rigid motions [[R, t], [0, 1]]; xi = (omega, u), hat(xi) = [[hat(omega), u], [0, 0]].
struct se3_algebra {
  static constexpr int n = 4, dim = 6;
  static constexpr const char* name = "SE(3)";
  template <class T>
  static Mat<T, 4, 4> hat(const Vec<T, 6>& xi) {
    Mat<T, 4, 4> X;
    const T z = constant<T>(0.0);
    X << z, -xi[2], xi[1], xi[3], xi[2], z, -xi[0], xi[4], -xi[1], xi[0], z, xi[5], z, z, z, z;
    return X;
  }
  template <class T>
  static Vec<T, 6> vee(const Mat<T, 4, 4>& X) {
    Vec<T, 6> xi;
    xi << 0.5 * (X(2, 1) - X(1, 2)), 0.5 * (X(0, 2) - X(2, 0)), 0.5 * (X(1, 0) - X(0, 1)), X(0, 3), X(1, 3), X(2, 3);
    return xi;
  }
  static double point_defect(const Mat<double, 4, 4>& g) {
    double d = SO3::point_defect(Mat<double, 3, 3>(g.topLeftCorner<3, 3>()));
    for (int j = 0; j < 3; ++j) d = std::fmax(d, std::fabs(g(3, j)));
    return std::fmax(d, std::fabs(g(3, 3) - 1.0));
  }
  static Mat<double, 4, 4> sample_point() {
    Vec<double, 6> xi;
    xi << 0.3, -0.7, 1.1, 0.5, -0.2, 0.9;
    return matrix_exp(hat(xi));
  }
};

// sl(2): trace-free 2x2 matrices, E = (diag(1, -1), e_12, e_21); SL(2) = {det = 1}.
struct sl2_algebra {
  static constexpr int n = 2, dim = 3;
  static constexpr const char* name = "SL(2)";
  template <class T>
  static Mat<T, 2, 2> hat(const Vec<T, 3>& xi) {
    Mat<T, 2, 2> X;
    X << xi[0], xi[1], xi[2], -xi[0];
    return X;
  }
  template <class T>
  static Vec<T, 3> vee(const Mat<T, 2, 2>& X) {
    return Vec<T, 3>(0.5 * (X(0, 0) - X(1, 1)), X(0, 1), X(1, 0));
  }
  static double point_defect(const Mat<double, 2, 2>& g) { return std::fabs(g.determinant() - 1.0); }
  static Mat<double, 2, 2> sample_point() { return matrix_exp(hat(Vec<double, 3>(0.4, -0.3, 0.8))); }
};

// The matrix group of the algebra A as a manifold (interface of core/manifolds.h).
template <class A>
struct MatrixLieGroup {
  static constexpr int n = A::n;
  static constexpr int dim = A::dim;
  static constexpr const char* name = A::name;
  template <class T>
  using Point = Mat<T, n, n>;
  template <class T>
  using Tangent = Vec<T, dim>;

  template <class T>
  static Mat<T, n, n> exp(const Vec<T, dim>& xi) {
    return matrix_exp(A::hat(xi));
  }
  // Jacobian of xi -> exp(hat(xi)) (n^2 x dim, column-major entries) at xi.
  static Mat<double, n * n, dim> exp_jacobian(const Vec<double, dim>& xi) {
    using D = ceres::Jet<double, dim>;
    Vec<D, dim> x;
    for (int i = 0; i < dim; ++i) x[i] = seed<double, dim>(xi[i], i);
    const Mat<D, n, n> E = exp(x);
    Mat<double, n * n, dim> J;
    for (int k = 0; k < n * n; ++k) J.row(k) = E(k).v.transpose();
    return J;
  }
  template <class T>
  static Vec<T, dim> log(const Mat<T, n, n>& W) {
    Mat<double, n, n> w;
    for (int k = 0; k < n * n; ++k) w(k) = value(W(k));
    // start: log(I + Y) ~ Y - Y^2/2 + Y^3/3
    const Mat<double, n, n> Y = w - Mat<double, n, n>::Identity();
    Vec<double, dim> xi = A::vee(Mat<double, n, n>(Y - 0.5 * Y * Y + Y * Y * Y / 3.0));
    Mat<double, dim, n * n> P;
    double r = 0.0;
    for (int it = 0; it < 40; ++it) {
      const Mat<double, n, n> E = exp(xi);
      const Mat<double, n * n, dim> J = exp_jacobian(xi);
      P = (J.transpose() * J).inverse() * J.transpose();
      Vec<double, n * n> F;
      for (int k = 0; k < n * n; ++k) F[k] = E(k) - w(k);
      r = max_abs(F);
      if (!std::isfinite(r)) break;
      const Vec<double, dim> d = P * F;
      xi -= d;
      if (r <= 4e-16 * std::fmax(1.0, max_abs(w)) || max_abs(d) <= 1e-17 * std::fmax(1.0, max_abs(xi))) {
        r = 0.0;
        break;
      }
    }
    if (!(r <= 1e-12 * std::fmax(1.0, max_abs(w))))
      throw MapDomainError(std::string(name) + " logarithm: Newton did not converge (the element is too far from "
                                               "the identity)");
    Vec<T, dim> x = constants<T>(xi);
    if constexpr (is_jet_v<T>) {
      for (int sweep = 0; sweep <= jet_depth<T>::value; ++sweep) {
        const Mat<T, n, n> E = exp(x);
        for (int i = 0; i < dim; ++i) {
          T c = constant<T>(0.0);
          for (int k = 0; k < n * n; ++k) c = c + P(i, k) * (E(k) - W(k));
          x[i] = x[i] - c;
        }
      }
    }
    return x;
  }

  template <class T>
  static Mat<T, n, n> constants_n(const Mat<double, n, n>& c) {
    Mat<T, n, n> out;
    for (int k = 0; k < n * n; ++k) out(k) = constant<T>(c(k));
    return out;
  }

  template <class T, class U>
  static Vec<T, dim> tangent(const Mat<U, n, n>&, const Vec<T, dim>& nu) {
    return nu;
  }
  template <class T>
  static Vec<T, dim> tangent_coordinates(const Mat<double, n, n>&, const Vec<T, dim>& v) {
    return v;
  }
  template <class T>
  static Mat<T, n, n> chart(const Mat<double, n, n>& c, const Vec<T, dim>& eta) {
    return detail::mat_mul(constants_n<T>(c), exp(eta));
  }
  template <class T>
  static Vec<T, dim> chart_inverse(const Mat<double, n, n>& c, const Mat<T, n, n>& y) {
    return log(detail::mat_solve(constants_n<T>(c), y));
  }
  // Body form of d/ds exp(hat(eta + s nu)): vee(exp(-X) L(X, Y)), L the Frechet derivative.
  template <class T>
  static Vec<T, dim> dexp_body(const Vec<T, dim>& eta, const Vec<T, dim>& nu, Mat<T, n, n>* E_out = nullptr) {
    Mat<T, n, n> E, L;
    matrix_exp_frechet(A::hat(eta), A::hat(nu), E, L);
    if (E_out) *E_out = E;
    return A::vee(detail::mat_solve(E, L));
  }
  template <class T>
  static std::pair<Mat<T, n, n>, Vec<T, dim>> chart_and_tangent(const Mat<double, n, n>& c, const Vec<T, dim>& eta,
                                                                const Vec<T, dim>& nu) {
    Mat<T, n, n> E;
    const Vec<T, dim> v = dexp_body(eta, nu, &E);
    return {detail::mat_mul(constants_n<T>(c), E), v};
  }
  static Vec<double, dim> covector_to_local(const Mat<double, n, n>&, const Vec<double, dim>& p) { return p; }
  static Vec<double, dim> covector_from_local(const Mat<double, n, n>&, const Vec<double, dim>& p) { return p; }
  static double point_defect(const Mat<double, n, n>& g) { return A::point_defect(g); }
  static double tangent_defect(const Mat<double, n, n>&, const Vec<double, dim>&) { return 0.0; }
  static double distance(const Mat<double, n, n>& a, const Mat<double, n, n>& b) {
    return (a - b).cwiseAbs().maxCoeff();
  }
  static Mat<double, n, n> clean(const Mat<double, n, n>& g) { return g; }
  static Mat<double, n, n> sample_point() { return A::sample_point(); }

  // The relative element q0^{-1} q1, from stored points or, for q1 = q0 exp(xi), as exp(xi).
  template <class T, class U>
  static Mat<T, n, n> relative(const Mat<U, n, n>& q0, const Mat<T, n, n>& q1) {
    Mat<T, n, n> a;
    for (int k = 0; k < n * n; ++k) {
      if constexpr (std::is_same_v<U, double>)
        a(k) = constant<T>(q0(k));
      else
        a(k) = q0(k);
    }
    return detail::mat_solve(a, q1);
  }
  template <class T>
  static Mat<T, n, n> relative_chart(const Mat<double, n, n>&, const Vec<T, dim>& xi) {
    return exp(xi);
  }
  static Vec<double, dim> next_guess(const Mat<double, n, n>& q_prev, const Mat<double, n, n>& q) {
    return log(Mat<double, n, n>(q_prev.inverse() * q));
  }
};

// The group-exponential maps R_d(g, xi) = (g exp(-theta xi), g exp((1 - theta) xi)):
// theta = 1/2 the midpoint form, theta = 0 the fixed-first-point form (g, g exp(xi)).
// Inverse in closed form for every theta: xi = log(g0^{-1} g1), g = g0 exp(theta xi).
template <class A>
class LieGroupExpMap {
 public:
  using Manifold = MatrixLieGroup<A>;
  static constexpr int n = A::n, dim = A::dim;
  LieGroupExpMap(double theta, std::string name) : theta_(theta), name_(std::move(name)) {
    detail::check_theta(theta);
  }
  double theta() const { return theta_; }
  std::string name() const { return name_; }
  bool symmetric() const { return theta_ == 0.5; }
  int order() const { return symmetric() ? 2 : 1; }
  bool closed_form_inverse() const { return true; }

  template <class T>
  ManifoldPair<Manifold, T> operator()(const Mat<T, n, n>& g, const Vec<T, dim>& xi) const {
    return {detail::mat_mul(g, Manifold::exp(Vec<T, dim>(-theta_ * xi))),
            detail::mat_mul(g, Manifold::exp(Vec<T, dim>((1.0 - theta_) * xi)))};
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse(const Mat<T, n, n>& q0, const Mat<T, n, n>& q1) const {
    return inverse_relative(q0, Manifold::relative(q0, q1));
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse_relative(const Mat<T, n, n>& q0, const Mat<T, n, n>& W) const {
    const Vec<T, dim> xi = Manifold::log(W);
    return {detail::mat_mul(q0, Manifold::exp(Vec<T, dim>(theta_ * xi))), xi};
  }

 private:
  double theta_;
  std::string name_;
};

template <class A>
LieGroupExpMap<A> adjoint_map(const LieGroupExpMap<A>& m) {
  return LieGroupExpMap<A>(1.0 - m.theta(), m.name() + "*");
}

}  // namespace dvm
