set terminal pngcairo size 900,560 enhanced font 'Sans,10'
set output '/work/main/bench/figures/claim.png'
set title 'Progressive solver, Cornell box: error at a fixed number of rays per element'
set logscale xy
set grid
set format y '%g'
set format x '%g'
set xlabel 'elements N'
set ylabel 'relative error (luminance)'
set key outside right top
set xrange [500:*]
plot '/work/main/bench/results/plot_claim.dat' index 0 using 1:2:3:4 with yerrorlines lw 2 pt 7 lc 1 title '30 rays/element, RMS (slope -0.20)', '/work/main/bench/results/plot_claim.dat' index 0 using 1:5 with linespoints dt 2 pt 6 lc 1 title 'p99 (slope -0.28)', \
     '/work/main/bench/results/plot_claim.dat' index 1 using 1:2:3:4 with yerrorlines lw 2 pt 7 lc 2 title '100 rays/element, RMS (slope -0.25)', '/work/main/bench/results/plot_claim.dat' index 1 using 1:5 with linespoints dt 2 pt 6 lc 2 title 'p99 (slope -0.33)'
