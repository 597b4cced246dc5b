# The API beside scenes: System, Method and integrate against the program on the
# shipped scenes they restate; the arrays' shapes, dtypes, names and memory; the
# listings; overrides; progress.
import json

import numpy as np
import pytest

import dvm
from conftest import assert_same_report, program, program_run, same_bits, scene

KEPLER = dvm.System(builtin="kepler", params={"mu": 1.0})
Q0, P0 = [0.4, 0.0], [0.0, 2.0]


def check_equal(result, name, tmp_path, overrides=()):
    expected, header, rows = program_run(scene(name), list(overrides), str(tmp_path))
    assert result.columns == header
    assert same_bits(result.data, rows)
    assert_same_report(result, expected)


def test_integrate_kepler_midpoint_equals_the_scene(tmp_path):
    r = dvm.integrate(KEPLER, dvm.Method(map="midpoint"), q0=Q0, p0=P0, h=0.005, t_end=100.0, every=20)
    check_equal(r, "kepler.toml", tmp_path)


def test_integrate_composition_and_galerkin(tmp_path):
    r = dvm.integrate(KEPLER, dvm.Method(map="explicit-euler", composition="kahan-li8"), q0=Q0, p0=P0,
                      h=0.05, t_end=100.0, every=20)
    check_equal(r, "kepler-composition.toml", tmp_path)
    g = dvm.integrate(KEPLER, dvm.Method(galerkin=6, quadrature="gauss"), q0=np.array(Q0), p0=np.array(P0),
                      h=0.05, t_end=100.0, every=20)
    check_equal(g, "kepler-galerkin.toml", tmp_path)
    assert g.method == "galerkin" and g.stages == 6 and g.order == 12


def test_integrate_a_written_lagrangian(tmp_path):
    pendulum = dvm.System(coordinates=["theta"], params={"m": 1.0, "l": 1.0, "g": 1.0},
                          lagrangian="0.5*m*l^2*theta_dot^2 + m*g*l*cos(theta)",
                          energy="0.5*m*l^2*theta_dot^2 - m*g*l*cos(theta)",
                          hamiltonian="p_theta^2/(2*m*l^2) - m*g*l*cos(theta)")
    r = dvm.integrate(pendulum, dvm.Method(map="midpoint"), q0=[2.0], p0=[0.0], h=0.01, t_end=100.0, every=10)
    check_equal(r, "pendulum_written.toml", tmp_path)
    assert r.columns == ["t", "theta", "p_theta", "energy"]


def test_integrate_on_so3(tmp_path):
    body = dvm.System(builtin="rigid-body", params={"I1": 1.0, "I2": 2.0, "I3": 3.0})
    r = dvm.integrate(body, dvm.Method(map="so3-cayley"), initial={"rotation": [1.0, 0.0, 0.0, 0.0],
                                                                      "omega": [0.05, 1.0, 0.02]},
                      h=0.01, t_end=100.0, every=10)
    check_equal(r, "rigid-body.toml", tmp_path)
    assert r.q.shape == (r.data.shape[0], 4)  # the quaternion w, x, y, z
    assert np.allclose(np.linalg.norm(r.q, axis=1), 1.0, atol=1e-14, rtol=0)


def test_shapes_dtypes_names_and_no_copy():
    r = dvm.integrate(KEPLER, dvm.Method(map="midpoint"), q0=Q0, p0=P0, h=0.01, steps=1000, every=10)
    rows = 1000 // 10 + 1
    assert r.columns == ["t", "q0", "q1", "p0", "p1", "energy"]
    assert r.data.shape == (rows, 6) and r.data.dtype == np.float64
    assert r.t.shape == (rows,) and r.energy.shape == (rows,)
    assert r.q.shape == (rows, 2) and r.p.shape == (rows, 2)
    for a in (r.t, r.q, r.p, r.energy):
        assert a.dtype == np.float64
        assert np.shares_memory(a, r.data)  # views of the one table
    assert not r.data.flags.owndata  # the buffer the recorder filled, owned by its capsule
    assert r.data.flags.c_contiguous
    assert same_bits(r.t, 0.01 * np.arange(0, 1001, 10, dtype=np.float64))
    assert r.steps == 1000 and r.status == "ok" and r.steps_requested == 1000
    assert same_bits(r.q[-1], np.array(r.q_final)) and same_bits(r.p[-1], np.array(r.p_final))
    assert r.energy[0] == r.energy_initial and r.energy[-1] == r.energy_final
    assert r.invariants["angular momentum"]["initial"] == pytest.approx(0.8, abs=1e-15)
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        r.nonsense
    with pytest.raises(KeyError, match="not a column"):
        r["nonsense"]


def test_rows_outlive_the_result():
    r = dvm.integrate(KEPLER, dvm.Method(map="midpoint"), q0=Q0, p0=P0, h=0.01, steps=100)
    q, first = r.q, r.q.copy()
    del r
    assert same_bits(q, first)


