"""The planner node's place_task service in-process (private Context, futures, no sleeps) and
the `place --node` client against it.

The oracle of the answer is not the node's own search: the returned best placement is
re-planned from its reported centre and angles by a separate core Planner, the returned
joints are put through the model's forward kinematics onto the placed circle, and the
certificate's bound is recomputed from the returned map by hand."""
import json
import os
import threading
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import Point  # noqa: E402
from irb_interfaces.msg import PathSpec  # noqa: E402
from irb_interfaces.srv import PlaceTask, PlanPath  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from irb_planning import place_cli  # noqa: E402
from irb_planning.messages import placement_from_msg  # noqa: E402
from irb_planning.placement import placement_request, plan_energy, plot_map  # noqa: E402
from irb_planning.planner_node import PlannerNode  # noqa: E402
from irb_planning.request import PlanRequest  # noqa: E402

pytestmark = pytest.mark.ros
TIMEOUT = 180.0
DURATION = 4.0
#: three centres along x: 0.5 and 0.9 m reachable, 1.3 m out of reach (the circle's far
#: point at 1.45 m)
LO, HI = (0.5, 0.0, 0.13), (1.3, 0.0, 0.13)


@pytest.fixture
def ros(tmp_path, monkeypatch):
    ctx = rclpy.Context()
    domain = int(os.environ.get('ROS_DOMAIN_ID', '41'))
    # the `place --node` client joins the default context, whose domain is the environment's:
    # the same one as the server's also when pytest runs without scripts/test.sh's variable
    monkeypatch.setenv('ROS_DOMAIN_ID', str(domain))
    rclpy.init(context=ctx, domain_id=domain)
    ns = f'/place_test_{uuid.uuid4().hex[:8]}'
    server = PlannerNode(context=ctx, namespace=ns, parameter_overrides=[
        Parameter('grid_size', value=40), Parameter('evaluation_rate_hz', value=500.0),
        Parameter('place_map_dir', value=str(tmp_path / 'maps'))])
    client = rclpy.create_node('place_test_client', namespace=ns, context=ctx)
    executor = MultiThreadedExecutor(num_threads=4, context=ctx)
    executor.add_node(server)
    executor.add_node(client)
    yield server, client, executor, ns
    executor.shutdown()
    client.destroy_node()
    server.destroy_node()
    rclpy.try_shutdown(context=ctx)


def _place(lo=LO, hi=HI, n=(3, 1, 1), **kw):
    req = PlaceTask.Request()
    req.path = PathSpec(type='circle', radius=0.15, direction=1)
    req.duration = DURATION
    req.lo, req.hi = Point(x=lo[0], y=lo[1], z=lo[2]), Point(x=hi[0], y=hi[1], z=hi[2])
    req.rotations, req.tilt_x, req.tilt_y = [0.0], [0.0], [0.0]
    req.grid_points = list(n)
    req.grid_size, req.coarse_grid_size, req.refine, req.min_step = 40, 30, 1, 0.15
    for k, v in kw.items():
        setattr(req, k, v)
    return req


def _wait(executor, future):
    executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
    assert future.done(), 'no answer in time'
    return future.result()


def _spin_until(executor, condition):
    """spin_once until ``condition()`` (bounded: TIMEOUT in steps of at most 0.1 s)."""
    for _ in range(int(TIMEOUT / 0.1)):
        if condition():
            return
        executor.spin_once(timeout_sec=0.1)
    assert condition(), 'condition not reached in time'


