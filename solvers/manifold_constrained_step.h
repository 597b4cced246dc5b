// The position-momentum step on S^2 or SO(3) under holonomic constraints g(t, x) = 0
// written in the scene (mechanics/written_manifold.h, ManifoldConstraints): the
// constrained discrete Euler-Lagrange equations with discrete multipliers and the
// constrained discrete Legendre transforms (Marsden and West, Acta Numerica 2001,
// Sec. 3.5), the manifold step's equations (solvers/manifold_step.h) with the
// constraint's normals added, written in the chart centred at each end as that step's
// are.
//
// With pi0 the chart components of p0 at q0, q1 = chart(q0, xi), G0 = the rows of Dg(t0,
// q0) in that chart (ManifoldConstraints::chart_gradient) and t1 = t0 + h, one step solves
//   1. pi0 + D1 L_d(q0, q1) + F_d^- - G0^T lambda = 0,   g(t1, q1) = 0
//      for (xi, lambda) (n + m unknowns): the left constrained Legendre transform;
//   2. pi1 = D2 L_d(q0, q1) + F_d^+ - G1^T mu (in the chart centred at q1, G1 = Dg(t1, q1)
//      there) with the velocity nu1 = FL^{-1}(q1, pi1) on the hidden constraint
//      G1 nu1 + g_t(t1, q1) = 0, for (nu1, mu): the right one.
// As on R^n (solvers/constrained_step.h), eliminating p between two steps gives the
// constrained discrete Euler-Lagrange equation, step 2 only chooses the representative
// of p1 along the normals, and without forces the step is symplectic on the
// constraint's cotangent bundle; for a scleronomic g the adjoint of the step of a map is
// the constrained step of the adjoint map, so symmetric compositions raise its order.
//
// Equation 1 is solved by newton_drive (solvers/newton_driver.h): the D1 L_d rows and the
// constraint rows differentiated in xi by one Jet level (as the manifold step's
// residual), the multiplier column -s G0^T, the multiplier carried as lambda / s with
// s = max|dF/dxi| / max|G0| at the first Jacobian, kept, so that the constraint rows and
// the multiplier column are of the size of the others and one step's multiplier is the
// next one's guess; a dense LU of the (n + m) x (n + m) saddle point, formed at every
// iteration. Equation 2 is Newton's method on (nu1, mu) with L's velocity Hessian in the
// chart (manifold_velocity_derivatives): one iteration for a Lagrangian quadratic in the
// velocity.
//
// Workspace is held by the object: one object must not be used from two threads at
// once (copies are independent).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/dense_solve.h"
#include "mechanics/written_manifold.h"
#include "solvers/manifold_step.h"

namespace dvm {

namespace manifold_constrained_detail {
// The force a space takes (ManifoldForce on S^2 and SO(3)), else NoForce.
template <class M>
struct ForceOf {
  using type = NoForce;
};
template <>
struct ForceOf<Sphere> {
  using type = ManifoldForce<Sphere>;
};
template <>
struct ForceOf<SO3> {
  using type = ManifoldForce<SO3>;
};
}  // namespace manifold_constrained_detail

// The force is optional at run time (null: none), so that one step type, and one run
// type, serves the constrained runs with and without a force.
template <class System, class Map>
class ConstrainedManifoldStep {
 public:
  using M = typename Map::Manifold;
  static constexpr int n = M::dim;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  using DL = ManifoldDiscreteLagrangian<System, Map>;
  using Con = ManifoldConstraints<M>;
  using Force = typename manifold_constrained_detail::ForceOf<M>::type;

  ConstrainedManifoldStep(System L, Map R, double h, StepOptions options, std::shared_ptr<const Con> con,
                          std::shared_ptr<const Force> force = nullptr)
      : dl_(std::move(L), std::move(R), h), options_(options), con_(std::move(con)), force_(std::move(force)) {
    if (!con_) throw std::invalid_argument("ConstrainedManifoldStep: needs its constraints");
    const int m = con_->count();
    w_.y = Eigen::VectorXd::Zero(n + m);
    w_.r.resize(n + m);
    w_.dx.resize(n + m);
    w_.start.resize(n + m);
    w_.J.resize(n + m, n + m);
    w_.la.resize(n + m);
    w_.g.resize(m);
    w_.gt.resize(m);
    w_.G.resize(m, n);
  }
  const DL& discrete_lagrangian() const { return dl_; }
  double step_size() const { return dl_.step(); }

