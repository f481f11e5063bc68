set terminal pngcairo size 960,600 enhanced font 'Sans,10'
set output '/work/main/bench/figures/cornell_10k.png'
set title 'Cornell box, about 10 k elements (N = 9888)'
set logscale xy
set grid xtics ytics mxtics mytics lc rgb '#dddddd'
set xlabel 'wall time of the solve (s, 2 threads)'
set ylabel 'RMS relative error of element radiosity (luminance, area-weighted)'
set format y '%g'
set format x '%g'
set key outside right top box
set yrange [*:*]
plot '/work/main/bench/results/plot_cornell_10k.dat' index 0 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#1f77b4' dt 1 pt 7 title 'progressive/montecarlo', \
     '/work/main/bench/results/plot_cornell_10k.dat' index 0 using 1:2:3 with labels offset 0.6,0.6 font ',7' tc rgb '#1f77b4' notitle, \
     '/work/main/bench/results/plot_cornell_10k.dat' index 1 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#9467bd' dt 1 pt 5 title 'reflection/montecarlo', \
     '/work/main/bench/results/plot_cornell_10k.dat' index 2 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#2ca02c' dt 1 pt 9 title 'gauss-seidel/montecarlo', \
     '/work/main/bench/results/plot_cornell_10k.dat' index 3 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#2ca02c' dt 2 pt 8 title 'jacobi/montecarlo', \
     '/work/main/bench/results/plot_cornell_10k.dat' index 4 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#ff7f0e' dt 1 pt 13 title 'gauss-seidel/hemicube', \
     '/work/main/bench/results/plot_cornell_10k.dat' index 4 using 1:2:3 with labels offset 0.6,0.6 font ',7' tc rgb '#ff7f0e' notitle, \
     '/work/main/bench/results/plot_cornell_10k.dat' index 5 using 1:2 with linespoints lw 2 ps 1.1 lc rgb '#ff7f0e' dt 2 pt 12 title 'jacobi/hemicube', 0.1 with lines lc rgb '#999999' dt 3 notitle, 0.03 with lines lc rgb '#999999' dt 3 notitle, 0.01 with lines lc rgb '#999999' dt 3 title '10 %, 3 %, 1 %', 0.002512 with lines lc rgb '#000000' dt 4 title 'reference noise'
