"""ROS_SECURITY_ENABLE=true on a middleware without DDS security: every node executable of the
workspace refuses to start with one line and exit code 3 (never runs open)."""
import os
import subprocess

import pytest

from irb_description.node_main import SECURITY_REFUSED_EXIT, middleware_security_support

# nodes or processes on the ROS graph: run with the ROS tests, one at a time (scripts/test.sh)
pytestmark = pytest.mark.ros

NODES = [('irb_control', 'simulator'), ('irb_control', 'pdplus'), ('irb_control', 'axis_bridge'),
         ('irb_control', 'fake_axis_computer'), ('irb_planning', 'planner'),
         ('irb_planning', 'plan'), ('irb_identification', 'recorder'),
         ('irb_identification', 'replay'), ('irb_identification', 'experiments'),
         ('irb_description', 'kinematics_server')]


@pytest.mark.slow
def test_every_node_refuses_without_security_support():
    supported, evidence = middleware_security_support()
    if supported is not False:
        pytest.skip(f'middleware security support: {supported} ({evidence})')
    env = dict(os.environ, ROS_SECURITY_ENABLE='true')
    env.pop('ROS_SECURITY_STRATEGY', None)
    procs = {exe: subprocess.Popen(['ros2', 'run', pkg, exe], env=env, text=True,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
             for pkg, exe in NODES}
    results = {}
    try:
        for exe, p in procs.items():
            out, err = p.communicate(timeout=120)
            results[exe] = (p.returncode, out, err)
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait(timeout=10)
    for exe, (rc, out, err) in results.items():
        lines = [ln for ln in (out + err).splitlines() if ln.strip()]
        assert rc == SECURITY_REFUSED_EXIT, (exe, rc, lines)
        assert len(lines) == 1 and lines[0].startswith('refusing to start: ROS_SECURITY'), \
            (exe, lines)
