set terminal pngcairo size 1000,420 enhanced font 'Sans,10'
set output '/work/main/bench/figures/scaling.png'
set multiplot layout 1,2
set logscale xy
set grid
set format x '%g'
set format y '%g'
set xlabel 'elements N'
set ylabel 'wall time (s)'
set title 'Progressive, 100 rays/element: time'
plot '/work/main/bench/results/plot_scaling.dat' using 1:2 with linespoints lw 2 pt 7 title 'measured', '/work/main/bench/results/plot_scaling.dat' using 1:($2*0+5.37159*$1/99232) with lines dt 2 title 'linear'
set ylabel 'peak RSS above start-up (MiB)'
set title 'memory'
set key left top
plot '/work/main/bench/results/plot_scaling.dat' using 1:5 with linespoints lw 2 pt 7 title 'measured', x * 1024 / 1048576 with lines dt 2 title '1 KiB per element'
unset multiplot
