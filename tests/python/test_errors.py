# Every error path raises the documented exception with the program's message: bad
# input InputError (a ValueError naming the key and its position), a failed step
# StepFailure (the step, time, residual and the rows up to it).
import json
import os

import numpy as np
import pytest

import dvm
from conftest import program, program_message, read_csv, same_bits, scene, sets

KEPLER_SCENE = """[system]
builtin = "kepler"

[initial]
q = [0.4, 0.0]
p = [0.0, 2.0]

[integrator]
mpa = "midpoint"
step = 0.01
steps = 10
"""

# what dvm.integrate gives the scene reader: a scene named dvm.integrate with its three
# sections, the arguments as --set overrides (the program reads the same from a file of
# that name); its messages name the argument where the program's say "(from --set)"
INTEGRATE_BASE = "[system]\n[initial]\n[integrator]\n"


def integrate_message(overrides, tmp_path):
    with open(os.path.join(tmp_path, "dvm.integrate"), "w") as f:
        f.write(INTEGRATE_BASE)
    return program_message(["run", "dvm.integrate", "--no-output"] + sets(overrides), str(tmp_path))


def test_a_key_in_a_file(tmp_path):
    path = os.path.join(tmp_path, "bad.toml")
    with open(path, "w") as f:
        f.write(KEPLER_SCENE)
    expected = program_message(["run", path], str(tmp_path))
    with pytest.raises(dvm.InputError) as e:
        dvm.load_scene(path)
    assert str(e.value) == expected
    assert isinstance(e.value, ValueError)
    assert e.value.key == "integrator.mpa" and e.value.source == path
    # the position of the key's value in the file
    line = KEPLER_SCENE.split("\n").index('mpa = "midpoint"') + 1
    assert (e.value.line, e.value.column) == (line, len("mpa = ") + 1)
    assert 'did you mean "map"?' in str(e.value)


def test_a_scene_given_as_text_names_its_keys():
    with pytest.raises(dvm.InputError) as e:
        dvm.load_scene(KEPLER_SCENE)
    line = KEPLER_SCENE.split("\n").index('mpa = "midpoint"') + 1
    assert e.value.key == "integrator.mpa" and e.value.line == line and e.value.source == "<scene text>"


def test_a_file_that_is_not_there(tmp_path):
    path = os.path.join(tmp_path, "none.toml")
    expected = program_message(["run", path], str(tmp_path))
    with pytest.raises(dvm.InputError) as e:
        dvm.load_scene(path)
    assert str(e.value) == expected


def test_an_override(tmp_path):
    expected = program_message(["run", scene("kepler.toml"), "--set", "integrator.step=-1.0"], str(tmp_path))
    with pytest.raises(dvm.InputError) as e:
        dvm.load_scene(scene("kepler.toml"), **{"integrator.step": -1.0})
    assert str(e.value) == expected
    assert e.value.key == "integrator.step" and e.value.line is None


def test_a_rule_between_keys(tmp_path):
    # validate()'s rule, with the position of the key it names
    over = ["integrator.composition=\"kahan-li8\"", "integrator.method=\"galerkin\""]
    expected = program_message(["run", scene("kepler.toml")] + sets(over), str(tmp_path))
    with pytest.raises(dvm.InputError) as e:
        dvm.load_scene(scene("kepler.toml"), integrator={"composition": "kahan-li8", "method": "galerkin"})
    assert str(e.value) == expected and e.value.key is not None


