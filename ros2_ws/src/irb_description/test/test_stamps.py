"""sec_nanosec: float seconds -> (sec, nanosec) without the one-second jump below integers."""
import pytest
from irb_description.stamps import NS_PER_S, sec_nanosec


@pytest.mark.parametrize('t, expected', [
    (0.0, (0, 0)),
    (12.5, (12, 500_000_000)),
    (2.99999999999998, (3, 0)),            # accumulated 100 x 0.01 s camera steps, etc.
    (125.99999999993877, (126, 0)),        # accumulated 31250 x 0.004032 s periods
    (1.9999999994, (1, 999_999_999)),
    (0.004032, (0, 4_032_000)),
    (-0.25, (-1, 750_000_000)),
])
def test_sec_nanosec(t, expected):
    assert sec_nanosec(t) == expected


def test_accumulated_periods_never_step_back():
    """Stamps of t += T (the simulator's clock) increase and stay within 1 ns of t."""
    t, prev = 0.0, -1
    for _ in range(50_000):
        t += 0.004032
        sec, ns = sec_nanosec(t)
        assert 0 <= ns < NS_PER_S
        total = sec * NS_PER_S + ns
        assert total > prev
        assert abs(total * 1e-9 - t) <= 1e-9 + 1e-12 * t
        prev = total
