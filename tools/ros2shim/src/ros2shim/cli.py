"""A minimal ``ros2`` command: ``run``, ``pkg``, and the everyday subset of ``topic``,
``service`` and ``bag``, with ros2cli's syntax, output shapes and exit codes.

PyPI carries the ROS 2 Jazzy runtime but not ros2cli, so this module reimplements the verbs
the project needs.  Package lookup follows ament_index_python (the first entry of
AMENT_PREFIX_PATH that registers a package wins); executable discovery follows ros2pkg's
``get_executable_paths``; error messages and exit codes follow ros2cli. The graph verbs
(``graph.py``) import rclpy lazily; ``bag play|record`` run the project's replay/recorder.
"""

import argparse
import os
import re
import shlex
import signal
import subprocess
import sys

SUPPORTED = ('run, pkg executables|list|prefix, topic list|echo|hz|info, service list|call, '
             'bag info|play|record')
RUN_USAGE = 'usage: ros2 run [-h] [--prefix PREFIX] package_name executable_name ...'
USAGE = """usage: ros2 <verb> ...

Minimal ros2 shim (ros2cli is not on PyPI). Supported commands:
  ros2 run [--prefix PREFIX] <package> <executable> [argv ...]
  ros2 pkg executables [--full-path] [package]
  ros2 pkg list
  ros2 pkg prefix [--share] <package>
  ros2 topic list [-t] | echo <topic> [type] [--once] | hz <topic> | info <topic> [-v]
  ros2 service list [-t] | call <service> <type> [values]
  ros2 bag info <bag> | play <bag> [-r RATE] [--clock [HZ]] | record [-a] [-o NAME] [topics]
'ros2 <verb> --help' gives each verb's options.
Anything else needs a full ROS 2 Jazzy install (apt install ros-jazzy-ros2cli)."""
# Valid package names as checked by ament_index_python.get_package_prefix (REP 127).
_PACKAGE_NAME = re.compile(r'[a-zA-Z0-9][a-zA-Z0-9_-]+', re.ASCII)


def _error(message, code=1):
    """Print ``message`` to stderr and return ``code`` (ros2cli does sys.exit(message))."""
    print(message, file=sys.stderr)
    return code


def _unavailable(command, what='not available in this environment'):
    """Report a command this shim does not implement, in one line; return exit code 1."""
    return _error(f'{command}: {what} (PyPI has no ros2cli); it '
                  'needs a full ROS 2 Jazzy install (apt install ros-jazzy-ros2cli) \u2014 '
                  f'this shim supports: {SUPPORTED}')


def _search_paths():
    """Return the existing, non-empty AMENT_PREFIX_PATH entries in order."""
    value = os.environ.get('AMENT_PREFIX_PATH', '')
    return [path for path in value.split(os.pathsep) if path and os.path.exists(path)]


def _index_dir(prefix):
    """Return the ament resource index directory of package markers under ``prefix``."""
    return os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages')


def get_package_prefix(package_name):
    """Return the first prefix registering ``package_name``, or None if there is none."""
    if _PACKAGE_NAME.fullmatch(package_name) is None:
        return None  # ament_index_python raises ValueError; ros2pkg treats it as not found
    for prefix in _search_paths():
        if os.path.isfile(os.path.join(_index_dir(prefix), package_name)):
            return prefix
    return None


def get_packages():
    """Map every package name in the index to its prefix (the first prefix wins)."""
    packages = {}
    for prefix in _search_paths():
        index = _index_dir(prefix)
        if not os.path.isdir(index):
            continue
        for name in os.listdir(index):
            if not name.startswith('.') and not os.path.isdir(os.path.join(index, name)):
                packages.setdefault(name, prefix)
    return packages