@pytest.mark.parametrize("case", [
    # (System keys, Method keys, integrate arguments, the same as --set overrides)
    ({"builtin": "kepelr"}, {"map": "midpoint"}, {"q0": [0.4, 0.0], "p0": [0.0, 2.0], "h": 0.01, "steps": 10},
     ['system.builtin="kepelr"', 'integrator.map="midpoint"', "initial.q=[0.4, 0.0]", "initial.p=[0.0, 2.0]",
      "integrator.step=0.01", "integrator.steps=10"]),
    ({"builtin": "kepler"}, {"map": "midpoint"}, {"q0": [0.4, 0.0, 1.0], "p0": [0.0, 2.0], "h": 0.01, "steps": 10},
     ['system.builtin="kepler"', 'integrator.map="midpoint"', "initial.q=[0.4, 0.0, 1.0]", "initial.p=[0.0, 2.0]",
      "integrator.step=0.01", "integrator.steps=10"]),
    ({"builtin": "kepler"}, {"map": "midpoint"}, {"q0": [0.4, 0.0], "p0": [0.0, 2.0], "h": 0.0, "steps": 10},
     ['system.builtin="kepler"', 'integrator.map="midpoint"', "initial.q=[0.4, 0.0]", "initial.p=[0.0, 2.0]",
      "integrator.step=0.0", "integrator.steps=10"]),
    ({"builtin": "kepler"}, {"mpa": "midpoint"}, {"q0": [0.4, 0.0], "p0": [0.0, 2.0], "h": 0.01, "steps": 10},
     ['system.builtin="kepler"', 'integrator.mpa="midpoint"', "initial.q=[0.4, 0.0]", "initial.p=[0.0, 2.0]",
      "integrator.step=0.01", "integrator.steps=10"]),
    ({"builtin": "kepler", "params": {"mu": 1.0, "m": 2.0}}, {"map": "midpoint"},
     {"q0": [0.4, 0.0], "p0": [0.0, 2.0], "h": 0.01, "steps": 10},
     ['system.builtin="kepler"', "system.params.mu=1.0", "system.params.m=2.0", 'integrator.map="midpoint"',
      "initial.q=[0.4, 0.0]", "initial.p=[0.0, 2.0]", "integrator.step=0.01", "integrator.steps=10"]),
    ({"builtin": "kepler"}, {"map": "midpoint"}, {"q0": [0.4, 0.0], "h": 0.01, "steps": 10},
     ['system.builtin="kepler"', 'integrator.map="midpoint"', "initial.q=[0.4, 0.0]",
      "integrator.step=0.01", "integrator.steps=10"]),
    ({"coordinates": ["x"], "lagrangian": "x_dot^2/2 - x^^2"}, {"map": "midpoint"},
     {"q0": [1.0], "v0": [0.0], "h": 0.01, "steps": 10},
     ['system.coordinates=["x"]', 'system.lagrangian="x_dot^2/2 - x^^2"', 'integrator.map="midpoint"',
      "initial.q=[1.0]", "initial.v=[0.0]", "integrator.step=0.01", "integrator.steps=10"]),
    ({"builtin": "kepler"}, {"map": "midpoint"}, {"q0": [0.4, 0.0], "p0": [0.0, 2.0], "h": 0.01, "t_end": -1.0},
     ['system.builtin="kepler"', 'integrator.map="midpoint"', "initial.q=[0.4, 0.0]", "initial.p=[0.0, 2.0]",
      "integrator.step=0.01", "integrator.t_end=-1.0"]),
    ({"builtin": "kepler"}, {"map": "midpoint"},
     {"q0": [0.4, 0.0], "p0": [0.0, 2.0], "h": 0.01, "steps": 10, "initial": {"w": 1.0}},
     ['system.builtin="kepler"', 'integrator.map="midpoint"', "initial.w=1.0", "initial.q=[0.4, 0.0]",
      "initial.p=[0.0, 2.0]", "integrator.step=0.01", "integrator.steps=10"]),
], ids=["unknown system", "size of q", "step", "unknown key", "unknown parameter", "no momentum",
        "written text", "t_end", "initial"])
def test_integrate_refuses_as_the_program(case, tmp_path):
    system, method, args, overrides = case
    expected = integrate_message(overrides, str(tmp_path))
    with pytest.raises(dvm.InputError) as e:
        dvm.integrate(dvm.System(**system), dvm.Method(**method), **args)
    # the program's message, with the argument that gave the key for "--set"
    origin = {"system": "the System", "integrator": "the Method", "initial": "argument initial"}
    key = e.value.key
    origin.update({"initial.q": "argument q0", "integrator.step": "argument h", "integrator.t_end": "argument t_end"})
    given = origin.get(key, origin.get(key.split(".")[0]))
    assert "(from --set)" not in str(e.value)
    assert str(e.value) == expected.replace("dvm.integrate (from --set)", f"dvm.integrate (from {given})")
    if "(from --set)" in expected:
        assert f"(from {given})" in str(e.value)
    assert e.value.source == "dvm.integrate"
    assert e.value.key and e.value.key.split(".")[0] in ("system", "initial", "integrator"), e.value.key
    assert e.value.line is None


