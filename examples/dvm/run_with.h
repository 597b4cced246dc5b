// The templated run behind `dvm run` and `dvm converge`, shared by the translation
// units that instantiate it for their systems (run.cc: the original built-ins;
// run_classic.cc, run_nbody.cc, run_written.cc). The system and map are resolved
// once per run into one instantiation; the loop has no runtime dispatch.
//
// A run writes its rows (t, q0.., p0.., energy; every k-th step and the last) to CSV
// and/or NumPy .npy, shows progress on stderr when stderr is a terminal, and ends
// with a summary (a table, or JSON with --json). Invariants monitored besides the
// energy: the momenta a symmetry conserves (angular momentum of Kepler and of the
// charged particle, total momentum and angular momentum of N bodies, the momentum of
// a cyclic coordinate of a written Lagrangian) and FPU's oscillatory energy.
#pragma once

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/SVD>

#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"
#include "examples/dvm/output.h"
#include "examples/dvm/report.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/composition.h"
#include "solvers/galerkin_step.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"

namespace dvm::cli {

namespace run_detail {


template <int N>
Vec<double, N> to_vec(const std::vector<double>& x) {
  Vec<double, N> v;
  for (int i = 0; i < N; ++i) v[i] = x[static_cast<std::size_t>(i)];
  return v;
}
template <int N>
std::vector<double> to_std(const Vec<double, N>& x) {
  return std::vector<double>(x.data(), x.data() + N);
}

// ---- invariants besides the energy: names once, values per step (no allocation)
constexpr int kMaxInvariants = 8;

template <class S>
std::vector<std::string> invariant_names(const S&) {
  return {};
}
template <class S, int N>
void invariants(const S&, const Vec<double, N>&, const Vec<double, N>&, double*) {}

inline std::vector<std::string> invariant_names(const Kepler&) { return {"angular momentum"}; }
inline void invariants(const Kepler&, const Vec<double, 2>& q, const Vec<double, 2>& p, double* out) {
  out[0] = Kepler::angular_momentum(q, p);
}
inline std::vector<std::string> invariant_names(const ChargedParticle&) { return {"angular momentum"}; }
inline void invariants(const ChargedParticle&, const Vec<double, 2>& q, const Vec<double, 2>& p, double* out) {
  out[0] = ChargedParticle::angular_momentum(q, p);
}
inline std::vector<std::string> invariant_names(const FermiPastaUlam&) {
  return {"oscillatory energy (adiabatic, O(1/omega))"};
}
inline void invariants(const FermiPastaUlam& F, const Vec<double, 6>& q, const Vec<double, 6>& p, double* out) {
  out[0] = F.oscillatory_energy(q, p);
}
template <int B>
std::vector<std::string> invariant_names(const NBody<B>&) {
  return {"momentum x", "momentum y", "momentum z", "angular momentum x", "angular momentum y", "angular momentum z"};
}
template <int B>
void invariants(const NBody<B>&, const Vec<double, 3 * B>& q, const Vec<double, 3 * B>& p, double* out) {
  const auto m = NBody<B>::momenta(q, p);
  for (int i = 0; i < 6; ++i) out[i] = m[static_cast<std::size_t>(i)];
}
template <int N>
std::vector<std::string> invariant_names(const WrittenLagrangian<N>& L) {
  std::vector<std::string> out;
  for (int i = 0; i < N && static_cast<int>(out.size()) < kMaxInvariants; ++i)
    if (L.cyclic(i)) out.push_back("p_" + L.system->coordinates[static_cast<std::size_t>(i)] + " (cyclic)");
  return out;
}
template <int N>
void invariants(const WrittenLagrangian<N>& L, const Vec<double, N>& q, const Vec<double, N>& p, double* out) {
  (void)q;
  int k = 0;
  for (int i = 0; i < N && k < kMaxInvariants; ++i)
    if (L.cyclic(i)) out[k++] = p[i];
}

// ---- energy: a written energy if the scene gives one, else E_L
template <class S, int N>
double monitored_energy(const S& L, const Vec<double, N>& q, const Vec<double, N>& v, const Vec<double, N>&) {
  return energy(L, q, v);
}
template <int N>
double monitored_energy(const WrittenLagrangian<N>& L, const Vec<double, N>& q, const Vec<double, N>& v,
                        const Vec<double, N>& p) {
  return L.energy_at(q, v, p);
}

// ---- exact solutions, where a system has one
template <class S, class = void>
struct has_exact_member : std::false_type {};
template <class S>
struct has_exact_member<S, std::void_t<decltype(std::declval<const S&>().exact(
                               0.0, std::declval<const Vec<double, S::dim>&>(),
                               std::declval<const Vec<double, S::dim>&>(), std::declval<Vec<double, S::dim>&>(),
                               std::declval<Vec<double, S::dim>&>()))>> : std::true_type {};
template <class S>
bool exact_available(const S& L) {
  if constexpr (!has_exact_member<S>::value) {
    (void)L;
    return false;
  } else if constexpr (std::is_same_v<S, Duffing> || std::is_same_v<S, ChargedParticle>) {
    return L.has_exact();
  } else {
    return true;
  }
}

// ---- NumPy .npy writer (format version 1.0): a little-endian float64 2-D array.
// The header holds the shape, unknown until the end: it is written with room to
// spare and rewritten before the file is finished (output.h: written under a
// temporary name and renamed at the end).
class NpyWriter {
 public:
  void open(const std::string& path, const std::string& what, double rows, int cols) {
    file_.open(path, what, npy_bytes(rows, cols));
    cols_ = cols;
    write_header();
  }
  explicit operator bool() const { return static_cast<bool>(file_); }
  void row(const double* x) {
    std::fwrite(x, sizeof(double), static_cast<std::size_t>(cols_), file_.get());
    ++rows_;
  }
  // The header with the final row count; then the file is ready for finish_outputs.
  OutputFile& file() {
    if (file_) {
      std::fseek(file_.get(), 0, SEEK_SET);
      write_header();
    }
    return file_;
  }