@pytest.mark.slow
def test_place_finds_the_best_shows_refused_points_and_keeps_plan_path_serving(
        ros, planner, model, tmp_path):
    server, client, executor, ns = ros
    place = client.create_client(PlaceTask, 'place_task')
    plan = client.create_client(PlanPath, 'plan_path')
    assert place.wait_for_service(timeout_sec=30.0) and plan.wait_for_service(timeout_sec=30.0)

    # the search is held inside its first plan until plan_path has answered: if plan_path
    # waited for the search (one callback group, too few executor threads, one lock), it
    # would not answer and the wait below would time out. (Without the gate the test raced:
    # since the search's planner skips the time-optimal check, this 3-point search can end
    # before a 4 s plan is answered.)
    gate, inner = threading.Event(), server.place_planner.plan

    def held(request):
        gate.wait(timeout=TIMEOUT)
        return inner(request)
    server.place_planner.plan = held
    running = place.call_async(_place())
    _spin_until(executor, lambda: server.place_running)
    # a second search while one runs: refused at once, not queued
    busy = _wait(executor, place.call_async(_place()))
    assert not busy.success and busy.error_code == PlaceTask.Response.ERROR_BUSY
    assert 'already running' in busy.message
    # plan_path answers while the search runs
    req = PlanPath.Request(objective='energy', duration=DURATION)
    req.path = PathSpec(type='circle', center=Point(x=0.6, y=0.0, z=0.13), radius=0.15,
                        direction=1)
    planned = _wait(executor, plan.call_async(req))
    assert planned.success, planned.message
    assert not running.done(), 'the plan should be answered before the search ends'
    gate.set()
    resp = _wait(executor, running)
    assert resp.success, resp.message
    assert resp.error_code == PlaceTask.Response.ERROR_NONE
    print(resp.message)

    # every map point is in the answer; the one out of reach with the planner's reason
    assert list(resp.map_shape) == [3, 1, 1, 1]
    np.testing.assert_allclose(resp.map_x, [0.5, 0.9, 1.3])
    E = np.asarray(resp.map_energy)
    assert E.size == len(resp.map_reason) == 3
    assert np.isnan(E[2]) and 'unreachable' in resp.map_reason[2]
    assert np.all(np.isfinite(E[:2])) and list(resp.map_reason[:2]) == ['', '']
    # the best is not worse than any map point beyond the grids' discretisation difference
    # (coarse 30 vs 40 nodes)
    assert resp.best_energy <= np.nanmin(E) * 1.01
    assert LO[0] <= resp.best_center.x <= HI[0]
    assert resp.best_center.y == LO[1] and resp.best_center.z == LO[2]

    # oracle 1: a separate Planner re-plans the reported placement from the reported numbers
    c = np.array([resp.best_center.x, resp.best_center.y, resp.best_center.z])
    again = planner.plan(placement_request(
        PlanRequest(radius=0.15, duration=DURATION, grid_size=40), c, resp.best_rotation,
        resp.best_tilt_x, resp.best_tilt_y))
    assert plan_energy(again, 'mechanical') == pytest.approx(resp.best_energy, rel=2e-3)
    # the plan fields are those of the best placement's plan
    assert resp.energy == pytest.approx(resp.best_energy, rel=1e-12)
    assert resp.energy <= resp.baseline_energy and resp.energy_model == 'mechanical'
    # oracle 2: the returned joints are on the circle placed at the reported centre
    q = np.array([p.positions for p in resp.trajectory.points])
    tcp = np.array([model.fk(x) for x in q])
    np.testing.assert_allclose(np.linalg.norm(tcp - c, axis=1), 0.15, atol=1e-6)
    np.testing.assert_allclose(tcp[:, 2], c[2], atol=1e-6)
    last = resp.trajectory.points[-1].time_from_start
    assert last.sec + 1e-9 * last.nanosec == pytest.approx(DURATION, rel=1e-6)
    assert resp.best_path.type == 'circle' and resp.best_path.center.x == c[0]

    # oracle 3: the certificate from the map by hand: one fully reachable cell of two
    h = 0.4
    lip = abs(E[1] - E[0]) / h
    assert resp.cells_covered == 1 and resp.cells_total == 2
    assert resp.lipschitz[0] == pytest.approx(lip, rel=1e-9)
    assert resp.region_lower_bound == pytest.approx(min(E[:2]) - lip * h / 2, rel=1e-9)
    assert resp.possible_improvement_pct == pytest.approx(
        100 * (resp.best_energy - resp.region_lower_bound) / resp.best_energy, rel=1e-9)
    assert resp.evaluations >= 4 and resp.search_time > 0
    assert resp.map_png and os.path.getsize(resp.map_png) > 0
    # the evidence not asked for: one compass search (from the best re-planned point), no
    # spread, no bounds; the coverage by hand: the refused x = 1.3 m end owns a quarter of
    # the box (boxes 0.2, 0.4, 0.2 m along x); mechanical: no electrical cap
    assert len(resp.end_energy) == len(resp.start_coarse_energy) == 1
    assert len(resp.start_center) == len(resp.end_center) == 3
    assert resp.end_energy[0] == resp.best_energy
    assert [resp.end_center[0], resp.end_center[1], resp.end_center[2]] == [c[0], c[1], c[2]]
    for name in ('multistart_spread_pct', 'grid_bound_floor', 'best_lower_bound',
                 'bound_gap_pct', 'fixed_electrical_energy'):
        assert np.isnan(getattr(resp, name)), name
    assert resp.covered_share == pytest.approx(0.75) and resp.refused_share == pytest.approx(
        0.25)

    # the client's side: the answer as a PlacementResult draws and writes the same JSON
    res = placement_from_msg(resp)
    assert res.reasons == {(2, 0, 0, 0): resp.map_reason[2]}
    assert plot_map(str(tmp_path / 'client.png'), res)
    out = place_cli.result_json(res)
    assert out['best_center'] == pytest.approx(c.tolist()) and len(out['refused']) == 1
    text = place_cli.summary(resp)
    assert f'best placement: centre [{c[0]:.4f}, {c[1]:.4f}, {c[2]:.4f}] m' in text
    assert f'{resp.best_energy:.2f} J' in text and 'trapezoid' in text
    lines = place_cli.evidence_lines(res, resp.fixed_electrical_energy)
    assert lines[0].startswith('start 1/1 ') and f'{resp.best_energy:.2f} J' in lines[0]
    assert 'convex bounds: not computed (--bounds)' in lines
    assert lines[-1].startswith('coverage: 75.0 % of the box')


