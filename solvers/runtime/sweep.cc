#include "solvers/runtime/sweep.h"

#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <sstream>

#include <omp.h>
#ifdef DVM_WITH_MPI
#include <mpi.h>
#endif
#include <toml++/toml.h>

#include "solvers/runtime/errors.h"
#include "solvers/runtime/json.h"
#include "solvers/runtime/output.h"
#include "solvers/runtime/scene.h"

namespace dvm {

namespace {

// ---- values: TOML text, JSON, CSV cell ----------------------------------------------

// A TOML basic string: JSON's escapes are TOML's too, and TOML also escapes DEL.
std::string toml_string(const std::string& s) {
  std::string out;
  for (char c : Json::string(s)) out += c == '\x7f' ? std::string("\\u007f") : std::string(1, c);
  return out;
}

// A float as TOML reads it back to the same double: the shortest digits, and a
// decimal point where they would read as an integer.
std::string toml_float(double x) {
  if (std::isnan(x)) return "nan";
  if (std::isinf(x)) return x > 0 ? "inf" : "-inf";
  std::string s = shortest(x);
  if (s.find_first_of(".eE") == std::string::npos) s += ".0";
  return s;
}

std::string toml_text(const toml::node& n) {
  if (const auto* s = n.as_string()) return toml_string(s->get());
  if (const auto* i = n.as_integer()) return std::to_string(i->get());
  if (const auto* f = n.as_floating_point()) return toml_float(f->get());
  if (const auto* b = n.as_boolean()) return b->get() ? "true" : "false";
  if (const auto* a = n.as_array()) {
    std::string out = "[";
    for (std::size_t k = 0; k < a->size(); ++k) out += (k ? ", " : "") + toml_text(*a->get(k));
    return out + "]";
  }
  if (const auto* t = n.as_table()) {
    std::string out = "{";
    bool first = true;
    for (const auto& [key, value] : *t) {
      out += (first ? " " : ", ") + toml_string(std::string(key.str())) + " = " + toml_text(value);
      first = false;
    }
    return out + (first ? "}" : " }");
  }
  std::ostringstream out;  // dates and times
  if (const auto* d = n.as_date()) out << d->get();
  if (const auto* t = n.as_time()) out << t->get();
  if (const auto* dt = n.as_date_time()) out << dt->get();
  return out.str();
}

std::string json_text(const toml::node& n) {
  if (const auto* s = n.as_string()) return Json::string(s->get());
  if (const auto* i = n.as_integer()) return std::to_string(i->get());
  if (const auto* f = n.as_floating_point()) return Json::number(f->get());
  if (const auto* b = n.as_boolean()) return b->get() ? "true" : "false";
  if (const auto* a = n.as_array()) {
    std::string out = "[";
    for (std::size_t k = 0; k < a->size(); ++k) out += (k ? ", " : "") + json_text(*a->get(k));
    return out + "]";
  }
  if (const auto* t = n.as_table()) {
    std::string out = "{";
    bool first = true;
    for (const auto& [key, value] : *t) {
      out += (first ? "" : ", ") + Json::string(std::string(key.str())) + ": " + json_text(value);
      first = false;
    }
    return out + "}";
  }
  return Json::string(toml_text(n));
}

SweepValue value_of(const toml::node& n) {
  SweepValue v;
  v.toml = toml_text(n);
  v.json = json_text(n);
  v.cell = n.is_string() ? n.as_string()->get() : v.toml;
  return v;
}

SweepValue number_value(double x, bool whole) {
  SweepValue v;
  if (whole) {
    v.toml = v.json = v.cell = std::to_string(std::llround(x));
  } else {
    v.toml = v.cell = toml_float(x);
    v.json = Json::number(x);
  }
  return v;
}

// A word as --set takes it without quotes (a string): a letter, then letters, digits
// and _ - . /
bool bare_word(const std::string& s) {
  return !s.empty() && std::isalpha(static_cast<unsigned char>(s[0])) &&
         s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-./") == std::string::npos;
}

std::string trim(const std::string& s) {
  const auto a = s.find_first_not_of(" \t");
  if (a == std::string::npos) return "";
  const auto b = s.find_last_not_of(" \t");
  return s.substr(a, b - a + 1);
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (true) {
    const auto at = s.find(sep, start);
    out.push_back(s.substr(start, at == std::string::npos ? std::string::npos : at - start));
    if (at == std::string::npos) return out;
    start = at + 1;
  }
}

const char* kSpecForms =
    "expected a list [v1, v2, ...], a range a:b:n, log:a:b:n, samples uniform:a:b:n:seed, or one value";

// ---- ranges and samples ---------------------------------------------------------------

struct RangeParser {
  const std::string& key;
  const std::string& spec;
  double max_values;

  [[noreturn]] void fail(const std::string& why) const {
    throw InputError("--vary " + echo(key) + ": '" + echo(spec) + "': " + why);
  }
  static bool integer_text(const std::string& t) {
    const std::string s = trim(t);
    std::size_t k = (!s.empty() && (s[0] == '+' || s[0] == '-')) ? 1 : 0;
    return k < s.size() && s.find_first_not_of("0123456789", k) == std::string::npos;
  }
  double number(const std::string& text, const char* what) const {
    const std::string t = trim(text);
    char* end = nullptr;
    const double x = std::strtod(t.c_str(), &end);
    if (t.empty() || *end != '\0' || !std::isfinite(x))
      fail(std::string(what) + " '" + echo(t) + "' is not a finite number; " + kSpecForms);
    return x;
  }
  std::size_t count(const std::string& text) const {
    const std::string t = trim(text);
    if (!integer_text(t) || t[0] == '-')
      fail("the number of points '" + echo(t) + "' is not a whole number >= 1");
    const double n = std::strtod(t.c_str(), nullptr);
    if (n < 1) fail("an empty range (0 points); expected at least 1 point");
    if (n > max_values) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.0f", max_values);
      fail(t + " points, more than the limit of " + buf + " runs of a sweep; expected fewer (or raise the limit with "
               "--max-runs)");
    }
    return static_cast<std::size_t>(n);
  }
};

// Points of a range whose ends are written as whole numbers are whole numbers where
// they are within round-off of one (log:100:12800:8 gives 100, 200, ... 12800).
SweepValue range_point(double x, bool whole_ends) {
  const double r = std::nearbyint(x);
  const bool whole = whole_ends && std::fabs(x - r) <= 1e-9 * std::fmax(1.0, std::fabs(x)) && std::fabs(r) < 9e15;
  return number_value(whole ? r : x, whole);
}

}  // namespace

