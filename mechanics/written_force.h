// A generalized force F(t, q, v) on R^n written in a scene ([system] forces): one
// expression per coordinate that has a component, the others 0. A force that is not
// the gradient of a potential (damping, a drive, friction) enters the discrete
// equations by the discrete Lagrange-d'Alembert principle (Marsden and West, Acta
// Numerica 2001, Sec. 3.2; solvers/dynamic_step.h).
//
// Each component is parsed with WrittenSystem::Kind::force: the coordinates, their
// velocities (name_dot), the time t, the parameters and the definitions. Evaluated in
// doubles; its Jacobians F_q = dF/dq and F_v = dF/dv by reverse mode on each
// component's tape (Expression::gradient), one pass per component. The time sits at
// entry dim() of the first block, so one gradient call also gives dF/dt (unused).
//
// Workspace is held per object: one object must not be used from two threads at once
// (copies are independent).
#pragma once

#include <Eigen/Core>
#include <memory>
#include <stdexcept>
#include <string>

#include "mechanics/written_lagrangian.h"

namespace dvm {

class WrittenForce {
 public:
  explicit WrittenForce(std::shared_ptr<const WrittenSystem> s) : system_(std::move(s)) {
    if (!system_ || system_->space != WrittenSystem::Space::euclidean)
      throw std::invalid_argument("WrittenForce: forces are written on R^n");
    if (system_->forces.empty()) throw std::invalid_argument("WrittenForce: the system writes no forces");
    const int n = system_->dim();
    qt_.setZero(n + 1);
    gq_.resize(n + 1);
    gv_.resize(n);
  }

  int dim() const { return system_->dim(); }

  // F(t, q, v) into F (size dim()).
  template <class Q, class V, class Out>
  void value(double t, const Q& q, const V& v, Out& F) const {
    load(t, q);
    F.setZero();
    for (const auto& [i, e] : system_->forces) F[i] = e(qt_.data(), v.data());
  }

  // F and its Jacobians F_q(i, j) = dF_i/dq_j, F_v(i, j) = dF_i/dv_j (n x n, sized by
  // the caller).
  template <class Q, class V, class Out, class Mat>
  void jacobian(double t, const Q& q, const V& v, Out& F, Mat& Fq, Mat& Fv) const {
    load(t, q);
    F.setZero();
    Fq.setZero();
    Fv.setZero();
    const int n = dim();
    for (const auto& [i, e] : system_->forces) {
      F[i] = e(qt_.data(), v.data());
      gq_.setZero();
      gv_.setZero();
      e.gradient(qt_.data(), v.data(), gq_.data(), gv_.data());
      for (int j = 0; j < n; ++j) {
        Fq(i, j) = gq_[j];
        Fv(i, j) = gv_[j];
      }
    }
  }

 private:
  template <class Q>
  void load(double t, const Q& q) const {
    const int n = dim();
    for (int i = 0; i < n; ++i) qt_[i] = q[i];
    qt_[n] = t;
  }

  std::shared_ptr<const WrittenSystem> system_;
  mutable Eigen::VectorXd qt_, gq_, gv_;  // (q, t), and one component's gradient
};

}  // namespace dvm
