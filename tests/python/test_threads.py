# A run releases the GIL: other Python threads run while it integrates, and two runs on
# two threads take clearly less than twice the time of one. Ctrl-C (SIGINT) stops a
# run with KeyboardInterrupt, and the module runs again afterwards.
import os
import signal
import subprocess
import sys
import threading
import time

import dvm

KEPLER = dvm.System(builtin="kepler")
VERLET = dvm.Method(map="explicit-euler", composition="stormer-verlet")


def long_run(steps):
    return dvm.integrate(KEPLER, dvm.Method(map="midpoint"), q0=[0.4, 0.0], p0=[0.0, 2.0], h=1e-3, steps=steps,
                         every=steps)


def steps_for(seconds):
    """A number of midpoint steps that takes about `seconds` here."""
    n = 20000
    while True:
        start = time.perf_counter()
        long_run(n)
        took = time.perf_counter() - start
        if took > 0.2:
            return int(n * seconds / took)
        n *= 4


def test_python_runs_while_a_run_integrates():
    steps = steps_for(1.0)
    span = {}

    def worker():
        span["start"] = time.perf_counter()
        long_run(steps)
        span["end"] = time.perf_counter()

    t = threading.Thread(target=worker)
    ticks = []
    t.start()
    while t.is_alive():
        ticks.append(time.perf_counter())
    t.join()
    inside = [x for x in ticks if span["start"] + 0.1 < x < span["end"] - 0.1]
    # a run that held the GIL would leave this thread no tick inside it
    assert len(inside) > 1000, (len(inside), span)


def test_runs_on_threads_equal_runs_in_turn():
    def one(h):
        return dvm.integrate(KEPLER, dvm.Method(map="midpoint", composition="suzuki5"), q0=[0.4, 0.0],
                             p0=[0.0, 2.0], h=h, steps=20000, every=100)
    steps = [0.001, 0.002, 0.003, 0.004]
    alone = [one(h).data for h in steps]
    together = [None] * len(steps)

    def worker(i):
        together[i] = one(steps[i]).data

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(len(steps))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for a, b in zip(alone, together):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()


def test_one_scene_run_on_threads():
    # make_run builds each run's own state (workspaces of written Lagrangians and maps
    # included): one Scene object serves runs on several threads at once
    from conftest import scene
    for name in ("pendulum_written.toml", "spherical_pendulum_written_map.toml", "heavy_top_written.toml"):
        s = dvm.load_scene(scene(name))
        alone = dvm.run(s).data
        out = [None] * 3

        def worker(i):
            out[i] = dvm.run(s).data

        threads = [threading.Thread(target=worker, args=(i,)) for i in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert all(o.tobytes() == alone.tobytes() for o in out), name


def test_two_threads_integrate_in_parallel():
    assert os.cpu_count() >= 2
    steps = steps_for(1.5)
    ratios = []
    # the machine may be busy with other work for a moment: up to three measurements
    for _ in range(3):
        start = time.perf_counter()
        long_run(steps)
        one = time.perf_counter() - start
        threads = [threading.Thread(target=long_run, args=(steps,)) for _ in range(2)]
        start = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        two = time.perf_counter() - start
        ratios.append(two / one)
        if two < 1.6 * one:
            return
    raise AssertionError(f"two runs on two threads took {ratios} times one run (expected < 1.6); the load "
                         f"average of the machine (other processes on its cores) was {os.getloadavg()}")


CHILD = r"""
import sys
import dvm
kepler = dvm.System(builtin="kepler")
print("start", flush=True)
try:
    dvm.integrate(kepler, dvm.Method(map="midpoint"), q0=[0.4, 0.0], p0=[0.0, 2.0], h=1e-3, steps=10**10,
                  every=10**10)
    print("completed", flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
r = dvm.integrate(kepler, dvm.Method(map="midpoint"), q0=[0.4, 0.0], p0=[0.0, 2.0], h=1e-3, steps=100)
print("again", r.steps, r.status, flush=True)
"""


def test_sigint_stops_a_run():
    env = dict(os.environ)
    child = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, env=env)
    try:
        assert child.stdout.readline().strip() == "start"
        time.sleep(0.5)  # inside the run (10^10 steps: hours)
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == 0, err
    assert out.split("\n")[:2] == ["interrupted", "again 100 ok"], (out, err)


# A boundary-value problem that no number of iterations solves in the time of the test:
# the pendulum from 0 to 3 rad in 10 s on 2 x 10^5 nodes, 1000 iterations allowed (each
# a sparse solve of tenths of a second). SIGINT reaches it between two iterations.
CHILD_BVP = r"""
import sys, time
import dvm
scene = dvm.load_scene(sys.argv[1], problem={"q_final": [3.0], "steps": 200000},
                       integrator={"step": 5e-5, "max_iterations": 1000})
print("start", flush=True)
start = time.perf_counter()
try:
    dvm.run(scene)
    print("completed", flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
except dvm.StepFailure as e:
    print("failed", e, flush=True)
print("took", time.perf_counter() - start, flush=True)
r = dvm.run(dvm.load_scene(sys.argv[1]))
print("again", r.steps, r.status, flush=True)
"""


def test_sigint_stops_a_boundary_value_solve():
    child = subprocess.Popen([sys.executable, "-c", CHILD_BVP, os.path.join(os.environ["DVM_SCENES"],
                                                                            "pendulum_bvp.toml")],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        assert child.stdout.readline().strip() == "start"
        time.sleep(1.0)  # inside the solve
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == 0, err
    lines = out.split("\n")
    assert lines[0] == "interrupted", (out, err)
    # stopped within an iteration or two of the signal, not at the end of the solve
    assert lines[1].startswith("took ") and float(lines[1].split()[1]) < 15.0, out
    assert lines[2] == "again 10000 ok", (out, err)
