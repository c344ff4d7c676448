"""report.json, report.md and PNG figures of a discrepancy run (matplotlib Agg). No rclpy."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .library import TCP, TORQUE


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _heldout(result):
    """Held-out rows per block, the nominal residual and the residual after the named terms
    as full-length channel arrays (NaN where a block has no row)."""
    B = result.extra['blocks']
    hold = result.extra['hold_blocks']
    fr = result.selection
    P = result.pooled
    n = len(P.r)
    out = {'tau0': np.full((n, 3), np.nan), 'tau1': np.full((n, 3), np.nan)}
    for cb in B.keys:
        m = np.isin(B.tb[cb], hold)
        if cb[0] == TORQUE:
            rows = B.rows[cb][m]
            out['tau0'][rows, cb[1]] = B.y[cb][m]
            out['tau1'][rows, cb[1]] = B.y[cb][m] - fr.contributions[cb][m]
        elif cb[0] == TCP:
            out['tcp0'] = B.y[cb][m].reshape(-1, 3)
            out['tcp1'] = (B.y[cb] - fr.contributions[cb])[m].reshape(-1, 3)
        else:
            out.setdefault('cmd0', []).append(B.y[cb][m])
            out.setdefault('cmd1', []).append(B.y[cb][m] - fr.contributions[cb][m])
    return out


def plots(result, out: Path) -> list[str]:
    """Residual figures: torque vs time and vs speed (held-out part, nominal and with the
    named terms), TCP and command residuals, first-step candidate scores."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    P = result.pooled
    H = _heldout(result)
    label = result.report['effect']
    files = []
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), sharey=False)
    for j, ax in enumerate(axes):
        m = np.isfinite(H['tau0'][:, j])
        ax.plot(P.qd[m, j], H['tau0'][m, j], '.', ms=1.5, alpha=0.5, label='nominal model')
        if result.selection.selected:
            ax.plot(P.qd[m, j], H['tau1'][m, j], '.', ms=1.5, alpha=0.5, label=f'+ {label}')
        ax.set_xlabel(f'joint {j + 1} speed [rad/s]')
        ax.set_ylabel('torque residual [N m]')
        ax.grid(alpha=0.3)
    axes[0].legend(markerscale=6, fontsize=8)
    fig.suptitle('held-out torque residual vs speed')
    fig.tight_layout()
    fig.savefig(out / 'residual_vs_speed.png', dpi=90)
    plt.close(fig)
    files.append('residual_vs_speed.png')
    fig, axes = plt.subplots(3, 1, figsize=(11, 6.5), sharex=True)
    for j, ax in enumerate(axes):
        m = np.isfinite(H['tau0'][:, j])
        ax.plot(P.t_global[m], H['tau0'][m, j], '.', ms=1.2, label='nominal model')
        if result.selection.selected:
            ax.plot(P.t_global[m], H['tau1'][m, j], '.', ms=1.2, label=f'+ {label}')
        ax.set_ylabel(f'joint {j + 1} [N m]')
        ax.grid(alpha=0.3)
    axes[0].legend(markerscale=6, fontsize=8)
    axes[-1].set_xlabel('time since first sample [s] (held-out blocks)')
    fig.tight_layout()
    fig.savefig(out / 'residual_vs_time.png', dpi=90)
    plt.close(fig)
    files.append('residual_vs_time.png')
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.6))
    if 'tcp0' in H:
        axes[0].plot(np.linalg.norm(H['tcp0'], axis=1) * 1e3, '.', ms=1.5,
                     label='camera - FK(encoders)')
        axes[0].plot(np.linalg.norm(H['tcp1'], axis=1) * 1e3, '.', ms=1.5, label=f'+ {label}')
        axes[0].set_ylabel('TCP residual [mm]')
        axes[0].set_xlabel('camera sample (held-out)')
        axes[0].legend(markerscale=6, fontsize=8)
    if 'cmd0' in H:
        axes[1].plot(np.linalg.norm(np.array(H['cmd0']), axis=0), '.', ms=1.5,
                     label='effort - cmd(t - 4T)')
        axes[1].plot(np.linalg.norm(np.array(H['cmd1']), axis=0), '.', ms=1.5,
                     label=f'+ {label}')
        axes[1].set_ylabel('command residual [N m]')
        axes[1].set_xlabel('sample (held-out)')
        axes[1].legend(markerscale=6, fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / 'tcp_and_command.png', dpi=90)
    plt.close(fig)
    files.append('tcp_and_command.png')
    cands = result.report['candidates']
    fig, ax = plt.subplots(figsize=(8, 0.25 * len(cands) + 1.5))
    names = [c['effect'] for c in cands]
    ev = [max(-c['delta_bic'], 0.0) for c in cands]
    ax.barh(names[::-1], ev[::-1],
            color=['C2' if c['eligible'] else 'C7' for c in cands[::-1]])
    ax.set_xscale('symlog', linthresh=10)
    ax.axvline(result.report['decision']['bic_threshold'], color='k', ls='--', lw=1)
    ax.set_xlabel('-dBIC, first step (green: eligible; dashed: threshold)')
    fig.tight_layout()
    fig.savefig(out / 'candidates.png', dpi=90)
    plt.close(fig)
    files.append('candidates.png')
    return files


