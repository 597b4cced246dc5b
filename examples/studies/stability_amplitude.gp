# drawn by dvm chart; to draw it again, in this folder: gnuplot stability_amplitude.gp
set terminal svg size 1000,640 font ",10"
set output "stability_amplitude.svg"
set title "pendulum, midpoint map composed: largest step before the solver fails (filled), first failure (open), over q0" noenhanced
set datafile missing "NaN"
set grid
set logscale y
set xlabel "initial.q" noenhanced
set ylabel "step" noenhanced
set key outside right top noenhanced font ",9"
set yrange [0.90509667991878096:8]
set ytics (1, 1.5, 2, 3, 5, 7)
set format y "%g"
plot for [i=0:3] "stability_amplitude.dat" index i using 1:2 with linespoints lt (i + 1) pt 7 ps 0.8 title columnheader(1), \
     for [i=0:3] "stability_amplitude.dat" index i using 1:3 with points lt (i + 1) pt 6 ps 0.8 notitle
