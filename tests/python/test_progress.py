# Long runs: progress=True draws a bar on stderr (its frames follow the run, the last
# is the whole bar), and the progress hook reaches the solve of a boundary-value
# problem (called after its iterations; an exception from it stops the solve).
import re
import time

import pytest

import dvm
from conftest import same_bits, scene

KEPLER = dvm.System(builtin="kepler")
VERLET = dvm.Method(map="explicit-euler", composition="stormer-verlet")
Q0, P0 = [0.4, 0.0], [0.0, 2.0]

FRAME = re.compile(r"^\[(?P<bar>[#.]+)\]\s+(?P<percent>\d+\.\d)%  (?P<unit>step|iteration) (?P<k>\d+)/(?P<n>\d+|\?)  ")


def frames(err):
    """The bar's frames, each drawn after a carriage return, parsed."""
    assert err.endswith("\n"), repr(err)
    out = []
    for text in err[:-1].split("\r"):
        if not text:
            continue
        m = FRAME.match(text)
        assert m, repr(text)
        out.append(m)
    return out


def test_a_bar_on_a_short_run(capsys):
    r = dvm.integrate(KEPLER, VERLET, q0=Q0, p0=P0, h=1e-3, steps=1000, every=10, progress=True)
    f = frames(capsys.readouterr().err)
    assert f[0]["k"] == "0" and f[0]["n"] == "1000" and float(f[0]["percent"]) == 0.0
    assert set(f[0]["bar"]) == {"."}
    last = f[-1]
    assert (last["unit"], last["k"], last["n"], last["percent"]) == ("step", "1000", "1000", "100.0")
    assert set(last["bar"]) == {"#"} and len(last["bar"]) == len(f[0]["bar"])
    # the bar changes nothing of the run
    plain = dvm.integrate(KEPLER, VERLET, q0=Q0, p0=P0, h=1e-3, steps=1000, every=10)
    assert same_bits(r.data, plain.data)
    assert capsys.readouterr().err == ""


def test_the_bar_follows_a_long_run(capsys):
    steps = 3_000_000  # several tenths of a second at least: the hook runs every 0.05 s
    dvm.integrate(KEPLER, VERLET, q0=Q0, p0=P0, h=1e-4, steps=steps, every=steps, progress=True)
    f = frames(capsys.readouterr().err)
    middle = f[1:-1]
    assert middle, "no frame drawn during the run"
    ks = [int(m["k"]) for m in middle]
    assert ks == sorted(ks) and all(0 < k < steps and k % dvm._dvm._poll_steps == 0 for k in ks)
    for m in middle:  # the percentage and the bar's length are the step's share
        share = int(m["k"]) / steps
        assert abs(float(m["percent"]) - 100 * share) <= 0.05 + 1e-9
        assert abs(m["bar"].count("#") - share * len(m["bar"])) <= 0.5 + 1e-9
    assert f[-1]["percent"] == "100.0"


def test_the_bar_ends_its_line_when_a_run_fails(capsys):
    with pytest.raises(dvm.StepFailure):
        dvm.run(dvm.load_scene(scene("pendulum.toml"), **{"integrator.step": 4.0, "integrator.t_end": 400.0}),
                progress=True)
    f = frames(capsys.readouterr().err)
    assert f[-1]["percent"] != "100.0"  # the last frame drawn before the failure


def test_progress_must_be_a_function_or_true():
    with pytest.raises(TypeError, match="progress"):
        dvm.integrate(KEPLER, VERLET, q0=Q0, p0=P0, h=1e-3, steps=10, progress="yes")


# a boundary-value problem whose solve takes tens of iterations and most of a second:
# the pendulum of the shipped scene on twice its nodes
BVP = {"problem": {"steps": 20000}, "integrator": {"step": 1e-4}}


def bvp(**overrides):
    keys = {k: dict(v) for k, v in BVP.items()}
    for section, values in overrides.items():
        keys[section].update(values)
    return dvm.load_scene(scene("pendulum_bvp.toml"), **keys)


def test_progress_during_a_boundary_value_solve():
    seen = []
    r = dvm.run(bvp(integrator={"max_iterations": 200}), progress=lambda k, n: seen.append((k, n)))
    assert r.status == "ok" and r.problem == "boundary-value"
    assert seen, f"no call during a solve of {r.wall_seconds} s"
    assert all(n == 200 for _, n in seen)
    ks = [k for k, _ in seen]
    assert ks == sorted(set(ks)) and 0 <= ks[0] and ks[-1] <= r.solver_iterations


def test_an_exception_from_progress_stops_a_boundary_value_solve():
    class Stop(Exception):
        pass

    calls = []

    def stop(k, n):
        calls.append(k)
        raise Stop(k)

    start = time.perf_counter()
    with pytest.raises(Stop):  # the solve stops at the first call
        dvm.run(bvp(), progress=stop)
    took = time.perf_counter() - start
    assert len(calls) == 1
    start = time.perf_counter()
    r = dvm.run(bvp())  # the same solve to its end; and the module runs again
    whole = time.perf_counter() - start
    assert r.status == "ok" and calls[0] < r.solver_iterations
    assert took < whole, f"the stopped solve took {took} s, the whole one {whole} s"


def test_a_bar_on_a_boundary_value_solve(capsys):
    r = dvm.run(bvp(), progress=True)
    f = frames(capsys.readouterr().err)
    assert all(m["unit"] == "iteration" for m in f)
    last = f[-1]
    assert last["percent"] == "100.0" and int(last["k"]) == r.solver_iterations
