"""Paths beyond the thesis circle (issue 18): line, arc in any plane, blended polyline,
spline; their joint paths, the along-path check and the path-parameter tracker.

Oracles: finite differences, arc length summed over a dense chord polygon, pinocchio's
forward kinematics, the geometric construction of a blend (tangent to both segments)."""
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from irb_description.model import UnreachableError
from irb_description.path import (ArcPath, CirclePath, LinePath, PolylinePath, SplinePath,
                                  check_joint_path, joint_path, path_from_spec, path_spec,
                                  rectangle_path, thesis_circle)
from irb_description.path_tracking import PathTracker

WAY = [[0.55, -0.25, 0.25], [0.8, -0.2, 0.3], [0.85, 0.05, 0.4], [0.7, 0.2, 0.35],
       [0.55, 0.15, 0.3]]


def paths():
    return {
        'arc_tilted': ArcPath([0.65, 0.0, 0.3], [0.2, -0.4, 1.0], 0.12, 0.4, -4.5),
        'circle_vertical': ArcPath([0.7, 0.05, 0.4], [1.0, 0.0, 0.0], 0.1),
        'line': LinePath([0.5, -0.2, 0.25], [0.8, 0.25, 0.45]),
        'polyline': PolylinePath(WAY, [0.03, 0.05, 0.02]),
        'rectangle': rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025),
        'spline': SplinePath(WAY),
        'spline_closed': SplinePath(WAY, closed=True),
    }


PATHS = paths()


@pytest.fixture(params=sorted(PATHS))
def path(request):
    return PATHS[request.param]


def interior(path, n=301):
    """theta samples avoiding the pieces' ends (where p'' may jump)."""
    th = np.linspace(1e-3, 2 * np.pi - 1e-3, n)
    if path.breaks.size:
        th = th[np.abs(th[:, None] - path.breaks[None, :]).min(axis=1) > 1e-4]
    return th


def test_derivatives_match_finite_differences(path):
    th, h = interior(path), 1e-6
    assert_allclose(path.d_point(th), (path.point(th + h) - path.point(th - h)) / (2 * h),
                    atol=2e-9)
    assert_allclose(path.dd_point(th), (path.d_point(th + h) - path.d_point(th - h)) / (2 * h),
                    atol=2e-8)


def test_theta_is_arc_length(path):
    """|p'(theta)| = L / 2 pi everywhere, and L equals the length of a dense chord polygon."""
    th = np.linspace(0, 2 * np.pi, 100001)
    chord = np.linalg.norm(np.diff(path.point(th), axis=0), axis=1).sum()
    assert path.length == pytest.approx(chord, rel=2e-8)
    speed = np.linalg.norm(path.d_point(interior(path)), axis=1)
    assert_allclose(speed, path.length / (2 * np.pi), rtol=1e-9)


def test_c1_everywhere_and_closed_paths_close(path):
    th = np.concatenate([path.breaks, [np.pi / 3, 2.0]])
    e = 1e-9
    assert_allclose(path.point(th - e), path.point(th + e), atol=1e-9)
    assert_allclose(path.d_point(th - e), path.d_point(th + e), atol=1e-7)
    if path.closed:
        assert_allclose(path.point(2 * np.pi), path.point(0.0), atol=1e-12)
        assert_allclose(path.d_point(2 * np.pi), path.d_point(0.0), atol=1e-9)
        assert_allclose(path.dd_point(2 * np.pi), path.dd_point(0.0), atol=1e-6)


def test_spec_round_trip(path):
    again = path_from_spec(path_spec(path))
    th = np.linspace(0, 2 * np.pi, 77)
    assert_allclose(again.point(th), path.point(th), atol=1e-14)
    assert again.closed == path.closed


def test_theta_of_and_distance(path):
    th = interior(path, 53)
    assert_allclose(path.theta_of(path.point(th)), th, atol=1e-9)
    # a point moved off the path along the principal normal is that far from the path
    dd = path.dd_point(th)
    n = np.linalg.norm(dd, axis=1)
    ok = n > 1e-6
    if np.any(ok):
        off = path.point(th[ok]) - 2e-3 * dd[ok] / n[ok, None]
        assert_allclose(path.distance(off), 2e-3, atol=1e-9)


