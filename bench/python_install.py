#!/usr/bin/env python3
"""`pip install .` and what the installed module costs (docs/BENCHMARKS.md, "Python install").

1. The install's wall time, each into a fresh `--system-site-packages` virtual environment with
   `pip install --no-build-isolation .`:
   - reuse: in this repository, whose build/ scripts/setup.sh has made (what CI does);
   - clean clone: a `git clone` of this repository's HEAD with no build directory, so that the
     backend configures one and compiles the libraries the module links (Release, no tests or
     benchmarks; ccache off unless --ccache). Skipped with --no-clean.
2. flatland.solve (2T = 1.181 s, the paper scene) in the installed module against the build tree's
   (PYTHONPATH=build/python), interleaved over --rounds rounds in separate processes; the ratio
   of medians. The installed module is the same shared object, so it must be equal (to 2 %).

Prints one JSON object.

    /usr/bin/python3 bench/python_install.py [--build build] [--rounds 7] [--jobs 2] [--no-clean]
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = "/usr/bin/python3"

# Median seconds of one flatland.solve, after a warm-up call, printed by the child process.
SOLVE_TIMER = """
import statistics, time, flatland
flatland.solve(period=1.181)
times = []
for _ in range({repeats}):
    t = time.perf_counter()
    flatland.solve(period=1.181)
    times.append(time.perf_counter() - t)
print(flatland.__file__)
print(statistics.median(times))
"""


def clean_env(**extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "FLATLAND_DATA_DIR", "FLATLAND_BUILD_DIR",
                        "CMAKE_CXX_COMPILER_LAUNCHER")}
    env.update(extra)
    return env


def timed_install(source, venv, env, jobs):
    subprocess.run([PYTHON, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    t = time.perf_counter()
    subprocess.run([str(venv / "bin" / "pip"), "install", "-q", "--no-build-isolation",
                    "--config-settings", f"jobs={jobs}", "."], cwd=source, env=env, check=True)
    return time.perf_counter() - t


def solve_seconds(python, env, repeats, cwd):
    out = subprocess.run([python, "-c", SOLVE_TIMER.format(repeats=repeats)], env=env, cwd=cwd,
                         capture_output=True, text=True, check=True).stdout.split()
    return out[0], float(out[1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default=str(ROOT / "build"))
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=20, help="solves per round")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--no-clean", action="store_true", help="skip the clean-clone install")
    parser.add_argument("--ccache", action="store_true", help="compile the clean clone with ccache")
    args = parser.parse_args()
    build = Path(args.build).resolve()
    result = {"jobs": args.jobs}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        result["install_reuse_s"] = timed_install(
            ROOT, tmp / "v-reuse", clean_env(FLATLAND_BUILD_DIR=str(build)), args.jobs)
        if not args.no_clean:
            clone = tmp / "clone"
            subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
            extra = {"CMAKE_CXX_COMPILER_LAUNCHER": "ccache"} if args.ccache else {}
            result["install_clean_clone_s"] = timed_install(clone, tmp / "v-clean",
                                                            clean_env(**extra), args.jobs)
            result["clean_clone_ccache"] = args.ccache
            shutil.rmtree(clone)
        installed_python = str(tmp / "v-reuse" / "bin" / "python")
        elsewhere = tmp / "elsewhere"
        elsewhere.mkdir()
        installed, tree = [], []
        for _ in range(args.rounds):
            path, seconds = solve_seconds(installed_python, clean_env(), args.repeats, elsewhere)
            assert path.startswith(str(tmp)), path
            installed.append(seconds)
            path, seconds = solve_seconds(PYTHON, clean_env(PYTHONPATH=str(build / "python")),
                                          args.repeats, elsewhere)
            assert path.startswith(str(build)), path
            tree.append(seconds)
    result["solve_installed_s"] = statistics.median(installed)
    result["solve_build_tree_s"] = statistics.median(tree)
    result["solve_installed_over_build_tree"] = result["solve_installed_s"] / \
        result["solve_build_tree_s"]
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
