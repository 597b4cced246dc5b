"""A parameter study in a few lines: the pendulum's period against its amplitude.

The pendulum (m = l = g = 1) is released from rest at amplitudes a from 0.1 to 3 rad
and integrated by a Galerkin method of order 4 (Gauss, s = 2) over a few periods; the
period is read off the run, twice the mean time between the zero crossings of q
(each located by linear interpolation between two rows, where q'' = -sin q vanishes).
The exact period is 4 K(sin(a/2)), K the complete elliptic integral of the first kind
(by the arithmetic-geometric mean: K(k) = pi / (2 AGM(1, sqrt(1 - k^2)))); the small
swings' 2 pi (1 + a^2/16) is shown beside it. The chart shows the period against a;
the table the measured period, the exact one and their relative difference.

    /usr/bin/python3 examples/python/parameter_study.py [--out pendulum_period.png] [--quick]

(PYTHONPATH at the built package, e.g. build-test/examples/python.) --quick runs five
amplitudes instead of twenty (what the tests run).
"""

import argparse
import math

import numpy as np

import dvm

PENDULUM = dvm.System(builtin="pendulum", params={"m": 1.0, "l": 1.0, "g": 1.0})
METHOD = dvm.Method(galerkin=2)


def measured_period(r):
    """Twice the mean spacing of the zero crossings of q in a run's rows."""
    q, t = r.q[:, 0], r.t
    i = np.nonzero(np.signbit(q[:-1]) != np.signbit(q[1:]))[0]  # q changes sign between rows i and i + 1
    crossings = t[i] - q[i] * (t[i + 1] - t[i]) / (q[i + 1] - q[i])
    return 2.0 * float(np.mean(np.diff(crossings)))


def exact_period(a):
    x, y = 1.0, math.cos(a / 2)  # AGM(1, sqrt(1 - k^2)), k = sin(a/2)
    for _ in range(40):  # converges quadratically: a handful of rounds reach round-off
        x, y = (x + y) / 2, math.sqrt(x * y)
    return 4 * math.pi / (2 * x)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="pendulum_period.png", help="the chart (PNG)")
    ap.add_argument("--quick", action="store_true", help="five amplitudes")
    a = ap.parse_args()
    amplitudes = np.linspace(0.1, 3.0, 5 if a.quick else 20)

    # the study: one run per amplitude, the period of each
    periods = [measured_period(dvm.integrate(PENDULUM, METHOD, q0=[amp], p0=[0.0], h=0.01, t_end=60.0))
               for amp in amplitudes]

    exact = [exact_period(amp) for amp in amplitudes]
    print(f"{'amplitude':>10s} {'period':>14s} {'exact':>14s} {'relative':>10s}")
    for amp, T, Te in zip(amplitudes, periods, exact):
        print(f"{amp:10.4f} {T:14.10f} {Te:14.10f} {abs(T - Te) / Te:10.2e}")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fine = np.linspace(0.05, 3.05, 200)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(fine, [exact_period(x) for x in fine], "-", lw=1, label="exact: 4 K(sin(a/2))")
    ax.plot(fine, 2 * np.pi * (1 + fine ** 2 / 16), ":", lw=1, label="small swings: 2 pi (1 + a^2/16)")
    ax.plot(amplitudes, periods, "o", label="measured on runs of dvm")
    ax.set_xlabel("amplitude a (rad)")
    ax.set_ylabel("period")
    ax.set_title("The pendulum's period against its amplitude")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(a.out, dpi=100)
    print("wrote", a.out)


if __name__ == "__main__":
    main()
