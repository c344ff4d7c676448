"""Process constraints (issue 18, part 2): a TCP speed band and a bound on |TCP acceleration|
along the path, for a gluing bead on the main job's rectangle.

Oracles: the TCP velocity of the played samples from pinocchio's Jacobian (not the DH
derivatives of verify.py), their acceleration by differentiating that velocity in time, and
where along the path a sample is from irb_description's own projection (``theta_of``); the
unconstrained plan on the same path as the witness that the band changes something; for
"defaults change nothing", the same problem built without the task-space data at all."""
import numpy as np
import pytest
import yaml
from irb_description.path import path_from_spec, path_spec, process_from_spec, rectangle_path
from numpy.testing import assert_array_equal

from irb_planning.planner import tcp_path
from irb_planning.request import (ERROR_INFEASIBLE_DURATION, ERROR_INVALID_REQUEST, PlanError,
                                  PlanRequest, validate)
from irb_planning.transcription import SolveRequest, Transcription
from irb_planning.verify import ArmKinematics, TcpBand

RECT = path_spec(rectangle_path([0.7, 0.0, 0.3], [0.3, 0.1, 1.0], 0.3, 0.2, 0.025))
PATH = path_from_spec(RECT)
T = 8.0                                          # the main job's gluing duration
BAND = dict(tcp_speed_min=0.09, tcp_speed_max=0.15, tcp_ramp_length=0.04, tcp_accel_max=1.0)


def rect(**kw) -> PlanRequest:
    return PlanRequest(path_type='polyline', waypoints=np.asarray(RECT['waypoints'], float),
                       blend_radii=np.asarray(RECT['blend_radii'], float), closed=True, **kw)


def played_tcp(model, ver):
    """(sigma [m] along the path, speed [m/s], |acceleration| [m/s^2]) of the played samples,
    by pinocchio and irb_description's projection."""
    v = np.array([model.jacobian(q) @ qd for q, qd in zip(ver.q, ver.qd)])
    acc = np.gradient(v, ver.t, axis=0)
    p = np.array([model.fk(q) for q in ver.q])
    sigma = PATH.theta_of(p) * PATH.length / (2 * np.pi)
    return sigma, np.linalg.norm(v, axis=1), np.linalg.norm(acc, axis=1)


@pytest.fixture(scope='module')
def free(planner):
    return planner.plan(rect(duration=T))


@pytest.fixture(scope='module')
def banded(planner):
    return planner.plan(rect(duration=T, **BAND))


def test_the_band_holds_as_played(planner, model, free, banded):
    assert banded.verification.ok and banded.evaluation.ok
    sigma, speed, acc = played_tcp(model, banded.verification)
    moving = (sigma >= BAND['tcp_ramp_length']) & (sigma <= PATH.length
                                                    - BAND['tcp_ramp_length'])
    assert speed.max() <= BAND['tcp_speed_max'] * (1 + 1e-6)
    assert speed[moving].min() >= BAND['tcp_speed_min'] * (1 - 1e-6)
    # over the ramps no creeping: at least a constant-acceleration start / stop's speed
    d = np.minimum(sigma, PATH.length - sigma)
    # (d / r)^(2/3): a constant-jerk start with the smoothness limits on, else 1/2
    ramp_floor = BAND['tcp_speed_min'] * np.clip(d / BAND['tcp_ramp_length'], 0, 1) ** \
        planner.ramp_exponent
    assert np.all(speed >= ramp_floor * (1 - 1e-6))
    # a time derivative by finite differences of 1 kHz samples: 0.2 % for its own error
    # (the independent check measured it in closed form; they agree to that)
    assert acc.max() <= BAND['tcp_accel_max'] * 1.002
    assert banded.verification.tcp_accel_peak == pytest.approx(acc.max(), rel=2e-3)
    assert banded.verification.tcp_speed_peak == pytest.approx(speed.max(), rel=1e-8)
    # the witness: the unconstrained optimum on the same path breaks the band
    f_sigma, f_speed, f_acc = played_tcp(model, free.verification)
    f_moving = (f_sigma >= 0.04) & (f_sigma <= PATH.length - 0.04)
    assert f_speed.max() > 0.15 or f_speed[f_moving].min() < 0.09
    # and pays for the band with at most what the trapezoid costs
    assert free.evaluation.energy <= banded.evaluation.energy * (1 + 1e-6)
    assert banded.evaluation.energy <= banded.baseline.energy * (1 + 1e-6)


