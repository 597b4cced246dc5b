// The position-momentum step of a sphere map on the chain of spherical pendulums with
// any number of links K, in O(K) operations per Newton iteration.
//
// It solves the equation of ManifoldStep (solvers/manifold_step.h) for the chain
// (Sec. 5 of the paper: the discrete Legendre equations of L_d(q0, q1) = h L(R^{-1}(q0, q1)/h)
// on Q = (S^2)^K, with the map R applied to each factor): given (q_k, p_k), find xi in
// R^{2K}, q_{k+1} = chart(q_k, xi), with
//   p_k + D1 L_d(q_k, q_{k+1}) = 0    (chart centred at q_k),
//   p_{k+1} = D2 L_d(q_k, q_{k+1})    (chart centred at q_{k+1}).
// With (X_i, U_i) = R^{-1}(q0_i, q1_i) the factors' base points and velocities times h,
// L_d = U^T M U / (2 h) - h sum_j c_j (X_j)_3 (mechanics/spherical_chain.h), and the
// component of D1 L_d on link i is
//   r_i = B_i^T (M U)_i / h - h c_i (A_i)_3,   B_i = dU_i/deta_i, A_i = dX_i/deta_i,
// eta_i moving q0_i in its chart. Only (M U)_i couples the links; the Jacobian in xi is
//   J = D + B^T M C / h,   C_i = dU_i/dxi_i,
//   D_i = (d^2 U_i / deta_i dxi_i) . (M U)_i / h - h c_i d^2 (X_i)_3 / deta_i dxi_i,
// block diagonal plus the coupling through M that ChainCouplingSolve factors in O(K).
// Each link's derivatives come from its own map inverse in Jet<Jet<double, 2>, 2>
// (first order in eta, second in xi), with the relative position q1_i - q0_i formed
// from xi as ManifoldStep forms it (Sphere::relative_chart), so the two steps solve the
// same equation: they agree to round-off at K = 1 to 4 (tests/solvers/test_sphere_chain.cc).
//
// Newton is simplified (the driver of solvers/newton_driver.h with Refresh::within_step):
// the Jacobian is formed and factored at the starting guess and again only where an
// iteration fails to shrink the residual fourfold. It has
// the contract of a manifold step for `integrate` and ComposedPointStep
// (M = DynamicSpherePower, n = Eigen::Dynamic). Workspace is allocated at construction
// and shared by copies: steps must not run on two threads at once.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/manifold_maps.h"
#include "mechanics/spherical_chain.h"
#include "solvers/newton_driver.h"

namespace dvm {

class SphereChainStep {
 public:
  using M = DynamicSpherePower;
  static constexpr int n = Eigen::Dynamic;
  using Point = Eigen::VectorXd;
  using Covector = Eigen::VectorXd;
  using V = Eigen::VectorXd;

  // The workspace of a step: the per-link blocks and the banded factorisation (1.6 kB a
  // link). The stages of a composition run one after another and each factors before
  // it solves, so they share one (as may the run's Legendre inverse, between steps).
  struct Work;
  static std::shared_ptr<Work> workspace(const DynamicSphericalChain& L) { return std::make_shared<Work>(L); }

  SphereChainStep(DynamicSphericalChain L, SphereMap R, double h, StepOptions options = {},
                  std::shared_ptr<Work> work = nullptr)
      : L_(std::move(L)), R_(std::move(R)), h_(h), options_(options), work_(work ? std::move(work) : workspace(L_)) {
    if (work_->solver->links() != L_.links()) throw std::invalid_argument("the workspace is another chain's");
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    if (options.solver != SolverKind::newton)
      throw std::invalid_argument("the spherical chain's step solves by Newton's method only (solver = \"newton\")");
  }

  double step_size() const { return h_; }
  const DynamicSphericalChain& lagrangian() const { return L_; }
  const SphereMap& map() const { return R_; }

