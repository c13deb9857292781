"""Controllers compared on the same worlds from Python: montecarlo(controllers=[...]) returns the
CLI's per-controller summaries and paired comparisons, and they agree with a count over its own
records."""

import math

import pytest

import flatland
from conftest import cli_json


def _same(python_value, cli_value):
    """Python's NaN is the CLI's null; tuples are its lists."""
    if isinstance(python_value, dict):
        return set(python_value) == set(cli_value) and all(
            _same(python_value[k], cli_value[k]) for k in python_value)
    if isinstance(python_value, (list, tuple)):
        return len(python_value) == len(cli_value) and all(
            _same(a, b) for a, b in zip(python_value, cli_value))
    if isinstance(python_value, float) and math.isnan(python_value):
        return cli_value is None
    return python_value == cli_value


def test_summaries_and_pairs_equal_the_clis_and_the_records(cli):
    names = ["open-loop", "paper"]
    r = flatland.montecarlo(runs=2, seed=7, controllers=names, threads=2)
    j = cli_json("montecarlo", "--n", 2, "--seed", 7, "--controller", ",".join(names),
                 "--threads", 2)
    assert [s["controller"] for s in r["summaries"]] == names
    assert _same(r["summaries"], j["summaries"])
    assert _same(r["pairs"], j["pairs"])

    # Against the records: successes per controller and the one pair's counts.
    ok = {(rec["controller"], rec["run"]): rec["success"] for rec in r["records"]}
    for s in r["summaries"]:
        assert s["successes"] == sum(ok[(s["controller"], w)] for w in range(2))
        assert sum(s["outcomes"].values()) == 2
    (pair,) = r["pairs"]
    a, b = pair["a"], pair["b"]
    assert (a, b) == tuple(names)
    assert pair["only_a"] == sum(ok[(a, w)] and not ok[(b, w)] for w in range(2))
    assert pair["only_b"] == sum(ok[(b, w)] and not ok[(a, w)] for w in range(2))
    assert pair["both"] == sum(ok[(a, w)] and ok[(b, w)] for w in range(2))
    assert pair["worlds"] == 2
    # Exact McNemar: 2 * P[Binomial(d, 1/2) <= min(only_a, only_b)], at most 1.
    d, m = pair["only_a"] + pair["only_b"], min(pair["only_a"], pair["only_b"])
    expected = min(1.0, 2 * sum(math.comb(d, i) for i in range(m + 1)) / 2**d)
    assert pair["p_value"] == pytest.approx(expected, rel=1e-12)
    # Each record names the world's friction coefficient, which its margin is taken against.
    assert all(rec["mu"] > 0 and rec["mu_max"] <= rec["mu"] for rec in r["records"])


def test_an_unknown_controller_is_a_value_error_naming_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown type 'bogus' \(known: open-loop, feedback"):
        flatland.montecarlo(runs=1, controllers=["paper", "bogus"])
