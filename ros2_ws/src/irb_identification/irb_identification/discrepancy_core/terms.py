"""Candidate terms of the joint regression: physical effects and model errors. No rclpy.

A ``Term`` is one candidate (or one selected) explanation with its columns on the residual
channel blocks ("cb"): ('torque', j) per joint (moving samples), ('tcp', None) (camera x/y/z
flattened), ('command', j) per joint. Columns are linear in the term's parameters; nonlinear
scales (Stribeck speed, cogging period, drift time constant, exponent, payload offset, backlash
smoothing, delay) are chosen on the current residual (profiled on the grid of library.Grids).

Model-error candidates (not physical effects; their names follow the same style):

=================== ======== ===================================================== ==========
name                channel  column (per joint j unless stated)                    parameter
=================== ======== ===================================================== ==========
coulomb_level       torque   sign(v) (dry-friction level F_c and F_s together)     dF_c [N m]
viscous_level       torque   v                                                     dF_v
torque_gain         torque   -effort_j (drive torque = g x reported effort)        g - 1
inertial_link2      torque   regressor columns of m, m c_x, m c_y, m c_z of link 2 dm, d(mc)
                             (pinocchio computeJointTorqueRegressor), all joints
inertial_link3      torque   the same for link 3 (+ wrist, tool, payload)          dm, d(mc)
encoder_scale       torque,  -d tau_model / d s_j and -J[:, j] q_j (a measured     e_j = s-1
                    tcp      q_j = (1 + e_j) q_true, e.g. a wrong gear ratio)
encoder_offset      torque,  -d tau_rigid / d q_j and -J[:, j] (a measured         d_j [rad]
                    tcp      q_j = q_true + d_j: a zero-offset calibration error)
=================== ======== ===================================================== ==========
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .library import (CHANNEL, COMMAND, INERTIAL_LINKS, PER_JOINT_SCALE, SHARED_SCALE, TCP,
                      TORQUE, Grids, Pooled, payload_unit_torque_cached, tcp_columns,
                      torque_columns)

MODEL_ERRORS = ('coulomb_level', 'viscous_level', 'torque_gain', 'inertial_link2',
                'inertial_link3', 'encoder_scale', 'encoder_offset')
MODEL_ERROR_CHANNEL = {'coulomb_level': TORQUE, 'viscous_level': TORQUE,
                       'torque_gain': TORQUE, 'inertial_link2': TORQUE,
                       'inertial_link3': TORQUE, 'encoder_scale': 'torque+tcp',
                       'encoder_offset': 'torque+tcp'}
INERTIAL_LABELS = ('mass_kg', 'first_moment_x_kgm', 'first_moment_y_kgm', 'first_moment_z_kgm')


def channel_of(name: str) -> str:
    return CHANNEL.get(name) or MODEL_ERROR_CHANNEL[name]


@dataclass
class Blocks:
    """Rows of the channel blocks in the pooled data: cb -> row index array into the
    channel's arrays (torque: P.r rows, tcp: flattened P.r_tcp, command: P.r_cmd rows), the
    residual y per cb, the time-block id per row, the noise floor per cb, and where the
    channel's own white noise can be measured in the data (the camera), its RMS per cb."""

    rows: dict
    y: dict
    tb: dict
    floor: dict
    white: dict = field(default_factory=dict)

    @property
    def keys(self) -> list:
        return list(self.rows)


def make_blocks(P: Pooled, floors: dict) -> Blocks:
    rows, y, tb, floor, white = {}, {}, {}, {}, {}
    for j in range(3):
        m = np.flatnonzero(P.mask[:, j])
        if len(m) >= 20:
            rows[(TORQUE, j)] = m
            y[(TORQUE, j)] = P.r[m, j]
            tb[(TORQUE, j)] = P.block[m]
            floor[(TORQUE, j)] = floors['torque'][j]
    if len(P.r_tcp) >= 20:
        k = np.arange(3 * len(P.r_tcp))
        rows[(TCP, None)] = k
        y[(TCP, None)] = P.r_tcp.reshape(-1)
        tb[(TCP, None)] = np.repeat(P.cam_block, 3)
        floor[(TCP, None)] = floors['tcp']
        white[(TCP, None)] = white_noise_rms(P.r_tcp)
    if len(P.r_cmd) >= 20:
        for j in range(3):
            rows[(COMMAND, j)] = np.arange(len(P.r_cmd))
            y[(COMMAND, j)] = P.r_cmd[:, j]
            tb[(COMMAND, j)] = P.cmd_block
            floor[(COMMAND, j)] = floors['command'][j]
    return Blocks(rows, y, tb, floor, white)


