"""flatland: the butterfly's rolling dynamics, camera and closed loop, from Python.

The package binds flatland's C++ library (the same code as the ``flatland`` command line):

* ``load(path)`` compiles a scene into a :class:`Model`;
* ``solve``, ``simulate``, ``time_optimal``, ``locus`` and ``surface`` run the simulator
  (paper sections 3-4) and return what ``flatland COMMAND --json`` prints, with trajectories
  as numpy arrays;
* :class:`Renderer` renders camera frames (H x W x 3 ``uint8`` BGR, OpenCV's convention) with
  their ground truth; :class:`Tracker` finds the disk in a frame; ``calibrate`` calibrates a
  camera from board images or corners;
* ``experiment`` and ``montecarlo`` run the vision-feedback closed loop (paper section 5).

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

from . import _flatland  # noqa: E402
from ._flatland import Model  # noqa: E402

__all__ = [
    "Model", "load", "default_scene_path", "solve", "simulate", "Simulation", "time_optimal",
    "locus", "surface", "Renderer", "Tracker", "calibrate", "render_calibration", "experiment",
    "Experiment", "montecarlo", "study",
]

SceneLike = Union[Model, str, "_os.PathLike[str]", None]


def load(path: Union[str, "_os.PathLike[str]", None] = None) -> Model:
    """Compile the scene file at ``path`` (YAML, docs/SCENE.md) into an immutable Model.

    ``None`` loads the bundled paper scene (``default_scene_path()``). A bad file raises
    ValueError naming the file, the field and the reason, as the CLI prints it.
    """
    return _flatland.load(path)


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
    return _flatland.solve(period, scene, k, solve_for, tolerance, method, rtol, atol, step,
                           energy_tolerance, formulation)


@dataclass(frozen=True)
class Simulation:
    """One run: ``report`` has the keys of ``flatland simulate --json``; ``trajectory`` one
    numpy array per column of the trajectory CSV (t, theta, s_h, x, y, f_n, fn_ratio, mode, ...;
    docs/OUTPUTS.md)."""

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
    """
    report, trajectory = _flatland.simulate(scene, period, k, duration, mu, model,
                                            stop_on_contact_loss, sample_dt, method, rtol, atol,
                                            step, energy_tolerance, formulation)
    return Simulation(report, trajectory)


def time_optimal(scene: SceneLike = None, *, mu: Optional[float] = None, from_: float = 0.9,
                 to: float = 1.5, period_tolerance: float = 1e-7, tolerance: float = 1e-9,
                 method: Optional[str] = None, rtol: Optional[float] = None,
                 atol: Optional[float] = None, step: Optional[float] = None,
                 energy_tolerance: Optional[float] = None,
                 formulation: Optional[str] = None) -> Dict[str, Any]:
    """The fastest butterfly in 2T in [from_, to] s that keeps contact (and, with ``mu``, does
    not slip). The keys of ``flatland time-optimal --json`` (period, k, limit, solution, ...)."""
    return _flatland.time_optimal(scene, mu, from_, to, period_tolerance, tolerance, method, rtol,
                                  atol, step, energy_tolerance, formulation)


def locus(scene: SceneLike = None, *, from_: float = 1.1, to: float = 3.0, n: int = 20,
          mu: Optional[float] = None, tolerance: float = 1e-9, method: Optional[str] = None,
          rtol: Optional[float] = None, atol: Optional[float] = None,
          step: Optional[float] = None, energy_tolerance: Optional[float] = None,
          formulation: Optional[str] = None) -> Dict[str, Any]:
    """The butterfly solutions k(2T) at ``n`` durations evenly spaced over [from_, to] s (paper
    Fig. 7). ``points`` and ``mu`` as ``flatland locus --json``; also one numpy array per field
    (period, k, fn_min_ratio, fn_apex_ratio, mu_required, friction_margin)."""
    return _flatland.locus(scene, from_, to, n, mu, tolerance, method, rtol, atol, step,
                           energy_tolerance, formulation)


def surface(scene: SceneLike = None, *, k_from: float = -1.6, k_to: float = -0.8, nk: int = 50,
            period_from: float = 0.8, period_to: float = 2.0, np: int = 50, threads: int = 0,
            method: Optional[str] = None, rtol: Optional[float] = None,
            atol: Optional[float] = None, step: Optional[float] = None,
            energy_tolerance: Optional[float] = None,
            formulation: Optional[str] = None) -> Dict[str, Any]:
    """s_h(T) on a k x 2T grid (paper Fig. 6): ``k`` (nk), ``period`` (np) and ``s_T``
    (nk x np) as numpy arrays; its zero level is the locus. ``threads``: 0 uses every core."""
    return _flatland.surface(scene, k_from, k_to, nk, period_from, period_to, np, threads, method,
                             rtol, atol, step, energy_tolerance, formulation)


