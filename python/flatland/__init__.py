"""flatland: the butterfly's rolling dynamics, camera and closed loop, from Python.

The package binds flatland's C++ library (the same code as the ``flatland`` command line):

* ``load(path)`` compiles a scene into a :class:`Model`;
* ``solve``, ``simulate``, ``time_optimal``, ``locus``, ``surface`` and ``design`` run the
  simulator (paper sections 3-4; docs/DESIGN.md) and return what ``flatland COMMAND --json``
  prints, with trajectories as numpy arrays;
* :class:`Renderer` renders camera frames (H x W x 3 ``uint8`` BGR, OpenCV's convention) with
  their ground truth; :class:`Tracker` finds the disk in a frame; ``calibrate`` calibrates a
  camera from board images or corners;
* ``experiment`` and ``montecarlo`` run the vision-feedback closed loop (paper section 5);
  ``experiment`` takes your own controller and estimator (any object with their methods);
* :class:`Env` is the closed loop one control tick at a time, in Gymnasium's convention
  (``reset``, ``step``, spaces, ``render``), for agents that choose the hand's acceleration.

Units are SI (m, s, rad, N); forces are also given as ratios to the in-plane weight
m g sin(tilt). Bad input raises ``ValueError`` with the CLI's one-line message (naming the
keyword argument instead of the option); a numerical or runtime failure raises
``RuntimeError``. Long calls release the GIL, and Ctrl-C interrupts them (KeyboardInterrupt).
docs/PYTHON.md has examples.
"""

from __future__ import annotations

import os as _os
from dataclasses import dataclass
from pathlib import Path as _Path
from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np

# The bundled scenes, unless FLATLAND_DATA_DIR says otherwise: flatland/data in an installed
# package (pip install ., python/backend), build/share/flatland beside build/python in the
# build tree.
_here = _Path(__file__).resolve().parent
for _candidate in (_here / "data", _here.parent.parent / "share" / "flatland"):
    if "FLATLAND_DATA_DIR" not in _os.environ and (_candidate / "scenes" / "butterfly.yaml").is_file():
        _os.environ["FLATLAND_DATA_DIR"] = str(_candidate)

import math as _math  # noqa: E402

from . import _flatland  # noqa: E402
from ._flatland import (ControlInput, ControllerContext, ControlOutput, Estimate,  # noqa: E402
                        EstimatorCounts, HandInput, JointReading, Measurement, Model, Plan,
                        UpdateReport)

__all__ = [
    "Model", "load", "default_scene_path", "solve", "simulate", "Simulation", "time_optimal",
    "design", "locus", "surface", "Renderer", "Tracker", "calibrate", "render_calibration", "experiment",
    "Experiment", "montecarlo", "study", "identify", "validate_world", "read_camera_file", "write_camera_file", "project",
    "Env", "Box", "success_reward", "Plan", "ControllerContext", "ControlInput", "ControlOutput", "JointReading",
    "Measurement", "Estimate", "HandInput", "UpdateReport", "EstimatorCounts",
]

SceneLike = Union[Model, str, "_os.PathLike[str]", None]


# Arguments are checked here, before the native module sees them, so that a wrong type is a
# one-line ValueError naming the keyword (pybind11 would raise a TypeError listing every overload)
# and a bool is not taken for a number (True would be a 1 s period). Values are checked by the
# library, with the CLI's messages.

def _type_name(value: Any) -> str:
    return type(value).__name__


def _is_bool(value: Any) -> bool:
    return isinstance(value, (bool, np.bool_))


def _number(name: str, value: Any, optional: bool = False) -> Optional[float]:
    """A real number (int, float or a numpy scalar; not a bool) as float, or None if optional."""
    if value is None and optional:
        return None
    if _is_bool(value) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name}: a number, got a {_type_name(value)}")
    return float(value)


def _integer(name: str, value: Any, low: int = -2**31, high: int = 2**31 - 1) -> int:
    """An integer (not a bool, not a float) within what the library's type holds."""
    if _is_bool(value) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: an integer, got a {_type_name(value)}")
    if not low <= int(value) <= high:
        raise ValueError(f"{name}: must be in [{low}, {high}], got {int(value)}")
    return int(value)


def _flag(name: str, value: Any) -> bool:
    if not _is_bool(value):
        raise ValueError(f"{name}: True or False, got a {_type_name(value)}")
    return bool(value)


def _text(name: str, value: Any, optional: bool = False) -> Optional[str]:
    if value is None and optional:
        return None
    if not isinstance(value, str):
        raise ValueError(f"{name}: a str, got a {_type_name(value)}")
    return value


def _scene(name: str, value: Any) -> Any:
    """A Model, a path (str or os.PathLike) or None."""
    if value is None or isinstance(value, (Model, str, _os.PathLike)):
        return value
    raise ValueError(f"{name}: a Model, a path or None, got a {_type_name(value)}")


def _path(name: str, value: Any) -> str:
    if isinstance(value, (str, _os.PathLike)):
        path = _os.fspath(value)
        if isinstance(path, str):
            return path
    raise ValueError(f"{name}: a path (str or os.PathLike), got a {_type_name(value)}")


def _mapping(name: str, value: Any, optional: bool = False) -> Optional[Dict[Any, Any]]:
    if value is None and optional:
        return None
    if not isinstance(value, dict):
        raise ValueError(f"{name}: a dict, got a {_type_name(value)}")
    return value


def _texts(name: str, value: Any) -> list:
    """A list or tuple of str (a str alone is not a list of words)."""
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"{name}: a list of str, got a {_type_name(value)}")
    for i, item in enumerate(value):
        _text(f"{name}[{i}]", item)
    return list(value)


def _array(name: str, value: Any) -> np.ndarray:
    if not isinstance(value, np.ndarray):
        raise ValueError(f"{name}: a numpy array, got a {_type_name(value)}")
    return value


def _integrator(method: Any, rtol: Any, atol: Any, step: Any, energy_tolerance: Any,
                formulation: Any) -> tuple:
    """The integrator keywords every simulator call has, checked."""
    return (_text("method", method, True), _number("rtol", rtol, True),
            _number("atol", atol, True), _number("step", step, True),
            _number("energy_tolerance", energy_tolerance, True),
            _text("formulation", formulation, True))