def _fmt(x):
    if isinstance(x, list):
        return [float(f'{v:.4g}') for v in x]
    return float(f'{x:.4g}')


def data_line(report: dict) -> str:
    """One sentence on the data the answer comes from: complete, or with gaps (how many
    samples missing, in how many pieces it was analysed)."""
    q = report.get('data_quality')
    if not q:
        return 'Data: not checked for gaps.'
    if q['complete']:
        return (f"Data: complete ({q['runs']} run(s), no gap and no duplicate in joint states, "
                'commands and camera).')
    s = 'Data WITH GAPS: '
    if q['joint_states_complete']:
        s += 'joint states complete; '
    else:
        s += (f"{q['missing_joint_states']} joint states missing; {q['runs']} run(s) analysed "
              f"as {q['pieces_analysed']} piece(s) split at the long gaps, short gaps "
              'interpolated; ')
    return s + f"{len(q['notes'])} series with gaps or duplicates (listed below)."


def answer_line(report: dict) -> str:
    """One sentence whose words match the confidence."""
    c = report['confidence']
    if report['effects']:
        parts = [f"{n['effect'] if n['kind'] != 'refit' else 'refit of ' + n['effect']} "
                 f"(joints {n['joints']}, confidence {n['confidence']:.2f}, "
                 + (f"indistinguishable here from {n['indistinguishable_from']}, "
                    if n.get('indistinguishable_from') else '') +
                 f"{100 * n['share_of_explained']:.0f} % of the explained residual)"
                 for n in report['effects']]
        s = 'named, in order: ' + '; '.join(parts)
        red = report['heldout_reduction']
        if red is not None:
            s += f'; held-out residual (all joints and channels) -{100 * red:.0f} %'
        if report['unexplained']:
            s += '; still UNEXPLAINED: ' + report['unexplained']['summary']
        return s
    if report['effect'] == 'ambiguous':
        a = report['ambiguous']
        split = ', '.join(f'{k} {100 * v:.0f} %' for k, v in a['wins'].items())
        return (f"AMBIGUOUS: the bootstrap splits ({split}), best {a['best']} supported in "
                f"{100 * a['support']:.0f} % of replicates (< "
                f"{100 * report['decision']['min_confidence']:.0f} %); nothing named"
                + ('; ' + report['unexplained']['summary'] if report['unexplained'] else ''))
    pf = report.get('partial_fits') or []
    if pf and report['effect'] in ('unexplained', 'none'):
        return ('UNEXPLAINED residual: ' + (report['unexplained'] or {}).get('summary', '') +
                '; partly fitted by ' + ', '.join(
                    f"{p['effect']} ({p['block']}: {p['explained_rms']:.3g} explained, "
                    f"{p['remaining_rms']:.3g} left)" for p in pf) +
                ' -- not named: no candidate describes it')
    if report['effect'] == 'unexplained':
        return ('UNEXPLAINED residual, no candidate fits (' +
                report['unexplained']['why_not_named'] + '): ' +
                report['unexplained']['summary'] + f' (no candidate in {100 * c:.0f} % of '
                'bootstrap replicates)')
    return (f'none: residual at the noise floor on every joint and channel (no candidate in '
            f'{100 * c:.0f} % of bootstrap replicates)')


