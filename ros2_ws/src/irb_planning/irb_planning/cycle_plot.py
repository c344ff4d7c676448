"""Figures of a planned work cycle (matplotlib, Agg): power over one cycle for the optimum and
baseline A, and each motion's energy-duration front with the chosen point."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def plot_timeline(plan, path: Path) -> Path:
    """Power [W] over one cycle: the optimum and baseline A, operations shaded."""
    from .cycle import timeline
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4.2))
    top = 0.0
    for choices, label, style in ((plan.baseline_a['choices'], 'baseline A: fastest motions, '
                                   f'motors hold ({plan.baseline_a["total_j"]:.0f} J)', 'C3'),
                                  (plan.solution.choices, 'planned: durations and modes '
                                   f'({plan.solution.total_j:.0f} J)', 'C0')):
        t, p = timeline(choices, plan.fronts, plan.modes)
        ax.plot(t, p, color=style, lw=1.4, label=label + (
            f', peak {p.max():.0f} W' if p.max() > 1500 else ''))
        top = max(top, float(np.percentile(p, 97)))
    t0 = 0.0
    for k, c in enumerate(plan.solution.choices):
        d = c['duration_s']
        ax.axvspan(t0, t0 + d, color='0.9' if k % 2 else '0.97', zorder=0)
        ax.text(t0 + d / 2, 0.02, c['name'] + ('' if c['kind'] == 'motion'
                                               else f'\n[{c["mode"]}]'),
                ha='center', va='bottom', fontsize=7, transform=ax.get_xaxis_transform())
        t0 += d
    ax.set_xlim(0, plan.solution.takt_s)
    ax.set_ylim(0, max(1.6 * top, 400.0))      # short peaks of fast motions clipped
    ax.set_xlabel('time in the cycle [s]')
    ax.set_ylabel('electrical power [W]')
    ax.set_title(f'one cycle, takt {plan.solution.takt_s:g} s')
    ax.legend(loc='upper right', fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_fronts(plan, path: Path) -> Path:
    """Each motion's energy-duration front (energy-optimal plans), its time-optimal plan and
    the chosen duration."""
    plt = _plt()
    fronts = plan.fronts
    fig, axes = plt.subplots(1, len(fronts), figsize=(3.6 * len(fronts), 3.4), squeeze=False)
    chosen = {c['name']: c for c in plan.solution.choices if c['kind'] == 'motion'}
    for ax, (name, f) in zip(axes[0], fronts.items()):
        d = np.array(sorted(f.points))
        e = np.array([f.points[x]['energy_j'] for x in d])
        ax.plot(d, e, 'o-', label='energy-optimal')
        ax.plot([f.fastest['duration_s']], [f.fastest['energy_j']], 's', color='C3',
                label='time-optimal (A)')
        c = chosen[name]
        ax.plot([c['duration_s']], [c['energy_j']], '*', ms=14, color='C2', label='chosen')
        ax.set_title(name, fontsize=9)
        ax.set_xlabel('duration [s]')
        ax.set_ylabel('electrical energy [J]')
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
