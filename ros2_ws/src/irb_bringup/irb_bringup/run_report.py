"""Figures of executed runs from their bags, and the main job's report (no ROS imports).

A run's bag holds /joint_states (effort = applied torque), /controller_state and /camera/tcp.
The path window is where the controller was in MODE_PATH; inside it:
energy E = int sum_i |tau_i qd_i| dt (thesis eq. 6.9) from the joint states, and the camera's
path error = distance of each camera point from the circle (or from any other path, e.g. the
gluing rectangle, by the path's own projection, irb_description.path).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from irb_control.pd_plus import MODE_HOLD, MODE_PATH

from irb_identification.bagio import read_messages, typestore

CONTROLLER_STATE = 'irb_interfaces/msg/ControllerState'
#: [s] the largest gap between recorded samples (4.032 ms apart) a run's path phase may have:
#: above, the recorder lost samples (a stall longer than the writers' 1 s keep-last history)
MAX_SAMPLE_GAP_S = 0.05


@dataclass
class RunFigures:
    """One executed circle: time t (N,) [s] from the path start, power (N,) [W], tau and qd
    (N, 3); camera path error err (M,) [m] at t_cam (M,) [s]; energy [J], duration [s]."""

    label: str
    bag: str
    t: np.ndarray
    power: np.ndarray
    tau: np.ndarray
    qd: np.ndarray
    t_cam: np.ndarray
    err: np.ndarray
    energy: float
    duration: float

    @property
    def err_mean_mm(self) -> float:
        return float(1e3 * self.err.mean()) if self.err.size else float('nan')

    @property
    def err_max_mm(self) -> float:
        return float(1e3 * self.err.max()) if self.err.size else float('nan')


def circle_error(p: np.ndarray, center: np.ndarray, radius: float) -> np.ndarray:
    """Distance (M,) [m] of points p (M, 3) from the horizontal circle (center (3,), radius)."""
    rho = np.hypot(p[:, 0] - center[0], p[:, 1] - center[1])
    return np.hypot(rho - radius, p[:, 2] - center[2])


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def largest_gap(t: np.ndarray, t0: float, t1: float) -> tuple[float, float]:
    """(largest gap [s], where it starts [s]) between the sorted stamps ``t`` in [t0, t1]."""
    t = np.sort(np.asarray(t, float))
    t = t[(t >= t0 - 1e-9) & (t <= t1 + 1e-9)]
    if t.size < 2:
        return float(t1 - t0), float(t0)
    d = np.diff(t)
    return float(d.max()), float(t[np.argmax(d)])


def check_gap(t: np.ndarray, t0: float, t1: float, what: str, bag) -> None:
    """ValueError if the stamps ``t`` of ``what`` have a gap > MAX_SAMPLE_GAP_S in [t0, t1]."""
    gap, at = largest_gap(t, t0, t1)
    if gap > MAX_SAMPLE_GAP_S:
        raise ValueError(f'bag {bag}: {what} misses {gap:.3f} s of samples from t = {at:.3f} s '
                         '(the recorder fell behind): figures of it would be wrong')


def path_window(bag: str | Path) -> tuple[float, float]:
    """(first, last) stamp [s] of the controller in MODE_PATH in a run's bag; ValueError if
    the bag has no path phase, ends before the controller finished it, or misses the
    controller states at either end of the path phase (the window would be wrong)."""
    store = typestore([CONTROLLER_STATE])
    ctrl = read_messages(bag, ['/controller_state'])['/controller_state']
    states = [store.deserialize_cdr(d, ctrl.msgtype) for d in ctrl.data]
    t_path = np.array([_stamp(m) for m in states if m.mode == MODE_PATH])
    if t_path.size < 2:
        raise ValueError(f'bag {bag}: the controller never followed the path (no MODE_PATH)')
    if not any(m.mode == MODE_HOLD and _stamp(m) > t_path.max() for m in states):
        # figures of a lap cut short would look plausible and be wrong (a shorter duration,
        # less energy): refuse them
        raise ValueError(f'bag {bag}: ends before the controller finished the path (no '
                         'MODE_HOLD after MODE_PATH: the recorder stopped early or fell behind)')
    t0, t1 = float(t_path.min()), float(t_path.max())
    # a hold after a gap hides a lap cut short just as well (run 20261124_235759: the last
    # 0.5 s of the path lost in a 1 s recorder stall, "5.49 s" and 30 % less energy)
    stamps = np.array([_stamp(m) for m in states])
    t_hold = stamps[np.array([m.mode == MODE_HOLD for m in states]) & (stamps > t1)].min()
    t_before = stamps[stamps < t0].max() if np.any(stamps < t0) else -np.inf
    for a, b, end in ((t_before, t0, 'start'), (t1, t_hold, 'end')):
        if b - a > MAX_SAMPLE_GAP_S:
            raise ValueError(f'bag {bag}: /controller_state misses {b - a:.3f} s of samples at '
                             f'the {end} of the path phase (the recorder fell behind): its '
                             'figures would be wrong')
    return t0, t1


def actuated_joint_names() -> list[str]:
    """The model's actuated joints (joint_1..3): what the figures are computed on, picked by
    name from joint states that may carry all six joints."""
    from irb_description.model import N_ACTUATED
    from irb_description.params import load_kinematics
    return list(load_kinematics().joint_names[:N_ACTUATED])


def run_figures(bag: str | Path, label: str, center: np.ndarray | None = None,
                radius: float | None = None, path=None) -> RunFigures:
    """Figures of the path phase of one run on the circle (center, radius) or on ``path``
    (an irb_description path); raises ValueError if the bag has no path phase or misses
    samples in it. The same reading and figures as ``report`` (run_analysis)."""
    from irb_description.path import CirclePath

    from .run_analysis import mechanical_energy, path_errors, read_run
    t0, t1 = path_window(bag)
    run = read_run(bag, actuated_joint_names(), topics=('/joint_states', '/camera/tcp'))
    check_gap(run.js_t, t0, t1, '/joint_states', bag)
    inside = (run.js_t >= t0) & (run.js_t <= t1)
    tau, qd = run.tau[inside], run.qd[inside]
    t = run.js_t[inside] - t0
    if path is None:
        path = CirclePath(np.asarray(center, float), float(radius), 0.0, 1)
    cam_t, cam_p = ((run.cam_t, run.cam_p) if run.cam_t is not None
                    else (np.zeros(0), np.zeros((0, 3))))
    sel = (cam_t >= t0) & (cam_t <= t1)
    err, _ = path_errors(path, cam_p[sel])
    return RunFigures(label, str(bag), t, np.abs(tau * qd).sum(axis=1), tau, qd,
                      cam_t[sel] - t0, err, mechanical_energy(run.js_t, run.tau, run.qd, t0, t1),
                      float(t1 - t0))


def plot_runs(runs: list[RunFigures], out_dir: Path) -> dict[str, str]:
    """Power (fig. 7.1), torques/speeds (fig. 7.2) and path error (fig. 4.15) PNGs."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}

    def save(fig, key, name):
        fig.tight_layout()
        files[key] = str(out_dir / name)
        fig.savefig(files[key], dpi=110)
        plt.close(fig)

    def lines(key, name, series, ylabel, title):
        """One axis, one line per run: series(run) -> (x, y, label)."""
        fig, ax = plt.subplots(figsize=(8, 3.5))
        for r in runs:
            x, y, label = series(r)
            ax.plot(x, y, label=label)
        ax.set(xlabel='time from path start [s]', ylabel=ylabel, title=title)
        ax.legend()
        ax.grid(alpha=0.3)
        save(fig, key, name)

    lines('power', 'power.png', lambda r: (r.t, r.power, f'{r.label}: {r.energy:.1f} J'),
          'power sum |tau qd| [W]', 'Power along the circle (cf. thesis fig. 7.1)')
    fig, axes = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    for r in runs:
        for j in range(3):
            axes[j, 0].plot(r.t, r.tau[:, j], label=r.label)
            axes[j, 1].plot(r.t, r.qd[:, j], label=r.label)
    for j in range(3):
        axes[j, 0].set_ylabel(f'tau_{j + 1} [N m]')
        axes[j, 1].set_ylabel(f'qd_{j + 1} [rad/s]')
    axes[0, 0].legend()
    axes[-1, 0].set_xlabel('time [s]')
    axes[-1, 1].set_xlabel('time [s]')
    fig.suptitle('Torques and joint speeds (cf. thesis fig. 7.2)')
    save(fig, 'torques', 'torques_speeds.png')
    lines('path_error', 'path_error.png',
          lambda r: (r.t_cam, 1e3 * r.err, f'{r.label}: mean {r.err_mean_mm:.3f} mm'),
          'camera path error [mm]', 'Path error from the camera (cf. thesis figs. 4.15-4.20)')
    return files


