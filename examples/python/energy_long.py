"""The energy error over a long run: symplectic methods against one that is not.

The pendulum (m = l = g = 1) released from rest at 1 rad (energy -cos 1, period about
6.7) is integrated over about 300 periods at one step h by

  explicit Euler         the SODE form with the explicit Euler map (Eq. 4.1): order 1,
                         not symplectic;
  symplectic Euler       the discrete Euler-Lagrange equations of the same map: order 1,
                         symplectic;
  Stormer-Verlet         that step composed with its adjoint: order 2, symplectic.

The chart shows |E(t) - E(0)| along each run (log scale). The symplectic methods keep
the energy error bounded, oscillating within each swing, however long the run;
explicit Euler's grows with time (each step adds energy: the swing widens until the
pendulum goes over the top). The summary gives, per method, the largest energy error
(the report's max_abs_energy_error, over every step), the error at the end, and the
largest over the first and over the last tenth of the run.

    /usr/bin/python3 examples/python/energy_long.py [--out pendulum_energy.png] [--quick]

(PYTHONPATH at the built package, e.g. build-test/examples/python.) --quick runs a
short span (what the tests run).
"""

import argparse

import numpy as np

import dvm

PENDULUM = dvm.System(builtin="pendulum", params={"m": 1.0, "l": 1.0, "g": 1.0})
Q0, P0 = [1.0], [0.0]

METHODS = [
    ("explicit Euler", dvm.Method(form="sode1", map="explicit-euler")),
    ("symplectic Euler", dvm.Method(map="explicit-euler")),
    ("Stormer-Verlet", dvm.Method(map="explicit-euler", composition="stormer-verlet")),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="pendulum_energy.png", help="the chart (PNG)")
    ap.add_argument("--quick", action="store_true", help="a short span")
    a = ap.parse_args()
    h = 0.002
    t_end = 100.0 if a.quick else 2000.0
    steps = int(round(t_end / h))
    every = max(1, steps // 4000)  # about 4000 rows kept per run

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    print(f"pendulum from 1 rad, h = {h}, {steps} steps to t = {t_end:g}")
    print(f"{'method':18s} {'max |dE|':>10s} {'|dE| at end':>12s} {'first tenth':>12s} {'last tenth':>12s}")
    for name, method in METHODS:
        r = dvm.integrate(PENDULUM, method, q0=Q0, p0=P0, h=h, steps=steps, every=every)
        error = np.abs(r.energy - r.energy[0])
        tenth = len(error) // 10
        print(f"{name:18s} {r.max_abs_energy_error:10.3e} {error[-1]:12.3e} {error[:tenth].max():12.3e} "
              f"{error[-tenth:].max():12.3e}")
        ax.semilogy(r.t[1:], np.maximum(error[1:], 1e-17), lw=0.7, label=name)
    ax.set_xlabel("t")
    ax.set_ylabel("|E(t) - E(0)|")
    ax.set_title(f"pendulum from 1 rad, h = {h}: the energy error over a long run")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.out, dpi=100)
    print("wrote", a.out)


if __name__ == "__main__":
    main()