SweepAxis parse_vary(const std::string& arg, double max_values) {
  const auto eq = arg.find('=');
  if (eq == std::string::npos || eq == 0)
    throw InputError("--vary: expected KEY=SPEC (e.g. integrator.step=[0.1, 0.05]), got '" + echo(arg) + "'");
  SweepAxis axis;
  axis.key = trim(arg.substr(0, eq));
  axis.spec = trim(arg.substr(eq + 1));
  const std::string& key = axis.key;
  const std::string& spec = axis.spec;
  if (key.find('.') == std::string::npos || key.front() == '.' || key.back() == '.')
    throw InputError("--vary " + echo(key) + ": expected a key section.key (e.g. integrator.step)");
  const RangeParser p{key, spec, max_values};
  if (spec.empty()) p.fail(std::string("no values; ") + kSpecForms);

  // a list, a quoted string or an inline table is TOML text (its strings may hold ':')
  const bool is_toml = spec.front() == '[' || spec.front() == '"' || spec.front() == '\'' || spec.front() == '{';
  const std::vector<std::string> parts = is_toml ? std::vector<std::string>{spec} : split(spec, ':');
  const std::string head = parts.size() > 1 ? trim(parts[0]) : "";
  if (head == "log") {
    if (parts.size() != 4) p.fail("expected log:a:b:n (n points from a to b, equal ratios)");
    const double a = p.number(parts[1], "the start"), b = p.number(parts[2], "the end");
    const std::size_t n = p.count(parts[3]);
    if (!(a > 0 && b > 0)) p.fail("a log range needs ends > 0");
    if (n == 1 && a != b) p.fail("1 point between two different ends; expected n >= 2, or a list");
    const bool whole = RangeParser::integer_text(parts[1]) && RangeParser::integer_text(parts[2]);
    const double la = std::log(a), lb = std::log(b);
    for (std::size_t i = 0; i < n; ++i) {
      const double x = i == 0 ? a : i + 1 == n ? b
                                  : std::exp(la + (lb - la) * static_cast<double>(i) / static_cast<double>(n - 1));
      axis.values.push_back(range_point(x, whole));
    }
    return axis;
  }
  if (head == "uniform") {
    if (parts.size() != 5) p.fail("expected uniform:a:b:n:seed (n samples in [a, b) drawn with the seed)");
    const double a = p.number(parts[1], "the start"), b = p.number(parts[2], "the end");
    const std::size_t n = p.count(parts[3]);
    const std::string seed_text = trim(parts[4]);
    if (!RangeParser::integer_text(seed_text) || seed_text[0] == '-' || seed_text.size() > 19)
      p.fail("the seed '" + echo(seed_text) + "' is not a whole number from 0 to 10^19 - 1");
    if (!(a <= b)) p.fail("expected a <= b");
    std::mt19937_64 engine(std::strtoull(seed_text.c_str(), nullptr, 10));
    for (std::size_t i = 0; i < n; ++i) {
      const double u = static_cast<double>(engine() >> 11) * 0x1.0p-53;  // in [0, 1), 53 random bits
      axis.values.push_back(number_value(a + (b - a) * u, false));
    }
    return axis;
  }
  if (parts.size() == 3) {
    const double a = p.number(parts[0], "the start"), b = p.number(parts[1], "the end");
    const std::size_t n = p.count(parts[2]);
    if (n == 1 && a != b) p.fail("1 point between two different ends; expected n >= 2, or a list");
    const bool whole = RangeParser::integer_text(parts[0]) && RangeParser::integer_text(parts[1]);
    for (std::size_t i = 0; i < n; ++i) {
      const double x = i + 1 == n ? b : a + (b - a) * static_cast<double>(i) / static_cast<double>(n - 1);
      axis.values.push_back(range_point(x, whole));
    }
    return axis;
  }
  if (parts.size() > 1) p.fail(kSpecForms);

  // a TOML array, or one TOML value; bare words are strings, as --set takes them
  toml::table parsed;
  bool read = false;
  try {
    parsed = toml::parse(std::string_view("value = " + spec), std::string_view("--vary"));
    read = parsed.size() == 1;
  } catch (const toml::parse_error&) {
  }
  if (read) {
    const toml::node& v = *parsed.get("value");
    if (const auto* a = v.as_array()) {
      if (a->empty()) p.fail("an empty list; expected at least one value");
      if (static_cast<double>(a->size()) > max_values) p.count(std::to_string(a->size()));
      for (std::size_t k = 0; k < a->size(); ++k) axis.values.push_back(value_of(*a->get(k)));
    } else {
      axis.values.push_back(value_of(v));
    }
    return axis;
  }
  if (spec.size() >= 2 && spec.front() == '[' && spec.back() == ']') {
    const std::string inner = trim(spec.substr(1, spec.size() - 2));
    if (inner.empty()) p.fail("an empty list; expected at least one value");
    for (const std::string& item : split(inner, ',')) {
      const std::string w = trim(item);
      if (!bare_word(w)) p.fail("'" + echo(w) + "' is not a TOML value (a string needs quotes: \"name\")");
      SweepValue v;
      v.toml = toml_string(w);
      v.json = Json::string(w);
      v.cell = w;
      axis.values.push_back(v);
    }
    return axis;
  }
  if (bare_word(spec)) {
    axis.values.push_back({toml_string(spec), Json::string(spec), spec});
    return axis;
  }
  p.fail(kSpecForms);
}

std::size_t sweep_size(const SweepOptions& o) {
  if (o.axes.empty()) throw InputError("dvm sweep needs at least one --vary KEY=SPEC");
  auto output_key = [](const std::string& key) {
    return key.rfind("output.", 0) == 0 && key != "output.monitor_every";
  };
  std::set<std::string> set_keys;
  for (const std::string& s : o.sets) {
    const std::string key = trim(s.substr(0, s.find('=')));
    if (output_key(key))
      throw InputError("--set " + echo(key) + ": a sweep writes no trajectories (its table is the output); of "
                       "[output], only output.monitor_every applies");
    set_keys.insert(key);
  }
  std::set<std::string> seen;
  double runs = 1.0;
  for (const SweepAxis& a : o.axes) {
    if (output_key(a.key))
      throw InputError("--vary " + echo(a.key) + ": a sweep writes no trajectories (its table is the output); of "
                       "[output], only output.monitor_every applies");
    if (!seen.insert(a.key).second) throw InputError("--vary " + echo(a.key) + ": the key is varied twice");
    if (set_keys.count(a.key))
      throw InputError("--vary " + echo(a.key) + ": the key is given by --set too; give it one way");
    if (a.values.empty()) throw InputError("--vary " + echo(a.key) + ": no values");
    if (o.zip && a.values.size() != o.axes.front().values.size())
      throw InputError("--zip: --vary " + echo(a.key) + " has " + std::to_string(a.values.size()) + " values and --vary " +
                       echo(o.axes.front().key) + " has " + std::to_string(o.axes.front().values.size()) +
                       "; zipped keys need lists of equal lengths");
    runs = o.zip ? static_cast<double>(a.values.size()) : runs * static_cast<double>(a.values.size());
  }
  if (runs > o.max_runs) {
    char buf[200];
    std::snprintf(buf, sizeof buf, "the sweep has %.0f runs, more than the limit of %.0f", runs, o.max_runs);
    throw InputError(std::string(buf) + "; expected fewer values (or raise the limit with --max-runs)");
  }
  return static_cast<std::size_t>(runs);
}

std::vector<std::size_t> sweep_values(const SweepOptions& o, std::size_t i) {
  std::vector<std::size_t> at(o.axes.size());
  if (o.zip) {
    std::fill(at.begin(), at.end(), i);
    return at;
  }
  for (std::size_t a = o.axes.size(); a-- > 0;) {  // the last key varies fastest
    const std::size_t n = o.axes[a].values.size();
    at[a] = i % n;
    i /= n;
  }
  return at;
}

std::vector<std::string> sweep_overrides(const SweepOptions& o, std::size_t i) {
  std::vector<std::string> out = o.sets;
  const std::vector<std::size_t> at = sweep_values(o, i);
  for (std::size_t a = 0; a < o.axes.size(); ++a) out.push_back(o.axes[a].key + "=" + o.axes[a].values[at[a]].toml);
  return out;
}

int default_jobs() { return std::max(1, omp_get_num_procs()); }

const char* to_string(RowStatus s) {
  switch (s) {
    case RowStatus::ok: return "ok";
    case RowStatus::failed: return "failed";
    case RowStatus::refused: return "refused";
  }
  return "?";
}

namespace {

// Row i's scene: read as `dvm run --set ...` reads it. Throws InputError.
Scene load_row(const SweepOptions& o, std::size_t i) {
  Scene s = load_scene_text(o.scene_text, o.scene_path, sweep_overrides(o, i));
  if (o.error && s.problem.boundary_value)
    throw InputError(o.scene_path + ": key 'problem.kind': --error measures the final state of initial-value runs; "
                     "a boundary-value problem's end is given");
  return s;
}

double thread_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

std::string failure_message(const RunReport& r) {
  if (r.boundary_value) return "the boundary-value problem did not converge: " + r.message;
  const StepSummary& f = r.loop.failure;
  char buf[160];
  std::snprintf(buf, sizeof buf, "step %lld (t = %s) failed after %d iterations, residual %.3e: ",
                static_cast<long long>(r.loop.failed_step), shortest(r.loop.failed_time).c_str(), f.iterations,
                f.residual);
  return buf + f.message;
}

// The key of a row's problem for --error: its values outside [integrator] and
// [output], and its time span (to 12 digits: spans equal but for round-off of
// steps x step are one problem).
std::string problem_key(const SweepOptions& o, std::size_t i, double t_end) {
  std::string key;
  const std::vector<std::size_t> at = sweep_values(o, i);
  for (std::size_t a = 0; a < o.axes.size(); ++a) {
    const std::string& k = o.axes[a].key;
    if (k.rfind("integrator.", 0) == 0 || k.rfind("output.", 0) == 0) continue;
    key += k + "=" + o.axes[a].values[at[a]].toml + "\n";
  }
  char buf[40];
  std::snprintf(buf, sizeof buf, "T=%.12g", t_end);
  return key + buf;
}

// --max-error measures along the run against an exact solution: a run without one is
// refused. Returns the sizes of the exact q and p.
std::pair<std::size_t, std::size_t> require_exact(const SweepOptions& o, const Scene& s, const Run& run) {
  std::vector<double> q, p;
  if (!run.exact(0.0, q, p)) {
    const std::string name = s.problem.system ? s.problem.system->name : std::string("written");
    throw InputError("--max-error: the system '" + name + "' of " + o.scene_path +
                     " has no exact solution here; the largest error along a run is measured against one "
                     "(--error alone measures the final state against a reference run)");
  }
  return {q.size(), p.size()};
}

}  // namespace

std::string check_row(const SweepOptions& o, std::size_t i) {
  try {
    const Scene s = load_row(o, i);
    const auto run = make_run(s.problem, s.method);
    if (o.error && o.max_error) require_exact(o, s, *run);
    return "";
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("internal error: ") + e.what();
  } catch (...) {
    return "internal error: an exception of unknown type";
  }
}

