"""Your own controller in Python: the paper's three-stage controller (section 5; the C++
PaperController of control/src/controller.cpp) written again in Python, run in the closed loop
in its place, and plotted over the C++ run. Same law, same operations in the same order on
IEEE doubles: the two logs are equal to the last bit (python/tests/test_controllers.py checks
it on every column).

    PYTHONPATH=build/python python3 examples/python_controller.py [--out DIR]
"""
import argparse
from pathlib import Path

import flatland

WAITING, DIP, SERVO, FINISH, OPEN_LOOP, DONE = (
    "waiting", "dip", "servo", "finish", "open-loop", "done")


class PaperController:
    """The paper's controller: an open-loop dip until the estimated s_h passes ``dip_until``,
    then a servo to the plan indexed by the estimated s_h, then the rest of the plan from
    ``finish_after`` with a cubic that removes the hand's offsets by the plan's end. The
    defaults are the scene section ``controller``'s (docs/SCENE.md)."""

    name = "paper-python"

    def __init__(self, feedback=True, law="paper", kp=900.0, kd=120.0, dip_until=-0.9,
                 finish_after=0.9):
        self.feedback, self.law, self.kp, self.kd = feedback, law, kp, kd
        self.dip_until, self.finish_after = dip_until, finish_after

    def start(self, context):
        """Once, before the first tick: the plan and the control period."""
        self.plan, self.dt = context.plan, context.dt
        self.stage, self.t_end = WAITING, None
        self.tau3 = self.t3 = self.c2 = self.c3 = 0.0

    def plan_acceleration(self, tau):
        # The mid-tick value: the joint integrates the held command to second order.
        return self.plan.hand(tau + 0.5 * self.dt)[2]

    def step(self, input):
        """The command for the tick at input.t."""
        t, joint, estimate = input.t, input.joint, input.estimate
        T = self.plan.duration
        if self.stage == WAITING and t >= 0:
            self.stage = DIP if self.feedback else OPEN_LOOP
        theta_ddot = 0.0
        if self.stage == OPEN_LOOP:
            if t >= T:
                self.stage, self.t_end = DONE, T
            else:
                theta_ddot = self.plan_acceleration(t)
        elif self.stage in (DIP, SERVO, FINISH):
            theta_ddot = self.feedback_stages(t, joint, estimate, T)
        done, t_done = False, None
        if self.stage == DONE:
            # Hold the plan's final angle.
            hold = self.plan.hand(T)[0]
            theta_ddot = self.kp * (hold - joint.theta) - self.kd * joint.theta_dot
            done, t_done = True, self.t_end
        if self.stage == SERVO:
            reference = self.plan.hand(self.plan.time_at(estimate.s_h))[0]
        else:
            reference = self.plan.hand(max(t, 0.0))[0]
        return flatland.ControlOutput(theta_ddot, mode=self.stage, theta_reference=reference,
                                      done=done, t_done=t_done)

    def feedback_stages(self, t, joint, estimate, T):
        """Stages 1 to 3; a stage that ends hands the tick to the next, as the C++ falls
        through its switch."""
        if self.stage == DIP:
            if estimate.s_h > self.dip_until:
                self.stage = SERVO
            else:
                return self.plan_acceleration(t)
        if self.stage == SERVO:
            if estimate.s_h > self.finish_after:
                self.stage, self.t3 = FINISH, t
                self.tau3 = self.plan.time_at(self.finish_after)
                tr = T - self.tau3
                angle, rate, _ = self.plan.hand(self.tau3)
                d_theta, d_rate = joint.theta - angle, joint.theta_dot - rate
                if tr > self.dt:
                    self.c3 = (2.0 * d_theta + d_rate * tr) / (tr * tr * tr)
                    self.c2 = -(d_rate + 3.0 * self.c3 * tr * tr) / (2.0 * tr)
                else:
                    self.c2 = self.c3 = 0.0
            else:
                tp = self.plan.time_at(estimate.s_h)
                angle, rate, acceleration = self.plan.hand(tp)
                if self.law == "paper":
                    return self.kp * (angle - joint.theta) + self.kd * (rate - joint.theta_dot)
                # time-scaled: the disk's pace against the plan's, bounded.
                pace = min(max(estimate.sdot_h / self.plan.sdot_h_at(tp), 0.5), 2.0)
                return (pace * pace * acceleration + self.kp * (angle - joint.theta)
                        + self.kd * (pace * rate - joint.theta_dot))
        elapsed = t - self.t3
        if self.tau3 + elapsed >= T:
            self.stage, self.t_end = DONE, self.t3 + (T - self.tau3)
            return 0.0
        s = elapsed + 0.5 * self.dt
        return self.plan_acceleration(self.tau3 + elapsed) + 2.0 * self.c2 + 6.0 * self.c3 * s


def main():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=".", help="directory for python_controller.png")
    args = parser.parse_args()

    cpp = flatland.experiment()  # the scene's controller: the C++ PaperController
    own = flatland.experiment(controller=PaperController())
    differ = [name for name, column in cpp.log.items()
              if not np.array_equal(column, own.log[name], equal_nan=column.dtype.kind == "f")]
    print(f"C++: {cpp['outcome']} in {cpp['duration_s']} s; Python: {own['outcome']} in "
          f"{own['duration_s']} s; log columns that differ: {differ or 'none'}")

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for run, label, style in ((cpp, "C++", "-"), (own, "Python", "--")):
        top.plot(run.log["t"], run.log["theta"], style, label=f"hand angle, {label}")
        bottom.plot(run.log["t"], run.log["s_true"], style, label=f"true $s_h$, {label}")
    top.set(ylabel="θ (rad)", title="The paper's controller in C++ and in Python")
    top.legend()
    bottom.set(xlabel="t (s)", ylabel="$s_h$")
    bottom.legend()
    fig.savefig(Path(args.out) / "python_controller.png", dpi=120)
    print(f"wrote {Path(args.out) / 'python_controller.png'}")


if __name__ == "__main__":
    main()
