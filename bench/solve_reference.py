#!/usr/bin/env python3
"""The butterfly solve of `flatland solve --period 1.181` in plain Python (no numpy, no scipy).

The reference for the start-up benchmark (bench/cli_startup.py, docs/BENCHMARKS.md "Start-up"):
what a researcher would write in an afternoon. The same equations as flatland's reduced disk
formulation (docs/DYNAMICS.md), derived here from the paper's hand and motion, the same
integrator (Dormand-Prince 5(4), rtol 1e-10, atol 1e-12) and a secant iteration on k until
|dk| < 1e-9. Prints one JSON object: k, s_h(T), simulations, rhs_evals.
"""
import json
import math
import sys

# The paper's butterfly (assets/scenes/butterfly.yaml), SI units.
A, B, C, D = 0.18, -0.18, -0.252, 0.216
E, F = -(A + C), -(B + 3 * D) / 5
R = 0.051            # disk radius, uniform disk: rho^2 = r^2 / 2
RHO2 = R * R / 2
G = 9.8
RTOL, ATOL = 1e-10, 1e-12


def hand(s):
    """Position and first three derivatives of the hand at s: the polynomial of section 4.1 on
    [-1, 1], mirrored (x -> -x) on [1, 3] and on [-3, -1], as flatland's PolynomialHand."""
    piece = math.floor((s + 1) / 2)
    mirrored = piece % 2 != 0
    u = 2 * piece - s if mirrored else s - 2 * piece
    du, mx = (-1, -1) if mirrored else (1, 1)
    u2, u3, u4 = u * u, u ** 3, u ** 4
    x = (A + C * u2 + E * u4, 2 * C * u + 4 * E * u3, 2 * C + 12 * E * u2, 24 * E * u)
    y = (B * u + D * u3 + F * u ** 5, B + 3 * D * u2 + 5 * F * u4, 6 * D * u + 20 * F * u3,
         6 * D + 60 * F * u2)
    return ((mx * x[0], du * mx * x[1], mx * x[2], du * mx * x[3]),
            (y[0], du * y[1], y[2], du * y[3]))


def motion(t, T, k):
    """theta, theta', theta'' of the butterfly motion (paper section 4.2)."""
    l = -(1 + 3 * k) / 5
    scale = math.pi / (2 * (1 + k + l))
    u = (t - T) / T
    u2 = u * u
    p = u * (1 + u2 * (k + l * u2))
    dp = 1 + u2 * (3 * k + 5 * l * u2)
    ddp = u * (6 * k + 20 * l * u2)
    return scale * p + math.pi / 2, scale * dp / T, scale * ddp / (T * T)


def rhs(t, y, T, k):
    s, sd = y
    (x0, x1, x2, x3), (y0, y1, y2, y3) = hand(s)
    speed = math.hypot(x1, y1)
    tx, ty = x1 / speed, y1 / speed
    nx, ny = -ty, tx  # outward normal: the tangent turned +90 degrees
    c12 = x1 * y2 - y1 * x2
    c13 = x1 * y3 - y1 * x3
    d12 = x1 * x2 + y1 * y2
    kappa = -c12 / speed ** 3
    kappa_ds = -(c13 / speed ** 3 - 3 * c12 * d12 / speed ** 5)
    speed_ds = d12 / speed
    sigma = speed * (1 + R * kappa)
    sigma_ds = speed_ds * (1 + R * kappa) + speed * R * kappa_ds
    qx, qy = x0 + R * nx, y0 + R * ny  # the disk's centre in the hand frame
    th, w, al = motion(t, T, k)
    # R^T (a_h - g) with a fixed joint and g = (0, -G): R^T (0, G)
    ax, ay = G * math.sin(th), G * math.cos(th)
    along = ax * tx + ay * ty + al * (-qy * tx + qx * ty) - w * w * (qx * tx + qy * ty)
    sdd = -(sigma_ds * sd * sd + (along - (RHO2 / R) * al) / (1 + RHO2 / (R * R))) / sigma
    return (sd, sdd)


# Dormand-Prince 5(4) (Hairer's DOPRI5 tableau).
C2, C3, C4, C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
B1, B3, B4, B5, B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
E1, E3, E4, E5, E6, E7 = (71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525,
                          -1 / 40)


def s_at_half_period(T, k, counter):
    """s_h(T) from rest at s_h = -1 (the palm well)."""
    t, y = 0.0, (-1.0, 0.0)
    h = 1e-4
    k1 = rhs(t, y, T, k)
    counter[0] += 1
    while t < T:
        h = min(h, T - t)

        def at(*terms):
            return tuple(y[i] + h * sum(a * kk[i] for a, kk in terms) for i in range(2))

        k2 = rhs(t + C2 * h, at((A21, k1)), T, k)
        k3 = rhs(t + C3 * h, at((A31, k1), (A32, k2)), T, k)
        k4 = rhs(t + C4 * h, at((A41, k1), (A42, k2), (A43, k3)), T, k)
        k5 = rhs(t + C5 * h, at((A51, k1), (A52, k2), (A53, k3), (A54, k4)), T, k)
        k6 = rhs(t + h, at((A61, k1), (A62, k2), (A63, k3), (A64, k4), (A65, k5)), T, k)
        y_new = at((B1, k1), (B3, k3), (B4, k4), (B5, k5), (B6, k6))
        k7 = rhs(t + h, y_new, T, k)
        counter[0] += 6
        err = 0.0
        for i in range(2):
            e = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] +
                     E7 * k7[i])
            sc = ATOL + RTOL * max(abs(y[i]), abs(y_new[i]))
            err += (e / sc) ** 2
        err = math.sqrt(err / 2)
        if err <= 1.0:
            t, y, k1 = t + h, y_new, k7
        h *= min(5.0, max(0.2, 0.9 * err ** -0.2)) if err > 0 else 5.0
    return y[0]


def main():
    period = float(sys.argv[1]) if len(sys.argv) > 1 else 1.181
    T = period / 2
    counter = [0]
    simulations = 0
    k0, k1 = -1.1393, -1.1393 + 1e-3
    f0 = s_at_half_period(T, k0, counter)
    f1 = s_at_half_period(T, k1, counter)
    simulations += 2
    while abs(k1 - k0) > 1e-9 and f1 != f0:
        k0, f0, k1 = k1, f1, k1 - f1 * (k1 - k0) / (f1 - f0)
        f1 = s_at_half_period(T, k1, counter)
        simulations += 1
    print(json.dumps({"period": period, "k": k1, "s_T": f1, "simulations": simulations,
                      "rhs_evals": counter[0]}))


if __name__ == "__main__":
    main()
