// A convergence study of any initial-value run: the same problem integrated to a time
// T with several step counts N (h = T/N), the error of each at T against a reference,
// the observed order between neighbouring runs and a least-squares fitted order.
//
// Error: max(|q - q_ref|, |p - p_ref|) in the max norm over the stored coordinates in
// their embedding (R^n: q; S^2: the unit vector(s); SO(3): the nine entries of R) and
// the stored momenta.
//
// Reference: the exact solution where the system has one (its accuracy: round-off of
// the closed form), else a run of a higher-order method of the same problem (Galerkin
// Gauss s = 6, order 12, where the system runs Galerkin; else the kahan-li8 composition
// of the space's midpoint map, order 8) refined by doubling its step count until two
// successive reference runs agree to 1/100 of the smallest error measured (or to
// round-off, or the refinement limit). The difference of the last two reference runs
// is reported as the reference's accuracy: an upper estimate of the error of the finer
// one.
//
// Fit: log(error) against log(h) by least squares over the runs whose error is above
// 10 times the reference's accuracy and below a tenth of the solution's size (the
// others are marked in the table: at the reference's floor, or not yet in the
// asymptotic range). With fewer than two such runs the fitted order is not determined
// and the report says why; it is never printed as a result. When the orders observed
// between neighbouring fitted runs disagree with the fitted order, the report carries
// a warning: the fit then mixes runs in and out of the asymptotic range.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "solvers/runtime/problem.h"

namespace dvm {

struct ConvergeOptions {
  std::vector<std::int64_t> steps_list;  // empty: the problem's count times 1, 2, 4, 8
  double t_end = 0.0;                    // 0: the problem's steps x step
  // The most steps the study's runs may take together (the reference runs not
  // counted); a longer study is refused before it starts.
  double max_total_steps = kDefaultMaxTotalSteps;
  static constexpr double kDefaultMaxTotalSteps = 1e8;
};

struct ConvergeRow {
  std::int64_t steps = 0;
  // order: against the previous row; NaN on the first row (and beside a failed run),
  // printed "-" in the table and null in the JSON
  double h = 0.0, error = 0.0, order = 0.0;
  std::int64_t iterations = 0;
  // the run's time in its integration loop (RunReport::wall_seconds; the run's
  // construction, and the reference runs, not counted)
  double wall_seconds = 0.0;
  // "" when the row enters the fit; else why not ("reference", "pre-asymptotic", "failed")
  std::string excluded;
};

struct ConvergeReport {
  std::string system, map, method_label, form, composition;
  std::vector<double> weights, thetas;  // composition "dirk": its weights and a theta per stage
  std::string lift;                     // hamiltonian and sode forms: the lift of the map
  bool galerkin = false;
  int stages = 0;
  std::string quadrature;
  int map_order = 0, method_order = 0;
  double t_end = 0.0;
  std::string reference;
  double reference_accuracy = 0.0;
  double scale = 0.0;  // the size of the solution at T
  std::vector<ConvergeRow> rows;
  double fitted_order = 0.0;  // NaN when not determined
  int fitted_points = 0;
  std::string fit_note;       // why the fit is not determined, or what was left out
  // What makes the fitted order doubtful: an order observed between two neighbouring
  // fitted runs that differs from the fitted order by more than max(0.5, a tenth of
  // it), a sign that the runs are not all in the asymptotic range. Empty: none.
  std::vector<std::string> warnings;
  std::string failure;        // the first run that failed (empty: none)
};

// The final state of a run as errors measure it: q in embedding coordinates
// (RunReport::q_embedded), p as stored (RunReport::p_final).
struct FinalState {
  std::vector<double> q, p;
};
// max(|q - q'|, |p - p'|), the max norm over both (the error above).
double state_distance(const FinalState& a, const FinalState& b);
// The largest entry of q and p in absolute value (the solution's size).
double final_state_size(const FinalState& a);
// The accuracy stated for an exact solution: round-off of its closed form.
double exact_accuracy(const FinalState& exact);

// The reference of a problem at time T, as described above.
struct Reference {
  FinalState state;
  bool exact = false;       // the exact solution (else a refined higher-order run)
  std::string description;  // "exact solution", or the method and its step count
  double accuracy = 0.0;
};
// The exact solution at T where the run of (problem, method) has one; else the
// reference method's runs from n_start steps, doubled until two successive runs agree
// to a hundredth of the smallest distance from the `measured` final states (or to
// round-off, or 5 doublings). show: the reference run under way on stderr. Throws
// InputError when a reference run fails or make_run refuses the problem.
Reference reference_solution(const Problem& problem, const Method& method, double T, std::int64_t n_start,
                             const std::vector<FinalState>& measured, bool show = false);

// Throws InputError for a boundary-value problem, fewer than two step counts, equal
// step counts, more steps in all than options.max_total_steps, or anything make_run
// refuses. Shows which run is under way on stderr when stderr is a terminal.
ConvergeReport converge(const Problem& problem, const Method& method, const ConvergeOptions& options);

// The table (or JSON) on stdout; returns the exit status (3 when a run failed).
int print_converge(const ConvergeReport& report, bool json);
// The JSON object `dvm converge --json` prints.
std::string converge_json(const ConvergeReport& report);

}  // namespace dvm
