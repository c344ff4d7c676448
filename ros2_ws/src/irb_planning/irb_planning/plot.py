"""Plots of a plan like the thesis's figures 6.2-6.4 (matplotlib, Agg; no ROS)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_plan(out: str | Path, theta: np.ndarray, theta_dot: np.ndarray, t: np.ndarray,
              qd: np.ndarray, tau: np.ndarray, title: str = '',
              baseline: dict | None = None) -> Path:
    """Write a 2 x 2 figure: theta_dot(theta) (fig. 6.2), joint speeds (6.3), torques,
    power sum_i |tau_i qd_i| (6.4). theta, theta_dot (N,); t (M,); qd, tau (M, n).
    ``baseline`` optional {'theta', 'theta_dot', 't', 'power'} drawn dashed."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    ax[0, 0].plot(theta, theta_dot, label='plan')
    ax[0, 0].set(xlabel='theta [rad]', ylabel='theta_dot [rad/s]', title='theta-speed')
    for i in range(qd.shape[1]):
        ax[0, 1].plot(t, qd[:, i], label=f'joint {i + 1}')
        ax[1, 0].plot(t, tau[:, i], label=f'joint {i + 1}')
    ax[0, 1].set(xlabel='t [s]', ylabel='qd [rad/s]', title='joint speeds')
    ax[1, 0].set(xlabel='t [s]', ylabel='tau [N m]', title='torques')
    power = np.abs(tau * qd).sum(axis=1)
    ax[1, 1].plot(t, power, label='plan')
    ax[1, 1].set(xlabel='t [s]', ylabel='P [W]', title='power sum |tau_i qd_i|')
    if baseline is not None:
        ax[0, 0].plot(baseline['theta'], baseline['theta_dot'], '--', label='trapezoid')
        ax[1, 1].plot(baseline['t'], baseline['power'], '--', label='trapezoid')
    for a in ax.ravel():
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(title)
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
