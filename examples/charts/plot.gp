# Renders the charts of `make charts` from the data files written by dvm_charts.
# usage: gnuplot -e "dir='examples/charts'" examples/charts/plot.gp
# Work-precision charts: dvm's methods solid, peers (Odeint, hand-written) dashed.
if (!exists("dir")) dir = "examples/charts"
problems = "harmonic pendulum kepler henon-heiles fpu outer-solar-system rigid-body"

set datafile missing "nan"
set grid
set key outside right top font ",9" noenhanced
set termoption noenhanced

# 15 distinguishable colours; line types 1-15 solid (dvm), 21-35 dashed (peers)
array colours[15] = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", \
                     "#e377c2", "#7f7f7f", "#bcbd22", "#17becf", "#000000", "#aa3377", \
                     "#66ccee", "#228833", "#ee6677"]
do for [k=1:15] {
  set linetype k lc rgb colours[k] lw 1.5 pt k dt 1
  set linetype (20 + k) lc rgb colours[k] lw 1.5 pt (k + 1) dt 2
}

exists_file(f) = system(sprintf("test -s '%s' && echo 1 || echo 0", f)) eq "1"
blocks(f) = system(sprintf("awk 'BEGIN{n=0;b=0} /^[^#]/ && NF>0 {if(!b){n++;b=1}} NF==0 {b=0} END{print n}' '%s'", f)) + 0

do for [kind in "png svg"] {
  if (kind eq "png") { set terminal pngcairo size 1200,720 font ",10" } else { set terminal svg size 1200,720 font ",10" }

  # work-precision charts: log error against log CPU time, one line per method
  do for [p in problems] {
    file = sprintf("%s/wp_%s.dat", dir, p)
    peers = sprintf("%s/wp_%s_peers.dat", dir, p)
    if (exists_file(file)) {
      nd = blocks(file)
      np = exists_file(peers) ? blocks(peers) : 0
      set output sprintf("%s/wp_%s.%s", dir, p, kind)
      set title sprintf("work precision: %s (global position error at T against CPU time; peers dashed)", p)
      set logscale xy
      set format x "%.0e"; set format y "%.0e"
      set xlabel "CPU seconds"
      set ylabel "error"
      plot for [i=0:nd-1] file index i using 1:2 with linespoints lt (i % 15 + 1) ps 0.8 title columnheader(1), \
           for [i=0:np-1] peers index i using 1:2 with linespoints lt (20 + i % 15 + 1) ps 0.8 title columnheader(1)
      unset logscale
    }
  }

  # energy error over a long run
  file = sprintf("%s/energy_long.dat", dir)
  if (exists_file(file)) {
    n = blocks(file)
    set output sprintf("%s/energy_long.%s", dir, kind)
    set title "Kepler e = 0.6, h = 0.01, 10^6 steps: relative energy error (max over blocks of 1000 steps)"
    set logscale xy
    set format x "%.0e"; set format y "%.0e"
    set xlabel "t"
    set ylabel "|H - H0| / |H0|"
    plot for [i=0:n-1] file index i using 1:2 with lines lt (i % 12 + 1) lw 1.5 title columnheader(1)
    unset logscale
  }

  # stability: largest stable h omega per method (bars capped at the end of the scan)
  file = sprintf("%s/stability_threshold.dat", dir)
  if (exists_file(file)) {
    set output sprintf("%s/stability_threshold.%s", dir, kind)
    set title "largest stable h*omega on q'' = -omega^2 q (bar at the top of the scan = stable on the whole scan)"
    set style data histograms
    set style histogram clustered gap 1
    set style fill solid 0.8 border -1
    set boxwidth 0.9
    set xtics rotate by -60 font ",8" noenhanced
    set format y "%g"
    set ylabel "h omega"
    set xlabel ""
    set yrange [0:*]
    plot file using 2:xtic(1) lt 1 title "by runs", '' using ($3 < 0 ? 1/0 : $3) lt 2 title "closed form |trace| < 2"
    set yrange [*:*]
    set xtics norotate font ",10"
    set style data points
  }

  # pendulum: the step at which each implicit solver stops converging
  file = sprintf("%s/stability_pendulum.dat", dir)
  if (exists_file(file)) {
    set output sprintf("%s/stability_pendulum.%s", dir, kind)
    set title "pendulum (q0 = 2): smallest step h at which the implicit solver fails (bar at the top = never on the scan)"
    set style data histograms
    set style fill solid 0.8 border -1
    set boxwidth 0.8
    set logscale y
    set format y "%g"
    set xtics rotate by -60 font ",8" noenhanced
    set ylabel "h"
    plot file using 2:xtic(1) lt 1 notitle
    unset logscale
    set xtics norotate font ",10"
    set style data points
  }
  unset output
}
