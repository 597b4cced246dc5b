"""dvm: discrete variational mechanics from Python.

The same engine as the ``dvm`` program, in process: a scene (a TOML file or text) or
a system, a method and an initial state go through the program's scene reader and
checks, run in the library's compiled kernels, and come back as numpy arrays that hold
the rows a run of ``dvm run`` writes to its CSV file, to the bit.

    >>> import dvm
    >>> r = dvm.run(dvm.load_scene("examples/scenes/kepler.toml"))
    >>> r.q.shape, r.max_abs_energy_error

    >>> kepler = dvm.System(builtin="kepler", params={"mu": 1.0})
    >>> r = dvm.integrate(kepler, dvm.Method(map="midpoint"), q0=[0.4, 0], p0=[0, 2],
    ...                   h=0.01, t_end=10)

Errors: bad input raises :class:`InputError` (a ValueError) with the program's
message, which names the scene key and, for a file, its line and column; a run that
fails numerically raises :class:`StepFailure`, carrying the step, the time, the
residual and the trajectory up to the failure. A run releases the GIL (threads run in
parallel) and stops with KeyboardInterrupt on Ctrl-C; ``progress=True`` draws a
progress bar on stderr.

:func:`check_map` checks a map's identities as ``dvm check-map`` does.

The listings :func:`systems`, :func:`maps` and :func:`methods` are those of
``dvm systems --json``, ``dvm maps --json`` and ``dvm methods --json``.
"""

import json as _json
import math as _math
import os as _os
import re as _re
import sys as _sys
import time as _time

from . import _dvm

__all__ = [
    "InputError", "StepFailure", "Scene", "Result", "System", "Method",
    "load_scene", "run", "integrate", "converge", "Convergence", "check_map", "MapCheck", "systems", "maps",
    "methods",
]


# ---- errors ------------------------------------------------------------------------

class InputError(ValueError):
    """Bad input, refused before a run: the program's message (``dvm run`` prints it
    after ``dvm: `` and exits with status 2).

    Attributes, parsed from the message where it has them (else None):
      key     the scene key the message names ('integrator.step', 'initial.q', ...)
      source  the scene's path (or the name of a scene given as text)
      line, column   the position of the key in the scene file (None for a key given
              by an override or an argument)
    """

    # "SOURCE:LINE:COLUMN: ..." or "SOURCE (from --set): ..." (a position, or none for an
    # override; integrate names the argument: "dvm.integrate (from argument h): ..."),
    # "SOURCE: key '...'", "SOURCE: missing key '...'"
    _SOURCE = _re.compile(r"^(?P<source>.+?)(?::(?P<line>\d+):(?P<column>\d+)| \(from [^)]+\))?: "
                          r"(?=key '|missing key '|character \d+ of the value|in [a-z_]+\.)")
    _KEY = _re.compile(r"(?:^|: )(?:key '|missing key '|in )(?P<key>[A-Za-z_]\w*(?:\.[\w\[\]]+)+)")
    _LEADING = _re.compile(r"^(?:--set )?(?P<key>[A-Za-z_]\w*(?:\.\w+)+):")

    def __init__(self, message):
        super().__init__(message)
        self.message = message
        self.key = self.source = self.line = self.column = None
        m = self._SOURCE.match(message)
        if m:
            self.source = m.group("source")
            if m.group("line"):
                self.line, self.column = int(m.group("line")), int(m.group("column"))
        m = self._KEY.search(message) or self._LEADING.match(message)
        if m:
            self.key = m.group("key")


