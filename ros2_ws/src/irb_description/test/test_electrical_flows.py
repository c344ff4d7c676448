"""ElectricalModel.flows / shares against an independent computation (issue 17, published
figures): a scalar per-sample loop written from the README's formulas, its own trapezoid sum,
a hand-computed copper loss, and a closed-form constant-speed case."""
import numpy as np
import pytest

from irb_description.electrical import (BUS_MODES, FLOW_PARTS, ElectricalModel,
                                        load_electrical, shares)


def _trajectory(seed=3):
    """Irregular stamps, three axes, power changing sign, noise: several effects at once."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.5e-3, 6e-3, 1500)])
    w = 2 * np.pi / t[-1]
    tau = np.stack([120 * np.sin(w * t) + 30, 200 * np.cos(w * t) + 150,
                    60 * np.sin(2 * w * t)], axis=1) + rng.normal(0, 2.0, (t.size, 3))
    qd = np.stack([1.2 * np.cos(w * t), -0.8 * np.sin(w * t), 0.9 * np.cos(2 * w * t)],
                  axis=1) + rng.normal(0, 0.01, (t.size, 3))
    return t, tau, qd


def _oracle(m: ElectricalModel, t, tau, qd, mode):
    """Sample by sample, scalar arithmetic, README 'Electrical model'; own trapezoid."""
    cols = ('standby', 'copper', 'gear', 'drive', 'idle', 'work', 'burned', 'regen_loss',
            'total')
    p = {k: np.zeros(t.size) for k in cols}
    for k in range(t.size):
        pax = []
        for i in range(m.n):
            pj = tau[k, i] * qd[k, i]
            if pj >= 0:
                pg = pj / m.gear_efficiency_motoring[i]
                taum = tau[k, i] / m.gear_ratio[i] / m.gear_efficiency_motoring[i]
            else:
                pg = pj * m.gear_efficiency_generating[i]
                taum = tau[k, i] / m.gear_ratio[i] * m.gear_efficiency_generating[i]
            i_q = taum / m.torque_constant[i]
            pcu = m.resistance[i] * i_q * i_q
            pe = pg + pcu
            conv = pe / m.drive_efficiency if pe > 0 else pe * m.drive_efficiency
            a = conv + m.drive_idle_power[i]
            pax.append(a)
            p['work'][k] += pj
            p['gear'][k] += pg - pj
            p['copper'][k] += pcu
            p['drive'][k] += conv - pe
            p['idle'][k] += m.drive_idle_power[i]
        p['standby'][k] = m.standby_power
        net = sum(pax)
        if mode == 'none':
            bus = sum(a for a in pax if a > 0)
            p['burned'][k] = -sum(a for a in pax if a < 0)
        elif mode == 'shared':
            bus = max(net, 0.0)
            p['burned'][k] = max(-net, 0.0)
        else:
            bus = net if net > 0 else m.regenerative_efficiency * net
            p['regen_loss'][k] = (1 - m.regenerative_efficiency) * max(-net, 0.0)
        p['total'][k] = m.standby_power + bus
    dt = np.diff(t)
    return {k: float(np.sum(0.5 * (v[1:] + v[:-1]) * dt)) for k, v in p.items()}


@pytest.mark.parametrize('mode', BUS_MODES)
def test_flows_match_an_independent_sample_loop(mode):
    m = load_electrical().axes(3)
    t, tau, qd = _trajectory()
    f = m.flows(t, tau, qd, mode)
    o = _oracle(m, t, tau, qd, mode)
    pairs = {'standby': 'standby', 'copper': 'copper', 'gear_loss': 'gear',
             'drive_conversion': 'drive', 'drive_idle': 'idle', 'work': 'work',
             'brake_resistor': 'burned', 'regeneration_loss': 'regen_loss', 'total': 'total'}
    for ours, theirs in pairs.items():
        assert f[ours] == pytest.approx(o[theirs], rel=1e-9, abs=1e-9), ours
    # the parts add up to the oracle's total, and the total is the model's own energy
    assert sum(f[k] for k in FLOW_PARTS) == pytest.approx(o['total'], rel=1e-12)
    assert f['total'] == pytest.approx(m.energy(t, tau, qd, mode), rel=1e-12)
    s = shares(f)
    assert s['parts_sum'] == pytest.approx(100.0, abs=1e-9)
    assert s['standby'] == pytest.approx(100 * m.standby_power * (t[-1] - t[0]) / o['total'])
    assert s['copper'] == pytest.approx(100 * o['copper'] / o['total'], rel=1e-9)
    # losses are losses; this trajectory generates, so each mode shows its own surplus sink
    for k in ('gear_loss', 'copper', 'drive_conversion', 'drive_idle'):
        assert f[k] > 0
    assert f['work_motoring'] - f['work_generated'] == pytest.approx(f['work'])
    assert f['work_generated'] > 0
    assert (f['brake_resistor'] > 0) == (mode != 'regenerative')
    assert (f['returned'] > 0) == (mode == 'regenerative')


def test_copper_loss_of_one_sample_by_hand():
    m = load_electrical().axes(3)
    t = np.array([0.0, 1.0])
    tau = np.array([[0.0, 300.0, 0.0]] * 2)      # axis 2 holding 300 N m, at rest
    qd = np.zeros((2, 3))
    f = m.flows(t, tau, qd, 'shared')
    # motor current = 300 / (N eta_m) / k_t; copper = R i^2 (holding counts as motoring)
    i_q = 300.0 / (120.0 * 0.85) / 0.95
    assert m.gear_ratio[1] == 120.0 and m.gear_efficiency_motoring[1] == 0.85
    assert m.torque_constant[1] == 0.95 and m.resistance[1] == 1.6
    assert f['copper'] == pytest.approx(1.6 * i_q ** 2, rel=1e-12)
    assert f['drive_conversion'] == pytest.approx(1.6 * i_q ** 2 * (1 / 0.95 - 1), rel=1e-12)
    assert f['work'] == 0.0 and f['gear_loss'] == 0.0


def test_constant_speed_closed_form_and_bad_input():
    # one axis lowering a load at constant speed (generating) next to one lifting (motoring)
    m = ElectricalModel(torque_constant=np.array([1.0, 1.0]), resistance=np.array([2.0, 2.0]),
                        gear_ratio=np.array([100.0, 100.0]),
                        gear_efficiency_motoring=np.array([0.8, 0.8]),
                        gear_efficiency_generating=np.array([0.5, 0.5]),
                        drive_idle_power=np.array([0.0, 0.0]), drive_efficiency=1.0,
                        standby_power=100.0, regenerative_efficiency=0.9)
    T = 4.0
    t = np.linspace(0.0, T, 9)
    tau = np.tile([100.0, 100.0], (9, 1))
    qd = np.tile([1.0, -2.0], (9, 1))
    # axis 1: P_j = 100, P_g = 125, i = 100/100/0.8 = 1.25 A -> P_cu = 3.125, P_ax = 128.125
    # axis 2: P_j = -200, P_g = -100, i = 0.5 A -> P_cu = 0.5, P_ax = -99.5; net 28.625 W
    f_none, f_shared = m.flows(t, tau, qd, 'none'), m.flows(t, tau, qd, 'shared')
    assert f_none['total'] == pytest.approx(T * (100 + 128.125))
    assert f_none['brake_resistor'] == pytest.approx(T * 99.5)
    assert f_shared['total'] == pytest.approx(T * (100 + 28.625))
    assert f_shared['brake_resistor'] == 0.0
    assert f_shared['copper'] == pytest.approx(T * 3.625)
    assert f_shared['gear_loss'] == pytest.approx(T * (25.0 + 100.0))
    assert shares(f_shared)['standby'] == pytest.approx(100 * 100 / 128.625)
    with pytest.raises(ValueError, match='bus mode'):
        m.flows(t, tau, qd, 'magic')
    with pytest.raises(ValueError, match='not positive'):
        shares(dict(f_shared, total=0.0))
