#!/bin/sh
# The parallel efficiency of dvm sweep across ranks (OpenMPI's mpirun), beside that of
# threads: the sweep of bench_sweep with 20 times its steps (200 pendulum runs of mixed
# cost, 20 step counts from 10^4 to 2 10^5 times 10 compositions of the midpoint map of
# 1 to 17 substeps, so that the start of mpirun, a fixed cost of a fraction of a
# second, is a small part of the sweep), timed by wall clock
# in this one script
#   T_1  dvm sweep --jobs 1 (the baseline)
#   M_1  mpirun -n 1 dvm sweep (the baseline with MPI's start and the ranks' protocol)
#   M_R  mpirun -n R dvm sweep (rank 0 hands out rows and runs rows on a second thread)
#   W_R  mpirun --bind-to none -n 1 dvm sweep --jobs R (one rank running R rows at a
#        time on threads; mpirun would bind the rank, and so its threads, to one core)
#   T_R  dvm sweep --jobs R
# each the best of REPEATS (default 3), and prints the efficiencies T_1 / (R M_R),
# M_1 / (R M_R), M_1 / (R W_R) and T_1 / (R T_R) (1: perfect). Every table must equal the baseline's
# to the bit but for the timing columns (wall_seconds, cpu_seconds); exit 1 if not.
#
# usage: sh examples/bench/bench_sweep_mpi.sh [DVM [R]]   (default build/examples/dvm, 2)
# As root (containers, CI) mpirun is given --allow-run-as-root; --oversubscribe lets R
# exceed the cores (then the efficiency measures the oversubscription).
set -eu
dvm=${1:-build/examples/dvm}
ranks=${2:-2}
repeats=${REPEATS:-3}
# Without mpirun, or with a dvm built without MPI, it says so and exits 77 (skipped).
command -v mpirun >/dev/null 2>&1 || { echo "bench_sweep_mpi: skipped: no mpirun on PATH (Debian: openmpi-bin)"; exit 77; }
"$dvm" sweep --help | grep -q "built with MPI\." ||
  { echo "bench_sweep_mpi: skipped: $dvm was built without MPI (Debian: libopenmpi-dev)"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/scene.toml" <<'SCENE'
[system]
builtin = "pendulum"
[initial]
q = [2.0]
p = [0.0]
[integrator]
map = "midpoint"
step = 0.01
steps = 100
SCENE
set -- sweep "$tmp/scene.toml" --vary integrator.steps=10000:200000:20 \
  --vary 'integrator.composition=[none, triple-jump, suzuki5, kahan-li6, kahan-li8, mclachlan4, yoshida6a, yoshida6b, yoshida8a, suzuki-umeno8]'
root=""
[ "$(id -u)" = 0 ] && root=--allow-run-as-root
mpi="mpirun --oversubscribe $root --mca btl_vader_single_copy_mechanism none"

now() { date +%s.%N; }
# best NAME COMMAND...: the least wall time of REPEATS runs, its table in $tmp/NAME.csv
best() {
  name=$1
  shift
  least=""
  i=0
  while [ "$i" -lt "$repeats" ]; do
    t0=$(now)
    "$@" --out "$tmp/$name" >/dev/null
    t1=$(now)
    least=$(echo "$t0 $t1 $least" | awk '{t = $2 - $1; if ($3 == "" || t < $3) t3 = t; else t3 = $3; printf "%.3f", t3}')
    i=$((i + 1))
  done
  echo "$least"
}
# The CSV without its timing columns (no cell of this sweep holds a comma).
untimed() {
  awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) if ($i == "wall_seconds" || $i == "cpu_seconds") drop[i] = 1 }
           { s = ""; for (i = 1; i <= NF; i++) if (!(i in drop)) s = s $i ","; print s }' "$1"
}

t1=$(best threads1 "$dvm" "$@" --jobs 1)
m1=$(best ranks1 $mpi -n 1 "$dvm" "$@")
mr=$(best ranks $mpi -n "$ranks" "$dvm" "$@")
wr=$(best ranks1jobs $mpi --bind-to none -n 1 "$dvm" "$@" --jobs "$ranks")
tr=$(best threads "$dvm" "$@" --jobs "$ranks")
untimed "$tmp/threads1.csv" > "$tmp/base"
same=identical
for name in ranks1 ranks ranks1jobs threads; do
  untimed "$tmp/$name.csv" | cmp -s - "$tmp/base" || same="DIFFERENT ($name)"
done
rows=$(($(wc -l < "$tmp/threads1.csv") - 1))
echo "sweep of $rows runs, best of $repeats (wall seconds)"
echo "  dvm sweep --jobs 1        $t1"
echo "  mpirun -n 1 dvm sweep     $m1"
echo "  mpirun -n $ranks dvm sweep     $mr"
echo "  mpirun --bind-to none -n 1 dvm sweep --jobs $ranks  $wr"
echo "  dvm sweep --jobs $ranks        $tr"
echo "$t1 $m1 $mr $tr $ranks $wr" | awk '{ printf "  parallel efficiency of %d ranks against --jobs 1: %.2f, against mpirun -n 1: %.2f\n", $5, $1 / ($5 * $3), $2 / ($5 * $3);
  printf "  parallel efficiency of %d threads in one rank against mpirun -n 1: %.2f\n", $5, $2 / ($5 * $6);
  printf "  parallel efficiency of %d threads (no MPI) against --jobs 1: %.2f\n", $5, $1 / ($5 * $4) }'
echo "  tables (all but the timing columns) against --jobs 1: $same"
[ "$same" = identical ]
