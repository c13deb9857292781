#!/usr/bin/env python3
"""What the Python binding costs over the C++ it calls, measured in one run (docs/BENCHMARKS.md,
"Python").

1. flatland.solve (2T = 1.181 s, rtol 1e-10, atol 1e-12, k to 1e-6, on a loaded Model) against
   the C++ BM_Solve/rtol:1e-10 (flatland_bench): the same solve, the same simulations.
2. A trivial binding (_flatland._noop) against a Python function that does nothing.
3. Renderer.render(state=...) into numpy (640 x 480, 2 x 2 supersampling, the butterfly-camera
   scene at t = 0.45 s) against the C++ BM_RenderButterflyCamera (flatland_render_bench).
4. flatland.solve against the same solve written with scipy (solve_ivp DOP853/RK45 and brentq,
   bench/solve_scipy.py), in this process.

The machine is shared and its speed swings: the C++ benchmarks and the Python measurements are
interleaved over --rounds rounds, and each ratio is of medians. Prints one JSON object.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_bindings.py [--build build] [--rounds 5]
"""
import argparse
import json
import statistics
import subprocess
import sys
import time
import timeit
from pathlib import Path

import flatland
from flatland import _flatland

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import solve_scipy  # noqa: E402


def cpp_benchmark(binary, name, min_time):
    out = subprocess.run([str(binary), f"--benchmark_filter=^{name}(/real_time)?$",
                          f"--benchmark_min_time={min_time}", "--benchmark_format=json"],
                         capture_output=True, text=True, check=True).stdout
    run = json.loads(out)["benchmarks"][0]
    scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}[run["time_unit"]]
    return run["real_time"] * scale, run


def best_of(fn, seconds):
    """Median seconds per call over repeated batches filling about `seconds`."""
    fn()
    t0 = time.perf_counter()
    fn()
    one = max(time.perf_counter() - t0, 1e-7)
    number = max(1, int(0.05 / one))
    batches = max(5, int(seconds / (one * number)))
    return statistics.median(timeit.repeat(fn, number=number, repeat=batches)) / number


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", default=str(HERE.parent / "build"))
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0, help="per measurement")
    args = parser.parse_args()
    bin_dir = Path(args.build) / "bin"

    model = flatland.load()
    camera = flatland.load(HERE.parent / "assets" / "scenes" / "butterfly-camera.yaml")
    row = flatland.simulate(camera, sample_dt=0.45).trajectory
    state = {"hand_angle": row["theta"][1], "disk_center": (row["x"][1], row["y"][1]),
             "disk_angle": row["object_angle"][1], "t": row["t"][1]}
    renderer = flatland.Renderer(camera)

    def py_solve():
        return flatland.solve(period=1.181, scene=model, tolerance=1e-6, rtol=1e-10, atol=1e-12)

    def py_render():
        return renderer.render(state=state)

    def empty():
        pass

    rounds = {k: [] for k in ("cpp_solve", "py_solve", "noop", "empty", "cpp_render", "py_render",
                              "scipy_solve")}
    solved = py_solve()
    cpp_run = None
    for i in range(args.rounds):
        print(f"round {i + 1}/{args.rounds}", file=sys.stderr)
        t, cpp_run = cpp_benchmark(bin_dir / "flatland_bench", "BM_Solve/rtol:1e-10",
                                   args.seconds)
        rounds["cpp_solve"].append(t)
        rounds["py_solve"].append(best_of(py_solve, args.seconds))
        rounds["noop"].append(best_of(_flatland._noop, args.seconds / 4))
        rounds["empty"].append(best_of(empty, args.seconds / 4))
        rounds["cpp_render"].append(cpp_benchmark(bin_dir / "flatland_render_bench",
                                                  "BM_RenderButterflyCamera", args.seconds)[0])
        rounds["py_render"].append(best_of(py_render, args.seconds))
        rounds["scipy_solve"].append(best_of(lambda: solve_scipy.solve(1.181, 1e-6), args.seconds))
    med = {k: statistics.median(v) for k, v in rounds.items()}
    scipy_k = solve_scipy.solve(1.181, 1e-6)["k"]
    print(json.dumps({
        "rounds": args.rounds,
        "solve": {"python_ms": med["py_solve"] * 1e3, "cpp_ms": med["cpp_solve"] * 1e3,
                  "ratio": med["py_solve"] / med["cpp_solve"],
                  "python_simulations": solved["simulations"],
                  "cpp_simulations": cpp_run["simulations"],
                  "python_rhs_evals": solved["rhs_evals"], "cpp_rhs_evals": cpp_run["rhs_evals"]},
        "trivial_binding_us": med["noop"] * 1e6,
        "empty_python_function_us": med["empty"] * 1e6,
        "render_640x480": {"python_ms": med["py_render"] * 1e3, "cpp_ms": med["cpp_render"] * 1e3,
                           "ratio": med["py_render"] / med["cpp_render"]},
        "scipy_solve": {"scipy_ms": med["scipy_solve"] * 1e3,
                        "flatland_ms": med["py_solve"] * 1e3,
                        "ratio": med["scipy_solve"] / med["py_solve"],
                        "k_scipy": scipy_k, "k_flatland": solved["k"],
                        "k_difference": abs(scipy_k - solved["k"])},
        "per_round": rounds,
    }, indent=2))


if __name__ == "__main__":
    main()
