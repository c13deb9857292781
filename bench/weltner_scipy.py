#!/usr/bin/env python3
"""Weltner's turntable with scipy: the spatial rolling equations (paper eqs. 1-4 in space, 11 x 10,
row (3) as in docs/DYNAMICS.md) for a uniform ball on a plate spinning about the vertical, written
with numpy and integrated by scipy.integrate.solve_ivp, as a researcher would without flatland: no
projection onto the contact manifold, numpy's least squares for A x = b. The same case as
flatland_bench's BM_SpatialWeltner10s (ball r = 2 cm, plate at 10 rad/s, 10 s, rtol 1e-10,
atol 1e-12); prints one JSON object with the time, the work, the centre's error against Weltner's
closed form and the constraint drift at the end, for docs/BENCHMARKS.md.

    /usr/bin/python3 bench/weltner_scipy.py [--method DOP853|RK45] [--t-end 10]
"""
import argparse
import json
import time

import numpy as np
from scipy.integrate import solve_ivp

R_BALL, MASS, OMEGA = 0.02, 0.2, 10.0
G = np.array([0.0, 0.0, -9.8])
INERTIA = 0.4 * MASS * R_BALL ** 2 * np.eye(3)


def cross(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def sphere(s, r=R_BALL):
    """Position, J, n, K and dJ/du, dJ/dv, dK/du, dK/dv of the ball's longitude/latitude chart."""
    u, v = s
    cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
    c = r * np.array([cv * cu, cv * su, sv])
    c_u = r * np.array([-cv * su, cv * cu, 0])
    c_v = r * np.array([-sv * cu, -sv * su, cv])
    c_uu = r * np.array([-cv * cu, -cv * su, 0])
    c_uv = r * np.array([sv * su, -sv * cu, 0])
    c_vv = r * np.array([-cv * cu, -cv * su, -sv])
    J = np.column_stack([c_u, c_v])
    dJ = [np.column_stack([c_uu, c_uv]), np.column_stack([c_uv, c_vv])]
    return c, J, c / r, J / r, dJ, [d / r for d in dJ]


def plate(s):
    c = np.array([s[0], s[1], 0.0])
    J = np.array([[1.0, 0], [0, 1], [0, 0]])
    zero = np.zeros((3, 2))
    return c, J, np.array([0, 0, 1.0]), zero, [zero, zero], [zero, zero]


def quat_to_matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def hand(t):
    a = OMEGA * t
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    return R, np.array([0, 0, OMEGA])


def rhs(t, y):
    x, q, v, w = y[0:3], y[3:7], y[7:10], y[10:13]
    s_o, s_h, sd_o, sd_h = y[13:15], y[15:17], y[17:19], y[19:21]
    Rh, wh = hand(t)
    Ro = quat_to_matrix(q)
    ch, Jh, nh, Kh, dJh, dKh = plate(s_h)
    co, Jo, no, Ko, dJo, dKo = sphere(s_o)
    rh, Jh, Nh, Kh = Rh @ ch, Rh @ Jh, Rh @ nh, Rh @ Kh
    ro, Jo, No, Ko = Ro @ co, Ro @ Jo, Ro @ no, Ro @ Ko
    Jdh = Rh @ (dJh[0] * sd_h[0] + dJh[1] * sd_h[1]) @ sd_h
    Kdh = Rh @ (dKh[0] * sd_h[0] + dKh[1] * sd_h[1]) @ sd_h
    Jdo = Ro @ (dJo[0] * sd_o[0] + dJo[1] * sd_o[1]) @ sd_o
    Kdo = Ro @ (dKo[0] * sd_o[0] + dKo[1] * sd_o[1]) @ sd_o
    w_h, w_o = Jh @ sd_h, Jo @ sd_o
    A_h = np.cross(wh, np.cross(wh, rh))  # the plate's point: no linear or angular acceleration
    Iw = Ro @ INERTIA @ Ro.T
    A = np.zeros((11, 10))
    b = np.zeros(11)
    A[0:3, 0:3] = -np.eye(3)
    A[0:3, 3:6] = cross(ro)
    A[0:3, 6:8] = -Jo
    A[0:3, 8:10] = Jh
    b[0:3] = -(A_h + 2 * np.cross(wh, w_h) + Jdh) + (np.cross(w, np.cross(w, ro)) +
                                                     2 * np.cross(w, w_o) + Jdo)
    A[3:6, 3:6] = -cross(No)
    A[3:6, 6:8] = Ko
    A[3:6, 8:10] = Kh
    b[3:6] = -(np.cross(w, np.cross(w, No)) + 2 * np.cross(w, Ko @ sd_o) + Kdo +
               np.cross(wh, np.cross(wh, Nh)) + 2 * np.cross(wh, Kh @ sd_h) + Kdh)
    T = Jh.T
    A[6:8, 0:3] = -T
    A[6:8, 3:6] = T @ cross(ro)
    b[6:8] = -T @ (A_h + np.cross(wh, w_h) - np.cross(w, np.cross(w, ro)) - np.cross(w, w_o))
    scale = 1 / (MASS * np.linalg.norm(ro))
    A[8:11, 0:3] = -MASS * cross(ro) * scale
    A[8:11, 3:6] = Iw * scale
    b[8:11] = (-np.cross(w, Iw @ w) - MASS * np.cross(ro, G)) * scale
    sol = np.linalg.lstsq(A, b, rcond=None)[0]
    qw = np.array([0.0, *w])
    qd = 0.5 * np.array([qw[0] * q[0] - qw[1:] @ q[1:],
                         *(qw[0] * q[1:] + q[0] * qw[1:] + np.cross(qw[1:], q[1:]))])
    return np.concatenate([v, qd, sol[0:3], sol[3:6], sd_o, sd_h, sol[6:8], sol[8:10]])


def initial_state():
    """flatland_bench's Turntable: centre above (0.12, -0.04), moving at (0.05, 0.03), spin 1.5."""
    contact, v = np.array([0.12, -0.04, 0.0]), np.array([0.05, 0.03, 0.0])
    w = v - np.cross([0, 0, OMEGA], contact)
    q = np.array([np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0])  # body +x to world -z
    return np.concatenate([contact + [0, 0, R_BALL], q, v, [-w[1] / R_BALL, w[0] / R_BALL, 1.5],
                           [0, 0], contact[:2], [w[1] / R_BALL, w[0] / R_BALL], w[:2]])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="DOP853")
    parser.add_argument("--t-end", type=float, default=10.0)
    args = parser.parse_args()
    y0 = initial_state()
    start = time.perf_counter()
    sol = solve_ivp(rhs, (0, args.t_end), y0, method=args.method, rtol=1e-10, atol=1e-12)
    seconds = time.perf_counter() - start
    k = 2 / 7 * OMEGA
    p0, v0 = y0[0:3], y0[7:10]
    c = p0 + np.cross([0, 0, 1.0], v0) / k
    a = k * args.t_end
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    expected = c + rot @ (p0 - c)
    y = sol.y[:, -1]
    Rh, _ = hand(args.t_end)
    gap = (Rh @ np.array([y[15], y[16], 0])) - (y[0:3] + quat_to_matrix(y[3:7]) @ sphere(y[13:15])[0])
    print(json.dumps({"method": args.method, "seconds": seconds, "steps": int(sol.t.size - 1),
                      "rhs_evals": int(sol.nfev),
                      "centre_error_m": float(np.linalg.norm(y[0:3] - expected)),
                      "radius_m": float(np.linalg.norm(v0) / k),
                      "contact_gap_m": float(np.linalg.norm(gap)),
                      "quaternion_norm_error": float(abs(np.linalg.norm(y[3:7]) - 1))}))


if __name__ == "__main__":
    main()
