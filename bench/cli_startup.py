#!/usr/bin/env python3
"""Whole-process start-up and solve of the `flatland` CLI, side by side in one run
(docs/BENCHMARKS.md, "Start-up"). Ratios, not absolute times, are what to compare: the machine
is shared and its absolute times swing by up to 2x.

  python3 bench/cli_startup.py [--build build] [--runs 40] [--json]

Measures, interleaved (each round runs every case once, so that a load change hits all alike):
  - `flatland solve --period 1.181 --json` against bench/solve_reference.py, the same solve in
    plain Python (same equations, integrator and tolerances; the k of both must agree);
  - the interpreter's own start-up, `python3 -c pass`;
  - `flatland --help` (the front end: simulator and scene loader only) against
    `flatland-camera --help` (every library of the camera stack, as the single program loaded
    before the split);
  - an OpenCV command's start-up, `flatland render --help` (the front end executes
    flatland-camera) against `flatland-camera render --help` (the cost of the hop).
Median and minimum wall time per case, peak RSS (with GNU time), and the shared libraries each program maps.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def run_once(argv):
    start = time.perf_counter()
    proc = subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"cli_startup: {' '.join(argv)} failed (exit {proc.returncode})")
    return elapsed, proc.stdout


def peak_rss_kb(argv):
    """Peak RSS of the program itself, through GNU time (None without it): the rusage that
    Python collects would count the forked interpreter before the exec."""
    if not os.access("/usr/bin/time", os.X_OK):
        return None
    proc = subprocess.run(["/usr/bin/time", "-f", "%M", *argv], stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True)
    return int(proc.stderr.strip().splitlines()[-1])


def shared_libraries(program):
    out = subprocess.run(["ldd", program], capture_output=True, text=True).stdout
    return sum(1 for line in out.splitlines() if "=>" in line or line.strip().startswith("/"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--build", default="build", help="build directory (default: build)")
    parser.add_argument("--runs", type=int, default=40, help="rounds (default: 40)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    if args.runs < 1:
        sys.exit("cli_startup: --runs must be >= 1")
    flatland = os.path.join(args.build, "bin", "flatland")
    camera = os.path.join(args.build, "libexec", "flatland", "flatland-camera")
    for p in (flatland, camera):
        if not os.access(p, os.X_OK):
            sys.exit(f"cli_startup: {p} is missing: build first (scripts/setup.sh)")
    cases = {
        "solve": [flatland, "solve", "--period", "1.181", "--json"],
        "solve_python": [sys.executable, os.path.join(HERE, "solve_reference.py"), "1.181"],
        "python_startup": [sys.executable, "-c", "pass"],
        "help": [flatland, "--help"],
        "help_camera_program": [camera, "--help"],
        "render_help": [flatland, "render", "--help"],
        "render_help_direct": [camera, "render", "--help"],
    }
    times = {name: [] for name in cases}
    outputs = {}
    for i in range(args.runs):
        for name, argv in cases.items():
            t, out = run_once(argv)
            times[name].append(t)
            outputs[name] = out
        if sys.stderr.isatty():
            print(f"\rcli_startup: round {i + 1}/{args.runs}", end="", file=sys.stderr)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    rss = {name: peak_rss_kb(argv) for name, argv in cases.items()}
    k_cli = json.loads(outputs["solve"])["k"]
    k_py = json.loads(outputs["solve_python"])["k"]
    if abs(k_cli - k_py) > 1e-8:
        sys.exit(f"cli_startup: the two solves disagree: k = {k_cli} (flatland), {k_py} (Python)")
    med = {n: statistics.median(v) for n, v in times.items()}
    result = {
        "runs": args.runs,
        "k": {"flatland": k_cli, "python": k_py},
        "median_ms": {n: round(v * 1e3, 3) for n, v in med.items()},
        "min_ms": {n: round(min(v) * 1e3, 3) for n, v in times.items()},
        "max_rss_kb": rss,
        "shared_libraries": {"flatland": shared_libraries(flatland),
                             "flatland-camera": shared_libraries(camera)},
        "ratios": {
            "python_over_flatland_solve": round(med["solve_python"] / med["solve"], 1),
            "camera_program_over_front_end_help": round(med["help_camera_program"] / med["help"], 1),
            "render_help_hop_ms": round((med["render_help"] - med["render_help_direct"]) * 1e3, 3),
        },
    }
    if args.json:
        print(json.dumps(result))
        return
    print(f"{'case':<22}{'median ms':>11}{'min ms':>9}{'max RSS MB':>12}")
    for n in cases:
        print(f"{n:<22}{med[n] * 1e3:>11.2f}{min(times[n]) * 1e3:>9.2f}{rss[n] / 1024 if rss[n] else float('nan'):>12.1f}")
    print(f"shared libraries: flatland {result['shared_libraries']['flatland']}, "
          f"flatland-camera {result['shared_libraries']['flatland-camera']}")
    for key, value in result["ratios"].items():
        print(f"{key}: {value}")
    print(f"k: flatland {k_cli!r}, Python {k_py!r}")


if __name__ == "__main__":
    main()