class StepFailure(RuntimeError):
    """A run that stopped because a step failed (a solve that did not converge, a
    non-finite state, a map or Legendre transform outside its domain), or a
    boundary-value problem that did not converge.

    The message is what ``dvm run`` prints on stderr (after ``dvm: ``; the program then
    exits with status 3). Attributes:
      step      the index k of the step k -> k+1 that failed (None for boundary values)
      time      t_k, the time that step starts at (None for boundary values)
      residual  the residual of the failed solve (None where there is none)
      result    the :class:`Result` of the run up to the failure: its rows up to the
                last completed step, and the report (``result.status == "failed"``,
                ``result.failure`` the report's failure object); from
                :func:`converge`, the :class:`Convergence` of the study
    """

    def __init__(self, message, result):
        super().__init__(message)
        self.message = message
        self.result = result
        failure = result.report.get("failure") or {}
        if not isinstance(failure, dict):  # a study's failure is its message
            failure = {}
        self.step = failure.get("step")
        self.time = failure.get("time")
        self.residual = failure.get("residual")
        if result.report.get("problem") == "boundary-value":
            self.residual = result.report.get("max_del_residual")
        if isinstance(self.step, float) and self.step.is_integer():
            self.step = int(self.step)


def _call(f, *args):
    try:
        return f(*args)
    except _dvm._InputError as e:
        raise InputError(str(e)) from None


# ---- values as the scene reader reads them ------------------------------------------

def _toml(value, where):
    """A Python value written as one TOML value (numbers exactly: repr round-trips)."""
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        value = value.tolist()  # numpy arrays and scalars
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if _math.isnan(value):
            return "nan"
        if _math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        out = ['"']
        for c in value:
            if c == '"':
                out.append('\\"')
            elif c == "\\":
                out.append("\\\\")
            elif c == "\n":
                out.append("\\n")
            elif c == "\t":
                out.append("\\t")
            elif ord(c) < 0x20 or ord(c) == 0x7F:
                out.append("\\u%04x" % ord(c))
            else:
                out.append(c)
        out.append('"')
        return "".join(out)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v, where) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(_toml(str(k), where) + " = " + _toml(v, where) for k, v in value.items()) + " }"
    raise TypeError(f"{where}: a {type(value).__name__} is not a scene value; expected a number, a string, "
                    "a bool, a list or a dict")


def _overrides(keys):
    """{'integrator.step': 0.01, 'system': {'params': {'mu': 2}}} -> ["integrator.step=0.01",
    "system.params.mu=2"]: nested dicts name sections and tables, as dotted keys do."""
    out = []

    def add(prefix, value):
        if isinstance(value, dict) and value:
            for k, v in value.items():
                add(prefix + "." + str(k), v)
        else:
            out.append(prefix + "=" + _toml(value, prefix))

    for k, v in keys.items():
        add(str(k), v)
    return out


# ---- scenes and runs ------------------------------------------------------------------

class Scene:
    """A scene read and validated by the scene reader of the dvm program (use
    :func:`load_scene`). Read-only attributes: ``path``, ``system`` (its name),
    ``dim``, ``step``, ``steps``, ``every``, ``monitor_every``, ``boundary_value``,
    ``method`` (a label), ``csv`` and ``npy`` (the scene's [output] files, which
    :func:`run` does not write)."""

    def __init__(self, handle, overrides):
        self._handle = handle
        self.overrides = list(overrides)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._handle, name)

    def __repr__(self):
        return (f"<dvm.Scene {self.path!r}: {self.system}, {self.method}, h = {self.step!r}, "
                f"{self.steps} steps>")


def load_scene(source, **overrides):
    """Reads and checks a scene as ``dvm run`` does.

    source: a path (str or os.PathLike) of a scene file, or the scene's TOML text
    (a str holding a newline).
    overrides: scene keys and values, applied as ``dvm run --set KEY=VALUE`` applies
    them (then the whole scene is checked): a dotted key through a dict,
    ``load_scene(p, **{"integrator.step": 0.01})``, or a section as a dict,
    ``load_scene(p, integrator={"step": 0.01, "map": "theta"})``.

    Returns a :class:`Scene`. Raises :class:`InputError` with the program's message.
    """
    sets = _overrides(overrides)
    if isinstance(source, _os.PathLike):
        source = _os.fspath(source)
    if not isinstance(source, str):
        raise TypeError("load_scene: expected a path or the text of a scene, got " + type(source).__name__)
    is_text = "\n" in source
    handle = _call(_dvm._load_scene, source, is_text, "<scene text>" if is_text else source, sets)
    return Scene(handle, sets)


