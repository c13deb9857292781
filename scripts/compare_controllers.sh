#!/bin/bash
# The controllers compared on identical worlds (docs/CLOSED_LOOP.md, "Comparing controllers"):
# `flatland montecarlo` over a grid of cells, each cell one setting around the default worlds of
# the bundled closed-loop scene (airtable-feedback.yaml):
#   - headline: the default perturbations, the scene's 30 Hz camera with one frame of latency;
#   - perturbation size: the tilt's, the contact friction's and the start offset's half-width
#     each raised alone (x2 and x4 of the default; the x4 cells, where controllers part, are
#     headline cells too);
#   - camera: 30, 60 and 180 Hz, each with 0, 1 and 2 frames of latency (the loop is told the
#     latency, as a calibrated rig would be; the jitter stays min(5 ms, latency)).
# Every cell runs the controllers of --controllers on the same worlds (seed 1: world i is the
# same whatever else runs) in one `flatland montecarlo`, which keeps its runs.csv and result.json
# in WORK/CELL/SET/ (SET: the controllers joined by '+'); a controller a cell has already run (in
# any set) is not run again, so an interrupted grid resumes, and a controller added to the list
# later runs alone beside the others. The
# camera cells leave the open loop out (it does not steer by the camera). At the end every cell's
# sets are gathered into OUT/controllers.csv (one row per cell and controller, from result.json's
# summaries), OUT/pairs.csv (one row per cell and pair of controllers over the worlds both ran
# without a numerical failure, with the exact two-sided McNemar p-value; for a pair run together
# it must equal montecarlo's own "pairs", which the gathering checks) and, if gnuplot is there,
# OUT/controllers.png with its script.
#
#   scripts/compare_controllers.sh [--flatland BIN] [--controllers LIST] [--headline-runs N]
#                                  [--runs N] [--threads N] [--work DIR] [--out DIR]
#
# Defaults: build/bin/flatland, open-loop,paper,transverse, 200 worlds in the headline cells (--headline-runs),
# 50 elsewhere (--runs), all cores,
# /tmp/flatland-compare-controllers, docs/closed_loop. Bad arguments: one line, exit 2.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
flatland=$root/build/bin/flatland
controllers=open-loop,paper,transverse
headline_runs=200
runs=50
threads=0
work=/tmp/flatland-compare-controllers
out=$root/docs/closed_loop

die() {
  echo "compare_controllers.sh: $*" >&2
  exit 2
}
positive() { [[ $2 =~ ^[1-9][0-9]*$ ]] || die "$1: must be a positive integer, got '$2'"; }

while [[ $# -gt 0 ]]; do
  [[ $# -ge 2 ]] || die "$1: needs a value"
  case $1 in
    --flatland) flatland=$2 ;;
    --controllers) controllers=$2 ;;
    --headline-runs) positive "$1" "$2"; headline_runs=$2 ;;
    --runs) positive "$1" "$2"; runs=$2 ;;
    --threads) [[ $2 =~ ^[0-9]+$ ]] || die "--threads: must be an integer >= 0, got '$2'"; threads=$2 ;;
    --work) work=$2 ;;
    --out) out=$2 ;;
    *) die "$1: unknown option (--flatland, --controllers, --headline-runs, --runs, --threads, --work, --out)" ;;
  esac
  shift 2
done
[[ -x $flatland ]] || die "--flatland: $flatland is not an executable"
scene=$root/assets/scenes/airtable-feedback.yaml
grep -q '^  fps: 30 ' "$scene" && grep -q '^  latency: 0.033 ' "$scene" ||
  die "$scene: expected its camera at fps 30 with latency 0.033 (the grid is built around them)"
# The controller names are checked by flatland itself: the first cell stops the script with its
# one-line message (exit 2) naming the known ones.
mkdir -p "$work" "$out"

