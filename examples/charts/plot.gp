# Renders the charts of `make charts` from the data files written by dvm_charts.
# usage: gnuplot -e "dir='examples/charts'" examples/charts/plot.gp
# Work-precision charts: one chart per problem in three panels by order (1-2, 4, 6 and
# more), at most 8 series in a panel, each with its own colour; dvm's methods solid,
# peers (Odeint, hand-written) dashed. The CSV (work_precision.csv) keeps every series.
if (!exists("dir")) dir = "examples/charts"
problems = "harmonic pendulum kepler henon-heiles fpu outer-solar-system rigid-body"

set datafile missing "nan"
set grid
set termoption noenhanced

# 12 distinguishable colours (Tol's bright and muted schemes); line types 1-12 solid
# (dvm), 21-32 the same colours dashed (peers)
array colours[12] = ["#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377", \
                     "#000000", "#ee7733", "#332288", "#999933", "#882255", "#bbbbbb"]
do for [k=1:12] {
  set linetype k lc rgb colours[k] lw 2 pt k dt 1
  set linetype (20 + k) lc rgb colours[k] lw 2 pt (k + 1) dt (5, 4)
}

# The 0-based indices of the blocks of file f (one block per method, its title on its
# first line) whose method is of the order class c, by the order work_precision.csv
# gives the method on problem p: "high" (6 and more), "four" (3 to 5), else "low".
class_blocks(f, p, c) = system(sprintf("awk -F, -v c=%s -v p='%s' 'NR==FNR { if ($1==p) ord[$2]=$4; next } \
  BEGIN{b=-1;inb=0} NF==0 {inb=0; next} /^#/ {next} \
  !inb {inb=1; b++; t=$0; sub(/^\"/, \"\", t); sub(/\".*$/, \"\", t); o=ord[t]+0; \
  k=(o>=6) ? \"high\" : (o>=3) ? \"four\" : \"low\"; if (k==c) printf \"%%d \", b}' '%s/work_precision.csv' '%s'", c, p, dir, f))
class_title(c) = c eq "low" ? "order 1 and 2" : (c eq "four" ? "order 4" : "order 6 to 12")

exists_file(f) = system(sprintf("test -s '%s' && echo 1 || echo 0", f)) eq "1"
blocks(f) = system(sprintf("awk 'BEGIN{n=0;b=0} /^[^#]/ && NF>0 {if(!b){n++;b=1}} NF==0 {b=0} END{print n}' '%s'", f)) + 0

do for [kind in "png svg"] {
  if (kind eq "png") { set terminal pngcairo size 1200,720 font ",10" } else { set terminal svg size 1200,720 font ",10" }

  # work-precision charts: log error against log CPU time, three panels by order
  do for [p in problems] {
    file = sprintf("%s/wp_%s.dat", dir, p)
    peers = sprintf("%s/wp_%s_peers.dat", dir, p)
    if (exists_file(file)) {
      if (kind eq "png") { set terminal pngcairo size 1800,700 font ",10" } else { set terminal svg size 1800,700 font ",10" }
      set output sprintf("%s/wp_%s.%s", dir, p, kind)
      set multiplot layout 1,3 title sprintf("work precision: %s (global position error at T against CPU time; dvm solid, peers dashed)", p)
      set logscale xy
      set format x "%.0e"; set format y "%.0e"
      set xlabel "CPU seconds"
      set ylabel "error"
      set key bottom left font ",9" noenhanced
      do for [c in "low four high"] {
        d = class_blocks(file, p, c)
        q = exists_file(peers) ? class_blocks(peers, p, c) : ""
        nd = words(d)
        set title class_title(c)
        if (nd + words(q) == 0) {
          unset key; plot 1/0 notitle; set key
        } else {
          if (words(q) == 0) {
            plot for [j=1:nd] file index (word(d, j) + 0) using 1:2 with linespoints lt j ps 0.8 title columnheader(1)
          } else {
            if (nd == 0) {
              plot for [j=1:words(q)] peers index (word(q, j) + 0) using 1:2 with linespoints lt (20 + j) ps 0.8 title columnheader(1)
            } else {
              plot for [j=1:nd] file index (word(d, j) + 0) using 1:2 with linespoints lt j ps 0.8 title columnheader(1), \
                   for [j=1:words(q)] peers index (word(q, j) + 0) using 1:2 with linespoints lt (20 + nd + j) ps 0.8 title columnheader(1)
            }
          }
        }
      }
      unset multiplot
      unset logscale
      if (kind eq "png") { set terminal pngcairo size 1200,720 font ",10" } else { set terminal svg size 1200,720 font ",10" }
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
    set key outside right top font ",9" noenhanced
    plot for [i=0:n-1] file index i using 1:2 with lines lt (i < 4 ? i + 1 : 20 + i + 1) title columnheader(1)
    unset logscale
  }

  # stability: largest stable h omega per method, one horizontal bar pair per method
  # (bars capped at the end of the scan), names legible on the vertical axis
  file = sprintf("%s/stability_threshold.dat", dir)
  if (exists_file(file)) {
    n = system(sprintf("grep -c '^\"' '%s'", file)) + 0
    if (kind eq "png") { set terminal pngcairo size 1100,(140 + 22 * n) font ",10" } else { set terminal svg size 1100,(140 + 22 * n) font ",10" }
    set output sprintf("%s/stability_threshold.%s", dir, kind)
    set title "largest stable h*omega on q'' = -omega^2 q (a bar at the end of the scan: stable on the whole scan)"
    set yrange [n:-1]
    set ytics font ",9" noenhanced
    set xrange [0:*]
    set format x "%g"
    set xlabel "h omega"
    set ylabel ""
    set key outside top center horizontal font ",10"
    set style fill solid 0.8 border -1
    plot file using (0):($0 - 0.2):(0):2:($0 - 0.4):($0):ytic(1) with boxxyerror lt 1 title "by runs", \
         '' using (0):($0 + 0.2):(0):($3 < 0 ? 1/0 : $3):($0):($0 + 0.4) with boxxyerror lt 2 title "closed form |trace| < 2"
    set yrange [*:*]; set xrange [*:*]
    set ytics font ",10"
    set style fill empty
  }

  # pendulum: the step at which each implicit solver stops converging
  file = sprintf("%s/stability_pendulum.dat", dir)
  if (exists_file(file)) {
    n = system(sprintf("grep -c '^\"' '%s'", file)) + 0
    if (kind eq "png") { set terminal pngcairo size 1100,(140 + 24 * n) font ",10" } else { set terminal svg size 1100,(140 + 24 * n) font ",10" }
    set output sprintf("%s/stability_pendulum.%s", dir, kind)
    set title "pendulum (q0 = 2): smallest step h at which the implicit solver fails (a bar at 100: never on the scan)"
    set yrange [n:-1]
    set ytics font ",9" noenhanced
    set logscale x
    set xrange [0.1:*]
    set format x "%g"
    set xlabel "h"
    set ylabel ""
    set style fill solid 0.8 border -1
    plot file using (sqrt(0.1 * $2)):($0):(0.1):2:($0 - 0.35):($0 + 0.35):ytic(1) with boxxyerror lt 1 notitle
    unset logscale
    set yrange [*:*]; set xrange [*:*]
    set ytics font ",10"
    set style fill empty
  }
  unset output
}
