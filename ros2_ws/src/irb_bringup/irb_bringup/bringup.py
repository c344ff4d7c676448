"""`ros2 run irb_bringup bringup [--config YAML]`: the node graph as processes.

PyPI has no launch_ros, so this starts each node of config/bringup.yaml with `ros2 run`,
prefixes their output, and runs until Ctrl-C / SIGTERM or until a required node fails; then
it stops every node (SIGINT, SIGTERM, SIGKILL after bounded waits). Exit code 0 after a
requested stop, 1 when a node failed. On a full ROS 2 install the same graph is
`ros2 launch irb_bringup irb_graph.launch.py`.
"""
from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path

from irb_control.process_group import ProcessGroup, ProcessSpec, ros2_run_cmd

from .graph_spec import load_graph


def main(args=None) -> int:
    from ament_index_python.packages import get_package_share_directory
    default = Path(get_package_share_directory('irb_bringup')) / 'config' / 'bringup.yaml'
    ap = argparse.ArgumentParser(prog='bringup', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--config', default=str(default), help='graph YAML')
    a = ap.parse_args(args)
    try:
        nodes = load_graph(a.config)
    except (OSError, ValueError) as exc:
        print(f'bringup: {exc}', file=sys.stderr)
        return 2
    specs = [ProcessSpec(n.name, ros2_run_cmd(n.package, n.executable, params=n.parameters),
                         n.required) for n in nodes]
    stop = threading.Event()
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, lambda *_: stop.set())
    group = ProcessGroup(specs, log=lambda m: print(f'[bringup] {m}', flush=True))
    with group:
        print(f'[bringup] {len(specs)} nodes up; Ctrl-C stops them', flush=True)
        while not stop.is_set() and group.poll() is None:
            stop.wait(0.2)
        failed = f' ({group.failed} failed)' if group.failed else ''
        print(f'[bringup] stopping the graph{failed}', flush=True)
    return 1 if group.failed else 0


if __name__ == '__main__':
    sys.exit(main())
