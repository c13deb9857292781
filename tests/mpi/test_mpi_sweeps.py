"""The sweeps on Open MPI (docs/CLUSTER.md): `mpirun -np N flatland <sweep>` writes what one
process writes, bit for bit, for any number of ranks and threads; a rank that dies ends the job
with one line naming it and nothing written; bad launches are refused with one line, exit 2.

Run by scripts/test.sh's MPI stage (pytest tests/mpi) against build/: needs mpirun (Debian's
openmpi-bin) and flatland-mpi (built when libopenmpi-dev is installed).
"""

import csv
import io
import json
import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("FLATLAND_BUILD_DIR", ROOT / "build"))
CLI = BUILD / "bin" / "flatland"
MPI_PROGRAM = BUILD / "libexec" / "flatland" / "flatland-mpi"
# -q: Open MPI's own multi-line banners off, so that flatland's one line is what a failure
# prints. --oversubscribe: 3 ranks on this 2-core machine.
MPIRUN = ["mpirun", "-q", "--allow-run-as-root", "--oversubscribe"]

# What may differ between two runs of the same sweep: wall and CPU times, and how it ran.
VOLATILE_KEYS = {"seconds", "runs_per_second", "cpu_seconds", "wall_s", "cpu_s", "threads", "ranks"}
VOLATILE_COLUMNS = {"wall[s]", "cpu[s]"}


@pytest.fixture(scope="module", autouse=True)
def mpi_build():
    if shutil.which("mpirun") is None:
        pytest.fail("mpirun is missing: apt-get install openmpi-bin libopenmpi-dev (scripts/setup.sh)")
    if not MPI_PROGRAM.is_file():
        pytest.fail(f"{MPI_PROGRAM} is missing: configure build/ with MPI found (libopenmpi-dev)")


def run(cmd, cwd, timeout=600):
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def without_volatile(value):
    if isinstance(value, dict):
        return {k: without_volatile(v) for k, v in value.items() if k not in VOLATILE_KEYS}
    if isinstance(value, list):
        return [without_volatile(v) for v in value]
    return value


def digest_outputs(cwd, stdout):
    """What must be equal: the JSON on stdout and every file under cwd/out, JSON without the
    volatile keys, CSV without the volatile columns, anything else byte for byte."""
    files = {"stdout": json.dumps(without_volatile(json.loads(stdout)), sort_keys=True)}
    out = Path(cwd) / "out"
    for path in sorted(out.rglob("*")) if out.exists() else []:
        if not path.is_file():
            continue
        name = str(path.relative_to(cwd))
        if path.suffix == ".json":
            files[name] = json.dumps(without_volatile(json.loads(path.read_text())), sort_keys=True)
        elif path.suffix == ".csv":
            rows = list(csv.reader(io.StringIO(path.read_text())))
            keep = [i for i, h in enumerate(rows[0]) if h not in VOLATILE_COLUMNS] if rows else []
            files[name] = [[r[i] for i in keep] for r in rows]
        else:
            files[name] = path.read_bytes()
    return files


SWEEPS = {
    "montecarlo": ["montecarlo", "--n", "40"],
    "study": ["study", "closed-loop", "--quick", "--no-plot"],
    "surface": ["surface", "--nk", "12", "--np", "12"],
    "locus": ["locus", "--n", "12"],
}
# The launches each sweep is compared over: (ranks, threads); ranks 0 is one process, no mpirun.
# study closed-loop has no --threads (one process uses every core; a rank uses one thread).
LAUNCHES = {
    "montecarlo": [(0, 1), (0, 2), (2, 1), (3, 1)],
    "study": [(0, None), (2, None), (3, None)],
    "surface": [(0, 1), (0, 2), (2, 1), (3, 1), (3, 2)],
    "locus": [(0, None), (2, None), (3, None)],
}