def load(path: Union[str, "_os.PathLike[str]", None] = None) -> Model:
    """Compile the scene file at ``path`` (YAML, docs/SCENE.md) into an immutable Model.

    ``None`` loads the bundled paper scene (``default_scene_path()``). A bad file raises
    ValueError naming the file, the field and the reason, as the CLI prints it.
    """
    return _flatland.load(_scene("path", path))


def default_scene_path() -> str:
    """The bundled paper butterfly scene (scenes/butterfly.yaml in the data directory)."""
    return _flatland.default_scene_path()


def solve(period: Optional[float] = None, scene: SceneLike = None, *, k: Optional[float] = None,
          solve_for: str = "k", tolerance: float = 1e-9, method: Optional[str] = None,
          rtol: Optional[float] = None, atol: Optional[float] = None,
          step: Optional[float] = None, energy_tolerance: Optional[float] = None,
          formulation: Optional[str] = None) -> Dict[str, Any]:
    """The butterfly solution for one duration 2T = ``period`` s (paper section 4.3).

    Finds the dip k (or, with ``solve_for="d"``, the hand's cubic coefficient d) that brings
    the disk to the fingertip at t = T. Returns the keys of ``flatland solve --json``: period,
    k, s_T, s_end, sdot_end, fn_apex_ratio, fn_min_ratio, mu_required, friction_margin,
    contact_lost, simulations, rhs_evals (and d). Forces are ratios to m g sin(tilt); a value
    that is not finite is None.

    ``scene``: a Model, a scene file, or None (the bundled paper scene). ``period``/``k``
    default to the scene's motion; ``method`` (dopri5, dop853, rk4), ``rtol``, ``atol``,
    ``step`` (rk4, s) and ``formulation`` (auto, general, reduced) override its simulator.
    """
    return _flatland.solve(_number("period", period, True), _scene("scene", scene),
                           _number("k", k, True), _text("solve_for", solve_for),
                           _number("tolerance", tolerance),
                           *_integrator(method, rtol, atol, step, energy_tolerance, formulation))


@dataclass(frozen=True)
class Simulation:
    """One run: ``report`` has the keys of ``flatland simulate --json``; ``trajectory`` one
    numpy array per column of the trajectory CSV (t, theta, s_h, x, y, f_n, fn_ratio, mode, ...;
    docs/CLI.md#trajectory-csv)."""

    report: Dict[str, Any]
    trajectory: Dict[str, np.ndarray]

    def __getitem__(self, key: str) -> Any:
        return self.report[key]


def simulate(scene: SceneLike = None, *, period: Optional[float] = None,
             k: Optional[float] = None, duration: Optional[float] = None,
             mu: Optional[float] = None, model: Optional[str] = None,
             stop_on_contact_loss: bool = True, sample_dt: Optional[float] = None,
             method: Optional[str] = None, rtol: Optional[float] = None,
             atol: Optional[float] = None, step: Optional[float] = None,
             energy_tolerance: Optional[float] = None,
             formulation: Optional[str] = None) -> Simulation:
    """One run of the scene, with the overrides ``flatland simulate`` has.

    ``period`` (2T, s; also the duration unless ``duration`` is given) and ``k`` change the
    butterfly; ``mu`` the friction coefficient; ``model`` is "rolling" (the paper's: it stops
    where contact is lost or the disk would slip) or "hybrid" (it slides, flies and is caught).
    The trajectory has one row per integrator step, or one every ``sample_dt`` s from the dense
    output.

    A spatial scene (``space: 3d``, given as its path) runs too, as ``flatland simulate`` runs it:
    the report of its ``--json`` and the columns of its CSV (docs/CLI.md#flatland-simulate), with
    the rolling model only (``model`` "rolling" or None).
    """
    report, trajectory = _flatland.simulate(
        _scene("scene", scene), _number("period", period, True), _number("k", k, True),
        _number("duration", duration, True), _number("mu", mu, True),
        _text("model", model, True), _flag("stop_on_contact_loss", stop_on_contact_loss),
        _number("sample_dt", sample_dt, True),
        *_integrator(method, rtol, atol, step, energy_tolerance, formulation))
    if isinstance(trajectory, str):  # a spatial scene's run: its CSV's text
        trajectory = _csv_columns(trajectory)
    return Simulation(report, trajectory)


def time_optimal(scene: SceneLike = None, *, mu: Optional[float] = None, from_: float = 0.9,
                 to: float = 1.5, period_tolerance: float = 1e-7, tolerance: float = 1e-9,
                 method: Optional[str] = None, rtol: Optional[float] = None,
                 atol: Optional[float] = None, step: Optional[float] = None,
                 energy_tolerance: Optional[float] = None,
                 formulation: Optional[str] = None) -> Dict[str, Any]:
    """The fastest butterfly in 2T in [from_, to] s that keeps contact (and, with ``mu``, does
    not slip). The keys of ``flatland time-optimal --json`` (period, k, limit, solution, ...)."""
    return _flatland.time_optimal(
        _scene("scene", scene), _number("mu", mu, True), _number("from_", from_),
        _number("to", to), _number("period_tolerance", period_tolerance),
        _number("tolerance", tolerance),
        *_integrator(method, rtol, atol, step, energy_tolerance, formulation))


def design(scene: SceneLike = None, *, objective: str = "least-friction",
           period: Optional[float] = None, mu: Optional[float] = None,
           motion_only: bool = False, shape_range: float = 0.25,
           fn_margin: float = 0.05, max_evaluations: int = 100, tolerance: float = 1e-7,
           method: Optional[str] = None, rtol: Optional[float] = None,
           atol: Optional[float] = None, step: Optional[float] = None,
           energy_tolerance: Optional[float] = None,
           formulation: Optional[str] = None) -> Dict[str, Any]:
    """The hand's shape (a, b, c, d) and the butterfly's k designed together at the period 2T
    (docs/DESIGN.md): ``objective`` "least-friction" (the least mu it needs) or "robustness" (the
    largest margin of mu f_n - |f_t| and f_n at ``mu``, default the scene's contact.mu);
    ``motion_only`` holds the scene's hand. The keys of ``flatland design --json``: start, best,
    active (what binds), stop, iterates, ..."""
    return _flatland.design(
        _scene("scene", scene), _text("objective", objective), _number("period", period, True),
        _number("mu", mu, True),
        _flag("motion_only", motion_only), _number("shape_range", shape_range),
        _number("fn_margin", fn_margin),
        _integer("max_evaluations", max_evaluations, 1, 100000), _number("tolerance", tolerance),
        *_integrator(method, rtol, atol, step, energy_tolerance, formulation))