def get_executable_paths(package_name):
    """List the executables under <prefix>/lib/<package>, or None if the package is unknown.

    Same rule as ros2pkg: walk the directory (skipping folders starting with '.'), in sorted
    order, and keep every non-directory entry that os.access reports as executable.
    """
    prefix = get_package_prefix(package_name)
    if prefix is None:
        return None
    paths = []
    for dirpath, dirnames, filenames in os.walk(os.path.join(prefix, 'lib', package_name)):
        dirnames[:] = sorted(name for name in dirnames if not name.startswith('.'))
        for filename in sorted(filenames):
            path = os.path.join(dirpath, filename)
            if os.access(path, os.X_OK):
                paths.append(path)
    return paths


def run_executable(cmd):
    """Run ``cmd`` as a child process and wait for it, as ros2run does.

    SIGINT is *not* forwarded: a terminal's Ctrl-C reaches the whole foreground process group,
    the child included, and ros2run only keeps waiting for the child to finish (forwarding it
    made the node get a second SIGINT during its clean-up). SIGTERM, which a terminal does not
    send to the group, is forwarded. Return the child's return code, which is -N if it was
    killed by signal N (ros2run returns it unchanged, so the shell sees 256 - N).
    """
    child, pending, previous = [], [], {}

    def forward(signum, _frame):
        if child:
            child[0].send_signal(signum)
        else:
            pending.append(signum)

    def keep_waiting(_signum, _frame):
        pass              # the child got the same Ctrl-C from the terminal

    handlers = {signal.SIGINT: keep_waiting, signal.SIGTERM: forward}
    for signum, handler in handlers.items():
        try:
            if signal.getsignal(signum) is not signal.SIG_IGN:
                previous[signum] = signal.signal(signum, handler)
        except ValueError:  # not in the main thread: leave signal handling alone
            break
    try:
        try:
            child.append(subprocess.Popen(cmd))
        except OSError as exc:
            return _error(f'ros2 run: cannot execute {cmd[0]!r}: {exc}')
        for signum in pending:
            child[0].send_signal(signum)
        return child[0].wait()
    finally:
        for signum, handler in previous.items():
            if handler is not None:  # None: the old handler was not set from Python
                signal.signal(signum, handler)


def _run(args):
    """Implement ``ros2 run [--prefix PREFIX] <package> <executable> [argv...]``."""
    args, prefix = list(args), None
    while args and args[0].startswith('-'):  # options may only precede the package name
        option = args.pop(0)
        if option in ('-h', '--help'):
            print(f'{RUN_USAGE}\n\nRun a package specific executable; everything after the '
                  'executable name is passed to it verbatim.')
            return 0
        if option.startswith('--prefix='):
            prefix = option.partition('=')[2]
        elif option == '--prefix' and args:
            prefix = args.pop(0)
        elif option == '--prefix':
            return _error(f'{RUN_USAGE}\nros2 run: error: argument --prefix: expected one '
                          'argument', 2)
        else:
            return _error(f'{RUN_USAGE}\nros2 run: error: unrecognized arguments: {option}', 2)
    if len(args) < 2:
        missing = ', '.join(['package_name', 'executable_name'][len(args):])
        return _error(f'{RUN_USAGE}\nros2 run: error: the following arguments are required: '
                      f'{missing}', 2)
    package_name, executable_name, argv = args[0], args[1], args[2:]
    paths = get_executable_paths(package_name)
    if paths is None:
        return _error(f"Package '{package_name}' not found")
    matches = [path for path in paths if os.path.basename(path) == executable_name]
    if len(matches) > 1:
        return _error('Multiple executables found:' + ''.join(f'\n- {p}' for p in matches))
    if not matches:
        return _error('No executable found')
    command = shlex.split(prefix) if prefix is not None else []
    return run_executable(command + [matches[0]] + argv)