class Result:
    """The outcome of a run.

    Arrays (numpy float64 views into ``data``, no copy of a row):
      data      every row written (rows x columns): the initial state, every ``every``-th
                step and the last, as the CSV file of ``dvm run`` holds them
      columns   the column names (the CSV header)
      t         the times, shape (rows,)
      q, p      the state as stored, shape (rows, len(q_final)) and (rows, len(p_final))
                (R^n: coordinates; S^2: unit vectors; SO(3): the quaternion w, x, y, z
                and the body angular momentum)
      energy    the energy at each row, shape (rows,)
      result["name"]  any column by name (e.g. the conserved momenta the rows of the
                      manifold systems carry after the energy)

    Every field of the JSON report of ``dvm run --json`` is an attribute of the same
    name, as json.loads reads it: ``status``, ``system``, ``steps``, ``t_final``,
    ``q_final``, ``max_abs_energy_error``, ``invariants`` (each conserved quantity's
    initial value and largest error), ``failure`` for a failed run, ... (``report`` is
    the whole dict).
    """

    def __init__(self, report, columns, data):
        self.report = report
        self.columns = list(columns)
        self.data = data
        nq, npp = len(report.get("q_final") or []), len(report.get("p_final") or [])
        if self.columns and self.columns[1 + nq + npp] != "energy":
            raise RuntimeError(f"dvm: unexpected columns {self.columns} for {nq} + {npp} state numbers")
        self.t = data[:, 0]
        self.q = data[:, 1:1 + nq]
        self.p = data[:, 1 + nq:1 + nq + npp]
        self.energy = data[:, 1 + nq + npp]

    def __getattr__(self, name):
        report = self.__dict__.get("report", {})
        if name in report:
            return report[name]
        raise AttributeError(f"'Result' has no attribute '{name}' (its report's fields: {', '.join(report)})")

    def __getitem__(self, name):
        try:
            return self.data[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"{name!r}: not a column; the columns are {self.columns}") from None

    def __dir__(self):
        return sorted(set(super().__dir__()) | set(self.report))

    def __repr__(self):
        return (f"<dvm.Result {self.report.get('status')}: {self.report.get('system')}, {self.report.get('steps')} "
                f"steps to t = {self.report.get('t_final')}, {self.data.shape[0]} rows x {self.data.shape[1]} columns>")


class _ProgressBar:
    """progress=True: a text bar on a stream (sys.stderr), redrawn in place ("\\r") at
    each visit of the run's poll hook, and completed with a newline when the run ends.

        [##########..........]  50.0%  step 500000/1000000  1.2 s, 1 s left

    A boundary-value problem counts the iterations of its solve against their most
    (integrator.max_iterations)."""

    WIDTH = 30

    def __init__(self, stream, unit, total):
        self.stream, self.unit, self.total = stream, unit, total
        self.start = _time.monotonic()
        self.shown = False
        if total:
            self.draw(0, total)

    def __call__(self, k, total):
        self.total = total
        self.draw(k, total)

    def draw(self, k, total, fraction=None, note=None):
        if fraction is None:
            fraction = min(max(k / total, 0.0), 1.0) if total > 0 else 1.0
        filled = int(fraction * self.WIDTH + 0.5)
        elapsed = _time.monotonic() - self.start
        if note is None:
            note = f"{elapsed:.1f} s"
            if 0.0 < fraction < 1.0 and self.unit == "step":
                note += f", {elapsed * (1.0 - fraction) / fraction:.0f} s left"
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.WIDTH - filled)}] {100.0 * fraction:5.1f}%  "
                          f"{self.unit} {k}/{total}  {note}   ")
        self.stream.flush()
        self.shown = True

    def finish(self, result):
        """The last frame: the whole bar for a completed run, then a newline."""
        elapsed = _time.monotonic() - self.start
        if result is not None and self.unit == "step":
            self.draw(result.report.get("steps"), self.total, 1.0, f"{elapsed:.1f} s")
        elif result is not None:
            self.draw(result.report.get("solver_iterations"), self.total or "?", 1.0, f"{elapsed:.1f} s, solved")
        if self.shown:
            self.stream.write("\n")
            self.stream.flush()


