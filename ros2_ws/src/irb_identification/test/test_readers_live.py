"""Every tool reads every bag the project records (issue 32): a bag recorded by the real
``recorder`` node (in-process, default topics) from a simulated run published as the live
stack publishes it (six-joint /joint_states with 4-6 locked, /torque_command with effort only
and no names, /camera/tcp), the main job's split run bags (``X`` + ``X_drive``), and the
same run written directly (excite's writer) must give the same discrepancy answer."""
import json
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
plant_mod = pytest.importorskip('irb_control.plant')
from geometry_msgs.msg import PointStamped  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from irb_identification import bagio, discrepancy, identify  # noqa: E402
from irb_identification.discrepancy_core.bagdata import write_run  # noqa: E402
from irb_identification.discrepancy_core.excitation import load_plan, run_plan  # noqa: E402
from irb_identification.readers import copy_bag  # noqa: E402
from irb_identification.recorder_node import DEFAULT_TOPICS, RecorderNode  # noqa: E402

pytestmark = pytest.mark.ros
START_NS = 1_700_000_000 * 10**9
LOCKED = [0.0, 0.0, 0.0]          # joints 4-6 at their locked values


def spin_until(executor, cond, timeout=30.0):
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    return cond()


def stamp(msg, t_ns):
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t_ns // 10**9), int(t_ns % 10**9)


@pytest.fixture(scope='module')
def run(model):
    from irb_description.friction import load_friction_map
    fm = load_friction_map(plant_mod.default_plant_yaml(), model.joint_names)
    plan = load_plan(discrepancy.default_config_path().parent / 'excitation.yaml', 'short')
    return run_plan(model, plan[:1], fm, fm, None, seed=5)[0].data


def record_live(ctx, run, root):
    """Publish ``run`` as the live stack does, in bursts the recorder can take, into the real
    recorder with its default topics; returns the bag path."""
    context, executor = ctx
    node = rclpy.create_node('live_pub', context=context)
    qos = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    pubs = {'/joint_states': node.create_publisher(JointState, '/joint_states', qos),
            '/torque_command': node.create_publisher(JointState, '/torque_command', qos),
            '/camera/tcp': node.create_publisher(PointStamped, '/camera/tcp', qos)}
    rec = RecorderNode(context=context, parameter_overrides=[
        rclpy.parameter.Parameter('root', value=str(root)),
        rclpy.parameter.Parameter('name', value='live'),
        rclpy.parameter.Parameter('progress_period_s', value=0.0)])
    assert list(rec.topics) == DEFAULT_TOPICS
    executor.add_node(node)
    executor.add_node(rec)
    ns = lambda t: START_NS + int(round(t * 1e9))  # noqa: E731
    events = sorted([(ns(t), 0, i) for i, t in enumerate(run.t)]
                    + [(ns(t), 1, i) for i, t in enumerate(run.cmd_t)]
                    + [(ns(t), 2, i) for i, t in enumerate(run.cam_t)])
    # the recorder subscribes once it sees a publisher: publish the first of each, then wait
    assert spin_until(executor, lambda: all(p.get_subscription_count() for p in pubs.values()))
    sent = 0
    for k in range(0, len(events), 200):
        for t_ns, kind, i in events[k:k + 200]:
            if kind == 0:
                m = JointState()
                stamp(m, t_ns)
                m.name = [f'joint_{j}' for j in range(1, 7)]
                m.position = run.q[i].tolist() + LOCKED
                m.velocity = run.qd[i].tolist() + [0.0] * 3
                m.effort = run.effort[i].tolist() + [0.0] * 3
                pubs['/joint_states'].publish(m)
            elif kind == 1:
                m = JointState()                     # as pdplus: effort only, no names
                stamp(m, t_ns)
                m.effort = run.cmd[i].tolist()
                pubs['/torque_command'].publish(m)
            else:
                m = PointStamped()
                stamp(m, t_ns)
                m.header.frame_id = 'base_link'
                m.point.x, m.point.y, m.point.z = run.cam_p[i].tolist()
                pubs['/camera/tcp'].publish(m)
            sent += 1
        assert spin_until(executor, lambda: rec.writer.message_count >= sent), (
            f'recorder took {rec.writer.message_count} of {sent}')
    executor.remove_node(rec)
    executor.remove_node(node)
    rec.close()
    rec.destroy_node()
    node.destroy_node()
    return rec.bag_path


