"""The paper's Fig. 6 and 7: s_h(T) over the motion space, whose zero level is the locus of
butterfly solutions k(2T), and the smallest normal force along that locus.

    PYTHONPATH=build/python python3 examples/fig6_fig7.py [--out DIR] [--quick]
"""
import argparse
from pathlib import Path

import matplotlib
matplotlib.use("Agg")  # files only: no window
import matplotlib.pyplot as plt
import numpy as np

import flatland

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=".", help="directory for fig6.png and fig7.png")
parser.add_argument("--quick", action="store_true", help="coarse grids (seconds, for CI)")
args = parser.parse_args()
out = Path(args.out)
n = 12 if args.quick else 60

surface = flatland.surface(nk=n, np=n, k_from=-1.6, k_to=-0.8, period_from=0.8, period_to=2.0)
locus = flatland.locus(n=n // 3, from_=1.1, to=2.0)
print(f"{n} x {n} surface: {surface['rhs_evals']} rhs evaluations; "
      f"locus k(1.1 s) = {locus['k'][0]:.5f}")

fig, ax = plt.subplots(figsize=(7, 5))
m = np.nanmax(np.abs(surface["s_T"]))
mesh = ax.pcolormesh(surface["period"], surface["k"], surface["s_T"], cmap="RdBu_r", vmin=-m,
                     vmax=m, shading="nearest")
ax.contour(surface["period"], surface["k"], surface["s_T"], levels=[0], colors="black")
ax.plot(locus["period"], locus["k"], "o", color="gold", label="solutions (locus)")
fig.colorbar(mesh, label="$s_h(T)$")
ax.set(xlabel="2T (s)", ylabel="k", title="Fig. 6: $s_h(T)$ over the motion space")
ax.legend(loc="upper left")
fig.savefig(out / "fig6.png", dpi=120)

fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6, 6))
top.plot(locus["period"], locus["k"], "o-")
top.set(ylabel="k", title="Fig. 7: butterfly solutions")
bottom.plot(locus["period"], locus["fn_min_ratio"], "o-")
bottom.axhline(0, color="black", lw=0.8)
bottom.set(xlabel="2T (s)", ylabel="min $f_n$ / (m g sin tilt)")
fig.savefig(out / "fig7.png", dpi=120)
print(f"wrote {out / 'fig6.png'} and {out / 'fig7.png'}")