def white_noise_rms(r: np.ndarray) -> float:
    """RMS of the white part of a residual r (M, 3) sampled much faster than what the model
    gets wrong varies (the camera: 37 um noise at 250 Hz, effects below ~10 Hz): robust
    (MAD) spread of the second differences / sqrt(6), pooled over the axes. A smooth error
    leaves almost nothing in second differences; the few samples at run boundaries and
    backlash flips are outliers the median ignores (measured on the bench's TCP residuals:
    36-38 um against 37 um simulated, with effects of 1-2.7 x the noise in them).
    NaN (not measured) unless the noise is white at the sample rate: first differences of
    white noise have a lag-1 correlation of -0.5, of a filtered camera's noise (AR(1), rho)
    -(1 - rho) / 2, whose second differences would read low by sqrt((3 - rho) (1 - rho) / 3)
    (-29 % at rho 0.5) and make the excess test permissive; outside -0.5 +- 0.1 it is off."""
    r = np.asarray(r, float)
    if len(r) < 8:
        return float('nan')
    d1 = np.diff(r, axis=0)
    d1 = d1 - np.median(d1, axis=0)
    lag1 = np.sum(d1[1:] * d1[:-1], axis=0) / np.maximum(np.sum(d1 ** 2, axis=0), 1e-300)
    if np.any(np.abs(lag1 + 0.5) > 0.1):
        return float('nan')
    d2 = r[2:] - 2.0 * r[1:-1] + r[:-2]
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) * 1.4826 / np.sqrt(6.0)
    return float(np.sqrt(np.mean(mad ** 2)))


@dataclass
class Term:
    """One candidate: ``cols`` cb -> (n_cb, p) columns (all rows of the cb), ``groups`` joint ->
    parameter indices, ``labels`` (p,), ``scales`` (joint or 'shared' -> value), ``kind``
    'effect' | 'model_error' | 'refit' (of an effect the model file already has), ``n_scales``
    profiled scales (BIC penalty), ``edge`` scales at a grid edge."""

    name: str
    kind: str
    joints: list
    cols: dict
    labels: list
    scales: dict = field(default_factory=dict)
    n_scales: int = 0
    edge: list = field(default_factory=list)
    known: object = None

    @property
    def p(self) -> int:
        return len(self.labels)

    @property
    def channel(self) -> str:
        return channel_of(self.name)

    def key(self) -> str:
        return f'refit:{self.name}' if self.kind == 'refit' else self.name


def _grid_edge(s, grid) -> bool:
    g = np.asarray(grid, float)
    return bool(len(g) > 1 and (np.isclose(s, g.min()) or np.isclose(s, g.max())))


def _lsq_rss(X, y):
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    return float(r @ r), beta


def _per_joint_torque_cols(name, P, B, j, s):
    return torque_columns(name, P, j, s)[B.rows[(TORQUE, j)]]