def test_the_trapezoid_keeps_a_band_around_its_cruise_speed_and_is_refused_outside(planner,
                                                                                   model):
    tr = planner.plan(rect(objective='trapezoid', duration=T, **BAND))
    assert tr.verification.ok
    # at the message's points the cruise speed L / (0.9 T), inside the band; as played too
    v = np.linalg.norm([model.jacobian(q) @ qd for q, qd in
                        zip(tr.trajectory['q'], tr.trajectory['qd'])], axis=1)
    cruise = PATH.length / (0.9 * T)
    assert v.max() == pytest.approx(cruise, rel=1e-9)
    sigma, speed, acc = played_tcp(model, tr.verification)
    assert speed.max() <= BAND['tcp_speed_max'] and acc.max() <= BAND['tcp_accel_max']
    with pytest.raises(PlanError) as e:        # cruise 0.133 m/s above a 0.125 m/s ceiling
        planner.plan(rect(objective='trapezoid', duration=T,
                          **dict(BAND, tcp_speed_max=0.125)))
    assert e.value.code == ERROR_INFEASIBLE_DURATION
    # the trapezoid's own band check names tcp_speed_max; with the smoothness limits on, the
    # jerk-limited time-optimal duration under the band (8.63 s > 8 s) refuses it first,
    # naming the band with its 0.125 m/s ceiling
    assert 'process constraints' in e.value.message
    assert ('tcp_speed_max' in e.value.message or '<= 0.125 m/s' in e.value.message)


@pytest.mark.parametrize('kw, code, text', [
    (dict(tcp_speed_min=0.2, tcp_speed_max=0.15, tcp_accel_max=1.0), ERROR_INVALID_REQUEST,
     'below tcp_speed_max'),
    (dict(tcp_speed_min=0.09), ERROR_INVALID_REQUEST, 'needs tcp_ramp_length'),
    (dict(tcp_speed_min=0.09, tcp_ramp_length=0.5), ERROR_INVALID_REQUEST, 'no part'),
    (dict(tcp_speed_max=-0.1), ERROR_INVALID_REQUEST, 'tcp_speed_max'),
    (dict(tcp_accel_max=float('nan')), ERROR_INVALID_REQUEST, 'not finite'),
    (dict(tcp_ramp_length=0.04), ERROR_INVALID_REQUEST, 'means nothing'),
    (dict(tcp_speed_max=0.1, objective='fourier', fourier_order=3), ERROR_INVALID_REQUEST,
     'Fourier'),
    (dict(tcp_speed_max=0.1), ERROR_INFEASIBLE_DURATION, 'too short for tcp_speed_max'),
    (dict(tcp_speed_min=0.2, tcp_ramp_length=0.04, duration=30.0), ERROR_INFEASIBLE_DURATION,
     'too long for tcp_speed_min'),
    (dict(tcp_speed_min=0.09, tcp_ramp_length=0.04, tcp_accel_max=0.1),
     ERROR_INFEASIBLE_DURATION, 'centripetal'),
])
def test_infeasible_bands_are_refused_with_a_reason(planner, kw, code, text):
    kw = dict(dict(duration=T), **kw)
    with pytest.raises(PlanError) as e:
        planner.plan(rect(**kw))
    assert e.value.code == code, e.value.message
    assert text in e.value.message, e.value.message


def test_without_constraints_the_problem_and_its_solution_are_the_same(planner):
    """On the thesis circle, the task-space data and the new bound code change nothing when
    no constraint is set: bounds and solution bit for bit against the problem built without
    them (as before the process constraints existed)."""
    req = validate(PlanRequest(duration=T), 60)
    path = path_from_spec(req.path_spec())
    entry = planner._entry(req, path, planner.model.friction)
    theta = entry.nodes.theta
    kw = dict(boundary=req.boundary, max_iter=planner.settings.max_iterations,
              tol=planner.settings.tolerance, warm_start=False,
              jerk=entry.transcription.jerk)      # the smoothness rows as the planner's
    plain = Transcription(entry.nodes, entry.mids, entry.friction, **kw)
    with_tcp = Transcription(entry.nodes, entry.mids, entry.friction,
                             tcp=tcp_path(path, theta), **kw)
    base, _ = planner._limits(req, planner.model.friction)
    assert base.process_key == (0.0, 0.0, 0.0, 0.0)
    sreq = SolveRequest(T, 0.0, 1.0, base.min_theta_dot, base.velocity_limit,
                        base.torque_limit, jerk_limit=base.jerk_limit,
                        tcp_jerk_max=base.tcp_jerk_max)
    for a, b in zip(plain._bounds(sreq), with_tcp._bounds(sreq)):
        assert_array_equal(a, b)
    ra, rb = plain.solve(sreq), with_tcp.solve(sreq)
    assert ra.stats.success
    assert_array_equal(ra.profile.theta_dot, rb.profile.theta_dot)
    assert_array_equal(ra.profile.theta_ddot_nodes, rb.profile.theta_ddot_nodes)
    # and the planner's own problem (cached, with its task-space data) gives that solution
    rc = entry.transcription.solve(sreq, warm=False)
    assert_array_equal(ra.profile.theta_dot, rc.profile.theta_dot)


