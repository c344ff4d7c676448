"""Excitation for the discrepancy workflow: circles at several speeds and multi-joint sweeps,
run through irb_control's offline closed loop (Plant + PdPlusController) and written as bags.
No rclpy.

All runs of a plan share one plant, one after the other in plant time (t continues from run to
run, so a slow drift such as ``viscous_temperature_drift`` is seen on one clock); each run is
one bag. Sweeps are time-driven: q_j(t) = q0_j + A_j (1 - cos(w_j t)), w_j = 2 pi n_j / D,
A_j = v_j / w_j (peak speed v_j, n_j whole periods in D, so each run starts and ends at rest)
and cover low speeds (Stribeck), high speeds, accelerations and a spread of poses (gravity).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .bagdata import RunData, write_run

PERIOD_S = 0.004032


@dataclass(frozen=True)
class RunSpec:
    """One motion. kind 'circle': the thesis circle in ``duration_s`` [s] (polynomial speed
    profile, theta-driven PD+). kind 'sweep': time-driven multi-joint sweep of ``duration_s``
    with ``cycles`` (3,) whole periods, peak speeds ``peak_speed`` (3,) [rad/s], from ``q0``."""

    kind: str
    duration_s: float
    cycles: tuple = (1, 1, 1)
    peak_speed: tuple = (0.0, 0.0, 0.0)
    q0: tuple = (0.0, 0.9, 0.25)

    def label(self) -> str:
        if self.kind == 'circle':
            return f'circle_{self.duration_s:g}s'.replace('.', 'p')
        v = max(self.peak_speed)
        return f'sweep_{v:.2f}rads'.replace('.', 'p')


def load_plan(path: str | Path, name: str) -> list[RunSpec]:
    """Plan ``name`` from config/excitation.yaml: a list of run mappings (RunSpec fields)."""
    data = yaml.safe_load(Path(path).read_text())
    plans = data['excitation']['plans']
    if name not in plans:
        raise KeyError(f'excitation plan {name!r} not in {path} (has {sorted(plans)})')
    return [RunSpec(r['kind'], float(r['duration_s']), tuple(r.get('cycles', (1, 1, 1))),
                    tuple(float(x) for x in r.get('peak_speed', (0, 0, 0))),
                    tuple(float(x) for x in r.get('q0', (0.0, 0.9, 0.25))))
            for r in plans[name]]


def sweep_trajectory(spec: RunSpec, dt: float = PERIOD_S):
    """irb_control TimeTrajectory of a sweep spec (see module docstring)."""
    from irb_control.profiles import TimeTrajectory
    D = spec.duration_s
    t = np.arange(0.0, D + dt / 2, dt)
    q = np.tile(np.asarray(spec.q0, float), (len(t), 1))
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    for j in range(3):
        if spec.peak_speed[j] <= 0:
            continue
        w = 2 * np.pi * spec.cycles[j] / D
        A = spec.peak_speed[j] / w
        q[:, j] += A * (1 - np.cos(w * t))
        qd[:, j] = A * w * np.sin(w * t)
        qdd[:, j] = A * w**2 * np.cos(w * t)
    qdd[-1] = 0.0
    return TimeTrajectory(t, q, qd, qdd)


@dataclass(frozen=True)
class EffortNoise:
    """Noise of the drive's reported effort (the applied torque is not changed), N m:
    ``white`` standard deviation per sample; ``coloured`` standard deviation of a first-order
    (AR(1)) process with correlation time ``coloured_tau_s`` [s]; ``quantum`` the reported
    value's resolution (0 = none). Per joint or one value for all."""

    white: tuple = (0.0, 0.0, 0.0)
    coloured: tuple = (0.0, 0.0, 0.0)
    coloured_tau_s: float = 0.05
    quantum: float = 0.0

    def __post_init__(self):
        for k in ('white', 'coloured'):
            v = np.broadcast_to(np.asarray(getattr(self, k), float), (3,))
            if not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ValueError(f'effort noise {k} must be finite and >= 0, got {v}')
            object.__setattr__(self, k, tuple(float(x) for x in v))
        if not (np.isfinite(self.coloured_tau_s) and self.coloured_tau_s > 0):
            raise ValueError(f'coloured noise time constant must be > 0 s, got '
                             f'{self.coloured_tau_s}')
        if not (np.isfinite(self.quantum) and self.quantum >= 0):
            raise ValueError(f'effort quantum must be >= 0 N m, got {self.quantum}')

    def __bool__(self) -> bool:
        return bool(any(self.white) or any(self.coloured) or self.quantum)

    def apply(self, t: np.ndarray, effort: np.ndarray, rng) -> np.ndarray:
        out = np.array(effort, float)
        n = len(t)
        out += rng.standard_normal((n, 3)) * np.asarray(self.white)
        if any(self.coloured):
            dt = np.diff(t, prepend=t[0])
            a = np.exp(-dt / self.coloured_tau_s)
            x = np.zeros((n, 3))
            e = rng.standard_normal((n, 3))
            x[0] = e[0]
            for k in range(1, n):
                x[k] = a[k] * x[k - 1] + np.sqrt(1 - a[k] ** 2) * e[k]
            out += x * np.asarray(self.coloured)
        if self.quantum > 0:
            out = np.round(out / self.quantum) * self.quantum
        return out


