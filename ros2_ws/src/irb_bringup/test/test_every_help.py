"""Every executable of every package answers ``--help`` with its usage and exits 0, and does
nothing else: no node on the graph, no file, no bag.

The executables are enumerated, not listed: each package's ``setup.py`` console scripts
(read with ``ast``, so a new entry point is covered without editing this test) must all be
installed where ``ros2 run`` finds them, and each is run as a user would run it
(``ros2 run <pkg> <exe> --help``) in an empty working directory with an empty HOME. Anything it writes there, or into the workspace's ``bags/`` and ``runs/``, fails the
test; so does an executable that is still running after the bound (a node that started).
"""
from __future__ import annotations

import ast
import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[4]
SRC = ROOT / 'ros2_ws' / 'src'
BOUND_S = 30.0          # generous: imports on a loaded 2-core machine; a node never exits


def console_scripts(setup_py: Path) -> list[str]:
    """Names of the ``console_scripts`` entry points in a setup.py (static read)."""
    tree = ast.parse(setup_py.read_text())
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for k, v in zip(node.keys, node.values):
                if isinstance(k, ast.Constant) and k.value == 'console_scripts':
                    for elt in v.elts:
                        names.append(elt.value.split('=')[0].strip())
    return names


def executables() -> list[tuple[str, str]]:
    out = []
    for setup_py in sorted(SRC.glob('*/setup.py')):
        pkg = setup_py.parent.name
        out += [(pkg, exe) for exe in console_scripts(setup_py)]
    return out


EXECUTABLES = executables()


def test_every_package_has_its_executables_enumerated():
    pkgs = {p for p, _ in EXECUTABLES}
    python_pkgs = {p.parent.name for p in SRC.glob('*/setup.py')}
    assert pkgs == python_pkgs, f'packages without console scripts: {python_pkgs - pkgs}'
    assert len(EXECUTABLES) >= 20


def _snapshot(*dirs: Path) -> set[str]:
    seen = set()
    for d in dirs:
        if d.exists():
            seen |= {str(p) for p in d.rglob('*')}
    return seen


@pytest.mark.ros
@pytest.mark.parametrize('pkg,exe', EXECUTABLES, ids=[f'{p}/{e}' for p, e in EXECUTABLES])
def test_help_prints_usage_and_does_nothing_else(pkg, exe, tmp_path):
    if shutil.which('ros2') is None:
        pytest.skip('no ros2 on PATH (source scripts/env.sh)')
    work, home = tmp_path / 'cwd', tmp_path / 'home'
    for d in (work, home):
        d.mkdir()
    env = dict(os.environ, HOME=str(home), MPLBACKEND='Agg',
               ROS_LOG_DIR=str(tmp_path / 'roslog'))
    watched = (ROOT / 'bags', ROOT / 'runs')
    before = _snapshot(*watched)
    proc = subprocess.Popen(['ros2', 'run', pkg, exe, '--help'], cwd=work, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=BOUND_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)      # the executable and whatever it started
        proc.communicate()
        pytest.fail(f'{pkg} {exe} --help still running after {BOUND_S:.0f} s (it started '
                    f'instead of printing its usage)')
    text = out + err
    assert proc.returncode == 0, f'{exe} --help exit {proc.returncode}:\n{text[-2000:]}'
    assert 'usage' in out.lower(), f'{exe} --help printed no usage:\n{text[-2000:]}'
    assert 'Traceback' not in text, text[-2000:]
    written = _snapshot(work, home)
    assert not written, f'{exe} --help wrote {sorted(written)[:5]}'
    assert not (tmp_path / 'roslog').exists(), f'{exe} --help started rclpy logging'
    assert _snapshot(*watched) == before, f'{exe} --help wrote into bags/ or runs/'


@pytest.mark.ros
@pytest.mark.parametrize('pkg,exe,args,words', [
    ('irb_control', 'simulator', ['-p', 'mode:=bogus'], "mode must be one of"),
    ('irb_control', 'pdplus', ['-p', 'kp:=abc'], "parameter 'kp'"),
    ('irb_planning', 'planner', ['-p', 'grid_size:=abc'], "parameter 'grid_size'"),
    ('irb_identification', 'replay', ['-p', 'rate:=fast'], "parameter 'rate'"),
])
def test_a_bad_parameter_is_one_line_and_a_non_zero_exit(pkg, exe, args, words, tmp_path):
    """A value of the wrong type or one the node refuses: one line naming it, no traceback,
    a non-zero exit, before anything runs."""
    env = dict(os.environ, HOME=str(tmp_path), ROS_LOG_DIR=str(tmp_path / 'log'))
    res = subprocess.run(['ros2', 'run', pkg, exe, '--ros-args', *args], cwd=tmp_path,
                         env=env, capture_output=True, text=True, timeout=4 * BOUND_S)
    text = res.stdout + res.stderr
    assert res.returncode != 0, text
    assert 'Traceback' not in text, text
    line = [ln for ln in res.stderr.splitlines() if ln.strip()][-1]
    assert line.startswith(f'{exe}: ') and words in line, text
