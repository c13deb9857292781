#!/usr/bin/env python3
"""The butterfly solve of `flatland solve --period 1.181` with scipy: the reduced disk equation of
bench/solve_reference.py (the same hand, motion and disk) integrated by
scipy.integrate.solve_ivp (DOP853 at rtol 1e-10, atol 1e-12, as flatland's default accuracy
needs) and k found by scipy.optimize.brentq on s_h(T). What a researcher would write with scipy;
bench/python_bindings.py times it against flatland.solve.

    /usr/bin/python3 bench/solve_scipy.py [PERIOD]
"""
import json
import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

sys.path.insert(0, str(Path(__file__).resolve().parent))
import solve_reference as ref  # noqa: E402


def s_at_half_period(T, k, counter, method="DOP853"):
    sol = solve_ivp(lambda t, y: ref.rhs(t, y, T, k), (0.0, T), [-1.0, 0.0], method=method,
                    rtol=ref.RTOL, atol=ref.ATOL)
    counter[0] += sol.nfev
    counter[1] += 1
    return sol.y[0, -1]


def solve(period, tolerance=1e-9, method="DOP853"):
    """k with s_h(T) = 0 for 2T = period, bracketed around the paper's -1.1393."""
    T = period / 2
    counter = [0, 0]
    k = brentq(lambda k: s_at_half_period(T, k, counter, method), -1.16, -1.12, xtol=tolerance)
    return {"period": period, "k": k, "simulations": counter[1], "rhs_evals": counter[0]}


if __name__ == "__main__":
    print(json.dumps(solve(float(sys.argv[1]) if len(sys.argv) > 1 else 1.181)))