def _progress_of(progress, scene):
    """The poll hook's function for run's ``progress``: None, a function, or True (a bar)."""
    if progress is None or progress is False:
        return None, None
    if progress is True:
        bar = (_ProgressBar(_sys.stderr, "iteration", None) if scene.boundary_value
               else _ProgressBar(_sys.stderr, "step", scene.steps))
        return bar, bar
    if not callable(progress):
        raise TypeError("progress: expected None, True (a bar on stderr) or a function progress(step, steps), got "
                        + type(progress).__name__)
    return progress, None


def run(scene, progress=None):
    """Runs a scene (from :func:`load_scene`) as ``dvm run`` does and returns its
    :class:`Result`: the rows its CSV would hold (``[output] every`` applies; no file is
    written) and its report.

    progress: None; True, for a text bar on stderr (the steps done, the time taken and
    left), redrawn while the run goes and completed when it ends; or a function called
    as progress(step, steps) from the run's thread about every 0.05 s while it runs (an
    exception it raises stops the run). For a boundary-value problem the bar and the
    function count the iterations of its solve: progress(iteration, max_iterations).

    The GIL is released while the run integrates. Raises :class:`StepFailure` when a
    step fails (its ``result`` holds the rows up to it), KeyboardInterrupt on Ctrl-C
    (also during the solve of a boundary-value problem), :class:`InputError` for a run
    the runtime refuses.
    """
    if not isinstance(scene, Scene):
        raise TypeError("run: expected a dvm.Scene (from dvm.load_scene), got " + type(scene).__name__)
    hook, bar = _progress_of(progress, scene)
    result, failure = None, ""
    try:
        report_text, failure, columns, data = _call(_dvm._run, scene._handle, scene.every, scene.monitor_every, hook)
        result = Result(_json.loads(report_text), columns, data)
    finally:
        if bar is not None:
            bar.finish(None if result is None or failure else result)
    if failure:
        raise StepFailure(failure, result)
    return result


# ---- systems, methods, integrate ------------------------------------------------------

class System:
    """A mechanical system: a built-in one, or a Lagrangian written as scenes write it.

        System(builtin="kepler", params={"mu": 1.0})
        System(coordinates=["th1", "th2"], lagrangian="...", params={...})
        System(coordinates=["x", "y", "z"], lagrangian="...", space="S^2")

    Every keyword is a key of the scene's [system] section (``dvm run --help`` lists
    them: builtin, params, lagrangian, coordinates, energy, hamiltonian, name, masses,
    space, ends, definitions, compile, invariants); they are checked by the scene reader
    when the system runs, with its messages.
    """

    def __init__(self, builtin=None, **keys):
        self.keys = dict(keys)
        if builtin is not None:
            self.keys["builtin"] = builtin

    def __repr__(self):
        return "dvm.System(" + ", ".join(f"{k}={v!r}" for k, v in self.keys.items()) + ")"


class Method:
    """How a system is integrated: the keys of the scene's [integrator] section.

        Method(map="midpoint")
        Method(map="explicit-euler", composition="kahan-li8")
        Method(galerkin=6)                  # method = "galerkin", stages = 6
        Method(galerkin=4, quadrature="lobatto")
        Method(form="hamiltonian", map="theta", theta=0.3)

    Keys: map, theta, form, lift, composition, weights, thetas, method, stages,
    quadrature, gamma, beta, solver, max_iterations, tolerance, use_structure (see
    ``dvm run --help``); ``written_map`` is the scene's [map] section (map = "written").
    The step and the number of steps are arguments of :func:`integrate`.
    """

    def __init__(self, galerkin=None, written_map=None, **keys):
        self.keys = dict(keys)
        if galerkin is not None:
            self.keys.setdefault("method", "galerkin")
            self.keys["stages"] = galerkin
        self.written_map = written_map

    def __repr__(self):
        return "dvm.Method(" + ", ".join(f"{k}={v!r}" for k, v in self.keys.items()) + ")"


