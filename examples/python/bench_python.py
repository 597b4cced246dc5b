"""The cost of a run from Python against the same run by the dvm program.

1. A long run: 10^6 midpoint steps of Kepler's problem, as dvm.run of a scene and as
   `dvm run` of the same scene file. Printed: the ratio of the integrate loops' times
   (the reports' wall_seconds) and of the whole calls (Python's call against the
   program's process, start and scene reading included).
2. A short run of 10^3 steps: the time of one dvm.integrate call against the time of a
   `dvm run` process (most of which is the process's start).

Each figure is the median of runs taken in turn (Python, program, Python, ...).

    /usr/bin/python3 examples/python/bench_python.py --dvm build-test/examples/dvm [--quick]

(PYTHONPATH at the built package.) --quick runs fewer and shorter runs (what the tests
run: the output's form only).
"""

import argparse
import json
import os
import statistics
import subprocess
import tempfile
import time

import dvm

SCENE = """[system]
builtin = "kepler"
[initial]
q = [0.4, 0.0]
p = [0.0, 2.0]
[integrator]
map = "midpoint"
step = 0.001
steps = {steps}
[output]
every = {steps}
"""


def program(binary, path):
    start = time.perf_counter()
    out = subprocess.run([binary, "run", path, "--json", "--no-output"], capture_output=True, text=True, check=True)
    return time.perf_counter() - start, json.loads(out.stdout)["wall_seconds"]


def python(path):
    start = time.perf_counter()
    r = dvm.run(dvm.load_scene(path))
    return time.perf_counter() - start, r.wall_seconds


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dvm", default=os.environ.get("DVM_BINARY", "dvm"), help="the dvm program")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    long_steps, repeats = (10**4, 3) if a.quick else (10**6, 7)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "kepler.toml")
        with open(path, "w") as f:
            f.write(SCENE.format(steps=long_steps))
        py, pr = [], []
        for _ in range(repeats):
            py.append(python(path))
            pr.append(program(a.dvm, path))
        py_call, py_loop = (statistics.median(x) for x in zip(*py))
        pr_call, pr_loop = (statistics.median(x) for x in zip(*pr))
        print(f"long run ({long_steps} Kepler midpoint steps):")
        print(f"  integrate loop, Python / program: {py_loop / pr_loop:.3f}  ({py_loop:.4g} s, {pr_loop:.4g} s)")
        print(f"  whole call, Python / program:     {py_call / pr_call:.3f}  ({py_call:.4g} s, {pr_call:.4g} s)")

        short = os.path.join(tmp, "short.toml")
        with open(short, "w") as f:
            f.write(SCENE.format(steps=1000))
        kepler = dvm.System(builtin="kepler")
        method = dvm.Method(map="midpoint")
        calls, processes = [], []
        for _ in range(repeats * 3):
            start = time.perf_counter()
            dvm.integrate(kepler, method, q0=[0.4, 0.0], p0=[0.0, 2.0], h=0.001, steps=1000, every=1000)
            calls.append(time.perf_counter() - start)
            processes.append(program(a.dvm, short)[0])
        call, process = statistics.median(calls), statistics.median(processes)
        print("short run (1000 steps):")
        print(f"  dvm.integrate call / dvm run process: {call / process:.3f}  ({call:.4g} s, {process:.4g} s)")


if __name__ == "__main__":
    main()
