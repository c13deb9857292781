"""The simulator's operations from Python: identical to the CLI's results, and right by
independent checks (the paper's numbers, invariants)."""

import csv
import math

import numpy as np
import pytest

import flatland
from conftest import cli_json, run_cli


def same(a, b):
    """Equal JSON-like values, NaN-free (JSON has null); floats compared exactly."""
    assert type(a) is type(b) or (isinstance(a, (int, float)) and isinstance(b, (int, float))), \
        (a, b)
    if isinstance(a, dict):
        assert list(a) == list(b)
        for k in a:
            same(a[k], b[k])
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            same(x, y)
    else:
        assert a == b, (a, b)


def test_solve_equals_the_cli(cli):
    expected = cli_json("solve", "--period", "1.181")
    del expected["files"]
    got = flatland.solve(period=1.181)
    same(got, expected)


def test_solve_finds_the_papers_butterfly(cli):
    # Paper section 4.3: 2T = 1.181 s gives k = -1.1393 (printed to 4 decimals).
    r = flatland.solve(period=1.181)
    assert abs(r["k"] - (-1.1393)) < 5e-4
    assert abs(r["s_T"]) < 1e-8
    assert r["contact_lost"] is False


def test_solve_for_d_and_overrides_equal_the_cli(cli):
    expected = cli_json("solve", "--period", "1.181", "--solve-for", "d", "--k", "-1.14",
                        "--method", "dop853", "--rtol", "1e-11")
    del expected["files"]
    got = flatland.solve(period=1.181, solve_for="d", k=-1.14, method="dop853", rtol=1e-11)
    same(got, expected)


def test_a_loaded_model_is_a_scene(cli):
    model = flatland.load(flatland.default_scene_path())
    assert model.origin.endswith("butterfly.yaml")
    same(flatland.solve(period=1.181, scene=model), flatland.solve(period=1.181))


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def test_simulate_report_and_trajectory_equal_the_cli(cli, tmp_path):
    out = tmp_path / "run.csv"
    expected = cli_json("simulate", "--model", "hybrid", "--mu", "0.6", "--out", out)
    del expected["csv"]
    sim = flatland.simulate(model="hybrid", mu=0.6)
    same(sim.report, expected)
    header, rows = read_csv(out)
    assert list(sim.trajectory) == header
    for c, name in enumerate(header):
        column = sim.trajectory[name]
        assert len(column) == len(rows)
        if name == "mode":
            assert list(column) == [r[c] for r in rows]
        else:
            np.testing.assert_array_equal(column, np.array([float(r[c]) for r in rows]))


def test_simulate_resampled_rows_are_evenly_spaced():
    sim = flatland.simulate(sample_dt=0.01)
    t = sim.trajectory["t"]
    # Every 0.01 s from 0, and the run's end (1.181 s) as the last row.
    assert t[0] == 0.0 and t[-1] == 1.181 and len(t) == 1 + math.floor(1.181 / 0.01 + 1e-9) + 1
    np.testing.assert_allclose(np.diff(t)[:-1], 0.01, rtol=0, atol=1e-12)


def test_rolling_run_keeps_its_constraint(cli):
    # The reduced disk formulation has no residual; the paper's general A x = b must stay on its
    # manifold (an invariant of the projection).
    sim = flatland.simulate(formulation="general")
    assert sim["formulation"] == "general"
    assert sim["max_constraint_residual"] < 1e-9
    assert np.all(sim.trajectory["constraint_residual"] < 1e-9)


def test_time_optimal_equals_the_cli(cli):
    expected = cli_json("time-optimal", "--from", "1.0", "--to", "1.3")
    del expected["files"]
    same(flatland.time_optimal(from_=1.0, to=1.3), expected)


def test_design_equals_the_cli_and_its_motion_only_design_is_the_solution(cli):
    expected = cli_json("design", "--motion-only")
    del expected["files"]
    got = flatland.design(motion_only=True)
    same(got, expected)
    solved = flatland.solve()
    assert got["best"]["feasible"]
    assert abs(got["best"]["k"] - solved["k"]) < 1e-6
    assert abs(got["best"]["mu_required"] - solved["mu_required"]) < 1e-6


def test_locus_equals_the_cli_and_gives_arrays(cli):
    expected = cli_json("locus", "--n", "3", "--from", "1.1", "--to", "1.5")
    got = flatland.locus(n=3, from_=1.1, to=1.5)
    same(got["points"], expected["points"])
    np.testing.assert_array_equal(got["k"], [p["k"] for p in expected["points"]])
    # Each point is a solution: solving at its period alone gives the same k.
    one = flatland.solve(period=float(got["period"][1]))
    assert abs(one["k"] - got["k"][1]) < 1e-8


def test_surface_changes_sign_across_the_locus(cli, tmp_path):
    s = flatland.surface(nk=9, np=3, k_from=-1.3, k_to=-1.0, period_from=1.1, period_to=1.3)
    assert s["s_T"].shape == (9, 3)
    # At 2T = 1.181 s the solution k = -1.1393 lies inside [-1.3, -1.0]: s_T changes sign along
    # k at the middle period (1.2 s, whose solution is near -1.14 too).
    column = s["s_T"][:, 1]
    assert np.any(column > 0) and np.any(column < 0)
    run_cli("surface", "--nk", "9", "--np", "3", "--k-from", "-1.3", "--k-to", "-1.0",
            "--period-from", "1.1", "--period-to", "1.3", "--out", tmp_path / "s", "--no-plot")
    header, rows = read_csv(tmp_path / "s" / "surface.csv")
    np.testing.assert_array_equal(s["s_T"].ravel(), [float(r[2]) for r in rows])


def test_sim_study_equals_the_clis_csv_but_for_its_timings(cli, tmp_path):
    got = flatland.study("sim", quick=True)
    run_cli("study", "sim", "--quick", "--out", tmp_path / "s", "--no-plot")
    header, rows = read_csv(tmp_path / "s" / "sim.csv")
    assert list(got) == header
    for c, name in enumerate(header):
        if name.startswith("cpu_"):
            assert np.all(got[name] > 0)  # a time, measured anew
            continue
        expected = [r[c] for r in rows]
        if got[name].dtype.kind == "U":
            assert list(got[name]) == expected
        else:
            np.testing.assert_array_equal(got[name], np.array([float(v) for v in expected]))
    # The work-precision diagram's point: tighter tolerances give smaller errors in k*.
    dopri = (got["method"] == "dopri5") & (got["formulation"] == "reduced")
    err = got["err_k"][dopri][np.argsort(got["rtol"][dopri])]
    assert err[0] < err[-1]


def test_every_run_reports_its_energy_audit():
    """The report's energy audit (docs/DYNAMICS.md): its terms add up to its balance, which is
    within its bound; the paper's hand does work on the disk, and a surface's points all balance."""
    e = flatland.simulate().report["energy"]
    assert e["holds"] and abs(e["balance"]) <= e["bound"]
    terms = e["final"] - e["initial"] - e["work_hand"] - e["work_losses"] - e["impact_losses"]
    assert abs(terms - e["balance"]) <= 1e-14
    assert e["work_hand"] != 0 and e["work_losses"] == 0
    s = flatland.surface(nk=2, np=2)
    assert s["numerical_failures"] == []