  // Equation 1 of the header comment for the driver: y = (xi, lambda / s).
  struct Equation {
    using Vector = Eigen::VectorXd;
    using Matrix = Eigen::MatrixXd;
    const ConstrainedManifoldStep* step;
    Point q0;
    Vec<double, n> pi0;
    const Eigen::Matrix<double, Eigen::Dynamic, n>* G0;
    double t_node, t1, s0;
    double* s;  // the multiplier's scale (0 until the first Jacobian)
    int m;

    void residual(const Vector& y, Vector& r) const {
      Matrix J(n + m, n + m);
      jacobian(y, r, J);
    }
    double jacobian(const Vector& y, Vector& r, Matrix& J) const {
      using D = ceres::Jet<double, n>;
      Vec<D, n> x;
      for (int i = 0; i < n; ++i) x[i] = D(y[i], i);
      const auto q1 = M::chart(q0, x);
      Vec<D, n> d1;
      if constexpr (is_force_v<Force>)
        if (step->force_) {
          d1 = step->dl_.D1_local(q0, q1, M::relative_chart(q0, x), *step->force_, t_node);
          return finish(y, r, J, d1, q1);
        }
      d1 = step->dl_.D1_local(q0, q1, M::relative_chart(q0, x));
      return finish(y, r, J, d1, q1);
    }
    double scale(double yn, double Jmax) const { return s0 + Jmax * yn; }
    double offset() const { return 1.0; }

   private:
    // The rows from D1 L_d (+ F_d^-) in Jets over xi, and the constraint's at q1.
    template <class D, class P>
    double finish(const Vector& y, Vector& r, Matrix& J, const Vec<D, n>& d1, const P& q1) const {
      std::array<D, n> g;
      step->con_->value(D(t1), q1, g.data());
      double Jd = 0.0;
      for (int i = 0; i < n; ++i) {
        r[i] = pi0[i] + d1[i].a;
        for (int j = 0; j < n; ++j) {
          J(i, j) = d1[i].v[j];
          Jd = std::fmax(Jd, std::fabs(J(i, j)));
        }
      }
      if (*s == 0.0) {
        const double gmax = G0->cwiseAbs().maxCoeff();
        *s = std::isfinite(Jd) && Jd > 0.0 && gmax > 0.0 ? Jd / gmax : 1.0;
      }
      for (int k = 0; k < m; ++k) {
        const double lk = *s * y[n + k];
        for (int i = 0; i < n; ++i) {
          r[i] -= (*G0)(k, i) * lk;
          J(i, n + k) = -*s * (*G0)(k, i);
        }
        r[n + k] = *s * g[static_cast<std::size_t>(k)].a;
        for (int j = 0; j < n; ++j) J(n + k, j) = *s * g[static_cast<std::size_t>(k)].v[j];
        for (int j = 0; j < m; ++j) J(n + k, n + j) = 0.0;
      }
      const double Jmax = J.cwiseAbs().maxCoeff();
      return std::isfinite(Jmax) ? Jmax : INFINITY;
    }
  };