 private:
  void write_header() {
    // magic, version 1.0, header length (little endian), then a Python dict literal
    // padded with spaces to a 16-byte-aligned total of 128 bytes, ending in '\n'.
    char dict[128];
    std::snprintf(dict, sizeof dict, "{'descr': '<f8', 'fortran_order': False, 'shape': (%20lld, %d), }",
                  static_cast<long long>(rows_), cols_);
    std::string h(dict);
    const std::size_t total = 128, len = total - 10;
    h.resize(len - 1, ' ');
    h += '\n';
    const unsigned char pre[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, static_cast<unsigned char>(len & 0xff),
                                   static_cast<unsigned char>(len >> 8)};
    std::fwrite(pre, 1, 10, file_.get());
    std::fwrite(h.data(), 1, h.size(), file_.get());
  }
  OutputFile file_;
  int cols_ = 0;
  long long rows_ = 0;
};

// ---- progress on stderr, only when stderr is a terminal
class Progress {
 public:
  Progress(bool enabled, std::int64_t total, double h)
      : on_(enabled && isatty(fileno(stderr))), total_(total), h_(h), start_(std::chrono::steady_clock::now()),
        last_(start_) {}
  void update(std::int64_t k) {
    if (!on_ || (k & 1023) != 0) return;
    const auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_).count() < 0.25) return;
    last_ = now;
    const double el = std::chrono::duration<double>(now - start_).count();
    const double rate = static_cast<double>(k) / el;
    const double left = static_cast<double>(total_ - k) / rate;
    std::fprintf(stderr, "\r  step %lld/%lld  t = %.6g  %.3g steps/s  %.0f s left   ", static_cast<long long>(k),
                 static_cast<long long>(total_), static_cast<double>(k) * h_, rate, left);
    std::fflush(stderr);
    shown_ = true;
  }
  ~Progress() {
    if (shown_) std::fprintf(stderr, "\r%*s\r", 78, "");
  }

 private:
  bool on_;
  std::int64_t total_;
  double h_;
  std::chrono::steady_clock::time_point start_, last_;
  bool shown_ = false;
};

template <class System>
StepOptions step_options(const Scene& s) {
  StepOptions opt;
  opt.solver = s.solver == "tiny" ? SolverKind::tiny : SolverKind::newton;
  opt.max_iterations = s.max_iterations;
  opt.residual_tolerance = s.tolerance;
  opt.accept_tolerance = std::fmax(opt.accept_tolerance, s.tolerance);
  return opt;
}