def integrate(system, method=None, *, q0=None, p0=None, v0=None, h=None, steps=None, t_end=None, every=1,
              monitor_every=None, initial=None, problem=None, progress=None):
    """Integrates ``system`` with ``method`` and returns a :class:`Result`.

    q0: the initial configuration ([initial] q; SO(3): give ``initial={"rotation": ...,
    "omega": ...}`` instead); p0 or v0: the initial momentum or velocity; h: the step;
    steps or t_end: how far; every: the steps between two rows kept (the initial state
    and the last are always kept); monitor_every: the steps between evaluations of the
    energy and invariants (default 1); initial, problem: further keys of the scene's
    [initial] and [problem] sections (problem={"kind": "boundary-value", "q_final": ...,
    "steps": K} for a boundary-value problem); progress: as in :func:`run` (True: a
    bar on stderr; a function: progress(step, steps)).

    The arguments become the keys of a scene read by the program's scene reader, so a
    refused value raises :class:`InputError` with the program's message, which names the
    scene key ('initial.q', 'integrator.step', ...) and where "(from --set)" would stand
    in the program's, the argument that gave it: "dvm.integrate (from argument h): key
    'integrator.step': ...", "(from the System)", "(from the Method)". Raises
    :class:`StepFailure` when a step fails.
    """
    if not isinstance(system, System):
        raise TypeError("integrate: expected a dvm.System, got " + type(system).__name__)
    if method is None:
        method = Method()
    if not isinstance(method, Method):
        raise TypeError("integrate: expected a dvm.Method, got " + type(method).__name__)
    keys = {"system": dict(system.keys), "integrator": dict(method.keys)}
    ini = dict(initial or {})
    for name, value in (("q", q0), ("p", p0), ("v", v0)):
        if value is not None:
            ini[name] = value
    if ini:
        keys["initial"] = ini
    for name, value in (("step", h), ("steps", steps), ("t_end", t_end)):
        if value is not None:
            keys["integrator"][name] = value
    output = {}
    if every != 1:
        output["every"] = every
    if monitor_every is not None:
        output["monitor_every"] = monitor_every
    if output:
        keys["output"] = output
    if problem:
        keys["problem"] = dict(problem)
    if method.written_map is not None:
        keys["map"] = dict(method.written_map)
    # the sections present (even empty), so that a message names a missing key, not a
    # missing section
    text = "[system]\n[initial]\n[integrator]\n"
    try:
        handle = _call(_dvm._load_scene, text, True, "dvm.integrate", _overrides(keys))
        return run(Scene(handle, []), progress=progress)
    except InputError as e:
        raise InputError(_integrate_message(str(e))) from None


# the arguments of integrate that give one scene key each
_INTEGRATE_ARGUMENTS = {"initial.q": "argument q0", "initial.p": "argument p0", "initial.v": "argument v0",
                        "integrator.step": "argument h", "integrator.steps": "argument steps",
                        "integrator.t_end": "argument t_end", "output.every": "argument every",
                        "output.monitor_every": "argument monitor_every"}
_INTEGRATE_SECTIONS = {"system": "the System", "integrator": "the Method", "map": "the Method's written_map",
                       "initial": "argument initial", "problem": "argument problem", "output": "the arguments"}
_FROM_SET = _re.compile(r"dvm\.integrate \(from --set\)(?=: (?:key '(?P<key>[^']+)'|character \d+ of the value: "
                        r"in (?P<within>[A-Za-z_][\w.\[\]]*))|)")


def _integrate_origin(key):
    """What gave a scene key integrate wrote: "argument h", "the System", ..."""
    if not key:
        return "the arguments"
    key = key.split("[")[0]
    if key in _INTEGRATE_ARGUMENTS:
        return _INTEGRATE_ARGUMENTS[key]
    return _INTEGRATE_SECTIONS.get(key.split(".")[0], "the arguments")


def _integrate_message(message):
    """The scene reader's message for integrate's scene, where "(from --set)" (a key
    without a position in a file) becomes the argument that gave the key:
    "dvm.integrate (from argument h): key 'integrator.step': ..."."""
    return _FROM_SET.sub(lambda m: f"dvm.integrate (from {_integrate_origin(m.group('key') or m.group('within'))})",
                         message)