@pytest.mark.slow
def test_place_on_the_electrical_model_judges_by_the_electrical_energy(ros, planner):
    """The search judges by the requested model: best_energy is the electrical (shared bus)
    energy of the plan, and a separate Planner re-planning the placement agrees."""
    server, client, executor, ns = ros
    place = client.create_client(PlaceTask, 'place_task')
    assert place.wait_for_service(timeout_sec=30.0)
    c = (0.6, 0.0, 0.13)
    resp = _wait(executor, place.call_async(_place(
        lo=c, hi=c, n=(1, 1, 1), energy_model='electrical_shared', grid_size=30)))
    assert resp.success, resp.message
    assert resp.energy_model == 'electrical_shared' and list(resp.map_shape) == [1, 1, 1, 1]
    shared = list(resp.electrical_bus_modes).index('shared')
    assert resp.best_energy == pytest.approx(resp.electrical_energy[shared], rel=1e-12)
    assert resp.best_energy > 10 * resp.energy          # standby: far above the mechanical
    assert resp.map_energy[0] == pytest.approx(resp.best_energy, rel=1e-3)   # same grid
    again = planner.plan(placement_request(
        PlanRequest(radius=0.15, duration=DURATION, grid_size=30,
                    energy_model='electrical_shared'), c))
    assert plan_energy(again, 'electrical_shared') == pytest.approx(resp.best_energy,
                                                                    rel=2e-3)
    # the electrical cap from the model's numbers by hand, below the plan's energy
    el = planner.electrical
    fixed = (float(el.standby_power) + float(np.sum(el.drive_idle_power))) * DURATION
    assert resp.fixed_electrical_energy == pytest.approx(fixed, rel=1e-12)
    assert fixed < resp.best_energy


