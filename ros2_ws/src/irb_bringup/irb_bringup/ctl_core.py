"""What ``ctl status`` says, and how ``ctl`` commands map onto services (no rclpy here).

The thin adapter ``ctl.py`` collects, over a short window, the last ControllerState,
PlanStatus and AxisStatus (as plain dicts) and the arrival times of the main topics; this module
turns them into rates and text, and decides exit codes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from irb_control.pd_plus import MODE_NAMES, MODE_STOPPED

#: topics whose rates ``ctl status`` measures (relative to pdplus's namespace)
MAIN_TOPICS = ('joint_states', 'torque_command', 'controller_state')
#: exit codes: done / refused by the node / node or service not there (or no answer)
OK, REFUSED, UNAVAILABLE = 0, 1, 2
#: command -> the pdplus service it calls; 'reset' also resets the drive (see reset_services)
PDPLUS_SERVICES = {'enable': 'enable', 'stop': 'stop', 'hold': 'hold', 'reset': 'reset'}
#: nodes whose ~/reset clears a latched drive error, in the order they are looked for
DRIVES = ('simulator', 'axis_bridge')


@dataclass(frozen=True)
class TopicRate:
    """Arrivals of one topic over the window: count, rate [Hz], largest gap [s]."""
    topic: str
    count: int
    rate_hz: float
    max_gap_s: float


def topic_rate(topic: str, times) -> TopicRate:
    """Rate from arrival times [s] (ascending): (n - 1) / (last - first), so a subscription
    matched late in the window still gives the true rate; NaN with fewer than two."""
    times = list(times)
    if len(times) < 2 or times[-1] <= times[0]:
        return TopicRate(topic, len(times), math.nan, math.nan)
    gaps = [b - a for a, b in zip(times, times[1:])]
    return TopicRate(topic, len(times), (len(times) - 1) / (times[-1] - times[0]), max(gaps))


def join_name(namespace: str, name: str) -> str:
    """``name`` in ``namespace`` ('/' + name in the root namespace)."""
    return namespace.rstrip('/') + '/' + name


def split_node(node: str) -> tuple[str, str]:
    """'/ns/pdplus' -> ('/ns', 'pdplus'); 'pdplus' -> ('/', 'pdplus')."""
    node = '/' + node.strip('/')
    ns, _, name = node.rpartition('/')
    return ns or '/', name


@dataclass
class Snapshot:
    """What ``ctl status`` collected (plain values, filled by the adapter)."""
    pdplus: str                        # the node's full name, e.g. '/pdplus'
    pdplus_seen: bool                  # the node is on the graph
    services: list[str] = field(default_factory=list)   # pdplus's Trigger services (short)
    controller: dict | None = None     # last ControllerState: mode, stop_reason, ...
    plan: dict | None = None           # last PlanStatus
    axis: dict | None = None           # last AxisStatus
    drive_resets: list[str] = field(default_factory=list)   # ~/reset services of drives
    rates: list[TopicRate] = field(default_factory=list)
    window_s: float = 1.0


def mode_name(mode: int) -> str:
    return MODE_NAMES.get(int(mode), f'unknown ({mode})')


def _fmt_rate(r: TopicRate, width: int) -> str:
    if r.count == 0:
        return f'  {r.topic:<{width}}  no messages'
    if math.isnan(r.rate_hz):
        return f'  {r.topic:<{width}}  {r.count} message'
    return (f'  {r.topic:<{width}}  {r.rate_hz:7.1f} Hz  ({r.count} msgs, largest gap '
            f'{r.max_gap_s * 1e3:.1f} ms)')


def format_status(s: Snapshot) -> str:
    """The text of ``ctl status``: pdplus's mode and latched stop, the last plan verdict, the
    drive's state and latched error, the rates of the main topics; with a hint at the
    command that gets out of a latched state."""
    lines = []
    c = s.controller
    if c is None:
        seen = 'on the graph' if s.pdplus_seen else 'not found on the graph'
        lines.append(f'pdplus {s.pdplus}: {seen}, no controller_state in '
                     f'{s.window_s:g} s (mode unknown)')
    else:
        lines.append(f"pdplus {s.pdplus}: mode {mode_name(c['mode'])}  (missed deadlines "
                     f"{c['missed_deadlines']}, rejected inputs {c['rejected_inputs']})")
        if int(c['mode']) == MODE_STOPPED:
            lines.append(f"  latched stop: {c['stop_reason'] or '(no reason given)'}")
            lines.append('  -> `ros2 run irb_bringup ctl enable` ramps back to the start'
                         + (' (after `ctl reset`: the drive reports an error)'
                            if s.axis and s.axis['error'] else ''))
    if s.services:
        lines.append(f"  services: {', '.join(sorted(s.services))}")
    p = s.plan
    if p is None:
        lines.append('plan: no verdict on plan_status' + (
            ' (no plan received since pdplus started)' if s.pdplus_seen else ''))
    else:
        verdict = (f"accepted ({p['points']} points, {p['duration']:.3f} s)" if p['accepted']
                   else f"refused: {p['reason'] or '(no reason given)'}")
        lines.append(f"plan: last {verdict}; accepted {p['accepted_count']}, refused "
                     f"{p['refused_count']} since pdplus started")
    a = s.axis
    if a is None:
        lines.append('drive: no axis_status (no simulator or axis_bridge reporting)')
    else:
        state = ('motors on' if a['motors_on'] else 'motors off') + ', ' + (
            'brakes engaged' if a['brakes_engaged'] else 'brakes released')
        error = (f"latched error {a['error']:#x}: {a['error_text'] or '(no text)'}"
                 if a['error'] else 'no error')
        lines.append(f"drive ({a['source'] or 'unknown'}): {state}, {error}")
        if a['error']:
            lines.append('  -> `ros2 run irb_bringup ctl reset` clears it'
                         + (f" ({', '.join(s.drive_resets)})" if s.drive_resets else ''))
    lines.append(f'rates over {s.window_s:g} s (wall clock):')
    width = max((len(r.topic) for r in s.rates), default=0)
    lines += [_fmt_rate(r, width) for r in s.rates]
    return '\n'.join(lines)


def status_code(s: Snapshot) -> int:
    """0 when pdplus answered (it is on the graph or its controller_state arrived), else 2."""
    return OK if (s.pdplus_seen or s.controller is not None) else UNAVAILABLE


def trigger_outcome(command: str, service: str, success: bool, message: str
                    ) -> tuple[int, str]:
    """Exit code and the line printed for a std_srvs/Trigger answer."""
    word = 'done' if success else 'refused'
    return (OK if success else REFUSED), f'{command} ({service}): {word}: {message}'


def reset_services(pdplus_services: list[str], pdplus: str, drive_resets: list[str]
                   ) -> list[str]:
    """What ``ctl reset`` calls: pdplus's own ~/reset when it offers one, then every drive's
    ~/reset (the simulator's or the axis bridge's: clears their latched error). pdplus's
    latched stop is left by ``enable`` (a reset never moves anything)."""
    own = [join_name(pdplus, 'reset')] if 'reset' in pdplus_services else []
    return own + list(drive_resets)


def missing_service_text(command: str, pdplus: str, offered: list[str]) -> str:
    """One line: pdplus does not offer the service ``command`` needs."""
    return (f"{command}: {pdplus} offers no ~/{PDPLUS_SERVICES[command]} service (it offers: "
            f"{', '.join(sorted(offered)) or 'none'})")


def wait_outcome(target: str, mode: int, stop_reason: str, seen_moving: bool,
                 after_motion: bool | None = None) -> int | None:
    """``ctl wait``'s verdict on one ControllerState: OK once pdplus is in mode ``target``,
    REFUSED when it is stopped (the latched stop ends the wait: it will not leave it by
    itself), None to keep waiting. ``ctl wait MODE`` ends as soon as pdplus is in MODE (also
    when it already is: 'hold' after a motion that ended earlier). ``after_motion`` asks for
    the mode only after pdplus has moved: ``ctl enable --wait`` waits for a resting mode after
    the motion it started, so it cannot end on the mode it started from."""
    if after_motion is None:
        after_motion = False
    if mode == MODE_STOPPED and target != 'stopped':
        return REFUSED
    if MODE_NAMES.get(mode) == target and (seen_moving or not after_motion):
        return OK
    return None


#: modes pdplus rests in; ``ctl enable --wait`` waits for one of them after the motion
RESTING = ('idle', 'hold')