# ---- convergence studies ----------------------------------------------------------------

class Convergence:
    """A convergence study (:func:`converge`): every field of ``dvm converge --json`` as
    an attribute (``t_end``, ``reference``, ``reference_accuracy``, ``runs``,
    ``fitted_order``, ``map_order``, ``method_order``, ``fit_note``, ``warnings``, ...;
    ``report`` is the whole dict), and the runs' columns as numpy arrays ``steps``,
    ``h``, ``error``, ``order`` (NaN where the JSON has null: the first run's order)."""

    def __init__(self, report):
        import numpy as np
        self.report = report
        runs = report.get("runs") or []

        def column(name):
            return np.array([np.nan if r.get(name) is None else r[name] for r in runs], dtype=np.float64)

        self.steps = np.array([int(r["steps"]) for r in runs], dtype=np.int64)
        self.h, self.error, self.order = column("h"), column("error"), column("order")

    def __getattr__(self, name):
        report = self.__dict__.get("report", {})
        if name in report:
            return report[name]
        raise AttributeError(f"'Convergence' has no attribute '{name}' (its fields: {', '.join(report)})")

    def __repr__(self):
        return (f"<dvm.Convergence {self.report.get('system')}, {len(self.steps)} runs, fitted order "
                f"{self.report.get('fitted_order')}>")


def _is_whole(value, least):
    return (not isinstance(value, bool) and isinstance(value, (int, float)) and _math.isfinite(value)
            and value == int(value) and value >= least)


def converge(scene, steps=None, t_end=None, max_steps=None):
    """A convergence study of a scene's run, as ``dvm converge`` makes it: the run at
    several step counts N to the time T (h = T/N), the error of each at T against the
    exact solution or a refined higher-order reference, the observed orders and a
    fitted order. Returns a :class:`Convergence`.

    steps: the step counts (``--steps-list``; default the scene's count times 1, 2, 4,
    8); t_end: T (``--t-end``; default the scene's span); max_steps: the most steps the
    runs may take together (``--max-steps``). Messages name them as the program's
    options. Raises :class:`InputError` for input the program refuses and
    :class:`StepFailure` when a run of the study fails (``dvm converge`` exits with
    status 3 then).
    """
    if not isinstance(scene, Scene):
        raise TypeError("converge: expected a dvm.Scene (from dvm.load_scene), got " + type(scene).__name__)
    steps_list = []
    if steps is not None:
        for n in steps:
            if not _is_whole(n, 1):
                raise InputError(f"--steps-list: '{n}' is not a whole number of steps >= 1")
            if n > 9e15:
                raise InputError(f"--steps-list: '{n}' is more steps than a run can count (at most 9e15)")
            steps_list.append(int(n))
        if len(steps_list) < 2:
            raise InputError("--steps-list needs at least two step counts")
    if t_end is None:
        t_end = 0.0
    elif isinstance(t_end, bool) or not isinstance(t_end, (int, float)) or not (t_end > 0) or _math.isinf(t_end):
        raise InputError("--t-end: expected a positive number")
    if max_steps is not None and not _is_whole(max_steps, 1):
        raise InputError(f"--max-steps: got '{max_steps}', expected a whole number >= 1")
    total = _dvm._converge_max_total_steps if max_steps is None else max_steps
    report = _json.loads(_call(_dvm._converge, scene._handle, steps_list, float(t_end), float(total)))
    study = Convergence(report)
    if report.get("failure"):
        raise StepFailure("a run of the convergence study did not converge: " + report["failure"], study)
    return study


# ---- map checks ----------------------------------------------------------------------

