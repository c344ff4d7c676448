"""A minimal ``ros2`` command: ``run`` and ``pkg``, with ros2run/ros2pkg semantics.

PyPI carries the ROS 2 Jazzy runtime but not ros2cli, so this module reimplements the two
verbs the project needs.  Package lookup follows ament_index_python (the first entry of
AMENT_PREFIX_PATH that registers a package wins); executable discovery follows ros2pkg's
``get_executable_paths``; error messages and exit codes follow ros2cli.
"""

import argparse
import os
import re
import shlex
import signal
import subprocess
import sys

SUPPORTED = 'run, pkg executables|list|prefix'
RUN_USAGE = 'usage: ros2 run [-h] [--prefix PREFIX] package_name executable_name ...'
USAGE = """usage: ros2 <verb> ...

Minimal ros2 shim (ros2cli is not on PyPI). Supported commands:
  ros2 run [--prefix PREFIX] <package> <executable> [argv ...]
  ros2 pkg executables [--full-path] [package]
  ros2 pkg list
  ros2 pkg prefix [--share] <package>
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
    except SystemExit as exc:  # argparse usage errors (2) and --help (0)
        return exc.code
    if not args:
        return _unavailable('ros2', 'no verb given, and the full ros2 CLI is not available here')
    return _unavailable(f'ros2 {args[0]}')


if __name__ == '__main__':
    sys.exit(main())