  // One step: xi holds the guess on entry and the chart coordinates of q1 on return.
  StepSummary step(double t, const Point& q0, const Covector& p0, Vec<double, n>& xi, Point& q1, Covector& p1) const {
    const int m = con_->count();
    const double h = dl_.step(), t1 = t + h;
    const double t_node = t + dl_.map().theta() * h;
    Work& w = w_;
    const Vec<double, n> pi0 = M::covector_to_local(q0, p0);
    StepSummary s;
    try {
      con_->chart_gradient(t, q0, w.g, w.G, w.gt);
      if (!w.G.allFinite()) {
        s.fail("the constraint's gradient is not finite");
        return s;
      }
      Equation eq{this, q0, pi0, &w.G, t_node, t1, max_abs(pi0), &w.scale, m};
      w.y.head(n) = xi;  // (the multiplier's guess: the last step's, kept in y)
      DriverState state;
      s = newton_drive(eq, w.la, Refresh::every_iteration, options_, w.y, w.r, w.dx, w.J, state, w.start);
      if (!s.converged) return s;
      xi = w.y.head(n);
      Point raw;
      if (!chart_end<M>(q0, xi, s, raw)) return s;
      const auto rel = M::relative_chart(q0, xi);
      Vec<double, n> pi1;
      bool forced = false;
      if constexpr (is_force_v<Force>)
        if (force_) {
          pi1 = dl_.D2_local(q0, raw, rel, *force_, t_node, &s.work);
          forced = true;
        }
      if (!forced) pi1 = dl_.D2_local(q0, raw, rel);
      if (project(t1, raw, pi1, s)) leave_at<M>(raw, pi1, s, q1, p1);
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    return s;
  }

  // Equation 2 of the header comment at (t1, q1): pi1 (chart components in the chart
  // centred at q1) moved along the rows of G1 onto the hidden constraint, in place (the
  // runtime projects an initial momentum by it too). False (s failed) where Newton's
  // method does not converge or the saddle point is singular.
  bool project(double t1, const Point& q1, Vec<double, n>& pi1, StepSummary& s) const {
    const int m = con_->count();
    Work& w = w_;
    con_->chart_gradient(t1, q1, w.g, w.G, w.gt);
    Eigen::VectorXd& z = w.dx;  // (nu1, mu)
    z.setZero();
    Eigen::VectorXd &r = w.r, &d = w.start;
    Eigen::MatrixXd& J = w.J;
    // the rule of manifold_legendre_inverse: the residual against the momentum's size
    // (the constraint rows against |G| |nu|), or a correction at round-off
    const double scale = std::fmax(1e-300, max_abs(pi1)), gmax = w.G.cwiseAbs().maxCoeff();
    for (int it = 0;; ++it) {
      Vec<double, n> grad;
      Mat<double, n, n> H;
      manifold_velocity_derivatives(dl_.lagrangian(), q1, Vec<double, n>(z.head(n)), grad, H);
      r.head(n) = grad - pi1 + w.G.transpose() * z.tail(m);
      r.tail(m) = w.G * z.head(n) + w.gt;
      const double nu = max_abs(Vec<double, n>(z.head(n)));
      if (max_abs(Vec<double, n>(r.head(n))) <= 1e-14 * scale && r.tail(m).cwiseAbs().maxCoeff() <= 1e-14 * gmax * nu)
        break;
      if (it == 50) {
        s.fail("the momentum's projection onto the hidden constraint did not converge");
        return false;
      }
      J.topLeftCorner(n, n) = H;
      J.topRightCorner(n, m) = w.G.transpose();
      J.bottomLeftCorner(m, n) = w.G;
      J.bottomRightCorner(m, m).setZero();
      if (!w.la.factor(J)) {
        s.fail("the momentum's projection onto the hidden constraint is singular (velocity Hessian or constraint "
               "gradient)");
        return false;
      }
      w.la.solve(r, d);
      z -= d;
      if (!z.allFinite()) {
        s.fail("non-finite velocity in the momentum's projection");
        return false;
      }
      if (max_abs(d) <= 4e-16 * std::fmax(1.0, max_abs(z))) break;
    }
    pi1 -= w.G.transpose() * z.tail(m);
    return true;
  }

 private:
  struct Work {
    Eigen::VectorXd y, r, dx, start, g, gt;
    Eigen::MatrixXd J;
    Eigen::Matrix<double, Eigen::Dynamic, n> G;
    DenseLU la;
    double scale = 0.0;
  };

  DL dl_;
  StepOptions options_;
  std::shared_ptr<const Con> con_;
  std::shared_ptr<const Force> force_;
  mutable Work w_;
};

}  // namespace dvm