def markdown(report: dict, files: list[str]) -> str:
    lines = ['# Model-discrepancy report', '',
             f"**Answer: `{report['effect']}`**, confidence {report['confidence']:.2f} "
             '(block bootstrap of each selection step).', '', answer_line(report), '',
             data_line(report), '']
    lines += [f'- {n}' for n in (report.get('data_quality') or {}).get('notes', [])]
    if lines[-1] != '':
        lines.append('')
    for n in report['effects']:
        lines += [f"## {n['order']}. `{n['effect']}` ({n['kind']}"
                  + (', refit of an effect already in the model' if n['refit_of_known']
                     else '') + ')', '',
                  f"joints {n['joints']}, channel {n['channel']}, dBIC {n['delta_bic']:.1f}, "
                  f"held-out dBIC {n['heldout_delta_bic']:.1f}, confidence "
                  f"{n['confidence']:.2f}, share of explained residual "
                  f"{100 * n['share_of_explained']:.0f} %", '',
                  '| parameter | value | 95 % interval |', '|---|---|---|']
        for k, v in n['parameters'].items():
            ci = ('grid (profiled)' if v.get('ci95') is None
                  else f"{_fmt(v['ci95'][0])} .. {_fmt(v['ci95'][1])}")
            lines.append(f"| {k} | {_fmt(v['value'])} | {ci} |")
        if n['flags']:
            lines += ['', 'Flags: ' + '; '.join(n['flags'])]
        lines.append('')
    b, a, fl = report['rms_before'], report['rms_after'], report['noise_floor']
    lines += ['| held-out RMS | before | after | noise floor |', '|---|---|---|---|']
    for k in b:
        unit = '[m]' if k == 'tcp' else '[N m]'
        lines.append(f'| {k} {unit} | {b[k]:.4g} | {a[k]:.4g} | {fl[k]:.3g} |')
    lines += ['', '| rank | candidate (first step) | kind | dBIC | joints | fit RMS reduction '
              '| bootstrap wins | why not |', '|---|---|---|---|---|---|---|---|']
    for c in report['candidates']:
        lines.append(f"| {c['rank']} | {c['effect']} | {c['kind']} | {c['delta_bic']:.1f} | "
                     f"{c['joints']} | {100 * c['fit_rms_reduction']:.0f} % | "
                     f"{c.get('bootstrap_wins', 0.0):.2f} | {c['reason']} |")
    lines += ['', '| step | added | support | held-out dBIC | stop reason |',
              '|---|---|---|---|---|']
    for i, s in enumerate(report['steps']):
        hd = '-' if s['heldout_delta_bic'] is None else f"{s['heldout_delta_bic']:.1f}"
        lines.append(f"| {i + 1} | {s['added'] or '-'} | {s['support']:.2f} | {hd} | "
                     f"{s['stop_reason']} |")
    sm = [s for s in report['smoothing'] if s['adapted']]
    if sm:
        lines += ['', 'Smoothing adapted to fast reversals: ' + ', '.join(
            f"{s['run']} window {1e3 * s['window_s']:.0f} ms (reversals every "
            f"{s['reversal_interval_s']:.2f} s)" for s in sm)]
    lines += ['', f"Updated model: `{report.get('updated_model')}`", '']
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
