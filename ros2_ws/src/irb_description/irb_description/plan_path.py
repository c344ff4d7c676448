"""The path a plan was planned on, carried in the plan message itself.

A plan on ``/planned_trajectory`` (trajectory_msgs/JointTrajectory) is only meaningful on its
path: the theta-driven controller estimates theta by projecting the measured TCP onto that
path and takes its references from it. The standard message has no field for a path, so the
planner carries it in ``header.frame_id``: the frame the path is given in, then ``#path=`` and
the path as compact JSON (the mapping of ``irb_description.path.path_from_spec``)::

    base_link#path={"type":"line","waypoints":[[0.55,-0.1,0.3],[0.75,0.1,0.3]]}

Backwards compatible both ways: a plan without the tag (older planners, hand-made plans,
bags) is a plan on the controller's configured path, as before; a consumer that ignores the
frame id sees an ordinary trajectory. Pure Python (no ROS).
"""
from __future__ import annotations

import json

PATH_TAG = '#path='
PATH_FRAME = 'base_link'


def path_frame_id(spec: dict, frame: str = PATH_FRAME) -> str:
    """``header.frame_id`` carrying the path ``spec`` (a ``path_from_spec`` mapping)."""
    return frame + PATH_TAG + json.dumps(spec, separators=(',', ':'), sort_keys=True)


def path_spec_from_frame_id(frame_id: str) -> dict | None:
    """The path mapping carried in ``frame_id``, or None when it carries none. ValueError
    (one line) when the tag is there but unreadable or in another frame than base_link."""
    if PATH_TAG not in frame_id:
        return None
    frame, _, text = frame_id.partition(PATH_TAG)
    if frame not in ('', PATH_FRAME):
        raise ValueError(f"the plan's path is given in frame {frame!r}; only {PATH_FRAME!r} "
                         'is supported')
    try:
        spec = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"the plan's path (header.frame_id) is not readable JSON: {exc}") \
            from None
    if not isinstance(spec, dict):
        raise ValueError("the plan's path (header.frame_id) must be a mapping with a type")
    return spec