# run_cell NAME CONTROLLERS RUNS FPS LATENCY_S [montecarlo options...]
run_cell() {
  local name=$1 set=$2 n=$3 fps=$4 latency=$5
  shift 5
  # Only the controllers this cell has not run yet (in any earlier set).
  local todo="" c done_dir
  for c in ${set//,/ }; do
    for done_dir in "$work/$name"/*/result.json; do
      [[ -f $done_dir && +$(basename "$(dirname "$done_dir")")+ == *+$c+* ]] && continue 2
    done
    todo+=${todo:+,}$c
  done
  if [[ -z $todo ]]; then
    [[ -z $set ]] || echo "$name ($set): done before, kept" >&2
    return 0
  fi
  set=$todo
  local dir=$work/$name/${set//,/+}
  mkdir -p "$work/$name"
  local jitter
  jitter=$(python3 -c "print(min(0.005, $latency))")
  # The loop's scene: the bundled one with this camera (exposure 0 fits every rate).
  sed -e "s/^  fps: 30 /  fps: $fps /" -e "s/^  latency: 0.033 /  latency: $latency /" \
    "$scene" > "$work/$name/scene.yaml"
  echo "$name: $n worlds x {$set}, $fps Hz, latency $latency s" >&2
  local t0=$SECONDS
  "$flatland" montecarlo --scene "$work/$name/scene.yaml" --n "$n" --seed 1 \
    --threads "$threads" --controller "$set" --latency "$latency" --latency-jitter "$jitter" \
    "$@" --out "$dir" --force > "$dir.txt" 2> "$dir.log" || {
    local code=$?
    tail -n 1 "$dir.log" >&2
    exit "$code"
  }
  echo "$name ($set): $((SECONDS - t0)) s" >&2
}

steering=$(python3 -c "import sys; print(','.join(c for c in sys.argv[1].split(',') if c != 'open-loop'))" "$controllers")
run_cell headline "$controllers" "$headline_runs" 30 0.033
for k in 2 4; do
  n=$runs
  [[ $k == 4 ]] && n=$headline_runs
  run_cell tilt-x$k "$controllers" "$n" 30 0.033 --tilt-deg "$(python3 -c "print(0.25 * $k)")"
  run_cell contact-x$k "$controllers" "$n" 30 0.033 --contact-rel "$(python3 -c "print(0.2 * $k)")"
  run_cell start-x$k "$controllers" "$n" 30 0.033 --s-h "$(python3 -c "print(0.02 * $k)")"
done
for fps in 30 60 180; do
  for frames in 0 1 2; do
    [[ $fps == 30 && $frames == 1 ]] && continue # the headline cell
    run_cell camera-${fps}hz-${frames}f "$steering" "$runs" "$fps" \
      "$(python3 -c "print(round($frames / $fps, 6))")"
  done
done

# Gather the cells into the two CSV files.
python3 "$root/scripts/compare_controllers_gather.py" "$work" "$out"

command -v gnuplot > /dev/null || {
  echo "no gnuplot: $out/controllers.png not drawn" >&2
  exit 0
}
# One panel per perturbation (its half-width as a multiple of the default; the headline cell is
# x1) and one for the camera (latency in frames, a curve per controller and rate). Success with
# its Wilson 95 % interval, one colour per controller. controllers_plot.csv (the gathering's):
# series, controller, x, success_pct, ci95_lo_pct, ci95_hi_pct, each series contiguous.
IFS=, read -r -a names <<< "$controllers"
colors=("#000000" "#d95f02" "#1b9e77" "#7570b3" "#e7298a")
data=controllers_plot.csv
# curve SERIES CONTROLLER X-OFFSET STYLE TITLE
curve() {
  echo -n "'$data' using (strcol(1) eq '$1' && strcol(2) eq '$2' ? column(3) + $3 : NaN):4:5:6 with yerrorlines $4 title '$5', "
}
panel() { # title xlabel series
  echo "set title '$1'; set xlabel '$2'; set xrange [0.5:4.5]; set xtics (1, 2, 4)"
  local plot="plot "
  for i in "${!names[@]}"; do
    plot+=$(curve "$3" "${names[$i]}" "$(python3 -c "print(0.06 * ($i - (${#names[@]} - 1) / 2))")" \
      "lw 2 pt 7 lc rgb '${colors[$i % 5]}'" "${names[$i]}")
  done
  echo "${plot%, }"
}
{
  echo "set terminal pngcairo size 1400,1000 font ',11'"
  echo "set output 'controllers.png'"
  echo "set datafile separator ','"
  echo "set datafile missing 'nan'"
  echo "set grid; set yrange [0:105]; set ylabel 'success (%)'; set key bottom left box opaque"
  echo "set multiplot layout 2,2 title 'Controllers on identical worlds: success with its Wilson 95 % interval (headline and x4: $headline_runs worlds, other points $runs)'"
  panel "table tilt error" "half-width / default (0.25 deg)" tilt
  panel "contact friction and losses" "half-width / default (20 %)" contact
  panel "start offset" "half-width / default (0.02 of s_h)" start
  echo "set title 'camera rate and latency (default perturbations)'; set xlabel 'latency (frames)'; set xrange [-0.3:2.3]; set xtics (0, 1, 2)"
  plot="plot "
  fps=(30 60 180)
  dashes=(1 2 4)
  points=(7 9 5)
  for i in "${!names[@]}"; do
    [[ ${names[$i]} == open-loop ]] && continue # it does not steer by the camera
    for j in 0 1 2; do
      plot+=$(curve "camera-${fps[$j]}" "${names[$i]}" "$(python3 -c "print(0.05 * ($j - 1) + 0.02 * $i)")" \
        "lw 2 dt ${dashes[$j]} pt ${points[$j]} lc rgb '${colors[$i % 5]}'" "${names[$i]} ${fps[$j]} Hz")
    done
  done
  echo "${plot%, }"
  echo "unset multiplot"
} > "$out/controllers.gp"
(cd "$out" && gnuplot controllers.gp)
echo "wrote $out/controllers.csv, $out/pairs.csv, $out/controllers_plot.csv, $out/controllers.gp, $out/controllers.png" >&2
