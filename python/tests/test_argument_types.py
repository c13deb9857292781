"""Every argument of every public function and method, given a value of the wrong type, raises a
one-line ValueError naming it, before anything runs; a bool is not a number (True is not a 1 s
period). The table below must list every parameter (the first test checks it against the
signatures), so that a new argument comes with its check."""

import inspect
from pathlib import Path

import numpy as np
import pytest

import flatland
from conftest import SCENES

CAMERA = SCENES / "butterfly-camera.yaml"
AIRTABLE = SCENES / "airtable-5deg.yaml"
# A valid recording (identify, validate_world): arrays of t, theta, s_h and one sigma.
A_RECORDING = {"t": np.linspace(0, 1, 8), "theta": np.zeros(8), "s_h": -np.ones(8), "sigma": 1e-3}
A_CAMERA = {"width": 640, "height": 480, "K": [[900, 0, 319.5], [0, 900, 239.5], [0, 0, 1]],
            "dist": [0, 0, 0, 0, 0], "R": np.eye(3), "t": [0, 0, 1.2]}

# Wrong values of each kind of argument.
WRONG = {
    "number": ["1.2", True, np.bool_(False), [1.0], 1j, object()],
    "optional_number": ["1.2", True, [1.0], 1j],
    "integer": [2.0, True, "3", None, [2]],
    "seed": [2.0, True, "3", None, -1],
    "flag": [1, "yes", None, 0.0],
    "text": [5, True, b"dopri5", ["k"], None],
    "optional_text": [5, True, b"dopri5", ["k"]],
    "scene": [5, True, 1.0, ["scene.yaml"], b"scene.yaml"],
    "path": [5, True, None, ["scene.yaml"]],
    "texts": ["feedback", 5, [1], ("feedback", None)],
    "optional_dict": [[1], "drop", 5],
    "array": [[[0, 0], [0, 0]], "frame", 5, None],
    "images": [5, "images", [np.zeros((4, 4), np.uint8), [[0]]]],
    "corners": [5, "corners"],
    "size": [5, (640,), "640x480", (640.5, 480), (True, 480)],
    "points": ["points", 5, None, [["0", "0", "0"]]],
    "camera": [5, "camera", None, [1]],
    # A controller or estimator: a name, or an object with the methods (none of these has them).
    "controller": [5, True, b"paper", ["k"], object()],
    "estimator": [5, True, b"ekf", ["k"], object()],
    "optional_callable": [5, "reward", True],
    "optional_seed": [2.0, True, "3", -1],
    "dict": [[1], "info", 5, None],
    "action": ["1.2", True, None, [1.0, 2.0], float("nan"), {"a": 1}],
    "render_mode": [5, "human", True],
    "recordings": [5, "run.csv", None, [5], [{"t": [0.0]}, "run.csv"]],
    "recording": [5, "run.csv", None, [1]],
    "optional_recording": [[1], "run.csv", 5],
}

INTEGRATOR = {"method": "optional_text", "rtol": "optional_number", "atol": "optional_number",
              "step": "optional_number", "energy_tolerance": "optional_number",
              "formulation": "optional_text"}


def renderer():
    return flatland.Renderer(CAMERA)


def tracker():
    return flatland.Tracker()


def env():
    e = flatland.Env(observation="state")
    e.reset()
    return e


