#include "solvers/runtime/sweep.h"

#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include <omp.h>
#include <toml++/toml.h>

#include "solvers/runtime/errors.h"
#include "solvers/runtime/json.h"
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

}  // namespace

std::string check_row(const SweepOptions& o, std::size_t i) {
  try {
    const Scene s = load_row(o, i);
    make_run(s.problem, s.method);
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
    const double cpu0 = thread_cpu_seconds();
    row.report = run->execute(&recorder);
    row.cpu_seconds = thread_cpu_seconds() - cpu0;
    row.ran = true;
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

SweepReport run_sweep(const SweepOptions& o) {
  const std::size_t n = sweep_size(o);
  match_thread_stacks();
  const int jobs = std::max(1, o.jobs);
  const long long count = static_cast<long long>(n);

  // 1. every row read and built, none run
  std::vector<std::string> refusals(n);
  {
    Progress progress("checked", n);
#pragma omp parallel for schedule(dynamic, 1) num_threads(jobs)
    for (long long i = 0; i < count; ++i) {
      refusals[static_cast<std::size_t>(i)] = check_row(o, static_cast<std::size_t>(i));
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

  // 2. the runs
  SweepReport rep;
  rep.runs = n;
  rep.rows.resize(n);
  {
    Progress progress("ran", n);
#pragma omp parallel for schedule(dynamic, 1) num_threads(jobs)
    for (long long i = 0; i < count; ++i) {
      const std::size_t k = static_cast<std::size_t>(i);
      if (refusals[k].empty()) {
        rep.rows[k] = run_row(o, k);
      } else {
        SweepRow& row = rep.rows[k];
        row.index = k;
        row.status = RowStatus::refused;
        row.code = 2;
        row.message = refusals[k];
      }
      progress.done_one();
    }
  }
  for (const SweepRow& row : rep.rows) {
    rep.ok += row.status == RowStatus::ok;
    rep.failed += row.status == RowStatus::failed;
    rep.refused += row.status == RowStatus::refused;
  }

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
      exact.push_back(!std::isnan(row.error));
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

}  // namespace

std::string sweep_csv(const SweepOptions& o, const SweepReport& rep) {
  std::size_t nq = 0, np = 0;
  for (const SweepRow& r : rep.rows)
    if (r.ran) nq = std::max(nq, r.report.q_final.size()), np = std::max(np, r.report.p_final.size());
  std::vector<std::string> head = {"index"};
  for (const SweepAxis& a : o.axes) head.push_back(a.key);
  for (const char* c : {"status", "code", "message"}) head.push_back(c);
  if (o.error) head.push_back("error");
  for (const char* c : {"system", "map", "form", "composition", "method", "step", "steps", "t_final", "wall_seconds",
                        "cpu_seconds", "energy_initial", "energy_final", "max_abs_energy_error", "solver_iterations",
                        "jacobians", "max_step_iterations", "order", "failed_step", "failed_time"})
    head.push_back(c);
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
    const RunReport& r = row.report;
    if (row.ran) {
      const bool failed = r.failed && !r.boundary_value;
      for (const std::string& s :
           {r.system, r.map, r.form, r.composition, r.method, num17(r.step), integer(r.steps), num17(r.t_final),
            num17(r.wall_seconds), num17(row.cpu_seconds), num17(r.energy_initial), num17(r.energy_final),
            num17(r.max_abs_energy_error), integer(r.solver_iterations), integer(r.jacobians),
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

std::string sweep_json(const SweepOptions& o, const SweepReport& rep) {
  Json::Object j;
  j.num("json_version", 1).str("scene", o.scene_path);
  std::string sets = "[";
  for (std::size_t k = 0; k < o.sets.size(); ++k) sets += (k ? ", " : "") + Json::string(o.sets[k]);
  j.raw("set", sets + "]");
  std::string vary = "[";
  for (std::size_t a = 0; a < o.axes.size(); ++a) {
    std::string values = "[";
    for (std::size_t v = 0; v < o.axes[a].values.size(); ++v) values += (v ? ", " : "") + o.axes[a].values[v].json;
    Json::Object x;
    x.str("key", o.axes[a].key).str("spec", o.axes[a].spec).raw("values", values + "]");
    vary += std::string(a ? ", " : "") + x.dump(6);
  }
  j.raw("vary", vary + "]").str("combine", o.zip ? "zip" : "product");
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
  for (std::size_t k = 0; k < rep.rows.size(); ++k) {
    const SweepRow& row = rep.rows[k];
    Json::Object x;
    x.num("index", static_cast<double>(row.index));
    Json::Object values;
    const std::vector<std::size_t> at = sweep_values(o, row.index);
    for (std::size_t a = 0; a < o.axes.size(); ++a) values.raw(o.axes[a].key, o.axes[a].values[at[a]].json);
    x.raw("values", values.dump(8)).str("status", to_string(row.status)).num("code", row.code);
    x.str("message", row.message);
    if (o.error) x.num("error", row.error).raw("reference", row.reference < 0 ? "null" : std::to_string(row.reference));
    x.raw("cpu_seconds", row.ran ? Json::number(row.cpu_seconds) : "null");
    x.raw("run", row.ran ? report_json(row.report) : "null");
    rows += std::string(k ? ",\n    " : "\n    ") + x.dump(6);
  }
  j.raw("rows", rows + (rep.rows.empty() ? "]" : "\n  ]"));
  return j.dump() + "\n";
}

}  // namespace dvm