def test_arc_lies_in_its_plane_at_its_radius():
    a = PATHS['arc_tilted']
    p = a.point(np.linspace(0, 2 * np.pi, 50))
    d = p - a.center
    nrm = np.array([0.2, -0.4, 1.0]) / np.linalg.norm([0.2, -0.4, 1.0])
    assert_allclose(d @ nrm, 0.0, atol=1e-15)
    assert_allclose(np.linalg.norm(d, axis=1), 0.12, atol=1e-15)
    assert a.length == pytest.approx(4.5 * 0.12)
    assert not a.closed and PATHS['circle_vertical'].closed
    # sweep < 0: clockwise about the normal
    t = np.cross(d[0], a.d_point(0.0))
    assert t @ nrm < 0


def test_blends_are_tangent_arcs_of_the_given_radius():
    pl = PATHS['polyline']
    w = np.array(WAY)
    th = np.linspace(0, 2 * np.pi, 20001)
    p, dd = pl.point(th), pl.dd_point(th)
    kappa = np.linalg.norm(dd, axis=1) / (pl.length / (2 * np.pi)) ** 2
    assert kappa.max() == pytest.approx(1 / 0.02, rel=1e-9)       # bounded curvature
    assert set(np.round(kappa[kappa > 0], 6)) == {round(1 / r, 6) for r in (0.03, 0.05, 0.02)}
    # straight pieces lie on the segments; every point within the corner's cut of them
    seg_d = np.full(th.size, np.inf)
    for a, b in zip(w[:-1], w[1:]):
        t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        seg_d = np.minimum(seg_d, np.linalg.norm(p - a - t[:, None] * (b - a), axis=1))
    assert_allclose(seg_d[kappa == 0], 0.0, atol=1e-12)
    # the corner error of a blend: r (1 / cos(alpha / 2) - 1) at the waypoint
    for k, r in zip((1, 2, 3), (0.03, 0.05, 0.02)):
        d_in, d_out = (w[k] - w[k - 1], w[k + 1] - w[k])
        d_in, d_out = d_in / np.linalg.norm(d_in), d_out / np.linalg.norm(d_out)
        alpha = math.acos(d_in @ d_out)
        gap = np.linalg.norm(p - w[k], axis=1).min()
        assert gap == pytest.approx(r * (1 / math.cos(alpha / 2) - 1), rel=1e-6)
    assert_allclose(pl.point([0.0, 2 * np.pi]), w[[0, -1]], atol=1e-15)


def test_spline_passes_the_waypoints_and_is_c2():
    for sp in (PATHS['spline'], PATHS['spline_closed']):
        assert_allclose(sp.distance(np.array(WAY)), 0.0, atol=1e-12)
        th = sp.theta_of(np.array(WAY[1:-1]))
        e = 1e-7
        assert_allclose(sp.dd_point(th - e), sp.dd_point(th + e), atol=1e-4)


