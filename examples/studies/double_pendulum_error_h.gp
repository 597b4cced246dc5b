# drawn by dvm chart; to draw it again, in this folder: gnuplot double_pendulum_error_h.gp
set terminal svg size 1000,640 font ",10"
set output "double_pendulum_error_h.svg"
set title "double pendulum (written), t = 4: error against the step, midpoint map composed" noenhanced
set datafile missing "NaN"
set grid
set logscale x
set format x "%.0e"
set logscale y
set format y "%.0e"
set xlabel "step" noenhanced
set ylabel "error" noenhanced
set key outside right top noenhanced font ",9"
plot for [i=0:4] "double_pendulum_error_h.dat" index i using 1:2 with linespoints lt (i + 1) pt (i % 13 + 1) ps 0.8 title columnheader(1)
