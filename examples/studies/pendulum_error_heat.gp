# drawn by dvm chart; to draw it again, in this folder: gnuplot pendulum_error_heat.gp
set terminal svg size 1000,700 font ",10"
set output "pendulum_error_heat.svg"
set title "pendulum, midpoint map, t = 12.8: error of the final state over h and q0 (x: the solver failed)" noenhanced
set datafile missing "NaN"
set grid
set logscale x
set logscale cb
set format cb "%.0e"
set cblabel "error" noenhanced
set palette rgbformulae 30,31,32
set xlabel "step" noenhanced
set ylabel "initial.q" noenhanced
set xrange [0.017677669529663688:4.5254833995939059]
set yrange [0.125:3.125]
set key outside top center horizontal
plot "pendulum_error_heat.dat" index 0 using 1:2:3:4:5:6:7 with boxxyerror fs solid 1.0 noborder lc palette notitle, \
     "pendulum_error_heat.dat" index 1 using 1:2 with points pt 2 ps 1.2 lc rgb "black" title "failed"
