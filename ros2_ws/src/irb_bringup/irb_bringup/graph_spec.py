"""The node graph description shared by `bringup` and launch/irb_graph.launch.py (no ROS).

config/bringup.yaml lists nodes (name, package, executable, parameters, required); `bringup`
turns them into processes (`ros2 run ...`), the launch file into launch_ros Node actions.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml


@dataclass(frozen=True)
class NodeSpec:
    """One node of the graph; ``parameters`` are overrides of the node's defaults."""

    name: str
    package: str
    executable: str
    parameters: dict = field(default_factory=dict)
    required: bool = True


def load_graph(path: str | Path) -> list[NodeSpec]:
    """Nodes of a bring-up YAML; ValueError naming the problem on a malformed file."""
    data = yaml.safe_load(Path(path).read_text())
    if not isinstance(data, dict) or not isinstance(data.get('nodes'), list):
        raise ValueError(f'{path}: expected a mapping with a list "nodes"')
    out = []
    for i, n in enumerate(data['nodes']):
        try:
            out.append(NodeSpec(str(n['name']), str(n['package']), str(n['executable']),
                                dict(n.get('parameters') or {}), bool(n.get('required', True))))
        except (KeyError, TypeError) as exc:
            raise ValueError(f'{path}: node {i} lacks {exc}') from exc
    names = [n.name for n in out]
    if len(set(names)) != len(names):
        raise ValueError(f'{path}: duplicate node names {names}')
    return out
