set terminal pngcairo size 960,600 enhanced font 'Sans,10'
set output '/work/main/bench/figures/cornell_1m.png'
set title 'Cornell box, about 10^6 elements (error from two seeds) (N = 997408)'
set logscale xy
set grid xtics ytics mxtics mytics lc rgb '#dddddd'
set xlabel 'wall time of the solve (s, 2 threads)'
set ylabel 'RMS relative error of element radiosity (luminance, area-weighted)'
set format y '%g'
set format x '%g'
set key outside right top box
set yrange [*:*]
plot '/work/main/bench/results/plot_cornell_1m.dat' index 0 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#1f77b4' dt 1 pt 7 title 'progressive/montecarlo', \
     '/work/main/bench/results/plot_cornell_1m.dat' index 0 using 1:2:3 with labels offset 0.6,0.6 font ',7' tc rgb '#1f77b4' notitle, 0.1 with lines lc rgb '#999999' dt 3 notitle, 0.03 with lines lc rgb '#999999' dt 3 notitle, 0.01 with lines lc rgb '#999999' dt 3 title '10 %, 3 %, 1 %'
