// The one writer of every run's rows: CSV and NumPy .npy, through the atomic output
// files of solvers/runtime/output.h (temporary file, size check against the free space
// before the run, rename when complete, PATH.partial when the run failed).
//
// A run declares its columns once (open), then hands over rows of that many doubles;
// which steps are written is decided by wants(k, last): the initial state, every
// `every`-th step and the last. The CSV header is the column names; the .npy file is
// a little-endian float64 array of shape rows x columns (format version 1.0, header
// rewritten with the row count when the file is finished), its column names beside it
// in PATH.json (written, kept or discarded with it; not for a stream such as -).
//
// Rows may also be kept in memory (OutputSpec::memory): one contiguous row-major
// buffer of doubles, reserved for the run's rows when the run opens the recorder and
// handed over whole by take_rows() (a binding wraps it as an array without copying).
//
// A run calls progress(k, ...) after every step; OutputSpec::poll, when set, is called
// from there every kPollSteps steps (and as poll(i, max_iterations) after every
// iteration i of the single solve of a boundary-value problem). It is the hook of a
// caller that must act while a run is in progress (check for an interrupt, show
// progress): an exception it throws stops the run and leaves Run::execute (the
// temporaries of the files are removed, no rows are lost from memory). It must not
// throw std::domain_error, which the integrate loop takes for a failed step.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "solvers/runtime/output.h"

namespace dvm {

struct OutputSpec {
  std::string csv, npy;                 // empty: not written
  std::string csv_source, npy_source;   // what gave each path, for messages
  std::vector<std::string> inputs;      // files the run reads (the scene): never written over
  // The derivative of every step (dvm run --linearize), a .npy file: one row per step k,
  // t_k then the entries of the 2n x 2n Jacobian A_k of (q_k, p_k) -> (q_{k+1}, p_{k+1}),
  // row by row (columns t, A[0,0], A[0,1], ...); empty: not written. The method must ask
  // for it (Method::linearize).
  std::string linearize, linearize_source;
  std::int64_t every = 1;
  // The energy, the invariants and the distance from the manifold are evaluated every
  // monitor_every steps, at every row written and at the last step, and the report's
  // maxima are over those steps. 1: every step. A larger value saves their cost where
  // it matters (n bodies: the energy costs as much as a force).
  std::int64_t monitor_every = 1;
  bool progress = false;                // progress on stderr when it is a terminal
  bool memory = false;                  // rows kept in memory (Recorder::take_rows)
  // Called as poll(k, steps) at every kPollSteps-th step k of an initial-value run, and
  // as poll(i, max_iterations) after every iteration i of the solve of a boundary-value
  // problem; see above.
  std::function<void(std::int64_t, std::int64_t)> poll;
};

// The steps between two calls of OutputSpec::poll (a power of 2).
constexpr std::int64_t kPollSteps = 64;

// The file beside a .npy file written to a path that holds its column names, as JSON
// {"columns": [...], "npy": FILE NAME}: PATH.json.
inline std::string npy_names_path(const std::string& npy) { return npy + ".json"; }

class Recorder {
 public:
  explicit Recorder(OutputSpec spec) : spec_(std::move(spec)) {}
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Checks the paths and the room for `rows` rows and creates the temporaries; throws
  // InputError (nothing is written then). Refused: the CSV and the .npy naming the same
  // file, an output naming one of the inputs, a .npy that cannot be rewound (a pipe).
  void open(const std::vector<std::string>& columns, double rows);
  bool wants(std::int64_t k, std::int64_t last) const { return k % spec_.every == 0 || k == last; }
  // Whether rows go anywhere (a CSV or a .npy file, memory, or a sink).
  bool writes_rows() const { return !spec_.csv.empty() || !spec_.npy.empty() || spec_.memory || sink_; }
  void row(const double* values);
  // Hands every row to `sink` as well (with or without files): the row's values in
  // the columns open() was given, which it receives first. A run then evaluates its
  // energy and invariants at every row, as when rows go to a file.
  using Sink = std::function<void(const std::vector<std::string>& columns, const double* values)>;
  void set_sink(Sink sink) { sink_ = std::move(sink); }
  // Renames the files onto their paths (complete) or onto PATH.partial; returns false
  // after printing any write error to stderr. `kept` lists the .partial files.
  bool finish(bool complete, std::string& kept);
  const OutputSpec& spec() const { return spec_; }
  std::int64_t every() const { return spec_.every; }
  // The column names the run declared (open), and with OutputSpec::memory the rows it
  // wrote: rows() / columns().size() of them, row-major. take_rows() moves them out.
  const std::vector<std::string>& columns() const { return names_; }
  const std::vector<double>& rows() const { return memory_; }
  std::vector<double> take_rows() { return std::move(memory_); }

  // Progress on stderr (step, time, rate, time left), only when asked and stderr is
  // a terminal; cheap to call every step. A line is written at every 1024th step k > 0
  // once at least the progress interval has passed since the last one: 0.25 s, or the
  // value of the environment variable DVM_PROGRESS_INTERVAL (seconds, a finite number
  // >= 0, read by open()). The tests set it to 0, so that every 1024th step is shown
  // whatever the speed of the machine (tests/README.md).
  void progress(std::int64_t k, std::int64_t total, double h);
  void end_progress();

 private:
  void write_npy_header();
  OutputSpec spec_;
  Sink sink_;
  OutputFile csv_, npy_, npy_names_;  // npy_names_: the .npy's column names (PATH.json)
  int columns_ = 0;
  std::vector<std::string> names_;  // the columns open() was given (also for the sink)
  std::vector<double> memory_;  // OutputSpec::memory: the rows written so far
  long long npy_rows_ = 0;
  bool progress_on_ = false, progress_shown_ = false;
  double progress_interval_ = 0.25;  // seconds between progress lines (DVM_PROGRESS_INTERVAL)
  std::chrono::steady_clock::time_point start_, last_;
};

}  // namespace dvm
