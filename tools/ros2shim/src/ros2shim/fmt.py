"""Pure helpers of the graph and bag verbs: output formats of ros2cli, rates, argv mapping.

No rclpy here (the verbs in ``graph.py`` import it lazily); PyYAML is imported inside the
functions that need it. Output shapes follow ros2cli (ros2topic, ros2service, ros2bag) so that
a script written against the shim works unchanged against a full ROS 2 install.
"""

from __future__ import annotations

import math
import os
import sys
import time

#: ros2cli's default for ``ros2 topic echo --truncate-length``
DEFAULT_TRUNCATE_LENGTH = 128


def is_hidden(name: str) -> bool:
    """A topic or service name with a token starting with '_' (ros2cli hides those)."""
    return any(token.startswith('_') for token in name.split('/'))


def format_names_and_types(names_and_types, show_types: bool,
                           include_hidden: bool = False) -> list[str]:
    """``ros2 topic list`` / ``ros2 service list`` lines: sorted names, ``-t`` adds
    ``[type, ...]``."""
    lines = []
    for name, types in sorted(names_and_types):
        if not include_hidden and is_hidden(name):
            continue
        lines.append(f"{name} [{', '.join(types)}]" if show_types else name)
    return lines


def expand_name(name: str, namespace: str = '/') -> str:
    """A relative topic/service name made absolute in ``namespace`` (ros2cli resolves
    relative names against the command's own node, which lives in '/')."""
    if name.startswith('/'):
        return name
    if name.startswith('~'):
        raise ValueError(f"'{name}': a private name cannot be resolved from the command line")
    return namespace.rstrip('/') + '/' + name


def split_type(type_name: str) -> tuple[str, str, str]:
    """'pkg/msg/Name' or 'pkg/Name' -> (pkg, kind, Name); ValueError when malformed."""
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], '', parts[1]]
    if len(parts) != 3 or not parts[0] or not parts[2]:
        raise ValueError(f"The passed type '{type_name}' is invalid")
    return parts[0], parts[1], parts[2]


# --- messages as YAML (rosidl_runtime_py.message_to_yaml) -----------------------------------
def _is_message(value) -> bool:
    return hasattr(value, 'get_fields_and_field_types')


def message_to_dict(msg, truncate_length: int | None = DEFAULT_TRUNCATE_LENGTH,
                    no_arr: bool = False, no_str: bool = False) -> dict:
    """The fields of a ROS message in declaration order, as plain Python values (what
    rosidl_runtime_py.message_to_ordereddict gives; arrays become lists, nested messages
    dicts, long arrays and strings are cut after ``truncate_length`` with '...')."""
    out = {}
    for name, ftype in msg.get_fields_and_field_types().items():
        out[name] = _convert(getattr(msg, name), ftype, truncate_length, no_arr, no_str)
    return out


def _convert(value, ftype, truncate_length, no_arr, no_str):
    if _is_message(value):
        return message_to_dict(value, truncate_length, no_arr, no_str)
    if isinstance(value, (bytes, bytearray)):
        value = list(value)
    if isinstance(value, str):
        if no_str:
            return f'<string length: <{len(value)}>>'
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + '...'
        return value
    if hasattr(value, 'tolist') and not isinstance(value, (int, float, bool)):
        value = value.tolist()         # numpy arrays and scalars
    elif hasattr(value, 'typecode'):
        value = list(value)            # array.array
    if isinstance(value, (list, tuple)):
        if no_arr:
            return f'<array type: {ftype}, length: {len(value)}>'
        cut = truncate_length is not None and len(value) > truncate_length
        items = [_convert(v, ftype, truncate_length, no_arr, no_str)
                 for v in (value[:truncate_length] if cut else value)]
        return items + ['...'] if cut else items
    return value


def dict_to_yaml(data: dict, flow_style: bool = False) -> str:
    """YAML text as ros2cli prints it (field order kept, no line wrapping)."""
    import yaml
    return yaml.dump(data, allow_unicode=True, width=sys.maxsize, sort_keys=False,
                     default_flow_style=flow_style)


