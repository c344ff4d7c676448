"""Friction-map figures like thesis figs. 4.2-4.4 (matplotlib, Agg backend). No rclpy."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .friction_fit import JointResult


def plot_joint(result: JointResult, path: str | Path, truth=None) -> Path:
    """One joint: eq. 4.8 points per sign, polynomials, parametric fit with its 95 % band,
    optional ``truth`` (JointFriction) dashed. Returns the PNG path."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    path = Path(path)
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=110)
    c = np.array([p.speed for p in result.points])
    if len(c):
        ax.errorbar(np.r_[c, -c], [p.f_pos for p in result.points]
                    + [p.f_neg for p in result.points],
                    yerr=2 * np.r_[[p.sem for p in result.points] * 2], fmt='o', ms=4,
                    color='k', label='measured, per sign')
        ax.plot(np.r_[c, -c], np.r_[[p.tau_f for p in result.points],
                                    [-p.tau_f for p in result.points]],
                'x', color='tab:red', label=r'eq. 4.8 $(\tau_+ - \tau_-)/2$')
    if result.binned and result.friction is not None:
        vb, fb = result.binned
        ax.plot(vb, fb, 'o', ms=3, color='k', label='measured, mean per speed bin')
        lo, hi = result.friction.valid_range
        v = np.r_[-np.geomspace(hi, lo, 200), np.nan, np.geomspace(lo, hi, 200)]
        j = result.friction
        ax.plot(v, j.parametric(v), color='tab:blue', label=(
            f'fit: $F_{{c+}}$={j.coulomb_positive:.3g}, $F_{{c-}}$={j.coulomb_negative:.3g}, '
            f'$F_s$={j.static:.3g}, offset {j.offset:.3g} N m, $F_v$={j.viscous:.3g} N m s/rad'))
        if truth is not None:
            ax.plot(v, truth.torque(v), ':', color='gray', label='truth')
    if result.parametric is not None:
        lo, hi = result.friction.valid_range
        v = np.r_[-np.linspace(hi, lo, 200), np.nan, np.linspace(lo, hi, 200)]
        pf = result.parametric
        y = pf.torque(v)
        band = pf.band95(v)
        ax.plot(v, y, color='tab:blue', label=(
            f'Coulomb+viscous+Stribeck: $F_c$={pf.coulomb:.2f}, $F_s$={pf.static:.2f} N m, '
            f'$v_s$={pf.stribeck_velocity:.3f} rad/s, $F_v$={pf.viscous:.2f} N m s/rad'))
        if np.any(np.isfinite(band)):
            ax.fill_between(v, y - band, y + band, color='tab:blue', alpha=0.2,
                            label='95 % confidence band')
        for coef, vv, lab in ((result.poly_pos, np.linspace(lo, hi, 200), 'polynomial v>0'),
                              (result.poly_neg, -np.linspace(lo, hi, 200), 'polynomial v<0')):
            if coef is not None:
                ax.plot(vv, np.polynomial.polynomial.polyval(vv, coef), '--',
                        label=f'{lab} (order {len(coef) - 1})')
        if truth is not None:
            ax.plot(v, truth.torque(v), ':', color='gray', label='truth (simulated plant)')
    ax.axhline(0, color='gray', lw=0.5)
    ax.axvline(0, color='gray', lw=0.5)
    ax.set_xlabel('joint speed [rad/s]')
    ax.set_ylabel('friction torque [N m]')
    title = f'Friction characteristics, {result.name}'
    if result.error:
        title += f'\n{result.error}'
    ax.set_title(title, fontsize=10)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc='upper left')
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