def test_bad_requests_refused_with_one_line_and_nothing_reachable_shows_the_map(ros):
    server, client, executor, ns = ros
    place = client.create_client(PlaceTask, 'place_task')
    assert place.wait_for_service(timeout_sec=30.0)
    bad = [(_place(lo=(0.8, 0, 0), hi=(0.4, 0, 0)), 1, 'lo <= hi'),
           (_place(lo=(float('nan'), 0, 0)), 1, 'finite'),
           (_place(rotations=[]), 1, 'rotations'),
           (_place(tilt_x=[np.radians(100.0)]), 1, 'tilt'),
           (_place(path=PathSpec(type='line', radius=0.15, direction=1)), 1, 'circle'),
           (_place(energy_model='nope'), 1, 'energy_model'),
           (_place(duration=0.0), 1, 'duration'),
           (_place(n=(100, 100, 1)), 1, 'place_max_points'),
           (_place(min_step=-1.0), 1, 'min_step'),
           (_place(path=PathSpec(type='circle', radius=-0.1, direction=1)), 1, 'radius'),
           (_place(coarse_grid_size=5), 1, 'grid_size'),
           (_place(starts=17), 1, 'place_max_starts'),
           (_place(friction_map='/no/such/map.yaml'), 4, '')]
    for req, code, word in bad:
        resp = _wait(executor, place.call_async(req))
        assert not resp.success and resp.error_code == code, (word, resp.message)
        assert resp.message and '\n' not in resp.message and word in resp.message
        assert 'Traceback' not in resp.message
        assert not server.place_running
    # nothing in the region reachable: refused with code 2, the map says why
    far = _wait(executor, place.call_async(_place(lo=(2.0, 0, 0.13), hi=(2.0, 0.2, 0.13),
                                                  n=(1, 2, 1))))
    assert not far.success and far.error_code == PlaceTask.Response.ERROR_UNREACHABLE
    assert list(far.map_shape) == [1, 2, 1, 1] and np.all(np.isnan(far.map_energy))
    assert all('unreachable' in r for r in far.map_reason) and far.message


@pytest.mark.slow
def test_place_with_starts_and_bounds_answers_the_global_evidence(ros, tmp_path, capsys):
    """starts = 2 and bounds on the 3 x 1 x 1 region (one point out of reach): one entry
    per start, the ends inside the box and never below the best, the convex bounds below
    the plans; the client prints the evidence from the answer, and refuses --starts 99
    through the node with one line."""
    server, client, executor, ns = ros
    place = client.create_client(PlaceTask, 'place_task')
    assert place.wait_for_service(timeout_sec=30.0)
    resp = _wait(executor, place.call_async(_place(starts=2, bounds=True)))
    assert resp.success, resp.message
    k = len(resp.end_energy)
    assert k == 2 and len(resp.start_coarse_energy) == len(resp.start_local_minimum) == k
    assert len(resp.start_center) == len(resp.end_center) == len(resp.end_orientation) == 3 * k
    E = np.asarray(resp.map_energy)
    start = np.asarray(resp.start_center).reshape(k, 3)
    # the starts are the two reachable map points, the best (a local minimum) first
    assert sorted(start[:, 0].tolist()) == pytest.approx([0.5, 0.9])
    np.testing.assert_allclose(sorted(resp.start_coarse_energy), np.sort(E[:2]), rtol=1e-12)
    assert resp.start_local_minimum[0] and resp.start_coarse_energy[0] == np.nanmin(E)
    ends = np.asarray(resp.end_center).reshape(k, 3)
    assert np.all(np.isfinite(resp.end_energy))
    lo, hi = np.array(LO), np.array(HI)
    assert np.all(ends >= lo - 1e-12) and np.all(ends <= hi + 1e-12)
    assert np.all(np.asarray(resp.end_orientation) == 0.0)
    assert min(resp.end_energy) == resp.best_energy
    assert all(e >= resp.best_energy - 1e-9 for e in resp.end_energy)
    spread = 100 * (max(resp.end_energy) - resp.best_energy) / resp.best_energy
    assert resp.multistart_spread_pct == pytest.approx(spread, rel=1e-9, abs=1e-12)
    # the convex bounds: below every timing at the best placement and at the map points
    assert 0.0 < resp.best_lower_bound <= resp.best_energy
    assert 0.0 < resp.grid_bound_floor <= np.nanmin(E)
    assert resp.bound_gap_pct == pytest.approx(
        100 * (resp.best_energy - resp.grid_bound_floor) / resp.best_energy, rel=1e-9)
    assert resp.covered_share == pytest.approx(0.75) and resp.refused_share == pytest.approx(
        0.25)
    assert np.isnan(resp.fixed_electrical_energy)
    assert 'starts, spread' in resp.message and 'convex bounds' in resp.message
    # the client's lines from the answer
    res = placement_from_msg(resp)
    lines = place_cli.evidence_lines(res)
    assert lines[0].startswith('start 1/2 ') and lines[1].startswith('start 2/2 ')
    assert f'{resp.end_energy[1]:.2f} J' in lines[1]
    assert lines[2].startswith('multi-start: 2 of 2 starts ended within')
    assert lines[3].startswith(f'convex bounds: every timing at every planned map point '
                               f'costs >= {resp.grid_bound_floor:.2f} J')
    out = place_cli.result_json(res)
    assert len(out['starts']) == 2 and out['grid_bound_floor_j'] == resp.grid_bound_floor
    # a user asking the node for too many starts: one line, exit 1, no search
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    code = place_cli.main(['--node', '--service', f'{ns}/place_task', '--starts', '99',
                           '--timeout', str(TIMEOUT), '--plot', ''])
    out = capsys.readouterr().out
    assert code == 1, out
    assert out.count('\n') == 2 and 'placement refused (error 1): 99 starts asked for, at ' \
        'most 16 (parameter place_max_starts)' in out


