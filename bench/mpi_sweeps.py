#!/usr/bin/env python3
"""Sweeps on Open MPI against threads, as whole processes, side by side in one run
(docs/BENCHMARKS.md, "Sweeps on MPI"). Ratios, not absolute times, are what to compare: the
machine is shared and its absolute times swing by up to 2x.

  python3 bench/mpi_sweeps.py [--build build] [--n 200] [--rounds 2] [--baseline OTHER_BUILD]

Measures, interleaved (each round runs every case once, so that a load change hits all alike):
  - `flatland montecarlo --n N` on 1 process x 2 threads against `mpirun -np 2` x 1 thread
    (the overhead of MPI itself on this 2-core machine), checking that runs.csv is the same;
  - the serial fraction of the one-process run: the wall time outside the sweep (start-up, the
    plan, gathering, summarising, writing) over the whole, and the efficiency Amdahl's law
    projects from it at 64, 256 and 1024 ranks (a projection, not a measurement);
  - with --baseline, `flatland solve --period 1.181 --json` of this build against the other's
    (start-up without mpirun: the front end must not have become slower).
"""
import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

MPIRUN = ["mpirun", "-q", "--allow-run-as-root"]


def timed(argv, cwd):
    start = time.perf_counter()
    proc = subprocess.run(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"mpi_sweeps: {' '.join(argv)} failed (exit {proc.returncode}): {proc.stderr}")
    return elapsed, proc.stdout


def md5(path):
    with open(path, "rb") as f:
        return hashlib.md5(f.read()).hexdigest()


def montecarlo_round(flatland, n, work):
    """One run of each configuration: (wall, sweep seconds, runs.csv digest) per configuration."""
    out = {}
    cases = {
        "1 process x 2 threads": [flatland, "montecarlo", "--n", str(n), "--threads", "2"],
        "2 ranks x 1 thread": MPIRUN + ["-np", "2", flatland, "montecarlo", "--n", str(n),
                                        "--threads", "1"],
    }
    for name, argv in cases.items():
        folder = tempfile.mkdtemp(dir=work)
        wall, stdout = timed(argv + ["--out", "out", "--json"], folder)
        out[name] = (wall, json.loads(stdout)["seconds"], md5(os.path.join(folder, "out", "runs.csv")))
    return out


def amdahl(serial_fraction, ranks):
    return 1.0 / (serial_fraction * ranks + (1 - serial_fraction))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--build", default="build", help="build directory (default: build)")
    parser.add_argument("--n", type=int, default=200, help="Monte Carlo worlds (default: 200)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds (default: 2)")
    parser.add_argument("--baseline", help="another build directory to compare start-up with")
    parser.add_argument("--startup-runs", type=int, default=40, help="start-up rounds (default: 40)")
    args = parser.parse_args()
    if args.n < 2 or args.rounds < 1 or args.startup_runs < 1:
        parser.error("--n must be >= 2, --rounds and --startup-runs >= 1")
    flatland = os.path.abspath(os.path.join(args.build, "bin", "flatland"))
    report = {}
    with tempfile.TemporaryDirectory() as work:
        rounds = []
        for r in range(args.rounds):
            rounds.append(montecarlo_round(flatland, args.n, work))
            print(f"mpi_sweeps: montecarlo round {r + 1}/{args.rounds}: "
                  + ", ".join(f"{k} {v[0]:.1f} s" for k, v in rounds[-1].items()), file=sys.stderr)
        names = list(rounds[0])
        digests = {v[2] for rnd in rounds for v in rnd.values()}
        ratios = [rnd[names[1]][0] / rnd[names[0]][0] for rnd in rounds]
        one = [rnd[names[0]] for rnd in rounds]
        serial = [(wall - sweep) / wall for wall, sweep, _ in one]
        f = statistics.median(serial)
        report["montecarlo"] = {
            "worlds": args.n,
            "wall_s": {name: [round(rnd[name][0], 2) for rnd in rounds] for name in names},
            "mpi_over_threads": [round(x, 4) for x in ratios],
            "mpi_over_threads_median": round(statistics.median(ratios), 4),
            "runs_csv_identical": len(digests) == 1,
            "serial_fraction": [round(x, 5) for x in serial],
            "serial_s": [round(wall - sweep, 3) for wall, sweep, _ in one],
            "amdahl_projected_efficiency": {str(p): round(amdahl(f, p), 3) for p in (64, 256, 1024)},
        }
        if args.baseline:
            other = os.path.abspath(os.path.join(args.baseline, "bin", "flatland"))
            argv = ["solve", "--period", "1.181", "--json"]
            times = {"this": [], "baseline": []}
            for _ in range(args.startup_runs):
                times["this"].append(timed([flatland, *argv], work)[0])
                times["baseline"].append(timed([other, *argv], work)[0])
            pairs = [a / b for a, b in zip(times["this"], times["baseline"])]
            report["startup_solve"] = {
                "median_ms": {k: round(1e3 * statistics.median(v), 3) for k, v in times.items()},
                "min_ms": {k: round(1e3 * min(v), 3) for k, v in times.items()},
                "this_over_baseline_median": round(statistics.median(pairs), 4),
            }
    print(json.dumps(report, indent=1))
    return 0 if report["montecarlo"]["runs_csv_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
