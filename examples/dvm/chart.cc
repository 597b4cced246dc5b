// dvm chart: a chart of a table of dvm sweep, drawn by gnuplot.
//
// The table's rows become points, grouped into lines by the values of some columns
// (--by), and four kinds of chart read them:
//
//   work-precision  y (error) against x (cpu_seconds), both logarithmic: a line per
//                   method, a point per step size joined in the order of the step;
//                   lower left is better
//   error-h         y (error) against x (step): the slope is the order
//   stability       over a parameter x, the largest stable step: among the rows of
//                   one x (and one line), sorted by step h, the largest h whose row
//                   and every row of a smaller h are stable; a row is unstable when
//                   it failed (status failed: the solver gave up) or, with
//                   --max-energy-error E, when its max_abs_energy_error is above E
//                   or not finite (a run that blew up). The smallest unstable h is
//                   drawn too: the boundary lies between the two
//   heat            z (error) over the grid of x (step) and y (a parameter), one
//                   cell per row, failed rows marked
//
// The data (NAME.dat) and the script (NAME.gp) are written beside the chart
// (NAME.png or NAME.svg), and gnuplot runs the script in that folder, so that the
// chart can be drawn again from the two files alone.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "examples/dvm/commands.h"
#include "solvers/runtime/errors.h"
#include "solvers/runtime/output.h"
#include "solvers/runtime/sweep.h"

namespace dvm::cli {

const std::vector<std::string>& chart_kinds() {
  static const std::vector<std::string> kinds = {"work-precision", "error-h", "stability", "heat"};
  return kinds;
}

namespace {

// A cell as a number: the whole cell a number, or a list of one number ("[0.5]",
// initial.q of one coordinate).
bool number_cell(const std::string& cell, double& x) {
  std::string s = cell;
  if (s.size() >= 2 && s.front() == '[' && s.back() == ']') {
    s = s.substr(1, s.size() - 2);
    const auto a = s.find_first_not_of(' '), b = s.find_last_not_of(' ');
    s = a == std::string::npos ? "" : s.substr(a, b - a + 1);
  }
  if (s.empty() || s.find(',') != std::string::npos) return false;
  char* end = nullptr;
  x = std::strtod(s.c_str(), &end);
  return *end == '\0';
}
double num(const std::string& s) {
  double x = NAN;
  return number_cell(s, x) ? x : NAN;
}

std::string num17(double x) {
  if (std::isnan(x)) return "NaN";
  if (std::isinf(x)) return x > 0 ? "Inf" : "-Inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

// A string for gnuplot's data files and scripts: in double quotes, without the
// characters that would end it.
std::string gp_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) out += (c == '"' || c == '\\' || c == '\n' || c == '\r') ? '\'' : c;
  return out + "\"";
}

// The keys of the step size a sweep varies: along a line, not lines of their own.
bool step_key(const std::string& k) {
  return k == "integrator.step" || k == "integrator.steps" || k == "integrator.t_end" || k == "step" || k == "steps";
}

std::string join(const std::vector<std::string>& v, const std::string& sep) {
  std::string out;
  for (std::size_t k = 0; k < v.size(); ++k) out += (k ? sep : "") + v[k];
  return out;
}

class Chart {
 public:
  Chart(const ChartOptions& o) : o_(o), t_(read_sweep_cells(o.table)) {}

  int draw();

