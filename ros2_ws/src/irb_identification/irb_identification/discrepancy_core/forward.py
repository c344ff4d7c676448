"""Forward selection of several effects with a joint refit, held-out stopping, bootstrap.

All candidates (terms.py: the 11 physical effects, the model-error candidates, and refits of
effects the model file already has) are columns of one weighted least-squares problem over the
residual channel blocks cb (torque per joint, TCP, command per joint), each block weighted by
1 / floor_cb^2 (its noise floor). Sufficient statistics (X'X, X'y, y'y, n) are accumulated per
time block, so any block weighting (fit part, held-out part, block-bootstrap counts) is a
weighted sum of small matrices and a refit costs one small solve.

Step i, with the set S already selected (jointly refitted on the fit part):

* every block gets ONE effective sample size n_eff,cb = n_cb / tau_cb, tau_cb the integrated
  autocorrelation time of the residual that S and all candidates of the step leave together
  (what nothing explains, ~ the noise), shared by all candidates (scores are comparable);
* each candidate's joints: parameter groups (joints) whose own dBIC is negative;
* score dBIC_c = sum_cb n_eff,cb ln(RSS_cb(S + c) / RSS_cb(S)) + k_c ln(n_eff of its blocks),
  k_c = parameters + profiled scales, RSS from the JOINT refit of S + c;
* eligible: plausible parameters (``plausibility``), dBIC_c < -bic_threshold and a fit RMS
  reduction of at least ``min_fit_reduction`` on its blocks -- or, where every block of the
  candidate has a white noise measured in the data (the camera, ``Blocks.white``) and the
  residual stands out of it (excess RMS >= ``min_excess`` x the noise), a reduction of at
  least ``min_excess_reduction`` of the residual above that noise. Near the noise floor the
  noise dilutes the plain reduction: a backlash of 80 urad on joint 3 (~60 um at the TCP
  against 37 um of camera noise) explained 90 % of what stands above the noise and 21 % of
  the RMS with the noise in it. Far above the floor both measures agree;
* the best eligible candidate is added if it also lowers the held-out residual significantly
  (sum_cb n_eff,cb,held-out ln(RSS_h(S + c) / RSS_h(S)) < -heldout_threshold, parameters from
  the fit part) and wins at least ``min_confidence`` of the block-bootstrap replicates of the
  step's decision; otherwise selection stops. The step's bootstrap support is its confidence.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .library import TCP
from .selection import tau_int
from .terms import Blocks, Term, restrict


@dataclass(frozen=True)
class Decision:
    bic_threshold: float = 30.0
    heldout_threshold: float = 10.0
    min_confidence: float = 0.6
    min_fit_reduction: float = 0.25
    min_excess_reduction: float = 0.5
    min_excess: float = 0.5
    n_boot: int = 40
    seed: int = 0
    max_terms: int = 4


class Stats:
    """Per-time-block sufficient statistics of the universe columns on every block."""

    def __init__(self, B: Blocks, e: dict, terms: list[Term]):
        self.B = B
        self.terms = terms
        self.offsets = []
        p = 0
        for t in terms:
            self.offsets.append(list(range(p, p + t.p)))
            p += t.p
        self.p = p
        self.tbs = np.unique(np.concatenate([B.tb[cb] for cb in B.keys]))
        T = len(self.tbs)
        # column scaling for conditioning
        sq = np.zeros(p)
        for cb in B.keys:
            for t, off in zip(terms, self.offsets):
                if cb in t.cols:
                    sq[off] += np.sum(t.cols[cb] ** 2, axis=0) / B.floor[cb] ** 2
        self.colscale = np.where(sq > 0, np.sqrt(sq), 1.0)
        self.G, self.h, self.yy, self.n, self.act = {}, {}, {}, {}, {}
        for cb in B.keys:
            act = [i for t, off in zip(terms, self.offsets) if cb in t.cols
                   for i, c in zip(off, t.cols[cb].T) if np.any(c)]
            X = np.zeros((len(B.rows[cb]), len(act)))
            pos = {i: k for k, i in enumerate(act)}
            for t, off in zip(terms, self.offsets):
                if cb in t.cols:
                    for i, c in zip(off, t.cols[cb].T):
                        if i in pos:
                            X[:, pos[i]] = c
            act = np.array(act, int)
            X /= self.colscale[act]
            wgt = 1.0 / B.floor[cb] ** 2
            y = e[cb]
            ti = np.searchsorted(self.tbs, B.tb[cb])
            order = np.argsort(ti, kind='stable')
            Xo, yo = X[order], y[order]
            bounds = np.searchsorted(ti[order], np.arange(T + 1))
            pc = len(act)
            G = np.zeros((T, pc, pc))
            h = np.zeros((T, pc))
            yy = np.zeros(T)
            n = np.diff(bounds).astype(float)
            for k in range(T):
                a0, a1 = bounds[k], bounds[k + 1]
                if a1 > a0:
                    Xk, yk = Xo[a0:a1], yo[a0:a1]
                    G[k] = wgt * Xk.T @ Xk
                    h[k] = wgt * Xk.T @ yk
                    yy[k] = wgt * float(yk @ yk)
            self.G[cb], self.h[cb], self.yy[cb], self.n[cb], self.act[cb] = G, h, yy, n, act

    def weighted(self, w: np.ndarray) -> dict:
        """cb -> (G (p, p), h (p,), y'y, n) summed over time blocks with weights w (T,)."""
        out = {}
        for cb in self.B.keys:
            act = self.act[cb]
            G = np.zeros((self.p, self.p))
            h = np.zeros(self.p)
            if len(act):
                G[np.ix_(act, act)] = np.einsum('t,tij->ij', w, self.G[cb])
                h[act] = w @ self.h[cb]
            out[cb] = (G, h, float(w @ self.yy[cb]), float(w @ self.n[cb]))
        return out

    @staticmethod
    def solve(Wd: dict, A: list) -> np.ndarray:
        if not A:
            return np.zeros(0)
        G = sum(v[0][np.ix_(A, A)] for v in Wd.values())
        h = sum(v[1][A] for v in Wd.values())
        beta, *_ = np.linalg.lstsq(G, h, rcond=1e-9)   # scaled columns: cond(X) < 3e4
        return beta

    @staticmethod
    def rss(Wd: dict, A: list, beta: np.ndarray) -> dict:
        out = {}
        for cb, (G, h, yy, n) in Wd.items():
            if A:
                r = yy - 2 * beta @ h[A] + beta @ G[np.ix_(A, A)] @ beta
            else:
                r = yy
            out[cb] = max(float(r), 1e-12 * max(n, 1.0))
        return out

    def unscale(self, A: list, beta: np.ndarray) -> np.ndarray:
        return beta / self.colscale[A]


@dataclass
class Step:
    """One forward step: the added term (or None), its score, held-out score, support."""

    added: str | None
    candidates: list
    wins: dict
    support: float
    heldout_delta: float | None = None
    stop_reason: str = ''
    best: str | None = None
    aliases: list = field(default_factory=list)


@dataclass
class ForwardResult:
    selected: list                    # Terms in order
    beta: dict                        # term key -> parameter values (unscaled)
    ci: dict                          # term key -> (lo, hi) arrays (bootstrap 95 %)
    steps: list
    contributions: dict               # cb -> array (all rows) of the selected terms' sum
    per_term: dict                    # term key -> cb -> contribution array
    flags: dict = field(default_factory=dict)
    n_eff: dict = field(default_factory=dict)
    boot: dict = field(default_factory=dict)      # term key -> (R, p) bootstrap values


def _term_contrib(t: Term, beta: np.ndarray) -> dict:
    return {cb: X @ beta for cb, X in t.cols.items()}


def forward_select(B: Blocks, e0: dict, fit_tb: np.ndarray, hold_tb: np.ndarray,
                   make_candidates, plausibility, decision: Decision = Decision(),
                   log=None, rebuild=None) -> ForwardResult:
    """Forward selection (module docstring). ``make_candidates(e, fitrow, selected_keys)``
    returns the candidate Terms built on the current residual e; ``plausibility(term,
    values)`` returns (bad groups -> reason, flags); ``rebuild(term, residual, fitrow)`` the
    term with its scales re-profiled on a residual (None: scales stay)."""
    rng = np.random.default_rng(decision.seed)
    all_tb = np.unique(np.concatenate([B.tb[cb] for cb in B.keys]))
    fit_set = set(fit_tb.tolist())
    fitmask_tb = np.array([t in fit_set for t in all_tb])
    holdmask_tb = np.isin(all_tb, hold_tb)
    fitrow = {cb: np.isin(B.tb[cb], fit_tb) for cb in B.keys}
    S: list[Term] = []
    steps = []
    flags = {}
    e = {cb: e0[cb].copy() for cb in B.keys}
    n_eff_last = {}
    while len(S) < decision.max_terms:
        cands = make_candidates(e, fitrow, {t.key() for t in S})
        terms = S + cands
        st = Stats(B, e0, terms)
        w_fit = fitmask_tb.astype(float)
        W = st.weighted(w_fit)
        # one effective sample size per block for the whole step: tau_int of the residual
        # left by ALL terms of the step together (S and every candidate), i.e. of what no
        # candidate explains -- the same n_eff for every candidate
        A_all = list(range(st.p))
        b_all = st.unscale(A_all, st.solve(W, A_all))
        r_all = {cb: e0[cb].copy() for cb in B.keys}
        for t, off in zip(terms, st.offsets):
            for cb, c in _term_contrib(t, b_all[off]).items():
                r_all[cb] = r_all[cb] - c
        tau = {}
        for cb in B.keys:
            r = r_all[cb][fitrow[cb]]
            if cb[0] == TCP:
                r3 = r.reshape(-1, 3)
                tau[cb] = float(np.mean([tau_int(r3[:, i]) for i in range(3)]))
            else:
                tau[cb] = tau_int(r)
        nS = sum(t.p for t in S)
        A_S = list(range(nS))

        def neff(Wd):
            return {cb: Wd[cb][3] / tau[cb] for cb in B.keys}

        def score(Wd, A_c, k, cbs_c, base_rss=None, A_base=None):
            ne = neff(Wd)
            A_b = A_S if A_base is None else A_base
            r0 = base_rss if base_rss is not None else st.rss(Wd, A_b, st.solve(Wd, A_b))
            A = A_b + A_c
            b = st.solve(Wd, A)
            r1 = st.rss(Wd, A, b)
            d = sum(ne[cb] * np.log(r1[cb] / r0[cb]) for cb in B.keys)
            n_c = sum(ne[cb] for cb in cbs_c) or 2.0
            return float(d + k * np.log(max(n_c, 2.0))), b, r0, r1

        r0_fit = st.rss(W, A_S, st.solve(W, A_S))
        n_eff_last = neff(W)
        table = []
        eligible = []
        for ci, t in enumerate(cands, start=len(S)):
            off = st.offsets[ci]
            # joints (parameter groups) with their own evidence
            groups = list(t.groups)
            if len(groups) > 1:
                keep = []
                for g in groups:
                    A_g = [off[i] for i in t.groups[g]]
                    cbs_g = [cb for cb, X in t.cols.items()
                             if np.any(X[:, t.groups[g]])]
                    k_g = len(A_g) + (1 if g in t.scales and t.n_scales else 0)
                    d_g = score(W, A_g, k_g, cbs_g, r0_fit)[0]
                    if d_g < 0:
                        keep.append(g)
            else:
                keep = groups
            row = {'effect': t.key(), 'kind': t.kind, 'joints': [], 'delta_bic': 0.0,
                   'fit_rms_reduction': 0.0, 'eligible': False, 'reason': '', 'flags': []}
            table.append(row)
            reasons = []
            for _ in range(3):
                if not keep:
                    row['reason'] = '; '.join(reasons) or 'no joint with evidence'
                    break
                tc = restrict(t, keep)
                if tc is None:
                    row['reason'] = 'no columns on the data'
                    break
                A_c = [off[i] for g in keep for i in t.groups[g]]
                A_c = sorted(A_c)
                k = len(A_c) + (t.n_scales if 'shared' in t.scales else
                                sum(1 for g in keep if g in t.scales and t.n_scales))
                cbs_c = [cb for cb in tc.cols]
                d, b, r0, r1 = score(W, A_c, k, cbs_c, r0_fit)
                vals = st.unscale(A_c, b[nS:])
                bad, fl = plausibility(tc, vals)
                if bad:
                    reasons += [f'{v}' for v in bad.values()]
                    keep = [g for g in keep if g not in bad]
                    if 'all' in bad:
                        keep = []
                    continue
                f0 = sum(r0[cb] for cb in cbs_c)
                f1 = sum(r1[cb] for cb in cbs_c)
                red = float(1 - np.sqrt(f1 / f0)) if f0 > 0 else 0.0
                red_x = _excess_reduction(B, W, cbs_c, f0, f1, decision.min_excess)
                row.update(joints=[g + 1 for g in keep if g != 'all'] or
                           [j + 1 for j in tc.joints], delta_bic=d, fit_rms_reduction=red,
                           excess_rms_reduction=red_x,
                           flags=fl + list(t.edge), parameters=dict(zip(tc.labels,
                                                                        vals.tolist())))
                if reasons:
                    row['flags'] = row['flags'] + [f'dropped: {r}' for r in reasons]
                if d >= -decision.bic_threshold:
                    row['reason'] = f'dBIC {d:.1f} above -{decision.bic_threshold:g}'
                elif red < decision.min_fit_reduction and (
                        red_x is None or red_x < decision.min_excess_reduction):
                    row['reason'] = (f'fit RMS reduction {100 * red:.1f} % < '
                                     f'{100 * decision.min_fit_reduction:.0f} %')
                    if red_x is not None:
                        row['reason'] += (f', of the residual above the measured noise '
                                          f'{100 * red_x:.0f} % < '
                                          f'{100 * decision.min_excess_reduction:.0f} %')
                else:
                    row['eligible'] = True
                    eligible.append((d, ci, tc, A_c, k, cbs_c, row))
                break
        table.sort(key=lambda r: (not r['eligible'], r['delta_bic']))
        if not eligible:
            steps.append(Step(None, table, {'none': decision.n_boot}, 1.0,
                              stop_reason='no candidate passes'))
            break
        eligible.sort(key=lambda x: x[0])
        d, ci, tc, A_c, k, cbs_c, row = eligible[0]
        # held-out significance (parameters from the fit part)
        hold_w = holdmask_tb.astype(float)
        Wh = st.weighted(hold_w)
        heldout = None
        if hold_w.sum() > 0:
            ne_h = neff(Wh)
            r0h = st.rss(Wh, A_S, st.solve(W, A_S))
            A = A_S + A_c
            r1h = st.rss(Wh, A, st.solve(W, A))
            heldout = float(sum(ne_h[cb] * np.log(r1h[cb] / r0h[cb]) for cb in B.keys))
        # aliases: eligible candidates such that neither explains anything more once the other
        # is in (e.g. joint-1 armature and link 2's mass at its axis): a replicate won by an
        # alias supports the same explanation; they are reported with it
        aliases = []
        for d_, ci_, tc_, A_c_, k_, cbs_, row_ in eligible[1:]:
            # mutual: neither adds anything once the other is in
            if (score(W, A_c_, k_, cbs_, None, A_S + A_c)[0] >= -decision.bic_threshold and
                    score(W, A_c, k, cbs_c, None, A_S + A_c_)[0] >= -decision.bic_threshold):
                aliases.append(tc_.key())
        row['aliases'] = aliases
        # bootstrap of the step's decision
        wins = {}
        fit_idx = np.flatnonzero(fitmask_tb)
        replicates = []                 # (block weights, winner) of each replicate
        for _ in range(decision.n_boot):
            draw = rng.choice(fit_idx, size=len(fit_idx), replace=True)
            wb = np.bincount(draw, minlength=len(all_tb)).astype(float)
            Wb = st.weighted(wb)
            r0b = st.rss(Wb, A_S, st.solve(Wb, A_S))
            best = ('none', -decision.bic_threshold)
            for d_, ci_, tc_, A_c_, k_, cbs_, row_ in eligible:
                db = score(Wb, A_c_, k_, cbs_, r0b)[0]
                if db < best[1]:
                    best = (tc_.key(), db)
            wins[best[0]] = wins.get(best[0], 0) + 1
            replicates.append((wb, best[0]))
        support = sum(wins.get(k, 0) for k in [tc.key()] + aliases) / max(decision.n_boot, 1)
        for r in table:
            r['bootstrap_wins'] = wins.get(r['effect'], 0) / max(decision.n_boot, 1)
        step = Step(tc.key(), table, wins, support, heldout, best=tc.key(), aliases=aliases)
        if heldout is not None and heldout >= -decision.heldout_threshold:
            step.added, step.stop_reason = None, (
                f'{tc.key()}: held-out dBIC {heldout:.1f} not below '
                f'-{decision.heldout_threshold:g}')
            steps.append(step)
            break
        if support < decision.min_confidence:
            pair = _pair_step(st, W, score, neff, eligible, eligible[0], aliases, replicates,
                              holdmask_tb, A_S, plausibility, nS, decision)
            if pair is not None and len(S) + 2 <= decision.max_terms:
                (tp, p_row), p_support, p_heldout = pair
                note = (f'joint step: the replicates split ({wins}) between {tc.key()} and '
                        f'{tp.key()}, each significant once the other is in; the pair is '
                        f'supported in {100 * p_support:.0f} % of them')
                step.support, step.heldout_delta, step.stop_reason = p_support, p_heldout, note
                steps.append(step)
                steps.append(Step(tp.key(), table, wins, p_support, p_heldout, note,
                                  best=tp.key(), aliases=p_row.get('aliases', [])))
                flags[tc.key()] = row['flags']
                flags[tp.key()] = p_row['flags']
                S.extend([tc, tp])
                if log:
                    log(note)
                if rebuild is not None:
                    S = _backfit_scales(B, e0, S, fit_tb, fitrow, rebuild)
                e = _refit(B, e0, S, fit_tb)
                continue
            step.added, step.stop_reason = None, (
                f'{tc.key()}: bootstrap support {support:.2f} < {decision.min_confidence:g} '
                f'(replicates: {wins})')
            steps.append(step)
            break
        steps.append(step)
        flags[tc.key()] = row['flags']
        S.append(tc)
        if log:
            log(f'step {len(S)}: {tc.key()} dBIC {d:.1f}, held-out {heldout}, support '
                f'{support:.2f}')
        if rebuild is not None and len(S) > 1:
            S = _backfit_scales(B, e0, S, fit_tb, fitrow, rebuild)
        e = _refit(B, e0, S, fit_tb)
    fin = final_fit(B, e0, S, fitmask_tb, decision.n_boot, rng)
    return ForwardResult(S, *fin[:2], steps, *fin[2:4], flags, n_eff_last, fin[4])


def _excess_reduction(B, Wd: dict, cbs: list, f0: float, f1: float,
                      min_excess: float) -> float | None:
    """1 - sqrt((RSS1 - N) / (RSS0 - N)) on the candidate's blocks, N the RSS the measured
    white noise alone would leave on their fit rows (weighted like RSS: n (white/floor)^2).
    None when a block has no measured noise or the residual does not stand out of it (RSS0 -
    N < min_excess^2 N: an excess RMS below min_excess x the noise RMS)."""
    if not cbs or any(not np.isfinite(B.white.get(cb, np.nan)) for cb in cbs):
        return None
    noise = sum(Wd[cb][3] * (B.white[cb] / B.floor[cb]) ** 2 for cb in cbs)
    if f0 - noise < min_excess ** 2 * noise:
        return None
    return float(1.0 - np.sqrt(max(f1 - noise, 0.0) / (f0 - noise)))


def _pair_step(st, W, score, neff, eligible, first, aliases, replicates, holdmask_tb, A_S,
               plausibility, nS, decision: Decision):
    """The step's replicates split between the best candidate and another one (not an
    alias): if each is significant once the other is in, plausible in their joint refit,
    the pair lowers the held-out residual, and the replicates that pick either one also
    find the other significant next (bootstrap of the two-step decision) in at least
    ``min_confidence`` of them, both go in together. Returns ((term, row), support, held-out
    dBIC) of the partner, or None. A single effect of two correlated names does not pass:
    the second adds nothing once the first is in."""
    d, ci, tc, A_c, k, cbs_c, row = first
    won = {w for _, w in replicates}
    partners = [x for x in eligible[1:] if x[2].key() in won and x[2].key() not in aliases]
    if not partners:
        return None
    wins = {x[2].key(): sum(1 for _, w in replicates if w == x[2].key()) for x in partners}
    d_p, ci_p, tp, A_p, k_p, cbs_p, row_p = max(partners, key=lambda x: wins[x[2].key()])
    thr = -decision.bic_threshold
    # each significant once the other is in (full fit part)
    if not (score(W, A_p, k_p, cbs_p, None, A_S + A_c)[0] < thr and
            score(W, A_c, k, cbs_c, None, A_S + A_p)[0] < thr):
        return None
    A = A_S + A_c + A_p
    b = st.solve(W, A)
    vals = st.unscale(A, b)[nS:]
    if plausibility(tc, vals[:len(A_c)])[0] or plausibility(tp, vals[len(A_c):])[0]:
        return None
    heldout = None
    hold_w = holdmask_tb.astype(float)
    if hold_w.sum() > 0:
        Wh = st.weighted(hold_w)
        r0h = st.rss(Wh, A_S, st.solve(W, A_S))
        r1h = st.rss(Wh, A, b)
        ne_h = neff(Wh)
        heldout = float(sum(ne_h[cb] * np.log(r1h[cb] / r0h[cb]) for cb in Wh))
        if heldout >= -decision.heldout_threshold:
            return None
    keys = {tc.key(), tp.key(), *aliases}
    support = 0
    for wb, w in replicates:
        if w not in keys:
            continue
        Wb = st.weighted(wb)
        other = (A_p, k_p, cbs_p) if w != tp.key() else (A_c, k, cbs_c)
        base = A_S + (A_c if w != tp.key() else A_p)
        if score(Wb, *other, None, base)[0] < thr:
            support += 1
    support /= max(decision.n_boot, 1)
    if support < decision.min_confidence:
        return None
    return (tp, row_p), support, heldout


def final_fit(B: Blocks, e0: dict, S: list, fitmask_tb: np.ndarray, n_boot: int, rng):
    """Joint fit of S on the fit blocks and bootstrap intervals: (beta, ci, contributions,
    per-term contributions, bootstrap values), all by term key."""
    beta, ci, contrib, per_term = {}, {}, {cb: np.zeros(len(B.rows[cb])) for cb in B.keys}, {}
    boot = {}
    if S:
        st = Stats(B, e0, S)
        A = list(range(st.p))
        W = st.weighted(fitmask_tb.astype(float))
        bu = st.unscale(A, st.solve(W, A))
        fit_idx = np.flatnonzero(fitmask_tb)
        boots = []
        for _ in range(n_boot):
            draw = rng.choice(fit_idx, size=len(fit_idx), replace=True)
            wb = np.bincount(draw, minlength=len(st.tbs)).astype(float)
            boots.append(st.unscale(A, st.solve(st.weighted(wb), A)))
        boots = np.array(boots) if boots else np.empty((0, st.p))
        for t, off in zip(S, st.offsets):
            beta[t.key()] = bu[off]
            if len(boots):
                lo, hi = np.percentile(boots[:, off], [2.5, 97.5], axis=0)
                ci[t.key()] = (lo, hi)
                boot[t.key()] = boots[:, off]
            c = _term_contrib(t, bu[off])
            per_term[t.key()] = c
            for cb, v in c.items():
                contrib[cb] = contrib[cb] + v
    return beta, ci, contrib, per_term, boot


def _refit(B, e0, S, fit_tb, parts: bool = False):
    """Residual after the joint refit of S on the fit part (all rows); with ``parts`` also
    each term's contribution (cb -> array)."""
    st = Stats(B, e0, S)
    all_tb = st.tbs
    w = np.isin(all_tb, fit_tb).astype(float)
    A = list(range(st.p))
    bu = st.unscale(A, st.solve(st.weighted(w), A))
    e = {cb: e0[cb].copy() for cb in B.keys}
    contrib = []
    for t, off in zip(S, st.offsets):
        c = _term_contrib(t, bu[off])
        contrib.append(c)
        for cb, v in c.items():
            e[cb] = e[cb] - v
    return (e, contrib) if parts else e


def _backfit_scales(B, e0, S, fit_tb, fitrow, rebuild):
    """Re-profile the grid scales of the selected terms, each on the residual the others
    leave (one backfitting sweep after a step): a scale chosen before a later effect was in
    can then follow the joint refit."""
    e, contrib = _refit(B, e0, S, fit_tb, parts=True)
    out = list(S)
    for i, t in enumerate(S):
        if not t.n_scales:
            continue
        partial = {cb: e[cb] + contrib[i].get(cb, 0.0) for cb in B.keys}
        nt = rebuild(t, partial, fitrow)
        if nt is not None:
            out[i] = nt
    return out

