"""The closed loop from Python: an experiment's log identical to `flatland experiment`'s."""

import csv
import json
import math

import numpy as np

import flatland
from conftest import run_cli


def test_experiment_log_and_result_equal_the_clis(cli, tmp_path):
    out = tmp_path / "run"
    run_cli("experiment", "--out", out, "--no-plot")
    e = flatland.experiment()
    with open(out / "log.csv", newline="") as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    assert list(e.log) == [h.split("[")[0] for h in header]
    for c, name in enumerate(e.log):
        column = e.log[name]
        assert len(column) == len(rows)
        if column.dtype.kind == "U":
            assert list(column) == [r[c] for r in rows]
        else:
            np.testing.assert_array_equal(column, np.array([float(r[c]) for r in rows]))
    result = json.loads((out / "result.json").read_text())
    for key, value in e.result.items():
        if key == "scene":
            continue
        assert result[key] == value, key


def test_a_feedback_experiment_succeeds_and_its_log_is_consistent():
    e = flatland.experiment(controller="feedback")
    assert e["success"] and e["outcome"] == "success"
    log = e.log
    # The loop ticks at 1 kHz.
    np.testing.assert_allclose(np.diff(log["t"]), 1e-3, rtol=0, atol=1e-9)
    # A measurement's capture precedes its tick, and only measured ticks have one.
    measured = log["measured"] == 1
    assert np.all(log["t_capture"][measured] <= log["t"][measured])
    assert np.all(np.isnan(log["s_meas"][~measured]))
    # The estimate follows the truth (synthetic run) to a few hundredths of s_h while estimating.
    est = log["estimating"] == 1
    assert np.nanmax(np.abs(log["s_est"][est] - log["s_true"][est])) < 0.1
    assert e["ticks"] == len(log["t"])


def test_montecarlo_counts_its_records():
    r = flatland.montecarlo(runs=2, controllers=["feedback"], seed=5)
    assert r["runs"] == 2 and len(r["records"]) == 2
    assert r["success_open_loop"] is None
    assert r["success_feedback"] == sum(rec["success"] for rec in r["records"])
    lo, hi = r["ci_feedback"]
    assert 0 <= lo <= r["success_feedback"] / 2 <= hi <= 1