def test_the_program_keeps_from_set(tmp_path):
    # the program's own messages for --set stay as they were
    message = integrate_message(['system.builtin="kepler"', 'integrator.map="midpoint"', "initial.q=[0.4, 0.0]",
                                 "initial.p=[0.0, 2.0]", "integrator.step=0.0", "integrator.steps=10"], str(tmp_path))
    assert message.startswith("dvm.integrate (from --set): key 'integrator.step'"), message


def test_values_that_are_not_scene_values():
    with pytest.raises(TypeError, match="initial.q"):
        dvm.integrate(dvm.System(builtin="kepler"), dvm.Method(map="midpoint"), q0=[object(), 0.0], p0=[0, 2],
                      h=0.01, steps=10)
    with pytest.raises(TypeError):
        dvm.run("kepler.toml")


def test_a_failed_step(tmp_path):
    over = ["integrator.step=4.0", "integrator.t_end=400.0", "output.every=1"]
    csv = os.path.join(tmp_path, "rows.csv")
    status, out, err = program(["run", scene("pendulum.toml"), "--csv", csv, "--json"] + sets(over), str(tmp_path))
    assert status == 3, err
    report = json.loads(out)
    kept = "; their rows are in " + csv + ".partial"
    assert err.startswith("dvm: ") and err.rstrip("\n").endswith(kept), err
    expected = err[len("dvm: "):].rstrip("\n")[:-len(kept)]
    header, rows = read_csv(csv + ".partial")
    with pytest.raises(dvm.StepFailure) as e:
        dvm.run(dvm.load_scene(scene("pendulum.toml"), **{"integrator.step": 4.0, "integrator.t_end": 400.0,
                                                         "output.every": 1}))
    f = e.value
    assert str(f) == expected and "did not converge" in str(f)
    assert f.step == report["failure"]["step"] and isinstance(f.step, int)
    assert f.time == report["failure"]["time"] and f.residual == report["failure"]["residual"]
    assert f.result.status == "failed" and f.result.failure == report["failure"]
    # the trajectory up to the failure: the rows the program kept in its .partial file
    assert f.result.columns == header and same_bits(f.result.data, rows)
    assert f.result.data.shape[0] == f.step + 1 == report["steps"] + 1
    assert same_bits(f.result.q[-1], np.array(report["q_final"]))


def test_a_failed_boundary_value_problem(tmp_path):
    over = ["problem.q_final=[3.0]", "problem.steps=10", "integrator.step=2.0", "integrator.max_iterations=3"]
    status, out, err = program(["run", scene("pendulum_bvp.toml"), "--no-output", "--json"] + sets(over),
                               str(tmp_path))
    assert status == 3, err  # three Ceres iterations cannot reach a swing over the top
    report = json.loads(out)
    with pytest.raises(dvm.StepFailure) as e:
        dvm.run(dvm.load_scene(scene("pendulum_bvp.toml"), problem={"q_final": [3.0], "steps": 10},
                               integrator={"step": 2.0, "max_iterations": 3}))
    assert str(e.value) == err[len("dvm: "):].rstrip("\n")
    assert e.value.step is None and e.value.residual == report["max_del_residual"]


def test_rows_that_do_not_fit_in_memory():
    # every row of 10^15 steps: refused before the run, naming output.every
    with pytest.raises(dvm.InputError) as e:
        dvm.integrate(dvm.System(builtin="kepler"), dvm.Method(map="midpoint"), q0=[0.4, 0.0], p0=[0.0, 2.0],
                      h=1e-3, steps=10**15)
    assert e.value.key == "output.every"
    assert "more than this machine's memory" in str(e.value)
