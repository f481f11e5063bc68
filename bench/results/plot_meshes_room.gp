set terminal pngcairo size 1100,460 enhanced font 'Sans,10'
set output '/work/main/bench/figures/meshes_room.png'
set multiplot layout 1,2 title 'Occluded room: normwise L2 error on the reference mesh'
set logscale xy
set grid xtics ytics mxtics mytics lc rgb '#dddddd'
set format x '%g'
set format y '%g'
set key top right
set ylabel 'relative L2 error of luminance'
set xlabel 'elements used (hierarchical: receiver pieces)'
set title 'against elements (labels: budget)'
plot '/work/main/bench/results/plot_meshes_room.dat' index 0 using 1:3 with points pt 7 ps 1.2 lc rgb '#1f77b4' title 'uniform', '/work/main/bench/results/plot_meshes_room.dat' index 0 using 1:3:4 with labels offset 0.5,0.5 font ',7' tc rgb '#1f77b4' notitle, \
     '/work/main/bench/results/plot_meshes_room.dat' index 2 using 1:3 with points pt 7 ps 1.2 lc rgb '#d62728' title 'adaptive', '/work/main/bench/results/plot_meshes_room.dat' index 2 using 1:3:4 with labels offset 0.5,0.5 font ',7' tc rgb '#d62728' notitle, \
     '/work/main/bench/results/plot_meshes_room.dat' index 4 using 1:3 with points pt 7 ps 1.2 lc rgb '#ff7f0e' title 'adaptive-resolve', '/work/main/bench/results/plot_meshes_room.dat' index 4 using 1:3:4 with labels offset 0.5,0.5 font ',7' tc rgb '#ff7f0e' notitle, \
     '/work/main/bench/results/plot_meshes_room.dat' index 6 using 1:3 with points pt 7 ps 1.2 lc rgb '#2ca02c' title 'hierarchical', '/work/main/bench/results/plot_meshes_room.dat' index 6 using 1:3:4 with labels offset 0.5,0.5 font ',7' tc rgb '#2ca02c' notitle, 0.05 with lines lc rgb '#999999' dt 3 notitle, 0.02 with lines lc rgb '#999999' dt 3 title '5 %, 2 %'
set xlabel 'wall time (s, 2 threads)'
set title 'against time (lines: fastest to each error)'
plot '/work/main/bench/results/plot_meshes_room.dat' index 0 using 2:3 with points pt 7 ps 1.2 lc rgb '#1f77b4' title 'uniform', '/work/main/bench/results/plot_meshes_room.dat' index 1 using 2:3 with lines lw 2 lc rgb '#1f77b4' notitle, \
     '/work/main/bench/results/plot_meshes_room.dat' index 2 using 2:3 with points pt 7 ps 1.2 lc rgb '#d62728' title 'adaptive', '/work/main/bench/results/plot_meshes_room.dat' index 3 using 2:3 with lines lw 2 lc rgb '#d62728' notitle, \
     '/work/main/bench/results/plot_meshes_room.dat' index 4 using 2:3 with points pt 7 ps 1.2 lc rgb '#ff7f0e' title 'adaptive-resolve', '/work/main/bench/results/plot_meshes_room.dat' index 5 using 2:3 with lines lw 2 lc rgb '#ff7f0e' notitle, \
     '/work/main/bench/results/plot_meshes_room.dat' index 6 using 2:3 with points pt 7 ps 1.2 lc rgb '#2ca02c' title 'hierarchical', '/work/main/bench/results/plot_meshes_room.dat' index 7 using 2:3 with lines lw 2 lc rgb '#2ca02c' notitle, 0.05 with lines lc rgb '#999999' dt 3 notitle, 0.02 with lines lc rgb '#999999' dt 3 title '5 %, 2 %'
unset multiplot