// The initial state (q, p, v) of a scene; rejects a Lagrangian that is degenerate
// there (singular velocity Hessian) and a written Hamiltonian that disagrees with
// the Legendre transform of L.
template <class System>
void initial_state(const Scene& s, const System& L, Vec<double, System::dim>& q, Vec<double, System::dim>& p,
                   Vec<double, System::dim>& v0) {
  constexpr int N = System::dim;
  q = to_vec<N>(s.q);
  const std::string where = s.written ? s.written_where : s.path;
  if constexpr (!has_velocity<System>::value) {
    // no closed-form inverse Legendre map: the velocity Hessian must be invertible
    auto check = [&](const Vec<double, N>& v) {
      const Mat<double, N, N> H = velocity_hessian(L, q, v);
      const Eigen::MatrixXd Hd = H;  // dynamic size: the fixed 1x1 SVD trips GCC's uninitialised warnings
      Eigen::JacobiSVD<Eigen::MatrixXd> svd(Hd);
      const auto sv = svd.singularValues();
      const double smax = sv.maxCoeff(), smin = sv.minCoeff();
      if (!(smin > 1e-12 * smax) || !std::isfinite(smax)) {
        std::ostringstream m;
        m << where << ": the Lagrangian is degenerate at the initial state: the velocity Hessian d2L/dv2 is "
          << "singular there (singular values from " << smax << " down to " << smin
          << "), so the Legendre transform cannot be inverted and the discrete equations do not define a step";
        throw InputError(m.str());
      }
    };
    if (s.momentum_given) {
      check(Vec<double, N>::Zero());
      try {
        v0 = legendre_inverse(L, q, to_vec<N>(s.p));
      } catch (const DegenerateLagrangianError& e) {
        throw InputError(where + ": the Lagrangian is degenerate at the initial state: " + e.what());
      }
    } else {
      v0 = to_vec<N>(s.v);
    }
    check(v0);
  } else {
    if (s.momentum_given) v0 = legendre_inverse(L, q, to_vec<N>(s.p));
  }
  if (s.momentum_given) {
    p = to_vec<N>(s.p);
  } else {
    v0 = to_vec<N>(s.v);
    p = legendre(L, q, v0);
  }
  if constexpr (std::is_same_v<System, WrittenLagrangian<N>>) {
    if (L.has_hamiltonian()) {
      const double H = L.hamiltonian(q, p), E = energy(L, q, v0);
      if (!(std::fabs(H - E) <= 1e-9 * std::fmax(1.0, std::fabs(E)))) {
        std::ostringstream m;
        m.precision(17);
        m << s.hamiltonian_where << ": system.hamiltonian does not match the Legendre transform of the Lagrangian at the "
          << "initial state: H(q, p) = " << H << " but E_L(q, v) = <p, v> - L = " << E;
        throw InputError(m.str());
      }
    }
  }
}

// ---- the method a scene names: the map's own step (possibly composed) or Galerkin
inline bool is_galerkin(const Scene& s) { return s.method == "galerkin"; }
inline QuadratureKind quadrature_kind(const Scene& s) {
  return s.quadrature == "lobatto" ? QuadratureKind::lobatto : QuadratureKind::gauss;
}
template <class Map>
std::string method_label(const Scene& s, const Map& R) {
  if (is_galerkin(s))
    return "galerkin " + s.quadrature + " s=" + std::to_string(s.stages) + " (order " + std::to_string(2 * s.stages) +
           ")";
  return R.name();
}

// ---- `dvm converge`: the error at t_end against a reference, for several steps
template <class System>
void reference_solution(const System& L, double t_end, std::int64_t steps, Vec<double, System::dim>& q,
                        Vec<double, System::dim>& p) {
  // Classical Runge-Kutta 4 on Hamilton's equations derived from L,
  //   dq/dt = v(q, p) (inverse Legendre),  dp/dt = dL/dq(q, v),
  // with compensated sums: an integrator independent of the variational one.
  constexpr int N = System::dim;
  using V = Vec<double, N>;
  const double h = t_end / static_cast<double>(steps);
  auto f = [&](const V& x, const V& y, V& dx, V& dy) {
    dx = legendre_inverse(L, x, y, dx);
    V g, b;
    lagrangian_gradient(L, x, dx, g, b);
    dy = g;
  };
  CompensatedVector<N> Q(q), P(p);
  V k1q = V::Zero(), k1p, k2q = V::Zero(), k2p, k3q = V::Zero(), k3p, k4q = V::Zero(), k4p;
  for (std::int64_t i = 0; i < steps; ++i) {
    const V q0 = Q.sum, p0 = P.sum;
    f(q0, p0, k1q, k1p);
    f(q0 + 0.5 * h * k1q, p0 + 0.5 * h * k1p, k2q, k2p);
    f(q0 + 0.5 * h * k2q, p0 + 0.5 * h * k2p, k3q, k3p);
    f(q0 + h * k3q, p0 + h * k3p, k4q, k4p);
    Q.add(V((h / 6.0) * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)));
    P.add(V((h / 6.0) * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)));
  }
  q = Q.sum;
  p = P.sum;
}

