# The Python module's tests (run by ctest as python_module, with PYTHONPATH at the built
# package and DVM_BINARY, DVM_SCENES naming the dvm program and examples/scenes).
import json
import os
import subprocess

import numpy as np
import pytest

BINARY = os.environ.get("DVM_BINARY", "")
SCENES = os.environ.get("DVM_SCENES", "")


@pytest.fixture(scope="session", autouse=True)
def _environment():
    assert BINARY and os.access(BINARY, os.X_OK), "DVM_BINARY must name the built dvm program"
    assert SCENES and os.path.isdir(SCENES), "DVM_SCENES must name examples/scenes"


def scene(name):
    return os.path.join(SCENES, name)


def program(args, cwd):
    """Runs the dvm program; returns (exit status, stdout, stderr)."""
    p = subprocess.run([BINARY] + list(args), cwd=cwd, capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def sets(overrides):
    """["--set", "k=v", ...] for a list of "k=v" strings."""
    out = []
    for o in overrides:
        out += ["--set", o]
    return out


def read_csv(path):
    """The header and the rows of a CSV file the program wrote (%.17g: exact)."""
    with open(path) as f:
        header = f.readline().strip().split(",")
        rows = [[float(x) for x in line.strip().split(",")] for line in f if line.strip()]
    return header, np.array(rows, dtype=np.float64).reshape(len(rows), len(header))


def program_run(path, overrides, tmp_path):
    """`dvm run PATH --csv ... --json` with the overrides: (report, header, rows)."""
    csv = os.path.join(tmp_path, "rows.csv")
    status, out, err = program(["run", path, "--csv", csv, "--json"] + sets(overrides), tmp_path)
    assert status == 0, err
    header, rows = read_csv(csv)
    return json.loads(out), header, rows


def program_message(args, cwd, status=2):
    """The message the program prints on stderr for bad input (after "dvm: ")."""
    code, _, err = program(args, cwd)
    assert code == status, err
    assert err.startswith("dvm: "), err
    return err[len("dvm: "):].rstrip("\n")


def same_bits(a, b):
    """Equal arrays, to the bit (NaN where NaN, the sign of zero included)."""
    return (a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
            and np.array_equal(np.signbit(a), np.signbit(b)))


# fields of a report that differ between two runs of the same scene
TIMES = {"wall_seconds", "compile_seconds"}


def assert_same_report(result, expected):
    assert set(result.report) == set(expected)
    for k, v in expected.items():
        if k in TIMES:
            continue
        assert result.report[k] == v, k
        assert getattr(result, k) == v, k