def locus(scene: SceneLike = None, *, from_: float = 1.1, to: float = 3.0, n: int = 20,
          mu: Optional[float] = None, tolerance: float = 1e-9, method: Optional[str] = None,
          rtol: Optional[float] = None, atol: Optional[float] = None,
          step: Optional[float] = None, energy_tolerance: Optional[float] = None,
          formulation: Optional[str] = None) -> Dict[str, Any]:
    """The butterfly solutions k(2T) at ``n`` durations evenly spaced over [from_, to] s (paper
    Fig. 7). ``points`` and ``mu`` as ``flatland locus --json``; also one numpy array per field
    (period, k, fn_min_ratio, fn_apex_ratio, mu_required, friction_margin)."""
    return _flatland.locus(_scene("scene", scene), _number("from_", from_), _number("to", to),
                           _integer("n", n), _number("mu", mu, True),
                           _number("tolerance", tolerance),
                           *_integrator(method, rtol, atol, step, energy_tolerance, formulation))


def surface(scene: SceneLike = None, *, k_from: float = -1.6, k_to: float = -0.8, nk: int = 50,
            period_from: float = 0.8, period_to: float = 2.0, np: int = 50, threads: int = 0,
            method: Optional[str] = None, rtol: Optional[float] = None,
            atol: Optional[float] = None, step: Optional[float] = None,
            energy_tolerance: Optional[float] = None,
            formulation: Optional[str] = None) -> Dict[str, Any]:
    """s_h(T) on a k x 2T grid (paper Fig. 6): ``k`` (nk), ``period`` (np) and ``s_T``
    (nk x np) as numpy arrays; its zero level is the locus. ``threads``: 0 uses every core."""
    return _flatland.surface(_scene("scene", scene), _number("k_from", k_from),
                             _number("k_to", k_to), _integer("nk", nk),
                             _number("period_from", period_from),
                             _number("period_to", period_to), _integer("np", np),
                             _integer("threads", threads),
                             *_integrator(method, rtol, atol, step, energy_tolerance, formulation))


class Renderer:
    """Synthetic camera frames of a scene with a camera (headless OpenGL: OSMesa or EGL).

    ``render(t=...)`` captures the frame at time t of the scene's run (simulated once, at the
    first call) through the scene's effects (exposure blur, noise, jitter, dropped frames);
    frames taken in order match ``flatland render``'s. ``render(state=...)`` draws one
    instant without effects. Images are H x W x 3 ``uint8`` BGR (OpenCV's order), or float32
    when the scene's effects do not quantise; the truth is a dict (t, theta, s_h, disk centre
    and marker in the table frame and in pixels, dropped).

    A spatial scene (``space: 3d``, given as its path) is run at its camera's rate at the first
    ``render(t=k / fps)`` and drawn as ``flatland render`` draws it (supersampling and the lens);
    its truth's disk_center_table and disk_center_px are the object's centre.
    """

    def __init__(self, model: SceneLike = None, backend: Optional[str] = None,
                 duration: Optional[float] = None):
        """``model``: a Model or scene (planar or spatial) with a camera section; ``backend``:
        osmesa or egl (default: the scene's render.backend); ``duration``: the run's length, s
        (default: the scene's)."""
        self._native = _flatland.Renderer(_scene("model", model), _text("backend", backend, True),
                                          _number("duration", duration, True))

    def render(self, t: Optional[float] = None, state: Optional[Dict[str, Any]] = None,
               mask: bool = False) -> Tuple[Optional[np.ndarray], Dict[str, Any]]:
        """(image, truth) at time ``t`` s of the run, or of ``state``, a dict with hand_angle
        (rad), disk_center ((x, y), m, table frame), disk_angle (rad) and optionally t. A
        dropped frame's image is None. truth["t_state"] is when its positions hold (the disk
        row's time under a rolling shutter). With ``mask``, truth["mask"] is the segmentation
        mask, H x W uint8: 0 background, 1 table, 2 hand, 3 disk, 4 + i board i (planar
        scenes)."""
        if (t is None) == (state is None):
            raise ValueError("render: give exactly one of t and state")
        with_mask = _flag("mask", mask)
        if t is not None:
            return self._native.render_at(_number("t", t), with_mask)
        _mapping("state", state)
        unknown = set(state) - {"hand_angle", "disk_center", "disk_angle", "t"}
        if unknown:
            raise ValueError(f"state: unknown keys {sorted(unknown, key=str)} (hand_angle, "
                             "disk_center, disk_angle, t)")
        center = state.get("disk_center", (0.0, 0.0))
        if not isinstance(center, (tuple, list, np.ndarray)) or len(center) != 2:
            raise ValueError("state.disk_center: a pair (x, y) in m, got a "
                             f"{_type_name(center)}")
        return self._native.render_state(
            _number("state.hand_angle", state.get("hand_angle", 0.0)),
            (_number("state.disk_center[0]", center[0]),
             _number("state.disk_center[1]", center[1])),
            _number("state.disk_angle", state.get("disk_angle", 0.0)),
            _number("state.t", state.get("t", 0.0)), with_mask)

    @property
    def camera(self) -> Dict[str, Any]:
        """The camera: width, height, fps, exposure, K, dist, R, t (x_cam = R x_table + t)."""
        return self._native.camera

    @property
    def t_end(self) -> float:
        """The end of the run, s: the scene's (or ``duration``'s), or where the run stopped."""
        return self._native.t_end

    @property
    def gl(self) -> str:
        """The OpenGL implementation in use."""
        return self._native.gl


class Tracker:
    """The disk tracker of ``flatland track``: the disk's centre in each frame (sub-pixel,
    OpenCV's pixel convention), its uncertainty and quality, and, given the hand angle and a
    scene's camera, the contact parameter s_h.

    ``model``: a Model (or scene) whose camera and hand the tracker knows; None: a plain image
    tracker. ``method``: edge (default), moments, hough or contour. Frames are H x W or H x W x 3 (BGR),
    uint8 or float32 numpy arrays; track them in order (the tracker predicts from the last).
    """

    def __init__(self, model: SceneLike = None, method: Optional[str] = None):
        self._native = _flatland.Tracker(_scene("model", model), _text("method", method, True))

    def track(self, frame: np.ndarray, theta: Optional[float] = None) -> Dict[str, Any]:
        """state (found, tracking, lost), center (u, v) px or None, radius_px, sigma_px,
        quality, edge_points, and s_h (with ``theta``, the hand angle in rad, and a model)."""
        return self._native.track(_array("frame", frame), _number("theta", theta, True))

    def reset(self) -> None:
        """Forget the track: the next frame is searched whole."""
        self._native.reset()


