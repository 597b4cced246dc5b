# The example scripts of examples/python run (--quick) and print what they say they
# print; their figures are checked for what the scripts show (errors falling with the
# step, observed orders near the method's, the energy error of explicit Euler growing
# and that of the symplectic methods not, periods against the exact ones), not for
# values of their own.
import math
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


def png(path):
    with open(path, "rb") as f:
        return f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_energy_over_a_long_run(tmp_path):
    out = script("energy_long.py", ["--quick", "--out", str(tmp_path / "energy.png")], str(tmp_path))
    assert png(tmp_path / "energy.png")
    rows = {}
    for line in out.splitlines():
        m = re.match(r"^(explicit Euler|symplectic Euler|Stormer-Verlet)\s+" + r"\s+".join([r"(\S+)"] * 4) + "$", line)
        if m:
            rows[m.group(1)] = [float(x) for x in m.groups()[1:]]
    assert set(rows) == {"explicit Euler", "symplectic Euler", "Stormer-Verlet"}, out
    euler, symplectic, verlet = rows["explicit Euler"], rows["symplectic Euler"], rows["Stormer-Verlet"]
    # explicit Euler's error grows over the run; the symplectic methods' stays where it was
    assert euler[3] > 3 * euler[2], euler
    for r in (symplectic, verlet):
        assert r[3] < 1.5 * r[2] and r[0] >= r[3], r
    assert verlet[0] < symplectic[0] < euler[0]


def test_convergence_table(tmp_path):
    out = script("convergence_table.py", ["--quick"], str(tmp_path))
    lines = out.splitlines()
    methods = 0
    for i, line in enumerate(lines):
        m = re.match(r"^(.+?)\s+error\s+(\d.*)$", line)
        if not m:
            continue
        methods += 1
        fields = m.group(2).split()
        errors, fitted, expected = [float(x) for x in fields[:-2]], float(fields[-2]), float(fields[-1])
        assert len(errors) == 3 and errors == sorted(errors, reverse=True), line
        orders = [float(x) for x in lines[i + 1].split()[1:]]
        assert len(orders) == 2, lines[i + 1]
        # the observed orders are the errors' ratios, and near the method's order
        for k, o in enumerate(orders):
            assert abs(o - math.log2(errors[k] / errors[k + 1])) < 0.02, (line, orders)
        assert abs(fitted - expected) < 0.3, line
    assert methods == 6, out


def test_parameter_study(tmp_path):
    out = script("parameter_study.py", ["--quick", "--out", str(tmp_path / "period.png")], str(tmp_path))
    assert png(tmp_path / "period.png")
    rows = [[float(x) for x in l.split()] for l in out.splitlines() if re.match(r"^\s*\d+\.\d+\s", l)]
    assert len(rows) == 5, out
    amplitude, period, exact, relative = zip(*rows)
    assert list(period) == sorted(period) and period[-1] > 2.5 * period[0]  # wider swings, longer periods
    assert all(abs(p - e) < 1e-6 * e for p, e in zip(period, exact)), rows
