// A sweep: one scene run many times, each run with some of its keys set to other
// values, every run a row of one table.
//
//   varied keys   k_1 .. k_m, each with a list of values v_j1 .. v_jn_j
//   runs          the cross product (n_1 x ... x n_m rows, the last key varying
//                 fastest) or, zipped, row i takes the i-th value of every key
//   row i         the scene read with --set k_j=v_j(i) for every key (after the
//                 sweep's own --set overrides): the same reader, the same messages and
//                 the same run as `dvm run --set ...`, so a row equals that run to the bit
//
// A value list is written as a TOML array ([0.1, 0.2], ["midpoint", "theta"]), a
// linear range a:b:n, a geometric range log:a:b:n (n points, both ends included) or n
// seeded uniform samples uniform:a:b:n:seed in [a, b). Samples come from std::mt19937_64
// (its output is fixed by the standard) through the top 53 bits of each draw, so the
// values are the same on every platform.
//
// The rows are independent: run_row(i) reads row i's scene and runs it with nothing
// shared with other rows, so rows may run on threads (run_sweep, OpenMP) or on other
// processes, in any order, with the same results. Rows that no run can read are bad
// input of the sweep; see run_sweep.
//
// Errors (SweepOptions::error): each run's final state against a reference (the one of
// dvm converge, solvers/runtime/converge.h) computed once per distinct problem: the
// rows that share their values outside [integrator] and [output] and their time span
// T = steps x step. Where the system has an exact solution, each run is measured
// against it at its own final time. SweepOptions::max_error adds the largest error
// along the run, over every step: measured against the exact solution, so a row
// whose system has none is refused.
//
// Tables written as rows finish, and resumed: run_sweep hands the rows finished so far
// to a callback (write_sweep_table writes them, each file by a temporary renamed onto
// its path), and read_sweep_table reads such a table back, so that a sweep stopped
// midway runs only the rows the table lacks. A row read back renders to the same
// text as when it was run (its numbers have 17 digits), so the resumed table is the
// uninterrupted one.
#pragma once

#include <cstddef>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "solvers/runtime/converge.h"
#include "solvers/runtime/run.h"

