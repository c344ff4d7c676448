"""import_log: CSV logs of other robots -> rosbag2 MCAP bags; every bad input is one line."""
import gzip

import numpy as np
import pytest

from irb_identification import import_log
from irb_identification.series import read_joint_series


def _log(rng, n=3000, t0=12.5):
    """Irregular stamps (1-13 ms), two joints with foreign names, friction torques."""
    t = t0 + np.cumsum(rng.uniform(1e-3, 13e-3, n))
    v1 = 0.4 * np.sin(1.3 * t)
    v2 = -0.9 * np.sin(0.4 * t + 1.0)
    cols = {'stamp': t, 'a_pos': np.cumsum(v1) * 1e-3, 'a_vel': v1,
            'a_tau': np.sign(v1) * 2 + v1, 'b_pos': np.cos(t), 'b_vel': v2,
            'b_tau': np.sign(v2) * 1.5, 'b_acc': np.gradient(v2, t)}
    return cols


def _write(path, cols, gz=False, sep=','):
    names = list(cols)
    lines = [sep.join(names)] + [sep.join(repr(float(x)) for x in row)
                                 for row in zip(*cols.values())]
    text = '\n'.join(lines) + '\n'
    if gz:
        with gzip.open(path, 'wt') as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


ARGS = ['--time-column', 'stamp', '--joint', 'Axis A:a_pos:a_vel:a_tau',
        '--joint', 'axis_b:b_pos:b_vel:b_tau']


@pytest.mark.parametrize('gz', [False, True])
def test_import_keeps_names_stamps_and_values(tmp_path, rng, gz, capsys, bag_check):
    cols = _log(rng)
    src = _write(tmp_path / ('log.csv.gz' if gz else 'log.csv'), cols, gz)
    out = tmp_path / 'bag'
    assert import_log.main([str(src), '--out', str(out), *ARGS,
                            '--accel-column', 'axis_b:b_acc']) == 0
    text = capsys.readouterr().out
    assert '3000 rows' in text and 'jitter' in text and 'Axis A: |v|' in text
    counts = bag_check(out, decode_limit=100)          # rosbags and mcap readers agree
    assert counts == {'/joint_states': 3000, '/joint_accelerations': 3000}
    s = read_joint_series(out)
    assert s.names == ('Axis A', 'axis_b')
    # stamps kept to the nanosecond (the log's own times, irregular)
    np.testing.assert_array_equal(np.round(s.t * 1e9).astype(np.int64),
                                  np.round(cols['stamp'] * 1e9).astype(np.int64))
    np.testing.assert_array_equal(s.velocity[:, 1], cols['b_vel'])
    np.testing.assert_array_equal(s.effort[:, 0], cols['a_tau'])
    acc = read_joint_series(out, '/joint_accelerations')
    np.testing.assert_array_equal(acc.position[:, 1], cols['b_acc'])
    assert np.all(np.isnan(acc.position[:, 0]))
    meta = (out / 'metadata.yaml').read_text()
    assert 'irb_identification.torque_kind: friction' in meta


def test_semicolon_separated_and_total_torque(tmp_path, rng):
    src = _write(tmp_path / 'log.csv', _log(rng, 500), sep=';')
    out = tmp_path / 'bag'
    assert import_log.main([str(src), '--out', str(out), *ARGS, '--torque-kind', 'total']) == 0
    assert 'torque_kind: total' in (out / 'metadata.yaml').read_text()


def _bad(tmp_path, rng, case):
    cols = _log(rng, 200)
    args = list(ARGS)
    if case == 'missing column':
        args[3] = 'Axis A:a_pos:nope:a_tau'
        return _write(tmp_path / 'l.csv', cols), args, 'no column nope'
    if case == 'non-numeric':
        path = _write(tmp_path / 'l.csv', cols)
        lines = path.read_text().split('\n')
        lines[7] = lines[7].replace(lines[7].split(',')[2], 'abc', 1)
        path.write_text('\n'.join(lines))
        return path, args, "row 8, column a_vel: not a number ('abc')"
    if case == 'nan':
        cols['b_tau'][50] = np.nan
        return _write(tmp_path / 'l.csv', cols), args, 'row 52, column b_tau: nan'
    if case == 'non-monotonic':
        cols['stamp'][100] = cols['stamp'][98]
        return _write(tmp_path / 'l.csv', cols), args, 'not strictly increasing at data row'
    if case == 'bad spec':
        return _write(tmp_path / 'l.csv', cols), ARGS[:3] + ['x:y'], 'expected <joint_name>'
    if case == 'no file':
        return tmp_path / 'none.csv', args, 'no such file'
    if case == 'not gzip':
        path = tmp_path / 'l.csv.gz'
        path.write_bytes(b'\x1f\x8b' + b'garbage' * 10)
        return path, args, 'unreadable'
    if case == 'empty':
        path = tmp_path / 'l.csv'
        path.write_text('')
        return path, args, 'empty file'
    raise AssertionError(case)


@pytest.mark.parametrize('case', ['missing column', 'non-numeric', 'nan', 'non-monotonic',
                                  'bad spec', 'no file', 'not gzip', 'empty'])
def test_bad_input_is_one_line_and_nothing_written(tmp_path, rng, capsys, case):
    src, args, message = _bad(tmp_path, rng, case)
    out = tmp_path / 'out' / 'bag'
    assert import_log.main([str(src), '--out', str(out), *args]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith('import_log: '), err
    assert message in err
    assert not out.exists()
    assert not list((tmp_path / 'out').glob('.*')) if (tmp_path / 'out').exists() else True


def test_existing_output_is_never_overwritten(tmp_path, rng, capsys):
    src = _write(tmp_path / 'l.csv', _log(rng, 100))
    out = tmp_path / 'bag'
    out.mkdir()
    (out / 'keep').write_text('x')
    assert import_log.main([str(src), '--out', str(out), *ARGS]) == 1
    assert 'exists already' in capsys.readouterr().err
    assert (out / 'keep').read_text() == 'x'