def link_path(p, base: Path) -> str:
    """``p`` as a Markdown link from a file in ``base``: relative (POSIX) when inside it,
    else as it is."""
    p, base = Path(p).resolve(), Path(base).resolve()
    return p.relative_to(base).as_posix() if p.is_relative_to(base) else str(p)


def saving_percent(optimal: float, baseline: float) -> float:
    """Energy saved by ``optimal`` relative to ``baseline`` [%]."""
    return 100.0 * (baseline - optimal) / baseline


def markdown_report(run_id: str, energy: RunFigures, trapezoid: RunFigures,
                    no_ff: RunFigures, plots: dict[str, str], friction_rows: list[tuple],
                    friction_plots: list[str], plan_rows: list[tuple], plan_plot: str | None,
                    bags: dict[str, str], notes: list[str], out: Path,
                    sections: list[str] | None = None) -> str:
    """Write the one-page report ``out`` (Markdown, PNGs referenced relatively); ``sections``:
    further Markdown lines before the bags (e.g. ``rectangle_section``)."""
    rel = partial(link_path, base=out.parent)
    saving = saving_percent(energy.energy, trapezoid.energy)
    improvement = 100.0 * (no_ff.err_mean_mm - energy.err_mean_mm) / no_ff.err_mean_mm
    lines = [
        f'# Thesis pipeline on the simulator — run {run_id}', '',
        'Identification sweeps → friction map → energy-optimal and trapezoidal plans at the '
        'same duration → both executed by the θ-driven PD+ controller with the identified '
        'friction compensation, and the optimal one again without compensation.', '',
        '## Energy (thesis: 6.98 % less than the robot\'s own planner)', '',
        '| run | duration [s] | energy E = ∫Σ\\|τq̇\\|dt [J] |', '|---|---|---|',
        f'| energy-optimal, identified FF | {energy.duration:.2f} | {energy.energy:.1f} |',
        f'| trapezoidal TCP speed, identified FF | {trapezoid.duration:.2f} | '
        f'{trapezoid.energy:.1f} |', '',
        f'**Saving: {saving:.1f} %** of the trapezoidal run\'s energy.', '',
        f'![power]({rel(plots["power"])})', '',
        '## Path accuracy (thesis: friction compensation cuts the error by 25-50 %)', '',
        '| run | camera path error mean [mm] | max [mm] |', '|---|---|---|',
        f'| energy-optimal, no FF | {no_ff.err_mean_mm:.3f} | {no_ff.err_max_mm:.3f} |',
        f'| energy-optimal, identified FF | {energy.err_mean_mm:.3f} | '
        f'{energy.err_max_mm:.3f} |', '',
        f'**Compensation cuts the mean path error by {improvement:.0f} %.**', '',
        f'![path error]({rel(plots["path_error"])})', '',
        f'![torques]({rel(plots["torques"])})', '',
        '## Identified friction (arm side) against the simulated plant', '',
        '| joint | F_c [N m] | F_v [N m s/rad] | F_s [N m] | plant F_c / F_v / F_s | speeds '
        '[rad/s] |', '|---|---|---|---|---|---|',
        *[f'| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]} |' for r in friction_rows],
        '', *[f'![friction {i + 1}]({rel(p)})' for i, p in enumerate(friction_plots)], '',
        '## Planner', '',
        '| plan | energy [J] | duration [s] | peak torques [N m] | solve time [s] |',
        '|---|---|---|---|---|',
        *[f'| {r[0]} | {r[1]:.1f} | {r[2]:.2f} | {r[3]} | {r[4]:.2f} |' for r in plan_rows], '',
        *([f'![plan]({rel(plan_plot)})', ''] if plan_plot else []),
        *(sections or []),
        '## Bags', '',
        *[f'- {k}: `{v}`' for k, v in bags.items()], '',
        *(['## Notes', '', *[f'- {n}' for n in notes], ''] if notes else []),
    ]
    text = '\n'.join(lines)
    out.write_text(text)
    return text