 private:
  // The column, or InputError naming the option and the columns there are.
  std::size_t col(const std::string& name, const std::string& option, const std::string& why = "") const {
    const int k = t_.column(name);
    if (k >= 0) return static_cast<std::size_t>(k);
    std::vector<std::string> shown;
    for (const std::string& h : t_.head)
      if (h.rfind("q_final[", 0) != 0 && h.rfind("p_final[", 0) != 0) shown.push_back(h);
    throw InputError("chart: " + option + ": the table " + o_.table + " has no column '" + echo(name) + "'" + why +
                     did_you_mean(name, t_.head) + "; its columns: " + join(shown, ", ") +
                     ", q_final[k], p_final[k]");
  }
  // The rows --where keeps.
  std::vector<std::size_t> kept() const {
    std::vector<std::pair<std::size_t, std::string>> conditions;
    for (const auto& [key, value] : o_.where) conditions.emplace_back(col(key, "--where " + key), value);
    std::vector<std::size_t> rows;
    for (std::size_t r = 0; r < t_.rows.size(); ++r) {
      bool keep = true;
      for (const auto& [c, value] : conditions) {
        const std::string& cell = t_.rows[r][c];
        double a = 0, b = 0;
        keep = keep && (cell == value || (number_cell(cell, a) && number_cell(value, b) && a == b));
      }
      if (keep) rows.push_back(r);
    }
    if (rows.empty())
      throw InputError("chart: no row of " + o_.table + " is left by --where; expected values the table holds");
    return rows;
  }
  // The lines: --by, else the varied keys that are not an axis or a step key.
  std::vector<std::size_t> by_columns(const std::vector<std::string>& axes) const {
    std::vector<std::size_t> out;
    if (o_.by_given) {
      for (const std::string& k : o_.by) out.push_back(col(k, "--by"));
      return out;
    }
    for (const std::string& k : t_.varied) {
      if (step_key(k) || std::find(axes.begin(), axes.end(), k) != axes.end()) continue;
      bool fixed = false;
      for (const auto& w : o_.where) fixed = fixed || w.first == k;
      if (!fixed) out.push_back(col(k, "--by"));
    }
    return out;
  }
  std::string label(std::size_t r, const std::vector<std::size_t>& by) const {
    if (by.empty()) return "runs";
    std::vector<std::string> parts;
    for (std::size_t c : by)
      parts.push_back(by.size() == 1 ? t_.rows[r][c] : t_.head[c] + "=" + t_.rows[r][c]);
    return join(parts, ", ");
  }
  // The row's line, in the order of first appearance.
  std::size_t group_of(std::size_t r, const std::vector<std::size_t>& by) {
    const std::string l = label(r, by);
    for (std::size_t g = 0; g < groups_.size(); ++g)
      if (groups_[g] == l) return g;
    groups_.push_back(l);
    return groups_.size() - 1;
  }
  bool ok(std::size_t r) const { return t_.rows[r][status_] == "ok"; }
  bool logged(char axis, const std::string& fallback) const {
    const std::string& l = o_.log.empty() ? fallback : o_.log;
    return l.find(axis) != std::string::npos;
  }

  int lines(const std::string& x, const std::string& y, const std::string& why_y);
  int stability();
  int heat();
  int finish(const std::string& data, const std::string& script_body, std::size_t points);