namespace dvm {

// One value of a varied key, in the three spellings the sweep needs.
struct SweepValue {
  std::string toml;  // as --set takes it: 0.1, 100, "midpoint", [0.5, 0.0]
  std::string json;  // in the JSON table
  std::string cell;  // in the CSV table (a string without its quotes)
};

struct SweepAxis {
  std::string key;   // section.key, as --set names it
  std::string spec;  // as given
  std::vector<SweepValue> values;
};

// Parses "KEY=SPEC". Throws InputError naming the key for a malformed or empty spec,
// a range of more than max_values points, a log range with an end <= 0.
SweepAxis parse_vary(const std::string& arg, double max_values);

struct SweepOptions {
  std::string scene_path;
  std::string scene_text;         // the scene file's text (read once)
  std::vector<std::string> sets;  // --set overrides of every run, before the varied keys
  std::vector<SweepAxis> axes;
  bool zip = false;
  bool error = false;  // measure each run's error against a reference
  bool max_error = false;  // and the largest along the run (with error; needs an exact solution)
  int jobs = 1;        // threads (under mpirun: on each rank)
  double max_runs = kDefaultMaxRuns;
  static constexpr double kDefaultMaxRuns = 1e6;
};

// The threads a sweep runs on by default: the processors this process may use.
int default_jobs();

// Checks the options (at least one key, no key twice or also given by --set, no
// [output] key but output.monitor_every, zipped lists of equal lengths, at most
// max_runs rows) and returns the number of rows. Throws InputError.
std::size_t sweep_size(const SweepOptions& options);

// The varied values of row i: an index into each axis's values.
std::vector<std::size_t> sweep_values(const SweepOptions& options, std::size_t i);
// Row i's overrides: the sweep's --set, then one per varied key.
std::vector<std::string> sweep_overrides(const SweepOptions& options, std::size_t i);

enum class RowStatus { ok, failed, refused };
const char* to_string(RowStatus s);

struct SweepRow {
  std::size_t index = 0;
  RowStatus status = RowStatus::ok;
  int code = 0;         // as `dvm run` would exit: 0, 2 (refused), 3 (failed)
  std::string message;  // why the run failed or was refused ("" for ok)
  bool ran = false;     // report holds the run's report
  RunReport report;
  double cpu_seconds = 0.0;  // CPU time of the run's thread during execute()
  // errors (SweepOptions::error)
  std::string problem;      // the key of its distinct problem
  double t_end = 0.0;       // steps x step of the problem
  FinalState final_state;   // as the error measures it
  double error = NAN;       // NaN: none (a failed or refused run, or a failed reference)
  double max_error = NAN;   // SweepOptions::max_error: the largest error over the steps
  double reference_accuracy = NAN;  // an exact solution's (the others are the reference's)
  int reference = -1;       // index into SweepReport::references
  std::string run_json;     // the report as JSON (report_json, or the text read back)
};

// Reads row i's scene and builds its run without running it; "" when it can run,
// else the message of the refusal (as `dvm run` prints it after "dvm: ").
std::string check_row(const SweepOptions& options, std::size_t i);
// Runs row i: never throws; a refusal or a failure is the row's status. With
// options.error and an exact solution the row's error is set here; otherwise the
// error needs the other rows of its problem (attach_errors).
SweepRow run_row(const SweepOptions& options, std::size_t i);

struct SweepReference {
  double t_end = 0.0;
  std::string description;  // "exact solution at each run's final time", or the reference run
  double accuracy = NAN;    // the largest over its rows for exact solutions
  std::string failure;      // the reference run failed: why ("" when it did not)
  std::vector<std::size_t> rows;
};

struct SweepReport {
  std::size_t runs = 0, ok = 0, failed = 0, refused = 0;
  std::vector<SweepRow> rows;  // in the sweep's order
  std::vector<SweepReference> references;
};

// The rows of a sweep as they stand: row i is there when have[i] (size: the sweep's).
struct SweepRows {
  std::vector<SweepRow> rows;
  std::vector<char> have;
};

// What run_sweep calls with the rows finished so far (with those given to it), in
// the sweep's order, without errors against reference runs (their rows need the
// others): after a row finishes, unless the last call took more than a tenth of the
// time since it ended (so at most a tenth of a sweep's time goes to it). One call at
// a time; the runs go on meanwhile.
using SweepFlush = std::function<void(const SweepReport& finished)>;

// The sweep on options.jobs threads:
//   1. every row is checked (check_row); a value of a varied key that every row it
//      takes part in refuses is bad input: InputError naming the key and the value,
//      nothing runs;
//   2. the other rows run (run_row), refused ones stay rows with status refused;
//   3. with options.error, the references and the errors of the rows without an
//      exact solution (attach_errors).
// The report is the same for any number of threads.
SweepReport run_sweep(const SweepOptions& options);
// The same, with the rows of `done` taken as they are (neither checked nor run again;
// a refused one counts as refused in step 1), and `flush` called as rows finish.
SweepReport run_sweep(const SweepOptions& options, const SweepRows& done, const SweepFlush& flush);

// The references of the rows not yet measured, one per distinct problem (on
// options.jobs threads), and their rows' errors.
void attach_errors(const SweepOptions& options, std::vector<SweepRow>& rows, std::vector<SweepReference>& references);

// The table as CSV (a header row, then one row per run) and as JSON. A report with
// fewer rows than the sweep has runs is a table of the rows finished so far.
std::string sweep_csv(const SweepOptions& options, const SweepReport& report);
std::string sweep_json(const SweepOptions& options, const SweepReport& report);

// Writes PATH.csv and PATH.json, each to a temporary beside it renamed onto it (the
// JSON first). Returns "" or what went wrong.
std::string write_sweep_table(const SweepOptions& options, const SweepReport& report, const std::string& path);

// Reads back the rows of a table PATH.json written by a sweep with the same options
// (scene file and its text, --set, varied keys and values, zip, errors measured).
// Throws InputError naming what differs, or where the text is not such a table.
SweepRows read_sweep_table(const SweepOptions& options, const std::string& json_path);

// A table of a sweep as cells, read from its CSV or its JSON (by the text: a JSON
// table starts with '{'), without the options that made it: the columns of the CSV
// (head; `varied` the varied keys among them, in order) and one row of cells per row.
// From the JSON the cells are those of the CSV but for the spelling of numbers: the
// JSON's text of each (the same double), and the varied values as JSON (strings
// without their quotes). What `dvm chart` reads. Throws InputError naming the file
// when the text is neither such a CSV nor such a JSON table.
struct SweepCells {
  std::vector<std::string> head;
  std::vector<std::string> varied;
  std::vector<std::vector<std::string>> rows;
  // the column's index, or -1
  int column(const std::string& name) const;
};
SweepCells read_sweep_cells(const std::string& path);

// One row as the table's JSON writes it, and back (the row's rendering, and its
// values, checked against the options; InputError otherwise).
std::string sweep_row_json(const SweepOptions& options, const SweepRow& row);
SweepRow sweep_row_from_json(const SweepOptions& options, const std::string& text);

// The hash of the scene's text a table carries (FNV-1a, 64 bits, in hex).
std::string scene_digest(const std::string& text);

// ---- ranks (MPI) -------------------------------------------------------------------
// A sweep started by OpenMPI's mpirun runs its rows on every rank: rank 0 checks the
// rows, hands out the index of the next row to run to whichever rank asks (ranks
// ask when they start and when they finish a row, so that cheap and costly rows
// spread evenly), runs rows itself on other threads meanwhile, gathers the rows
// (each sent as the text of its row in the JSON table) and alone writes the table.
// Each rank runs options.jobs rows at a time, on as many threads: its main thread
// alone calls MPI (it asks once for each thread, and once for each row a thread
// finishes), so MPI_THREAD_FUNNELED is all it needs. The rows are those of the same
// sweep on threads, so the table is the same.
//
// MPI is an optional part of the build (DVM_WITH_MPI, only this library's sweep.cc
// is compiled against it). A process is taken as started by mpirun when OpenMPI's
// environment variable OMPI_COMM_WORLD_SIZE is set: only then is MPI initialised, so
// a process started otherwise never touches MPI.

// Whether this library was built with MPI.
bool sweep_mpi_built();
// Whether OMPI_COMM_WORLD_SIZE is set.
bool launched_by_mpirun();

// The ranks of this process's launch: MPI initialised for the lifetime of the object
// when launched by mpirun (InputError when this library was built without MPI), a
// single rank 0 otherwise.
class SweepRanks {
 public:
  SweepRanks();
  ~SweepRanks();
  SweepRanks(const SweepRanks&) = delete;
  SweepRanks& operator=(const SweepRanks&) = delete;
  bool mpi() const { return mpi_; }  // whether MPI was initialised
  int rank() const { return rank_; }
  int size() const { return size_; }
  // Rank 0's value on every rank (every rank calls it, in the same order).
  std::string share(const std::string& on_rank0) const;
  int share(int on_rank0) const;
  // Ends every rank's process with the code (after a failure that leaves some rank
  // waiting for the others).
  [[noreturn]] void abort(int code) const;

 private:
  bool mpi_ = false;
  int rank_ = 0, size_ = 1;
};

// run_sweep over the ranks (one of them, ranks.size() 1: run_sweep above). Every rank
// calls it; rank 0 returns the report (it throws the InputError of step 1, after
// telling the others), the other ranks an empty report (runs 0).
SweepReport run_sweep(const SweepOptions& options, const SweepRows& done, const SweepFlush& flush,
                      const SweepRanks& ranks);

}  // namespace dvm
