# drawn by dvm chart; to draw it again, in this folder: gnuplot stability_compositions.gp
set terminal svg size 1000,640 font ",10"
set output "stability_compositions.svg"
set title "pendulum, q0 = 0.01, Stormer-Verlet composed: largest stable h (filled), smallest unstable (open)" noenhanced
set datafile missing "NaN"
set grid
set logscale y
set xlabel "integrator.composition" noenhanced
set ylabel "step" noenhanced
unset key
set yrange [0.72823636251574186:4.3425373705409935]
set ytics (1, 1.5, 2, 3)
set format y "%g"
set xrange [-0.5:11 - 0.5]
set xtics rotate by -40 noenhanced font ",9"
plot for [i=0:0] "stability_compositions.dat" index i using ($1 + 0.5 * (i - 0 / 2.0) / 1):2:xtic(5) with points lt (i + 1) pt 7 ps 1.2 title columnheader(1), \
     for [i=0:0] "stability_compositions.dat" index i using ($1 + 0.5 * (i - 0 / 2.0) / 1):3 with points lt (i + 1) pt 6 ps 1.2 notitle