  const ChartOptions& o_;
  SweepCells t_;
  std::size_t status_ = 0;
  std::vector<std::string> groups_;
  std::string stem_, name_;  // the chart's path without its extension, and its file name
};

int Chart::draw() {
  status_ = col("status", "TABLE");
  const std::string ext = std::filesystem::path(o_.out).extension().string();
  stem_ = o_.out.substr(0, o_.out.size() - ext.size());
  name_ = std::filesystem::path(stem_).filename().string();
  if (o_.kind == "work-precision")
    return lines(o_.x.empty() ? "cpu_seconds" : o_.x, o_.y.empty() ? "error" : o_.y,
                 ": a work-precision chart needs each run's error, measured by dvm sweep --error");
  if (o_.kind == "error-h")
    return lines(o_.x.empty() ? "step" : o_.x, o_.y.empty() ? "error" : o_.y,
                 ": an error-h chart needs each run's error, measured by dvm sweep --error");
  if (o_.kind == "stability") return stability();
  return heat();
}

// The gnuplot lines of the script's start: the terminal by the extension.
std::string preamble(const std::string& name, const std::string& ext, const std::string& title, int width,
                     int height) {
  std::string s = "# drawn by dvm chart; to draw it again, in this folder: gnuplot " + name + ".gp\n";
  s += ext == ".svg" ? "set terminal svg size " : "set terminal pngcairo size ";
  s += std::to_string(width) + "," + std::to_string(height) + " font \",10\"\n";
  s += "set output " + gp_string(name + ext) + "\n";
  s += "set title " + gp_string(title) + " noenhanced\n";
  s += "set datafile missing \"NaN\"\n";
  s += "set grid\n";
  return s;
}

int Chart::lines(const std::string& x, const std::string& y, const std::string& why_y) {
  const std::size_t xc = col(x, "--x"), yc = col(y, "--y", y == "error" ? why_y : "");
  const std::vector<std::size_t> by = by_columns({x, y});
  // a line joins its points in the order of the step (else of x)
  const int sc = t_.column("step");
  const std::string along = sc >= 0 ? "step" : x;
  std::vector<std::vector<std::array<double, 3>>> points;  // (along, x, y)
  std::size_t drawn = 0, left_out = 0;
  for (std::size_t r : kept()) {
    const double a = num(t_.rows[r][xc]), b = num(t_.rows[r][yc]);
    const std::size_t g = group_of(r, by);
    if (points.size() < groups_.size()) points.resize(groups_.size());
    const bool usable = ok(r) && std::isfinite(a) && std::isfinite(b) && (!logged('x', "xy") || a > 0) &&
                        (!logged('y', "xy") || b > 0);
    if (!usable) {
      ++left_out;
      continue;
    }
    points[g].push_back({sc >= 0 ? num(t_.rows[r][static_cast<std::size_t>(sc)]) : a, a, b});
    ++drawn;
  }
  if (drawn == 0)
    throw InputError("chart: no row of " + o_.table + " has status ok and finite " + x + " and " + y +
                     (logged('x', "xy") || logged('y', "xy") ? " (> 0 on a logarithmic axis)" : "") +
                     "; nothing to draw");
  std::string data = "# dvm chart --kind " + o_.kind + " of " + o_.table + ": " + x + " against " + y +
                     "; one block per line (" + (by.empty() ? std::string("every row") : "by ");
  std::vector<std::string> by_names;
  for (std::size_t c : by) by_names.push_back(t_.head[c]);
  data += join(by_names, ", ") + "), its title first, then " + x + " and " + y + " of each row, in the order of " +
          along + "\n";
  data += "# rows left out (not ok, or no finite value to draw): " + std::to_string(left_out) + "\n";
  std::size_t blocks = 0;
  for (std::size_t g = 0; g < groups_.size(); ++g) {
    if (points[g].empty()) continue;
    std::stable_sort(points[g].begin(), points[g].end(), [](const auto& a, const auto& b) { return a[0] < b[0]; });
    data += std::string(blocks ? "\n\n" : "") + gp_string(groups_[g]) + "\n";
    for (const auto& p : points[g]) data += num17(p[1]) + " " + num17(p[2]) + "\n";
    ++blocks;
  }
  const std::string title =
      o_.title.empty() ? (o_.kind == "work-precision" ? "work precision: " : "error against step: ") + y +
                             " against " + x + " (" + std::filesystem::path(o_.table).filename().string() + ")"
                       : o_.title;
  std::string s = preamble(name_, std::filesystem::path(o_.out).extension().string(), title, 1000, 640);
  if (logged('x', "xy")) s += "set logscale x\nset format x \"%.0e\"\n";
  if (logged('y', "xy")) s += "set logscale y\nset format y \"%.0e\"\n";
  s += "set xlabel " + gp_string(x) + " noenhanced\nset ylabel " + gp_string(y) + " noenhanced\n";
  s += by.empty() ? "unset key\n" : "set key outside right top noenhanced font \",9\"\n";
  s += "plot for [i=0:" + std::to_string(blocks - 1) + "] " + gp_string(name_ + ".dat") +
       " index i using 1:2 with linespoints lt (i + 1) pt (i % 13 + 1) ps 0.8 title columnheader(1)\n";
  return finish(data, s, drawn);
}

int Chart::stability() {
  const std::string h = o_.y.empty() ? "step" : o_.y;
  const std::size_t hc = col(h, "--y", " (the step whose largest stable value is drawn)");
  const std::size_t ec = std::isnan(o_.max_energy_error) ? 0 : col("max_abs_energy_error", "--max-energy-error");
  // the parameter: --x, else the one varied key that is not a step key nor a line
  std::string x = o_.x;
  if (x.empty()) {
    std::vector<std::string> candidates;
    for (const std::string& k : t_.varied) {
      bool other = step_key(k) || k == h || std::find(o_.by.begin(), o_.by.end(), k) != o_.by.end();
      for (const auto& w : o_.where) other = other || w.first == k;
      if (!other) candidates.push_back(k);
    }
    if (candidates.size() != 1)
      throw InputError("chart: --x: a stability chart draws the largest stable step over a parameter; the table " +
                       o_.table + " varies " + (candidates.empty() ? std::string("none but the step") : join(candidates, ", ")) +
                       " besides the step: name the parameter with --x (and the lines with --by)");
    x = candidates.front();
  }
  const std::size_t xc = col(x, "--x");
  const std::vector<std::size_t> by = by_columns({x, h});
  // per line and parameter value: (h, stable) of each row
  std::vector<std::vector<std::string>> xs;  // per line, the parameter values in order of first appearance
  std::vector<std::map<std::string, std::vector<std::pair<double, bool>>>> runs;
  bool categorical = false;
  std::size_t used = 0;
  for (std::size_t r : kept()) {
    const std::string& status = t_.rows[r][status_];
    if (status == "refused") continue;
    const double step = num(t_.rows[r][hc]);
    if (!(std::isfinite(step) && step > 0)) continue;  // a refused or odd row: no step to place it at
    const std::size_t g = group_of(r, by);
    if (xs.size() < groups_.size()) xs.resize(groups_.size()), runs.resize(groups_.size());
    const std::string& v = t_.rows[r][xc];
    double a = 0;
    categorical = categorical || !number_cell(v, a);
    if (!runs[g].count(v)) xs[g].push_back(v);
    bool stable = status == "ok";
    if (stable && !std::isnan(o_.max_energy_error)) {
      const double e = num(t_.rows[r][ec]);
      stable = std::isfinite(e) && e <= o_.max_energy_error;
    }
    runs[g][v].emplace_back(step, stable);
    ++used;
  }
  if (used == 0) throw InputError("chart: no row of " + o_.table + " that ran has a step " + h + " > 0; nothing to draw");
  // categories: the x values of every line, in order of first appearance
  std::vector<std::string> categories;
  for (const auto& line : xs)
    for (const std::string& v : line)
      if (std::find(categories.begin(), categories.end(), v) == categories.end()) categories.push_back(v);
  std::vector<std::string> by_names;
  for (std::size_t c : by) by_names.push_back(t_.head[c]);
  std::string data = "# dvm chart --kind stability of " + o_.table + ": over " + x + ", the largest " + h +
                     " whose run and the runs of every smaller " + h + " are stable, the smallest unstable " + h +
                     ", and the largest " + h + " run; a run is unstable when it failed";
  if (!std::isnan(o_.max_energy_error)) data += " or its max_abs_energy_error is above " + num17(o_.max_energy_error) + " or not finite";
  data += "\n# one block per line (" + (by.empty() ? std::string("every row") : "by " + join(by_names, ", ")) +
          "), its title first; columns: " + (categorical ? "category index" : x) + ", largest stable " + h +
          " (NaN: the smallest is unstable), smallest unstable " + h + " (NaN: none), largest " + h + " run" +
          (categorical ? ", " + x : std::string()) + "\n";
  std::size_t blocks = 0, unstable_points = 0;
  double low = INFINITY, high = -INFINITY;  // of the steps drawn
  for (std::size_t g = 0; g < groups_.size(); ++g) {
    std::vector<std::pair<double, std::string>> order;
    for (const std::string& v : xs[g])
      order.emplace_back(categorical ? static_cast<double>(std::find(categories.begin(), categories.end(), v) -
                                                           categories.begin())
                                     : num(v),
                         v);
    std::stable_sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    data += std::string(blocks ? "\n\n" : "") + gp_string(groups_[g]) + "\n";
    for (const auto& [pos, v] : order) {
      auto rs = runs[g][v];
      std::stable_sort(rs.begin(), rs.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
      double largest_stable = NAN, smallest_unstable = NAN;
      for (const auto& [step, stable] : rs) {
        if (!stable) {
          smallest_unstable = step;
          break;
        }
        largest_stable = step;
      }
      unstable_points += !std::isnan(smallest_unstable);
      for (double drawn : {largest_stable, smallest_unstable})
        if (!std::isnan(drawn)) low = std::fmin(low, drawn), high = std::fmax(high, drawn);
      data += num17(pos) + " " + num17(largest_stable) + " " + num17(smallest_unstable) + " " + num17(rs.back().first);
      if (categorical) data += " " + gp_string(v);
      data += "\n";
    }
    ++blocks;
  }
  const std::string title = o_.title.empty() ? "largest stable " + h + " over " + x + " (filled; open: smallest unstable) (" +
                                                   std::filesystem::path(o_.table).filename().string() + ")"
                                             : o_.title;
  const int width = categorical ? std::max(1000, 60 * static_cast<int>(categories.size()) + 300) : 1000;
  std::string s = preamble(name_, std::filesystem::path(o_.out).extension().string(), title, width, 640);
  if (logged('x', "y") && !categorical) s += "set logscale x\n";
  if (logged('y', "y")) s += "set logscale y\n";
  s += "set xlabel " + gp_string(x) + " noenhanced\nset ylabel " + gp_string(h) + " noenhanced\n";
  s += by.empty() ? "unset key\n" : "set key outside right top noenhanced font \",9\"\n";
  // a margin around the steps drawn (a range of its own where they are all one step)
  if (logged('y', "y")) {
    s += "set yrange [" + num17(low / 1.25) + ":" + num17(high * 1.25) + "]\n";
    // within a decade or two gnuplot would label the powers of ten alone: 1, 1.5, 2, 3, 5, 7 of each
    std::vector<std::string> tics;
    for (int e = static_cast<int>(std::floor(std::log10(low / 1.25))); e <= std::ceil(std::log10(high * 1.25)); ++e)
      for (double m : {1.0, 1.5, 2.0, 3.0, 5.0, 7.0}) {
        const double v = m * std::pow(10.0, e);
        if (v >= low / 1.25 && v <= high * 1.25) tics.push_back(num17(v));
      }
    if (tics.size() >= 2) s += "set ytics (" + join(tics, ", ") + ")\nset format y \"%g\"\n";
  } else {
    s += "set yrange [" + num17(low - 0.1 * std::fmax(high - low, std::fabs(low))) + ":" +
         num17(high + 0.1 * std::fmax(high - low, std::fabs(high))) + "]\n";
  }
  const std::string file = gp_string(name_ + ".dat"), last = std::to_string(blocks - 1);
  if (categorical) {
    s += "set xrange [-0.5:" + std::to_string(categories.size()) + " - 0.5]\n";
    s += "set xtics rotate by -40 noenhanced font \",9\"\n";
    // the lines side by side within a category
    const std::string shift = "($1 + 0.5 * (i - " + last + " / 2.0) / " + std::to_string(blocks) + ")";
    s += "plot for [i=0:" + last + "] " + file + " index i using " + shift +
         ":2:xtic(5) with points lt (i + 1) pt 7 ps 1.2 title columnheader(1)";
    if (unstable_points)
      s += ", \\\n     for [i=0:" + last + "] " + file + " index i using " + shift +
           ":3 with points lt (i + 1) pt 6 ps 1.2 notitle";
  } else {
    s += "plot for [i=0:" + last + "] " + file +
         " index i using 1:2 with linespoints lt (i + 1) pt 7 ps 0.8 title columnheader(1)";
    if (unstable_points)
      s += ", \\\n     for [i=0:" + last + "] " + file + " index i using 1:3 with points lt (i + 1) pt 6 ps 0.8 notitle";
  }
  s += "\n";
  return finish(data, s, used);
}

// Cell edges around sorted distinct values: midpoints (geometric on a log axis), the
// ends as far out as the first and last midpoints are in.
std::map<double, std::pair<double, double>> edges(const std::set<double>& values, bool log) {
  std::vector<double> v(values.begin(), values.end());
  std::map<double, std::pair<double, double>> out;
  auto mid = [&](double a, double b) { return log ? std::sqrt(a * b) : 0.5 * (a + b); };
  for (std::size_t k = 0; k < v.size(); ++k) {
    double lo, hi;
    if (v.size() == 1) {
      lo = log ? v[0] / 1.2 : v[0] - 0.5;
      hi = log ? v[0] * 1.2 : v[0] + 0.5;
    } else {
      lo = k > 0 ? mid(v[k - 1], v[k]) : (log ? v[0] * v[0] / mid(v[0], v[1]) : 2 * v[0] - mid(v[0], v[1]));
      hi = k + 1 < v.size() ? mid(v[k], v[k + 1])
                            : (log ? v[k] * v[k] / mid(v[k - 1], v[k]) : 2 * v[k] - mid(v[k - 1], v[k]));
    }
    out[v[k]] = {lo, hi};
  }
  return out;
}

int Chart::heat() {
  const std::string x = o_.x.empty() ? "step" : o_.x, z = o_.z.empty() ? "error" : o_.z;
  const std::size_t xc = col(x, "--x");
  const std::size_t zc = col(z, "--z", z == "error" ? ": a heat map of errors needs dvm sweep --error" : "");
  std::string y = o_.y;
  if (y.empty()) {
    std::vector<std::string> candidates;
    for (const std::string& k : t_.varied) {
      bool other = step_key(k) || k == x;
      for (const auto& w : o_.where) other = other || w.first == k;
      if (!other) candidates.push_back(k);
    }
    if (candidates.size() != 1)
      throw InputError("chart: --y: a heat map draws " + z + " over " + x + " and a parameter; the table " + o_.table +
                       " varies " + (candidates.empty() ? std::string("none but the step") : join(candidates, ", ")) +
                       " besides it: name the parameter with --y (and fix the others with --where KEY=VALUE)");
    y = candidates.front();
  }
  const std::size_t yc = col(y, "--y");
  // every other varied key must be fixed: one row per cell
  for (const std::string& k : t_.varied) {
    if (k == x || k == y || (step_key(k) && (x == "step" || x == "steps"))) continue;
    bool fixed = false;
    for (const auto& w : o_.where) fixed = fixed || w.first == k;
    if (fixed) continue;
    std::set<std::string> values;
    for (const auto& row : t_.rows) values.insert(row[static_cast<std::size_t>(t_.column(k))]);
    if (values.size() > 1)
      throw InputError("chart: a heat map has one row per cell of " + x + " and " + y + ", and the table " + o_.table +
                       " also varies " + k + ": fix it with --where " + k + "=VALUE");
  }
  const bool xlog = logged('x', "x"), ylog = logged('y', "x");
  struct Cell {
    double x, y, z;
    bool failed;
  };
  std::vector<Cell> cells;
  std::set<std::pair<double, double>> seen;
  std::set<double> xs, ys;
  for (std::size_t r : kept()) {
    const std::string& status = t_.rows[r][status_];
    if (status == "refused") continue;
    const double a = num(t_.rows[r][xc]), b = num(t_.rows[r][yc]);
    if (!std::isfinite(a) || !std::isfinite(b)) {
      if (status == "ok")
        throw InputError("chart: --x " + x + ", --y " + y + ": row " + t_.rows[r][0] +
                         " has no number there; a heat map needs numbers on both axes");
      continue;
    }
    if ((xlog && a <= 0) || (ylog && b <= 0))
      throw InputError("chart: --log: row " + t_.rows[r][0] + " has " + x + " = " + num17(a) + ", " + y + " = " + num17(b) +
                       ", not > 0 on a logarithmic axis");
    if (!seen.insert({a, b}).second)
      throw InputError("chart: a heat map has one row per cell, and the table " + o_.table + " has two at " + x + " = " +
                       num17(a) + ", " + y + " = " + num17(b) + ": fix the other varied keys with --where KEY=VALUE");
    xs.insert(a), ys.insert(b);
    cells.push_back({a, b, num(t_.rows[r][zc]), status != "ok"});
  }
  if (cells.empty()) throw InputError("chart: no row of " + o_.table + " ran; nothing to draw");
  const auto xe = edges(xs, xlog), ye = edges(ys, ylog);
  std::string data = "# dvm chart --kind heat of " + o_.table + ": " + z + " over " + x + " and " + y +
                     "\n# block 0, a cell per run that completed: " + x + ", " + y + ", the cell's edges (" + x +
                     " low, high, " + y + " low, high), " + z + " (NaN: none, or not > 0)\n";
  std::size_t failed = 0, drawn = 0;
  for (const Cell& c : cells) {
    if (c.failed) {
      ++failed;
      continue;
    }
    const double value = std::isfinite(c.z) && c.z > 0 ? c.z : NAN;
    drawn += !std::isnan(value);
    data += num17(c.x) + " " + num17(c.y) + " " + num17(xe.at(c.x).first) + " " + num17(xe.at(c.x).second) + " " +
            num17(ye.at(c.y).first) + " " + num17(ye.at(c.y).second) + " " + num17(value) + "\n";
  }
  data += "\n\n# block 1, the runs that failed: " + x + ", " + y + "\n";
  for (const Cell& c : cells)
    if (c.failed) data += num17(c.x) + " " + num17(c.y) + "\n";
  if (drawn == 0 && failed == 0)
    throw InputError("chart: no run of " + o_.table + " has a " + z + " > 0; nothing to draw");
  const std::string title = o_.title.empty() ? z + " over " + x + " and " + y + " (x: failed) (" +
                                                   std::filesystem::path(o_.table).filename().string() + ")"
                                             : o_.title;
  std::string s = preamble(name_, std::filesystem::path(o_.out).extension().string(), title, 1000, 700);
  if (xlog) s += "set logscale x\n";
  if (ylog) s += "set logscale y\n";
  s += "set logscale cb\nset format cb \"%.0e\"\nset cblabel " + gp_string(z) + " noenhanced\n";
  s += "set palette rgbformulae 30,31,32\n";
  s += "set xlabel " + gp_string(x) + " noenhanced\nset ylabel " + gp_string(y) + " noenhanced\n";
  s += "set xrange [" + num17(xe.begin()->second.first) + ":" + num17(xe.rbegin()->second.second) + "]\n";
  s += "set yrange [" + num17(ye.begin()->second.first) + ":" + num17(ye.rbegin()->second.second) + "]\n";
  s += "set key outside top center horizontal\n";
  const std::string file = gp_string(name_ + ".dat");
  std::vector<std::string> parts;
  if (drawn) parts.push_back(file + " index 0 using 1:2:3:4:5:6:7 with boxxyerror fs solid 1.0 noborder lc palette notitle");
  if (failed) parts.push_back(file + " index 1 using 1:2 with points pt 2 ps 1.2 lc rgb \"black\" title \"failed\"");
  s += "plot " + join(parts, ", \\\n     ") + "\n";
  return finish(data, s, cells.size());
}

// The program gnuplot: $DVM_GNUPLOT, else gnuplot on PATH; "" when there is none.
std::string find_gnuplot() {
  if (const char* g = std::getenv("DVM_GNUPLOT"); g && *g) return access(g, X_OK) == 0 ? g : "";
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "";
  std::size_t start = 0;
  while (start <= dirs.size()) {
    const std::size_t end = std::min(dirs.find(':', start), dirs.size());
    const std::string dir = dirs.substr(start, end - start);
    const std::string p = (dir.empty() ? "." : dir) + "/gnuplot";
    if (access(p.c_str(), X_OK) == 0) return p;
    start = end + 1;
  }
  return "";
}

void write_file(const std::string& path, const std::string& text) {
  OutputFile f;
  f.open(path, "--out (" + path + ")", static_cast<double>(text.size()));
  if (std::fwrite(text.data(), 1, text.size(), f.get()) != text.size()) {
    const std::string why = f.finish(false);
    throw InputError("--out: " + path + " could not be written" + (why.empty() ? "" : ": " + why));
  }
  const std::string why = f.finish(true);
  if (!why.empty()) throw InputError("--out: " + why);
}

int Chart::finish(const std::string& data, const std::string& script, std::size_t points) {
  write_file(stem_ + ".dat", data);
  write_file(stem_ + ".gp", script);
  if (o_.data_only) {
    std::cout << "wrote " << stem_ << ".dat and " << stem_ << ".gp (" << points << " rows drawn; not run: --data-only)\n";
    return 0;
  }
  const std::string gnuplot = find_gnuplot();
  std::string dir = std::filesystem::path(stem_).parent_path().string();
  if (dir.empty()) dir = ".";
  std::cout.flush();
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("chart: fork failed");
  if (pid == 0) {
    if (chdir(dir.c_str()) != 0) _exit(127);
    const std::string script_name = name_ + ".gp";
    execl(gnuplot.c_str(), gnuplot.c_str(), script_name.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::cerr << "dvm: chart: gnuplot (" << gnuplot << ") failed on " << stem_ << ".gp"
              << (WIFEXITED(status) ? " with exit status " + std::to_string(WEXITSTATUS(status)) : std::string())
              << "; the data and the script are written\n";
    return 3;
  }
  std::cout << "wrote " << o_.out << " (" << points << " rows drawn; data " << stem_ << ".dat, script " << stem_
            << ".gp)\n";
  return 0;
}

}  // namespace

int chart_command(const ChartOptions& o) {
  const auto& kinds = chart_kinds();
  if (std::find(kinds.begin(), kinds.end(), o.kind) == kinds.end())
    throw InputError("chart: --kind: '" + echo(o.kind) + "' is not a kind of chart" + did_you_mean(o.kind, kinds) +
                     "; expected one of " + join(kinds, ", "));
  const std::string ext = std::filesystem::path(o.out).extension().string();
  if (ext != ".png" && ext != ".svg")
    throw InputError("chart: --out " + o.out + ": expected a path ending in .png or .svg (the chart's format)");
  if (!o.log.empty() && o.log != "none" && o.log.find_first_not_of("xy") != std::string::npos)
    throw InputError("chart: --log: got '" + echo(o.log) + "', expected x, y, xy or none");
  if (!o.data_only && find_gnuplot().empty()) {
    const char* g = std::getenv("DVM_GNUPLOT");
    throw InputError(std::string("chart: gnuplot not found (") +
                     (g && *g ? "DVM_GNUPLOT=" + std::string(g) + " is not an executable program"
                              : std::string("no gnuplot on PATH")) +
                     "); install it (Debian: apt-get install gnuplot-nox; make charts does), or write the data and "
                     "the script only with --data-only");
  }
  Chart chart(o);
  return chart.draw();
}

}  // namespace dvm::cli
