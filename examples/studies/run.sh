#!/bin/sh
# The shipped studies (README.md here): four sweeps of dvm sweep and their charts by
# dvm chart, PNG and SVG, with the data and gnuplot script of each beside it.
#
#   sh examples/studies/run.sh [DVM [CHARTS [TABLES]]]
#
# DVM the program (default build/examples/dvm), CHARTS the folder of the charts
# (default this one), TABLES the folder of the sweeps' tables (default build/studies;
# they are not kept in the repository: the charts' .dat files hold what is drawn).
# Run from the top folder; `make charts` runs it. JOBS threads (default: all).
set -eu
here=$(dirname "$0")
dvm=${1:-build/examples/dvm}
charts=${2:-$here}
tables=${3:-build/studies}
jobs=${JOBS:-$(nproc)}
mkdir -p "$charts" "$tables"

# A sweep whose failed runs are rows (exit 3) is a study's result, not an error.
sweep() {
  status=0
  "$dvm" sweep --jobs "$jobs" "$@" || status=$?
  [ "$status" -eq 0 ] || [ "$status" -eq 3 ] || exit "$status"
}
# A chart in both formats.
chart() {
  table=$1
  name=$2
  shift 2
  for ext in png svg; do
    "$dvm" chart "$table" --out "$charts/$name.$ext" "$@"
  done
}

# (a) The largest stable step of each composition of Stormer-Verlet on a pendulum of
# small amplitude (a linear oscillator with omega = 1), to set beside the thresholds
# h* omega of `dvm methods`.
sweep "$here/pendulum_small_swing.toml" --out "$tables/stability_compositions" \
  --vary 'integrator.composition=["none", "triple-jump", "suzuki5", "mclachlan4", "yoshida6a", "yoshida6b",
          "kahan-li6", "yoshida8a", "yoshida8d", "suzuki-umeno8", "kahan-li8"]' \
  --vary integrator.step=log:0.5:4:60
chart "$tables/stability_compositions.json" stability_compositions --kind stability \
  --x integrator.composition --max-energy-error 1e-2 \
  --title "pendulum, q0 = 0.01, Stormer-Verlet composed: largest stable h (filled), smallest unstable (open)"

# (a) The step at which the midpoint compositions' solver fails, over the amplitude.
sweep "$here/pendulum_midpoint.toml" --out "$tables/stability_amplitude" \
  --vary 'initial.q=[[0.25], [0.5], [0.75], [1.0], [1.25], [1.5], [1.75], [2.0], [2.25], [2.5], [2.75], [3.0]]' \
  --vary integrator.step=log:0.2:6.4:31 \
  --vary 'integrator.composition=[none, triple-jump, suzuki5, kahan-li8]'
chart "$tables/stability_amplitude.json" stability_amplitude --kind stability --x initial.q \
  --by integrator.composition --log y \
  --title "pendulum, midpoint map composed: largest step before the solver fails (filled), first failure (open), over q0"

# (b) Work precision of the double pendulum written in its scene, to t = 4 (before
# chaos amplifies the errors past the orders), against the reference run of dvm
# converge.
sweep examples/scenes/double_pendulum_written.toml --out "$tables/double_pendulum" --error \
  --set integrator.t_end=4.0 \
  --vary 'integrator.composition=[none, triple-jump, suzuki5, kahan-li6, kahan-li8]' \
  --vary 'integrator.step=[0.1, 0.05, 0.025, 0.0125, 0.00625, 0.003125, 0.0015625]'
chart "$tables/double_pendulum.json" double_pendulum_work_precision --kind work-precision \
  --title "double pendulum (written), t = 4: error against CPU time, midpoint map composed"
chart "$tables/double_pendulum.json" double_pendulum_error_h --kind error-h \
  --title "double pendulum (written), t = 4: error against the step, midpoint map composed"

# (c) The error of the midpoint map on the pendulum over the step and the amplitude,
# failed runs marked.
sweep "$here/pendulum_error.toml" --out "$tables/pendulum_error" --error \
  --vary 'initial.q=[[0.25], [0.5], [0.75], [1.0], [1.25], [1.5], [1.75], [2.0], [2.25], [2.5], [2.75], [3.0]]' \
  --vary integrator.step=log:0.025:3.2:8
chart "$tables/pendulum_error.json" pendulum_error_heat --kind heat --y initial.q \
  --title "pendulum, midpoint map, t = 12.8: error of the final state over h and q0 (x: the solver failed)"