def build_term(name: str, P: Pooled, B: Blocks, e: dict, fitrow: dict, grids: Grids,
               kind: str = 'effect', fixed_scales: dict | None = None, joints=None,
               known_delay_s: float = 0.0, record_s: float = np.inf,
               stroke: np.ndarray | None = None) -> Term | None:
    """Columns of candidate ``name`` with its scales chosen on the current residual ``e``
    (cb -> array, fit rows ``fitrow`` cb -> bool) unless ``fixed_scales`` (refit of a known
    effect). ``joints``: None = all joints its channel has (the selection drops joints later).
    Returns None if the data have no rows for it."""
    tq = [j for j in range(3) if (TORQUE, j) in B.rows]
    joints = list(tq if joints is None else [j for j in joints if j in tq])
    fixed = fixed_scales or {}
    if name in ('torque_offset', 'coulomb_asymmetry', 'rotor_inertia', 'stribeck', 'cogging',
                'coulomb_level', 'viscous_level', 'torque_gain'):
        if not joints:
            return None
        cols, labels, groups, scales, edge = {}, [], {}, {}, []
        width = 2 if name == 'cogging' else 1
        p = width * len(joints)
        for i, j in enumerate(joints):
            cb = (TORQUE, j)
            if name in PER_JOINT_SCALE:
                grid = getattr(grids, PER_JOINT_SCALE[name])
                if j in fixed:
                    s = fixed[j]
                else:
                    f = fitrow[cb]
                    tries = list(grid)
                    if name == 'cogging' and stroke is not None:
                        tries = [g for g in grid if g <= stroke[j] / 2] or [min(grid)]
                    res = [(_lsq_rss(_per_joint_torque_cols(name, P, B, j, g)[f], e[cb][f])[0],
                            g) for g in tries]
                    k = int(np.argmin([r[0] for r in res]))
                    lo, hi = tries[max(k - 1, 0)], tries[min(k + 1, len(tries) - 1)]
                    for g in np.geomspace(lo, hi, 15)[1:-1]:
                        res.append((_lsq_rss(_per_joint_torque_cols(name, P, B, j, float(g))[f],
                                             e[cb][f])[0], float(g)))
                    s = float(min(res)[1])
                    if _grid_edge(s, grid):
                        edge.append(f'{PER_JOINT_SCALE[name]} joint {j + 1} at grid edge {s:g}')
                scales[j] = s
                X = _per_joint_torque_cols(name, P, B, j, s)
            elif name == 'coulomb_level':
                X = np.sign(P.qd[B.rows[cb], j])[:, None]
            elif name == 'viscous_level':
                X = P.qd[B.rows[cb], j][:, None]
            elif name == 'torque_gain':
                X = -P.effort[B.rows[cb], j][:, None]
            else:
                X = _per_joint_torque_cols(name, P, B, j, None)
            full = np.zeros((len(B.rows[cb]), p))
            full[:, width * i:width * (i + 1)] = X
            cols[cb] = full
            groups[j] = list(range(width * i, width * (i + 1)))
            labels += [f'{name}[{j + 1}]{"sc"[k] if width == 2 else ""}' for k in range(width)]
        n_sc = len(joints) if name in PER_JOINT_SCALE and not fixed else 0
        t = Term(name, kind, joints, cols, labels, scales, n_sc, edge)
        t.groups = groups
        return t
    if name in ('viscous_nonlinear', 'viscous_temperature_drift', 'payload_mass'):
        if not tq:
            return None
        key = SHARED_SCALE[name]
        grid = list(getattr(grids, key))
        if name == 'viscous_temperature_drift':
            grid = [g for g in grid if g <= 2 * record_s] or [min(grid)]

        def make(s):
            cols = {}
            if name == 'payload_mass':
                U = payload_unit_torque_cached(P, s)
                for j in tq:
                    cols[(TORQUE, j)] = U[B.rows[(TORQUE, j)], j][:, None]
                return cols, ['payload_mass_kg'], {'all': [0]}
            for i, j in enumerate(joints):
                X = np.zeros((len(B.rows[(TORQUE, j)]), len(joints)))
                X[:, i] = _per_joint_torque_cols(name, P, B, j, s)[:, 0]
                cols[(TORQUE, j)] = X
            return cols, [f'{name}[{j + 1}]' for j in joints], {j: [i] for i, j in
                                                                 enumerate(joints)}
        if 'shared' in fixed:
            s = fixed['shared']
        else:
            s = _profile_shared(make, grid, e, fitrow, B)
        cols, labels, groups = make(s)
        edge = ([f'{key} at grid edge {s:g}'] if _grid_edge(s, getattr(grids, key)) and
                'shared' not in fixed else [])
        t = Term(name, kind, tq if name == 'payload_mass' else joints, cols, labels,
                 {'shared': s}, 0 if 'shared' in fixed else 1, edge)
        t.groups = groups
        return t
    if name in INERTIAL_LINKS:
        if not tq:
            return None
        off = 0 if name == 'inertial_link2' else 4
        cols = {(TORQUE, j): P.inertial[B.rows[(TORQUE, j)], j, off:off + 4] for j in tq}
        # parameters the motion cannot see (e.g. link 2's first moment along its own axis)
        # are left out: column norm below 1e-4 of the largest (noise-weighted)
        nrm = np.sqrt(sum(np.sum(X**2, axis=0) / B.floor[cb] ** 2 for cb, X in cols.items()))
        keep = np.flatnonzero(nrm > 1e-4 * nrm.max()) if nrm.max() > 0 else []
        if len(keep) == 0:
            return None
        cols = {cb: X[:, keep] for cb, X in cols.items()}
        t = Term(name, kind, tq, cols, [f'{name}.{INERTIAL_LABELS[i]}' for i in keep])
        t.groups = {'all': list(range(len(keep)))}
        return t
    if name == 'encoder_scale':
        cols = {}
        for j in tq:
            cols[(TORQUE, j)] = -P.enc_tau[B.rows[(TORQUE, j)], j, :]
        if (TCP, None) in B.rows:
            cols[(TCP, None)] = -(P.J * P.cam_q[:, None, :]).reshape(-1, 3)
        if not cols:
            return None
        t = Term(name, kind, [0, 1, 2], cols, [f'encoder_scale[{j + 1}]' for j in range(3)])
        t.groups = {j: [j] for j in range(3)}
        return t
    if name == 'encoder_offset':
        cols = {}
        for j in tq:
            cols[(TORQUE, j)] = -P.off_tau[B.rows[(TORQUE, j)], j, :]
        if (TCP, None) in B.rows:
            cols[(TCP, None)] = -P.J.reshape(-1, 3)
        if not cols:
            return None
        t = Term(name, kind, [0, 1, 2], cols, [f'encoder_offset[{j + 1}]' for j in range(3)])
        t.groups = {j: [j] for j in range(3)}
        return t
    if name in ('backlash', 'joint_elasticity'):
        if (TCP, None) not in B.rows:
            return None
        grid = list(grids.backlash_smoothing) if name == 'backlash' else [None]

        def make(s):
            return ({(TCP, None): tcp_columns(name, P, s)}, [f'{name}[{j + 1}]'
                                                            for j in range(3)],
                    {j: [j] for j in range(3)})
        s = fixed.get('shared', None) if fixed else None
        if s is None and name == 'backlash':
            s = _profile_shared(make, grid, e, fitrow, B)
        cols, labels, groups = make(s)
        t = Term(name, kind, [0, 1, 2], cols, labels, {'shared': s if s is not None else 2.0},
                 1 if name == 'backlash' and not fixed else 0)
        t.groups = groups
        return t
    if name == 'time_delay':
        cbs = [(COMMAND, j) for j in range(3) if (COMMAND, j) in B.rows]
        if not cbs:
            return None
        k0 = int(np.argmin(np.abs(P.delays - known_delay_s)))

        def make_k(k):
            return {cb: (P.cmd_pred[k][:, cb[1]] - P.cmd_pred[k0][:, cb[1]])[:, None]
                    for cb in cbs}
        if 'shared' in fixed:
            k = int(np.argmin(np.abs(P.delays - fixed['shared'])))
        else:
            rss = []
            for k in range(len(P.delays)):
                r = 0.0
                for cb, X in make_k(k).items():
                    f = fitrow[cb]
                    d = e[cb][f] - X[f, 0]                # coefficient 1: the delay itself
                    r += float(d @ d) / B.floor[cb] ** 2
                rss.append(r)
            k = int(np.argmin(rss))
        t = Term(name, kind, [0, 1, 2], make_k(k), ['time_delay.coefficient'],
                 {'shared': float(P.delays[k])}, 0 if 'shared' in fixed else 1,
                 [f'extra_delay_s at grid edge {P.delays[k]:g}'] if k == len(P.delays) - 1
                 else [])
        t.groups = {'all': [0]}
        return t
    raise KeyError(name)