def calibrate(board: str, images: Optional[Sequence[np.ndarray]] = None, *,
              corners: Optional[Sequence[Tuple[np.ndarray, np.ndarray]]] = None,
              image_size: Optional[Tuple[int, int]] = None, fix: str = "",
              rational: bool = False) -> Dict[str, Any]:
    """Camera intrinsics from views of a board, as ``flatland calibrate --images`` finds them.

    ``board``: "chessboard:COLSxROWS:SQUARE_M" (inner corners, OpenCV's patternSize) or
    "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT]". Give ``images`` (uint8 arrays), or ``corners``:
    one (image_points (N, 2) px, object_points (N, 3) m) pair per view, with ``image_size``
    (width, height). ``fix``: "k3,tangential,aspect,principal-point" (any); ``rational``:
    OpenCV's rational model. Returns camera (K, dist, ...), rms_px, view_rms_px, views_used,
    rejected, not_found and std (of fx fy cx cy k1 k2 p1 p2 k3).
    """
    if images is not None:
        if not isinstance(images, (list, tuple)):
            raise ValueError(f"images: a list of image arrays, got a {_type_name(images)}")
        images = [_array(f"images[{i}]", image) for i, image in enumerate(images)]
    if corners is not None:
        if not isinstance(corners, (list, tuple)):
            raise ValueError("corners: a list of (image_points, object_points) pairs, got a "
                             f"{_type_name(corners)}")
        corners = list(corners)
    if image_size is not None:
        if not isinstance(image_size, (tuple, list)) or len(image_size) != 2:
            raise ValueError(f"image_size: a pair (width, height) in px, got a "
                             f"{_type_name(image_size)}")
        image_size = (_integer("image_size[0]", image_size[0]),
                      _integer("image_size[1]", image_size[1]))
    return _flatland.calibrate(_text("board", board), images, corners, image_size,
                               _text("fix", fix), _flag("rational", rational))


def render_calibration(model: SceneLike = None, *, intrinsics_views: int = 16,
                       table_views: int = 4, joint_views: int = 8, seed: int = 1,
                       board: str = "") -> Dict[str, Any]:
    """A rendered calibration session (``flatland render-calibration``): ``images`` by path
    (intrinsics/view_00.png, table/..., joint/...), the ``board`` notation, the
    ``intrinsics_images`` paths and the true ``camera``."""
    return _flatland.render_calibration(
        _scene("model", model), _integer("intrinsics_views", intrinsics_views),
        _integer("table_views", table_views), _integer("joint_views", joint_views),
        _integer("seed", seed, 0, 2**64 - 1), _text("board", board))


def _matrix(name: str, value: Any, shape: Tuple[int, ...]) -> np.ndarray:
    """A finite float array of `shape` (lists, tuples and arrays of numbers; no bools)."""
    try:
        array = np.asarray(value)
    except Exception:  # ragged nesting and the like
        array = np.asarray([])
    if array.dtype.kind not in "iuf" or array.shape != shape:
        raise ValueError(f"{name}: {' x '.join(map(str, shape))} numbers, got "
                         f"{_type_name(value) if array.dtype.kind not in 'iuf' else array.shape}")
    array = array.astype(float)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: every value must be finite")
    return array


def _camera(name: str, camera: Any, pose: bool) -> Dict[str, Any]:
    """A camera dict (width, height, K, dist; R and t when `pose`; fps, exposure optional), as
    Renderer.camera, calibrate()["camera"] and read_camera_file()["camera"] give it, checked as
    the camera file reader checks a file (camera/src/camera_file.cpp)."""
    if not isinstance(camera, dict):
        raise ValueError(f"{name}: a dict (width, height, K, dist, R, t), got a "
                         f"{_type_name(camera)}")
    for key in ("width", "height", "K", "dist") + (("R", "t") if pose else ()):
        if key not in camera:
            raise ValueError(f"{name}.{key}: missing")
    width = _integer(f"{name}.width", camera["width"], 1, 16384)
    height = _integer(f"{name}.height", camera["height"], 1, 16384)
    K = _matrix(f"{name}.K", camera["K"], (3, 3))
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise ValueError(f"{name}.K: fx and fy must be positive")
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise ValueError(f"{name}.K: must be upper triangular with a 1 in the corner")
    dist = np.asarray(camera["dist"]) if isinstance(camera["dist"], (list, tuple, np.ndarray)) \
        else None
    if dist is None or dist.shape not in ((5,), (8,)):
        raise ValueError(f"{name}.dist: 5 (plumb_bob) or 8 (rational_polynomial) numbers")
    dist = _matrix(f"{name}.dist", dist, dist.shape)
    out = {"width": width, "height": height, "K": K, "dist": dist, "R": None, "t": None,
           "fps": _number(f"{name}.fps", camera.get("fps", 30.0)),
           "exposure": _number(f"{name}.exposure", camera.get("exposure", 0.0))}
    if not (out["fps"] > 0 and np.isfinite(out["fps"])):
        raise ValueError(f"{name}.fps: must be positive and finite")
    if not (out["exposure"] >= 0 and np.isfinite(out["exposure"])):
        raise ValueError(f"{name}.exposure: must be finite and not negative")
    if pose:
        R = _matrix(f"{name}.R", camera["R"], (3, 3))
        if not (np.allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-9) and np.linalg.det(R) > 0):
            raise ValueError(f"{name}.R: must be a rotation (orthonormal, determinant 1)")
        out["R"], out["t"] = R, _matrix(f"{name}.t", camera["t"], (3,))
    return out


def read_camera_file(path: Union[str, "_os.PathLike[str]"]) -> Dict[str, Any]:
    """A camera file (ROS camera_info YAML with flatland's extras; docs/CALIBRATION.md), as
    ``flatland calibrate`` and ``flatland render`` write it and ``flatland track --camera``
    read it: camera_name, camera (width, height, fps, exposure, K, dist, R, t), rational_model,
    table_pose (whether R, t are the table's pose), joint (axis_table (x, y) m, encoder_offset rad)
    or None, the calibrations' reports (report, table_report, joint_report) or None, and
    unsupported: the sections ``calibrate --force`` wrote although their data could not support
    them ("joint: why", docs/CALIBRATION.md; empty when none). A bad file raises ValueError naming
    the file and the field."""
    return _flatland.read_camera_file(_path("path", path))


