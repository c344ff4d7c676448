"""Live identification: experiments drive the simulated plant through pdplus while the
identifier listens to the live /joint_states (no bag in between); ~/compute then gives a map
that matches the plant's friction (irb_control/config/plant.yaml)."""
import json
import os

import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.lockstep_e2e]

SPEEDS = [0.02, 0.035, 0.06, 0.1, 0.2, 0.4, 0.8, 1.2]   # [rad/s], two below v_s = 0.04


def test_live_experiments_into_the_identifier_match_the_plant(tmp_path):
    import rclpy
    from ament_index_python.packages import get_package_share_directory
    from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd
    from irb_description.friction import load_friction_map
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    fmap, report = tmp_path / 'live_map.yaml', tmp_path / 'live_map.json'
    specs = [
        ProcessSpec('simulator', ros2_run_cmd('irb_control', 'simulator', params={
            'mode': 'lockstep', 'lockstep_wait_s': 0.5})),
        ProcessSpec('pdplus', ros2_run_cmd('irb_control', 'pdplus', params={
            'use_sim_time': True, 'reference_mode': 'time', 'friction_mode': 'none'})),
        # live: the stream never ends by itself (the plant keeps holding), so no quiet
        # period; the map is asked for with ~/compute once the experiments are done
        ProcessSpec('identifier', ros2_run_cmd('irb_identification', 'identifier', params={
            'out_map': str(fmap), 'out_report': str(report), 'joints': "['joint_3']",
            'quiet_period_s': 0.0, 'effort_lag_s': 0.0024192})),
    ]
    # started once the identifier listens: the first move (+0.02 rad/s) comes ~2.5 s of
    # simulated time after the start, a fraction of a second of wall time in lockstep, and
    # an identifier that subscribed later missed it (fresh-clone CI 2026-11-26: 19231
    # samples received instead of ~21500, "speed 0.01998 rad/s seen only with sign -")
    experiments = ProcessSpec(
        'experiments', ros2_run_cmd('irb_identification', 'experiments', params={
            'mode': 'ros', 'use_sim_time': True, 'root': str(tmp_path / 'bags'),
            'prefix': 'live', 'joints': "['joint_3']", 'speeds_rad_s': str(SPEEDS),
            'hold_max_s': 2.5, 'hold_min_s': 2.5}), required=False)
    lines = []

    class Out:
        def write(self, text):
            lines.append(text)

        def flush(self):
            pass
    group = ProcessGroup(specs, log=lines.append, stream=Out())
    group.start()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        listening = group.wait_until(lambda: any(
            ln.startswith('[identifier]') and 'subscribed to' in ln for ln in list(lines)),
            120.0)
        assert listening, ''.join(map(str, lines))[-3000:]
        group.add(experiments)
        done = group.wait_until(lambda: group.procs['experiments'].poll() is not None, 400.0,
                                period_s=0.5)
        tail = ''.join(map(str, lines))[-3000:]
        assert done and group.procs['experiments'].returncode == 0, tail
        node = rclpy.create_node('live_ident_test', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        client = node.create_client(Trigger, '/identifier/compute')
        assert client.wait_for_service(timeout_sec=60.0), tail
        fut = client.call_async(Trigger.Request())
        executor.spin_until_future_complete(fut, timeout_sec=120.0)
        assert fut.done(), tail
        res = fut.result()
        assert res.success, res.message + tail
        assert res.message == str(fmap)
    finally:
        codes = group.stop()
        context.try_shutdown()
    assert codes['identifier'] == 0, ''.join(map(str, lines))[-3000:]   # Ctrl-C: clean exit
    rep = json.loads(report.read_text())
    # the live stream: everything the plant published while the identifier listened,
    # holds and moves between runs included; one run per speed found in it
    assert rep['stream']['trigger'] == 'service' and rep['stream']['received'] > 2000
    j3 = rep['joints']['joint_3']
    assert j3['error'] is None and j3['speeds'] >= len(SPEEDS), j3
    def joint_3(m):
        return m.joints[m.joint_names.index('joint_3')]
    got = joint_3(load_friction_map(fmap))
    plant = joint_3(load_friction_map(
        os.path.join(get_package_share_directory('irb_control'), 'config', 'plant.yaml')))
    v = np.array(SPEEDS)
    err = np.abs(got.torque(v) - plant.torque(v))
    # the plant's friction torque at the swept speeds (11.5 .. 28 N m) within 0.5 % (seen:
    # <= 0.004 N m, 0.03 %). Without the speeds below the plant's Stribeck velocity
    # (0.04 rad/s) the fit has no hump to find and Coulomb absorbs it: +0.5 N m at 0.05 rad/s
    assert np.all(err < 0.005 * plant.torque(v)), (err, got, plant)
    assert got.coulomb == pytest.approx(plant.coulomb, rel=0.02)
    assert got.viscous == pytest.approx(plant.viscous, rel=0.02)
