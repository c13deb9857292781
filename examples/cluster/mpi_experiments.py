"""Spread flatland.experiment calls over the ranks of an MPI job with mpi4py.futures
(docs/PYTHON.md, "On a cluster"): each world is the closed-loop scene with its own sensor-noise
seed (effects.seed), run with the feedback controller; the results come back in the worlds' order.

    mpirun -np 4 python3 -m mpi4py.futures examples/cluster/mpi_experiments.py --worlds 16

Rank 0 runs this script and the other ranks run the worlds (so -np 4 is 3 workers). Prints one
JSON object: each world's outcome and its estimator's mean NEES, the success count and the
number of workers. --serial runs the same worlds in this process, without MPI (what the MPI run
must equal).
"""

import argparse
import json
import re
import tempfile
from pathlib import Path

import flatland


def world_scene(base, index):
    """The closed-loop scene's text with world `index`'s sensor-noise seed."""
    text, edits = re.subn(r"(?m)^(  seed:) \d+", rf"\g<1> {index + 1}", base, count=1)
    if edits != 1:
        raise SystemExit("mpi_experiments: the scene has no effects.seed line to edit")
    return text


def run_world(job):
    """One experiment: runs on whichever rank the executor gives it."""
    index, text = job
    with tempfile.TemporaryDirectory() as folder:
        scene = Path(folder) / f"world-{index}.yaml"
        scene.write_text(text)
        run = flatland.experiment(str(scene), controller="feedback")
    return {"world": index, "success": bool(run.result["success"]),
            "outcome": run.result["outcome"], "nees_mean": run.result["nees_mean"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worlds", type=int, default=8, help="worlds to run (default 8)")
    parser.add_argument("--serial", action="store_true", help="run them here, without MPI")
    args = parser.parse_args()
    if args.worlds < 1:
        parser.error("--worlds: must be >= 1")
    base = (Path(flatland.default_scene_path()).parent / "airtable-feedback.yaml").read_text()
    jobs = [(i, world_scene(base, i)) for i in range(args.worlds)]
    if args.serial:
        results, workers = [run_world(job) for job in jobs], 0
    else:
        from mpi4py import MPI
        from mpi4py.futures import MPIPoolExecutor

        workers = MPI.COMM_WORLD.Get_size() - 1  # under `python3 -m mpi4py.futures`
        with MPIPoolExecutor() as pool:
            results = list(pool.map(run_world, jobs))  # in the jobs' order, whoever ran them
    print(json.dumps({"outcomes": [r["outcome"] for r in results],
                      "successes": sum(r["success"] for r in results),
                      "nees_mean": [r["nees_mean"] for r in results], "workers": workers}))


if __name__ == "__main__":
    main()
