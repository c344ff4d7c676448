"""The root README's walkthrough ("Your own path") runs literally, as a user would type it.

The commands are taken from the README's first ``bash`` block under that heading (so the
docs cannot drift from the code) and run in one bash, ``set -e``, in an empty working
directory with a private ROS domain and ``IRB_ROOT`` there (nothing lands in the checkout).
Then every step's result is checked from outside: the plan plot, the bag (read with the
``mcap`` reader, not the project's), the report, the friction map (loaded by the model's
loader) and the discrepancy verdict.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[4]
HEADING = '## Your own path'
BOUND_S = 900.0          # generous: a loaded 2-core machine; the walkthrough takes ~2-4 min


def walkthrough_commands(readme: Path = ROOT / 'README.md') -> str:
    """The first ```bash block of the README's walkthrough section, as written."""
    text = readme.read_text()
    start = text.index(HEADING)
    section = text[start:]
    nxt = re.search(r'\n## ', section[len(HEADING):])
    if nxt:
        section = section[:len(HEADING) + nxt.start()]
    m = re.search(r'```bash\n(.*?)```', section, re.S)
    assert m, f'no ```bash block under {HEADING!r}'
    return m.group(1)


def test_walkthrough_is_in_the_readme():
    block = walkthrough_commands()
    for step in ('bringup', 'plan', 'ctl enable', 'bag record', 'report', 'identify',
                 'discrepancy'):
        assert step in block, f'the walkthrough lost its {step!r} step'


@pytest.mark.ros
@pytest.mark.slow
def test_walkthrough_runs_literally(tmp_path):
    block = walkthrough_commands()
    script = tmp_path / 'walkthrough.sh'
    # the README's lines unchanged; bash -e stops at the first failing command, and the
    # trap ends whatever the block left running if it failed half-way
    script.write_text('set -xeo pipefail\n'
                      'trap \'kill $(jobs -p) 2>/dev/null || true; wait || true\' EXIT\n'
                      + block)
    env = dict(os.environ, IRB_ROOT=str(tmp_path), MPLBACKEND='Agg',
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(100 + os.getpid() % 100))
    log = tmp_path / 'walkthrough.log'
    with open(log, 'w') as out:
        proc = subprocess.Popen(['bash', str(script)], cwd=tmp_path, env=env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            code = proc.wait(timeout=BOUND_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f'walkthrough still running after {BOUND_S:.0f} s:\n'
                        + log.read_text()[-4000:])
    text = log.read_text()
    assert code == 0, f'walkthrough exit {code}:\n{text[-6000:]}'
    assert 'Traceback' not in text, text[-6000:]

    # plan: accepted by pdplus, plot written
    assert 'plan accepted' in text, text[-3000:]
    assert (tmp_path / 'my_plan.png').stat().st_size > 10_000

    # the bag: read with the mcap reader; every joint state of the run, all six joints
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    files = sorted((tmp_path / 'bags' / 'my_run').glob('*.mcap'))
    assert files, 'no MCAP file in bags/my_run'
    stamps, modes, mode_seq = [], set(), []
    for f in files:
        with open(f, 'rb') as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _, channel, _, msg in reader.iter_decoded_messages(
                    topics=['/joint_states', '/controller_state']):
                if channel.topic == '/joint_states':
                    assert list(msg.name)[:3] == ['joint_1', 'joint_2', 'joint_3']
                    assert len(msg.name) == 6
                    stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
                else:
                    modes.add(msg.mode)
                    mode_seq.append(msg.mode)
    assert len(stamps) > 500, len(stamps)           # > 2 s at 248 Hz: the run is in it
    steps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert max(steps) < 0.05, f'a hole of {max(steps):.3f} s in /joint_states'
    assert {1, 2} <= modes, f'the bag saw no ramp and path: modes {modes}'
    # nothing moved before the enable: the graph came up idle, and the recording (started
    # before the plan) opens on idle
    assert re.search(r'pdplus \S+: mode idle', text), text[-3000:]
    assert mode_seq[0] == 0, f'the recording opens in mode {mode_seq[0]}, not idle'

    # report: Markdown with the run's figures, PNGs beside it
    report = (tmp_path / 'my_report' / 'report.md').read_text()
    assert 'energy' in report.lower() and 'path error' in report.lower(), report[:2000]
    assert list((tmp_path / 'my_report').rglob('*.png'))

    # friction map: the model's own loader reads it, three joints
    from irb_description.friction import load_friction_map
    fmap = load_friction_map(tmp_path / 'my_map.yaml')
    assert set(fmap.joint_names) >= {'joint_2'}, fmap.joint_names

    # discrepancy: a verdict with a named effect (or none)
    rep = json.loads((tmp_path / 'my_discrepancy' / 'report.json').read_text())
    assert 'verdict' in json.dumps(rep) or 'effect' in json.dumps(rep)