  // One step: xi holds the guess on entry and the chart coordinates of q1 on return.
  StepSummary step(double /*t*/, const Point& q0, const Covector& p0, V& xi, Point& q1, Covector& p1) const {
    StepSummary s;
    const int K = L_.links();
    if (q0.size() != 3 * K || p0.size() != 3 * K || xi.size() != 2 * K) {
      s.message = "the state has " + std::to_string(q0.size()) + " stored coordinates; the chain has " +
                  std::to_string(3 * K);
      return s;
    }
    Work& w = *work_;
    const V pi0 = M::covector_to_local(q0, p0);
    try {
      Equation eq{*this, q0, pi0, max_abs(pi0)};
      Banded la{w, 1.0 / h_};
      DriverState state;
      s = newton_drive(eq, la, Refresh::within_step, options_, xi, w.r, w.dx, w.unused, state, w.start);
      if (!s.converged) return s;
      finish(q0, xi, s, q1, p1);
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    return s;
  }

  // For checks: the residual p0 + D1 L_d(q0, chart(q0, xi)) in the chart at q0 and its
  // Jacobian D + B^T M C / h in xi, dense (O(K^2)).
  void residual_and_jacobian(const Point& q0, const Covector& p0, const V& xi, V& r, Eigen::MatrixXd& J) const {
    evaluate(q0, xi, true);
    const Work& w = *work_;
    const int K = L_.links();
    r = M::covector_to_local(q0, p0) + w.d1;
    J.setZero(2 * K, 2 * K);
    for (int i = 0; i < K; ++i)
      for (int j = 0; j < K; ++j) {
        const std::size_t u = static_cast<std::size_t>(i), v = static_cast<std::size_t>(j);
        const double Mij = L_.lengths()[i] * L_.lengths()[j] * L_.mass_below(std::max(i, j));
        J.block<2, 2>(2 * i, 2 * j) = (Mij / h_) * w.B[u].transpose() * w.C[v];
        if (i == j) J.block<2, 2>(2 * i, 2 * j) += w.D[u];
      }
  }

  struct Work {
    explicit Work(const DynamicSphericalChain& L)
        : solver(std::make_shared<ChainCouplingSolve>(L)),
          D(static_cast<std::size_t>(L.links())),
          B(static_cast<std::size_t>(L.links())),
          C(static_cast<std::size_t>(L.links())),
          d2U(static_cast<std::size_t>(L.links())),
          d2X(static_cast<std::size_t>(L.links())) {
      const int K = L.links();
      U.resize(3 * K);
      MU.resize(3 * K);
      d1.resize(2 * K);
      r.resize(2 * K);
      dx.resize(2 * K);
      A3.resize(2 * K);
      start.resize(2 * K);
    }
    std::shared_ptr<ChainCouplingSolve> solver;
    std::vector<Mat<double, 2, 2>> D;
    std::vector<Mat<double, 3, 2>> B, C;
    // per link: d^2 U_i / deta_e dxi_s (3 components x 4) and d^2 (X_i)_3 / deta_e dxi_s
    std::vector<Mat<double, 3, 4>> d2U;
    std::vector<Mat<double, 2, 2>> d2X;
    V U, MU, d1, r, dx, A3, start;
    Eigen::MatrixXd unused;  // (the driver's matrix: the Jacobian lives in the blocks)
  };

 private:
  // The equation in xi for the driver: F(xi) = pi0 + D1 L_d(q0, chart(q0, xi)), its
  // Jacobian the blocks D, B, C (evaluate) factored by ChainCouplingSolve.
  struct Equation {
    using Vector = V;
    using Matrix = Eigen::MatrixXd;
    const SphereChainStep& st;
    const V& q0;
    const V& pi0;
    double pscale;
    void residual(const V& xi, V& r) const {
      st.evaluate(q0, xi, false);
      r = pi0 + st.work_->d1;
    }
    double jacobian(const V& xi, V& r, Matrix&) const {
      st.evaluate(q0, xi, true);
      r = pi0 + st.work_->d1;
      return st.jacobian_size();
    }
    double scale(double xin, double Jmax) const { return pscale + Jmax * xin; }
    double offset() const { return 1.0; }  // (xi is a chart coordinate; the points have norm 1)
  };
  struct Banded {
    Work& w;
    double inverse_step;
    bool factor(const Eigen::MatrixXd&, double) { return w.solver->factor(w.D, w.B, w.C, inverse_step); }
    void solve(const V& r, V& dx) const { w.solver->solve(r, dx); }
    const char* name() const { return "banded LU of the chain"; }
  };

  using J2 = ceres::Jet<double, 2>;
  using JJ = ceres::Jet<J2, 2>;

  // The map inverse of link i at its unknown xi_i, as a function of eta_i (moving
  // q0_i in its chart): (X_i, U_i) in Jets of eta over T, T = double for the residual
  // alone, Jet<double, 2> (seeded in xi_i) for its Jacobian too.
  template <class T>
  ManifoldTangent<Sphere, ceres::Jet<T, 2>> link_inverse(const Vec<double, 3>& x0, const Vec<T, 2>& xi) const {
    using D = ceres::Jet<T, 2>;
    const Vec<T, 3> q1 = Sphere::chart(x0, xi);
    const Vec<T, 3> rel = Sphere::relative_chart(x0, xi);
    const Vec<D, 2> eta(seed<T, 2>(constant<T>(0.0), 0), seed<T, 2>(constant<T>(0.0), 1));
    const Vec<D, 3> a = Sphere::chart(x0, eta);
    Vec<D, 3> d;
    for (int k = 0; k < 3; ++k) {
      d[k] = D(q1[k]) - a[k];
      d[k].a = rel[k];
    }
    return R_.inverse_relative(a, d);
  }

  // d1 = D1 L_d(q0, chart(q0, xi)) in the chart at q0; with `jacobian`, also the blocks
  // D, B, C of its Jacobian in xi.
  void evaluate(const V& q0, const V& xi, bool jacobian) const {
    Work& w = *work_;
    const int K = L_.links();
    for (int i = 0; i < K; ++i) {
      const std::size_t u = static_cast<std::size_t>(i);
      const Vec<double, 3> x0 = q0.segment<3>(3 * i);
      const Vec<double, 2> xii = xi.segment<2>(2 * i);
      if (jacobian) {
        const ManifoldTangent<Sphere, JJ> t = link_inverse(x0, Vec<J2, 2>(J2(xii[0], 0), J2(xii[1], 1)));
        for (int k = 0; k < 3; ++k) {
          w.U[3 * i + k] = t.v[k].a.a;
          for (int e = 0; e < 2; ++e) {
            w.B[u](k, e) = t.v[k].v[e].a;
            w.C[u](k, e) = t.v[k].a.v[e];
            for (int sx = 0; sx < 2; ++sx) w.d2U[u](k, 2 * e + sx) = t.v[k].v[e].v[sx];
          }
        }
        for (int e = 0; e < 2; ++e) {
          w.A3[2 * i + e] = t.x[2].v[e].a;
          for (int sx = 0; sx < 2; ++sx) w.d2X[u](e, sx) = t.x[2].v[e].v[sx];
        }
      } else {
        const ManifoldTangent<Sphere, J2> t = link_inverse(x0, xii);
        for (int k = 0; k < 3; ++k) {
          w.U[3 * i + k] = t.v[k].a;
          for (int e = 0; e < 2; ++e) w.B[u](k, e) = t.v[k].v[e];
        }
        for (int e = 0; e < 2; ++e) w.A3[2 * i + e] = t.x[2].v[e];
      }
    }
    L_.mass_times(w.U, w.MU);
    for (int i = 0; i < K; ++i) {
      const std::size_t u = static_cast<std::size_t>(i);
      const Vec<double, 3> mu = w.MU.segment<3>(3 * i) / h_;
      const double ch = h_ * L_.height_coefficient(i);
      w.d1.segment<2>(2 * i) = w.B[u].transpose() * mu - ch * w.A3.segment<2>(2 * i);
      if (jacobian)
        for (int e = 0; e < 2; ++e)
          for (int sx = 0; sx < 2; ++sx)
            w.D[u](e, sx) = w.d2U[u].col(2 * e + sx).dot(mu) - ch * w.d2X[u](e, sx);
    }
  }
  // The size of the Jacobian's largest entry: its diagonal blocks exactly, and a bound of
  // the others, |B_i^T M_ij C_j| <= sqrt(M_ii) |B_i| sqrt(M_jj) |C_j| / |h| (columns'
  // 2-norms; M_ij = l_i l_j mu_max(i, j) <= sqrt(M_ii M_jj)).
  double jacobian_size() const {
    const Work& w = *work_;
    double diag = 0.0, b = 0.0, c = 0.0;
    for (std::size_t i = 0; i < w.D.size(); ++i) {
      const double Mii = L_.mass_diagonal(static_cast<int>(i));
      diag = std::fmax(diag, max_abs(Mat<double, 2, 2>(w.D[i] + (Mii / h_) * w.B[i].transpose() * w.C[i])));
      b = std::fmax(b, std::sqrt(Mii) * w.B[i].colwise().norm().maxCoeff());
      c = std::fmax(c, std::sqrt(Mii) * w.C[i].colwise().norm().maxCoeff());
    }
    const double J = std::fmax(diag, b * c / std::fabs(h_));
    return std::isfinite(J) ? J : INFINITY;
  }
  // q1 = chart(q0, xi) and p1 = D2 L_d(q0, q1) in the chart at q1, stored.
  void finish(const V& q0, const V& xi, StepSummary& s, Point& q1, Covector& p1) const {
    Work& w = *work_;
    const int K = L_.links();
    q1.resize(3 * K);
    p1.resize(3 * K);
    // U at the solution (the Jacobian may be older than the last iterate)
    std::vector<Vec<double, 2>> A1(static_cast<std::size_t>(K));
    std::vector<Mat<double, 3, 2>> B1(static_cast<std::size_t>(K));
    for (int i = 0; i < K; ++i) {
      const std::size_t u = static_cast<std::size_t>(i);
      const Vec<double, 3> x0 = q0.segment<3>(3 * i);
      const Vec<double, 2> xii = xi.segment<2>(2 * i);
      const Vec<double, 3> raw = Sphere::chart(x0, xii);
      const double defect = Sphere::point_defect(raw);
      if (!(defect <= 1e-12)) {
        s.fail("the chart left the manifold by " + std::to_string(defect) + " (more than round-off)");
        return;
      }
      q1.segment<3>(3 * i) = raw;
      // eta moves q1_i in its chart; q0_i stays
      const Vec<double, 3> rel = Sphere::relative_chart(x0, xii);
      const Vec<J2, 2> eta(seed<double, 2>(0.0, 0), seed<double, 2>(0.0, 1));
      const Vec<J2, 3> b = Sphere::chart(raw, eta);
      Vec<J2, 3> a, d;
      for (int k = 0; k < 3; ++k) {
        a[k] = J2(x0[k]);
        d[k] = b[k] - a[k];
        d[k].a = rel[k];
      }
      const ManifoldTangent<Sphere, J2> t = R_.inverse_relative(a, d);
      for (int k = 0; k < 3; ++k) {
        w.U[3 * i + k] = t.v[k].a;
        for (int e = 0; e < 2; ++e) B1[u](k, e) = t.v[k].v[e];
      }
      for (int e = 0; e < 2; ++e) A1[u][e] = t.x[2].v[e];
    }
    L_.mass_times(w.U, w.MU);
    for (int i = 0; i < K; ++i) {
      const std::size_t u = static_cast<std::size_t>(i);
      const Vec<double, 2> pi1 =
          B1[u].transpose() * (w.MU.segment<3>(3 * i) / h_) - (h_ * L_.height_coefficient(i)) * A1[u];
      p1.segment<3>(3 * i) = Sphere::tangent(Vec<double, 3>(q1.segment<3>(3 * i)), pi1);
    }
    if (!std::isfinite(max_abs(p1))) s.fail("non-finite momentum");
  }

  DynamicSphericalChain L_;
  SphereMap R_;
  double h_;
  StepOptions options_;
  std::shared_ptr<Work> work_;
};

}  // namespace dvm
