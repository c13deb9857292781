#!/usr/bin/env bash
# scripts/test.sh's install stage: install BUILD into a temporary prefix, build this directory's
# downstream project against it with find_package (a program with its own closed-loop controller),
# and run both it and the installed CLI from outside the source tree. Fails (non-zero) on any
# difference from what an install must give.
#   tests/downstream/check.sh [BUILD]
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
prefix=$work/prefix
fail() { echo "downstream: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$prefix" >/dev/null
for f in bin/flatland libexec/flatland/flatland-camera include/flatland/flatland.hpp \
  lib/cmake/flatland/flatlandConfig.cmake share/flatland/scenes/butterfly.yaml; do
  [ -e "$prefix/$f" ] || fail "the install lacks $f"
done
cmake -S "$root/tests/downstream" -B "$work/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build "$work/build" >&2

cd "$work"  # nowhere near the source tree
library=$("$work/build/downstream")
cli=$("$prefix/bin/flatland" solve --period 1.181 --json 2>/dev/null)
# A program outside the prefix finds the data where FLATLAND_DATA_DIR says, never in the source
# tree.
located=$(FLATLAND_DATA_DIR="$prefix/share/flatland" "$work/build/downstream" --no-loop)
python3 - "$library" "$cli" "$located" "$prefix" "$root" <<'PY'
import json, sys
library, cli, located = (json.loads(a) for a in sys.argv[1:4])
prefix, root = sys.argv[4], sys.argv[5]
if library["k"] != cli["k"]:
    sys.exit(f"downstream: the library's k {library['k']!r} differs from the CLI's {cli['k']!r}")
if abs(library["study_k"] - cli["k"]) > 1e-8 or library["study_rows"] != 20:
    sys.exit(f"downstream: the quick sim study gave k* {library['study_k']!r} in "
             f"{library['study_rows']} rows (the CLI's k {cli['k']!r}, 20 settings)")
if abs(cli["k"] + 1.1393) > 1e-3:
    sys.exit(f"downstream: k = {cli['k']!r}, the paper's is -1.1393")
if library["default_scene"].startswith(root + "/"):
    sys.exit(f"downstream: the library's default scene {library['default_scene']} is in the source tree")
if located["default_scene"] != prefix + "/share/flatland/scenes/butterfly.yaml":
    sys.exit(f"downstream: with FLATLAND_DATA_DIR the default scene is {located['default_scene']}")
# Its own controller ran in the installed library's loop (the program checked the details: called
# at every tick, its modes logged, Monte Carlo's records named and on the paper's worlds).
own = library["own_controller"]
if own["controller"] != "pd" or own["calls"] < 1 or own["modes"] < 2:
    sys.exit(f"downstream: its own controller did not run as written: {own}")
PY
# The installed CLI names its installed scenes, and its camera commands run.
"$prefix/bin/flatland" solve --help | grep -q -- "$prefix/share/flatland/scenes/butterfly.yaml" ||
  fail "the installed flatland's default scene is not under $prefix/share/flatland"
"$prefix/bin/flatland" experiment --help | grep -q -- "$prefix/share/flatland/scenes/airtable-feedback.yaml" ||
  fail "the installed flatland-camera's default scene is not under $prefix/share/flatland"
"$prefix/bin/flatland" render --duration 0.05 --scene "$prefix/share/flatland/scenes/butterfly-camera.yaml" \
  --out "$work/frames" >/dev/null 2>&1 || fail "the installed flatland render failed"
ls "$work/frames"/frame_000000.png >/dev/null || fail "the installed flatland render wrote no frame"
echo "downstream: installed, built against with find_package, and ran: $library" >&2