# name: (the callable, with the instance made first for a method; valid arguments besides the
# one under test; the kind of each parameter).
PUBLIC = {
    "load": (lambda: flatland.load, {}, {"path": "scene"}),
    "solve": (lambda: flatland.solve, {}, {
        "period": "optional_number", "scene": "scene", "k": "optional_number",
        "solve_for": "text", "tolerance": "number", **INTEGRATOR}),
    "simulate": (lambda: flatland.simulate, {}, {
        "scene": "scene", "period": "optional_number", "k": "optional_number",
        "duration": "optional_number", "mu": "optional_number", "model": "optional_text",
        "stop_on_contact_loss": "flag", "sample_dt": "optional_number", **INTEGRATOR}),
    "time_optimal": (lambda: flatland.time_optimal, {}, {
        "scene": "scene", "mu": "optional_number", "from_": "number", "to": "number",
        "period_tolerance": "number", "tolerance": "number", **INTEGRATOR}),
    "design": (lambda: flatland.design, {}, {
        "scene": "scene", "objective": "text", "period": "optional_number",
        "mu": "optional_number", "motion_only": "flag",
        "shape_range": "number", "fn_margin": "number", "max_evaluations": "integer",
        "tolerance": "number", **INTEGRATOR}),
    "locus": (lambda: flatland.locus, {}, {
        "scene": "scene", "from_": "number", "to": "number", "n": "integer",
        "mu": "optional_number", "tolerance": "number", **INTEGRATOR}),
    "surface": (lambda: flatland.surface, {}, {
        "scene": "scene", "k_from": "number", "k_to": "number", "nk": "integer",
        "period_from": "number", "period_to": "number", "np": "integer", "threads": "integer",
        **INTEGRATOR}),
    "Renderer": (lambda: flatland.Renderer, {"model": CAMERA}, {
        "model": "scene", "backend": "optional_text", "duration": "optional_number"}),
    "Renderer.render/t": (lambda: renderer().render, {}, {"t": "optional_number"}),
    "Renderer.render/state": (lambda: renderer().render, {}, {"state": "optional_dict"}),
    "Renderer.render/mask": (lambda: renderer().render, {"t": 0.0}, {"mask": "flag"}),
    "Tracker": (lambda: flatland.Tracker, {}, {"model": "scene", "method": "optional_text"}),
    "Tracker.track": (lambda: tracker().track, {"frame": np.zeros((8, 8), np.uint8)},
                      {"frame": "array", "theta": "optional_number"}),
    "calibrate": (lambda: flatland.calibrate, {"board": "chessboard:9x6:0.02"}, {
        "board": "text", "images": "images", "corners": "corners", "image_size": "size",
        "fix": "text", "rational": "flag"}),
    "render_calibration": (lambda: flatland.render_calibration, {}, {
        "model": "scene", "intrinsics_views": "integer", "table_views": "integer",
        "joint_views": "integer", "seed": "seed", "board": "text"}),
    "experiment": (lambda: flatland.experiment, {}, {
        "model": "scene", "controller": "controller", "estimator": "estimator"}),
    "Env": (lambda: flatland.Env, {}, {
        "model": "scene", "observation": "text", "ticks_per_step": "integer",
        "reward": "optional_callable", "duration": "optional_number",
        "time_limit": "optional_number", "estimator": "estimator", "render_mode": "render_mode"}),
    "Env.reset": (lambda: flatland.Env(observation="state").reset, {},
                  {"seed": "optional_seed", "options": "optional_dict"}),
    "Env.step": (lambda: env().step, {}, {"action": "action"}),
    "success_reward": (lambda: flatland.success_reward, {}, {"info": "dict"}),
    "montecarlo": (lambda: flatland.montecarlo, {}, {
        "model": "scene", "runs": "integer", "seed": "seed", "controllers": "texts",
        "threads": "integer", "perturbations": "optional_dict"}),
    "study": (lambda: flatland.study, {"name": "sim"}, {
        "name": "text", "scene": "scene", "quick": "flag"}),
    "read_camera_file": (lambda: flatland.read_camera_file, {}, {"path": "path"}),
    "write_camera_file": (lambda: flatland.write_camera_file, {
        "path": "/nonexistent-dir/camera.yaml", "camera": A_CAMERA}, {
        "path": "path", "camera": "camera", "camera_name": "text", "table_pose": "flag",
        "joint": "optional_dict", "unsupported": "texts", "force": "flag"}),
    "identify": (lambda: flatland.identify, {"scene": AIRTABLE, "recordings": A_RECORDING, "unknowns": ["drag"]}, {
        "scene": "scene", "recordings": "recordings", "unknowns": "texts", "segment": "number",
        "bounds": "optional_dict", "initial": "optional_dict", "max_iterations": "integer",
        "threads": "integer", "validate": "optional_recording"}),
    "validate_world": (lambda: flatland.validate_world, {"scene": AIRTABLE, "recording": A_RECORDING}, {
        "scene": "scene", "recording": "recording", "angle_offset": "number",
        "time_offset": "number"}),
    "project": (lambda: flatland.project,
                {"camera": A_CAMERA, "points": np.zeros((1, 3))},
                {"camera": "camera", "points": "points"}),
}

