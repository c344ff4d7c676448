"""ROS_SECURITY_ENABLE=true is never ignored: a node refuses to start with one line when the
middleware has no DDS security, and a missing keystore fails instead of running open."""
import os
import subprocess
import sys

import pytest

rclpy = pytest.importorskip('rclpy')
from irb_description import node_main  # noqa: E402

# nodes or processes on the ROS graph: run with the ROS tests, one at a time (scripts/test.sh)
pytestmark = pytest.mark.ros

NODE = ['-m', 'irb_description.kinematics_server']


def _env(**extra):
    env = dict(os.environ)
    env.pop('ROS_SECURITY_STRATEGY', None)
    env.update(extra)
    return env


def _fake_prefix(tmp_path, have_security=None, rmw_without_security=False):
    if have_security is not None:
        inc = tmp_path / 'include' / 'fastrtps'
        inc.mkdir(parents=True)
        inc.joinpath('config.h').write_text(
            f'#ifndef HAVE_SECURITY\n#define HAVE_SECURITY {have_security}\n#endif\n')
    if rmw_without_security:
        lib = tmp_path / 'lib'
        lib.mkdir(parents=True)
        lib.joinpath('librmw_fastrtps_shared_cpp.so').write_bytes(
            b"\x7fELF...This Fast DDS version doesn't have the security libraries\n\0")
    return tmp_path


@pytest.mark.parametrize('have, rmw_flag, expected', [
    (0, False, False), (1, False, True), (1, True, False), (None, False, None)])
def test_build_evidence(tmp_path, monkeypatch, have, rmw_flag, expected):
    prefix = _fake_prefix(tmp_path, have, rmw_flag)
    monkeypatch.setattr(node_main, '_prefixes', lambda: [prefix])
    supported, evidence = node_main.middleware_security_support('rmw_fastrtps_cpp')
    assert supported is expected and evidence
    assert node_main.middleware_security_support('rmw_cyclonedds_cpp')[0] is None


def test_no_security_request_changes_nothing(monkeypatch):
    monkeypatch.delenv('ROS_SECURITY_ENABLE', raising=False)
    monkeypatch.delenv('ROS_SECURITY_STRATEGY', raising=False)
    node_main.refuse_insecure_start()
    assert 'ROS_SECURITY_STRATEGY' not in os.environ


def test_unknown_support_forces_enforce(monkeypatch):
    monkeypatch.setenv('ROS_SECURITY_ENABLE', 'true')
    monkeypatch.setenv('ROS_SECURITY_STRATEGY', 'Permissive')
    monkeypatch.setattr(node_main, 'middleware_security_support', lambda: (None, 'unknown'))
    node_main.refuse_insecure_start()
    assert os.environ['ROS_SECURITY_STRATEGY'] == 'Enforce'


def test_this_middleware_build_is_recognised():
    """The wheels this workspace installs are built without DDS security (DESIGN §9); on a
    full ROS 2 install with SROS2 the answer is True. Either way it is not unknown."""
    supported, evidence = node_main.middleware_security_support()
    if rclpy.get_rmw_implementation_identifier().startswith('rmw_fastrtps'):
        assert supported is not None, evidence


def test_node_refuses_with_one_line():
    supported, _ = node_main.middleware_security_support()
    if supported is not False:
        pytest.skip('this middleware has DDS security: nothing to refuse')
    res = subprocess.run([sys.executable, *NODE], env=_env(ROS_SECURITY_ENABLE='true'),
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == node_main.SECURITY_REFUSED_EXIT, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith('refusing to start: ROS_SECURITY_ENABLE')
    assert 'Traceback' not in res.stdout + res.stderr


def test_missing_keystore_refused_not_open(tmp_path):
    """Where the middleware could secure (or nobody can tell), a node without a keystore
    stops with one line; rcl's default Permissive strategy would have run it unsecured."""
    code = ('import sys; from irb_description import node_main as m; '
            "m.middleware_security_support = lambda: (None, 'test'); "
            'from irb_description.kinematics_server import main; sys.exit(main())')
    res = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=60, env=_env(ROS_SECURITY_ENABLE='true',
                                              ROS_SECURITY_KEYSTORE=str(tmp_path / 'none')))
    assert res.returncode == node_main.SECURITY_REFUSED_EXIT, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith('refusing to start')]
    assert len(lines) == 1 and 'security set-up failed' in lines[0]
    assert 'Traceback' not in res.stderr
