"""The process tests' retry on a platform stall: only PlatformStall is retried, at most the
given number of times, and each retry is reported."""
import pytest


def test_a_stall_is_run_again_and_reported(stall_retries):
    calls = []

    def scenario():
        calls.append(1)
        if len(calls) < 3:
            raise stall_retries.Stall(f'watchdog: no valid joint_states, run {len(calls)}')
        return 'subject reached'
    with pytest.warns(UserWarning, match='platform stall') as seen:
        assert stall_retries(scenario, attempts=3) == 'subject reached'
    assert len(calls) == 3 and len(seen) == 2


def test_stalls_every_time_fail_with_the_reasons(stall_retries):
    def scenario():
        raise stall_retries.Stall('watchdog: no valid joint_states for 0.33 s')
    with pytest.warns(UserWarning), pytest.raises(AssertionError, match='0.33 s'):
        stall_retries(scenario, attempts=2)


def test_any_other_failure_is_not_retried(stall_retries):
    calls = []

    def scenario():
        calls.append(1)
        raise AssertionError('tracking error 0.2 rad')
    with pytest.raises(AssertionError, match='tracking'):
        stall_retries(scenario)
    assert calls == [1]


@pytest.mark.parametrize('reason, stall', [
    ('watchdog: no valid joint_states for 0.1037 s', True),
    ('axis_bridge: error 0x1 (comm timeout)', True),
    ('tracking error 0.21 rad > 0.2 rad', False),
    ('joint_states refused: NaN in position', False)])
def test_only_timing_reasons_count_as_stalls(stall_retries, reason, stall):
    assert stall_retries.is_stall(reason) is stall
