"""A trajectory message played as a joint trajectory controller plays it, written here for
the tests and benchmarks and sharing nothing with the planner's check (verify.py):

* stamps as the message carries them (``irb_description.stamps.sec_nanosec``: 1 ns);
* per interval the quintic through (q, qd, qdd) at both ends, its coefficients from a
  3 x 3 linear solve (verify.py uses closed-form coefficients);
* sampled on a global 10 kHz clock (t = k / rate from the first stamp), as a controller's
  update loop samples it, plus every point's own stamp;
* TCP velocity J qd and acceleration J qdd + (dJ/dt) qd from pinocchio's Jacobian, dJ/dt by a
  central difference along qd (verify.py differentiates its own DH product in closed form);
* torque: pinocchio RNEA + the model's friction map (the planner's evaluator integrates the
  theta profile instead of playing the message).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from irb_description.stamps import sec_nanosec

RATE_HZ = 10_000.0
#: [s] message intervals shorter than this are evaluated at every sample whatever the stride
SHORT_INTERVAL_S = 1.5e-3
#: instants per short interval (besides the clock's)
SHORT_SAMPLES = 64


@dataclass
class Played:
    t: np.ndarray              # (M,) [s]
    q: np.ndarray              # (M, n)
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray            # (L, n) [N m] at the samples idx
    tcp_speed: np.ndarray      # (L,) [m/s] at the samples idx
    tcp_accel: np.ndarray      # (L,) [m/s^2] at the samples idx
    stamps: np.ndarray         # (K,) [s] the message's stamps
    idx: np.ndarray            # (L,) the samples the TCP and torque are evaluated at


def message_stamps(t) -> np.ndarray:
    """The stamps as a receiver reads them from (sec, nanosec)."""
    return np.array([s + 1e-9 * ns for s, ns in map(sec_nanosec, np.asarray(t, float))])


def play(model, t, q, qd, qdd, rate: float = RATE_HZ, stride: int = 1) -> Played:
    """Play the message points (t (K,) [s] as planned; q, qd, qdd (K, n)) at ``rate``;
    ``stride`` > 1 evaluates the TCP and torque on every stride-th sample only (the peaks
    of the quintic's q, qd, qdd keep the full rate; so do intervals shorter than
    SHORT_INTERVAL_S)."""
    ts = message_stamps(t)
    q, qd, qdd = (np.asarray(x, float) for x in (q, qd, qdd))
    clock = ts[0] + np.arange(int(np.floor((ts[-1] - ts[0]) * rate)) + 1) / rate
    # intervals shorter than SHORT_INTERVAL_S (the twin points around a blend end, where the
    # torque and TCP acceleration spike within 1 ms) also at SHORT_SAMPLES instants: their
    # peaks then do not depend on the clock's phase (a controller's clock may hit the top)
    short = np.flatnonzero(np.diff(ts) < SHORT_INTERVAL_S)
    fine = [np.linspace(ts[j], ts[j + 1], SHORT_SAMPLES) for j in short]
    tt = np.unique(np.concatenate([clock, ts] + fine))
    k = np.clip(np.searchsorted(ts, tt, side='right') - 1, 0, ts.size - 2)
    out_q, out_v, out_a = (np.empty((tt.size, q.shape[1])) for _ in range(3))
    for j in range(ts.size - 1):
        sel = k == j
        T = ts[j + 1] - ts[j]
        A = np.array([[T ** 3, T ** 4, T ** 5], [3 * T ** 2, 4 * T ** 3, 5 * T ** 4],
                      [6 * T, 12 * T ** 2, 20 * T ** 3]])
        rhs = np.stack([q[j + 1] - q[j] - qd[j] * T - 0.5 * qdd[j] * T ** 2,
                        qd[j + 1] - qd[j] - qdd[j] * T, qdd[j + 1] - qdd[j]])
        c3, c4, c5 = np.linalg.solve(A, rhs)
        s = (tt[sel] - ts[j])[:, None]
        out_q[sel] = q[j] + qd[j] * s + 0.5 * qdd[j] * s ** 2 + c3 * s ** 3 + c4 * s ** 4 \
            + c5 * s ** 5
        out_v[sel] = qd[j] + qdd[j] * s + 3 * c3 * s ** 2 + 4 * c4 * s ** 3 + 5 * c5 * s ** 4
        out_a[sel] = qdd[j] + 6 * c3 * s + 12 * c4 * s ** 2 + 20 * c5 * s ** 3
    # every sample inside the short intervals, whatever the stride (a stride stepped over
    # their spike: 45.36 vs 46.28 N m on joint 1 at stride 2)
    inside = np.isin(k, short) if short.size else np.zeros(tt.size, bool)
    idx = np.unique(np.concatenate([np.arange(0, tt.size, stride),
                                    np.searchsorted(tt, ts), np.flatnonzero(inside)]))
    h = 1e-6
    vel, acc, tau = [], [], []
    for a, b, c in zip(out_q[idx], out_v[idx], out_a[idx]):
        J = model.jacobian(a)
        dJ = (model.jacobian(a + h * b) - model.jacobian(a - h * b)) / (2 * h)
        vel.append(J @ b)
        acc.append(J @ c + dJ @ b)
        tau.append(model.inverse_dynamics(a, b, c))
    tau = np.array(tau) + model.friction.torque(out_v[idx])
    return Played(tt, out_q, out_v, out_a, tau, np.linalg.norm(vel, axis=1),
                  np.linalg.norm(acc, axis=1), ts, idx)
