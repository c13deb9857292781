#!/usr/bin/env python3
"""What a controller in Python and a step of flatland.Env cost, measured in one run
(docs/BENCHMARKS.md, "Python controllers and flatland.Env").

1. The synthetic open-loop experiment (the bundled air table) with a trivial Python controller
   (the plan's acceleration, open loop: PlanPlayback below) against the same experiment with the
   C++ controller (controller="open-loop"): the same commands to the last bit (checked), so the
   difference is the 1 kHz callback. Also the paper's feedback controller written in Python
   (examples/python_controller.py) against the C++ one, the same log to the last bit (checked).
2. Env.step with observation="measurement" and "image", one tick a step, over the first second
   of the motion (the plan's accelerations as actions), against the same Env stepping 100 ticks
   a step (the same ticks, with a hundredth of the Python calls): steps per second and the
   ratio of the per-tick times.

Rounds are interleaved (each measurement once per round) and each ratio is of medians, of wall
time and of the process's CPU time (all its threads: llvmpipe renders on several), which a
machine shared with other work disturbs less. Prints one JSON object.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_loop_bench.py [--rounds 5]
"""
import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import flatland

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples"))
from python_controller import PaperController  # noqa: E402


class PlanPlayback:
    """The plan's acceleration, open loop: the C++ open-loop mode's law, in Python."""

    name = "playback"

    def start(self, context):
        self.plan, self.dt = context.plan, context.dt
        self.T = self.plan.duration
        self.final_angle = self.plan.hand(self.T)[0]

    def step(self, input):
        if input.t < 0:
            return flatland.ControlOutput(0.0, mode="waiting")
        if input.t >= self.T:
            hold = 900.0 * (self.final_angle - input.joint.theta) - 120.0 * input.joint.theta_dot
            return flatland.ControlOutput(hold, mode="done", done=True, t_done=self.T)
        return self.plan.hand(input.t + 0.5 * self.dt)[2]


def timed(fn):
    """(wall s, CPU s, fn())."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - t0, time.process_time() - c0, out


def env_steps(observation, ticks_per_step, actions):
    """(wall s, CPU s) per tick of Env.step over `actions` (one per tick), reset excluded."""
    env = flatland.Env(observation=observation, ticks_per_step=ticks_per_step)
    env.reset(seed=1)
    chosen = actions[::ticks_per_step]

    def run():
        for a in chosen:
            env.step(a)
    wall, cpu, _ = timed(run)
    env.close()
    ticks = len(chosen) * ticks_per_step
    return wall / ticks, cpu / ticks


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()

    reference = flatland.experiment(controller="open-loop")
    t = reference.log["t"]
    actions = reference.log["command"][(t >= 0) & (t < 1.0)]  # the first second: 1000 ticks
    ticks = len(t)

    names = ("cpp_open", "py_open", "cpp_feedback", "py_feedback", "env_measurement_1",
             "env_measurement_100", "env_image_1", "env_image_100")
    wall = {k: [] for k in names}
    cpu = {k: [] for k in names}

    def note(name, w, c):
        wall[name].append(w)
        cpu[name].append(c)

    for i in range(args.rounds):
        print(f"round {i + 1}/{args.rounds}", file=sys.stderr)
        w, c, cpp = timed(lambda: flatland.experiment(controller="open-loop"))
        note("cpp_open", w, c)
        w, c, own = timed(lambda: flatland.experiment(controller=PlanPlayback()))
        note("py_open", w, c)
        assert np.array_equal(cpp.log["command"], own.log["command"]), "not the same experiment"
        w, c, cpp_fb = timed(lambda: flatland.experiment())
        note("cpp_feedback", w, c)
        w, c, own_fb = timed(lambda: flatland.experiment(controller=PaperController()))
        note("py_feedback", w, c)
        assert np.array_equal(cpp_fb.log["command"], own_fb.log["command"]), "not the same law"
        for observation in ("measurement", "image"):
            for n in (1, 100):
                note(f"env_{observation}_{n}", *env_steps(observation, n, actions))
    feedback_ticks = len(cpp_fb.log["t"])

    def summary(med):
        return {
            "open_loop_experiment": {
                "ticks": ticks, "cpp_s": med["cpp_open"], "python_controller_s": med["py_open"],
                "ratio": med["py_open"] / med["cpp_open"],
                "callback_us_per_tick": (med["py_open"] - med["cpp_open"]) / ticks * 1e6},
            "feedback_experiment": {
                "ticks": feedback_ticks, "cpp_s": med["cpp_feedback"],
                "python_port_s": med["py_feedback"],
                "ratio": med["py_feedback"] / med["cpp_feedback"],
                "port_us_per_tick":
                    (med["py_feedback"] - med["cpp_feedback"]) / feedback_ticks * 1e6},
            "env_step": {
                obs: {"steps_per_s": 1.0 / med[f"env_{obs}_1"],
                      "ticks_per_s_100_a_step": 1.0 / med[f"env_{obs}_100"],
                      "ratio": med[f"env_{obs}_1"] / med[f"env_{obs}_100"],
                      "overhead_us_per_step":
                          (med[f"env_{obs}_1"] - med[f"env_{obs}_100"]) * 1e6}
                for obs in ("measurement", "image")}}

    print(json.dumps({
        "rounds": args.rounds,
        "wall": summary({k: statistics.median(v) for k, v in wall.items()}),
        "cpu": summary({k: statistics.median(v) for k, v in cpu.items()}),
        "per_round": {"wall": wall, "cpu": cpu},
    }, indent=2))


if __name__ == "__main__":
    main()
