// Whole trajectories on (S^2)^K as one Ceres problem with Ceres' manifold support
// (the boundary-value problem of solvers/boundary_value.h, on a curved space).
//
// With q_0 and q_K fixed on the sphere(s), the discrete action
// S = sum_k L_d(q_k, q_{k+1}) is stationary in the interior nodes exactly when, at each
// interior node, the differential of L_d(q_{k-1}, q_k) + L_d(q_k, q_{k+1}) in q_k
// vanishes on the tangent space T_{q_k}. With the nodes stored as unit vectors in
// R^3, that differential is the tangential part of the ambient gradient,
//   DEL_k = (I - q_k q_k^T) grad_{q_k} [L_d(q_{k-1}, q_k) + L_d(q_k, q_{k+1})]
// (per factor on (S^2)^K): any smooth extension of L_d off the sphere gives the same
// tangential part, so the closed-form inverses of the sphere maps serve as that
// extension. Each node is a parameter block of size 3 per sphere with
// ceres::SphereManifold<3> (Ceres 2.1, Problem::SetManifold; ProductManifold for K > 1),
// so Ceres' updates are retractions and every node stays a unit vector; the residual
// block of node k depends on nodes k-1, k, k+1 only (a sparse, block-tridiagonal
// Jacobian). The result is checked as on R^n: every DEL_k below residual_tolerance
// times the momentum scale, max_k |p_k| + |M| max|q| / h.
#pragma once

#include <ceres/ceres.h>
#include <ceres/manifold.h>
#include <ceres/product_manifold.h>
#include <ceres/sphere_manifold.h>

#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/manifold_systems.h"
#include "solvers/boundary_value.h"

namespace dvm {

template <class System, class Map>
class SphereBoundaryValueProblem {
 public:
  using M = typename Map::Manifold;
  static constexpr int S = M::template Point<double>::RowsAtCompileTime;  // 3 per sphere
  static constexpr int spheres = S / 3;
  using P = Vec<double, S>;
  using DL = ManifoldDiscreteLagrangian<System, Map>;
  static_assert(S % 3 == 0 && M::dim == 2 * spheres, "boundary-value problems here live on (S^2)^K");

  SphereBoundaryValueProblem(System L, Map R, double h) : dl_(std::move(L), std::move(R), h) {}
  const DL& discrete_lagrangian() const { return dl_; }

  struct DelResidual {
    const DL* dl;
    template <class T>
    bool operator()(const T* a, const T* b, const T* c, T* r) const {
      using J = ceres::Jet<T, S>;
      typename M::template Point<J> qa, qb, qc;
      for (int i = 0; i < S; ++i) {
        qa[i] = J(a[i]);
        qc[i] = J(c[i]);
        qb[i] = J(b[i], i);
      }
      const J s = (*dl)(qa, qb) + (*dl)(qb, qc);
      for (int k = 0; k < spheres; ++k) {
        T d = b[3 * k] * s.v[3 * k];
        for (int i = 1; i < 3; ++i) d = d + b[3 * k + i] * s.v[3 * k + i];
        for (int i = 0; i < 3; ++i) r[3 * k + i] = s.v[3 * k + i] - d * b[3 * k + i];
      }
      return true;
    }
  };

  P del(const P& a, const P& b, const P& c) const {
    P r;
    DelResidual{&dl_}(a.data(), b.data(), c.data(), r.data());
    return r;
  }

