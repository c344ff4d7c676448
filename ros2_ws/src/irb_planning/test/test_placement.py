"""Placement search on a stand-in planner with a known energy field (analytic oracle)."""
from types import SimpleNamespace

import numpy as np
import pytest

from irb_planning.placement import Region, certificate, plot_map, search
from irb_planning.request import ERROR_UNREACHABLE, PlanError, PlanRequest

TRUE_MIN = np.array([0.63, -0.07, 0.05])


class FieldPlanner:
    """E(c) = 60 + 400 |c - c*|^2 + 5 sin(rotation); x > 0.78 is unreachable."""

    def __init__(self):
        self.requests = []

    def plan(self, req):
        self.requests.append(req)
        c = np.asarray(req.center, float)
        if c[0] > 0.78:
            raise PlanError(ERROR_UNREACHABLE, 'path unreachable: outside the workspace')
        e = 60 + 400 * float(np.sum((c - TRUE_MIN) ** 2)) + 5 * np.sin(req.start_angle)
        return SimpleNamespace(verification=SimpleNamespace(energy=e, electrical={}))


def test_search_finds_the_minimum_keeps_refused_points_and_bounds_the_region(tmp_path):
    pl = FieldPlanner()
    region = Region(np.array([0.4, -0.4, -0.2]), np.array([0.8, 0.4, 0.4]),
                    (0.0, -np.pi / 2))
    lines = []
    res = search(pl, PlanRequest(duration=10.0), region, (5, 5, 4), coarse_grid=30,
                 refine=2, min_step=0.005, progress=lines.append)
    assert res.best_rotation == pytest.approx(-np.pi / 2)
    np.testing.assert_allclose(res.best_center, TRUE_MIN, atol=0.01)
    assert res.best_energy == pytest.approx(55.0, abs=400 * 3 * 0.01 ** 2 + 1e-9)
    # the x = 0.8 plane is refused: in the map as NaN with the planner's reason
    assert np.all(np.isnan(res.energy[-1])) and not np.any(np.isnan(res.energy[:-1]))
    assert len(res.reasons) == 5 * 4 * 2
    assert all('unreachable' in r for r in res.reasons.values())
    assert len(lines) >= res.energy.size                     # progress per grid point
    # the certificate's lower bound is below the true minimum over the reachable cells
    assert res.region_lower_bound <= 55.0
    assert res.cells_covered == 4 * 4 * 3 * 2 - 4 * 3 * 2 and res.cells_total == 4 * 4 * 3 * 2
    assert plot_map(str(tmp_path / 'm.png'), res) and (tmp_path / 'm.png').stat().st_size > 0


def test_certificate_on_a_linear_field_is_exact():
    axes = [np.linspace(0, 1, 3), np.linspace(0, 2, 3), np.array([0.0])]
    X, Y = np.meshgrid(axes[0], axes[1], indexing='ij')
    E = (10 + 3 * X + 2 * Y)[:, :, None, None]
    low, L, covered, total = certificate(axes, E)
    assert covered == total == 4
    np.testing.assert_allclose(L, [3.0, 2.0, 0.0])
    # on a cell, min(corner) - (L_x h_x + L_y h_y) / 2 = 10 - (1.5 + 2) / 2
    assert low == pytest.approx(10 - 1.75)
    assert low <= 10.0                                        # the true minimum


def test_a_cell_with_a_refused_corner_is_not_covered():
    axes = [np.linspace(0, 1, 3), np.array([0.0]), np.array([0.0])]
    E = np.array([5.0, np.nan, 7.0])[:, None, None, None]
    low, _, covered, total = certificate(axes, E)
    assert np.isnan(low) and covered == 0 and total == 2


def test_everything_refused_gives_no_best():
    class Refuse:
        def plan(self, req):
            raise PlanError(ERROR_UNREACHABLE, 'no')
    res = search(Refuse(), PlanRequest(duration=5.0),
                 Region(np.zeros(3), np.ones(3)), (2, 1, 1), progress=lambda s: None)
    assert res.best_center is None and len(res.reasons) == 2
