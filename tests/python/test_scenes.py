# Every shipped scene run by dvm.run equals `dvm run` on it to the bit: the rows (the
# CSV the program writes), the column names and every field of the JSON report.
import os

import numpy as np
import pytest

import dvm
from conftest import SCENES, assert_same_report, program_run, same_bits, scene

# A shorter run of the slowest scene (the same override for both).
SHORTER = {"rope.toml": {"integrator.t_end": 0.25}}

NAMES = sorted(f for f in os.listdir(SCENES) if f.endswith(".toml"))


def test_every_scene_is_here():
    assert len(NAMES) >= 30


@pytest.mark.parametrize("name", NAMES)
def test_scene_equals_the_program(name, tmp_path):
    overrides = SHORTER.get(name, {})
    expected, header, rows = program_run(scene(name), [f"{k}={v!r}" for k, v in overrides.items()], str(tmp_path))
    result = dvm.run(dvm.load_scene(scene(name), **overrides))
    assert result.columns == header
    assert result.data.dtype == np.float64
    assert result.data.shape == rows.shape
    assert same_bits(result.data, rows)
    assert_same_report(result, expected)
    # the arrays are the documented columns of those rows
    nq, npp = len(expected["q_final"]), len(expected["p_final"])
    assert same_bits(result.t, rows[:, 0])
    assert same_bits(result.q, rows[:, 1:1 + nq])
    assert same_bits(result.p, rows[:, 1 + nq:1 + nq + npp])
    assert header[1 + nq + npp] == "energy"
    assert same_bits(result.energy, rows[:, 1 + nq + npp])
    for i, c in enumerate(header):
        assert same_bits(result[c], rows[:, i])
    if expected["problem"] == "initial-value":
        # (equal values: JSON reads -0 as 0)
        assert np.array_equal(result.q[-1], np.array(expected["q_final"]))
        assert np.array_equal(result.p[0], np.array(expected["p_initial"]))