# Public callables whose parameters the table lists; methods by "Class.method".
CALLABLES = {
    "load": flatland.load, "solve": flatland.solve, "simulate": flatland.simulate,
    "time_optimal": flatland.time_optimal, "locus": flatland.locus, "surface": flatland.surface,
    "design": flatland.design, "Renderer": flatland.Renderer.__init__, "Renderer.render": flatland.Renderer.render,
    "Tracker": flatland.Tracker.__init__, "Tracker.track": flatland.Tracker.track,
    "calibrate": flatland.calibrate, "render_calibration": flatland.render_calibration,
    "experiment": flatland.experiment, "montecarlo": flatland.montecarlo,
    "Env": flatland.Env.__init__, "Env.reset": flatland.Env.reset, "Env.step": flatland.Env.step,
    "success_reward": flatland.success_reward,
    "study": flatland.study, "read_camera_file": flatland.read_camera_file,
    "write_camera_file": flatland.write_camera_file, "project": flatland.project,
    "default_scene_path": flatland.default_scene_path,
    "identify": flatland.identify, "validate_world": flatland.validate_world,
}


def test_the_table_lists_every_public_function_and_parameter():
    # Left out: the result classes; Box, a description that Env makes; the native module's small
    # classes of the loop (ControlOutput, Estimate, ...: their constructors' checks are in
    # test_controllers.py).
    native = {name for name in flatland.__all__
              if getattr(getattr(flatland, name), "__module__", "") == "flatland._flatland"}
    functions = {name for name in flatland.__all__
                 if callable(getattr(flatland, name)) and name not in native
                 and not (inspect.isclass(getattr(flatland, name))
                          and name in ("Simulation", "Experiment", "Box"))}
    assert functions <= {name.split(".")[0] for name in CALLABLES}, functions
    for name, fn in CALLABLES.items():
        params = [p for p in inspect.signature(fn).parameters if p != "self"]
        listed = set()
        for key, (_, _, kinds) in PUBLIC.items():
            if key.split("/")[0] == name:
                listed |= set(kinds)
        assert listed == set(params), (name, set(params) ^ listed)


CASES = [(name, param, i)
         for name, (_, _, kinds) in PUBLIC.items()
         for param, kind in kinds.items()
         for i in range(len(WRONG[kind]))]


@pytest.mark.parametrize("name, param, i", CASES,
                         ids=[f"{n}-{p}-{i}" for n, p, i in CASES])
def test_a_wrong_type_is_a_value_error_naming_the_argument(name, param, i, tmp_path):
    make, valid, kinds = PUBLIC[name]
    value = WRONG[kinds[param]][i]
    fn = make()
    kwargs = dict(valid)
    kwargs[param] = value
    if name == "write_camera_file":
        kwargs.setdefault("path", tmp_path / "camera.yaml")
        if param != "path":
            kwargs["path"] = tmp_path / "camera.yaml"
    with pytest.raises(ValueError) as e:
        fn(**kwargs)
    message = str(e.value)
    assert "\n" not in message
    assert message.startswith(param), (param, message)
    if name == "write_camera_file":
        assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("call", [
    lambda: flatland.solve(period=True),
    lambda: flatland.simulate(duration=False),
    lambda: flatland.locus(n=True),
    lambda: flatland.surface(threads=True),
])
def test_a_bool_is_not_a_number(call):
    with pytest.raises(ValueError, match=r"^\w+: (a number|an integer), got a bool$"):
        call()


def test_numpy_scalars_are_numbers():
    got = flatland.solve(period=np.float64(1.181))
    assert got == flatland.solve(period=1.181)
    assert len(flatland.locus(n=np.int64(2), from_=np.float32(1.1), to=1.3)["k"]) == 2
