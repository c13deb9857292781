#!/usr/bin/env bash
# Digest of the outputs that a refactoring must leave bit-identical (docs/DEVELOPING.md,
# "Refactoring"): run it with the flatland built before and after a change and diff the two.
#   scripts/output_digest.sh [FLATLAND] > before.txt
# Each line: an md5 and what it digests. Outputs that carry wall-clock times (timings, dates) are
# left out of the digest field by field, not file by file, and so are the paths of the output and
# the scene (the bundled scenes are found at run time, wherever the program is).
set -euo pipefail
flatland=${1:-build/bin/flatland}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
digest() { md5sum | cut -d' ' -f1; }
# JSON without wall-clock fields (jq-free: one key per line after python's formatting).
strip_times() {
  python3 -c 'import json,sys
def drop(v):
    if isinstance(v, dict):
        return {k: drop(x) for k, x in v.items() if not any(w in k for w in ("wall", "elapsed", "seconds", "_ms", "timing")) and k not in ("out", "output", "scene")}
    if isinstance(v, list):
        return [drop(x) for x in v]
    return v
print(json.dumps(drop(json.load(sys.stdin)), sort_keys=True))'
}
echo "$("$flatland" solve --period 1.181 --json | strip_times | digest) solve --period 1.181 --json"
echo "$("$flatland" simulate --json | strip_times | digest) simulate --json"
"$flatland" solve --period 1.181 --out "$work/solve" --no-plot >/dev/null 2>&1
echo "$(digest <"$work/solve/trajectory.csv") solve --out: trajectory.csv"
"$flatland" render --scene assets/scenes/butterfly-camera.yaml --duration 0.2 --out "$work/frames" >/dev/null 2>&1
echo "$(cat "$work"/frames/frame_*.png | digest) render: every PNG frame (0.2 s)"
echo "$(digest <"$work/frames/truth.csv") render: truth.csv"
"$flatland" experiment --out "$work/experiment" --no-plot >/dev/null 2>&1
echo "$(digest <"$work/experiment/log.csv") experiment: log.csv"
echo "$(strip_times <"$work/experiment/result.json" | digest) experiment: result.json"
"$flatland" track --camera "$work/frames/camera.yaml" --encoder "$work/frames/encoder.csv" \
  --scene assets/scenes/butterfly-camera.yaml --images "$work/frames/frame_*.png" \
  --out "$work/track.csv" >/dev/null 2>&1
echo "$(digest <"$work/track.csv") track: track.csv"
"$flatland" montecarlo --help >/dev/null