template <class System, class Map>
int converge_with(const Scene& s, const System& L, const Map& R, const RunOptions& o) {
  constexpr int N = System::dim;
  using V = Vec<double, N>;
  V q0, p0, v0;
  initial_state(s, L, q0, p0, v0);
  const double T = o.t_end > 0.0 ? o.t_end : static_cast<double>(s.steps) * s.step;
  std::vector<std::int64_t> list = o.steps_list;
  if (list.empty()) {
    const std::int64_t n0 = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::llround(T / s.step)));
    list = {n0, 2 * n0, 4 * n0, 8 * n0};
  }
  V qr = q0, pr = p0;
  std::string reference;
  if (exact_available(L)) {
    if constexpr (has_exact_member<System>::value) L.exact(T, q0, p0, qr, pr);
    reference = "exact solution";
  } else {
    std::int64_t nmax = 0;
    for (auto n : list) nmax = std::max(nmax, n);
    const std::int64_t nref = 16 * nmax;
    reference_solution(L, T, nref, qr, pr);
    reference = "RK4 with " + std::to_string(nref) + " steps";
  }
  const double scale = std::fmax(max_abs(qr), max_abs(pr));
  const StepOptions opt = step_options<System>(s);
  std::vector<double> hs, errs;
  std::vector<std::int64_t> iters;
  std::string first_failure;
  for (auto n : list) {
    const double h = T / static_cast<double>(n);
    V q = q0, p = p0;
    const RunSummary run =
        is_galerkin(s)
            ? integrate(GalerkinStep<System>(L, quadrature_kind(s), s.stages, h, opt), 0.0, q, p, v0, n,
                        [](auto&&...) {})
            : integrate(PositionMomentumStep<System, Map>(L, R, h, opt), 0.0, q, p, v0, n, [](auto&&...) {});
    hs.push_back(h);
    errs.push_back(run.failed ? NAN : std::fmax(max_abs(q - qr), max_abs(p - pr)));
    iters.push_back(run.solver_iterations);
    if (run.failed && first_failure.empty()) {
      std::ostringstream m;
      m.precision(17);
      m << "the run with " << n << " steps (h = " << h << ") failed at step " << run.failed_step
        << " (t = " << run.failed_time << "): " << run.failure.message << " (residual " << run.failure.residual
        << ")";
      first_failure = m.str();
    }
  }
  // orders between neighbours, and a least-squares fit above the round-off plateau
  std::vector<double> orders(hs.size(), NAN);
  for (std::size_t i = 1; i < hs.size(); ++i)
    orders[i] = std::log(errs[i - 1] / errs[i]) / std::log(hs[i - 1] / hs[i]);
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int used = 0;
  for (std::size_t i = 0; i < hs.size(); ++i) {
    if (!(errs[i] > 1e-12 * std::fmax(1.0, scale))) continue;
    const double x = std::log(hs[i]), y = std::log(errs[i]);
    sx += x, sy += y, sxx += x * x, sxy += x * y;
    ++used;
  }
  const double fit = used >= 2 ? (used * sxy - sx * sy) / (used * sxx - sx * sx) : NAN;
  if (o.json) {
    Json::Object j;
    j.str("system", L.name()).str("map", is_galerkin(s) ? std::string("none") : R.name()).num("t_end", T).str("reference", reference);
    if (is_galerkin(s)) j.str("method", "galerkin").num("stages", s.stages).str("quadrature", s.quadrature);
    std::string rows = "[\n";
    for (std::size_t i = 0; i < hs.size(); ++i) {
      Json::Object r;
      r.num("steps", static_cast<double>(list[i])).num("h", hs[i]).num("error", errs[i]).num("order", orders[i]);
      rows += "    " + r.dump(6) + (i + 1 < hs.size() ? ",\n" : "\n");
    }
    j.raw("runs", rows + "  ]").num("fitted_order", fit).num("map_order", is_galerkin(s) ? 2 * s.stages : R.order());
    std::cout << j.dump() << "\n";
  } else {
    std::printf("%s with %s to t = %g; reference: %s\n", L.name().c_str(), method_label(s, R).c_str(), T,
                reference.c_str());
    std::printf("  %12s %14s %14s %8s %12s\n", "steps", "h", "error", "order", "iterations");
    for (std::size_t i = 0; i < hs.size(); ++i)
      std::printf("  %12lld %14.6e %14.6e %8.3f %12lld\n", static_cast<long long>(list[i]), hs[i], errs[i], orders[i],
                  static_cast<long long>(iters[i]));
    std::printf("  fitted order %.3f (the %s order is %d; points below %.1e are left out as round-off)\n", fit,
                is_galerkin(s) ? "method's" : "map's", is_galerkin(s) ? 2 * s.stages : R.order(),
                1e-12 * std::fmax(1.0, scale));
  }
  for (double e : errs)
    if (std::isnan(e)) {
      std::fprintf(stderr, "dvm: a run of the convergence study did not converge: %s\n", first_failure.c_str());
      return 3;
    }
  return 0;
}

}  // namespace run_detail

