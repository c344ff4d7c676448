"""Offline closed loop: Plant + PdPlusController, no ROS (tests, benchmarks, other packages).

    from irb_control.closed_loop import build_default, simulate_closed_loop
    plant, ctrl = build_default(friction_mode='nominal', duration_s=10.0)
    res = simulate_closed_loop(plant, ctrl, 11.0)
    res.path_error_camera()      # (M,) [m]

Each period: measure -> controller step -> command -> plant step, the same order and delay as
the two ROS nodes in lockstep mode. The joint count is the plant's: 3 (``build_default``, the
thesis) or 6 (``build_six_joint``: ``SixJointModel``, config/pdplus_six_axis.yaml, the six
joints of config/plant.yaml).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from irb_description.friction import FrictionMap, load_friction_map
from irb_description.model import RobotModel
from irb_description.path import CirclePath, PathBase, thesis_circle

from .pd_plus import MODE_HOLD, ControllerConfig, PdPlusController
from .plant import Plant, PlantConfig, PlantFriction, default_plant_yaml, load_plant_friction
from .profiles import default_circle_profile


@dataclass
class ClosedLoopResult:
    """Logged arrays of one run; N controller periods, M camera samples, SI units.

    t (N,) [s]; q, qd (N, n) true state at t (n joints: 3 or 6); q_meas, qd_meas (N, n) encoder
    samples; tau_cmd (N, n) command computed at t (0 when none); tau_applied (N, n) torque
    acting over [t, t + T); q_ref, qd_ref (N, n) (NaN where undefined); theta (N,); mode (N,) int;
    published (N,) bool; cam_t (M,) [s], cam_p (M, 3) [m]; energy [J] = int sum |tau qd| dt
    over the run (from the plant's substeps); events: plant log lines; stop_reason.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_meas: np.ndarray
    qd_meas: np.ndarray
    tau_cmd: np.ndarray
    tau_applied: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    theta: np.ndarray
    mode: np.ndarray
    published: np.ndarray
    cam_t: np.ndarray
    cam_p: np.ndarray
    energy: float
    events: list
    stop_reason: str
    path: PathBase | None = None
    prediction_samples: int = 0

    def path_error_camera(self, t_from: float | None = None) -> np.ndarray:
        """Distance (M,) [m] from each camera point to the nearest point of the path (any
        type), from ``t_from`` (default: start of the path motion) on."""
        t0 = self.path_start_time() if t_from is None else t_from
        sel = self.cam_t >= t0
        return path_distance(self.path, self.cam_p[sel])

    def path_start_time(self) -> float:
        """Time [s] of the first sample in PATH/TIME mode (end of the ramp)."""
        idx = np.flatnonzero((self.mode == 2) | (self.mode == 3))
        return float(self.t[idx[0]]) if idx.size else float(self.t[-1])

    def motion_mask(self) -> np.ndarray:
        """(N,) True in PATH/TIME mode."""
        return (self.mode == 2) | (self.mode == 3)

    def joint_error(self) -> np.ndarray:
        """Joint tracking error (N, n) [rad]: the reference computed at t_k (which is for
        t_k + n T, n = prediction_samples) minus the true q at t_{k+n}; NaN where undefined."""
        n = self.prediction_samples
        e = np.full_like(self.q, np.nan)
        e[:len(e) - n] = self.q_ref[:len(e) - n] - self.q[n:]
        return e

    def finished(self) -> bool:
        return bool(np.any(self.mode == MODE_HOLD))


def circle_distance(path: CirclePath, p: np.ndarray) -> np.ndarray:
    """Distance (M,) [m] from points p (M, 3) to the nearest point of a horizontal circle."""
    p = np.asarray(p, float).reshape(-1, 3)
    rho = np.hypot(p[:, 0] - path.center[0], p[:, 1] - path.center[1])
    return np.hypot(rho - path.radius, p[:, 2] - path.center[2])


def path_distance(path: PathBase, p: np.ndarray) -> np.ndarray:
    """Distance (M,) [m] from points p (M, 3) to the nearest point of ``path``: the circle's
    closed form for the thesis's CirclePath, the path's own projection otherwise."""
    if type(path) is CirclePath:
        return circle_distance(path, p)
    return np.asarray(path.distance(np.asarray(p, float).reshape(-1, 3)), float)


def polyline_distance(curve: np.ndarray, p: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Distance (M,) [m] from points p (M, 3) to the polyline ``curve`` (K, 3) (segments)."""
    a, b = curve[:-1], curve[1:]
    ab = b - a
    L2 = np.maximum(np.einsum('ij,ij->i', ab, ab), 1e-18)
    out = np.empty(len(p))
    for s in range(0, len(p), chunk):
        P = p[s:s + chunk, None, :]
        u = np.clip(np.einsum('mkj,kj->mk', P - a[None], ab) / L2, 0.0, 1.0)
        d = np.linalg.norm(P - (a[None] + u[..., None] * ab[None]), axis=2)
        out[s:s + chunk] = d.min(axis=1)
    return out


def energy(t: np.ndarray, tau: np.ndarray, qd: np.ndarray) -> float:
    """E = int sum_i |tau_i qd_i| dt [J] (thesis eq. 6.9), rectangle rule on the samples."""
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.0))
    return float(np.sum(np.abs(tau * qd).sum(axis=1) * dt))


def simulate_closed_loop(plant: Plant, controller: PdPlusController, duration: float,
                         enable: bool = True, stop_when_done: float | None = 0.2
                         ) -> ClosedLoopResult:
    """Run plant and controller together for ``duration`` [s] of simulated time.

    ``enable``: call ``controller.enable()`` first. ``stop_when_done``: end the run this long
    [s] after the controller reaches HOLD (None: always run ``duration``).
    """
    n = int(round(duration / plant.config.period_s))
    t = np.empty(n)
    arr = {k: np.full((n, plant.n), np.nan) for k in ('q', 'qd', 'q_meas', 'qd_meas', 'tau_cmd',
                                                'tau_applied', 'q_ref', 'qd_ref')}
    theta = np.full(n, np.nan)
    mode = np.zeros(n, int)
    published = np.zeros(n, bool)
    cam_t, cam_p = [], []
    if enable:
        controller.enable()
    e0 = plant.state.energy
    done_at = None
    k = 0
    for k in range(n):
        s = plant.state
        t[k] = s.t
        arr['q'][k] = s.q
        arr['qd'][k] = s.qd
        y = plant.measure()
        arr['q_meas'][k] = y.q
        arr['qd_meas'][k] = y.qd
        out = controller.step(y.t, y.q, y.qd)
        if out.publish:
            plant.command(out.tau)
            arr['tau_cmd'][k] = out.tau
            published[k] = True
        else:
            arr['tau_cmd'][k] = 0.0
        arr['q_ref'][k] = out.q_ref
        arr['qd_ref'][k] = out.qd_ref
        theta[k] = out.theta
        mode[k] = out.mode
        plant.step()
        arr['tau_applied'][k] = plant.applied
        for ct, cp in plant.take_camera():
            cam_t.append(ct)
            cam_p.append(cp)
        if stop_when_done is not None and out.mode == MODE_HOLD:
            if done_at is None:
                done_at = s.t
            elif s.t - done_at >= stop_when_done:
                break
    m = k + 1
    return ClosedLoopResult(
        t[:m], *(arr[key][:m] for key in ('q', 'qd', 'q_meas', 'qd_meas', 'tau_cmd',
                                          'tau_applied', 'q_ref', 'qd_ref')),
        theta[:m], mode[:m], published[:m], np.array(cam_t), np.array(cam_p).reshape(-1, 3),
        plant.state.energy - e0, list(plant.events), controller.stop_reason, controller.path,
        controller.config.prediction_samples)


def controller_friction(model: RobotModel, mode: str, path: str | Path | None = None
                        ) -> FrictionMap | None:
    """Friction feed-forward map for ``mode``: 'none' -> None, 'nominal' -> model.friction,
    'file' -> load_friction_map(path) (e.g. config/plant.yaml for true-plant FF)."""
    if mode == 'none':
        return None
    if mode == 'nominal':
        return model.friction
    if mode == 'file':
        if not path:
            raise ValueError("friction mode 'file' needs a friction-map path")
        return load_friction_map(path, model.joint_names)
    raise ValueError(f"friction mode must be 'none', 'nominal' or 'file', not {mode!r}")


def build_default(friction_mode: str = 'nominal', friction_file: str | Path | None = None,
                  duration_s: float = 10.0, model: RobotModel | None = None,
                  plant_config: PlantConfig = PlantConfig(),
                  controller_config: ControllerConfig = ControllerConfig(),
                  plant_friction: PlantFriction | None = None,
                  path: PathBase | None = None) -> tuple[Plant, PdPlusController]:
    """Plant (friction from config/plant.yaml) and controller on the thesis circle with the
    default polynomial profile of ``duration_s`` [s]."""
    model = model or RobotModel.load()
    path = path or thesis_circle()
    if plant_friction is None:
        _, plant_friction = load_plant_friction(default_plant_yaml(), model.joint_names)
    if friction_mode == 'file' and friction_file is None:
        friction_file = default_plant_yaml()
    plant = Plant(model, plant_friction, plant_config)
    ctrl = PdPlusController(model, path, controller_config,
                            controller_friction(model, friction_mode, friction_file))
    ctrl.set_path_profile(default_circle_profile(model, path, duration_s))
    return plant, ctrl


def six_axis_controller_config(path: str | Path | None = None, **overrides) -> ControllerConfig:
    """ControllerConfig of six joints: the per-joint settings of config/pdplus_six_axis.yaml
    (``pdplus.ros__parameters``: kp, kd, torque_rate_limit_nm_s, max_tracking_error_rad, ki,
    integral_limit_nm, stribeck_measured, stiction_prediction, stiction_rest_speed_rad_s,
    dither_amplitude_nm, dither_period_samples), the
    rest ControllerConfig's defaults (= config/pdplus.yaml), then ``overrides``."""
    import yaml

    from .plant import config_path
    p = Path(path) if path else config_path('pdplus_six_axis.yaml')
    block = yaml.safe_load(p.read_text())['pdplus']['ros__parameters']
    keys = ('kp', 'kd', 'torque_rate_limit_nm_s', 'max_tracking_error_rad')
    vals = {k: tuple(float(x) for x in block[k]) for k in keys}
    design = block.get('gain_design_inertia_kg_m2', [])
    vals['gain_design_inertia_kg_m2'] = tuple(float(x) for x in design) if design else None
    for k in ('ki', 'integral_limit_nm'):       # integral action, when the file has it
        if block.get(k):
            vals[k] = tuple(float(x) for x in block[k])
    if block.get('stribeck_measured'):
        vals['stribeck_measured'] = tuple(bool(x) for x in block['stribeck_measured'])
    if 'stiction_prediction' in block:
        vals['stiction_prediction'] = bool(block['stiction_prediction'])
    if 'stiction_rest_speed_rad_s' in block:
        vals['stiction_rest_speed_rad_s'] = float(block['stiction_rest_speed_rad_s'])
    if block.get('dither_amplitude_nm'):
        vals['dither_amplitude_nm'] = tuple(float(x) for x in block['dither_amplitude_nm'])
        vals['dither_period_samples'] = int(block.get('dither_period_samples', 2))
    return ControllerConfig(**{**vals, **overrides})


def build_six_joint(profile, path: PathBase, tcp=None, friction_mode: str = 'nominal',
                    friction_file: str | Path | None = None, model=None,
                    plant_config: PlantConfig | None = None,
                    controller_config: ControllerConfig | None = None,
                    tracker=None) -> tuple[Plant, PdPlusController]:
    """Six-joint plant (config/plant.yaml's six joints) and PD+
    (``six_axis_controller_config``) with the theta-profile ``profile`` (PathProfile (N, 6))
    on ``path`` offered; the TCP ``tcp`` (4, 4) in tool0 (the point the path is about). The
    plant starts at rest at the profile's start unless ``plant_config`` says otherwise."""
    from irb_description.six_axis_model import SixJointModel

    model = model or SixJointModel(tcp)
    _, plant_friction = load_plant_friction(default_plant_yaml(), model.joint_names)
    if plant_config is None:        # ideal brakes, as build_default's
        plant_config = PlantConfig(initial_q=tuple(profile.q[0].tolist()))
    if friction_mode == 'file' and friction_file is None:
        friction_file = default_plant_yaml()
    plant = Plant(model, plant_friction, plant_config)
    ctrl = PdPlusController(model, path, controller_config or six_axis_controller_config(),
                            controller_friction(model, friction_mode, friction_file))
    ctrl.set_path_profile(profile, path, tracker)
    return plant, ctrl
