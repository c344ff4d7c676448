"""The plan file and figure of `plan` (plan_plot), without ROS: a response-like object with
the planner's trapezoid along a line as its plan."""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from irb_planning.plan_plot import (path_unit, read_plan_file, save_plan_outputs,
                                    spec_from_path_msg, trapezoid)

LINE = [[0.55, -0.1, 0.3], [0.75, 0.1, 0.3]]


def _point(x):
    return NS(x=x[0], y=x[1], z=x[2])


def _response(duration=2.0):
    th, thd, t = trapezoid(duration)
    pts = [NS(time_from_start=NS(sec=int(tk), nanosec=int(round((tk % 1) * 1e9))),
              positions=[0.1 * k, 0.2, 0.3], velocities=[0.1, 0.0, -0.1],
              effort=[1.0, -2.0, 3.0]) for k, tk in enumerate(t)]
    return NS(trajectory=NS(joint_names=['joint_1', 'joint_2', 'joint_3'], points=pts),
              theta=th, theta_dot=thd, theta_ddot=[], duration=duration, energy=10.0,
              baseline_energy=11.0, electrical_bus_modes=['none'], electrical_energy=[100.0],
              baseline_electrical_energy=[110.0])


def test_trapezoid_overlay_has_the_duration_and_covers_the_path():
    th, thd, t = trapezoid(3.0)
    assert t[-1] == pytest.approx(3.0, rel=1e-9)
    # theta_dot is linear in time on the ramps and constant between: the trapezoid rule in
    # time is exact and must cover the whole path parameter
    assert float(np.sum(0.5 * (thd[1:] + thd[:-1]) * np.diff(t))) == pytest.approx(
        2 * math.pi, rel=1e-9)


def test_the_path_parameter_is_shown_in_its_unit():
    from irb_description.path import LinePath, thesis_circle
    assert path_unit(thesis_circle())[:2] == ('theta', 'rad')
    line = LinePath(np.array(LINE[0]), np.array(LINE[1]))
    name, unit, k = path_unit(line)
    assert (name, unit) == ('s', 'm')
    assert k * 2 * math.pi == pytest.approx(math.hypot(0.2, 0.2), rel=1e-12)


def test_plan_file_and_plot_round_trip(tmp_path):
    msg = NS(type='line', waypoints=[_point(w) for w in LINE], blend_radii=[], closed=False)
    text = save_plan_outputs(tmp_path / 'plan.png', _response(), msg, 'energy')
    assert 'plan file' in text
    assert (tmp_path / 'plan.png').stat().st_size > 20_000
    rec = read_plan_file(tmp_path / 'plan.json')
    assert rec['path'] == {'type': 'line', 'waypoints': LINE}
    assert rec['energy_j'] == 10.0 and rec['baseline_energy_j'] == 11.0
    assert rec['electrical_energy_j'] == {'none': 100.0}
    assert rec['t'][-1] == pytest.approx(2.0, abs=1e-9)
    assert np.asarray(rec['q']).shape == (len(rec['t']), 3)


def test_spec_of_a_path_message_keeps_the_planner_defaults():
    arc = NS(type='arc', center=_point([0.6, 0, 0.3]), normal=_point([0, 0, 1]), radius=0.1,
             start_angle=0.0, sweep=0.0)
    assert spec_from_path_msg(arc)['sweep'] == pytest.approx(2 * math.pi)
    circle = NS(type='', center=_point([0.6, 0, 0.13]), radius=0.15, start_angle=0.0,
                direction=0)
    assert spec_from_path_msg(circle)['direction'] == 1


@pytest.mark.parametrize('content,why', [('{', 'not JSON'), ('{"format": "x"}', 'not a plan')])
def test_a_bad_plan_file_is_refused_in_one_line(tmp_path, content, why):
    f = tmp_path / 'p.json'
    f.write_text(content)
    with pytest.raises(ValueError, match=why) as exc:
        read_plan_file(f)
    assert '\n' not in str(exc.value)
