"""Work against precision on Kepler's problem, from Python.

Kepler's problem with eccentricity 0.6 (q0 = (0.4, 0), p0 = (0, 2); period 2 pi) is
integrated to t = T by methods of orders 2 to 8 at several step sizes h. For each run
the chart shows the error of the final position, against a Galerkin run of order 12 at
a small step, against the time the run took (the report's wall_seconds, the integrate loop alone;
the least of three runs). A method of order p is a line of slope -p in error against steps; in
error against time, the lower left wins.

    /usr/bin/python3 examples/python/work_precision.py [--out kepler_wp.png] [--quick]

(PYTHONPATH at the built package, e.g. build-test/examples/python.) --quick runs a
short span with few step sizes (what the tests run). The table of errors and times is
printed too.
"""

import argparse

import numpy as np

import dvm

KEPLER = dvm.System(builtin="kepler", params={"mu": 1.0})
Q0, P0 = [0.4, 0.0], [0.0, 2.0]

METHODS = [
    ("Stormer-Verlet (2)", dvm.Method(map="explicit-euler", composition="stormer-verlet")),
    ("midpoint (2)", dvm.Method(map="midpoint")),
    ("triple jump of Verlet (4)", dvm.Method(map="explicit-euler", composition="triple-jump")),
    ("Galerkin Gauss s = 3 (6)", dvm.Method(galerkin=3)),
    ("Kahan-Li of Verlet (8)", dvm.Method(map="explicit-euler", composition="kahan-li8")),
]


def final_position(method, h, t_end, repeats=1):
    """q at t_end, and the least time of `repeats` runs (the first run of a method in a
    process also pays for touching its code and data)."""
    steps = int(round(t_end / h))
    runs = [dvm.integrate(KEPLER, method, q0=Q0, p0=P0, h=t_end / steps, steps=steps, every=steps)
            for _ in range(repeats)]
    return runs[0].q[-1], min(r.wall_seconds for r in runs)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="kepler_wp.png", help="the chart (PNG)")
    ap.add_argument("--quick", action="store_true", help="a short span and few step sizes")
    a = ap.parse_args()
    t_end = 2 * np.pi if a.quick else 20 * np.pi
    hs = [0.1, 0.05, 0.025] if a.quick else [0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625]
    reference, _ = final_position(dvm.Method(galerkin=6), t_end / 4000, t_end)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    print(f"{'method':28s} {'h':>9s} {'error':>10s} {'seconds':>10s}")
    for name, method in METHODS:
        errors, times = [], []
        for h in hs:
            q, seconds = final_position(method, h, t_end, repeats=3)
            errors.append(float(np.linalg.norm(q - reference)))
            times.append(seconds)
            print(f"{name:28s} {h:9.5f} {errors[-1]:10.3e} {seconds:10.3e}")
        ax.loglog(times, np.maximum(errors, 1e-16), "o-", label=name)
    ax.set_xlabel("wall time of the run (s)")
    ax.set_ylabel(f"error of q at t = {t_end:.4g}")
    ax.set_title("Kepler, e = 0.6: work against precision")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.out, dpi=100)
    print("wrote", a.out)


if __name__ == "__main__":
    main()