def test_load_scene_overrides_are_those_of_set(tmp_path):
    over = ["integrator.step=0.01", "integrator.map=\"theta\"", "integrator.theta=0.25", "system.params.mu=2.0"]
    a = dvm.run(dvm.load_scene(scene("kepler.toml"), **{"integrator.step": 0.01, "integrator.map": "theta",
                                                       "integrator.theta": 0.25, "system.params.mu": 2.0}))
    check_equal(a, "kepler.toml", tmp_path, over)
    b = dvm.run(dvm.load_scene(scene("kepler.toml"), integrator={"step": 0.01, "map": "theta", "theta": 0.25},
                               system={"params": {"mu": 2.0}}))
    assert same_bits(a.data, b.data)


def test_load_scene_from_text_and_pathlike():
    import pathlib
    path = scene("pendulum.toml")
    with open(path) as f:
        text = f.read()
    a = dvm.run(dvm.load_scene(path))
    b = dvm.run(dvm.load_scene(text))
    c = dvm.run(dvm.load_scene(pathlib.Path(path)))
    assert same_bits(a.data, b.data) and same_bits(a.data, c.data)
    s = dvm.load_scene(path)
    assert s.system == "pendulum" and s.every == 10 and s.path == path


@pytest.mark.parametrize("name", ["systems", "maps", "methods"])
def test_listings_are_the_programs(name, tmp_path):
    status, out, err = program([name, "--json"], str(tmp_path))
    assert status == 0, err
    assert getattr(dvm, name)() == json.loads(out)


def test_progress_is_called_and_can_stop_a_run():
    seen = []
    steps = 3_000_000
    dvm.integrate(KEPLER, dvm.Method(map="explicit-euler", composition="stormer-verlet"), q0=Q0, p0=P0, h=1e-4,
                  steps=steps, every=steps, progress=lambda k, n: seen.append((k, n)))
    assert seen, "no progress reported during a run of several tenths of a second at least"
    assert all(n == steps and 0 < k < steps and k % dvm._dvm._poll_steps == 0 for k, n in seen)
    assert [k for k, _ in seen] == sorted(set(k for k, _ in seen))

    class Stop(Exception):
        pass

    def stop(k, n):
        raise Stop(k)

    with pytest.raises(Stop):
        dvm.integrate(KEPLER, dvm.Method(map="explicit-euler", composition="stormer-verlet"), q0=Q0, p0=P0,
                      h=1e-4, steps=steps, every=steps, progress=stop)


def test_docstrings():
    for f in (dvm, dvm.load_scene, dvm.run, dvm.integrate, dvm.System, dvm.Method, dvm.Result, dvm.InputError,
              dvm.StepFailure, dvm.systems, dvm.maps, dvm.methods, dvm.check_map, dvm.MapCheck):
        assert f.__doc__ and len(f.__doc__) > 80, f


@pytest.mark.parametrize("name, steps, t_end", [("harmonic.toml", [100, 200, 400], 1.0),
                                                ("pendulum.toml", [100, 200, 400], 1.0),
                                                ("kepler-composition.toml", [20, 40, 80], 2.0)])
def test_converge_equals_dvm_converge(name, steps, t_end, tmp_path):
    status, out, err = program(["converge", scene(name), "--steps-list", ",".join(map(str, steps)), "--t-end",
                                repr(t_end), "--json"], str(tmp_path))
    assert status == 0, err
    expected = json.loads(out)
    study = dvm.converge(dvm.load_scene(scene(name)), steps=steps, t_end=t_end)
    assert set(study.report) == set(expected)
    for k, v in expected.items():
        if k == "runs":
            assert len(study.runs) == len(v)
            for a, b in zip(study.runs, v):
                assert {x: y for x, y in a.items() if x != "wall_seconds"} == \
                       {x: y for x, y in b.items() if x != "wall_seconds"}
        else:
            assert getattr(study, k) == v, k
    assert list(study.steps) == steps and study.steps.dtype == np.int64
    assert same_bits(study.h, np.array([r["h"] for r in expected["runs"]]))
    assert same_bits(study.error, np.array([r["error"] for r in expected["runs"]]))
    assert np.isnan(study.order[0]) and same_bits(study.order[1:], np.array([r["order"] for r in expected["runs"][1:]]))


@pytest.mark.parametrize("kwargs, args", [
    ({"steps": [100]}, ["--steps-list", "100"]),
    ({"steps": [100, 100]}, ["--steps-list", "100,100"]),
    ({"steps": [100, 0]}, ["--steps-list", "100,0"]),
    ({"steps": [100, 200], "t_end": -1.0}, ["--steps-list", "100,200", "--t-end", "-1.0"]),
    ({"steps": [100, 200], "max_steps": 250}, ["--steps-list", "100,200", "--max-steps", "250"]),
], ids=["one count", "twice", "zero", "t_end", "max_steps"])
def test_converge_refuses_as_the_program(kwargs, args, tmp_path):
    code, _, err = program(["converge", scene("harmonic.toml")] + args, str(tmp_path))
    assert code == 2 and err.startswith("dvm: "), err
    expected = err[len("dvm: "):].split("\n")[0]
    with pytest.raises(dvm.InputError) as e:
        dvm.converge(dvm.load_scene(scene("harmonic.toml")), **kwargs)
    assert str(e.value) == expected
