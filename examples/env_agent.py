"""An agent in flatland.Env, the closed loop a step at a time (Gymnasium's convention): it plays
the plan's acceleration open loop, 10 ms a step, and sees what a real loop sees. The figure
shows what it observed (the camera's measurements of s_h, arriving at 30 Hz a frame late, and
the estimator's belief) against the truth from info, and the last frame it rendered.

    PYTHONPATH=build/python python3 examples/env_agent.py [--out DIR] [--seed N]
"""
import argparse
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import flatland

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=".", help="directory for env_agent.png")
parser.add_argument("--seed", type=int, default=1, help="the camera noise's seed")
args = parser.parse_args()

env = flatland.Env(observation="measurement", ticks_per_step=10)
names = env.observation_names
obs, info = env.reset(seed=args.seed)
observations, truths, total = [obs], [info], 0.0
done = False
while not done:
    # The plan's acceleration at the middle of the step: an open-loop agent.
    action = env.plan.hand(info["t"] + 0.5 * env.dt)[2]
    obs, reward, terminated, truncated, info = env.step(action)
    observations.append(obs)
    truths.append(info)
    total += reward
    done = terminated or truncated
print(f"{len(observations) - 1} steps, ended by {info['ended_by']}: {info['outcome']}, "
      f"reward {total}")

seen = {name: np.array([o[i] for o in observations]) for i, name in enumerate(names)}
t = seen["t"]
fig, (top, bottom) = plt.subplots(1, 2, figsize=(12, 4.5))
top.plot(t, [i["s_h"] for i in truths], color="lightgray", lw=4, label="true (info)")
top.plot(t, np.where(np.isfinite(seen["sigma_s_est"]), seen["s_est"], np.nan), label="estimate")
measured = np.isfinite(seen["t_capture"])
top.step(t[measured], seen["s_meas"][measured], where="post", label="latest measurement")
top.set(xlabel="t (s)", ylabel="$s_h$", title=f"What the agent observed ({info['outcome']})")
top.legend()
frame = env.render()
if frame is not None:
    bottom.imshow(frame)
bottom.set(title="env.render(): the last camera frame")
bottom.axis("off")
fig.tight_layout()
fig.savefig(Path(args.out) / "env_agent.png", dpi=100)
print(f"wrote {Path(args.out) / 'env_agent.png'}")
env.close()