def _num(x: float, fmt: str = '.3f') -> str:
    return '–' if x != x else format(x, fmt)


def _band_cell(plan) -> str:
    """'low-peak' TCP speed of a plan as played ('–' if the planner did not check it)."""
    if plan.tcp_speed_peak != plan.tcp_speed_peak:
        return '–'
    return f'{_num(plan.tcp_speed_low)}-{_num(plan.tcp_speed_peak)}'


def rectangle_section(energy: RunFigures, trapezoid: RunFigures, plots: dict[str, str],
                      plan_e, plan_t, rect: dict, path, out: Path, band: str = ''
                      ) -> list[str]:
    """Markdown lines of the gluing-contour task: the process constraints ``band`` (in
    words, '' = none), the two runs' planned and executed energy and camera path error, the
    plans' TCP speed and acceleration as played, the plots. plan_e/plan_t: the planner's
    responses."""
    rel = partial(link_path, base=out.parent)
    saving = saving_percent(energy.energy, trapezoid.energy)
    speed = path.length / max(energy.duration, 1e-9)
    return [
        '## Gluing contour: rectangle with blended corners in a tilted plane', '',
        f'{rect["width_m"]} x {rect["height_m"]} m about {rect["center_m"]} m, plane normal '
        f'{rect["normal"]}, {rect["blend_radius_m"] * 1e3:.0f} mm corner blends, '
        f'length {path.length:.3f} m in {rect["duration_s"]} s (mean TCP speed '
        f'{speed:.3f} m/s); pdplus follows it by projection (PathTracker).', '',
        f'Process constraints of both plans: {band or "none"}.', '',
        '| run | duration [s] | energy planned [J] | executed [J] | camera path error mean '
        '[mm] | max [mm] | planned TCP speed [m/s] | planned max \\|a\\| [m/s²] |',
        '|---|---|---|---|---|---|---|---|',
        *[f'| {name}, identified FF | {r.duration:.2f} | {p.energy:.1f} | {r.energy:.1f} | '
          f'{r.err_mean_mm:.3f} | {r.err_max_mm:.3f} | {_band_cell(p)} | '
          f'{_num(p.tcp_accel_peak)} |'
          for name, r, p in (('energy-optimal', energy, plan_e),
                             ('trapezoid along arc length', trapezoid, plan_t))], '',
        f'**Saving: {saving:.1f} %** of the trapezoidal run\'s energy (planned: '
        f'{plan_e.energy:.1f} J vs {plan_t.energy:.1f} J).', '',
        f'![power]({rel(plots["power"])})', '',
        f'![path error]({rel(plots["path_error"])})', '']
