// dvm._dvm: the extension module under the Python package dvm (examples/python/src/dvm).
//
// It binds the runtime layer as the dvm program uses it: load_scene (the one scene
// reader, with its messages), make_run and Run::execute with a Recorder that keeps the
// rows in memory, report_json and run_failure_message (what `dvm run --json` prints and
// what a failed run says on stderr), the listings of the registries, the convergence
// study and the map checks (the JSON of `dvm converge --json` and `dvm check-map`). The
// Python side (src/dvm/__init__.py) turns these into the documented API.
//
// A run releases the GIL: make_run (which may compile a written Lagrangian) and the
// whole integrate loop run without it. The recorder's poll hook (solvers/runtime/
// recorder.h) takes the GIL back at most every kPollSeconds to run Python's signal
// handlers (Ctrl-C raises KeyboardInterrupt in the main thread) and the caller's
// progress function; an exception from either leaves the loop, and the run's objects
// are released as the C++ stack unwinds.
//
// The rows are one row-major buffer of doubles, filled by the recorder as the run goes;
// the numpy array returned owns that buffer through a capsule, so no row is copied.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "solvers/runtime/check_map.h"
#include "solvers/runtime/converge.h"
#include "solvers/runtime/errors.h"
#include "solvers/runtime/listings.h"
#include "solvers/runtime/recorder.h"
#include "solvers/runtime/run.h"
#include "solvers/runtime/scene.h"

namespace py = pybind11;

namespace {

// The least time between two visits of the poll hook to Python (signals, progress).
constexpr double kPollSeconds = 0.05;

dvm::Scene load(const std::string& source, bool is_text, const std::string& name,
                const std::vector<std::string>& overrides) {
  py::gil_scoped_release release;
  return is_text ? dvm::load_scene_text(source, name, overrides) : dvm::load_scene(source, overrides);
}

// Runs a scene's problem with its method; the rows go to memory. Returns the report
// as `dvm run --json` prints it, the failure message ("" for a run that did not
// fail), the column names and the rows (rows x columns, float64).
py::tuple run(const dvm::Scene& scene, std::int64_t every, std::int64_t monitor_every, const py::object& progress) {
  if (every < 1) throw dvm::InputError("output.every: got " + std::to_string(every) + ", expected a whole number >= 1");
  if (monitor_every < 1)
    throw dvm::InputError("output.monitor_every: got " + std::to_string(monitor_every) +
                          ", expected a whole number >= 1");
  dvm::OutputSpec spec;
  spec.memory = true;
  spec.every = every;
  spec.monitor_every = monitor_every;
  using Clock = std::chrono::steady_clock;
  Clock::time_point last = Clock::now();
  const bool report_progress = !progress.is_none();
  spec.poll = [&](std::int64_t k, std::int64_t total) {
    const Clock::time_point now = Clock::now();
    if (std::chrono::duration<double>(now - last).count() < kPollSeconds) return;
    last = now;
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    if (report_progress) progress(k, total);  // a Python exception comes as error_already_set
  };
  dvm::Recorder recorder(spec);
  dvm::RunReport report;
  {
    py::gil_scoped_release release;
    const std::unique_ptr<dvm::Run> r = dvm::make_run(scene.problem, scene.method);
    report = r->execute(&recorder);
  }
  const std::vector<std::string> columns = recorder.columns();
  auto* rows = new std::vector<double>(recorder.take_rows());
  py::capsule owner(rows, [](void* p) { delete static_cast<std::vector<double>*>(p); });
  const auto ncols = static_cast<py::ssize_t>(columns.size());
  const py::ssize_t nrows = ncols > 0 ? static_cast<py::ssize_t>(rows->size()) / ncols : 0;
  py::array_t<double> data({nrows, ncols},
                           {static_cast<py::ssize_t>(ncols * sizeof(double)), static_cast<py::ssize_t>(sizeof(double))},
                           rows->data(), owner);
  return py::make_tuple(dvm::report_json(report), dvm::run_failure_message(report), columns, data);
}

// A convergence study of a scene's run (dvm converge): the JSON `dvm converge --json`
// prints. steps_list empty, t_end 0: the study's defaults.
std::string converge(const dvm::Scene& scene, const std::vector<std::int64_t>& steps_list, double t_end,
                     double max_total_steps) {
  dvm::ConvergeOptions o;
  o.steps_list = steps_list;
  o.t_end = t_end;
  o.max_total_steps = max_total_steps;
  py::gil_scoped_release release;
  return dvm::converge_json(dvm::converge(scene.problem, scene.method, o));
}

// The identity checks of a map of the registry (theta < 0: the map's own; dim 0: the
// default) or of a scene's map: the JSON `dvm check-map` prints.
std::string check_map(const std::string& name, double theta, int dim, double tolerance) {
  py::gil_scoped_release release;
  return dvm::map_check_json(dvm::check_map(name, theta, dim, tolerance));
}

std::string check_scene_map(const dvm::Scene& scene, int dim, double tolerance) {
  py::gil_scoped_release release;
  return dvm::map_check_json(dvm::check_scene_map(scene, dim, tolerance));
}

}  // namespace

