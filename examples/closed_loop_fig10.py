"""A closed-loop butterfly with vision feedback (the paper's Fig. 10): the hand angle, and the
contact s_h as estimated from 30 Hz camera frames, measured, and true.

    PYTHONPATH=build/python python3 examples/closed_loop_fig10.py [--out DIR]
"""
import argparse
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import flatland

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=".", help="directory for fig10.png")
parser.add_argument("--controller", default="feedback", choices=["feedback", "open-loop"])
args = parser.parse_args()

run = flatland.experiment(controller=args.controller)
log = run.log
print(f"{args.controller}: {run['outcome']} in {run['duration_s']} s, "
      f"{run['measurements']} measurements of {run['frames']} frames")

fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
top.plot(log["t"], log["theta"], label="hand angle")
top.plot(log["t"], log["theta_plan"], "--", label="plan")
top.set(ylabel="θ (rad)", title=f"Fig. 10: {args.controller} butterfly ({run['outcome']})")
top.legend()
measured = log["measured"] == 1
bottom.plot(log["t"], log["s_true"], color="lightgray", lw=4, label="true")
bottom.plot(log["t"], np.where(log["estimating"] == 1, log["s_est"], np.nan), label="estimate")
bottom.plot(log["t_capture"][measured], log["s_meas"][measured], ".", ms=4, label="camera")
bottom.set(xlabel="t (s)", ylabel="$s_h$")
bottom.legend()
fig.savefig(Path(args.out) / "fig10.png", dpi=120)
print(f"wrote {Path(args.out) / 'fig10.png'}")