def _pkg(args):
    """Implement ``ros2 pkg executables|list|prefix``."""
    if not args or args[0] not in ('executables', 'list', 'prefix'):
        return _unavailable(' '.join(['ros2 pkg'] + args[:1]))
    parser = argparse.ArgumentParser(prog=f'ros2 pkg {args[0]}')
    if args[0] == 'executables':
        parser.add_argument('package_name', nargs='?', help='The package name')
        parser.add_argument('--full-path', action='store_true',
                            help='Show full path of each executable')
    elif args[0] == 'prefix':
        parser.add_argument('package_name', help='The package name')
        parser.add_argument('--share', action='store_true',
                            help='Show share directory for the package')
    options = parser.parse_args(args[1:])
    if args[0] == 'list':
        for name in sorted(get_packages()):
            print(name)
        return 0
    if args[0] == 'prefix':
        prefix = get_package_prefix(options.package_name)
        if prefix is None:
            return _error('Package not found')
        print(os.path.join(prefix, 'share', options.package_name) if options.share else prefix)
        return 0
    names = [options.package_name] if options.package_name else sorted(get_packages())
    for name in names:
        paths = get_executable_paths(name)
        if paths is None:
            if options.package_name is None:
                continue  # registered under an invalid name: ros2pkg cannot look it up either
            return _error('Package not found')
        for path in sorted(paths):
            print(path if options.full_path else f'{name} {os.path.basename(path)}')
    return 0

# --- topic, service, bag ----------------------------------------------------------------------
#: list verbs wait this long for discovery [s]: longer than Fast DDS's 3 s participant
#: announcement period, so a node whose first announcements were missed (a loaded host: a
#: 2 s wait listed only the command's own topics) is announced again within the wait
LIST_SPIN_S = 3.5
SPIN_TIME_HELP = ('wait for discovery [s] (ros2cli: --spin-time); list waits all of it, the '
                  'others stop once the name is there and the graph has not changed for 1 s')


def _verb_parser(verb, subverbs, description):
    """``ros2 <verb>`` with one sub-parser per supported sub-verb."""
    parser = argparse.ArgumentParser(prog=f'ros2 {verb}', description=description)
    sub = parser.add_subparsers(dest='subverb', metavar='Commands', required=True)
    return parser, {name: sub.add_parser(name, prog=f'ros2 {verb} {name}', help=text,
                                         description=text)
                    for name, text in subverbs.items()}


def _spin_time(parser, default):
    parser.add_argument('--spin-time', type=float, default=default, help=SPIN_TIME_HELP +
                        f' (default: {default:g})')


def _non_negative_int(text):
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError('value must be non-negative integer')
    return value


def _positive_float(text):
    value = float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError('value must be positive')
    return value


TOPIC_VERBS = {'list': 'Output a list of available topics',
               'echo': 'Output messages from a topic',
               'hz': 'Print the average publishing rate to screen',
               'info': 'Print information about a topic'}
SERVICE_VERBS = {'list': 'Output a list of available services',
                 'call': 'Call a service'}
BAG_VERBS = {'info': 'Print information about a bag to the screen',
             'play': "Play back ROS data from a bag (the project's replay)",
             'record': "Record ROS data to a bag (the project's recorder)"}