def message_to_yaml(msg, truncate_length: int | None = DEFAULT_TRUNCATE_LENGTH,
                    no_arr: bool = False, no_str: bool = False,
                    flow_style: bool = False) -> str:
    """rosidl_runtime_py.message_to_yaml: the message as YAML text (ends with a newline)."""
    return dict_to_yaml(message_to_dict(msg, truncate_length, no_arr, no_str), flow_style)


def select_field(data, field: str | None):
    """``--field a.b.c`` of ros2 topic echo: the value at that dotted path; ValueError when
    the message has no such field."""
    if not field:
        return data
    for part in field.split('.'):
        if not isinstance(data, dict) or part not in data:
            raise ValueError(f"Invalid field value '{field}'")
        data = data[part]
    return data


def fill_message(msg, values: dict, where: str = ''):
    """Set the fields of ``msg`` from a mapping (``ros2 service call ... "{data: true}"``);
    nested messages from nested mappings. ValueError naming an unknown field."""
    if not isinstance(values, dict):
        raise ValueError(f'values must be a YAML mapping, not {values!r}')
    fields = msg.get_fields_and_field_types()
    for name, value in values.items():
        if name not in fields:
            raise ValueError(f"Failed to populate field: '{where}{name}' is not a field of "
                             f"{type(msg).__name__} (fields: {', '.join(fields) or 'none'})")
        current = getattr(msg, name)
        if _is_message(current):
            fill_message(current, value, f'{where}{name}.')
        else:
            try:
                setattr(msg, name, _coerce(current, value))
            except (AssertionError, TypeError, ValueError) as exc:
                raise ValueError(f"Failed to populate field '{where}{name}': {exc}") from None
    return msg


