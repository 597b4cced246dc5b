// The N-body Lagrangian of any number of bodies as a run-time-sized system
// (mechanics/dynamic_system.h: the concept; systems_classic.h: NBody<B>, its fixed-size
// form).
#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/nbody_momenta.h"
#include "mechanics/structure.h"
#include "mechanics/systems.h"

namespace dvm {

// ---------------------------------------------------------------------------------
// The N-body Lagrangian of any number of bodies B in R^3 (systems_classic.h, NBody<B>):
//
//   L = sum_i m_i |v_i|^2/2 + sum_{i<j} k_ij / r_ij,   k_ij = G m_i m_j,
//   r_ij = |d|, d = q_i - q_j.
//
// With f = k_ij / r_ij^3: L_{q_i} gets -f d and L_{q_j} gets +f d from the pair; its
// Hessian block is B_ij = f (3 d d^T / r_ij^2 - I), added to (i, i) and (j, j) and
// subtracted from (i, j) and (j, i). L_qv = 0, L_vv = diag(m_i I_3), v_i = p_i / m_i.
class NBodyDynamic {
 public:
  static constexpr Structure structure = Structure::separable;
  double G = 1.0;
  std::vector<double> mass;

  NBodyDynamic(double G_, std::vector<double> masses) : G(G_), mass(std::move(masses)) {
    if (mass.empty()) throw std::invalid_argument("nbody: at least one body is needed");
    if (!std::isfinite(G) || G < 0) throw std::invalid_argument("nbody: parameter G must be finite and >= 0");
    for (double m : mass) detail::require_positive("nbody", "mass", m);
  }
  std::string name() const { return "nbody"; }
  int bodies() const { return static_cast<int>(mass.size()); }
  int dim() const { return 3 * bodies(); }
  double m(int i) const { return mass[static_cast<std::size_t>(i)]; }

  double value(const DynIn& q, const DynIn& v) const {
    const int B = bodies();
    double kin = 0.0, pot = 0.0;
    for (int i = 0; i < B; ++i)
      kin += m(i) * (v[3 * i] * v[3 * i] + v[3 * i + 1] * v[3 * i + 1] + v[3 * i + 2] * v[3 * i + 2]);
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        const double dx = q[3 * i] - q[3 * j], dy = q[3 * i + 1] - q[3 * j + 1], dz = q[3 * i + 2] - q[3 * j + 2];
        pot += (G * m(i) * m(j)) / std::sqrt(dx * dx + dy * dy + dz * dz);
      }
    return 0.5 * kin + pot;
  }

  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const {
    const int B = bodies();
    Lq.setZero();
    for (int i = 0; i < B; ++i)
      for (int a = 0; a < 3; ++a) Lv[3 * i + a] = m(i) * v[3 * i + a];
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        double d[3];
        for (int a = 0; a < 3; ++a) d[a] = q[3 * i + a] - q[3 * j + a];
        const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const double f = (G * m(i) * m(j)) / (r2 * std::sqrt(r2));
        for (int a = 0; a < 3; ++a) {
          const double fa = f * d[a];
          Lq[3 * i + a] -= fa;
          Lq[3 * j + a] += fa;
        }
      }
  }

  void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
               DynMatOut Lvv) const {
    const int B = bodies();
    Lq.setZero();
    Lqq.setZero();
    Lqv.setZero();
    Lvv.setZero();
    for (int i = 0; i < B; ++i)
      for (int a = 0; a < 3; ++a) {
        Lv[3 * i + a] = m(i) * v[3 * i + a];
        Lvv(3 * i + a, 3 * i + a) = m(i);
      }
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        double d[3];
        for (int a = 0; a < 3; ++a) d[a] = q[3 * i + a] - q[3 * j + a];
        const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const double f = (G * m(i) * m(j)) / (r2 * std::sqrt(r2));
        const double g = 3.0 * f / r2;
        for (int a = 0; a < 3; ++a) {
          const double fa = f * d[a];
          Lq[3 * i + a] -= fa;
          Lq[3 * j + a] += fa;
          for (int b = 0; b < 3; ++b) {
            const double Bab = g * d[a] * d[b] - (a == b ? f : 0.0);
            Lqq(3 * i + a, 3 * i + b) += Bab;
            Lqq(3 * j + a, 3 * j + b) += Bab;
            Lqq(3 * i + a, 3 * j + b) -= Bab;
            Lqq(3 * j + a, 3 * i + b) -= Bab;
          }
        }
      }
  }

  void velocity(const DynIn&, const DynIn& p, DynOut v) const {
    for (int i = 0; i < bodies(); ++i)
      for (int a = 0; a < 3; ++a) v[3 * i + a] = p[3 * i + a] / m(i);
  }

  // Total momentum (3) and total angular momentum (3) (mechanics/nbody_momenta.h).
  static std::array<double, 6> momenta(const DynIn& q, const DynIn& p) {
    return nbody_momenta(q.data(), p.data(), static_cast<int>(q.size() / 3));
  }
};

}  // namespace dvm
