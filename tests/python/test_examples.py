# The example scripts of examples/python run and print what they say they print (no
# figure of their output is checked beyond its form and the order of the errors).
import os
import re
import subprocess
import sys

from conftest import BINARY, SCENES

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(SCENES))), "examples", "python")


def script(name, args, cwd):
    p = subprocess.run([sys.executable, os.path.join(EXAMPLES, name)] + args, cwd=cwd, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    return p.stdout


def test_work_precision_chart(tmp_path):
    out = script("work_precision.py", ["--quick", "--out", str(tmp_path / "wp.png")], str(tmp_path))
    with open(tmp_path / "wp.png", "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    rows = [l.split() for l in out.splitlines() if re.search(r"\(\d\)\s+\d", l)]
    by_method = {}
    for r in rows:
        name = " ".join(r[:-3])
        by_method.setdefault(name, []).append((float(r[-3]), float(r[-2])))
    assert len(by_method) == 5 and all(len(v) == 3 for v in by_method.values())
    for name, points in by_method.items():  # smaller steps, smaller errors
        errors = [e for _, e in sorted(points, reverse=True)]
        assert errors == sorted(errors, reverse=True), (name, points)


def test_benchmark_script(tmp_path):
    out = script("bench_python.py", ["--quick", "--dvm", BINARY], str(tmp_path))
    for what in ("integrate loop, Python / program:", "whole call, Python / program:",
                 "dvm.integrate call / dvm run process:"):
        assert re.search(re.escape(what) + r"\s+\d+\.\d{3}", out), out