def _coerce(current, value):
    """``value`` checked against the type of the field's current value (rclpy does not
    check every assignment): bool for bool, int for int, a number for float, text for
    str, a list for sequences."""
    def bad(kind):
        return TypeError(f'{value!r} is not {kind}')
    if isinstance(current, bool):
        if not isinstance(value, bool):
            raise bad('a bool (true/false)')
    elif isinstance(current, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad('an integer')
    elif isinstance(current, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad('a number')
        value = float(value)
    elif isinstance(current, str):
        if not isinstance(value, str):
            raise bad('a string')
    elif not isinstance(value, list):
        raise bad('a list')
    return value


def format_request(obj) -> str:
    """``std_srvs.srv.Trigger_Request()`` as ros2 service call prints it (the message's
    repr)."""
    return repr(obj)


# --- rates (ros2 topic hz) -----------------------------------------------------------------
def rate_stats(times) -> dict | None:
    """From arrival times [s] (ascending): the average rate [Hz] = 1 / mean interval, the
    min/max interval [s], the (population) standard deviation of the intervals [s] and the
    window (number of messages). None with fewer than two arrivals."""
    times = list(times)
    if len(times) < 2:
        return None
    deltas = [b - a for a, b in zip(times, times[1:])]
    mean = sum(deltas) / len(deltas)
    std = math.sqrt(sum((d - mean) ** 2 for d in deltas) / len(deltas))
    return {'rate': 1.0 / mean if mean > 0 else math.inf, 'min': min(deltas),
            'max': max(deltas), 'std_dev': std, 'window': len(times)}


def format_hz(stats: dict) -> str:
    """The two lines ros2 topic hz prints per report."""
    return (f"average rate: {stats['rate']:.3f}\n\tmin: {stats['min']:.3f}s max: "
            f"{stats['max']:.3f}s std dev: {stats['std_dev']:.5f}s window: {stats['window']}")


# --- topic info -----------------------------------------------------------------------------
def format_topic_info(types, publishers, subscriptions, verbose: bool) -> str:
    """``ros2 topic info [-v]``: type, counts and, with -v, one block per endpoint
    (``publishers``/``subscriptions``: lists of endpoint texts, rclpy's TopicEndpointInfo
    str())."""
    if not verbose:
        return (f"Type: {', '.join(types)}\nPublisher count: {len(publishers)}\n"
                f'Subscription count: {len(subscriptions)}')
    parts = [f"Type: {', '.join(types)}", '', f'Publisher count: {len(publishers)}', '']
    for text in publishers:
        parts += [str(text), '']
    parts += [f'Subscription count: {len(subscriptions)}', '']
    for text in subscriptions:
        parts += [str(text), '']
    return '\n'.join(parts).rstrip('\n') + '\n'


# --- bags ------------------------------------------------------------------------------------
def human_size(n: int) -> str:
    """Bytes as ros2 bag info writes them (B, KiB, MiB, GiB)."""
    size = float(n)
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if size < 1024 or unit == 'GiB':
            return f'{size:.0f} {unit}' if unit == 'B' else f'{size:.1f} {unit}'
        size /= 1024
    return f'{size:.1f} GiB'


def _stamp(ns: int) -> str:
    sec, nsec = divmod(int(ns), 1_000_000_000)
    text = time.strftime('%b %e %Y %H:%M:%S', time.localtime(sec))
    return f'{text}.{nsec:09d} ({sec}.{nsec:09d})'


def format_bag_info(info: dict) -> str:
    """``ros2 bag info`` text from a summary: files (names), size_bytes, storage_id,
    ros_distro, duration_ns, start_ns, end_ns, message_count, topics [(name, type, count,
    serialization_format)]."""
    pad = 19
    lines = ['']
    files = info['files'] or ['']
    lines.append('Files:'.ljust(pad) + files[0])
    lines += [' ' * pad + f for f in files[1:]]
    lines.append('Bag size:'.ljust(pad) + human_size(info['size_bytes']))
    lines.append('Storage id:'.ljust(pad) + info['storage_id'])
    lines.append('ROS Distro:'.ljust(pad) + (info.get('ros_distro') or 'unknown'))
    dur = info['duration_ns']
    lines.append('Duration:'.ljust(pad) + f'{dur // 1_000_000_000}.{dur % 1_000_000_000:09d}s')
    if info['message_count']:
        lines.append('Start:'.ljust(pad) + _stamp(info['start_ns']))
        lines.append('End:'.ljust(pad) + _stamp(info['end_ns']))
    lines.append('Messages:'.ljust(pad) + str(info['message_count']))
    topics = [f'Topic: {name} | Type: {ty} | Count: {count} | Serialization Format: {fmt}'
              for name, ty, count, fmt in info['topics']]
    lines.append('Topic information: ' + (topics[0] if topics else ''))
    lines += [' ' * pad + t for t in topics[1:]]
    lines.append('Service:'.ljust(pad) + '0')
    lines.append('Service information: ')
    return '\n'.join(lines)


def param_list(values) -> str:
    """A string list as a --ros-args parameter value (YAML flow sequence)."""
    return '[' + ', '.join("'" + v.replace("'", "''") + "'" for v in values) + ']'


def default_bag_name(now: float | None = None) -> str:
    """ros2 bag record's default output name: rosbag2_YYYY_MM_DD-HH_MM_SS."""
    return time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S', time.localtime(now))


def record_ros_args(topics, output: str | None, cwd: str, now: float | None = None) -> list:
    """``--ros-args`` of the project's recorder for ``ros2 bag record -o output topics``:
    the bag goes where ros2 bag would put it (``output`` relative to the working directory,
    or rosbag2_<date> in it)."""
    path = os.path.abspath(os.path.join(cwd, output or default_bag_name(now)))
    return ['--ros-args', '-p', f'root:={os.path.dirname(path)}',
            '-p', f'name:={os.path.basename(path)}',
            '-p', f'topics:={param_list([expand_name(t) for t in topics])}']


def play_ros_args(bag: str, cwd: str, rate: float = 1.0, clock: float | None = None,
                  topics=(), delay: float | None = None) -> list:
    """``--ros-args`` of the project's replay for ``ros2 bag play`` (``clock``: the /clock
    rate [Hz], None = no /clock)."""
    args = ['--ros-args', '-p', f'bag:={os.path.abspath(os.path.join(cwd, bag))}',
            '-p', f'rate:={float(rate)!r}']
    if clock is not None:
        args += ['-p', 'clock:=true', '-p', f'clock_frequency_hz:={float(clock)!r}']
    if topics:
        args += ['-p', f'topics:={param_list([expand_name(t) for t in topics])}']
    if delay is not None:
        args += ['-p', f'start_delay_s:={float(delay)!r}']
    return args
