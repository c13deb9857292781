#!/usr/bin/env python3
"""flatland's renderer against MuJoCo's on the same software OpenGL (OSMesa, llvmpipe), in one
run (docs/BENCHMARKS.md, "Renderer against MuJoCo"): a 640 x 480 frame of the butterfly with 2 x 2
supersampling, read back into memory (flatland_render_bench BM_RenderButterflyCamera), against
bench/mujoco_render.c's frame of a table, a hand-sized box and the disk from the same height with
MuJoCo's 4x multisampling, with its defaults (shadows, reflections, skybox) and without them
(--plain; flatland draws none of them), its table a plane of 2 x 2 quads as flatland's; the
plain frame with MuJoCo's table as a 1 cm grid (--fine-grid, 100 x 100 quads: what the harness
drew before 2026-11-28) shows that grid's cost. Interleaved over --rounds; medians. Prints one
JSON object.

    python3 bench/render_vs_mujoco.py [--build build] [--rounds 5]
"""
import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path


def flatland_ms(binary, seconds):
    out = subprocess.run([str(binary), "--benchmark_filter=^BM_RenderButterflyCamera(/real_time)?$",
                          f"--benchmark_min_time={seconds}", "--benchmark_format=json"],
                         capture_output=True, text=True, check=True).stdout
    run = json.loads(out)["benchmarks"][0]
    return run["real_time"] * {"ns": 1e-6, "us": 1e-3, "ms": 1.0}[run["time_unit"]]


def mujoco_ms(binary, seconds, plain, fine_grid=False):
    args = [str(binary), "--seconds", str(seconds)] + (["--plain"] if plain else []) + (
        ["--fine-grid"] if fine_grid else [])
    return json.loads(subprocess.run(args, capture_output=True, text=True,
                                     check=True).stdout)["ms_per_frame"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default=str(Path(__file__).resolve().parent.parent / "build"))
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0)
    args = parser.parse_args()
    bin_dir = Path(args.build) / "bin"
    harness = bin_dir / "flatland_mujoco_render"
    if not harness.is_file():
        sys.exit(f"render_vs_mujoco: {harness} was not built (Debian libmujoco-dev is missing)")
    rounds = {"flatland": [], "mujoco_default": [], "mujoco_plain": [],
              "mujoco_plain_fine_grid": []}
    for i in range(args.rounds):
        print(f"round {i + 1}/{args.rounds}", file=sys.stderr)
        rounds["flatland"].append(flatland_ms(bin_dir / "flatland_render_bench", args.seconds))
        rounds["mujoco_default"].append(mujoco_ms(harness, args.seconds, False))
        rounds["mujoco_plain"].append(mujoco_ms(harness, args.seconds, True))
        rounds["mujoco_plain_fine_grid"].append(mujoco_ms(harness, args.seconds, True, True))
    med = {k: statistics.median(v) for k, v in rounds.items()}
    print(json.dumps({"ms_per_frame": med,
                      "mujoco_default_over_flatland": med["mujoco_default"] / med["flatland"],
                      "mujoco_plain_over_flatland": med["mujoco_plain"] / med["flatland"],
                      "mujoco_plain_fine_grid_over_flatland":
                          med["mujoco_plain_fine_grid"] / med["flatland"],
                      "per_round": rounds}, indent=2))


if __name__ == "__main__":
    main()