SweepRow run_row(const SweepOptions& o, std::size_t i) {
  SweepRow row;
  row.index = i;
  try {
    const Scene s = load_row(o, i);
    const auto run = make_run(s.problem, s.method);
    // no rows written; the energy monitored as `dvm run` monitors it
    OutputSpec spec;
    spec.monitor_every = s.monitor_every;
    Recorder recorder(spec);
    // --max-error: every step's state (t, q, p, ... on R^n, where exact solutions
    // are) against the exact solution at its time
    double max_error = 0.0;
    bool without_exact = false;  // a step where the exact solution could not be evaluated
    std::vector<double> qe, pe;
    if (o.error && o.max_error) {
      const auto [nq, np] = require_exact(o, s, *run);
      recorder.set_sink([&, nq = nq, np = np](const std::vector<std::string>& columns, const double* x) {
        if (columns.size() < 1 + nq + np || columns.front() != "t")
          throw std::logic_error("--max-error: rows without t, q and p");
        if (!run->exact(x[0], qe, pe)) {
          without_exact = true;
          return;
        }
        for (std::size_t k = 0; k < nq; ++k) max_error = std::fmax(max_error, std::fabs(x[1 + k] - qe[k]));
        for (std::size_t k = 0; k < np; ++k) max_error = std::fmax(max_error, std::fabs(x[1 + nq + k] - pe[k]));
      });
    }
    const double cpu0 = thread_cpu_seconds();
    row.report = run->execute(&recorder);
    row.cpu_seconds = thread_cpu_seconds() - cpu0;
    row.ran = true;
    row.run_json = report_json(row.report);
    row.t_end = static_cast<double>(s.problem.steps) * s.problem.step;
    if (row.report.failed) {
      row.status = RowStatus::failed;
      row.code = 3;
      row.message = failure_message(row.report);
      return row;
    }
    if (o.error) {
      row.problem = problem_key(o, i, row.t_end);
      row.final_state = {row.report.q_embedded, row.report.p_final};
      FinalState exact;
      if (run->exact(row.report.t_final, exact.q, exact.p)) {
        row.error = state_distance(row.final_state, exact);
        row.reference_accuracy = exact_accuracy(exact);
      }
      if (o.max_error) row.max_error = without_exact ? NAN : max_error;
    }
  } catch (const InputError& e) {
    row = SweepRow{};
    row.index = i;
    row.status = RowStatus::refused;
    row.code = 2;
    row.message = e.what();
  } catch (const std::exception& e) {
    row.status = RowStatus::failed;
    row.code = 3;
    row.message = std::string("internal error: ") + e.what();
  } catch (...) {
    row.status = RowStatus::failed;
    row.code = 3;
    row.message = "internal error: an exception of unknown type";
  }
  return row;
}

namespace {

// "run k of n" on stderr while a terminal shows it, at most four times a second.
class Progress {
 public:
  Progress(const char* what, std::size_t total) : what_(what), total_(total), on_(isatty(fileno(stderr))) {}
  void done_one() {
    const std::size_t done = ++done_;
    if (!on_) return;
    const auto now = std::chrono::steady_clock::now();
#pragma omp critical(dvm_sweep_progress)
    if (now - last_ > std::chrono::milliseconds(250) || done == total_) {
      last_ = now;
      std::fprintf(stderr, "\r  sweep: %s %zu of %zu   ", what_, done, total_);
      std::fflush(stderr);
    }
  }
  ~Progress() {
    if (on_) std::fprintf(stderr, "\r%*s\r", 60, "");
  }