@pytest.mark.parametrize("sweep", sorted(SWEEPS))
def test_ranks_and_threads_write_the_same_outputs(sweep, tmp_path):
    digests = {}
    for ranks, threads in LAUNCHES[sweep]:
        cwd = tmp_path / f"np{ranks}-t{threads}"
        cwd.mkdir()
        cmd = [str(CLI), *SWEEPS[sweep], "--out", "out", "--json"]
        if threads is not None:
            cmd += ["--threads", str(threads)]
        if ranks:
            cmd = MPIRUN + ["-np", str(ranks)] + cmd
        p = run(cmd, cwd)
        assert p.returncode == 0, f"{' '.join(cmd)} exited {p.returncode}: {p.stderr}"
        if ranks and sweep != "locus":
            assert f"{ranks} ranks x" in p.stderr, p.stderr  # it did run on the ranks
        if ranks:  # progress on rank 0, as lines (its stderr is the launcher's pipe)
            assert re.search(r"^flatland: [a-z -]+: 100% \((\d+)/\1\)$", p.stderr, re.M), p.stderr
        digests[(ranks, threads)] = digest_outputs(cwd, p.stdout)
    reference = digests[LAUNCHES[sweep][0]]
    assert len(reference) > 1, f"{sweep} wrote no files"
    for launch, files in digests.items():
        assert files.keys() == reference.keys(), launch
        for name in reference:
            assert files[name] == reference[name], f"{sweep}: {name} differs at (ranks, threads) = {launch}"


def rank_pids(marker):
    """The flatland ranks of the job whose command line contains `marker`: {rank: pid}."""
    ranks = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            if marker not in cmdline or "mpirun" in cmdline:
                continue
            env = (entry / "environ").read_bytes().split(b"\0")
        except OSError:
            continue
        for var in env:
            if var.startswith(b"OMPI_COMM_WORLD_RANK="):
                ranks[int(var.split(b"=", 1)[1])] = int(entry.name)
    return ranks


