"""Power modes: powers follow the electrical model, transitions compose along the chain, waits
are feasible only when their transitions fit, YAML errors are one-line messages."""
import numpy as np
import pytest
import yaml

from irb_description.electrical import load_electrical
from irb_description.params import config_path
from irb_description.power_modes import (BRAKES, BUS_OFF, HIBERNATE, HOLD, MODES,
                                         holding_power_w, load_power_modes)


@pytest.fixture(scope='module')
def pm():
    return load_power_modes()


def test_hold_is_the_electrical_model_at_rest(pm):
    e = load_electrical()
    zero = np.zeros(e.n)
    assert pm.power_w(HOLD) == pytest.approx(float(e.power(zero, zero)), abs=1e-9)
    tau = np.array([0.0, 120.0, 40.0, 0.0, 2.0, 0.0])
    p = holding_power_w(e, tau)
    assert p > pm.power_w(HOLD)                      # holding copper losses add
    assert pm.power_w(HOLD, holding_power_w=p) == p
    with pytest.raises(ValueError, match='axes'):
        holding_power_w(e, tau[:3])


def test_modes_are_ordered_and_deeper_modes_ignore_the_pose(pm):
    p = [pm.power_w(m, holding_power_w=300.0) for m in MODES]
    assert p == sorted(p, reverse=True) and p[-1] > 0
    assert pm.power_w(BRAKES, 999.0) == pm.power_w(BRAKES)
    # by construction of the YAML quantities (independent arithmetic)
    assert pm.power_w(BRAKES) == pytest.approx(pm.standby_power_w - pm.brake_coils_w)
    assert pm.power_w(BUS_OFF) == pytest.approx(
        pm.standby_power_w - pm.brake_coils_w - pm.bus_on_w)


def test_transitions_compose_along_the_chain(pm):
    hp = 290.0
    a = pm.transition(HOLD, BRAKES, hp)
    b = pm.transition(BRAKES, BUS_OFF, hp)
    ab = pm.transition(HOLD, BUS_OFF, hp)
    assert ab.path == (HOLD, BRAKES, BUS_OFF)
    assert ab.duration_s == pytest.approx(a.duration_s + b.duration_s)
    assert ab.energy_j == pytest.approx(a.energy_j + b.energy_j)
    back = pm.transition(BUS_OFF, BRAKES, hp)
    # power of the target (brakes) during the precharge, plus C V^2
    spec = [t for t in pm.transitions if (t.src, t.dst) == (BUS_OFF, BRAKES)][0]
    assert back.energy_j == pytest.approx(
        spec.duration_s * pm.power_w(BRAKES) + pm.bus_capacitance_f * pm.bus_voltage_v ** 2)
    assert pm.transition(BRAKES, BRAKES).duration_s == 0.0
    with pytest.raises(ValueError, match='unknown'):
        pm.transition(HOLD, 'sleep')


def test_wait_feasibility_and_energy(pm):
    hp = 285.0
    for m in MODES:
        dmin = pm.min_wait_s(m)
        assert pm.feasible(m, dmin) and (m == HOLD or not pm.feasible(m, 0.99 * dmin))
        if m != HOLD:
            with pytest.raises(ValueError, match='cannot use'):
                pm.wait_energy_j(m, 0.99 * dmin, hp)
    d = 20.0
    e_in, e_out = pm.transition(HOLD, BUS_OFF, hp), pm.transition(BUS_OFF, HOLD, hp)
    expect = e_in.energy_j + e_out.energy_j + pm.power_w(BUS_OFF) * (
        d - e_in.duration_s - e_out.duration_s)
    assert pm.wait_energy_j(BUS_OFF, d, hp) == pytest.approx(expect)
    assert pm.wait_energy_j(HOLD, d, hp) == pytest.approx(hp * d)
    # the break-even wait of a mode costs the same as holding
    be = pm.break_even_s(BUS_OFF, hp)
    assert pm.wait_energy_j(BUS_OFF, be, hp) == pytest.approx(hp * be)
    mode, e = pm.best_wait(d, hp)
    assert e == min(pm.wait_energy_j(m, d, hp) for m in MODES if pm.feasible(m, d))
    assert pm.best_wait(0.1, hp) == (HOLD, pytest.approx(0.1 * hp))
    assert pm.best_wait(1e4, hp)[0] == HIBERNATE


def test_variants_for_sensitivity(pm):
    slow = pm.with_params(duration_factor=2.0)
    assert slow.min_wait_s(BUS_OFF) == pytest.approx(2 * pm.min_wait_s(BUS_OFF))
    one = pm.with_params(bus_off__brakes=5.0, bus_on_w=10.0)
    assert one.transition(BUS_OFF, BRAKES).duration_s == 5.0
    assert one.power_w(BUS_OFF) == pytest.approx(pm.power_w(BRAKES) - 10.0)
    with pytest.raises(ValueError, match='no transition'):
        pm.with_params(hold__hibernate=1.0)


def _write(tmp_path, mutate):
    d = yaml.safe_load(config_path('power_modes.yaml').read_text())
    mutate(d)
    p = tmp_path / 'pm.yaml'
    p.write_text(yaml.safe_dump(d))
    return p


@pytest.mark.parametrize('mutate, match', [
    (lambda d: d['modes'].pop('bus_off'), 'missing mode modes.bus_off'),
    (lambda d: d['modes']['brakes'].update(brake_coils_w='lots'), 'must be a number'),
    (lambda d: d['modes']['brakes'].update(brake_coils_w=-1.0), '>= 0'),
    (lambda d: d['modes']['hibernate'].update(fraction_of_idle=1.5), r'\(0, 1\]'),
    (lambda d: d['transitions'][0].update(to='nap'), 'two different ones'),
    (lambda d: d['transitions'][0].update(power='both'), "'from' or 'to'"),
    (lambda d: d.update(transitions=[t for t in d['transitions'] if t['to'] != 'hold']),
     'no chain of transitions'),
    (lambda d: d.pop('bus'), 'mappings `modes` and `bus`'),
])
def test_yaml_errors_are_one_line(tmp_path, mutate, match):
    with pytest.raises(ValueError, match=match) as err:
        load_power_modes(_write(tmp_path, mutate))
    assert '\n' not in str(err.value)


def test_unreadable_yaml_is_one_line(tmp_path):
    p = tmp_path / 'bad.yaml'
    p.write_text('modes: [unclosed\n  - x: :\n')
    with pytest.raises(ValueError) as err:
        load_power_modes(p)
    assert '\n' not in str(err.value)
    with pytest.raises(ValueError, match='cannot read'):
        load_power_modes(tmp_path / 'missing.yaml')
