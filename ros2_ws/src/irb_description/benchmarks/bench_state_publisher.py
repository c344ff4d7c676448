#!/usr/bin/env python3
"""Cost of the state_publisher per joint state (it runs at 248 Hz).

    python ros2_ws/src/irb_description/benchmarks/bench_state_publisher.py

1. The six joint transforms (parent -> child, translation + quaternion, what /tf carries):
   ``robot_state.TfTree.transforms`` (own URDF-tree code) against pinocchio
   (``forwardKinematics`` on the six-joint model, then each joint's ``liMi`` placement as a
   quaternion), both checked equal first.
2. The node's whole callback on serialized joint states (``on_state_raw``: CDR read,
   positions by name, transforms, CDR TFMessage, trace bookkeeping), and for comparison the
   same work through rclpy's message objects (deserialize the JointState, build and serialize
   a TFMessage of six TransformStamped), in-process with the publishers replaced by no-ops,
   so the figures are Python work, not DDS.
Median, 90th percentile and max [us] over 5 repeats of 2000 random states; writes
results/state_publisher.json.
"""
import json
import os
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from irb_description.params import load_kinematics, urdf_path
from irb_description.robot_state import TfTree

RESULTS = Path(__file__).resolve().parent / 'results'
N = 2000
REPEATS = 5


def stats(samples_s):
    x = np.asarray(samples_s) * 1e6
    return {'median_us': float(np.median(x)), 'p90_us': float(np.percentile(x, 90)),
            'max_us': float(x.max()), 'n': int(len(x))}


def pinocchio_transforms(model, data, q):
    pin.forwardKinematics(model, data, q)
    out = []
    for j in range(1, model.njoints):
        M = data.liMi[j]
        out.append((model.names[model.parents[j]], model.names[j],
                    tuple(M.translation), tuple(pin.Quaternion(M.rotation).coeffs())))
    return out


def time_each(fn, qs):
    t = []
    for q in qs:
        t0 = time.perf_counter()
        fn(q)
        t.append(time.perf_counter() - t0)
    return t


def main():
    kin = load_kinematics()
    tree = TfTree(urdf_path().read_text())
    model = pin.buildModelFromUrdf(str(urdf_path()))
    data = model.createData()
    rng = np.random.default_rng(7)
    qs = rng.uniform(kin.lower, kin.upper, size=(N, 6))
    for q in qs[:50]:                            # the two agree before they are timed
        own = tree.transforms(q)
        ref = pinocchio_transforms(model, data, q)
        for (_, _, t, r), (_, _, t2, r2) in zip(own, ref):
            assert np.allclose(t, t2, atol=1e-12)
            assert min(np.abs(np.subtract(r, r2)).max(), np.abs(np.add(r, r2)).max()) < 1e-12
    out = {'load_average_before': os.getloadavg(), 'states': N, 'repeats': REPEATS}
    own_t, pin_t = [], []
    for _ in range(REPEATS):
        own_t += time_each(tree.transforms, qs)
        pin_t += time_each(lambda q: pinocchio_transforms(model, data, q), qs)
    out['transforms_own'] = stats(own_t)
    out['transforms_pinocchio'] = stats(pin_t)
    out['callback_raw'], out['callback_objects'] = callback_cost(qs)
    out['load_average_after'] = os.getloadavg()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / 'state_publisher.json').write_text(json.dumps(out, indent=2) + '\n')
    print(json.dumps(out, indent=2))


def callback_cost(qs):
    import rclpy
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import JointState

    from irb_description.state_publisher import make_node

    class Null:
        def publish(self, msg):
            pass

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')))
    try:
        node = make_node(context=ctx, namespace='/bench_state_publisher')
        node.pub_tf = node.pub_trace = Null()
        names = [f'joint_{i}' for i in range(1, 7)]
        msgs = []
        for k, q in enumerate(qs):
            m = JointState(name=names, position=q.tolist(), velocity=[0.0] * 6,
                           effort=[0.0] * 6)
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(k * 4_032_000, 10**9)
            msgs.append(m)
        raw = [serialize_message(m) for m in msgs]
        t = []
        for _ in range(REPEATS):
            t += time_each(node.on_state_raw, raw)
        from geometry_msgs.msg import TransformStamped
        from tf2_msgs.msg import TFMessage

        def objects(data):
            m = deserialize_message(data, JointState)
            q, _ = node.tree.positions(m.name, m.position)
            out = TFMessage()
            for parent, child, tr, ro in node.tree.transforms(q):
                x = TransformStamped()
                x.header.stamp = m.header.stamp
                x.header.frame_id, x.child_frame_id = parent, child
                v, r = x.transform.translation, x.transform.rotation
                v.x, v.y, v.z = tr
                r.x, r.y, r.z, r.w = ro
                out.transforms.append(x)
            serialize_message(out)
        t_obj = []
        for _ in range(REPEATS):
            t_obj += time_each(objects, raw)
        node.destroy_node()
        return stats(t), stats(t_obj)
    finally:
        rclpy.try_shutdown(context=ctx)


if __name__ == '__main__':
    main()
