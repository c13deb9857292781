"""Render camera frames of a butterfly and track the disk with your own code (here a numpy
threshold centroid; cv2 works the same on these BGR arrays), next to flatland's tracker, both
against the renderer's exact truth.

    PYTHONPATH=build/python python3 examples/render_and_track.py [--out DIR]
"""
import argparse
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import flatland

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=".", help="directory for tracking.png")
args = parser.parse_args()

model = flatland.load(Path(flatland.default_scene_path()).with_name("butterfly-camera.yaml"))
renderer, tracker = flatland.Renderer(model), flatland.Tracker(model)
t, mine, theirs = [], [], []
for i in range(int(renderer.t_end * 30) + 1):
    image, truth = renderer.render(t=i / 30)        # H x W x 3 uint8, BGR
    gray = image.mean(axis=2)
    v, u = np.nonzero(gray > 200)                    # the disk's bright face (marker excluded)
    mine.append(np.hypot(u.mean() - truth["disk_center_px"][0],
                         v.mean() - truth["disk_center_px"][1]))
    found = tracker.track(image, theta=truth["theta"])
    theirs.append(np.hypot(*np.subtract(found["center"], truth["disk_center_px"])))
    t.append(truth["t"])
print(f"{len(t)} frames: centroid error median {np.median(mine):.3f} px, "
      f"flatland.Tracker {np.median(theirs):.4f} px")

fig, ax = plt.subplots(figsize=(7, 4))
ax.semilogy(t, mine, label="threshold centroid (yours)")
ax.semilogy(t, theirs, label="flatland.Tracker (edge fit)")
ax.set(xlabel="t (s)", ylabel="centre error (px)", title="Tracking rendered frames")
ax.legend()
fig.savefig(Path(args.out) / "tracking.png", dpi=120)
print(f"wrote {Path(args.out) / 'tracking.png'}")
