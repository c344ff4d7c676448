"""report.json, report.md and PNG figures of a discrepancy run (matplotlib Agg). No rclpy."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .library import COMMAND, TCP, TORQUE, contribution


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def plots(result, out: Path) -> list[str]:
    """Residual figures: torque vs time and vs speed (before/after on the held-out part),
    TCP residual vs time, candidate scores. Returns the file names."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    H, sel = result.holdout, result.selection
    corr = {}
    if sel.winner is not None:
        ch, pred = contribution(sel.effect, sel.winner.block, H)
        corr[ch] = pred
    files = []
    # torque residual vs speed, per joint
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharey=False)
    for j, ax in enumerate(axes):
        m = H.mask[:, j]
        ax.plot(H.qd[m, j], H.r[m, j], '.', ms=1.5, alpha=0.5, label='nominal model')
        if TORQUE in corr:
            ax.plot(H.qd[m, j], H.r[m, j] - corr[TORQUE][m, j], '.', ms=1.5, alpha=0.5,
                    label=f'+ {sel.effect}')
        ax.set_xlabel(f'joint {j + 1} speed [rad/s]')
        ax.set_ylabel('torque residual [N m]')
        ax.grid(alpha=0.3)
    axes[0].legend(markerscale=6, fontsize=8)
    fig.suptitle('held-out torque residual vs speed')
    fig.tight_layout()
    fig.savefig(out / 'residual_vs_speed.png', dpi=90)
    plt.close(fig)
    files.append('residual_vs_speed.png')
    # torque residual vs time
    fig, axes = plt.subplots(3, 1, figsize=(11, 6.5), sharex=True)
    for j, ax in enumerate(axes):
        m = H.mask[:, j]
        ax.plot(H.t_global[m], H.r[m, j], '.', ms=1.2, label='nominal model')
        if TORQUE in corr:
            ax.plot(H.t_global[m], H.r[m, j] - corr[TORQUE][m, j], '.', ms=1.2,
                    label=f'+ {sel.effect}')
        ax.set_ylabel(f'joint {j + 1} [N m]')
        ax.grid(alpha=0.3)
    axes[0].legend(markerscale=6, fontsize=8)
    axes[-1].set_xlabel('time since first sample [s] (held-out blocks)')
    fig.tight_layout()
    fig.savefig(out / 'residual_vs_time.png', dpi=90)
    plt.close(fig)
    files.append('residual_vs_time.png')
    # TCP and command channels
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.6))
    if len(H.r_tcp):
        e0 = np.linalg.norm(H.r_tcp, axis=1) * 1e3
        axes[0].plot(e0, '.', ms=1.5, label='camera - FK(encoders)')
        if TCP in corr:
            axes[0].plot(np.linalg.norm(H.r_tcp - corr[TCP], axis=1) * 1e3, '.', ms=1.5,
                         label=f'+ {sel.effect}')
        axes[0].set_ylabel('TCP residual [mm]')
        axes[0].set_xlabel('camera sample (held-out)')
        axes[0].legend(markerscale=6, fontsize=8)
    if len(H.r_cmd):
        axes[1].plot(np.linalg.norm(H.r_cmd, axis=1), '.', ms=1.5, label='effort - cmd(t - 4T)')
        if COMMAND in corr:
            axes[1].plot(np.linalg.norm(H.r_cmd - corr[COMMAND], axis=1), '.', ms=1.5,
                         label=f'+ {sel.effect}')
        axes[1].set_ylabel('command residual [N m]')
        axes[1].set_xlabel('sample (held-out)')
        axes[1].legend(markerscale=6, fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / 'tcp_and_command.png', dpi=90)
    plt.close(fig)
    files.append('tcp_and_command.png')
    # candidate scores
    fig, ax = plt.subplots(figsize=(8, 3.8))
    names = [f.name for f in sel.ranked]
    scores = [min(f.score, 0.0) for f in sel.ranked]
    ax.barh(names[::-1], [-s for s in scores[::-1]])
    ax.set_xscale('symlog', linthresh=10)
    ax.axvline(result.report['decision']['bic_threshold'], color='k', ls='--', lw=1)
    ax.set_xlabel('-dBIC (evidence; dashed: threshold)')
    fig.tight_layout()
    fig.savefig(out / 'candidates.png', dpi=90)
    plt.close(fig)
    files.append('candidates.png')
    return files


def markdown(report: dict, files: list[str]) -> str:
    lines = ['# Model-discrepancy report', '',
             f"**Effect: `{report['effect']}`** (joints {report['joints'] or '-'}, channel "
             f"{report['channel'] or '-'}), confidence {report['confidence']:.2f} "
             f"(block bootstrap).", '']
    if report['effect'] != 'none':
        red = report['heldout_reduction']
        lines += [f"Held-out residual reduction in its channel: {100 * red:.0f} %.", '',
                  '| parameter | value | 95 % interval |', '|---|---|---|']

        def r(x):
            return [float(f'{v:.4g}') for v in x] if isinstance(x, list) else float(f'{x:.4g}')
        for k, v in report['parameters'].items():
            ci = ('grid (profiled)' if v['ci95'] is None
                  else f"{r(v['ci95'][0])} .. {r(v['ci95'][1])}")
            lines.append(f"| {k} | {r(v['value'])} | {ci} |")
        lines.append('')
    b, a = report['rms_before'], report['rms_after']
    fmt = lambda x: '-' if x is None else f'{x:.4g}'  # noqa: E731
    lines += ['| held-out RMS | before | after |', '|---|---|---|']
    for j in range(3):
        lines.append(f"| joint {j + 1} torque [N m] | {fmt(b['torque_nm'][j])} | "
                     f"{fmt(a['torque_nm'][j])} |")
    lines.append(f"| TCP [m] | {fmt(b['tcp_m'])} | {fmt(a['tcp_m'])} |")
    if b['command_nm']:
        lines.append(f"| command channel [N m] | {fmt(float(np.linalg.norm(b['command_nm'])))}"
                     f" | {fmt(float(np.linalg.norm(a['command_nm'])))} |")
    lines += ['', '| rank | candidate | dBIC | joints | fit RMS reduction | bootstrap wins |',
              '|---|---|---|---|---|---|']
    for c in report['candidates']:
        lines.append(f"| {c['rank']} | {c['effect']} | {c['delta_bic']:.1f} | {c['joints']} |"
                     f" {100 * c['fit_rms_reduction']:.0f} % | {c['bootstrap_wins']:.2f} |")
    loc = report['localisation']['largest']
    lines += ['', f"Largest nominal torque residual: joint {loc['joint']}, speeds "
              f"{loc['speed_range_rad_s']} rad/s.", '',
              f"Updated model: `{report.get('updated_model')}`", '']
    lines += [f'![{f}]({f})' for f in files]
    return '\n'.join(lines) + '\n'


def write_report(result, out_dir: str | Path, make_plots: bool = True) -> Path:
    """Write report.json (+ report.md and PNGs) into ``out_dir``; returns report.json."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = plots(result, out) if make_plots else []
    result.report['plots'] = files
    (out / 'report.md').write_text(markdown(result.report, files))
    path = out / 'report.json'
    path.write_text(json.dumps(result.report, indent=1, default=_json_default))
    return path