class Renderer:
    """Synthetic camera frames of a scene with a camera (headless OpenGL: OSMesa or EGL).

    ``render(t=...)`` captures the frame at time t of the scene's run (simulated once, at the
    first call) through the scene's effects (exposure blur, noise, jitter, dropped frames);
    frames taken in order match ``flatland render``'s. ``render(state=...)`` draws one
    instant without effects. Images are H x W x 3 ``uint8`` BGR (OpenCV's order), or float32
    when the scene's effects do not quantise; the truth is a dict (t, theta, s_h, disk centre
    and marker in the table frame and in pixels, dropped).
    """

    def __init__(self, model: SceneLike = None, backend: Optional[str] = None,
                 duration: Optional[float] = None):
        """``model``: a Model or scene with a camera section; ``backend``: osmesa or egl
        (default: the scene's render.backend); ``duration``: the run's length, s (default: the
        scene's)."""
        self._native = _flatland.Renderer(model, backend, duration)

    def render(self, t: Optional[float] = None, state: Optional[Dict[str, Any]] = None
               ) -> Tuple[Optional[np.ndarray], Dict[str, Any]]:
        """(image, truth) at time ``t`` s of the run, or of ``state``, a dict with hand_angle
        (rad), disk_center ((x, y), m, table frame), disk_angle (rad) and optionally t. A
        dropped frame's image is None."""
        if (t is None) == (state is None):
            raise ValueError("render: give exactly one of t and state")
        if t is not None:
            return self._native.render_at(float(t))
        unknown = set(state) - {"hand_angle", "disk_center", "disk_angle", "t"}
        if unknown:
            raise ValueError(f"state: unknown keys {sorted(unknown)} (hand_angle, disk_center, "
                             "disk_angle, t)")
        return self._native.render_state(float(state.get("hand_angle", 0.0)),
                                         tuple(state.get("disk_center", (0.0, 0.0))),
                                         float(state.get("disk_angle", 0.0)),
                                         float(state.get("t", 0.0)))

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
    tracker. ``method``: edge (default), moments or hough. Frames are H x W or H x W x 3 (BGR),
    uint8 or float32 numpy arrays; track them in order (the tracker predicts from the last).
    """

    def __init__(self, model: SceneLike = None, method: Optional[str] = None):
        self._native = _flatland.Tracker(model, method)

    def track(self, frame: np.ndarray, theta: Optional[float] = None) -> Dict[str, Any]:
        """state (found, tracking, lost), center (u, v) px or None, radius_px, sigma_px,
        quality, edge_points, and s_h (with ``theta``, the hand angle in rad, and a model)."""
        return self._native.track(frame, theta)

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
    return _flatland.calibrate(board, None if images is None else list(images),
                               None if corners is None else list(corners), image_size, fix,
                               rational)


def render_calibration(model: SceneLike = None, *, intrinsics_views: int = 16,
                       table_views: int = 4, joint_views: int = 8, seed: int = 1,
                       board: str = "") -> Dict[str, Any]:
    """A rendered calibration session (``flatland render-calibration``): ``images`` by path
    (intrinsics/view_00.png, table/..., joint/...), the ``board`` notation, the
    ``intrinsics_images`` paths and the true ``camera``."""
    return _flatland.render_calibration(model, intrinsics_views, table_views, joint_views, seed,
                                        board)


@dataclass(frozen=True)
class Experiment:
    """A synthetic closed-loop experiment: ``result`` has the keys of ``flatland experiment
    --json`` that a synthetic run has; ``log`` one numpy array per column of its log.csv (t,
    theta, command, stage, s_est, s_meas, s_true, mode_true, ...: docs/EXPERIMENT.md)."""

    result: Dict[str, Any]
    log: Dict[str, np.ndarray]

    def __getitem__(self, key: str) -> Any:
        return self.result[key]


def experiment(model: SceneLike = None, *, controller: Optional[str] = None) -> Experiment:
    """One synthetic experiment of the vision-feedback loop (paper section 5): the world of the
    scene (default: the bundled closed-loop air table, scenes/airtable-feedback.yaml) filmed at
    its camera's rate, the estimator and ``controller`` ("feedback" or "open-loop"; default the
    scene's) at 1 kHz."""
    result, log = _flatland.experiment(model, controller)
    return Experiment(result, log)


def montecarlo(model: SceneLike = None, *, runs: int = 20, seed: int = 1,
               controllers: Sequence[str] = ("open-loop", "feedback"), threads: int = 0,
               perturbations: Optional[Dict[str, float]] = None) -> Dict[str, Any]:
    """``runs`` experiments of each controller, each in a perturbed world (the same worlds for
    both): success counts with Wilson 95 % intervals and one record per experiment.
    ``perturbations`` overrides the spreads of ``flatland montecarlo`` (s_h, tilt_deg,
    radius_rel, noise_dn, latency, latency_jitter, drop, friction_rel, contact_rel)."""
    return _flatland.montecarlo(model, runs, seed, list(controllers), threads, perturbations)


def study(name: str, scene: SceneLike = None, *, quick: bool = False) -> Dict[str, np.ndarray]:
    """A speed-accuracy study (``flatland study NAME``, docs/ACCURACY.md): "sim" (the
    integrators' work-precision), "calibration", "render", "tracker" or "closed-loop". Returns
    the rows of the CSV file the CLI writes, one numpy array per column (numbers as float, words
    as str). ``quick``: the CLI's --quick grid (seconds to a minute instead of minutes). The
    scene defaults to the CLI study's (the paper scene, butterfly-camera.yaml for render and
    tracker, airtable-feedback.yaml for closed-loop; calibration takes none)."""
    text = _flatland.study(name, scene, quick)
    return _csv_columns(text)


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