PYBIND11_MODULE(_dvm, m) {
  m.doc() = "The runtime layer of dvm, bound for the package dvm (use dvm, not this module).";
  py::register_exception<dvm::InputError>(m, "_InputError", PyExc_ValueError);

  py::class_<dvm::Scene>(m, "_Scene", "A scene read and validated by the scene reader.")
      .def_readonly("path", &dvm::Scene::path)
      .def_readonly("csv", &dvm::Scene::csv)
      .def_readonly("npy", &dvm::Scene::npy)
      .def_readonly("every", &dvm::Scene::every)
      .def_readonly("monitor_every", &dvm::Scene::monitor_every)
      .def_property_readonly("system", [](const dvm::Scene& s) { return s.problem.system->name; })
      .def_property_readonly("dim", [](const dvm::Scene& s) { return s.problem.dim; })
      .def_property_readonly("step", [](const dvm::Scene& s) { return s.problem.step; })
      .def_property_readonly("steps", [](const dvm::Scene& s) { return s.problem.steps; })
      .def_property_readonly("boundary_value", [](const dvm::Scene& s) { return s.problem.boundary_value; })
      .def_property_readonly("method", [](const dvm::Scene& s) { return s.method.label(); });

  m.def("_load_scene", &load, py::arg("source"), py::arg("is_text"), py::arg("name"), py::arg("overrides"),
        "Reads a scene (a file, or text named `name` in messages) with --set overrides.");
  m.def("_run", &run, py::arg("scene"), py::arg("every"), py::arg("monitor_every"), py::arg("progress"),
        "Runs a scene: (report JSON, failure message, columns, rows).");
  m.def("_converge", &converge, py::arg("scene"), py::arg("steps_list"), py::arg("t_end"), py::arg("max_total_steps"),
        "A convergence study: the JSON of `dvm converge --json`.");
  m.attr("_converge_max_total_steps") = dvm::ConvergeOptions::kDefaultMaxTotalSteps;
  m.def("_check_map", &check_map, py::arg("name"), py::arg("theta"), py::arg("dim"), py::arg("tolerance"),
        "A map's identity checks: the JSON of `dvm check-map NAME`.");
  m.def("_check_scene_map", &check_scene_map, py::arg("scene"), py::arg("dim"), py::arg("tolerance"),
        "The identity checks of a scene's map: the JSON of `dvm check-map --scene`.");
  m.def("_systems_json", &dvm::systems_json, "`dvm systems --json`");
  m.def("_maps_json", &dvm::maps_json, "`dvm maps --json`");
  m.def("_methods_json", &dvm::methods_json, "`dvm methods --json`");
  m.attr("_poll_steps") = dvm::kPollSteps;
}
