import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from irb_description.model import RobotModel


@pytest.fixture(scope='session')
def model() -> RobotModel:
    return RobotModel.load()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope='session')
def domain_id() -> int:
    """ROS domain for in-process and subprocess tests: ROS_DOMAIN_ID, else one of 50..69."""
    if 'ROS_DOMAIN_ID' not in os.environ:
        os.environ['ROS_DOMAIN_ID'] = str(50 + os.getpid() % 20)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    return int(os.environ['ROS_DOMAIN_ID'])


@pytest.fixture
def ctx(domain_id):
    """A private rclpy context on ``domain_id`` and a SingleThreadedExecutor in it."""
    rclpy = pytest.importorskip('rclpy')
    from rclpy.executors import SingleThreadedExecutor
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    executor = SingleThreadedExecutor(context=context)
    yield context, executor
    executor.shutdown()
    rclpy.try_shutdown(context=context)


def check_bag(path, decode_limit: int = 2000) -> dict:
    """Read a bag with rosbags and with mcap (+ mcap_ros2 decoding), CRCs validated.

    Both readers must see the same messages (topic, log time, bytes) and the counts of
    metadata.yaml. Returns {topic: count}.
    """
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader

    path = Path(path)
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['storage_identifier'] == 'mcap' and info['version'] == 9
    with Reader(path) as r:
        a = [(c.topic, t, bytes(d)) for c, t, d in r.messages()]
    b, decoded = [], 0
    for rel in info['relative_file_paths']:
        with open(path / rel, 'rb') as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
            summary = reader.get_summary()
            assert summary is not None and summary.statistics is not None
            for schema, channel, msg in reader.iter_messages(log_time_order=True):
                assert schema.encoding == 'ros2msg' and channel.message_encoding == 'cdr'
                b.append((channel.topic, msg.log_time, msg.data))
        if decoded < decode_limit:
            with open(path / rel, 'rb') as f:
                reader = make_reader(f, decoder_factories=[DecoderFactory()],
                                     validate_crcs=True)
                for _, _, _, ros_msg in reader.iter_decoded_messages():
                    assert ros_msg is not None
                    decoded += 1
                    if decoded >= decode_limit:
                        break
    assert sorted(a, key=lambda x: (x[1], x[0])) == sorted(b, key=lambda x: (x[1], x[0]))
    assert len(a) == info['message_count']
    counts = {}
    for topic, _, _ in a:
        counts[topic] = counts.get(topic, 0) + 1
    for entry in info['topics_with_message_count']:
        assert counts.get(entry['topic_metadata']['name'], 0) == entry['message_count']
    return counts


@pytest.fixture(scope='session')
def bag_check():
    return check_bag
