// Checks of the identities every discretization map must satisfy, usable on any map
// (built-in or a user's). Each check returns the largest residual over a set of
// sample points; a correct map gives residuals at round-off level (about 1e-15 for
// data of size one), a wrong one gives residuals of the size of its error.
//
//   zero_section            R_d(x, 0) = (x, x)                          (Def. 2.2 i)
//   tangent_identity        d/dv R^2(x, 0) - d/dv R^1(x, 0) = Id         (Def. 2.2 ii)
//   inverse_round_trip      R_d^{-1}(R_d(x, v)) = (x, v) and R_d(R_d^{-1}(q0, q1)) = (q0, q1)
//   adjoint_involution      (R_d^*)^* = R_d                              (Prop. 2.4)
//   adjoint_difference      |R_d^* - R_d|: zero exactly for a symmetric map; a map that
//                           claims to be symmetric must show zero, one that does not must
//                           show a clearly non-zero value (claims are checked both ways)
//   tangent_lift_*          the tangent lift R_d^T is a discretization map on TQ: its
//                           zero section, identity and round trip        (Prop. 3.2)
//   cotangent_symplectic    |M^T Omega_12 M - W| with M the Jacobian of R_d^{T*} and W
//                           the matrix of d_T w_Q                         (Prop. 3.4)
//   cotangent_round_trip    (R_d^{T*})^{-1} o R_d^{T*} = Id                (Eq. 3.6)
#pragma once

#include <random>
#include <string>
#include <vector>

#include "core/map_operations.h"

namespace dvm {

struct CheckEntry {
  std::string name;
  double residual;
};

struct MapCheckReport {
  std::string map_name;
  int dimension = 0;
  bool claims_symmetric = false;
  std::vector<CheckEntry> entries;

