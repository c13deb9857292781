# Type stubs of the native module flatland._flatland. The public API, with its documentation, is
# the package flatland (__init__.py); these are the functions it calls, every argument given.
from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

SceneArg = Union["Model", str, "PathLike[str]", None]

class Model:
    @property
    def origin(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def has_camera(self) -> bool: ...
    @property
    def camera(self) -> Optional[Dict[str, Any]]: ...

def load(path: SceneArg = None) -> Model: ...
def default_scene_path() -> str: ...
def data_directory() -> str: ...
def solve(period: Optional[float], scene: SceneArg, k: Optional[float], solve_for: str,
          tolerance: float, method: Optional[str], rtol: Optional[float], atol: Optional[float],
          step: Optional[float], energy_tolerance: Optional[float],
          formulation: Optional[str]) -> Dict[str, Any]: ...
def simulate(scene: SceneArg, period: Optional[float], k: Optional[float],
             duration: Optional[float], mu: Optional[float], model: Optional[str],
             stop_on_contact_loss: bool, sample_dt: Optional[float], method: Optional[str],
             rtol: Optional[float], atol: Optional[float], step: Optional[float],
             energy_tolerance: Optional[float], formulation: Optional[str]
             ) -> Tuple[Dict[str, Any], Union[Dict[str, np.ndarray], str]]: ...
def time_optimal(scene: SceneArg, mu: Optional[float], from_: float, to: float,
                 period_tolerance: float, tolerance: float, method: Optional[str],
                 rtol: Optional[float], atol: Optional[float], step: Optional[float],
                 energy_tolerance: Optional[float], formulation: Optional[str]) -> Dict[str, Any]: ...
def design(scene: SceneArg, objective: str, period: Optional[float], mu: Optional[float],
           motion_only: bool,
           shape_range: float, fn_margin: float, max_evaluations: int, tolerance: float,
           method: Optional[str], rtol: Optional[float], atol: Optional[float],
           step: Optional[float], energy_tolerance: Optional[float],
           formulation: Optional[str]) -> Dict[str, Any]: ...
def locus(scene: SceneArg, from_: float, to: float, n: int, mu: Optional[float],
          tolerance: float, method: Optional[str], rtol: Optional[float], atol: Optional[float],
          step: Optional[float], energy_tolerance: Optional[float],
          formulation: Optional[str]) -> Dict[str, Any]: ...
def surface(scene: SceneArg, k_from: float, k_to: float, nk: int, period_from: float,
            period_to: float, np: int, threads: int, method: Optional[str],
            rtol: Optional[float], atol: Optional[float], step: Optional[float],
            energy_tolerance: Optional[float], formulation: Optional[str]) -> Dict[str, Any]: ...

class Renderer:
    def __init__(self, model: SceneArg, backend: Optional[str] = None,
                 duration: Optional[float] = None) -> None: ...
    def render_at(self, t: float, mask: bool = False
                  ) -> Tuple[Optional[np.ndarray], Dict[str, Any]]: ...
    def render_state(self, hand_angle: float, disk_center: Tuple[float, float],
                     disk_angle: float, t: float, mask: bool = False
                     ) -> Tuple[np.ndarray, Dict[str, Any]]: ...
    @property
    def t_end(self) -> float: ...
    @property
    def gl(self) -> str: ...
    @property
    def camera(self) -> Dict[str, Any]: ...

class Tracker:
    def __init__(self, model: SceneArg, method: Optional[str] = None) -> None: ...
    def track(self, frame: np.ndarray, theta: Optional[float] = None) -> Dict[str, Any]: ...
    def reset(self) -> None: ...

def calibrate(board: str, images: Optional[List[np.ndarray]],
              corners: Optional[List[Tuple[np.ndarray, np.ndarray]]],
              image_size: Optional[Tuple[int, int]], fix: str, rational: bool) -> Dict[str, Any]: ...
def render_calibration(scene: SceneArg, intrinsics_views: int, table_views: int, joint_views: int,
                       seed: int, board: str) -> Dict[str, Any]: ...
def experiment(scene: SceneArg, controller: Any, estimator: Any
               ) -> Tuple[Dict[str, Any], Dict[str, np.ndarray]]: ...

class Plan:
    @property
    def duration(self) -> float: ...
    def hand(self, t: float) -> Tuple[float, float, float]: ...
    def time_at(self, s_h: float) -> float: ...
    def s_h_at(self, t: float) -> float: ...
    def sdot_h_at(self, t: float) -> float: ...
    @property
    def s_from(self) -> float: ...
    @property
    def s_to(self) -> float: ...

class ControllerContext:
    @property
    def plan(self) -> Plan: ...
    dt: float
    t_start: float
    s_h_start: float

class JointReading:
    t: float
    theta: float
    theta_dot: float

class Measurement:
    t_capture: float
    t_arrival: float
    s_h: float
    sigma: float

class Estimate:
    def __init__(self, t: float, s_h: float, sdot_h: float,
                 covariance: Sequence[Sequence[float]]) -> None: ...
    t: float
    s_h: float
    sdot_h: float
    @property
    def covariance(self) -> Tuple[Tuple[float, float], Tuple[float, float]]: ...

class ControlInput:
    t: float
    joint: JointReading
    estimate: Estimate
    estimating: bool
    measurement: Optional[Measurement]

class ControlOutput:
    def __init__(self, theta_ddot: float, mode: Optional[str] = None,
                 theta_reference: Optional[float] = None, done: bool = False,
                 t_done: Optional[float] = None, stop: Optional[str] = None) -> None: ...
    theta_ddot: float
    mode: str
    theta_reference: float
    done: bool
    t_done: Optional[float]
    @property
    def stop(self) -> Optional[str]: ...

class HandInput:
    theta: float
    theta_dot: float
    theta_ddot: float

class UpdateReport:
    def __init__(self, applied: bool = True, innovation: float = 0.0,
                 innovation_sigma: float = 0.0, nis: float = 0.0,
                 repropagated_steps: int = 0) -> None: ...
    applied: bool
    innovation: float
    innovation_sigma: float
    nis: float
    repropagated_steps: int

class EstimatorCounts:
    def __init__(self, steps: int = 0, repropagated: int = 0, updates: int = 0) -> None: ...
    steps: int
    repropagated: int
    updates: int

class Env:
    def __init__(self, scene: SceneArg, observation: str, ticks_per_step: int,
                 duration: Optional[float], time_limit: Optional[float], estimator: Any) -> None: ...
    def reset(self, seed: Optional[int]) -> Tuple[np.ndarray, Dict[str, Any]]: ...
    def step(self, action: float) -> Tuple[np.ndarray, bool, bool, Dict[str, Any]]: ...
    def render(self) -> Optional[np.ndarray]: ...
    def log(self) -> Dict[str, np.ndarray]: ...
    def close(self) -> None: ...
    @property
    def description(self) -> Dict[str, Any]: ...
    @property
    def plan(self) -> Plan: ...
def montecarlo(scene: SceneArg, runs: int, seed: int, controllers: Sequence[str], threads: int,
               perturbations: Optional[Dict[str, float]]) -> Dict[str, Any]: ...
def study(name: str, scene: SceneArg, quick: bool) -> str: ...
def identify(scene: SceneArg, recordings: List[Dict[str, Any]], unknowns: List[str],
             segment: float, bounds: Dict[str, Tuple[float, float]], initial: Dict[str, float],
             max_iterations: int, threads: int, validate: Optional[Dict[str, Any]],
             command: str) -> Dict[str, Any]: ...
def validate_world(scene: SceneArg, recording: Dict[str, Any], angle_offset: float,
                   time_offset: float) -> Dict[str, Any]: ...
def read_camera_file(path: str) -> Dict[str, Any]: ...
def write_camera_file(path: str, camera_name: str, width: int, height: int, K: np.ndarray,
                      dist: np.ndarray, R: Optional[np.ndarray], t: Optional[np.ndarray],
                      fps: float, exposure: float, joint: Optional[Tuple[float, float, float]],
                      unsupported: List[str], force: bool) -> None: ...
def project(width: int, height: int, K: np.ndarray, dist: np.ndarray, R: Optional[np.ndarray],
            t: Optional[np.ndarray], points: np.ndarray) -> np.ndarray: ...
def _noop() -> None: ...
