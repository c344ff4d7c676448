"""End to end on the nodes (issue 30): a six-axis plan from ``plan6 --publish`` taken by pdplus
(joints 6) and played on the simulator (joints 6), measured from the simulator's
/joint_states with the independent check's DH kinematics (benchmarks/bench_six_joint_nodes.py,
whose ``run`` this calls; the rectangle's figures are in irb_control's
benchmarks/RESULTS.md)."""
import importlib.util
from pathlib import Path

import pytest

pytest.importorskip('rclpy')
pytestmark = pytest.mark.ros
BENCH = Path(__file__).resolve().parents[1] / 'benchmarks' / 'bench_six_joint_nodes.py'
DURATION = 8.0          # [s] the energy plan of the gluing rectangle (grid 40: ~10 s to plan)


def test_plan6_plan_played_by_pdplus_on_the_simulator():
    from irb_planning.six_axis_plan import config_path
    spec = importlib.util.spec_from_file_location('bench_six_joint_nodes', BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    # the simulator starts away from the plan's start: pdplus ramps there on enable
    out = bench.run(str(config_path().parent / 'path6_rectangle.yaml'), DURATION, grid=40,
                    timeout=120.0)
    assert out.get('plan6_exit') == 0, out
    assert 'accepted' in out['plan6_output'][-1], out['plan6_output']
    assert out['completed'] and not out['stop_reason'], out
    # the whole plan was followed in PATH mode (pdplus holds ~1 step before the plan's end)
    assert out['path_s'] == pytest.approx(DURATION, abs=0.1)
    # on the path and the tool's orientation held by the six joints (a locked wrist tilts
    # the nozzle by tens of degrees around the rectangle); figures: RESULTS.md
    assert out['path_error_max_mm'] < 5.0, out
    assert out['orientation_error_max_deg'] < 2.0, out