def _topic(args):
    """Implement ``ros2 topic list|echo|hz|info``."""
    if args and not args[0].startswith('-') and args[0] not in TOPIC_VERBS:
        return _unavailable(f'ros2 topic {args[0]}')
    parser, p = _verb_parser('topic', TOPIC_VERBS, 'Various topic related sub-commands')
    p['list'].add_argument('-t', '--show-types', action='store_true',
                           help='Additionally show the topic type')
    p['list'].add_argument('-c', '--count-topics', action='store_true',
                           help='Only display the number of topics discovered')
    p['list'].add_argument('--include-hidden-topics', action='store_true',
                           help='Consider hidden topics as well')
    _spin_time(p['list'], LIST_SPIN_S)
    e = p['echo']
    e.add_argument('topic_name', help="Name of the ROS topic to listen to (e.g. '/chatter')")
    e.add_argument('message_type', nargs='?',
                   help="Type of the ROS message (e.g. 'std_msgs/msg/String')")
    e.add_argument('--once', action='store_true',
                   help='Print the first message received and then exit.')
    e.add_argument('--timeout', type=_positive_float, default=None,
                   help='With --once: give up after this many seconds without a message '
                        '(exit 1)')
    e.add_argument('--field', help='Echo a selected field of a message, e.g. header.stamp')
    e.add_argument('--full-length', '-f', action='store_true',
                   help='Output all elements for arrays, bytes, and string')
    e.add_argument('--truncate-length', '-l', type=_non_negative_int, default=128,
                   help='The length to truncate arrays, bytes, and string to (default: 128)')
    e.add_argument('--no-arr', action='store_true', help="Don't print array fields of messages")
    e.add_argument('--no-str', action='store_true',
                   help="Don't print string fields of messages")
    e.add_argument('--flow-style', action='store_true',
                   help='Print collections in the flow style')
    _spin_time(e, 5.0)
    h = p['hz']
    h.add_argument('topic_name', help="Name of the ROS topic to listen to (e.g. '/chatter')")
    h.add_argument('message_type', nargs='?', help=argparse.SUPPRESS)
    h.add_argument('--window', '-w', type=_non_negative_int, default=10000,
                   help='window size, in # of messages, for calculating rate (default: 10000)')
    h.add_argument('--wall-time', action='store_true',
                   help='calculates rate using wall time (always the case here)')
    _spin_time(h, 5.0)
    i = p['info']
    i.add_argument('topic_name', help="Name of the ROS topic to get info (e.g. '/chatter')")
    i.add_argument('--verbose', '-v', action='store_true',
                   help='Prints detailed information like the node name, node namespace, '
                        'topic type, GUID and QoS Profile of the publishers and subscribers '
                        'to this topic')
    _spin_time(i, 5.0)
    options = parser.parse_args(args)
    if options.subverb == 'hz' and options.window < 2:
        parser.error('--window must be at least 2')
    from . import graph
    return getattr(graph, f'topic_{options.subverb}')(options)


def _service(args):
    """Implement ``ros2 service list|call``."""
    if args and not args[0].startswith('-') and args[0] not in SERVICE_VERBS:
        return _unavailable(f'ros2 service {args[0]}')
    parser, p = _verb_parser('service', SERVICE_VERBS, 'Various service related sub-commands')
    p['list'].add_argument('-t', '--show-types', action='store_true',
                           help='Additionally show the service type')
    p['list'].add_argument('-c', '--count-services', action='store_true',
                           help='Only display the number of services discovered')
    p['list'].add_argument('--include-hidden-services', action='store_true',
                           help='Consider hidden services as well')
    _spin_time(p['list'], LIST_SPIN_S)
    c = p['call']
    c.add_argument('service_name',
                   help="Name of the ROS service to call to (e.g. '/pdplus/enable')")
    c.add_argument('service_type',
                   help="Type of the ROS service (e.g. 'std_srvs/srv/Trigger')")
    c.add_argument('values', nargs='?', default='{}',
                   help="Values to fill the service request with in YAML format (e.g. "
                        "'{data: true}'), otherwise the service request will be published "
                        'with default values')
    c.add_argument('--timeout', type=_positive_float, default=None,
                   help='give up (exit 1) when the service is not there or has not answered '
                        'after this many seconds (default: wait, as ros2cli)')
    options = parser.parse_args(args)
    from . import graph
    return getattr(graph, f'service_{options.subverb}')(options)