@dataclass(frozen=True)
class SensorErrors:
    """Errors of the measurement chain (model errors outside the physics), per joint:
    ``torque_gain`` g: the drive applies g x the torque it reports (effort and command are
    reported in the same units, so both are divided by g); ``encoder_scale`` s: the encoder
    (gear ratio) reports s x the true joint position and speed. Applied to the logged data
    of the closed-loop run (the controller saw the true values: a small difference of
    trajectory, the same error signature)."""

    torque_gain: tuple = (1.0, 1.0, 1.0)
    encoder_scale: tuple = (1.0, 1.0, 1.0)

    def __post_init__(self):
        for k in ('torque_gain', 'encoder_scale'):
            v = np.broadcast_to(np.asarray(getattr(self, k), float), (3,))
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f'{k} must be finite and > 0, got {v}')
            object.__setattr__(self, k, tuple(float(x) for x in v))

    def __bool__(self) -> bool:
        return self.torque_gain != (1.0, 1.0, 1.0) or self.encoder_scale != (1.0, 1.0, 1.0)


def perturbed_model(model, link: int, delta_mass_kg: float, at_m=None):
    """A RobotModel whose link ``link`` (2 or 3; 3 = with wrist, tool and payload) carries
    ``delta_mass_kg`` more at ``at_m`` (link frame; default its centre of mass): mass and first
    moments change, as a heavier casting or motor would. Its copy() (what the plant takes)
    keeps the change."""
    import pinocchio as pin
    m = model.copy()
    pm = m.model
    c = np.asarray(pm.inertias[link].lever if at_m is None else at_m, float)
    pm.inertias[link] = pm.inertias[link] + pin.Inertia(float(delta_mass_kg), c,
                                                        np.zeros((3, 3)))
    m.data = pm.createData()
    m.copy = lambda: perturbed_model(model, link, delta_mass_kg, at_m)
    return m


@dataclass
class SimulatedRun:
    """One simulated run: its spec, the arrays as they go into a bag, the plant's events."""

    spec: RunSpec
    data: RunData
    events: list = field(default_factory=list)


def run_plan(model, plan: list[RunSpec], plant_friction, controller_friction=None,
             effects=None, seed: int = 1, plant_config=None, log=None,
             effort_noise: EffortNoise | None = None, sensor: SensorErrors | None = None,
             plant_model=None) -> list[SimulatedRun]:
    """Run every spec of ``plan`` on one plant (irb_control) and return the logged runs.

    plant_friction: FrictionMap of the plant; controller_friction: the PD+'s feed-forward
    map (None: none); effects: irb_control PlantEffects switched on in the plant;
    effort_noise / sensor: what the logged effort, commands and positions go through;
    plant_model: the plant's RobotModel if not ``model`` (e.g. ``perturbed_model``).
    """
    from irb_control.closed_loop import simulate_closed_loop
    from irb_control.pd_plus import ControllerConfig, PdPlusController
    from irb_control.plant import Plant, PlantConfig, PlantFriction
    from irb_control.profiles import default_circle_profile
    from irb_description.path import thesis_circle

    cfg = plant_config or PlantConfig(seed=seed)
    plant = Plant(plant_model or model, PlantFriction.from_map(plant_friction), cfg, effects)
    noise_rng = np.random.default_rng([seed, 7])
    path = thesis_circle()
    runs = []
    last_effort = np.zeros(3)
    for spec in plan:
        ctrl = PdPlusController(model, path, ControllerConfig(), controller_friction)
        if spec.kind == 'circle':
            ctrl.set_path_profile(default_circle_profile(model, path, spec.duration_s))
        elif spec.kind == 'sweep':
            ctrl.set_time_trajectory(sweep_trajectory(spec))
        else:
            raise ValueError(f"run kind must be 'circle' or 'sweep', not {spec.kind!r}")
        res = simulate_closed_loop(plant, ctrl, spec.duration_s + 3.0, stop_when_done=0.3)
        if res.stop_reason:
            raise RuntimeError(f'{spec.label()}: controller stopped: {res.stop_reason}')
        # effort in the state at t_k = torque applied over [t_{k-1}, t_k) (as the simulator
        # node publishes it)
        effort = np.vstack([last_effort, res.tau_applied[:-1]])
        last_effort = res.tau_applied[-1].copy()
        pub = res.published
        q, qd, cmd = res.q_meas, res.qd_meas, res.tau_cmd[pub]
        logged = effort
        if sensor:
            g = np.asarray(sensor.torque_gain)
            logged, cmd = logged / g, cmd / g
            q, qd = q * np.asarray(sensor.encoder_scale), qd * np.asarray(sensor.encoder_scale)
        if effort_noise:
            logged = effort_noise.apply(res.t, logged, noise_rng)
        data = RunData(res.t, q, qd, logged, res.t[pub], cmd, res.cam_t, res.cam_p,
                       spec.label())
        runs.append(SimulatedRun(spec, data, list(res.events)))
        if log:
            log(f'{spec.label()}: {res.t[-1] - res.t[0]:.1f} s, {len(res.t)} samples')
    return runs


def write_runs(runs: list[SimulatedRun], out_dir: str | Path, joint_names: list[str],
               prefix: str = 'excite', custom_data: dict | None = None) -> list[Path]:
    """One bag per run: ``<out_dir>/<prefix>_<index>_<label>``; returns the paths."""
    out = []
    for i, r in enumerate(runs):
        meta = {'experiment': 'discrepancy_excitation', 'run': r.spec.label(),
                'source': 'irb_identification.discrepancy_core.excitation'}
        meta.update({k: str(v) for k, v in (custom_data or {}).items()})
        d = r.data
        out.append(write_run(Path(out_dir) / f'{prefix}_{i:02d}_{r.spec.label()}',
                             joint_names, d.t, d.q, d.qd, d.effort, d.cmd_t, d.cmd, d.cam_t,
                             d.cam_p, custom_data=meta))
    return out
