"""The time weight makes E + w_T T proportional to the cycle's cost."""
import numpy as np
import pytest

from irb_planning.costs import cycle_cost, time_weight


def test_time_weight_ranks_plans_like_their_cost():
    p, c = 0.25, 40.0                           # currency/kWh, currency/h
    w = time_weight(p, c)
    assert w == pytest.approx(160000.0)         # 40/3600 per s over 0.25/3.6e6 per J
    rng = np.random.default_rng(1)
    E, T = rng.uniform(50, 5000, 200), rng.uniform(1, 20, 200)
    cost = cycle_cost(E, T, p, c)
    np.testing.assert_allclose(cost, (E + w * T) * p / 3.6e6, rtol=1e-12)
    with pytest.raises(ValueError):
        time_weight(0.0, 1.0)
