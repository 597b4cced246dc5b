// `dvm run` and `dvm converge`: the scene's problem and method handed to the runtime
// layer (solvers/runtime): one Run built by make_run, its rows written by one
// Recorder, its summary printed by print_report; or a convergence study of the same.
#include "examples/dvm/commands.h"
#include "solvers/runtime/converge.h"
#include "solvers/runtime/run.h"

namespace dvm::cli {

int run_scene(const Scene& s, const RunOptions& o) {
  if (o.converge) {
    ConvergeOptions co;
    co.steps_list = o.steps_list;
    co.t_end = o.t_end;
    co.max_total_steps = o.max_total_steps;
    const ConvergeReport r = converge(s.problem, s.method, co);
    return print_converge(r, o.json);
  }
  Method method = s.method;
  method.linearize = !o.linearize.empty();
  const auto run = make_run(s.problem, method);
  OutputSpec out;
  out.csv = o.csv.empty() ? s.csv : o.csv;
  out.npy = o.npy.empty() ? s.npy : o.npy;
  out.csv_source = output_source(s.path, o.csv, "--csv", "output.csv");
  out.npy_source = output_source(s.path, o.npy, "--npy", "output.npy");
  out.inputs = {s.path};
  out.linearize = o.linearize;
  out.linearize_source = "--linearize " + o.linearize;
  for (const std::string* rows : {&out.csv, &out.npy})
    if (!o.linearize.empty() && *rows == o.linearize)
      throw InputError(out.linearize_source + ": the same file as the run's rows (" +
                       (rows == &out.csv ? out.csv_source : out.npy_source) + ")");
  out.every = s.every;
  out.monitor_every = s.monitor_every;
  out.progress = !o.quiet;
  // rows on standard output: the summary moves to standard error
  const bool rows_on_stdout = descriptor_path(out.csv) == 1 || descriptor_path(out.npy) == 1;
  Recorder recorder(out);
  const RunReport r = run->execute(&recorder);
  print_report(r, o.json, o.quiet, rows_on_stdout ? stderr : stdout);
  return r.failed || r.output_error ? 3 : 0;
}

}  // namespace dvm::cli