def write_camera_file(path: Union[str, "_os.PathLike[str]"], camera: Dict[str, Any], *,
                      camera_name: str = "flatland", table_pose: bool = False,
                      joint: Optional[Dict[str, Any]] = None,
                      unsupported: Sequence[str] = (), force: bool = False) -> None:
    """Write ``camera`` (a dict as ``read_camera_file()["camera"]``, ``Renderer.camera`` or
    ``calibrate()["camera"]`` gives it) as a camera file the CLI reads. ``table_pose``: write its
    R and t as the table's pose; ``joint``: {"axis_table": (x, y) m, "encoder_offset": rad};
    ``unsupported``: the marks of sections written against their data ("joint: why", as
    ``read_camera_file()["unsupported"]`` lists them), kept so that a file read and written back
    still says so. The file is written whole or not at all; an existing one only with
    ``force``."""
    path = _path("path", path)
    marks = _texts("unsupported", unsupported)
    name = _text("camera_name", camera_name)
    pose = _flag("table_pose", table_pose)
    joint = _mapping("joint", joint, True)
    overwrite = _flag("force", force)
    checked = _camera("camera", camera, pose)
    joint_values = None
    if joint is not None:
        if set(joint) != {"axis_table", "encoder_offset"}:
            raise ValueError("joint: the keys axis_table and encoder_offset")
        axis = _matrix("joint.axis_table", joint["axis_table"], (2,))
        offset = _number("joint.encoder_offset", joint["encoder_offset"])
        if not np.isfinite(offset):
            raise ValueError("joint.encoder_offset: must be finite")
        joint_values = (float(axis[0]), float(axis[1]), offset)
    _flatland.write_camera_file(path, name, checked["width"], checked["height"], checked["K"],
                                checked["dist"], checked["R"], checked["t"], checked["fps"],
                                checked["exposure"], joint_values, marks, overwrite)


def project(camera: Dict[str, Any], points: Any) -> np.ndarray:
    """Table-frame points (N x 3, m) through ``camera`` (a dict with its pose R, t: x_cam = R
    x_table + t) to pixels (N x 2, OpenCV's convention, with the lens distortion): the renderer's
    and the tracker's projection (cv::projectPoints)."""
    checked = _camera("camera", camera, True)
    if not isinstance(points, (list, tuple, np.ndarray)):
        raise ValueError(f"points: an array of shape (N, 3), got a {_type_name(points)}")
    array = np.asarray(points)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points: an array of shape (N, 3), got shape {array.shape}")
    array = _matrix("points", array, array.shape)
    return _flatland.project(checked["width"], checked["height"], checked["K"], checked["dist"],
                             checked["R"], checked["t"], array)


@dataclass(frozen=True)
class Experiment:
    """A synthetic closed-loop experiment: ``result`` has the keys of ``flatland experiment
    --json`` that a synthetic run has; ``log`` one numpy array per column of its log.csv (t,
    theta, command, stage, s_est, s_meas, s_true, mode_true, ...:
    docs/CLI.md#flatland-experiment)."""

    result: Dict[str, Any]
    log: Dict[str, np.ndarray]

    def __getitem__(self, key: str) -> Any:
        return self.result[key]


def experiment(model: SceneLike = None, *, controller: Any = None,
               estimator: Any = None) -> Experiment:
    """One synthetic experiment of the vision-feedback loop (paper section 5): the world of the
    scene (default: the bundled closed-loop air table, scenes/airtable-feedback.yaml) filmed at
    its camera's rate, the estimator and the controller at 1 kHz.

    ``controller``: None (the scene's), "feedback" or "open-loop" (the scene's controller in that
    mode), a built-in type ("paper", ...: the scene's ``controller.type``), or your own: any
    object with ``step(input) -> float | ControlOutput`` and optionally ``start(context)`` and
    ``name`` (docs/PYTHON.md, "Your own controller"). ``estimator``: None (the scene's), a
    built-in type ("ekf", ...), or any object with ``reset(t, s_h, sdot_h)``,
    ``propagate(t_next, hand)``, ``update(z)`` and ``estimate() -> Estimate`` (optionally
    ``counts()`` and ``name``). Their methods are called with light objects (ControlInput,
    HandInput, Measurement: a few floats each), with the GIL held only during the call.

    A controller that raises stops the run safely (``result["stop_reason"]`` has
    "ExceptionType: message"); one that returns NaN or something else than a number or a
    ControlOutput raises ValueError naming what and when; an estimator that raises stops the
    run safely too (``stop_reason`` starts "estimator: ").
    """
    result, log = _flatland.experiment(_scene("model", model), controller, estimator)
    return Experiment(result, log)


def montecarlo(model: SceneLike = None, *, runs: int = 20, seed: int = 1,
               controllers: Sequence[str] = ("open-loop", "feedback"), threads: int = 0,
               perturbations: Optional[Dict[str, float]] = None) -> Dict[str, Any]:
    """``runs`` experiments of each controller, each in a perturbed world (the same worlds for
    all): success counts with Wilson 95 % intervals, one record per experiment, and the
    controllers compared on those worlds: ``summaries`` (one dict per controller: successes,
    ``ci95``, ``outcomes``, ``safe_stops`` by cause, and the successes' ``duration_s``,
    ``fn_min_ratio`` and ``friction_use`` spreads) and ``pairs`` (per two controllers:
    ``both``, ``only_a``, ``only_b``, ``neither`` and the exact McNemar ``p_value``), as
    ``flatland montecarlo --json`` has them. ``controllers``: "open-loop", "feedback" or a
    controller type ("paper", ...), each once. ``perturbations`` overrides the spreads of
    ``flatland montecarlo`` (s_h, tilt_deg, radius_rel, noise_dn, latency, latency_jitter, drop,
    friction_rel, contact_rel)."""
    perturbations = _mapping("perturbations", perturbations, True)
    if perturbations is not None:
        perturbations = {_text("perturbations key", key): _number(f"perturbations.{key}", value)
                         for key, value in perturbations.items()}
    return _flatland.montecarlo(_scene("model", model), _integer("runs", runs),
                                _integer("seed", seed, 0, 2**64 - 1),
                                _texts("controllers", controllers),
                                _integer("threads", threads, 0, 2**32 - 1), perturbations)