def running(pid):
    """True if process `pid` exists and is not a zombie (a rank mpirun left to init to reap)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"


def start_sweep(tmp_path, ranks, seed):
    """A Monte Carlo job of `ranks` ranks (its seed marks its processes), once every rank runs
    and is 2 s into the sweep: (the mpirun process, {rank: pid})."""
    marker = f"--seed {seed}"
    cmd = MPIRUN + ["-np", str(ranks), str(CLI), "montecarlo", "--n", "40", "--seed", str(seed),
                    "--out", "out", "--json"]
    job = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    deadline = time.monotonic() + 60
    pids = {}
    while len(pids) < ranks and time.monotonic() < deadline and job.poll() is None:
        time.sleep(0.2)
        pids = rank_pids(marker)
    if len(pids) < ranks:
        job.kill()
        pytest.fail(f"the {ranks} ranks did not start: {pids}")
    time.sleep(2)  # into the sweep: every rank holds worlds now
    return job, pids


def finish(job):
    """(stdout, the error lines of stderr) once the job has ended."""
    try:
        out, err = job.communicate(timeout=120)
    finally:
        if job.poll() is None:
            job.kill()
    return out, [line for line in err.splitlines() if line.startswith("flatland: error:")]


def test_a_killed_rank_ends_the_job_with_one_line_naming_it(tmp_path):
    job, pids = start_sweep(tmp_path, 3, 424242)
    os.kill(pids[1], signal.SIGKILL)
    out, errors = finish(job)
    assert job.returncode != 0
    assert len(errors) == 1, errors
    assert f"rank 1 (pid {pids[1]}) ended abnormally" in errors[0], errors[0]
    assert "nothing written" in errors[0], errors[0]
    assert out == ""
    assert not (tmp_path / "out").exists()


def test_ctrl_c_on_mpirun_stops_every_rank_and_writes_nothing(tmp_path):
    job, pids = start_sweep(tmp_path, 2, 434343)
    job.send_signal(signal.SIGINT)  # what Ctrl-C sends mpirun
    out, errors = finish(job)
    assert job.returncode != 0
    assert len(errors) == 1 and "nothing written" in errors[0], errors
    assert out == ""
    assert not (tmp_path / "out").exists()
    time.sleep(1)
    assert not [pid for pid in pids.values() if running(pid)], "a rank survived"


@pytest.mark.parametrize(
    "ranks, args, message",
    [
        (3, ["montecarlo", "--n", "1", "--controller", "feedback"],
         "mpirun -np 3: more ranks than the 1 run of this sweep"),
        (2, ["surface", "--nk", "2", "--np", "2", "--threads", "0"],
         "--threads: 0 (one per core) is refused under MPI"),
        (2, ["montecarlo", "--n", "4", "--threads", "0"],
         "--threads: 0 (one per core) is refused under MPI"),
        (2, ["solve", "--period", "1.181"], "'solve' is not a sweep"),
        (2, ["render", "--duration", "0.1"], "'render' is not a sweep"),
        (2, ["study", "tracker", "--quick"], "study tracker: not a sweep"),
        (2, ["montecarlo", "--n", "4", "--s-h", "-1"], "--s-h: must be finite and >= 0"),
    ],
)
def test_bad_launches_are_refused_with_one_line(ranks, args, message, tmp_path):
    p = run(MPIRUN + ["-np", str(ranks), str(CLI), *args, "--out", "out"], tmp_path)
    assert p.returncode == 2, p.stderr
    errors = [line for line in p.stderr.splitlines() if line.startswith("flatland: error:")]
    assert len(errors) == 1 and message in errors[0], p.stderr
    assert not (tmp_path / "out").exists()


def test_a_rank_that_fails_alone_is_named(tmp_path):
    # The scene exists for rank 0 only: rank 1 is refused before its sweep, and rank 0, already
    # in the sweep, reports it rather than waiting for it.
    scene = tmp_path / "mine.yaml"
    shutil.copy(ROOT / "assets" / "scenes" / "airtable-feedback.yaml", scene)
    wrapper = tmp_path / "only-rank-0-has-the-scene.sh"
    wrapper.write_text(
        "#!/bin/sh\n"
        f'if [ "$OMPI_COMM_WORLD_RANK" = 0 ]; then exec "$@" --scene {scene}; fi\n'
        f'exec "$@" --scene {scene}.missing-on-rank-1\n')
    wrapper.chmod(0o755)
    p = run(MPIRUN + ["-np", "2", str(wrapper), str(CLI), "montecarlo", "--n", "4", "--out", "out"],
            tmp_path)
    errors = [line for line in p.stderr.splitlines() if line.startswith("flatland: error:")]
    assert p.returncode == 2, p.stderr
    assert len(errors) == 1, p.stderr
    assert "rank 1: " in errors[0] and "missing-on-rank-1" in errors[0], errors[0]
    assert not (tmp_path / "out").exists()


def test_python_calls_spread_with_mpi4py_futures(tmp_path):
    example = ROOT / "examples" / "cluster" / "mpi_experiments.py"
    env = dict(os.environ, PYTHONPATH=str(BUILD / "python"))
    python = "/usr/bin/python3"  # Debian's, which has mpi4py and numpy
    p = subprocess.run(MPIRUN + ["-np", "2", python, "-m", "mpi4py.futures", str(example),
                                 "--worlds", "3"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, p.stderr
    spread = json.loads(p.stdout)
    assert spread["workers"] == 1
    # The same worlds in one process: the same outcomes and estimates, in the same order.
    single = subprocess.run([python, str(example), "--worlds", "3", "--serial"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=600, env=env)
    assert single.returncode == 0, single.stderr
    alone = json.loads(single.stdout)
    assert spread["outcomes"] == alone["outcomes"] and spread["nees_mean"] == alone["nees_mean"]
    assert len(set(alone["nees_mean"])) == 3  # each world has its own noise
