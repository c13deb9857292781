"""Your own controller and estimator in Python (flatland.experiment(controller=obj,
estimator=obj)): the paper's controller written in Python gives the C++ run to the last bit, a
Python estimator is called with what the loop measured, and every way of getting it wrong is
one line."""

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import flatland
from conftest import ROOT, SCENES

sys.path.insert(0, str(ROOT / "examples"))
from python_controller import PaperController  # noqa: E402


def assert_logs_equal(a, b, skip=()):
    assert list(a) == list(b)
    for name, column in a.items():
        if name in skip:
            continue
        if column.dtype.kind == "U":
            assert list(column) == list(b[name]), name
        else:
            # Bit for bit: equal numbers, NaN where NaN.
            np.testing.assert_array_equal(column, b[name], err_msg=name)


@pytest.fixture(scope="module")
def cpp_feedback():
    return flatland.experiment()


def test_the_paper_controller_in_python_gives_the_cpp_log_bit_for_bit(cpp_feedback):
    own = flatland.experiment(controller=PaperController())
    assert cpp_feedback["success"] and cpp_feedback["t_stage2"] is not None
    assert_logs_equal(cpp_feedback.log, own.log)
    for key, value in cpp_feedback.result.items():
        if key != "controller":
            assert own[key] == value, key
    assert own["controller"] == "paper-python"


def test_the_python_port_in_open_loop_mode_too():
    cpp = flatland.experiment(controller="open-loop")
    own = flatland.experiment(controller=PaperController(feedback=False))
    assert_logs_equal(cpp.log, own.log)
    assert own["outcome"] == cpp["outcome"]


def test_the_python_port_with_the_time_scaled_law_too(tmp_path):
    # The bundled scene with stage 2's other law (controller.law: time-scaled).
    text = (SCENES / "airtable-feedback.yaml").read_text()
    assert "\n  law: paper " in text
    scene = tmp_path / "time-scaled.yaml"
    scene.write_text(text.replace("\n  law: paper ", "\n  law: time-scaled "))
    cpp = flatland.experiment(scene)
    own = flatland.experiment(scene, controller=PaperController(law="time-scaled"))
    assert cpp["t_stage2"] is not None
    assert_logs_equal(cpp.log, own.log)


def test_controller_names_choose_built_in_types(cpp_feedback):
    # The scene's own choice by its names: the same run.
    named = flatland.experiment(controller="paper", estimator="ekf")
    assert_logs_equal(cpp_feedback.log, named.log)
    assert named.result == cpp_feedback.result
    with pytest.raises(ValueError, match=r"^controller: unknown 'pid' \(a mode: feedback, "
                                         r"open-loop; a type: paper"):
        flatland.experiment(controller="pid")
    with pytest.raises(ValueError, match=r"^estimator: unknown 'kalman' \(a type: ekf"):
        flatland.experiment(estimator="kalman")


class Constant:
    """A controller that commands a constant, or returns whatever it is given."""

    def __init__(self, value):
        self.value = value

    def step(self, input):
        return self.value


class RaisesAt:
    """Holds the hand, then raises at t >= t_raise."""

    name = "raiser"

    def __init__(self, t_raise):
        self.t_raise = t_raise

    def step(self, input):
        if input.t >= self.t_raise:
            return 1 / 0
        return 0.0


def test_a_controller_that_raises_stops_the_run_safely_with_its_message():
    e = flatland.experiment(controller=RaisesAt(0.1))
    assert e["safe_stop"] and e["outcome"] == "safe_stop"
    assert e["stop_reason"].startswith("controller: 'raiser' raised ZeroDivisionError: ")
    assert "at t = 0.1 s" in e["stop_reason"]
    # The loop stopped asking it: the ticks after t = 0.1 s are the loop's safe stop.
    log = e.log
    assert set(log["stage"][log["t"] >= 0.1]) == {"safe-stop"}
    assert set(log["stage"][log["t"] < 0.1]) == {"raiser"}


@pytest.mark.parametrize("value, what", [
    (float("nan"), r"returned a non-finite acceleration \(nan\) at t = -0\.25 s"),
    (math.inf, r"returned a non-finite acceleration \(inf\) at t = -0\.25 s"),
    ("fast", r"step returned a str \('fast'\) at t = -0\.25 s; expected a number"),
    (None, r"step returned a NoneType \(None\) at t = -0\.25 s"),
    (True, r"step returned a bool \(True\) at t = -0\.25 s"),
    (np.array([1.0, 2.0]), r"step returned a ndarray \(array\(\[1\., 2\.\]\)\)"),
])
def test_a_controller_returning_nan_or_the_wrong_type_is_a_value_error(value, what):
    with pytest.raises(ValueError, match=what) as raised:
        flatland.experiment(controller=Constant(value))
    assert "\n" not in str(raised.value)
    assert str(raised.value).startswith("controller 'Constant': ")


class FirstThenRaise(Constant):
    """Returns its value at the first tick, then raises (the run stops safely at once)."""

    def step(self, input):
        if hasattr(self, "t0"):
            raise RuntimeError("done")
        self.t0 = input.t
        return self.value


def test_numpy_scalars_and_ints_are_numbers():
    for value in (np.float32(0.5), np.int64(2), 3, np.array(0.25)):
        e = flatland.experiment(controller=FirstThenRaise(value))
        assert e.log["command"][0] == float(value) and e.log["stage"][0] == "FirstThenRaise"
        assert e["stop_reason"] == "controller: 'FirstThenRaise' raised RuntimeError: done at t = -0.249 s"


