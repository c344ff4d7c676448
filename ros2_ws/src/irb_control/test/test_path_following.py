"""pdplus on any path (issue 18): theta by projection near the previous estimate, the
thesis circle still by atan2; closed loop on a tilted rectangle, a spline and a line.

Oracles: the simulated plant's camera (link-side TCP) against the path's own geometry; the
thesis circle's atan2 formula; the same circle given as an ArcPath (other class, other
formulas) run through the tracker."""
import numpy as np
import pytest
from irb_description.path import (ArcPath, LinePath, SplinePath, path_spec, rectangle_path,
                                  thesis_circle)

from irb_control.closed_loop import controller_friction, path_distance, simulate_closed_loop
from irb_control.pd_plus import ControllerConfig, PdPlusController
from irb_control.plant import Plant, PlantConfig, default_plant_yaml, load_plant_friction
from irb_control.profiles import (default_circle_profile, profile_from_joint_trajectory,
                                  profile_from_theta_samples)

RECT = rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025)


def test_the_thesis_circle_keeps_atan2_to_the_bit(model, circle, rng):
    ctrl = PdPlusController(model, circle)
    assert ctrl._tracker is None
    for q in rng.uniform([-0.5, -0.3, -0.5], [0.5, 0.6, 0.5], (200, 3)):
        p = model.fk(q)
        ang = float(np.arctan2(p[1] - 0.0, p[0] - 0.6))
        want = ang % (2 * np.pi)
        assert ctrl._theta_of(q) == (0.0 if want >= 2 * np.pi else want)
        assert ctrl._theta_of(q) == float(circle.theta_of(p))


def run(model, path, duration, mode='file', seed=5, delay_prediction='auto'):
    _, pf = load_plant_friction(default_plant_yaml(), model.joint_names)
    plant = Plant(model, pf, PlantConfig(seed=seed))
    ctrl = PdPlusController(model, path, ControllerConfig(delay_prediction=delay_prediction),
                            controller_friction(model, mode, default_plant_yaml()
                                                if mode == 'file' else None))
    prof = default_circle_profile(model, path, duration)
    ctrl.set_path_profile(prof)
    plant.reset(prof.q[0])
    return simulate_closed_loop(plant, ctrl, duration + 2.0)


def test_a_circle_as_arc_is_followed_like_the_thesis_circle(model, circle):
    """Same geometry, tracker instead of atan2: the same motion to round-off (with the same
    delay compensation: 'auto' takes the thesis's rule on the CirclePath only)."""
    arc = ArcPath(circle.center, [0.0, 0.0, 1.0], circle.radius)
    a = run(model, circle, 6.0)
    b = run(model, arc, 6.0, delay_prediction='reference')
    n = min(a.t.size, b.t.size)
    assert a.finished() and b.finished()
    sel = a.motion_mask()[:n]
    assert np.nanmax(np.abs(a.theta[:n][sel] - b.theta[:n][sel])) < 1e-8
    assert np.abs(a.q[:n] - b.q[:n]).max() < 1e-8


@pytest.mark.slow
@pytest.mark.parametrize('name', ['rectangle', 'spline', 'line'])
def test_paths_are_followed_within_the_goal(model, name):
    """0.25 m/s peak TCP speed (the polynomial law peaks at 1.875 x the mean), plant friction
    as the compensation: mean <= 0.1 mm, max <= 0.5 mm on the camera."""
    path = {'rectangle': RECT,
            'spline': SplinePath([[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4],
                                  [0.7, 0.2, 0.35], [0.55, 0.15, 0.3]]),
            'line': LinePath([0.5, -0.2, 0.25], [0.8, 0.25, 0.45])}[name]
    T = 1.875 * path.length / 0.25
    r = run(model, path, T)
    assert r.stop_reason == '' and r.finished()
    th = r.theta[r.motion_mask()]
    assert np.diff(th).min() > -1e-3          # never jumps back (noise only: < 0.2 mm)
    assert th[-1] == pytest.approx(2 * np.pi, abs=0.02)
    err = r.path_error_camera()
    assert err.size > 100
    assert np.mean(err) < 1e-4 and np.max(err) < 5e-4
    # the camera's own distance, recomputed from the plant's true TCP: the same order
    assert path_distance(path, r.cam_p).max() == pytest.approx(np.max(
        path.distance(r.cam_p)))


def test_plans_of_any_path_become_profiles(model):
    """A joint trajectory along the rectangle -> theta-profile (as the plan gate builds it):
    theta runs 0 .. 2 pi and the joints are the trajectory's."""
    th = np.linspace(0, 2 * np.pi, 400)
    prof = profile_from_theta_samples(model, RECT, th, np.full(th.size, 0.8),
                                      np.zeros(th.size), th / 0.8)
    back = profile_from_joint_trajectory(model, RECT, prof.t, prof.q, prof.qd, prof.qdd)
    assert back.theta[0] == pytest.approx(0.0, abs=1e-9)
    assert back.theta[-1] == pytest.approx(2 * np.pi, abs=1e-9)
    np.testing.assert_allclose(back.theta, prof.theta, atol=1e-8)
    np.testing.assert_allclose(back.theta_dot, 0.8, rtol=1e-6)
    with pytest.raises(Exception, match='does not follow'):
        profile_from_joint_trajectory(model, thesis_circle(), prof.t, prof.q, prof.qd, prof.qdd)
    assert path_spec(RECT)['closed']


@pytest.mark.parametrize('text, words', [
    ('type: polyline\nwaypoints: [[0.5, 0, 0.3], [0.7, 0, 0.3], [0.5, 0, 0.3]]\n'
     'blend_radii: [0.01]\n', 'turns back'),
    (None, 'cannot read path file'),
])
@pytest.mark.ros
def test_pdplus_refuses_a_bad_path_file_with_one_line(tmp_path, text, words):
    import os
    import subprocess
    f = tmp_path / 'path.yaml'
    if text is not None:
        f.write_text(text)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    res = subprocess.run(['ros2', 'run', 'irb_control', 'pdplus', '--ros-args', '-p',
                          f'path_file:={f}'], capture_output=True, text=True, timeout=60,
                         env=env)
    assert res.returncode == 2          # a configuration the node refuses (node_main.run_node)
    assert words in res.stderr and 'Traceback' not in res.stderr
    assert res.stderr.strip().count('\n') == 0