def _bag(args):
    """Implement ``ros2 bag info|play|record``."""
    if args and not args[0].startswith('-') and args[0] not in BAG_VERBS:
        return _unavailable(f'ros2 bag {args[0]}')
    parser, p = _verb_parser('bag', BAG_VERBS, 'Various rosbag related sub-commands')
    p['info'].add_argument('bag_path', help='Bag to open')
    p['info'].add_argument('-s', '--storage', default='', help='Storage implementation of bag. '
                           'Only mcap is read here.')
    pl = p['play']
    pl.add_argument('bag_path', help='Bag to open')
    pl.add_argument('-r', '--rate', type=float, default=1.0,
                    help='rate at which to play back messages; 0 = as fast as possible '
                         '(default: 1.0)')
    pl.add_argument('--topics', nargs='+', default=[], help='topics to replay (default: all)')
    pl.add_argument('--clock', type=_positive_float, nargs='?', const=40.0, default=0.0,
                    help='Publish to /clock at a specific frequency in Hz (default: 40 when '
                         'given without a value)')
    pl.add_argument('-d', '--delay', type=float, default=None,
                    help='Sleep duration before play (each loop), in seconds')
    pl.add_argument('-l', '--loop', action='store_true', help='not supported here (exit 1)')
    r = p['record']
    r.add_argument('topics', nargs='*', help='List of topics to record.')
    r.add_argument('--topics', dest='topics_opt', nargs='+', default=[], metavar='TOPIC',
                   help='List of topics to record.')
    r.add_argument('-a', '--all', action='store_true',
                   help='Record all topics on the graph now (a topic that appears later is '
                        'not recorded)')
    r.add_argument('-o', '--output', help='Destination of the bagfile to create, defaults to '
                   'a timestamped folder in the current directory')
    r.add_argument('-s', '--storage', default='mcap',
                   help="Storage identifier: only 'mcap' (default)")
    _spin_time(r, LIST_SPIN_S)
    options = parser.parse_args(args)
    from . import bag
    if options.subverb == 'info':
        if options.storage not in ('', 'mcap'):
            return _error(f"ros2 bag info: storage '{options.storage}' is not supported here "
                          '(mcap only)')
        try:
            return bag.info(options)
        except bag.BagInfoError as exc:
            return _error(str(exc))
    if options.subverb == 'play':
        if options.loop:
            return _error('ros2 bag play: --loop is not supported by the project\'s replay')
        return _run(bag.play_command(options, bag.cwd()))
    if options.storage != 'mcap':
        return _error(f"ros2 bag record: storage '{options.storage}' is not supported here "
                      '(the recorder writes mcap)')
    if options.all and (options.topics or options.topics_opt):
        return _error('ros2 bag record: give either -a or topics, not both', 2)
    if not options.all and not (options.topics or options.topics_opt):
        return _error('ros2 bag record: no topics given (name them, or -a for all)', 2)
    found = bag.discover_topics(options.spin_time) if options.all else None
    if options.all and not found:
        return _error('ros2 bag record -a: no topics on the graph')
    return _run(bag.record_command(options, bag.cwd(), found))


def main(argv=None):
    """Run the ``ros2`` command line with ``argv`` (default: sys.argv[1:]); return exit code."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] in ('-h', '--help'):
        print(USAGE)
        return 0
    try:
        if args and args[0] == 'run':
            return _run(args[1:])
        if args and args[0] == 'pkg':
            return _pkg(args[1:])
        verbs = {'topic': _topic, 'service': _service, 'bag': _bag}
        if args and args[0] in verbs:
            return verbs[args[0]](args[1:])
    except SystemExit as exc:  # argparse usage errors (2) and --help (0)
        return exc.code
    except Exception as exc:  # noqa: BLE001 - one line, never a traceback
        from .graph import CliError
        if isinstance(exc, (CliError, ValueError)):
            return _error(str(exc))
        return _error(f'ros2 {args[0]}: {type(exc).__name__}: {exc}')
    if not args:
        return _unavailable('ros2', 'no verb given, and the full ros2 CLI is not available here')
    return _unavailable(f'ros2 {args[0]}')


if __name__ == '__main__':
    sys.exit(main())