  // Solves for q_1 .. q_{K-1} between q_0 = qa and q_K = qb. `guess` (K + 1 nodes,
  // ends ignored) defaults to normalised linear interpolation of each unit vector.
  BoundaryValueResult<S> solve(const P& qa, const P& qb, int K, const BoundaryValueOptions& opt = {},
                               const std::vector<P>* guess = nullptr) const {
    if (K < 2) throw std::invalid_argument("boundary-value problem: need at least 2 steps (one interior node)");
    if (M::point_defect(qa) > 1e-12 || M::point_defect(qb) > 1e-12)
      throw std::invalid_argument("boundary-value problem: the end points are not on the manifold");
    std::vector<double> x(static_cast<std::size_t>(K + 1) * S);
    auto node = [&](int k) { return x.data() + static_cast<std::size_t>(k) * S; };
    for (int k = 0; k <= K; ++k) {
      P qk;
      if (guess && static_cast<int>(guess->size()) == K + 1 && k > 0 && k < K) {
        qk = (*guess)[static_cast<std::size_t>(k)];
      } else {
        const double t = static_cast<double>(k) / K;
        qk = (1.0 - t) * qa + t * qb;
        for (int j = 0; j < spheres; ++j) {
          if (!(qk.template segment<3>(3 * j).norm() > 0.0))
            throw std::invalid_argument("boundary-value problem: antipodal end points (every great circle joins "
                                        "them; the starting path passes through the centre)");
          qk.template segment<3>(3 * j).normalize();
        }
      }
      for (int i = 0; i < S; ++i) node(k)[i] = qk[i];
    }
    ceres::Problem problem;
    for (int k = 1; k < K; ++k) {
      auto* cost = new ceres::AutoDiffCostFunction<DelResidual, S, S, S, S>(new DelResidual{&dl_});
      problem.AddResidualBlock(cost, nullptr, node(k - 1), node(k), node(k + 1));
    }
    for (int k = 1; k < K; ++k) problem.SetManifold(node(k), make_manifold().release());
    problem.SetParameterBlockConstant(node(0));
    problem.SetParameterBlockConstant(node(K));

    const ceres::Solver::Summary summary = solve_del_problem(problem, opt, 1e-16, 1e-16);

    BoundaryValueResult<S> res;
    res.iterations = static_cast<int>(summary.iterations.size());
    res.q.resize(static_cast<std::size_t>(K + 1));
    for (int k = 0; k <= K; ++k)
      for (int i = 0; i < S; ++i) res.q[static_cast<std::size_t>(k)][i] = node(k)[i];
    // momenta p_k = -D1 L_d(q_k, q_{k+1}), p_K = D2 L_d(q_{K-1}, q_K), stored as tangent vectors
    res.p.resize(static_cast<std::size_t>(K + 1));
    double rmax = 0.0, pmax = 0.0;
    for (int k = 0; k < K; ++k) {
      const P& a = res.q[static_cast<std::size_t>(k)];
      const P& b = res.q[static_cast<std::size_t>(k + 1)];
      res.p[static_cast<std::size_t>(k)] =
          M::covector_from_local(a, Vec<double, M::dim>(-dl_.D1_local(a, b, M::relative(a, b))));
      pmax = std::fmax(pmax, max_abs(res.p[static_cast<std::size_t>(k)]));
      if (k >= 1) rmax = std::fmax(rmax, max_abs(del(res.q[static_cast<std::size_t>(k - 1)], a, b)));
    }
    const P& qk1 = res.q[static_cast<std::size_t>(K - 1)];
    res.p[static_cast<std::size_t>(K)] =
        M::covector_from_local(qb, dl_.D2_local(qk1, qb, M::relative(qk1, qb)));
    pmax = std::fmax(pmax, max_abs(res.p[static_cast<std::size_t>(K)]));
    // the momentum carried by a rounding of the nodes (|q| = 1): |M| eps / h, with |M|
    // the largest velocity-Hessian entry, from the Legendre map at the first node
    // (a solve that ended away from any solution, or at non-finite nodes, may leave no
    // velocity there: the run is then reported as not converged, not thrown)
    double W = 0.0;
    std::string degenerate;
    try {
      const P v0 = manifold_legendre_inverse(dl_.lagrangian(), res.q[0], res.p[0]);
      for (int i = 0; i < S; ++i) {
        P e = P::Zero();
        e[i] = 1.0;
        const P t = M::tangent(res.q[0], M::tangent_coordinates(res.q[0], e));
        W = std::fmax(W, max_abs(P(manifold_legendre(dl_.lagrangian(), res.q[0], P(v0 + t)) -
                                   manifold_legendre(dl_.lagrangian(), res.q[0], v0))));
      }
    } catch (const DegenerateLagrangianError& e) {
      W = NAN;
      degenerate = e.what();
    }
    res.max_residual = rmax;
    res.scale = pmax + W / dl_.step();
    res.converged = degenerate.empty() && std::isfinite(rmax) &&
                    rmax <= opt.residual_tolerance * std::fmax(res.scale, 1e-300);
    res.message = summary.BriefReport();
    if (!degenerate.empty())
      res.message = "no velocity at the first node (" + degenerate + "); Ceres: " + res.message;
    else if (!res.converged)
      res.message = "discrete Euler-Lagrange residual " + std::to_string(rmax) + " above tolerance (scale " +
                    std::to_string(res.scale) + "); Ceres: " + res.message;
    return res;
  }

 private:
  static std::unique_ptr<ceres::Manifold> make_manifold() {
    if constexpr (spheres == 1) {
      return std::make_unique<ceres::SphereManifold<3>>();
    } else if constexpr (spheres == 2) {
      return std::make_unique<ceres::ProductManifold<ceres::SphereManifold<3>, ceres::SphereManifold<3>>>(
          ceres::SphereManifold<3>(), ceres::SphereManifold<3>());
    } else {
      static_assert(spheres <= 2, "boundary-value problems on (S^2)^K: K = 1 or 2 for now");
      return nullptr;
    }
  }

  DL dl_;
};

}  // namespace dvm