def rms(out):
    return json.loads((out / 'report.json').read_text())


def test_recorder_bag_main_job_pair_and_direct_bag_agree(ctx, run, model, tmp_path):
    live = record_live(ctx, run, tmp_path / 'bags')
    counts = bagio.bag_info(live)['topics']
    assert counts['/joint_states']['count'] == len(run.t)
    direct = write_run(tmp_path / 'direct', model.joint_names, run.t, run.q, run.qd,
                       run.effort, run.cmd_t, run.cmd, run.cam_t, run.cam_p)
    # the main job's shape: run bag + <run>_drive with the commands
    pair = copy_bag(live, tmp_path / 'main' / 'r1', topics=['/joint_states', '/camera/tcp'])
    copy_bag(live, tmp_path / 'main' / 'r1_drive', topics=['/torque_command'])
    plant = str(plant_mod.default_plant_yaml())
    reports = {}
    for name, bag in (('live', live), ('direct', direct), ('pair', pair),
                      ('folder', tmp_path / 'main')):
        out = tmp_path / f'out_{name}'
        code = discrepancy.main(['--bag', str(bag), '--model', plant, '--out', str(out),
                                 '--no-plots'])
        assert code == 0, name
        reports[name] = rms(out)
    d = reports['direct']
    assert d['data_quality']['complete']
    for name in ('live', 'pair', 'folder'):
        r = reports[name]
        assert r['effect'] == d['effect'], name
        assert r['data_quality']['complete'], (name, r['data_quality']['notes'])
        assert set(r['rms_before']) == set(d['rms_before']), name    # command channel too
        for k, v in d['rms_before'].items():
            assert r['rms_before'][k] == pytest.approx(v, rel=1e-9, abs=1e-12), (name, k)
    assert reports['folder']['bags'] == [str(pair)]      # r1_drive read through r1
    # identify on the live bag: joints 1-3 by name (4-6 are locked), no reading error
    j = tmp_path / 'id.json'
    code = identify.main(['--bag', str(live), '--out', str(tmp_path / 'id.yaml'), '--json',
                          str(j), '--no-plots', '--method', 'samples'])
    rep = json.loads(j.read_text())
    assert not rep['problems'] and set(rep['joints']) == {'joint_1', 'joint_2', 'joint_3'}
    assert code in (0, 2) and rep['complete_data']
    # identify given the drive half reads /joint_states from its run bag
    j2 = tmp_path / 'id2.json'
    identify.main(['--bag', str(tmp_path / 'main' / 'r1_drive'), '--out',
                   str(tmp_path / 'id2.yaml'), '--json', str(j2), '--no-plots', '--method',
                   'samples'])
    rep2 = json.loads(j2.read_text())
    assert not rep2['problems'] and set(rep2['joints']) == set(rep['joints'])
    # a drive bag alone: the error names the topic and what it is needed for
    lone = copy_bag(live, tmp_path / 'lone', topics=['/torque_command'])
    j3 = tmp_path / 'id3.json'
    assert identify.main(['--bag', str(lone), '--out', str(tmp_path / 'id3.yaml'), '--json',
                          str(j3)]) == 1
    err = json.loads(j3.read_text())['error']
    assert f'bag {lone}: no /joint_states (needed for the measured position' in err
    assert '/torque_command' in err
    out = tmp_path / 'out_lone'
    assert discrepancy.main(['--bag', str(lone), '--model', plant, '--out', str(out)]) == 1