def study(name: str, scene: SceneLike = None, *, quick: bool = False) -> Dict[str, np.ndarray]:
    """A speed-accuracy study (``flatland study NAME``, docs/ACCURACY.md): "sim" (the
    integrators' work-precision), "calibration", "render", "tracker" or "closed-loop". Returns
    the rows of the CSV file the CLI writes, one numpy array per column (numbers as float, words
    as str). ``quick``: the CLI's --quick grid (seconds to a minute instead of minutes). The
    scene defaults to the CLI study's (the paper scene, butterfly-camera.yaml for render and
    tracker, airtable-feedback.yaml for closed-loop; calibration takes none)."""
    text = _flatland.study(_text("name", name), _scene("scene", scene), _flag("quick", quick))
    return _csv_columns(text)


_RECORDING_KEYS = ("t", "theta", "s_h", "sigma", "joint_t", "joint_theta", "name")


def _recording(name: str, value: Any) -> Dict[str, Any]:
    """A recording as the native module takes it: float arrays t, s_h, sigma, joint_t,
    joint_theta and a name (docs/PYTHON.md, "Identifying the world")."""
    rec = _mapping(name, value)
    for key in rec:
        if key not in _RECORDING_KEYS:
            raise ValueError(f"{name}: unknown key {key!r} (known: {', '.join(_RECORDING_KEYS)})")

    def array(key: str) -> np.ndarray:
        if key not in rec:
            raise ValueError(f"{name}.{key}: missing")
        try:
            a = np.asarray(rec[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{name}.{key}: an array of numbers, got a {_type_name(rec[key])}") from None
        if a.ndim != 1:
            raise ValueError(f"{name}.{key}: a 1-D array, got shape {a.shape}")
        return a

    t, s_h = array("t"), array("s_h")
    if "sigma" not in rec:
        raise ValueError(f"{name}.sigma: missing (s_h's standard deviation weights the fit; "
                         "an array, or one number for every sample)")
    if np.ndim(rec["sigma"]) == 0:
        sigma = np.full(t.shape, _number(f"{name}.sigma", rec["sigma"]))
    else:
        sigma = array("sigma")
    if "joint_t" in rec or "joint_theta" in rec:
        if "theta" in rec:
            raise ValueError(f"{name}: theta or joint_t and joint_theta, not both")
        joint_t, joint_theta = array("joint_t"), array("joint_theta")
    else:
        joint_t, joint_theta = t, array("theta")
        if joint_theta.shape != t.shape:
            raise ValueError(f"{name}.theta: {joint_theta.size} values for {t.size} times")
    label = _text(f"{name}.name", rec.get("name", name))
    return {"name": label, "t": t, "s_h": s_h, "sigma": sigma, "joint_t": joint_t,
            "joint_theta": joint_theta}


def identify(scene: SceneLike, recordings: Any, unknowns: Sequence[str], *,
             segment: float = 1.0, bounds: Optional[Dict[str, Tuple[float, float]]] = None,
             initial: Optional[Dict[str, float]] = None, max_iterations: int = 200,
             threads: int = 0, validate: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """Fit the world's parameters ``unknowns`` to ``recordings`` (``flatland identify``,
    docs/IDENTIFY.md): "mu_static", "mu_kinetic", "restitution", "rolling_resistance" (m),
    "drag" (N s/m), "drag_angular" (N m s/rad), "tilt" (rad), "angle_offset" (rad),
    "time_offset" (s).

    ``scene``: the world to start from (a Model, a path or None). ``recordings``: a dict or a
    list of dicts, each with numpy arrays ``t`` (s), ``s_h`` and ``sigma`` (s_h's standard
    deviation, an array or one number) and either ``theta`` (rad, the hand angle at each t) or
    the joint's own log ``joint_t``, ``joint_theta``; optional ``name``. ``segment``: the
    shooting segments' length (s). ``bounds``: {name: (low, high)} replacing the defaults;
    ``initial``: {name: value} to start from. ``validate``: a held-out recording, simulated from
    its first state with the fitted world (and its fitted offsets). ``threads``: segments
    simulated at once (0: every core).

    Returns a dict: ``names``, ``values`` and ``sigmas`` (numpy, in ``unknowns``' order; sigma
    NaN where the data do not determine the parameter; scaled by ``sigma_scale`` =
    sqrt(chi2/dof) when chi2 exceeds ``chi2_limit``, its 99 % quantile), ``sigmas_unscaled``,
    ``determined`` (bool array), ``held`` (bool array: not determined, so held at its starting
    value while the others were fitted), ``not_determined`` ({name: why}), ``correlation``
    (K x K, NaN rows for undetermined ones), ``chi2``, ``degrees_of_freedom``, ``chi2_limit``,
    ``sigma_scale``, ``iterations``, ``converged`` (Ceres converged and the minimum lies within
    0.3 sigma: ``step_in_sigma``, the largest of ``steps_to_minimum`` / sigma, the Gauss-Newton
    step at the solution per unknown, and ``chi2_decrease_expected``; with ``termination_type`` and
    ``termination``, Ceres' own; a fit that did not converge also has a warning), ``fits`` (per recording:
    t, measured, fitted, normalised_residual), ``segments``, ``warnings``, ``scene`` (the fitted scene file's
    text, None when the scene is not a file) and ``validation`` (t, measured, predicted, error,
    normalised_error, rms_error, max_abs_error, time_to_3_sigma, stopped; None without
    ``validate``)."""
    if isinstance(recordings, dict):
        recordings = [recordings]
    if not isinstance(recordings, (list, tuple)) or not recordings:
        raise ValueError(f"recordings: a dict or a non-empty list of dicts, got a {_type_name(recordings)}")
    recs = [_recording(f"recordings[{i}]", r) for i, r in enumerate(recordings)]
    names = _texts("unknowns", unknowns)
    bounds = _mapping("bounds", bounds, True) or {}
    native_bounds = {}
    for key, pair in bounds.items():
        _text("bounds key", key)
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise ValueError(f"bounds.{key}: a pair (low, high)")
        native_bounds[key] = (_number(f"bounds.{key}[0]", pair[0]), _number(f"bounds.{key}[1]", pair[1]))
    initial = _mapping("initial", initial, True) or {}
    native_initial = {_text("initial key", key): _number(f"initial.{key}", value)
                      for key, value in initial.items()}
    held_out = None if validate is None else _recording("validate", validate)
    segment = _number("segment", segment)
    command = (f"flatland.identify(unknowns={names!r}, segment={segment!r}, "
               f"recordings={[r['name'] for r in recs]!r})")
    return _flatland.identify(_scene("scene", scene), recs, names, segment, native_bounds,
                              native_initial, _integer("max_iterations", max_iterations, 1, 10000),
                              _integer("threads", threads, 0, 1024), held_out, command)


def validate_world(scene: SceneLike, recording: Dict[str, Any], *, angle_offset: float = 0.0,
                   time_offset: float = 0.0) -> Dict[str, Any]:
    """How far the world of ``scene`` (a fitted scene, say) predicts ``recording`` (arrays as
    for :func:`identify`): simulated from its first state, the error over time (``identify
    --validate``). ``angle_offset`` (rad) and ``time_offset`` (s): the joint's offsets, as
    identify fitted them. Returns t, measured, predicted, error, normalised_error, rms_error,
    max_abs_error, time_to_3_sigma (None: never beyond 3 sigma) and stopped (why the prediction
    ended early, or None)."""
    return _flatland.validate_world(_scene("scene", scene), _recording("recording", recording),
                                    _number("angle_offset", angle_offset),
                                    _number("time_offset", time_offset))


def _csv_columns(text: str) -> Dict[str, np.ndarray]:
    """CSV text as one array per column: float where every value parses (empty: NaN), else str."""
    import csv
    import io
    rows = list(csv.reader(io.StringIO(text)))
    header, rows = rows[0], rows[1:]
    columns: Dict[str, np.ndarray] = {}
    for i, name in enumerate(header):
        values = [r[i] if i < len(r) else "" for r in rows]
        try:
            columns[name] = np.array([float(v) if v != "" else np.nan for v in values])
        except ValueError:
            columns[name] = np.array(values)
    return columns


# ---------------------------------------------------------------------------------------------
# The step-by-step environment. gymnasium is imported when flatland.Env is first used (not at
# `import flatland`): Env then subclasses gymnasium.Env and its spaces are gymnasium.spaces.Box;
# without gymnasium (Debian does not package it) Env is a plain class with flatland.Box spaces.

class Box:
    """A box of arrays as ``gymnasium.spaces.Box`` describes one, for when gymnasium is not
    importable: ``shape``, ``dtype``, ``low`` and ``high`` (arrays of ``shape``) and
    ``contains(x)``."""

    def __init__(self, low: Any, high: Any, shape: Sequence[int], dtype: Any = np.float64):
        self.dtype = np.dtype(dtype)
        self.shape = tuple(int(n) for n in shape)
        self.low = np.broadcast_to(np.asarray(low, dtype=self.dtype), self.shape).copy()
        self.high = np.broadcast_to(np.asarray(high, dtype=self.dtype), self.shape).copy()

    def contains(self, x: Any) -> bool:
        """Whether ``x`` is an array of this shape, of a dtype that casts safely to this one,
        within [low, high] (as gymnasium's Box.contains)."""
        if not isinstance(x, np.ndarray):
            try:
                x = np.asarray(x, dtype=self.dtype)
            except (ValueError, TypeError):
                return False
        return bool(np.can_cast(x.dtype, self.dtype) and x.shape == self.shape
                    and np.all(x >= self.low) and np.all(x <= self.high))

    def __contains__(self, x: Any) -> bool:
        return self.contains(x)

    def __repr__(self) -> str:
        return f"Box({self.low.min()}, {self.high.max()}, {self.shape}, {self.dtype})"


def success_reward(info: Dict[str, Any]) -> float:
    """Env's default reward: 1 at the step that ends the episode in success (the disk rests in
    the goal well, judged as ``experiment`` judges it), 0 at every other step."""
    return 1.0 if _mapping("info", info).get("success") else 0.0


def _action(value: Any, limit: float) -> float:
    """An action as the acceleration it commands: a number or an array of shape (1,) (or ()),
    finite and within [-limit, limit]."""
    wrong = f"action: a number or an array of shape (1,) (rad/s^2), got a {_type_name(value)}"
    if _is_bool(value) or isinstance(value, (str, bytes)):
        raise ValueError(wrong)
    if isinstance(value, (int, float, np.integer, np.floating)):
        a = float(value)
    else:
        try:
            array = np.asarray(value)
        except Exception:  # ragged nesting and the like
            raise ValueError(wrong) from None
        if array.dtype.kind not in "iuf":
            raise ValueError(f"{wrong} of {array.dtype}")
        if array.shape not in ((1,), ()):
            raise ValueError(f"action: shape (1,) (rad/s^2), got shape {array.shape}")
        a = float(array.reshape(-1)[0])
    if not _math.isfinite(a):
        raise ValueError(f"action: must be finite (rad/s^2), got {a}")
    if abs(a) > limit:
        raise ValueError(f"action: must be within +-{limit:g} rad/s^2 (joint.torque_limit / "
                         f"joint.inertia), got {a:g}")
    return a


_ENV_DOC = """The closed loop one control tick at a time, in Gymnasium's convention: an agent
chooses the hand's angular acceleration (rad/s^2) at each tick of the 1 kHz loop, in place of a
controller. The world is ``experiment``'s synthetic one (the hybrid contact model, the
joint's drive, the rendered camera with its noise, rate and latency, the tracker and the
scene's estimator).

``Env(model=None, *, observation="measurement", ticks_per_step=1, reward=None, duration=None,
time_limit=None, estimator=None, render_mode="rgb_array")``. ``model``: a Model or a scene
with a camera and a disk (default: the bundled closed-loop air table).

* ``reset(seed=None, options=None) -> (observation, info)``: a new world (``seed`` is the
  scene's ``effects.seed``: the camera's noise, drops and latency jitter follow it; None: the
  scene's seed at the first reset, the last seed + 1 after), the waiting phase run (t < 0: the
  hand at rest while the estimator locks on), the first observation at t = 0. ``options``: none
  are known (None or {}).
* ``step(action) -> (observation, reward, terminated, truncated, info)``: the action (a number
  or an array of shape (1,), within ``action_space``) commanded for ``ticks_per_step`` ticks.
  ``terminated`` when the loop stops safely (``info["ended_by"]``: "disk" when the world's
  failure came first, the disk out of the hand's reach; "safe-stop" when the loop's safety
  monitor stopped it: implausible innovations, the camera or tracking lost; ``info["outcome"]``
  says where the disk went) or when the motion's time is up
  (``duration``, default the plan's: "motion-end"; the hand is then held at the plan's final
  angle, as the paper's controller holds it, and the experiment judged as ``experiment`` judges
  it: ``info["success"]``, ``info["outcome"]``). ``truncated`` at ``time_limit`` s (default
  none), with no judgement. A step that reaches an end stops there (it may cover fewer ticks).
* Observations, arriving with the camera's rate and latency: "measurement" (float64, the
  entries of ``observation_names``: t, the joint's theta and theta_dot as read, the latest
  measured s_meas with its sigma_meas and capture time t_capture (s_h at the start, inf and
  -inf before the first), the estimator's s_est and sdot_est with their sigmas (inf before the
  first measurement)); "image" (the latest camera frame, H x W x 3 uint8 BGR as every flatland
  image, read-only; zeros before the first); "state" (the truth: theta, theta_dot, s_h,
  sdot_h).
* ``reward``: a callable(info) -> float, default ``flatland.success_reward`` (1 at the step
  that ends in success, else 0).
* ``info``: the truth at the observation's tick (t, s_h, sdot_h, theta, theta_dot, fn_ratio,
  mu_required, mode: the contact's), the loop's flags (estimating, measured, stopping,
  stop_reason, ended_by) and the verdict (success, outcome; at the end also failure, s_end,
  duration_s, fn_min_ratio, mu_max).
* ``render()``: the latest camera frame at the observation's tick as RGB (Gymnasium's
  rgb_array), or None before one.
* ``log()``: the episode's 1 kHz log so far, as ``experiment``'s ``log``; ``plan``: the
  planned motion (a Plan); ``close()`` frees the renderer.

Bad arguments and actions (NaN, the wrong shape, a str, beyond the joint's reach) raise
ValueError naming them; ``step`` before ``reset`` or after the end raises RuntimeError, and so
does a failure of the world's simulation (the episode is then over).
"""

_Env = None


def _define_env(base: type, box: Any) -> type:
    """Env on `base` (gymnasium.Env or object) with `box` (gymnasium.spaces.Box or Box)."""

    class Env(base):  # type: ignore[misc, valid-type]
        __doc__ = _ENV_DOC
        metadata: Dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 30.0}

        def __init__(self, model: SceneLike = None, *, observation: str = "measurement",
                     ticks_per_step: int = 1, reward: Any = None,
                     duration: Optional[float] = None, time_limit: Optional[float] = None,
                     estimator: Any = None, render_mode: Optional[str] = "rgb_array"):
            if reward is not None and not callable(reward):
                raise ValueError(f"reward: a callable(info) -> float, got a {_type_name(reward)}")
            if render_mode not in (None, "rgb_array"):
                raise ValueError(f"render_mode: rgb_array or None, got {render_mode!r}")
            if _is_bool(estimator):
                raise ValueError("estimator: a name or an object with an estimator's methods, "
                                 "got a bool")
            self._native = _flatland.Env(
                _scene("model", model), _text("observation", observation),
                _integer("ticks_per_step", ticks_per_step, 1, 1_000_000),
                _number("duration", duration, True), _number("time_limit", time_limit, True),
                estimator)
            d = self._native.description
            self.render_mode = render_mode
            self.metadata = {"render_modes": ["rgb_array"], "render_fps": d["fps"]}
            self.observation_names: Tuple[str, ...] = tuple(d["observation_names"])
            self.dt: float = d["dt"] * ticks_per_step
            self.max_acceleration: float = d["max_acceleration"]
            self.action_space = box(-self.max_acceleration, self.max_acceleration, (1,),
                                    np.float64)
            if observation == "image":
                self.observation_space = box(0, 255, d["image_shape"], np.uint8)
            else:
                low = np.full(len(self.observation_names), -np.inf)
                if observation == "measurement":  # the sigmas are not negative
                    for name in ("sigma_meas", "sigma_s_est", "sigma_sdot_est"):
                        low[self.observation_names.index(name)] = 0.0
                self.observation_space = box(low, np.full_like(low, np.inf), low.shape,
                                             np.float64)
            self._reward = reward if reward is not None else success_reward

        def reset(self, *, seed: Optional[int] = None,
                  options: Optional[Dict[str, Any]] = None) -> Tuple[Any, Dict[str, Any]]:
            if seed is not None:
                seed = _integer("seed", seed, 0, 2**64 - 1)
            options = _mapping("options", options, True)
            if options:
                raise ValueError(f"options: none are known, got {sorted(map(str, options))}")
            if base is not object:
                super().reset(seed=seed)  # gymnasium's np_random
            return self._native.reset(seed)

        def step(self, action: Any) -> Tuple[Any, float, bool, bool, Dict[str, Any]]:
            obs, terminated, truncated, info = self._native.step(
                _action(action, self.max_acceleration))
            reward = self._reward(info)
            if _is_bool(reward) or not isinstance(reward, (int, float, np.integer, np.floating)) \
                    or not _math.isfinite(reward):
                raise ValueError(f"reward: the callable returned {reward!r} at t = "
                                 f"{info['t']:.6g} s; a finite number is needed")
            return obs, float(reward), terminated, truncated, info

        def render(self) -> Optional[np.ndarray]:
            return self._native.render() if self.render_mode == "rgb_array" else None

        def log(self) -> Dict[str, np.ndarray]:
            """The episode's 1 kHz log so far: one array per column of ``experiment``'s log
            (the mode column says "waiting", "action", then "done" or "safe-stop")."""
            return self._native.log()

        @property
        def plan(self) -> Plan:
            """The planned motion: ``duration``, ``hand(t)`` -> (angle, rate, acceleration),
            ``time_at(s_h)``, ``s_h_at(t)``, ``sdot_h_at(t)``, ``s_from``, ``s_to``."""
            return self._native.plan

        def close(self) -> None:
            self._native.close()

    Env.__module__ = __name__
    return Env


def _env_class() -> type:
    global _Env
    if _Env is None:
        try:
            import gymnasium
            _Env = _define_env(gymnasium.Env, gymnasium.spaces.Box)
        except ImportError:
            _Env = _define_env(object, Box)
    return _Env


def __getattr__(name: str) -> Any:
    if name == "Env":
        return _env_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
