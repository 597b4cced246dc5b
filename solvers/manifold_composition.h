// Composition methods on manifolds: Psi_h = Phi_{gamma_s h} o ... o Phi_{gamma_1 h}
// with Phi the position-momentum step of a map on S^2, (S^2)^n or SO(3) (paper Sec. 6;
// the tables of solvers/composition_methods.h). A map that is not symmetric enters
// with its adjoint, the map of the same retraction with theta replaced by 1 - theta
// (Prop. 2.4), exactly as on R^n (solvers/composition.h). Each substep is a full
// manifold step, so the composition stays on the manifold and keeps the symmetries
// of its stages (discrete Noether holds stage by stage).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "solvers/composition_methods.h"
#include "solvers/newton.h"

namespace dvm {

// Any manifold step type `Stage` (the contract of integrate on a manifold: M, n, Point,
// Covector, step_size(), step(q0, p0, xi, q1, p1)), composed: make_plain(hk) and
// make_dual(hk) build the stage of size hk of the basic method and of its adjoint.
// This is how the Hamiltonian step of a manifold map composes as the
// position-momentum step does.
template <class Stage>
class ComposedPointStep {
 public:
  using M = typename Stage::M;
  static constexpr int n = Stage::n;
  using Point = typename Stage::Point;
  using Covector = typename Stage::Covector;

  template <class MakePlain, class MakeDual>
  ComposedPointStep(double h, const std::vector<Substep>& substeps, const MakePlain& make_plain,
                    const MakeDual& make_dual)
      : h_(h) {
    if (substeps.empty()) throw std::invalid_argument("a composition needs at least one substep");
    for (const Substep& s : substeps) {
      if (!(s.weight != 0.0) || !std::isfinite(s.weight))
        throw std::invalid_argument("composition substeps must have nonzero finite weights");
      weights_.push_back(s.weight);
      stages_.push_back(s.adjoint ? make_dual(s.weight * h) : make_plain(s.weight * h));
    }
  }
  double step_size() const { return h_; }
  std::size_t stages() const { return stages_.size(); }

  // The same contract as ManifoldStep::step; xi (the full step's chart coordinates at
  // q0) seeds each stage's guess with its fraction of the step.
  StepSummary step(double t, const Point& q0, const Covector& p0, Vec<double, n>& xi, Point& q1, Covector& p1) const {
    double elapsed = 0.0;  // the weights of the stages done
    Point q = q0;
    Covector p = p0;
    StepSummary total;
    total.converged = true;
    total.residual = 0.0;
    total.scale = 0.0;
    for (std::size_t i = 0; i < stages_.size(); ++i) {
      Vec<double, n> guess = weights_[i] * xi;
      Point qn;
      Covector pn;
      const StepSummary s = stages_[i].step(t + elapsed * h_, q, p, guess, qn, pn);
      total.iterations += s.iterations;
      total.jacobians += s.jacobians;
      total.work += s.work;  // (a force's work, summed over the substeps)
      if (!s.converged) {
        total = s;
        if (stages_.size() > 1)  // (one stage: the step itself, a runtime's composition "none")
          total.message = "substep " + std::to_string(i + 1) + " of " + std::to_string(stages_.size()) + ": " + s.message;
        return total;
      }
      if (s.residual / s.scale > total.residual / std::fmax(total.scale, 1e-300)) {
        total.residual = s.residual;
        total.scale = s.scale;
      }
      q = qn;
      p = pn;
      elapsed += weights_[i];
    }
    q1 = q;
    p1 = p;
    return total;
  }

  // The controls the stages' force reads (where the stage type says).
  template <class S = Stage, class = decltype(std::declval<const S&>().controls())>
  int controls() const {
    return stages_.front().controls();
  }

  // The derivative of the whole step from (q0, p0) at time t to its end q1, in the
  // canonical coordinates around q0 and q1 (ManifoldStep::derivatives): the product
  // A_s ... A_1 of the stages' derivatives, each in the canonical coordinates around its
  // own ends, at the stage states found again by solving the stages from (q0, p0) (the
  // stages keep no state between steps); with B, u held over the step, the sum of
  // A_s ... A_{k+1} B_k. False where a stage fails or its derivative does not exist.
  template <class S = Stage,
            class = decltype(std::declval<const S&>().derivatives(0.0, std::declval<const Point&>(),
                                                                  std::declval<const Covector&>(),
                                                                  std::declval<const Point&>(),
                                                                  std::declval<Eigen::MatrixXd&>(), nullptr))>
  bool derivatives(double t, const Point& q0, const Covector& p0, const Point& q1, Eigen::MatrixXd& A,
                   Eigen::MatrixXd* B = nullptr) const {
    if (stages_.size() == 1) return stages_.front().derivatives(t, q0, p0, q1, A, B);
    Vec<double, n> xi;
    try {
      xi = M::chart_inverse(q0, q1);
    } catch (const std::domain_error&) {
      return false;
    }
    double elapsed = 0.0;
    Point q = q0;
    Covector p = p0;
    A = Eigen::MatrixXd::Identity(2 * n, 2 * n);
    if (B) B->resize(2 * n, 0);
    Eigen::MatrixXd Ak, Bk;
    for (std::size_t i = 0; i < stages_.size(); ++i) {
      Vec<double, n> guess = weights_[i] * xi;
      Point qn;
      Covector pn;
      const double ti = t + elapsed * h_;
      if (!stages_[i].step(ti, q, p, guess, qn, pn).converged) return false;
      if (!stages_[i].derivatives(ti, q, p, qn, Ak, B ? &Bk : nullptr)) return false;
      if (B) {
        if (B->cols() == 0) B->setZero(2 * n, Bk.cols());
        *B = Ak * *B + Bk;
      }
      A = Ak * A;
      q = qn;
      p = pn;
      elapsed += weights_[i];
    }
    return true;
  }

 private:
  double h_;
  std::vector<double> weights_;
  std::vector<Stage> stages_;
};

}  // namespace dvm