def test_place_response_carries_every_plan_path_field():
    plan = PlanPath.Response.get_fields_and_field_types()
    place = PlaceTask.Response.get_fields_and_field_types()
    assert {k: place.get(k) for k in plan} == plan
    for name in ('ERROR_NONE', 'ERROR_INVALID_REQUEST', 'ERROR_UNREACHABLE',
                 'ERROR_FRICTION_MAP', 'ERROR_SOLVER'):
        assert getattr(PlaceTask.Response, name) == getattr(PlanPath.Response, name)


def test_place_client_asks_the_node_and_writes_its_outputs(ros, tmp_path, capsys):
    """The client end to end against the node (spun in a thread): a region out of reach,
    so that it runs in a second; its refusal, and the map JSON naming every refused point.
    The success summary is checked on a real answer in the first test."""
    server, client, executor, ns = ros
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    png, js = tmp_path / 'p.png', tmp_path / 'p.json'
    code = place_cli.main(['--node', '--service', f'{ns}/place_task', '--lo', '2.0', '0',
                           '0.13', '--hi', '2.0', '0.3', '0.13', '--n', '1', '3', '1',
                           '--rotations', '0', '90', '--duration', str(DURATION),
                           '--timeout', str(TIMEOUT), '--plot', str(png), '--json', str(js)])
    out = capsys.readouterr().out
    assert code == 1, out
    assert f'placement refused (error {PlaceTask.Response.ERROR_UNREACHABLE})' in out
    data = json.loads(js.read_text())
    assert data['best_center'] is None and len(data['refused']) == 3 * 2
    assert all('unreachable' in r for r in data['refused'].values())
    assert not png.exists()                # nothing to colour: no empty picture
    # bad arguments: one line, exit 2, no call
    assert place_cli.main(['--node', '--lo', '1', '0', '0', '--hi', '0', '0', '0']) == 2
    assert 'lo <= hi' in capsys.readouterr().err


def test_destroying_the_node_stops_a_running_search_at_its_next_plan():
    """Ctrl-C must not wait for a search of minutes: after destroy_node no further plan of
    the search starts (counted at the planner), and the search ends."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '41')))
    ns = f'/place_stop_{uuid.uuid4().hex[:8]}'
    server = PlannerNode(context=ctx, namespace=ns,
                         parameter_overrides=[Parameter('grid_size', value=40)])
    client = rclpy.create_node('place_stop_client', namespace=ns, context=ctx)
    executor = MultiThreadedExecutor(num_threads=4, context=ctx)
    executor.add_node(server)
    executor.add_node(client)
    calls = []
    plan = server.place_planner.plan
    server.place_planner.plan = lambda req: calls.append(req) or plan(req)
    try:
        place = client.create_client(PlaceTask, 'place_task')
        assert place.wait_for_service(timeout_sec=30.0)
        place.call_async(_place(lo=(0.5, -0.2, 0.13), hi=(0.7, 0.2, 0.13), n=(3, 3, 1)))
        _spin_until(executor, lambda: len(calls) >= 1)
        server.destroy_node()
        started = len(calls)
        _spin_until(executor, lambda: not server.place_running)
        assert len(calls) == started < 9
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.try_shutdown(context=ctx)
