# dvm.check_map against `dvm check-map`: the same JSON fields for maps of every space
# and for scenes' maps (written ones included), passed where the program exits 0 and
# not where it exits 1, and the program's messages for the input it refuses.
import json

import pytest

import dvm
from conftest import program, scene


def program_check(args, tmp_path):
    status, out, err = program(["check-map"] + args, str(tmp_path))
    assert status in (0, 1), err
    return status, json.loads(out)


@pytest.mark.parametrize("name, kwargs, args", [
    ("midpoint", {}, []),
    ("explicit-euler", {"dim": 1}, ["--dim", "1"]),
    ("theta", {"theta": 0.3, "dim": 3}, ["--theta", "0.3", "--dim", "3"]),
    ("retraction-theta", {"theta": 0.25, "dim": 4}, ["--theta", "0.25", "--dim", "4"]),
    ("sphere-exp", {}, []),
    ("sphere-projection-theta", {"theta": 0.3}, ["--theta", "0.3"]),
    ("so3-cayley", {}, []),
    ("midpoint", {"tolerance": 1e-30}, ["--tolerance", "1e-30"]),
], ids=["midpoint", "euler dim 1", "theta", "retraction-theta", "sphere-exp", "sphere theta", "so3-cayley",
        "too strict"])
def test_a_map_of_the_registry(name, kwargs, args, tmp_path):
    status, expected = program_check([name] + args, tmp_path)
    c = dvm.check_map(name, **kwargs)
    assert isinstance(c, dvm.MapCheck)
    assert c.report == expected
    assert c.passed == (status == 0) and bool(c) == c.passed
    assert c.map.startswith(name) and c.residuals == expected["residuals"] and c.tolerance == expected["tolerance"]
    if "tolerance" in kwargs:  # at 1e-30 the round-off of the identities is too much
        assert not c.passed and status == 1


@pytest.mark.parametrize("name, overrides, args", [
    ("pendulum_written_map.toml", {}, []),
    ("pendulum_written_map.toml", {}, ["--dim", "3"]),
    ("spherical_pendulum_written_map.toml", {}, []),
    ("kepler.toml", {"integrator.map": "theta", "integrator.theta": 0.7}, ["--set", "integrator.map=\"theta\"",
                                                                          "--set", "integrator.theta=0.7"]),
], ids=["written on R^n", "written dim 3", "written on S^2", "theta from the scene"])
def test_the_map_of_a_scene(name, overrides, args, tmp_path):
    status, expected = program_check(["--scene", scene(name)] + args, tmp_path)
    dim = int(args[args.index("--dim") + 1]) if "--dim" in args else None
    c = dvm.check_map(dvm.load_scene(scene(name), **overrides), dim=dim)
    assert c.report == expected
    assert c.passed == (status == 0)


@pytest.mark.parametrize("map_, kwargs, args", [
    ("nope", {}, ["nope"]),
    ("midpoint", {"theta": 0.3}, ["midpoint", "--theta", "0.3"]),
    ("theta", {"theta": 2}, ["theta", "--theta", "2"]),
    ("theta", {"theta": -0.5}, ["theta", "--theta", "-0.5"]),
    ("theta", {"theta": float("nan")}, ["theta", "--theta", "nan"]),
    ("theta", {"dim": 9}, ["theta", "--dim", "9"]),
    ("theta", {"tolerance": 0.0}, ["theta", "--tolerance", "0"]),
    ("theta", {"tolerance": float("inf")}, ["theta", "--tolerance", "inf"]),
    ("sphere-exp", {"dim": 3}, ["sphere-exp", "--dim", "3"]),
    ("sphere-written", {}, ["sphere-written"]),
    ("kepler.toml", {"theta": 0.3}, ["--scene", "kepler.toml", "--theta", "0.3"]),
], ids=["unknown map", "theta to midpoint", "theta above 1", "theta below 0", "theta nan", "dim 9",
        "tolerance 0", "tolerance inf", "dim on S^2", "written without a scene", "theta with a scene"])
def test_refuses_as_the_program(map_, kwargs, args, tmp_path):
    if map_.endswith(".toml"):
        map_ = dvm.load_scene(scene(map_))
        args = [scene(a) if a.endswith(".toml") else a for a in args]
    code, _, err = program(["check-map"] + args, str(tmp_path))
    assert code == 2 and err.startswith("dvm: "), err
    expected = err[len("dvm: "):].split("\n")[0]
    with pytest.raises(dvm.InputError) as e:
        dvm.check_map(map_, **kwargs)
    assert str(e.value) == expected


def test_not_a_map():
    with pytest.raises(TypeError):
        dvm.check_map(dvm.Method(map="midpoint"))
