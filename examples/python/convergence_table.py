"""A convergence table: the error and the observed order of several methods.

Kepler's problem with eccentricity 0.6 (q0 = (0.4, 0), p0 = (0, 2)) is integrated to
t = T = 1 by each method at N, 2N, 4N, ... steps (h = T/N). dvm.converge makes the
study as `dvm converge` does: the error of each run at T against the exact solution
(Kepler's equation), the observed order between two runs, log2(e(h) / e(h/2)), and an
order fitted by least squares in log-log, leaving out runs at the round-off floor. A
method of order p shows orders near p, until its errors reach round-off.

    /usr/bin/python3 examples/python/convergence_table.py [--quick]

(PYTHONPATH at the built package, e.g. build-test/examples/python.) --quick runs three
step counts per method instead of five (what the tests run).
"""

import argparse

import dvm

# the scene every study starts from; each method's keys are overrides of [integrator]
SCENE = """
[system]
builtin = "kepler"
params = { mu = 1.0 }

[initial]
q = [0.4, 0.0]
p = [0.0, 2.0]

[integrator]
map = "midpoint"
step = 0.1
t_end = 1.0
"""

METHODS = [
    ("symplectic Euler", {"map": "explicit-euler"}),
    ("midpoint", {"map": "midpoint"}),
    ("Stormer-Verlet", {"map": "explicit-euler", "composition": "stormer-verlet"}),
    ("triple jump", {"map": "explicit-euler", "composition": "triple-jump"}),
    ("Galerkin Gauss s = 2", {"method": "galerkin", "stages": 2}),
    ("Yoshida 6", {"map": "explicit-euler", "composition": "yoshida6a"}),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="three step counts per method")
    a = ap.parse_args()
    steps = [20, 40, 80] if a.quick else [20, 40, 80, 160, 320]

    head = f"{'method':22s} {'':6s}" + "".join(f"{'N = ' + str(n):>11s}" for n in steps)
    for name, keys in METHODS:
        # (a Galerkin method takes no map: the scene's is set aside, as by --set)
        study = dvm.converge(dvm.load_scene(SCENE, integrator=keys), steps=steps, t_end=1.0)
        if name == METHODS[0][0]:
            print(f"Kepler e = 0.6: the error at t = 1 against the {study.reference}")
            print(head + f"{'fitted':>9s} {'expected':>9s}")
        expected = study.method_order if study.method_order is not None else study.map_order
        fitted = "-" if study.fitted_order is None else f"{study.fitted_order:.2f}"
        print(f"{name:22s} {'error':6s}" + "".join(f"{e:11.3e}" for e in study.error) +
              f"{fitted:>9s} {expected!s:>9s}")
        print(f"{'':22s} {'order':6s}" + "".join(f"{'':>11s}" if o != o else f"{o:11.2f}" for o in study.order))
        if study.fitted_order is None and study.fit_note:
            print(f"{'':22s} fit: {study.fit_note}")
        for w in study.warnings or []:
            print(f"{'':22s} note: {w}")


if __name__ == "__main__":
    main()