class MapCheck:
    """The identity checks of a discretization map (:func:`check_map`): every field of
    ``dvm check-map``'s JSON as an attribute: ``map``, ``space`` ("R^n", "S^2",
    "SO(3)"), ``theta``, ``dim`` (the dimension the identities were checked in; on a
    manifold its chart's), ``claims_symmetric``, ``residuals`` (a dict: each identity's
    largest residual over the sample points), ``tolerance`` and ``passed`` (every
    identity holds to the tolerance and adjoint_difference matches the symmetry claim;
    ``dvm check-map`` exits with status 1 when not). ``report`` is the whole dict."""

    def __init__(self, report):
        self.report = report

    def __getattr__(self, name):
        report = self.__dict__.get("report", {})
        if name in report:
            return report[name]
        raise AttributeError(f"'MapCheck' has no attribute '{name}' (its fields: {', '.join(report)})")

    def __bool__(self):
        return bool(self.report.get("passed"))

    def __repr__(self):
        worst = max(self.report.get("residuals", {}).items(), key=lambda kv: -1.0 if kv[1] is None else kv[1],
                    default=(None, None))
        return (f"<dvm.MapCheck {self.report.get('map')} on {self.report.get('space')}: "
                f"{'passed' if self.report.get('passed') else 'failed'} (largest residual {worst[1]!r}, "
                f"{worst[0]})>")


def _finite_option(option, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not _math.isfinite(value):
        raise InputError(f"{option}: got '{value}', expected a finite number")
    return float(value)


def check_map(map, theta=None, dim=None, tolerance=1e-12):
    """Checks the identities of a discretization map, as ``dvm check-map`` does:
    R_d(x, 0) = (x, x), T R^2 - T R^1 = Id, the inverse's round trip, the adjoint's
    involution and the symmetry claim, the same axioms for the tangent lift, the
    symplecticity and round trip of the cotangent lift; on S^2 and SO(3) in a chart,
    and the closed-form inverse on the manifold. Each residual is the largest over
    random sample points (the same points every call).

    map: a map's name (:func:`maps` lists them; ``dvm check-map NAME``), or a
    :class:`Scene`: the map it runs, a written one from its [map] section
    (``dvm check-map --scene FILE``). theta: the theta of a theta map (``--theta``,
    default the map's own; a scene's is its integrator.theta); dim: 1 to 4, the
    dimension of R^n the identities are checked in (``--dim``, default 2; maps on a
    manifold take none); tolerance: ``--tolerance`` (default 1e-12).

    Returns a :class:`MapCheck` (true when the check passed). Raises
    :class:`InputError` with the program's message (naming its options) for an unknown
    map, a theta, dim or tolerance it refuses.
    """
    if theta is not None:
        given, theta = theta, _finite_option("--theta", theta)
        if not (0.0 <= theta <= 1.0):
            raise InputError(f"--theta: got {given}, expected a number in [0, 1]")
    if dim is not None:
        d = _finite_option("--dim", dim)
        if d != int(d) or d < 1 or d > 4:
            raise InputError("--dim: expected 1, 2, 3 or 4")
        dim = int(d)
    tolerance = _finite_option("--tolerance", tolerance)
    if not (tolerance > 0):
        raise InputError("--tolerance: expected a positive number")
    if isinstance(map, Scene):
        if theta is not None:
            raise InputError("--theta: with --scene, the scene's integrator.theta is the map's (use --set)")
        text = _call(_dvm._check_scene_map, map._handle, dim or 0, tolerance)
    elif isinstance(map, str):
        text = _call(_dvm._check_map, map, -1.0 if theta is None else theta, dim or 0, tolerance)
    else:
        raise TypeError("check_map: expected a map's name or a dvm.Scene, got " + type(map).__name__)
    return MapCheck(_json.loads(text))


# ---- listings -----------------------------------------------------------------------

def systems():
    """The built-in systems as ``dvm systems --json`` lists them: a list of dicts (name,
    dim, lagrangian, space, params with defaults, forms, and what each runs)."""
    return _json.loads(_dvm._systems_json())


def maps():
    """The discretization maps as ``dvm maps --json`` lists them: a list of dicts (name,
    formula, symmetric, order, closed_form_inverse, space, note, takes_theta)."""
    return _json.loads(_dvm._maps_json())


def methods():
    """The methods as ``dvm methods --json`` lists them: the compositions (order,
    stages, symmetry, stability threshold with the explicit Euler map, forces a step),
    the Galerkin discrete Lagrangians and the lifts, a list of dicts."""
    return _json.loads(_dvm._methods_json())
