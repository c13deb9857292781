set terminal pngcairo size 1400,1000 font ',11'
set output 'controllers.png'
set datafile separator ','
set datafile missing 'nan'
set grid; set yrange [0:105]; set ylabel 'success (%)'; set key bottom left box opaque
set multiplot layout 2,2 title 'Controllers on identical worlds: success with its Wilson 95 % interval (headline and x4: 200 worlds, other points 50)'
set title 'table tilt error'; set xlabel 'half-width / default (0.25 deg)'; set xrange [0.5:4.5]; set xtics (1, 2, 4)
plot 'controllers_plot.csv' using (strcol(1) eq 'tilt' && strcol(2) eq 'open-loop' ? column(3) + -0.03 : NaN):4:5:6 with yerrorlines lw 2 pt 7 lc rgb '#000000' title 'open-loop', 'controllers_plot.csv' using (strcol(1) eq 'tilt' && strcol(2) eq 'paper' ? column(3) + 0.03 : NaN):4:5:6 with yerrorlines lw 2 pt 7 lc rgb '#d95f02' title 'paper'
set title 'contact friction and losses'; set xlabel 'half-width / default (20 %)'; set xrange [0.5:4.5]; set xtics (1, 2, 4)
plot 'controllers_plot.csv' using (strcol(1) eq 'contact' && strcol(2) eq 'open-loop' ? column(3) + -0.03 : NaN):4:5:6 with yerrorlines lw 2 pt 7 lc rgb '#000000' title 'open-loop', 'controllers_plot.csv' using (strcol(1) eq 'contact' && strcol(2) eq 'paper' ? column(3) + 0.03 : NaN):4:5:6 with yerrorlines lw 2 pt 7 lc rgb '#d95f02' title 'paper'
set title 'start offset'; set xlabel 'half-width / default (0.02 of s_h)'; set xrange [0.5:4.5]; set xtics (1, 2, 4)
plot 'controllers_plot.csv' using (strcol(1) eq 'start' && strcol(2) eq 'open-loop' ? column(3) + -0.03 : NaN):4:5:6 with yerrorlines lw 2 pt 7 lc rgb '#000000' title 'open-loop', 'controllers_plot.csv' using (strcol(1) eq 'start' && strcol(2) eq 'paper' ? column(3) + 0.03 : NaN):4:5:6 with yerrorlines lw 2 pt 7 lc rgb '#d95f02' title 'paper'
set title 'camera rate and latency (default perturbations)'; set xlabel 'latency (frames)'; set xrange [-0.3:2.3]; set xtics (0, 1, 2)
plot 'controllers_plot.csv' using (strcol(1) eq 'camera-30' && strcol(2) eq 'paper' ? column(3) + -0.030000000000000002 : NaN):4:5:6 with yerrorlines lw 2 dt 1 pt 7 lc rgb '#d95f02' title 'paper 30 Hz', 'controllers_plot.csv' using (strcol(1) eq 'camera-60' && strcol(2) eq 'paper' ? column(3) + 0.02 : NaN):4:5:6 with yerrorlines lw 2 dt 2 pt 9 lc rgb '#d95f02' title 'paper 60 Hz', 'controllers_plot.csv' using (strcol(1) eq 'camera-180' && strcol(2) eq 'paper' ? column(3) + 0.07 : NaN):4:5:6 with yerrorlines lw 2 dt 4 pt 5 lc rgb '#d95f02' title 'paper 180 Hz'
unset multiplot