def _profile_shared(make, grid, e, fitrow, B) -> float:
    best = None
    for s in grid:
        cols, labels, _ = make(s)
        G = np.zeros((len(labels), len(labels)))
        h = np.zeros(len(labels))
        yy = 0.0
        for cb, X in cols.items():
            f = fitrow[cb]
            wgt = 1.0 / B.floor[cb] ** 2
            G += wgt * X[f].T @ X[f]
            h += wgt * X[f].T @ e[cb][f]
            yy += wgt * float(e[cb][f] @ e[cb][f])
        beta = np.linalg.lstsq(G, h, rcond=None)[0]
        rss = yy - beta @ h
        if best is None or rss < best[0]:
            best = (rss, s)
    return float(best[1])


def restrict(term: Term, keep_groups: list) -> Term | None:
    """The term with only the parameter groups ``keep_groups`` (joints)."""
    idx = sorted(i for g in keep_groups for i in term.groups[g])
    if not idx:
        return None
    cols = {cb: X[:, idx] for cb, X in term.cols.items()}
    cols = {cb: X for cb, X in cols.items() if np.any(X)}
    if not cols:
        return None
    t = Term(term.name, term.kind, [g for g in keep_groups if g != 'all'] or term.joints,
             cols, [term.labels[i] for i in idx],
             {k: v for k, v in term.scales.items() if k == 'shared' or k in keep_groups},
             (sum(1 for g in keep_groups if g in term.scales) if term.n_scales and
              'shared' not in term.scales else term.n_scales), list(term.edge), term.known)
    remap = {i: n for n, i in enumerate(idx)}
    t.groups = {g: [remap[i] for i in term.groups[g]] for g in keep_groups}
    return t
