"""What a node is, in data: its parameters (name, default, unit, meaning), topics and services.

One ``NodeSpec`` per node serves three readers: the node declares its parameters from it
(``node_main.declare_params``), ``--help`` prints it without starting anything
(``exit_if_help``), and a README table can be made from it (``param_table_md``), so the three
cannot disagree. Pure Python: no rclpy, no message types (``--help`` must not need a ROS
context, and must answer fast).

    SPEC = NodeSpec('recorder', 'irb_identification', 'record topics into an MCAP bag',
                    params=(Param('name', '', '', 'bag name; empty: rec_<date>_<time>'),),
                    publishes=(Topic('/recorder/status', 'std_msgs/String', 'progress'),))

    def main(args=None):
        exit_if_help(args, SPEC)        # before rclpy.init, before any file is touched
        ...
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field

# types a parameter may declare when its default cannot say it (an empty list)
ARRAY_TYPES = ('bool[]', 'int[]', 'double[]', 'string[]')


@dataclass(frozen=True)
class Param:
    """A ROS parameter: ``default`` is the value the node declares (its type is the
    parameter's type); ``unit`` is '' for dimensionless or text values; ``type`` is needed
    only for an empty-list default (one of ``ARRAY_TYPES``)."""
    name: str
    default: object
    unit: str
    description: str
    type: str = ''

    def __post_init__(self):
        if isinstance(self.default, tuple):           # frozen dataclass: keep lists as lists
            object.__setattr__(self, 'default', list(self.default))
        if isinstance(self.default, list) and not self.default and self.type not in ARRAY_TYPES:
            raise ValueError(f'parameter {self.name}: an empty list default needs type= one '
                             f'of {ARRAY_TYPES}')

    @property
    def type_name(self) -> str:
        if self.type:
            return self.type
        d = self.default
        if isinstance(d, list):
            return _scalar_type(d[0]) + '[]'
        return _scalar_type(d)

    def described(self) -> str:
        """The text for the parameter's ROS descriptor: the unit in brackets first."""
        return f'[{self.unit}] {self.description}' if self.unit else self.description


def _scalar_type(v) -> str:
    if isinstance(v, bool):
        return 'bool'
    if isinstance(v, int):
        return 'int'
    if isinstance(v, float):
        return 'double'
    if isinstance(v, str):
        return 'string'
    raise TypeError(f'unsupported parameter value {v!r}')


@dataclass(frozen=True)
class Topic:
    """A topic or a service: name (relative names are under the node's namespace, ``~/x``
    under its name), interface type and what it carries."""
    name: str
    type: str
    description: str = ''


@dataclass(frozen=True)
class NodeSpec:
    """Everything ``--help`` says of a node executable."""
    executable: str
    package: str
    summary: str
    params: tuple = ()
    subscribes: tuple = ()
    publishes: tuple = ()
    services: tuple = ()
    clients: tuple = ()
    example: str = ''
    notes: str = ''
    _names: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        for p in self.params:
            if p.name in self._names:
                raise ValueError(f'{self.executable}: parameter {p.name} declared twice')
            self._names[p.name] = p

    def param(self, name: str) -> Param:
        return self._names[name]

    def default(self, name: str):
        return self.param(name).default


def _fmt_value(v) -> str:
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, bool):
        return 'true' if v else 'false'
    if isinstance(v, list):
        return '[' + ', '.join(_fmt_value(x) for x in v) + ']'
    return repr(v)


def format_help(spec: NodeSpec) -> str:
    """The text of ``--help``: usage, summary, parameters, topics, services, example."""
    ros_run = f'ros2 run {spec.package} {spec.executable}'
    out = [f'usage: {ros_run} [--help] [--ros-args -p NAME:=VALUE ...]',
           f'       {ros_run} --ros-args --params-file FILE.yaml', '',
           spec.summary.strip(), '']
    if spec.params:
        out.append('parameters (name, type, default, [unit] meaning):')
        width = max(len(p.name) for p in spec.params)
        for p in spec.params:
            out.append(f'  {p.name:<{width}}  {p.type_name:<8} {_fmt_value(p.default)}')
            out.append(f'  {"":<{width}}  {p.described()}')
        out.append('')
    for title, items in (('subscribes', spec.subscribes), ('publishes', spec.publishes),
                         ('services', spec.services), ('calls services', spec.clients)):
        if items:
            out.append(f'{title}:')
            for t in items:
                out.append(f'  {t.name}  ({t.type})' + (f'  {t.description}'
                                                         if t.description else ''))
            out.append('')
    if spec.notes:
        out += [spec.notes.strip(), '']
    if spec.example:
        out += ['example:', '  ' + spec.example.strip().replace('\n', '\n  '), '']
    return '\n'.join(out)


def param_table_md(spec: NodeSpec) -> str:
    """The README table of a node's parameters (name, type, default, unit, meaning)."""
    rows = ['| name | type | default | unit | meaning |', '|---|---|---|---|---|']
    for p in spec.params:
        rows.append(f'| `{p.name}` | {p.type_name} | `{_fmt_value(p.default)}` | '
                    f'{p.unit or "-"} | {p.description} |')
    return '\n'.join(rows)


def own_args(args=None) -> list[str]:
    """A command-line tool's own arguments: ``args`` (None: ``sys.argv[1:]``) up to any
    ``--ros-args`` (``ros2 run`` and launch files may append ROS arguments to any
    executable; a tool that takes none ignores them)."""
    argv = list(sys.argv[1:] if args is None else args)
    return argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv


def wants_help(args=None) -> bool:
    """True when ``-h``/``--help`` stands among the program's own arguments (before any
    ``--ros-args``); ``args`` as ``main(args)`` gets them (None: ``sys.argv``, whose first
    item is the program)."""
    argv = list(sys.argv[1:] if args is None else args)
    if argv and args is not None and argv[0] == sys.argv[0]:
        argv = argv[1:]
    argv = own_args(argv)
    return '-h' in argv or '--help' in argv


def exit_if_help(args, spec: NodeSpec | str) -> None:
    """Print the usage and exit 0 when ``--help`` was asked for; else return. Call it first
    in ``main``, before rclpy.init and before anything is created, opened or written."""
    if wants_help(args):
        text = spec if isinstance(spec, str) else format_help(spec)
        sys.stdout.write(text.rstrip('\n') + '\n')
        sys.stdout.flush()
        raise SystemExit(0)