 private:
  const char* what_;
  std::size_t total_;
  bool on_;
  std::atomic<std::size_t> done_{0};
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace

namespace {

// A run on a worker thread gets the stack a run on the main thread has (the fixed-size
// kernels keep their Jets on it). libgomp's threads take glibc's default, the stack
// limit; libomp's take a smaller default of their own, raised here to the limit
// before the first parallel region creates them ($OMP_STACKSIZE, when set, wins).
void match_thread_stacks() {
#ifdef KMP_VERSION_MAJOR
  rlimit limit{};
  if (std::getenv("OMP_STACKSIZE") || std::getenv("KMP_STACKSIZE")) return;
  if (getrlimit(RLIMIT_STACK, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
    kmp_set_stacksize_s(static_cast<std::size_t>(limit.rlim_cur));
#endif
}

}  // namespace

namespace {

// The rows a sweep runs (those `done` lacks), in the sweep's order.
std::vector<long long> rows_to_run(std::size_t n, const SweepRows& done) {
  std::vector<long long> todo;
  for (std::size_t i = 0; i < n; ++i)
    if (!(i < done.have.size() && i < done.rows.size() && done.have[i])) todo.push_back(static_cast<long long>(i));
  return todo;
}

// Step 1 of run_sweep: each row's refusal ("" when it runs), the rows of `done`
// keeping theirs; throws InputError for a value refused by every row it is in.
std::vector<std::string> check_rows(const SweepOptions& o, const SweepRows& done, const std::vector<long long>& todo,
                                    int jobs) {
  const std::size_t n = sweep_size(o);
  std::vector<std::string> refusals(n);
  for (std::size_t i = 0; i < n && i < done.rows.size() && i < done.have.size(); ++i)
    if (done.have[i] && done.rows[i].status == RowStatus::refused) refusals[i] = done.rows[i].message;
  const long long count = static_cast<long long>(todo.size());
  {
    Progress progress("checked", todo.size());
#pragma omp parallel for schedule(dynamic, 1) num_threads(jobs)
    for (long long t = 0; t < count; ++t) {
      const std::size_t i = static_cast<std::size_t>(todo[static_cast<std::size_t>(t)]);
      refusals[i] = check_row(o, i);
      progress.done_one();
    }
  }
  // a value that every run it takes part in refuses is bad input of the sweep
  {
    std::vector<std::vector<std::size_t>> total(o.axes.size()), refused(o.axes.size());
    std::vector<std::vector<std::size_t>> first(o.axes.size());
    for (std::size_t a = 0; a < o.axes.size(); ++a) {
      total[a].assign(o.axes[a].values.size(), 0);
      refused[a].assign(o.axes[a].values.size(), 0);
      first[a].assign(o.axes[a].values.size(), n);
    }
    for (std::size_t i = 0; i < n; ++i) {
      const std::vector<std::size_t> at = sweep_values(o, i);
      for (std::size_t a = 0; a < o.axes.size(); ++a) {
        ++total[a][at[a]];
        if (refusals[i].empty()) continue;
        ++refused[a][at[a]];
        first[a][at[a]] = std::min(first[a][at[a]], i);
      }
    }
    if (std::all_of(refusals.begin(), refusals.end(), [](const std::string& r) { return !r.empty(); }))
      throw InputError("every run of the sweep is refused (" + std::to_string(n) +
                       "); nothing was run. The first (row 0): " + refusals.front());
    // the first such value whose key the refusal names, else the first such value
    std::size_t pick_a = o.axes.size(), pick_v = 0;
    for (std::size_t a = 0; a < o.axes.size(); ++a)
      for (std::size_t v = 0; v < total[a].size(); ++v) {
        if (total[a][v] == 0 || refused[a][v] != total[a][v]) continue;
        const bool named = refusals[first[a][v]].find(o.axes[a].key) != std::string::npos;
        const bool picked_named =
            pick_a < o.axes.size() && refusals[first[pick_a][pick_v]].find(o.axes[pick_a].key) != std::string::npos;
        if (pick_a == o.axes.size() || (named && !picked_named)) pick_a = a, pick_v = v;
      }
    if (pick_a < o.axes.size()) {
      const SweepAxis& a = o.axes[pick_a];
      throw InputError("--vary " + echo(a.key) + ": the value " + echo(a.values[pick_v].toml) +
                       " is refused by every run it takes part in (" + std::to_string(total[pick_a][pick_v]) +
                       "); nothing was run. The first (row " + std::to_string(first[pick_a][pick_v]) +
                       "): " + refusals[first[pick_a][pick_v]]);
    }
  }

  return refusals;
}

SweepRow refused_row(std::size_t k, const std::string& why) {
  SweepRow row;
  row.index = k;
  row.status = RowStatus::refused;
  row.code = 2;
  row.message = why;
  return row;
}

// The rows as they finish, from any thread, and the calls of `flush` (see SweepFlush).
class Gather {
 public:
  Gather(std::size_t n, const SweepRows& done, const SweepFlush& flush) : flush_(flush), have_(n, 0) {
    rep_.runs = n;
    rep_.rows.resize(n);
    for (std::size_t i = 0; i < n && i < done.rows.size() && i < done.have.size(); ++i)
      if (done.have[i]) rep_.rows[i] = done.rows[i], have_[i] = 1;
  }
  void add(SweepRow row) {
    {
      std::lock_guard<std::mutex> lock(rows_lock_);
      const std::size_t k = row.index;
      rep_.rows[k] = std::move(row);
      have_[k] = 1;
    }
    maybe_flush();
  }
  // The report of every row (all added), without errors.
  SweepReport finish() {
    for (const SweepRow& row : rep_.rows) {
      rep_.ok += row.status == RowStatus::ok;
      rep_.failed += row.status == RowStatus::failed;
      rep_.refused += row.status == RowStatus::refused;
    }
    return std::move(rep_);
  }

 private:
  void maybe_flush() {
    if (!flush_) return;
    std::unique_lock<std::mutex> one(flush_lock_, std::try_to_lock);
    if (!one.owns_lock()) return;
    const auto start = std::chrono::steady_clock::now();
    if (start - last_end_ < 10 * last_took_) return;
    SweepReport finished;
    finished.runs = rep_.runs;
    {
      std::lock_guard<std::mutex> lock(rows_lock_);
      for (std::size_t i = 0; i < have_.size(); ++i)
        if (have_[i]) finished.rows.push_back(rep_.rows[i]);
    }
    for (const SweepRow& row : finished.rows) {
      finished.ok += row.status == RowStatus::ok;
      finished.failed += row.status == RowStatus::failed;
      finished.refused += row.status == RowStatus::refused;
    }
    flush_(finished);
    last_end_ = std::chrono::steady_clock::now();
    last_took_ = last_end_ - start;
  }
  const SweepFlush& flush_;
  SweepReport rep_;
  std::vector<char> have_;
  std::mutex rows_lock_, flush_lock_;
  std::chrono::steady_clock::time_point last_end_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::duration last_took_{0};
};

}  // namespace

SweepReport run_sweep(const SweepOptions& o) { return run_sweep(o, SweepRows{}, SweepFlush{}); }

SweepReport run_sweep(const SweepOptions& o, const SweepRows& done, const SweepFlush& flush) {
  const std::size_t n = sweep_size(o);
  match_thread_stacks();
  const int jobs = std::max(1, o.jobs);
  const std::vector<long long> todo = rows_to_run(n, done);
  // 1. every row read and built, none run (a row given keeps its refusal)
  const std::vector<std::string> refusals = check_rows(o, done, todo, jobs);
  // 2. the runs, handed to `flush` as they finish
  Gather gather(n, done, flush);
  {
    const long long count = static_cast<long long>(todo.size());
    Progress progress("ran", todo.size());
#pragma omp parallel for schedule(dynamic, 1) num_threads(jobs)
    for (long long t = 0; t < count; ++t) {
      const std::size_t k = static_cast<std::size_t>(todo[static_cast<std::size_t>(t)]);
      gather.add(refusals[k].empty() ? run_row(o, k) : refused_row(k, refusals[k]));
      progress.done_one();
    }
  }
  SweepReport rep = gather.finish();
  // 3. errors against references
  if (o.error) attach_errors(o, rep.rows, rep.references);
  return rep;
}

void attach_errors(const SweepOptions& o, std::vector<SweepRow>& rows, std::vector<SweepReference>& refs) {
  // the distinct problems, in the order of their first row
  std::map<std::string, std::size_t> index;
  std::vector<bool> exact;
  for (SweepRow& row : rows) {
    if (row.status != RowStatus::ok || row.problem.empty()) continue;
    auto [it, added] = index.emplace(row.problem, refs.size());
    if (added) {
      SweepReference r;
      r.t_end = row.t_end;
      refs.push_back(r);
      exact.push_back(!std::isnan(row.reference_accuracy));
    }
    row.reference = static_cast<int>(it->second);
    refs[it->second].rows.push_back(row.index);
  }
  const long long count = static_cast<long long>(refs.size());
  std::vector<FinalState> states(refs.size());
  const int jobs = std::max(1, o.jobs);
#pragma omp parallel for schedule(dynamic, 1) num_threads(jobs)
  for (long long k = 0; k < count; ++k) {
    SweepReference& ref = refs[static_cast<std::size_t>(k)];
    if (exact[static_cast<std::size_t>(k)]) {
      ref.description = "exact solution at each run's final time";
      ref.accuracy = 0.0;
      for (std::size_t i : ref.rows) ref.accuracy = std::fmax(ref.accuracy, rows[i].reference_accuracy);
      continue;
    }
    try {
      const std::size_t first = ref.rows.front();
      const Scene s = load_row(o, first);
      std::int64_t n_start = 1;
      std::vector<FinalState> measured;
      for (std::size_t i : ref.rows) {
        n_start = std::max(n_start, rows[i].report.steps_requested);
        measured.push_back(rows[i].final_state);
      }
      const Reference r = reference_solution(s.problem, s.method, ref.t_end, n_start, measured);
      ref.description = r.description;
      ref.accuracy = r.accuracy;
      states[static_cast<std::size_t>(k)] = r.state;
    } catch (const std::exception& e) {
      ref.failure = e.what();
    }
  }
  for (std::size_t k = 0; k < refs.size(); ++k) {
    if (exact[k] || !refs[k].failure.empty()) continue;
    for (std::size_t i : refs[k].rows) rows[i].error = state_distance(rows[i].final_state, states[k]);
  }
}

// ---- the table -----------------------------------------------------------------------

namespace {

std::string csv_cell(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

std::string num17(double x) {
  if (!std::isfinite(x)) return "";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

std::string integer(std::int64_t x) { return std::to_string(x); }

// The CSV's columns from a run's report, in order, between the row's own columns and
// the final state's components: sweep_csv writes them, read_sweep_cells reads a JSON
// table into them (cpu_seconds is the row's; failed_step and failed_time are the
// failure's step and time).
constexpr const char* kRunColumns[] = {
    "system", "map", "form", "composition", "method", "step", "steps", "t_final", "wall_seconds", "cpu_seconds",
    "energy_initial", "energy_final", "max_abs_energy_error", "work", "max_abs_energy_balance", "max_constraint_residual",
    "max_hidden_constraint_residual", "solver_iterations", "jacobians",
    "max_step_iterations", "order", "failed_step", "failed_time"};

}  // namespace

std::string sweep_csv(const SweepOptions& o, const SweepReport& rep) {
  std::size_t nq = 0, np = 0;
  for (const SweepRow& r : rep.rows)
    if (r.ran) nq = std::max(nq, r.report.q_final.size()), np = std::max(np, r.report.p_final.size());
  std::vector<std::string> head = {"index"};
  for (const SweepAxis& a : o.axes) head.push_back(a.key);
  for (const char* c : {"status", "code", "message"}) head.push_back(c);
  if (o.error) head.push_back("error");
  if (o.error && o.max_error) head.push_back("max_error");
  for (const char* c : kRunColumns) head.push_back(c);
  for (std::size_t k = 0; k < nq; ++k) head.push_back("q_final[" + std::to_string(k) + "]");
  for (std::size_t k = 0; k < np; ++k) head.push_back("p_final[" + std::to_string(k) + "]");
  std::string out;
  for (std::size_t k = 0; k < head.size(); ++k) out += (k ? "," : "") + csv_cell(head[k]);
  out += "\n";
  for (const SweepRow& row : rep.rows) {
    std::vector<std::string> c = {std::to_string(row.index)};
    const std::vector<std::size_t> at = sweep_values(o, row.index);
    for (std::size_t a = 0; a < o.axes.size(); ++a) c.push_back(o.axes[a].values[at[a]].cell);
    c.push_back(to_string(row.status));
    c.push_back(std::to_string(row.code));
    c.push_back(row.message);
    if (o.error) c.push_back(num17(row.error));
    if (o.error && o.max_error) c.push_back(num17(row.max_error));
    const RunReport& r = row.report;
    if (row.ran) {
      const bool failed = r.failed && !r.boundary_value;
      for (const std::string& s :
           {r.system, r.map, r.form, r.composition, r.method, num17(r.step), integer(r.steps), num17(r.t_final),
            num17(r.wall_seconds), num17(row.cpu_seconds), num17(r.energy_initial), num17(r.energy_final),
            num17(r.max_abs_energy_error), r.forced ? num17(r.work) : std::string(),
            r.forced ? num17(r.max_abs_energy_balance) : std::string(),
            r.constrained ? num17(r.max_constraint_residual) : std::string(),
            r.constrained ? num17(r.max_hidden_constraint_residual) : std::string(), integer(r.solver_iterations),
            integer(r.jacobians),
            integer(r.max_step_iterations), r.order > 0 ? integer(r.order) : std::string(),
            failed ? integer(r.loop.failed_step) : std::string(), failed ? num17(r.loop.failed_time) : std::string()})
        c.push_back(s);
      for (std::size_t k = 0; k < nq; ++k) c.push_back(k < r.q_final.size() ? num17(r.q_final[k]) : "");
      for (std::size_t k = 0; k < np; ++k) c.push_back(k < r.p_final.size() ? num17(r.p_final[k]) : "");
    } else {
      c.resize(head.size());
    }
    for (std::size_t k = 0; k < c.size(); ++k) out += (k ? "," : "") + csv_cell(c[k]);
    out += "\n";
  }
  return out;
}

std::string scene_digest(const std::string& text) {
  std::uint64_t h = 14695981039346656037ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[24];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

namespace {

// The header's fields that say which sweep made a table (a resumed table must be of
// the same sweep): the JSON text of each.
std::string set_json(const SweepOptions& o) {
  std::string sets = "[";
  for (std::size_t k = 0; k < o.sets.size(); ++k) sets += (k ? ", " : "") + Json::string(o.sets[k]);
  return sets + "]";
}
std::string values_json(const SweepAxis& a) {
  std::string values = "[";
  for (std::size_t v = 0; v < a.values.size(); ++v) values += (v ? ", " : "") + a.values[v].json;
  return values + "]";
}
std::string errors_json(const SweepOptions& o) {
  return !o.error ? "[]" : o.max_error ? "[\"error\", \"max_error\"]" : "[\"error\"]";
}
std::string row_values_json(const SweepOptions& o, std::size_t i, int indent) {
  Json::Object values;
  const std::vector<std::size_t> at = sweep_values(o, i);
  for (std::size_t a = 0; a < o.axes.size(); ++a) values.raw(o.axes[a].key, o.axes[a].values[at[a]].json);
  return values.dump(indent);
}

}  // namespace

std::string sweep_row_json(const SweepOptions& o, const SweepRow& row) {
  Json::Object x;
  x.num("index", static_cast<double>(row.index));
  x.raw("values", row_values_json(o, row.index, 8)).str("status", to_string(row.status)).num("code", row.code);
  x.str("message", row.message);
  if (o.error) {
    x.num("error", row.error);
    if (o.max_error) x.num("max_error", row.max_error);
    x.raw("reference", row.reference < 0 ? "null" : std::to_string(row.reference));
    x.num("reference_accuracy", row.reference_accuracy);
    if (row.problem.empty() && row.final_state.q.empty() && row.final_state.p.empty()) {
      x.raw("final_state", "null");
    } else {
      Json::Object f;
      f.arr("q", row.final_state.q).arr("p", row.final_state.p);
      x.raw("final_state", f.dump(8));
    }
  }
  x.raw("cpu_seconds", row.ran ? Json::number(row.cpu_seconds) : "null");
  x.raw("run", row.ran ? (row.run_json.empty() ? report_json(row.report) : row.run_json) : "null");
  return x.dump(6);
}

std::string sweep_json(const SweepOptions& o, const SweepReport& rep) {
  Json::Object j;
  j.num("json_version", 1).str("scene", o.scene_path).str("scene_digest", scene_digest(o.scene_text));
  j.raw("set", set_json(o));
  std::string vary = "[";
  for (std::size_t a = 0; a < o.axes.size(); ++a) {
    Json::Object x;
    x.str("key", o.axes[a].key).str("spec", o.axes[a].spec).raw("values", values_json(o.axes[a]));
    vary += std::string(a ? ", " : "") + x.dump(6);
  }
  j.raw("vary", vary + "]").str("combine", o.zip ? "zip" : "product").raw("errors", errors_json(o));
  j.num("runs", static_cast<double>(rep.runs)).num("ok", static_cast<double>(rep.ok));
  j.num("failed", static_cast<double>(rep.failed)).num("refused", static_cast<double>(rep.refused));
  if (o.error) {
    std::string refs = "[";
    for (std::size_t k = 0; k < rep.references.size(); ++k) {
      const SweepReference& r = rep.references[k];
      std::string rows = "[";
      for (std::size_t i = 0; i < r.rows.size(); ++i) rows += (i ? ", " : "") + std::to_string(r.rows[i]);
      Json::Object x;
      x.num("index", static_cast<double>(k)).num("t_end", r.t_end).str("reference", r.description);
      x.num("accuracy", r.accuracy).raw("rows", rows + "]");
      if (!r.failure.empty()) x.str("failure", r.failure);
      refs += std::string(k ? ",\n    " : "\n    ") + x.dump(6);
    }
    j.raw("references", refs + (rep.references.empty() ? "]" : "\n  ]"));
  }
  std::string rows = "[";
  for (std::size_t k = 0; k < rep.rows.size(); ++k)
    rows += std::string(k ? ",\n    " : "\n    ") + sweep_row_json(o, rep.rows[k]);
  j.raw("rows", rows + (rep.rows.empty() ? "]" : "\n  ]"));
  return j.dump() + "\n";
}

std::string write_sweep_table(const SweepOptions& o, const SweepReport& rep, const std::string& path) {
  try {
    // the JSON (what a resumed sweep reads) first
    for (const bool json : {true, false}) {
      const std::string file = path + (json ? ".json" : ".csv");
      const std::string text = json ? sweep_json(o, rep) : sweep_csv(o, rep);
      OutputFile f;
      f.open(file, "--out (" + file + ")", static_cast<double>(text.size()));
      if (std::fwrite(text.data(), 1, text.size(), f.get()) != text.size()) {
        const std::string why = f.finish(false);
        return file + ": the table could not be written" + (why.empty() ? std::string() : ": " + why);
      }
      const std::string why = f.finish(true);
      if (!why.empty()) return why;
    }
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

// ---- reading a table back --------------------------------------------------------------

namespace {

// A JSON value as the table's reader needs it: its kind, its contents, and where its
// text is (the run's object is kept as the text it was written as).
struct JValue {
  enum Kind { null, boolean, number, string, array, object } kind = null;
  bool b = false;
  double x = NAN;
  std::string s;
  std::vector<JValue> items;
  std::vector<std::pair<std::string, JValue>> members;
  std::size_t begin = 0, end = 0;

  const JValue* find(const std::string& key) const {
    for (const auto& [k, v] : members)
      if (k == key) return &v;
    return nullptr;
  }
};

class JReader {
 public:
  JReader(const std::string& text, std::string where) : t_(text), where_(std::move(where)) {}
  JValue document() {
    JValue v = value(0);
    space();
    if (at_ < t_.size()) fail("text after the end of the JSON value");
    return v;
  }

 private:
  [[noreturn]] void fail(const std::string& why) const {
    throw InputError(where_ + ": not a JSON table of dvm sweep (at byte " + std::to_string(at_) + ": " + why + ")");
  }
  void space() {
    while (at_ < t_.size() && (t_[at_] == ' ' || t_[at_] == '\n' || t_[at_] == '\r' || t_[at_] == '\t')) ++at_;
  }
  bool word(const char* w) {
    const std::size_t n = std::strlen(w);
    if (t_.compare(at_, n, w) != 0) return false;
    at_ += n;
    return true;
  }
  JValue value(int depth) {
    if (depth > 64) fail("nested too deeply");
    space();
    if (at_ >= t_.size()) fail("unexpected end");
    JValue v;
    v.begin = at_;
    const char c = t_[at_];
    if (c == '{') {
      v.kind = JValue::object;
      ++at_;
      space();
      if (at_ < t_.size() && t_[at_] == '}') {
        ++at_;
      } else {
        while (true) {
          space();
          if (at_ >= t_.size() || t_[at_] != '"') fail("expected a member name");
          std::string key = string_text();
          space();
          if (at_ >= t_.size() || t_[at_] != ':') fail("expected ':'");
          ++at_;
          v.members.emplace_back(std::move(key), value(depth + 1));
          space();
          if (at_ < t_.size() && t_[at_] == ',') {
            ++at_;
            continue;
          }
          if (at_ < t_.size() && t_[at_] == '}') {
            ++at_;
            break;
          }
          fail("expected ',' or '}'");
        }
      }
    } else if (c == '[') {
      v.kind = JValue::array;
      ++at_;
      space();
      if (at_ < t_.size() && t_[at_] == ']') {
        ++at_;
      } else {
        while (true) {
          v.items.push_back(value(depth + 1));
          space();
          if (at_ < t_.size() && t_[at_] == ',') {
            ++at_;
            continue;
          }
          if (at_ < t_.size() && t_[at_] == ']') {
            ++at_;
            break;
          }
          fail("expected ',' or ']'");
        }
      }
    } else if (c == '"') {
      v.kind = JValue::string;
      v.s = string_text();
    } else if (word("null")) {
      v.kind = JValue::null;
    } else if (word("true")) {
      v.kind = JValue::boolean;
      v.b = true;
    } else if (word("false")) {
      v.kind = JValue::boolean;
    } else {
      const std::size_t start = at_;
      while (at_ < t_.size() && std::strchr("+-0123456789.eE", t_[at_])) ++at_;
      const std::string num = t_.substr(start, at_ - start);
      char* end = nullptr;
      v.kind = JValue::number;
      v.x = std::strtod(num.c_str(), &end);
      if (num.empty() || *end != '\0') fail("expected a value");
    }
    v.end = at_;
    return v;
  }
  static void utf8(std::string& out, unsigned cp) {
    if (cp < 0x80) {
      out += static_cast<char>(cp);
    } else if (cp < 0x800) {
      out += static_cast<char>(0xc0 | (cp >> 6));
      out += static_cast<char>(0x80 | (cp & 0x3f));
    } else {
      out += static_cast<char>(0xe0 | (cp >> 12));
      out += static_cast<char>(0x80 | ((cp >> 6) & 0x3f));
      out += static_cast<char>(0x80 | (cp & 0x3f));
    }
  }
  std::string string_text() {
    ++at_;  // the opening quote
    std::string out;
    while (true) {
      if (at_ >= t_.size()) fail("a string without its closing quote");
      const char c = t_[at_++];
      if (c == '"') return out;
      if (c != '\\') {
        out += c;
        continue;
      }
      if (at_ >= t_.size()) fail("a string without its closing quote");
      const char e = t_[at_++];
      switch (e) {
        case '"': out += '"'; break;
        case '\\': out += '\\'; break;
        case '/': out += '/'; break;
        case 'b': out += '\b'; break;
        case 'f': out += '\f'; break;
        case 'n': out += '\n'; break;
        case 'r': out += '\r'; break;
        case 't': out += '\t'; break;
        case 'u': {
          if (at_ + 4 > t_.size()) fail("a short \\u escape");
          const std::string hex = t_.substr(at_, 4);
          char* end = nullptr;
          const unsigned long cp = std::strtoul(hex.c_str(), &end, 16);
          if (*end != '\0') fail("a bad \\u escape");
          at_ += 4;
          utf8(out, static_cast<unsigned>(cp));
          break;
        }
        default: fail("an unknown escape");
      }
    }
  }
  const std::string& t_;
  std::string where_;
  std::size_t at_ = 0;
};

[[noreturn]] void bad_table(const std::string& where, const std::string& why) {
  throw InputError(where + ": not a JSON table of dvm sweep (" + why + ")");
}

const JValue& member(const JValue& v, const std::string& key, JValue::Kind kind, const std::string& where) {
  const JValue* m = v.kind == JValue::object ? v.find(key) : nullptr;
  if (!m) bad_table(where, "no member '" + key + "'");
  if (m->kind != kind && !(kind == JValue::number && m->kind == JValue::null))
    bad_table(where, "'" + key + "' is not of the expected type");
  return *m;
}
double number_or_nan(const JValue& v, const std::string& key, const std::string& where) {
  const JValue* m = v.find(key);
  if (!m || m->kind == JValue::null) return NAN;
  if (m->kind != JValue::number) bad_table(where, "'" + key + "' is not a number");
  return m->x;
}
std::string text_of(const JValue& v, const std::string& key, const std::string& where) {
  const JValue* m = v.find(key);
  if (!m) return "";
  if (m->kind != JValue::string) bad_table(where, "'" + key + "' is not a string");
  return m->s;
}
std::vector<double> numbers(const JValue* v, const std::string& where) {
  std::vector<double> out;
  if (!v) return out;
  if (v->kind != JValue::array) bad_table(where, "expected an array of numbers");
  for (const JValue& x : v->items) {
    if (x.kind != JValue::number && x.kind != JValue::null) bad_table(where, "expected an array of numbers");
    out.push_back(x.x);
  }
  return out;
}

// A row of the table, as sweep_row_json wrote it.
SweepRow row_from(const SweepOptions& o, const JValue& v, const std::string& text, const std::string& where) {
  if (v.kind != JValue::object) bad_table(where, "a row is not an object");
  const double index = member(v, "index", JValue::number, where).x;
  const std::size_t n = sweep_size(o);
  if (!(index >= 0 && index < static_cast<double>(n) && index == std::floor(index)))
    bad_table(where, "a row index outside the sweep's " + std::to_string(n) + " runs");
  SweepRow row;
  row.index = static_cast<std::size_t>(index);
  const std::string at = where + ", row " + std::to_string(row.index);
  // the row's values are those of its index in this sweep
  const JValue& values = member(v, "values", JValue::object, at);
  if (text.compare(values.begin, values.end - values.begin, row_values_json(o, row.index, 8)) != 0)
    throw InputError(at + ": its values " + text.substr(values.begin, values.end - values.begin) +
                     " are not those of row " + std::to_string(row.index) + " of this sweep " +
                     row_values_json(o, row.index, 8) + "; the table was made by another sweep");
  const std::string status = member(v, "status", JValue::string, at).s;
  if (status == "ok") row.status = RowStatus::ok;
  else if (status == "failed") row.status = RowStatus::failed;
  else if (status == "refused") row.status = RowStatus::refused;
  else bad_table(at, "status '" + status + "'");
  row.code = static_cast<int>(member(v, "code", JValue::number, at).x);
  row.message = member(v, "message", JValue::string, at).s;
  if (o.error) {
    row.error = number_or_nan(v, "error", at);
    if (o.max_error) row.max_error = number_or_nan(v, "max_error", at);
    row.reference_accuracy = number_or_nan(v, "reference_accuracy", at);
    const double reference = number_or_nan(v, "reference", at);
    row.reference = std::isnan(reference) ? -1 : static_cast<int>(reference);
    const JValue* f = v.find("final_state");
    if (f && f->kind == JValue::object) {
      row.final_state.q = numbers(f->find("q"), at);
      row.final_state.p = numbers(f->find("p"), at);
    }
  }
  const JValue* run = v.find("run");
  if (!run) bad_table(at, "no member 'run'");
  if (run->kind == JValue::object) {
    row.ran = true;
    row.cpu_seconds = number_or_nan(v, "cpu_seconds", at);
    row.run_json = text.substr(run->begin, run->end - run->begin);
    RunReport& r = row.report;
    r.failed = text_of(*run, "status", at) == "failed";
    r.boundary_value = text_of(*run, "problem", at) == "boundary-value";
    r.system = text_of(*run, "system", at);
    r.map = text_of(*run, "map", at);
    r.method = text_of(*run, "method", at);
    r.composition = text_of(*run, "composition", at);
    r.form = text_of(*run, "form", at);
    r.step = number_or_nan(*run, "step", at);
    r.steps = static_cast<std::int64_t>(number_or_nan(*run, "steps", at));
    const double requested = number_or_nan(*run, "steps_requested", at);
    r.steps_requested = std::isnan(requested) ? 0 : static_cast<std::int64_t>(requested);
    r.t_final = number_or_nan(*run, "t_final", at);
    r.wall_seconds = number_or_nan(*run, "wall_seconds", at);
    r.energy_initial = number_or_nan(*run, "energy_initial", at);
    r.energy_final = number_or_nan(*run, "energy_final", at);
    r.max_abs_energy_error = number_or_nan(*run, "max_abs_energy_error", at);
    if (const JValue* f = run->find("forced"); f && f->kind == JValue::boolean && f->b) {
      r.forced = true;
      r.work = number_or_nan(*run, "work", at);
      r.max_abs_energy_balance = number_or_nan(*run, "max_abs_energy_balance", at);
    }
    if (const JValue* c = run->find("constrained"); c && c->kind == JValue::boolean && c->b) {
      r.constrained = true;
      r.constraints = static_cast<int>(number_or_nan(*run, "constraints", at));
      r.max_constraint_residual = number_or_nan(*run, "max_constraint_residual", at);
      r.max_hidden_constraint_residual = number_or_nan(*run, "max_hidden_constraint_residual", at);
    }
    r.solver_iterations = static_cast<std::int64_t>(number_or_nan(*run, "solver_iterations", at));
    r.jacobians = static_cast<std::int64_t>(number_or_nan(*run, "jacobians", at));
    const double most = number_or_nan(*run, "max_step_iterations", at);
    r.max_step_iterations = std::isnan(most) ? 0 : static_cast<int>(most);
    const double order = number_or_nan(*run, "order", at);
    r.order = std::isnan(order) ? 0 : static_cast<int>(order);
    r.q_final = numbers(run->find("q_final"), at);
    r.p_final = numbers(run->find("p_final"), at);
    if (const JValue* f = run->find("failure"); f && f->kind == JValue::object) {
      r.loop.failed_step = static_cast<std::int64_t>(number_or_nan(*f, "step", at));
      r.loop.failed_time = number_or_nan(*f, "time", at);
    }
  } else if (run->kind != JValue::null) {
    bad_table(at, "'run' is neither an object nor null");
  }
  // the key of its problem (errors against a reference run)
  if (o.error && row.status == RowStatus::ok) {
    const Scene s = load_row(o, row.index);
    row.t_end = static_cast<double>(s.problem.steps) * s.problem.step;
    row.problem = problem_key(o, row.index, row.t_end);
  }
  // the row must render as it was read
  if (sweep_row_json(o, row) != text.substr(v.begin, v.end - v.begin))
    throw InputError(at + ": the row does not read back as it was written (a table written by another version of "
                     "dvm, or edited)");
  // the references are found again (attach_errors), and the errors against reference
  // runs measured again
  row.reference = -1;
  if (std::isnan(row.reference_accuracy)) row.error = NAN;
  return row;
}

}  // namespace

SweepRow sweep_row_from_json(const SweepOptions& o, const std::string& text) {
  JReader reader(text, "a row of the sweep");
  return row_from(o, reader.document(), text, "a row of the sweep");
}

SweepRows read_sweep_table(const SweepOptions& o, const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError("--resume: cannot read the table " + path);
  std::ostringstream buf;
  buf << in.rdbuf();
  const std::string text = buf.str();
  const std::string where = "--resume: " + path;
  JReader reader(text, where);
  const JValue doc = reader.document();
  if (doc.kind != JValue::object) bad_table(where, "not an object");
  auto raw = [&](const JValue& v) { return text.substr(v.begin, v.end - v.begin); };
  auto differs = [&](const std::string& what, const std::string& table, const std::string& ours) {
    throw InputError(where + " was made by another sweep: " + what + " " + table + " in the table, " + ours +
                     " in this sweep; run it without --resume (or with another --out) to start again");
  };
  if (member(doc, "json_version", JValue::number, where).x != 1) bad_table(where, "json_version is not 1");
  const std::string scene = member(doc, "scene", JValue::string, where).s;
  if (scene != o.scene_path) differs("the scene file is", Json::string(scene), Json::string(o.scene_path));
  const std::string digest = text_of(doc, "scene_digest", where);
  if (digest != scene_digest(o.scene_text))
    differs("the scene's text (its digest) is", Json::string(digest),
            Json::string(scene_digest(o.scene_text)) + " (the file changed since)");
  if (raw(member(doc, "set", JValue::array, where)) != set_json(o))
    differs("--set is", raw(*doc.find("set")), set_json(o));
  const JValue& vary = member(doc, "vary", JValue::array, where);
  std::string keys = "[", our_keys = "[";
  for (std::size_t a = 0; a < vary.items.size(); ++a)
    keys += (a ? ", " : "") + Json::string(member(vary.items[a], "key", JValue::string, where).s);
  for (std::size_t a = 0; a < o.axes.size(); ++a) our_keys += (a ? ", " : "") + Json::string(o.axes[a].key);
  if (keys + "]" != our_keys + "]") differs("the varied keys are", keys + "]", our_keys + "]");
  for (std::size_t a = 0; a < o.axes.size(); ++a) {
    const std::string values = raw(member(vary.items[a], "values", JValue::array, where));
    if (values != values_json(o.axes[a]))
      differs("the values of --vary " + o.axes[a].key + " are", values, values_json(o.axes[a]));
  }
  const std::string combine = member(doc, "combine", JValue::string, where).s;
  if (combine != (o.zip ? "zip" : "product"))
    differs("the combination (--zip or not) is", combine, o.zip ? "zip" : "product");
  if (raw(member(doc, "errors", JValue::array, where)) != errors_json(o))
    differs("the errors measured (--error, --max-error) are", raw(*doc.find("errors")), errors_json(o));
  const std::size_t n = sweep_size(o);
  if (member(doc, "runs", JValue::number, where).x != static_cast<double>(n))
    bad_table(where, "'runs' is not the sweep's number of runs");
  SweepRows out;
  out.rows.resize(n);
  out.have.assign(n, 0);
  for (const JValue& r : member(doc, "rows", JValue::array, where).items) {
    SweepRow row = row_from(o, r, text, where);
    if (out.have[row.index]) bad_table(where, "row " + std::to_string(row.index) + " twice");
    out.have[row.index] = 1;
    out.rows[row.index] = std::move(row);
  }
  return out;
}

// ---- a table as cells (dvm chart) ------------------------------------------------------

int SweepCells::column(const std::string& name) const {
  for (std::size_t k = 0; k < head.size(); ++k)
    if (head[k] == name) return static_cast<int>(k);
  return -1;
}

namespace {

// RFC 4180 CSV: cells in double quotes may hold commas, quotes (doubled) and newlines.
std::vector<std::vector<std::string>> csv_records(const std::string& text, const std::string& where) {
  std::vector<std::vector<std::string>> records;
  std::vector<std::string> cells;
  std::string cell;
  bool quoted = false, any = false;
  for (std::size_t k = 0; k < text.size(); ++k) {
    const char c = text[k];
    if (quoted) {
      if (c == '"' && k + 1 < text.size() && text[k + 1] == '"') cell += '"', ++k;
      else if (c == '"') quoted = false;
      else cell += c;
    } else if (c == '"') {
      quoted = true;
      any = true;
    } else if (c == ',') {
      cells.push_back(cell), cell.clear();
      any = true;
    } else if (c == '\n' || c == '\r') {
      if (c == '\r' && k + 1 < text.size() && text[k + 1] == '\n') ++k;
      if (any || !cell.empty()) cells.push_back(cell), records.push_back(cells);
      cells.clear(), cell.clear(), any = false;
    } else {
      cell += c;
      any = true;
    }
  }
  if (quoted) throw InputError(where + ": not a CSV table of dvm sweep (a quoted cell without its closing quote)");
  if (any || !cell.empty()) cells.push_back(cell), records.push_back(cells);
  return records;
}

}  // namespace

SweepCells read_sweep_cells(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path + ": is a directory; expected a table of dvm sweep");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot read the table");
  std::ostringstream buf;
  buf << in.rdbuf();
  const std::string text = buf.str();
  SweepCells t;
  const std::size_t first = text.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) throw InputError(path + ": empty; expected a table of dvm sweep (CSV or JSON)");
  if (text[first] != '{') {
    auto records = csv_records(text, path);
    t.head = records.front();
    if (t.head.empty() || t.head.front() != "index" || t.column("status") < 0)
      throw InputError(path + ": not a CSV table of dvm sweep (its header does not start with index and has no "
                       "status column)");
    for (int k = 1; k < t.column("status"); ++k) t.varied.push_back(t.head[static_cast<std::size_t>(k)]);
    for (std::size_t r = 1; r < records.size(); ++r) {
      if (records[r].size() != t.head.size())
        throw InputError(path + ": not a CSV table of dvm sweep (record " + std::to_string(r + 1) + " has " +
                         std::to_string(records[r].size()) + " cells, the header " + std::to_string(t.head.size()) +
                         ")");
      t.rows.push_back(std::move(records[r]));
    }
    return t;
  }
  const std::string& where = path;
  JReader reader(text, where);
  const JValue doc = reader.document();
  if (doc.kind != JValue::object) bad_table(where, "not an object");
  auto cell = [&](const JValue* v) -> std::string {
    if (!v || v->kind == JValue::null) return "";
    if (v->kind == JValue::string) return v->s;
    if (v->kind == JValue::boolean) return v->b ? "true" : "false";
    return text.substr(v->begin, v->end - v->begin);
  };
  for (const JValue& a : member(doc, "vary", JValue::array, where).items)
    t.varied.push_back(member(a, "key", JValue::string, where).s);
  std::vector<std::string> errors;
  if (const JValue* e = doc.find("errors"); e && e->kind == JValue::array)
    for (const JValue& x : e->items) errors.push_back(cell(&x));
  const auto& rows = member(doc, "rows", JValue::array, where).items;
  std::size_t nq = 0, np = 0;
  for (const JValue& r : rows)
    if (const JValue* run = r.find("run"); run && run->kind == JValue::object) {
      if (const JValue* q = run->find("q_final"); q && q->kind == JValue::array) nq = std::max(nq, q->items.size());
      if (const JValue* p = run->find("p_final"); p && p->kind == JValue::array) np = std::max(np, p->items.size());
    }
  t.head = {"index"};
  for (const std::string& k : t.varied) t.head.push_back(k);
  for (const char* c : {"status", "code", "message"}) t.head.push_back(c);
  for (const std::string& e : errors) t.head.push_back(e);
  for (const char* c : kRunColumns) t.head.push_back(c);
  for (std::size_t k = 0; k < nq; ++k) t.head.push_back("q_final[" + std::to_string(k) + "]");
  for (std::size_t k = 0; k < np; ++k) t.head.push_back("p_final[" + std::to_string(k) + "]");
  for (const JValue& r : rows) {
    if (r.kind != JValue::object) bad_table(where, "a row is not an object");
    std::vector<std::string> c = {cell(&member(r, "index", JValue::number, where))};
    const JValue& values = member(r, "values", JValue::object, where);
    for (const std::string& k : t.varied) c.push_back(cell(values.find(k)));
    c.push_back(member(r, "status", JValue::string, where).s);
    c.push_back(cell(r.find("code")));
    c.push_back(cell(r.find("message")));
    for (const std::string& e : errors) c.push_back(cell(r.find(e)));
    const JValue* run = r.find("run");
    if (run && run->kind == JValue::object) {
      const JValue* failure = run->find("failure");
      if (failure && failure->kind != JValue::object) failure = nullptr;
      for (const std::string f : kRunColumns) {
        if (f == "cpu_seconds")
          c.push_back(cell(r.find(f)));
        else if (f == "failed_step" || f == "failed_time")
          c.push_back(failure ? cell(failure->find(f == "failed_step" ? "step" : "time")) : "");
        else
          c.push_back(cell(run->find(f)));
      }
      auto components = [&](const char* name, std::size_t n) {
        const JValue* v = run->find(name);
        for (std::size_t k = 0; k < n; ++k)
          c.push_back(v && v->kind == JValue::array && k < v->items.size() ? cell(&v->items[k]) : "");
      };
      components("q_final", nq);
      components("p_final", np);
    }
    c.resize(t.head.size());
    t.rows.push_back(std::move(c));
  }
  return t;
}

// ---- ranks (MPI) ---------------------------------------------------------------------

bool launched_by_mpirun() { return std::getenv("OMPI_COMM_WORLD_SIZE") != nullptr; }

#ifdef DVM_WITH_MPI

bool sweep_mpi_built() { return true; }

SweepRanks::SweepRanks() {
  if (!launched_by_mpirun()) return;
  // A rank waiting in MPI (a worker for its next row, a rank that has finished) yields
  // its core instead of spinning on it, which slows the rows that the other ranks and
  // threads run on the same cores (bench_sweep_mpi.sh measures the ranks' parallel
  // efficiency). A value the user set for this OpenMPI parameter stays.
  setenv("OMPI_MCA_mpi_yield_when_idle", "1", 0);
  // only the main thread calls MPI (the other threads run rows)
  int provided = 0;
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  mpi_ = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

SweepRanks::~SweepRanks() {
  if (mpi_) MPI_Finalize();
}

std::string SweepRanks::share(const std::string& on_rank0) const {
  if (!mpi_) return on_rank0;
  unsigned long long n = on_rank0.size();
  MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD);
  std::string text = rank_ == 0 ? on_rank0 : std::string(n, '\0');
  // in pieces that an int counts
  for (unsigned long long at = 0; at < n; at += 1ull << 30) {
    const int piece = static_cast<int>(std::min<unsigned long long>(n - at, 1ull << 30));
    MPI_Bcast(text.data() + at, piece, MPI_CHAR, 0, MPI_COMM_WORLD);
  }
  return text;
}

int SweepRanks::share(int on_rank0) const {
  int v = on_rank0;
  if (mpi_) MPI_Bcast(&v, 1, MPI_INT, 0, MPI_COMM_WORLD);
  return v;
}

void SweepRanks::abort(int code) const {
  if (mpi_) MPI_Abort(MPI_COMM_WORLD, code);
  std::exit(code);
}

namespace {

constexpr int kTagAsk = 1;    // worker -> 0: the text of the row it ran ("" at first)
constexpr int kTagIndex = 2;  // 0 -> worker: the next row to run, or -1: none left

// Rank 0's side: answers the other ranks' threads (`jobs` on each) until each has
// been told that no row is left, taking rows from `next` as its own threads do.
void serve(const SweepOptions& o, const std::vector<long long>& runs, std::atomic<std::size_t>& next,
           Gather& gather, int ranks, int jobs) {
  int working = (ranks - 1) * jobs;
  std::string text;
  while (working > 0) {
    int waiting = 0;
    MPI_Status st;
    MPI_Iprobe(MPI_ANY_SOURCE, kTagAsk, MPI_COMM_WORLD, &waiting, &st);
    if (!waiting) {
      // (OpenMPI's blocking receive would spin on a core that rank 0's rows need)
      const timespec pause{0, 200000};
      nanosleep(&pause, nullptr);
      continue;
    }
    int length = 0;
    MPI_Get_count(&st, MPI_CHAR, &length);
    text.assign(static_cast<std::size_t>(length), '\0');
    MPI_Recv(text.data(), length, MPI_CHAR, st.MPI_SOURCE, kTagAsk, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (!text.empty()) gather.add(sweep_row_from_json(o, text));
    const std::size_t t = next++;
    const long long index = t < runs.size() ? runs[t] : -1;
    MPI_Send(&index, 1, MPI_LONG_LONG, st.MPI_SOURCE, kTagIndex, MPI_COMM_WORLD);
    if (index < 0) --working;
  }
}

// One question to rank 0: the text of the row run ("" at first); the answer is the
// next row to run, or -1.
long long ask(const std::string& text) {
  MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, 0, kTagAsk, MPI_COMM_WORLD);
  long long index = -1;
  MPI_Recv(&index, 1, MPI_LONG_LONG, 0, kTagIndex, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
  return index;
}

// The other ranks' side: ask, run, send the row back with the next question. With
// `jobs` threads, the main thread (the only one that calls MPI) asks once for each
// thread, then once for each row a thread finishes, and hands the answers to the
// threads; a thread told -1 ends.
void work(const SweepOptions& o, int jobs) {
  if (jobs <= 1) {
    std::string text;
    for (long long index = ask(text); index >= 0; index = ask(text))
      text = sweep_row_json(o, run_row(o, static_cast<std::size_t>(index)));
    return;
  }
  std::mutex lock;
  std::condition_variable changed;
  std::deque<long long> todo;      // answers, for the threads
  std::deque<std::string> done;    // rows run, for the main thread to send
#pragma omp parallel num_threads(jobs + 1)
  {
    if (omp_get_thread_num() == 0) {
      int ended = 0;  // threads told -1
      for (int k = 0; k < jobs; ++k) {
        const long long index = ask("");
        ended += index < 0;
        std::lock_guard<std::mutex> g(lock);
        todo.push_back(index);
        changed.notify_all();
      }
      while (ended < jobs) {
        std::string text;
        {
          std::unique_lock<std::mutex> g(lock);
          changed.wait(g, [&] { return !done.empty(); });
          text = std::move(done.front());
          done.pop_front();
        }
        const long long index = ask(text);
        ended += index < 0;
        std::lock_guard<std::mutex> g(lock);
        todo.push_back(index);
        changed.notify_all();
      }
    } else {
      while (true) {
        long long index = -1;
        {
          std::unique_lock<std::mutex> g(lock);
          changed.wait(g, [&] { return !todo.empty(); });
          index = todo.front();
          todo.pop_front();
        }
        if (index < 0) break;
        std::string text = sweep_row_json(o, run_row(o, static_cast<std::size_t>(index)));
        std::lock_guard<std::mutex> g(lock);
        done.push_back(std::move(text));
        changed.notify_all();
      }
    }
  }
}

}  // namespace

SweepReport run_sweep(const SweepOptions& o, const SweepRows& done, const SweepFlush& flush, const SweepRanks& ranks) {
  if (ranks.size() == 1) return run_sweep(o, done, flush);
  const int jobs = std::max(1, o.jobs);
  if (ranks.rank() != 0) {
    if (ranks.share(0) == 1) {  // rank 0 found no bad input
      match_thread_stacks();
      work(o, jobs);
    }
    return SweepReport{};
  }
  const std::size_t n = sweep_size(o);
  match_thread_stacks();
  const std::vector<long long> todo = rows_to_run(n, done);
  // 1. checked on rank 0 alone; the other ranks wait for the outcome
  std::vector<std::string> refusals;
  try {
    refusals = check_rows(o, done, todo, 1);
  } catch (...) {
    ranks.share(0);
    throw;
  }
  ranks.share(1);
  // 2. refused rows at once; the others handed out one at a time
  Gather gather(n, done, flush);
  std::vector<long long> runs;
  for (long long k : todo) {
    if (refusals[static_cast<std::size_t>(k)].empty())
      runs.push_back(k);
    else
      gather.add(refused_row(static_cast<std::size_t>(k), refusals[static_cast<std::size_t>(k)]));
  }
  std::atomic<std::size_t> next{0};
  std::string failure;
#pragma omp parallel num_threads(jobs + 1)
  {
    if (omp_get_thread_num() == 0) {
      try {
        serve(o, runs, next, gather, ranks.size(), jobs);
      } catch (const std::exception& e) {
        failure = e.what();
      }
    } else {
      for (std::size_t t = next++; t < runs.size(); t = next++)
        gather.add(run_row(o, static_cast<std::size_t>(runs[t])));
    }
  }
  if (!failure.empty()) {
    std::fprintf(stderr, "dvm: internal error: sweep: a row from another rank: %s\n", failure.c_str());
    ranks.abort(3);
  }
  SweepReport rep = gather.finish();
  // 3. errors against references, on rank 0
  if (o.error) attach_errors(o, rep.rows, rep.references);
  return rep;
}

#else

bool sweep_mpi_built() { return false; }

SweepRanks::SweepRanks() {
  if (launched_by_mpirun())
    throw InputError("sweep: started by mpirun (OMPI_COMM_WORLD_SIZE is set), but this dvm was built without MPI; "
                     "rebuild with Debian's libopenmpi-dev installed, or run without mpirun (--jobs N threads)");
}
SweepRanks::~SweepRanks() = default;
std::string SweepRanks::share(const std::string& on_rank0) const { return on_rank0; }
int SweepRanks::share(int on_rank0) const { return on_rank0; }
void SweepRanks::abort(int code) const { std::exit(code); }

SweepReport run_sweep(const SweepOptions& o, const SweepRows& done, const SweepFlush& flush, const SweepRanks&) {
  return run_sweep(o, done, flush);
}

#endif

}  // namespace dvm