def test_objects_without_the_methods_are_refused_at_the_call():
    with pytest.raises(ValueError, match=r"^controller: a object has no step method"):
        flatland.experiment(controller=object())
    with pytest.raises(ValueError, match=r"^controller\.step: must be a method, got a int"):
        flatland.experiment(controller=type("C", (), {"step": 3})())
    with pytest.raises(ValueError, match=r"^controller\.name: a str"):
        flatland.experiment(controller=type("C", (), {"step": lambda s, i: 0.0, "name": 5})())
    with pytest.raises(ValueError, match=r"^estimator: a Constant has no reset method"):
        flatland.experiment(estimator=Constant(0.0))
    with pytest.raises(ValueError, match=r"^ControlOutput\.theta_ddot: a number, got a str"):
        flatland.ControlOutput("x")
    with pytest.raises(ValueError, match=r"^ControlOutput\.done: True or False, got a int"):
        flatland.ControlOutput(0.0, done=1)
    with pytest.raises(ValueError, match=r"^Estimate\.covariance: 2 x 2 numbers"):
        flatland.Estimate(0.0, 0.0, 0.0, ((1.0, 0.0),))
    with pytest.raises(ValueError, match=r"^Estimate\.covariance: the variances"):
        flatland.Estimate(0.0, 0.0, 0.0, ((-1.0, 0.0), (0.0, 1.0)))


class StopsAt:
    """Asks for a safe stop at t >= t_stop."""

    def __init__(self, t_stop):
        self.t_stop = t_stop

    def step(self, input):
        if input.t >= self.t_stop:
            return flatland.ControlOutput(0.0, stop="lost faith in the plan")
        return 0.0


def test_a_controller_may_ask_for_a_safe_stop():
    e = flatland.experiment(controller=StopsAt(0.05))
    assert e["outcome"] == "safe_stop"
    assert e["stop_reason"] == "controller: lost faith in the plan"


class AlphaBeta:
    """A constant-velocity alpha-beta filter that ignores the camera's latency: simple enough to
    run again from the log's columns. It notes the types it was called with."""

    name = "alpha-beta"
    alpha, beta, period = 0.5, 0.2, 1 / 30

    def __init__(self):
        self.called_with = set()

    def reset(self, t, s_h, sdot_h):
        self.t, self.s, self.v = t, s_h, sdot_h

    def propagate(self, t_next, hand):
        self.called_with.add(type(hand).__name__)
        self.s += self.v * (t_next - self.t)
        self.t = t_next

    def update(self, z):
        self.called_with.add(type(z).__name__)
        r = z.s_h - self.s
        self.s += self.alpha * r
        self.v += self.beta * r / self.period
        return r * r / (z.sigma * z.sigma + 1e-4)

    def estimate(self):
        return flatland.Estimate(self.t, self.s, self.v, ((1e-4, 0.0), (0.0, 1e-2)))


def test_a_python_estimator_gets_what_the_loop_measured():
    estimator = AlphaBeta()
    e = flatland.experiment(estimator=estimator)
    assert estimator.called_with == {"HandInput", "Measurement"}
    log = e.log
    assert e["measurements"] > 20 and e["estimator_steps"] > 1000
    # The same filter run again from the log: reset at the first measurement (its tick, its
    # s_h, at rest), updated at each measured tick, propagated from tick to tick. The loop's
    # logged estimate at each tick (after its measurement, before its propagation) must be it.
    replay = AlphaBeta()
    started = False
    checked = 0
    for i, t in enumerate(log["t"]):
        if log["measured"][i] == 1:
            if not started:
                replay.reset(t, log["s_meas"][i], 0.0)
                started = True
            else:
                replay.update(SimpleNamespace(s_h=log["s_meas"][i], sigma=0.0))
        assert (log["estimating"][i] == 1) == started
        if started:
            assert log["s_est"][i] == replay.s and log["sdot_est"][i] == replay.v, t
            checked += 1
            if i + 1 < len(log["t"]):
                replay.propagate(log["t"][i + 1], None)
    assert checked > 1000
    # Counted by the adapter (the filter has no counts method): a propagation per tick.
    assert e["estimator_steps"] == checked - 1 or e["estimator_steps"] == checked


class WrongEstimate(AlphaBeta):
    def estimate(self):
        return (self.t, self.s, self.v)


class RaisingUpdate(AlphaBeta):
    def update(self, z):
        raise KeyError("no such frame")


def test_an_estimator_returning_the_wrong_type_is_one_line_and_one_raising_stops_safely():
    with pytest.raises(ValueError, match=r"^estimator 'alpha-beta': estimate returned a tuple "
                                         r"\(\(.*\)\) at t = .* s; expected a flatland\.Estimate$"):
        flatland.experiment(estimator=WrongEstimate())
    # A filter that fails is the loop's to handle, as a controller that fails: the hand is
    # stopped safely, with the estimator's message, and the filter is not asked again.
    e = flatland.experiment(estimator=RaisingUpdate())
    assert e["safe_stop"] and e["outcome"] == "safe_stop"
    assert e["stop_reason"].startswith(
        "estimator: estimator 'alpha-beta': update raised KeyError: 'no such frame' at t = ")
    log = e.log
    first_failure = log["t"][log["stage"] == "safe-stop"].min()
    assert not log["estimating"][log["t"] > first_failure].any()