  double residual(const std::string& name) const {
    for (const auto& e : entries)
      if (e.name == name) return e.residual;
    throw std::out_of_range("no check named " + name);
  }
};

// The identities that must hold to round-off for every map (everything but
// adjoint_difference, whose expected value depends on the symmetry claim).
inline std::vector<std::string> identity_names() {
  return {"zero_section",
          "tangent_identity",
          "inverse_round_trip",
          "adjoint_involution",
          "tangent_lift_zero_section",
          "tangent_lift_identity",
          "tangent_lift_round_trip",
          "cotangent_symplectic",
          "cotangent_round_trip"};
}

namespace detail {

template <class M, int N>
double zero_section(const M& map, const Vec<double, N>& x) {
  const PointPair<double, N> r = map(x, Vec<double, N>::Zero().eval());
  return std::fmax(max_abs(r.q0 - x), max_abs(r.q1 - x));
}

template <class M, int N>
double tangent_identity(const M& map, const Vec<double, N>& x) {
  Mat<double, 2 * N, 2 * N> J;
  map_with_jacobian(map, x, Vec<double, N>::Zero().eval(), J);
  const Mat<double, N, N> D = J.template block<N, N>(N, N) - J.template block<N, N>(0, N);
  return max_abs(D - Mat<double, N, N>::Identity());
}

template <class M, int N>
double round_trip(const M& map, const Vec<double, N>& x, const Vec<double, N>& v) {
  const PointPair<double, N> r = map(x, v);
  const TangentPoint<double, N> t = inverse(map, r.q0, r.q1);
  double res = std::fmax(max_abs(t.x - x), max_abs(t.v - v));
  // and the other way round, from a pair of nearby points
  const Vec<double, N> q0 = x, q1 = x + 0.5 * v;
  const TangentPoint<double, N> s = inverse(map, q0, q1);
  const PointPair<double, N> back = map(s.x, s.v);
  return std::fmax(res, std::fmax(max_abs(back.q0 - q0), max_abs(back.q1 - q1)));
}

template <class A, class B, int N>
double map_distance(const A& a, const B& b, const Vec<double, N>& x, const Vec<double, N>& v) {
  const PointPair<double, N> ra = a(x, v), rb = b(x, v);
  return std::fmax(max_abs(ra.q0 - rb.q0), max_abs(ra.q1 - rb.q1));
}

// |M^T Omega_12 M - W| for the Jacobian M of the cotangent lift at z = (q, p, qdot, pdot).
template <class M, int N>
double cotangent_symplectic(const M& map, const Vec<double, 4 * N>& z) {
  using D = ceres::Jet<double, 4 * N>;
  Vec<D, N> q, p, qd, pd;
  for (int i = 0; i < N; ++i) {
    q[i] = seed<double, 4 * N>(z[i], i);
    p[i] = seed<double, 4 * N>(z[N + i], N + i);
    qd[i] = seed<double, 4 * N>(z[2 * N + i], 2 * N + i);
    pd[i] = seed<double, 4 * N>(z[3 * N + i], 3 * N + i);
  }
  const CotangentPair<D, N> out = cotangent_lift(map, q, p, qd, pd);
  Mat<double, 4 * N, 4 * N> Jm;
  for (int i = 0; i < N; ++i) {
    Jm.row(i) = out.q0[i].v.transpose();
    Jm.row(N + i) = out.p0[i].v.transpose();
    Jm.row(2 * N + i) = out.q1[i].v.transpose();
    Jm.row(3 * N + i) = out.p1[i].v.transpose();
  }
  // Omega_12 = dq1 ^ dp1 - dq0 ^ dp0 on (q0, p0, q1, p1).
  Mat<double, 4 * N, 4 * N> Omega = Mat<double, 4 * N, 4 * N>::Zero();
  const Mat<double, N, N> I = Mat<double, N, N>::Identity();
  Omega.template block<N, N>(0, N) = -I;
  Omega.template block<N, N>(N, 0) = I;
  Omega.template block<N, N>(2 * N, 3 * N) = I;
  Omega.template block<N, N>(3 * N, 2 * N) = -I;
  // d_T w_Q = dq ^ dpdot + dqdot ^ dp on (q, p, qdot, pdot).
  Mat<double, 4 * N, 4 * N> W = Mat<double, 4 * N, 4 * N>::Zero();
  W.template block<N, N>(0, 3 * N) = I;
  W.template block<N, N>(3 * N, 0) = -I;
  W.template block<N, N>(2 * N, N) = I;
  W.template block<N, N>(N, 2 * N) = -I;
  return max_abs(Jm.transpose() * Omega * Jm - W);
}

template <class M, int N>
double cotangent_round_trip(const M& map, const Vec<double, 4 * N>& z) {
  const Vec<double, N> q = z.template segment<N>(0), p = z.template segment<N>(N),
                       qd = z.template segment<N>(2 * N), pd = z.template segment<N>(3 * N);
  const CotangentPair<double, N> c = cotangent_lift(map, q, p, qd, pd);
  const CotangentVelocity<double, N> back = cotangent_lift_inverse(map, c.q0, c.p0, c.q1, c.p1);
  return std::fmax(std::fmax(max_abs(back.q - q), max_abs(back.p - p)),
                   std::fmax(max_abs(back.qdot - qd), max_abs(back.pdot - pd)));
}

}  // namespace detail

// Runs every check at `samples` random points with coordinates in [-1, 1] and
// velocities in [-velocity_scale, velocity_scale].
template <int N, class M>
MapCheckReport check_map(const M& map, int samples = 16, double velocity_scale = 0.5, unsigned seed = 12345) {
  static_assert(N >= 1 && N != Eigen::Dynamic, "check_map needs a fixed dimension");
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  auto rand_vec = [&](auto& v, double s) {
    for (int i = 0; i < v.rows(); ++i) v[i] = s * U(rng);
  };
  MapCheckReport report;
  report.map_name = map.name();
  report.dimension = N;
  report.claims_symmetric = map.symmetric();
  double zs = 0, ti = 0, rt = 0, ai = 0, ad = 0, tz = 0, tt = 0, tr = 0, cs = 0, cr = 0;
  const auto adj = adjoint(map);
  const auto adj2 = adjoint(adj);
  const auto lift = tangent_lift(map);
  for (int s = 0; s < samples; ++s) {
    Vec<double, N> x, v;
    rand_vec(x, 1.0);
    rand_vec(v, velocity_scale);
    zs = std::fmax(zs, detail::zero_section(map, x));
    ti = std::fmax(ti, detail::tangent_identity(map, x));
    rt = std::fmax(rt, detail::round_trip(map, x, v));
    ai = std::fmax(ai, detail::map_distance(adj2, map, x, v));
    ad = std::fmax(ad, detail::map_distance(adj, map, x, v));
    Vec<double, 2 * N> X, V;
    rand_vec(X, 1.0);
    rand_vec(V, velocity_scale);
    tz = std::fmax(tz, detail::zero_section(lift, X));
    tt = std::fmax(tt, detail::tangent_identity(lift, X));
    tr = std::fmax(tr, detail::round_trip(lift, X, V));
    Vec<double, 4 * N> z;
    rand_vec(z, 1.0);
    z.template tail<2 * N>() *= velocity_scale;
    cs = std::fmax(cs, detail::cotangent_symplectic<M, N>(map, z));
    cr = std::fmax(cr, detail::cotangent_round_trip<M, N>(map, z));
  }
  report.entries = {{"zero_section", zs},
                    {"tangent_identity", ti},
                    {"inverse_round_trip", rt},
                    {"adjoint_involution", ai},
                    {"adjoint_difference", ad},
                    {"tangent_lift_zero_section", tz},
                    {"tangent_lift_identity", tt},
                    {"tangent_lift_round_trip", tr},
                    {"cotangent_symplectic", cs},
                    {"cotangent_round_trip", cr}};
  return report;
}

// True when every identity is below tol and the symmetry claim matches what the
// adjoint shows (zero for a symmetric map, above `asymmetry_floor` otherwise).
inline bool report_passes(const MapCheckReport& r, double tol = 1e-12, double asymmetry_floor = 1e-6) {
  for (const auto& name : identity_names())
    if (!(r.residual(name) <= tol)) return false;
  const double ad = r.residual("adjoint_difference");
  return r.claims_symmetric ? ad <= tol : ad > asymmetry_floor;
}

}  // namespace dvm