@pytest.mark.parametrize('spec, words', [
    ({'type': 'star'}, 'unknown path type'),
    ({'type': 'line', 'waypoints': [[0, 0, 0]]}, 'start, end'),
    ({'type': 'polyline', 'waypoints': [[0.5, 0, 0.3], [0.7, 0, 0.3], [0.7, 0.01, 0.3]],
      'blend_radii': [0.05]}, 'overlap'),
    ({'type': 'polyline', 'waypoints': [[0.5, 0, 0.3], [0.7, 0, 0.3], [0.5, 0, 0.3]],
      'blend_radii': [0.01]}, 'turns back'),
    ({'type': 'polyline', 'waypoints': [[0.5, 0, 0.3], [0.7, 0, 0.3], [0.7, 0.2, 0.3]],
      'blend_radii': [0.0]}, 'blend radius > 0'),
    ({'type': 'polyline', 'waypoints': [[0.5, 0, 0.3], [0.7, 0, 0.3], [0.7, 0.2, 0.3]],
      'closed': True, 'blend_radii': [0.01]}, 'waypoint 0'),
    ({'type': 'spline', 'waypoints': [[0.5, 0, 0.3], [0.5, 0, 0.3], [0.7, 0.2, 0.3]]},
     'coincide'),
    ({'type': 'arc', 'center': [0.6, 0, 0.3], 'normal': [0, 0, 0], 'radius': 0.1}, 'normal'),
    ({'type': 'arc', 'center': [0.6, 0, 0.3], 'normal': [0, 0, 1], 'radius': 0.1,
      'sweep': 7.0}, 'sweep'),
    ({'type': 'circle', 'center': [0.6, 0, 0.3], 'radius': 0.1, 'waypoints': []},
     'not'),
    ({'type': 'spline', 'waypoints': [[0.5, 0, 'x'], [0.6, 0, 0.3]]}, 'spline'),
    ({'type': 'line', 'waypoints': [[0.5, 0, 0.3], [0.7, 0, 0.3]],
      'orientation': {'law': 'fixed'}}, 'six-axis chain'),
])
def test_bad_specs_say_why(spec, words):
    with pytest.raises(ValueError, match=words):
        path_from_spec(spec)


def test_thesis_circle_is_unchanged_to_the_bit():
    """The circle's formulas as they were before issue 18 (p = c + r (cos, sin, 0))."""
    c = thesis_circle()
    th = np.linspace(0, 2 * np.pi, 1001)
    a = 1 * th + 0.0
    ref = np.array([0.6, 0.0, 0.13]) + 0.15 * np.stack([np.cos(a), np.sin(a), 0 * a], -1)
    assert np.array_equal(c.point(th), ref)
    spec = path_from_spec({'type': 'circle', 'center': [0.6, 0.0, 0.13], 'radius': 0.15})
    assert type(spec) is CirclePath and np.array_equal(spec.point(th), ref)


def test_joint_paths_are_the_paths(model, path):
    th = interior(path, 61)
    jp = joint_path(model, path, th)
    assert_allclose(np.array([model.fk(q) for q in jp.q]), path.point(th), atol=1e-12)
    h = 1e-6
    plus, minus = joint_path(model, path, th + h), joint_path(model, path, th - h)
    assert_allclose(jp.dq, (plus.q - minus.q) / (2 * h), atol=1e-7)
    assert_allclose(jp.ddq, (plus.dq - minus.dq) / (2 * h), atol=1e-5)
    check_joint_path(model, path)          # all of these are reachable all along


def test_along_path_check_finds_limits_and_branch_changes(model):
    # joint 3 above its limit between reachable ends (both at 42 deg, 64 deg in the middle)
    with pytest.raises(UnreachableError, match='joint_3 crosses its upper limit'):
        check_joint_path(model, LinePath([0.42, -0.45, 0.65], [0.42, 0.45, 0.65]))
    # through the base axis: joint 1 would turn by pi in no time
    with pytest.raises(UnreachableError, match='jumps'):
        check_joint_path(model, LinePath([0.3, -0.3, 0.9], [-0.3, 0.3, 0.9]))
    # leaves the workspace in the middle although both ends are reachable
    with pytest.raises(UnreachableError, match='workspace'):
        check_joint_path(model, PolylinePath([[0.6, -0.5, 0.2], [1.6, 0.0, 0.2],
                                              [0.6, 0.5, 0.2]], 0.05))