def test_verify_tcp_rates_agree_with_pinocchio(planner, model, banded):
    lim = planner.model.limits
    kin = ArmKinematics(velocity=lim.velocity, torque=lim.torque, **planner._kin)
    ver = banded.verification
    k = np.linspace(0, ver.t.size - 1, 50).astype(int)
    v, a = kin.tcp_rates(ver.q[k], ver.qd[k], ver.qdd[k])
    v_pin = np.array([model.jacobian(q) @ qd for q, qd in zip(ver.q[k], ver.qd[k])])
    np.testing.assert_allclose(v, v_pin, atol=1e-9)
    # acceleration: pinocchio velocity at q + qd h + qdd h^2 / 2, central difference in h
    h = 1e-5
    vp = np.array([model.jacobian(q + qd * h + 0.5 * qdd * h * h) @ (qd + qdd * h)
                   for q, qd, qdd in zip(ver.q[k], ver.qd[k], ver.qdd[k])])
    vm = np.array([model.jacobian(q - qd * h + 0.5 * qdd * h * h) @ (qd - qdd * h)
                   for q, qd, qdd in zip(ver.q[k], ver.qd[k], ver.qdd[k])])
    np.testing.assert_allclose(a, (vp - vm) / (2 * h), atol=1e-7)
    assert TcpBand(0.15).active and not TcpBand().active


def test_the_check_catches_a_plan_that_breaks_the_band(planner, free):
    """The unconstrained plan's message checked against the band: named problems."""
    from irb_planning.planner import request_path
    req = validate(rect(duration=T, **BAND), 60)
    _, checked = planner._limits(req, planner.model.friction)
    fm, raw = planner.friction_map('')
    _, ver = planner.trajectory(free.profile, req, request_path(req), fm, raw, checked)
    assert any(p.startswith('tcp_') for p in ver.problems), ver.problems


def test_the_process_block_of_a_path_file(tmp_path):
    from irb_planning.plan_cli import build_request, main, parse_args
    spec = dict(RECT, process=dict(tcp_speed_max=0.15, tcp_speed_min=0.09,
                                   tcp_ramp_length=0.04))
    f = tmp_path / 'glue.yaml'
    f.write_text(yaml.safe_dump(spec))
    assert path_from_spec(spec).length == pytest.approx(PATH.length, rel=1e-15)  # pdplus
    r = build_request(parse_args(['--path-file', str(f), '--duration', '8']))
    assert (r.tcp_speed_max, r.tcp_speed_min, r.tcp_accel_max, r.tcp_ramp_length) == (
        0.15, 0.09, 0.0, 0.04)
    r = build_request(parse_args(['--path-file', str(f), '--tcp-speed-max', '0.2',
                                  '--tcp-accel-max', '1']))
    assert (r.tcp_speed_max, r.tcp_accel_max) == (0.2, 1.0)
    assert process_from_spec(RECT) == {}
    for block, words in ((dict(tcp_speed=1.0), 'takes'), (dict(tcp_speed_max='fast'),
                                                          'finite number')):
        with pytest.raises(ValueError, match=words):
            process_from_spec(dict(RECT, process=block))
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump(dict(RECT, process=dict(tcp_speed_max=-1))))
    assert main(['plan', '--path-file', str(bad)]) == 1


