"""Electrical model: numpy and CasADi forms agree; hand-computed cases; bus modes; loader."""
import casadi as ca
import numpy as np
import pytest

from irb_description.electrical import (BUS_MODES, ElectricalModel, load_electrical)


def _model(**kw):
    base = dict(torque_constant=np.array([1.0, 0.5]), resistance=np.array([2.0, 4.0]),
                gear_ratio=np.array([100.0, 50.0]),
                gear_efficiency_motoring=np.array([0.8, 0.9]),
                gear_efficiency_generating=np.array([0.7, 0.6]),
                drive_idle_power=np.array([5.0, 3.0]), drive_efficiency=0.95,
                standby_power=200.0, bus_mode='shared', regenerative_efficiency=0.9)
    base.update(kw)
    return ElectricalModel(**base)


def test_numpy_and_casadi_agree_to_1e_9():
    m = load_electrical()
    rng = np.random.default_rng(3)
    M = 400
    tau = rng.normal(0, 200, (M, m.n)) * np.array([1, 1, 1, 0.1, 0.1, 0.05])
    qd = rng.normal(0, 1.5, (M, m.n))
    qd[::17] = 0.0                            # holding samples
    T, Q = ca.SX.sym('tau', m.n, M), ca.SX.sym('qd', m.n, M)
    for mode in BUS_MODES:
        f = ca.Function('p', [T, Q], [m.casadi_power(T, Q, mode),
                                      m.casadi_axis_power(T, Q)])
        p_ca, pax_ca = (np.asarray(v) for v in f(tau.T, qd.T))
        np.testing.assert_allclose(p_ca.ravel(), m.power(tau, qd, mode), rtol=0, atol=1e-9)
        np.testing.assert_allclose(pax_ca.T, m.axis_power(tau, qd), rtol=0, atol=1e-9)


def test_smoothing_converges_to_the_exact_form():
    m = load_electrical().axes(3)
    rng = np.random.default_rng(5)
    tau, qd = rng.normal(0, 100, (50, 3)), rng.normal(0, 1, (50, 3))
    T, Q = ca.SX.sym('tau', 3, 50), ca.SX.sym('qd', 3, 50)
    errs = []
    for eps in (1e-1, 1e-3, 1e-6):
        f = ca.Function('p', [T, Q], [m.casadi_power(T, Q, 'none', smoothing=eps)])
        errs.append(np.abs(np.asarray(f(tau.T, qd.T)).ravel()
                           - m.power(tau, qd, 'none')).max())
    # the step of the gearbox efficiency is smoothed too, so the error is not O(eps) where
    # |tau qd| < eps; it vanishes with eps
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-3


def test_hand_computed_axis_powers():
    m = _model()
    # axis 1 motoring: tau 80 N m, 2 rad/s -> 160 W at the joint
    # motor shaft 160/0.8 = 200 W; tau_m = 80/100/0.8 = 1 N m -> I = 1 A -> P_cu = 2 W
    # drive: (200 + 2)/0.95 + 5 W idle
    # axis 2 generating: tau 30 N m, -2 rad/s -> -60 W; shaft -60*0.6 = -36 W;
    # tau_m = 30/50*0.6 = 0.36 N m -> I = 0.72 A -> P_cu = 4*0.5184 W; drive (-36+P_cu)*0.95
    p1 = 202.0 / 0.95 + 5.0
    pcu2 = 4.0 * 0.72 ** 2
    p2 = (-36.0 + pcu2) * 0.95 + 3.0
    pax = m.axis_power(np.array([80.0, 30.0]), np.array([2.0, -2.0]))
    np.testing.assert_allclose(pax, [p1, p2], rtol=1e-12)
    tau, qd = np.array([80.0, 30.0]), np.array([2.0, -2.0])
    assert m.power(tau, qd, 'none') == pytest.approx(200.0 + p1)       # p2 < 0 burned
    assert m.power(tau, qd, 'shared') == pytest.approx(200.0 + p1 + p2)
    assert m.power(tau, qd, 'regenerative') == pytest.approx(200.0 + p1 + p2)
    # surplus on the bus: regenerative returns 90 % of it, shared burns it
    tau2, qd2 = np.array([0.0, 30.0]), np.array([0.0, -2.0])
    net = 5.0 + p2
    assert net < 0
    assert m.power(tau2, qd2, 'shared') == pytest.approx(200.0)
    assert m.power(tau2, qd2, 'regenerative') == pytest.approx(200.0 + 0.9 * net)


def test_holding_costs_copper_losses_only():
    m = _model(drive_idle_power=np.zeros(2), standby_power=0.0)
    p = m.axis_power(np.array([[50.0, -20.0]]), np.zeros((1, 2)))
    # at rest: tau_m = tau / (N eta_m) (holding counted as motoring)
    expect = np.array([2.0 * (50 / 100 / 0.8) ** 2, 4.0 * (20 / 50 / 0.9 / 0.5) ** 2]) / 0.95
    np.testing.assert_allclose(p.ravel(), expect, rtol=1e-12)


def test_energy_ordering_and_breakdown():
    m = load_electrical().axes(3)
    t = np.linspace(0, 2 * np.pi, 2001)
    # a swinging arm: power changes sign; the modes must order none >= shared >= regen
    tau = np.stack([100 * np.sin(t), 150 * np.cos(t) + 100, 50 * np.sin(2 * t)], axis=1)
    qd = np.stack([np.cos(t), -np.sin(t), 0.5 * np.cos(2 * t)], axis=1)
    b = m.breakdown(t, tau, qd)
    assert b['total_none'] >= b['total_shared'] - 1e-9
    assert b['total_shared'] >= b['total_regenerative'] - 1e-9
    assert b['standby'] == pytest.approx(m.standby_power * 2 * np.pi)
    assert b['copper'] > 0 and b['gear_loss'] > 0 and b['drive_loss'] > 0
    # independent quadrature of the mechanical energy
    dt = np.diff(t)
    pm = np.abs(tau * qd).sum(axis=1)
    assert b['mechanical'] == pytest.approx(float(np.sum(0.5 * (pm[1:] + pm[:-1]) * dt)))


def test_loader_reads_gear_ratios_from_dynamics_and_rejects_bad_files(tmp_path):
    from irb_description.params import load_dynamics
    m = load_electrical()
    np.testing.assert_array_equal(m.gear_ratio, load_dynamics().gear_ratio)
    assert m.n == 6 and m.axes(3).n == 3
    bad = tmp_path / 'e.yaml'
    bad.write_text('axes: {}\n')
    with pytest.raises(ValueError, match='missing key'):
        load_electrical(bad)
    with pytest.raises(ValueError, match='bus mode'):
        _model(bus_mode='magic')
    with pytest.raises(ValueError, match='gear_efficiency'):
        _model(gear_efficiency_motoring=np.array([1.2, 0.9]))
