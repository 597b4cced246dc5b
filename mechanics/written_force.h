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
// A force may read control inputs u ([system] controls, ControlSignal below): each an
// expression in t, or a table of one value per step. A tabulated control is piecewise
// constant, u_k over the step from t_k to t_{k+1}, whatever substep of a composition
// evaluates the force (some of whose nodes lie outside [t_k, t_{k+1}]): the run sets the
// index k before each step (ControlSignal::set_step), and every force that shares the
// signal reads u_k. Controls follow t in the first block (entries dim() + 1 ...), so
// one gradient call also gives F_u, the Jacobian the step's derivative in u reads.
//
// Workspace is held per object: one object must not be used from two threads at once
// (copies are independent; they share the control signal, which one run advances).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/written_lagrangian.h"

namespace dvm {

// The control inputs of a run, in the order of WrittenSystem::controls, and the step
// the run is at.
class ControlSignal {
 public:
  explicit ControlSignal(std::vector<WrittenSystem::Control> controls) : controls_(std::move(controls)) {}
  int count() const { return static_cast<int>(controls_.size()); }
  // The step that the next evaluations belong to (tabulated controls: u_k for step k).
  void set_step(std::int64_t k) const { step_ = k; }
  std::int64_t step() const { return step_; }
  // u at time t of the current step, into u[0 .. count() - 1].
  void values(double t, double* u) const {
    for (std::size_t j = 0; j < controls_.size(); ++j) {
      const WrittenSystem::Control& c = controls_[j];
      if (c.table.empty()) {
        u[j] = c.expression(&t);
      } else {
        const std::int64_t last = static_cast<std::int64_t>(c.table.size()) - 1;
        u[j] = c.table[static_cast<std::size_t>(std::clamp<std::int64_t>(step_, 0, last))];
      }
    }
  }

 private:
  std::vector<WrittenSystem::Control> controls_;
  mutable std::int64_t step_ = 0;
};

class WrittenForce {
 public:
  // controls: the run's control signal, required where the system declares controls.
  explicit WrittenForce(std::shared_ptr<const WrittenSystem> s, std::shared_ptr<const ControlSignal> controls = nullptr)
      : system_(std::move(s)), controls_(std::move(controls)) {
    if (!system_ || system_->space != WrittenSystem::Space::euclidean)
      throw std::invalid_argument("WrittenForce: forces are written on R^n");
    if (system_->forces.empty()) throw std::invalid_argument("WrittenForce: the system writes no forces");
    const int c = static_cast<int>(system_->controls.size());
    if (c > 0 && (!controls_ || controls_->count() != c))
      throw std::invalid_argument("WrittenForce: the system declares " + std::to_string(c) +
                                  " controls; their signal is needed");
    const int n = system_->dim();
    qt_.setZero(n + 1 + c);
    gq_.resize(n + 1 + c);
    gv_.resize(n);
  }

  int dim() const { return system_->dim(); }
  int controls() const { return static_cast<int>(system_->controls.size()); }
  const ControlSignal* signal() const { return controls_.get(); }

  // F(t, q, v) into F (size dim()).
  template <class Q, class V, class Out>
  void value(double t, const Q& q, const V& v, Out& F) const {
    load(t, q);
    F.setZero();
    for (const auto& [i, e] : system_->forces) F[i] = e(qt_.data(), v.data());
  }

  // F and its Jacobians F_q(i, j) = dF_i/dq_j, F_v(i, j) = dF_i/dv_j (n x n, sized by
  // the caller), and where Fu is given F_u(i, j) = dF_i/du_j (n x controls()).
  template <class Q, class V, class Out, class Mat>
  void jacobian(double t, const Q& q, const V& v, Out& F, Mat& Fq, Mat& Fv, Eigen::MatrixXd* Fu = nullptr) const {
    load(t, q);
    F.setZero();
    Fq.setZero();
    Fv.setZero();
    const int n = dim(), c = controls();
    if (Fu) Fu->setZero(n, c);
    for (const auto& [i, e] : system_->forces) {
      F[i] = e(qt_.data(), v.data());
      gq_.setZero();
      gv_.setZero();
      e.gradient(qt_.data(), v.data(), gq_.data(), gv_.data());
      for (int j = 0; j < n; ++j) {
        Fq(i, j) = gq_[j];
        Fv(i, j) = gv_[j];
      }
      if (Fu)
        for (int j = 0; j < c; ++j) (*Fu)(i, j) = gq_[n + 1 + j];
    }
  }

 private:
  template <class Q>
  void load(double t, const Q& q) const {
    const int n = dim();
    for (int i = 0; i < n; ++i) qt_[i] = q[i];
    qt_[n] = t;
    if (controls_) controls_->values(t, qt_.data() + n + 1);
  }

  std::shared_ptr<const WrittenSystem> system_;
  std::shared_ptr<const ControlSignal> controls_;
  mutable Eigen::VectorXd qt_, gq_, gv_;  // (q, t), and one component's gradient
};

}  // namespace dvm