def test_tracker_follows_noisy_points():
    """(Its cost per update is measured by irb_control's bench_path_tracking.py.)"""
    for name in ('rectangle', 'spline_closed', 'line', 'polyline'):
        p = PATHS[name]
        tr = PathTracker(p)
        th = np.linspace(0, 2 * np.pi, 4001)
        rng = np.random.default_rng(3)
        pts = p.point(th) + rng.normal(0.0, 1e-4, (th.size, 3))
        prev, est = 0.0, np.empty(th.size)
        for k, x in enumerate(pts):
            prev = est[k] = tr.update(x, prev)
        along = np.abs((est - th + np.pi) % (2 * np.pi) - np.pi) * p.length / (2 * np.pi)
        assert along.max() < 6e-4, name          # 1e-4 m noise, 6 sigma
        exact = np.array([tr.update(x, t) for x, t in zip(p.point(th), th)])
        err = np.abs((exact - th + np.pi) % (2 * np.pi) - np.pi)
        assert err.max() * p.length / (2 * np.pi) < 1e-8, name


def test_tracker_does_not_jump_to_a_near_part_of_the_path():
    """A narrow rectangle (8 mm between its long sides) and a spline crossing itself: the
    estimate stays on the part it follows although another part is nearer at times."""
    narrow = rectangle_path([0.7, 0.0, 0.3], [0, 0, 1], 0.3, 0.008, 0.0035)
    tr = PathTracker(narrow, window_m=0.02)
    th = np.linspace(0, 0.95 * narrow.breaks[0], 200)
    # 5 mm towards the other long side, 3 mm from it: the estimate stays on its own side
    pts = narrow.point(th) + [0.0, 0.005, 0.0]
    prev = 0.0
    for t, x in zip(th, pts):
        prev = tr.update(x, prev)
        assert abs(prev - t) * narrow.length / (2 * np.pi) < 0.002
    eight = SplinePath([[0.7, 0.0, 0.3], [0.8, 0.1, 0.3], [0.8, -0.1, 0.3], [0.7, 0.0, 0.3],
                        [0.6, 0.1, 0.3], [0.6, -0.1, 0.3]], closed=True)
    tr = PathTracker(eight)
    th = np.linspace(0, 2 * np.pi, 3000, endpoint=False)
    prev = 0.0
    for t, x in zip(th, eight.point(th)):
        prev = tr.update(x, prev)
        assert abs((prev - t + np.pi) % (2 * np.pi) - np.pi) < 1e-6
    assert CirclePath  # the circle keeps its own atan2 (tested in irb_control)


def test_a_path_file_that_is_not_yaml_names_line_and_column(tmp_path):
    from irb_description.path import load_path_file
    f = tmp_path / 'bad.yaml'
    f.write_text('type: line\nwaypoints: [[0.5, 0, 0.3]\n  bad: x\n')
    with pytest.raises(ValueError, match=r'bad.yaml is not YAML: .* at line 3, column 3$'):
        load_path_file(f)


def test_theta_of_on_a_closed_spline_whose_legs_cross():
    """bench_smooth --seed 31's closed spline: its legs cross (68 and 413 mm along it). Its
    own points are at distance 0 and at their own theta, and points 1-3 mm off it are as far
    as a brute-force search over 200001 path points says (3.2 um apart: it overestimates by
    at most 7e-9 m at 0.19 mm; before, a point of one leg could be put on the other: 0.19
    mm where it was on the path)."""
    way = [[0.57738276, -0.26699967, 0.44288097], [0.76253304, -0.23166506, 0.54776359],
           [0.76408912, -0.22259135, 0.54289186], [0.51455009, -0.32050884, 0.43450325]]
    sp = SplinePath(way, closed=True)
    th = np.linspace(0.0, 2 * np.pi, 8001)[:-1]
    p = sp.point(th)
    assert sp.distance(p).max() < 1e-12
    got = sp.theta_of(p)
    assert np.abs((got - th + np.pi) % (2 * np.pi) - np.pi).max() < 1e-9
    rng = np.random.default_rng(3)
    off = p[::16] + rng.normal(0.0, 1.5e-3, (th[::16].size, 3))
    fine = sp.point(np.linspace(0.0, 2 * np.pi, 200001))
    from scipy.spatial import cKDTree
    brute, _ = cKDTree(fine).query(off)
    got = sp.distance(off)
    assert np.all(got <= brute + 1e-12) and np.all(brute - got <= 1e-8)