template <class System, class Map>
int run_with(const Scene& s, const System& L, const Map& R, const RunOptions& o) {
  using namespace run_detail;
  if (o.converge) return converge_with(s, L, R, o);
  constexpr int N = System::dim;
  using V = Vec<double, N>;
  V q, p, v0;
  initial_state(s, L, q, p, v0);
  auto energy_at = [&](const V& qk, const V& pk) { return monitored_energy(L, qk, legendre_inverse(L, qk, pk), pk); };
  const double E0 = monitored_energy(L, q, v0, p);
  if (!std::isfinite(E0)) throw InputError(s.path + ": the energy at the initial state is not finite");
  const Vec<double, 2> sigma0 = velocity_hessian_scale(L, q, v0);  // for a failure's message


  const std::string csv_path = o.csv.empty() ? s.csv : o.csv;
  const std::string npy_path = o.npy.empty() ? s.npy : o.npy;
  const double rows = output_rows(s.steps, s.every);
  OutputFile csv;
  if (!csv_path.empty()) {
    csv.open(csv_path, output_source(s.path, o.csv, "--csv", "output.csv"), csv_bytes(rows, 2 * N + 2));
    std::fputs("t", csv.get());
    for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",q%d", i);
    for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",p%d", i);
    std::fputs(",energy\n", csv.get());
  }
  NpyWriter npy;
  if (!npy_path.empty()) npy.open(npy_path, output_source(s.path, o.npy, "--npy", "output.npy"), rows, 2 * N + 2);
  double row[2 * N + 2];
  auto write_row = [&](double t, const V& qk, const V& pk, double e) {
    if (csv) {
      std::fprintf(csv.get(), "%.17g", t);
      for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",%.17g", qk[i]);
      for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",%.17g", pk[i]);
      std::fprintf(csv.get(), ",%.17g\n", e);
    }
    if (npy) {
      row[0] = t;
      for (int i = 0; i < N; ++i) row[1 + i] = qk[i], row[1 + N + i] = pk[i];
      row[2 * N + 1] = e;
      npy.row(row);
    }
  };
  write_row(0.0, q, p, E0);

  const std::vector<std::string> inv_names = invariant_names(L);
  const int n_inv = static_cast<int>(inv_names.size());
  double I0[kMaxInvariants] = {}, Ik[kMaxInvariants] = {}, I_err[kMaxInvariants] = {};
  invariants(L, q, p, I0);
  double max_energy_error = 0.0, E = E0;
  Progress progress(!o.quiet, s.steps, s.step);
  const auto start = std::chrono::steady_clock::now();
  auto observer = [&](std::int64_t k, double t, const V& qk, const V& pk, const StepSummary&) {
    E = energy_at(qk, pk);
    max_energy_error = std::fmax(max_energy_error, std::fabs(E - E0));
    if (n_inv > 0) {
      invariants(L, qk, pk, Ik);
      for (int i = 0; i < n_inv; ++i) I_err[i] = std::fmax(I_err[i], std::fabs(Ik[i] - I0[i]));
    }
    if (k % s.every == 0 || k == s.steps) write_row(t, qk, pk, E);
    progress.update(k);
  };
  // The map's own step, or its steps composed (resolved once, here).
  const StepOptions opt = step_options<System>(s);
  RunSummary run =
      is_galerkin(s)
          ? integrate(GalerkinStep<System>(L, quadrature_kind(s), s.stages, s.step, opt), 0.0, q, p, v0, s.steps,
                      observer)
      : s.composition == "none"
          ? integrate(PositionMomentumStep<System, Map>(L, R, s.step, opt), 0.0, q, p, v0, s.steps, observer)
          : integrate(CompositionStep<System, Map>(L, R, s.step,
                                                   substeps(find_composition(s.composition), R.symmetric()), opt),
                      0.0, q, p, v0, s.steps, observer);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  // a solve that did not converge: say what the Legendre transform looked like where it stopped
  if (run.failed && run.failure.iterations > 0 && std::isfinite(run.failure.residual))
    run.failure.message += "; " + legendre_diagnosis(L, q, p, v0, sigma0);
  std::string kept;
  if (!finish_outputs(!run.failed, {&csv, &npy.file()}, kept)) return 3;
  const double t_final = static_cast<double>(run.steps_done) * s.step;
  int angular = -1;  // a scalar angular momentum, reported with the historical JSON keys
  for (int i = 0; i < n_inv; ++i)
    if (inv_names[static_cast<std::size_t>(i)] == "angular momentum") angular = i;

  if (o.json) {
    Json::Object j;
    j.str("status", run.failed ? "failed" : "ok")
        .str("system", L.name())
        .str("map", is_galerkin(s) ? std::string("none") : R.name())
        .str("method", s.method)
        .str("composition", s.composition)
        .str("solver", s.solver)
        .num("step", s.step)
        .num("steps", static_cast<double>(run.steps_done))
        .num("steps_requested", static_cast<double>(s.steps))
        .num("t_final", t_final)
        .arr("q_final", to_std<N>(q))
        .arr("p_final", to_std<N>(p))
        .num("energy_initial", E0)
        .num("energy_final", E)
        .num("max_abs_energy_error", max_energy_error)
        .num("wall_seconds", wall)
        .num("solver_iterations", static_cast<double>(run.solver_iterations))
        .num("max_step_iterations", run.max_step_iterations)
        .str("form", s.form);
    if (is_galerkin(s)) j.num("stages", s.stages).str("quadrature", s.quadrature).num("order", 2 * s.stages);
    if (angular >= 0)
      j.num("angular_momentum_initial", I0[angular]).num("max_abs_angular_momentum_error", I_err[angular]);
    if (n_inv > 0) {
      Json::Object inv;
      for (int i = 0; i < n_inv; ++i) {
        Json::Object e;
        e.num("initial", I0[i]).num("max_abs_error", I_err[i]);
        inv.raw(inv_names[static_cast<std::size_t>(i)], e.dump(6));
      }
      j.raw("invariants", inv.dump(4));
    }
    if (run.failed) j.raw("failure", failure_json(run));
    std::cout << j.dump() << "\n";
  } else if (!o.quiet) {
    std::printf("%s with %s%s (h = %g): %lld steps to t = %.6g\n", L.name().c_str(), method_label(s, R).c_str(),
                s.composition == "none" ? "" : (", composition " + s.composition).c_str(), s.step,
                static_cast<long long>(run.steps_done), t_final);
    std::printf("  %-44s %22s %12s\n", "quantity", "initial", "max |change|");
    std::printf("  %-44s %22.15g %12.3e\n", "energy", E0, max_energy_error);
    for (int i = 0; i < n_inv; ++i)
      std::printf("  %-44s %22.15g %12.3e\n", inv_names[static_cast<std::size_t>(i)].c_str(), I0[i], I_err[i]);
    std::printf("  solver iterations %lld (%.2f per step, at most %d in a step); wall time %.3f s (%.3g us/step)\n",
                static_cast<long long>(run.solver_iterations),
                static_cast<double>(run.solver_iterations) / std::fmax(1.0, static_cast<double>(run.steps_done)),
                run.max_step_iterations, wall, 1e6 * wall / std::fmax(1.0, static_cast<double>(run.steps_done)));
    if (!run.failed && !csv_path.empty()) std::printf("  wrote %s\n", csv_path.c_str());
    if (!run.failed && !npy_path.empty()) std::printf("  wrote %s\n", npy_path.c_str());
  }
  if (run.failed) {
    print_failure(run, s.step, kept);
    return 3;
  }
  return 0;
}

// The map named in the scene, resolved once.
template <class System>
int run_system(const Scene& s, const System& L, const RunOptions& o) {
  if (s.map == "retraction-theta") return run_with(s, L, RetractionMap<EuclideanRetraction>({}, s.theta), o);
  if (s.map == "explicit-euler") return run_with(s, L, ThetaMap::explicit_euler(), o);
  if (s.map == "adjoint-euler") return run_with(s, L, ThetaMap::adjoint_euler(), o);
  if (s.map == "midpoint") return run_with(s, L, ThetaMap::midpoint(), o);
  return run_with(s, L, ThetaMap(s.theta), o);
}

}  // namespace dvm::cli