def test_an_open_line_at_gluing_speed_plans_inside_its_band(planner, model):
    """Regression (bench_paths_sim --band): on an open line at 0.05 m/s the played sample at
    rest projected a hair past the path's start, met a ramp floor > 0 at speed 0 and the
    planner divided by that ratio (ZeroDivisionError instead of a plan)."""
    ends = np.array([[0.5, -0.2, 0.25], [0.8, 0.25, 0.45]])
    length = float(np.linalg.norm(ends[1] - ends[0]))
    mean = 0.9 * 0.05
    band = dict(tcp_speed_min=0.75 * mean, tcp_speed_max=1.25 * mean, tcp_ramp_length=0.04,
                tcp_accel_max=1.0)
    res = planner.plan(PlanRequest(path_type='line', waypoints=ends, duration=length / mean,
                                   **band))
    assert res.verification.ok and res.evaluation.ok
    assert res.verification.tcp_floor_ratio >= 1 - 1e-6
    ver = res.verification
    v = np.linalg.norm([model.jacobian(q) @ qd for q, qd in zip(ver.q, ver.qd)], axis=1)
    s = np.array([np.dot(model.fk(q) - ends[0], ends[1] - ends[0]) / length for q in ver.q])
    moving = (s >= 0.04) & (s <= length - 0.04)
    assert v.max() <= band['tcp_speed_max'] * (1 + 1e-6)
    assert v[moving].min() >= band['tcp_speed_min'] * (1 - 1e-6)


def _b_between_nodes(theta, theta_dot, a, per=64):
    """b = theta_dot^2 at ``per`` points inside every interval from its defining quadratic,
    b(theta_k + s) = b_k + 2 a_k s + (a_{k+1} - a_k) s^2 / h_k (written here, not imported),
    (K, per)."""
    b, h = theta_dot ** 2, np.diff(theta)
    s = np.linspace(0.0, 1.0, per)[None, :] * h[:, None]
    return (b[:-1, None] + 2 * a[:-1, None] * s
            + (a[1:, None] - a[:-1, None]) * s ** 2 / h[:, None])


@pytest.mark.parametrize('boundary, T, same', [('rest', 4.0, True), ('periodic', 4.0, True),
                                             ('rest', 30.0, True), ('rest', 60.0, False),
                                             ('periodic', 60.0, False)])
def test_the_quarter_point_rows_are_implied_without_a_band(planner, boundary, T, same):
    """Without a TCP speed band the problem has no rows of b at the quarter points (their
    bounds are implied: transcription docstring); its optimum still keeps theta_dot >= delta
    between the nodes, sampled densely from the profile's own quadratic, as closely as the
    problem with those rows does, and where the optimum is well defined it is the same one.
    At 30 and 60 s the floor is reached (the check bites); at 60 s the problem is flat and
    both end in different local optima (measured: 77.53 vs 77.73 J rest, 77.94 vs 77.71 J
    periodic), so only the floor is compared there."""
    req = validate(PlanRequest(duration=T, boundary=boundary), 60)
    path = path_from_spec(req.path_spec())
    entry = planner._entry(req, path, planner.model.friction)
    kw = dict(boundary=boundary, max_iter=planner.settings.max_iterations,
              tol=planner.settings.tolerance, warm_start=False)
    rows = Transcription(entry.nodes, entry.mids, entry.friction, band_rows=True, **kw)
    lean = Transcription(entry.nodes, entry.mids, entry.friction, **kw)
    K = entry.nodes.theta.size - 1
    assert rows._rows[-1] - lean._rows[-1] == 3 * K
    base, _ = planner._limits(req, planner.model.friction)
    sreq = SolveRequest(T, 0.0, 1.0, base.min_theta_dot, base.velocity_limit,
                        base.torque_limit)
    ra, rb = rows.solve(sreq), lean.solve(sreq)
    assert ra.stats.success and rb.stats.success
    if same:
        assert abs(rb.energy - ra.energy) <= 1e-6 * ra.energy
    delta2 = base.min_theta_dot ** 2
    low = []
    for r in (ra, rb):
        b = _b_between_nodes(r.profile.theta, r.profile.theta_dot,
                             r.profile.theta_ddot_nodes)
        inner = b[1:-1] if boundary == 'rest' else b
        assert b.min() >= -1e-9
        low.append(inner.min())
    # IPOPT holds bounds to ~1e-8 absolute (4e-6 of delta^2 = 0.0025 rad^2/s^2)
    assert low[1] >= min(low[0], delta2) - 2e-8, (low, delta2)
    if T > 20:
        assert low[1] <= 1.001 * delta2              # the floor is reached: the check bites
    with pytest.raises(ValueError, match='band_rows'):
        lean._bounds(SolveRequest(T, 0.0, 1.0, base.min_theta_dot, base.velocity_limit,
                                  base.torque_limit, tcp_speed_max=0.5))
