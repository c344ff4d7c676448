import numpy as np
import pytest
from irb_description.model import RobotModel

from irb_planning.planner import Planner, PlannerSettings

#: small grid so the package's tests stay fast on 2 cores
TEST_GRID = 60


@pytest.fixture(scope='session')
def model() -> RobotModel:
    return RobotModel.load()


@pytest.fixture(scope='session')
def map_dir(tmp_path_factory):
    """A directory the test planners may read friction maps from."""
    return tmp_path_factory.mktemp('maps')


@pytest.fixture(scope='session')
def planner(model, map_dir) -> Planner:
    # limit_cost off: the suite's many plans skip the extra solve of the cost of the
    # smoothness limits (test_smoothness.py tests it on its own planner)
    return Planner(model.copy(), PlannerSettings(grid_size=TEST_GRID, limit_cost=False,
                                                 friction_map_dirs=(str(map_dir),)))


@pytest.fixture(scope='session')
def unlimited(model, map_dir) -> Planner:
    """The test planner with the smoothness limits off (issue 28): the problem the trapezoid
    baseline and the convex bound belong to (neither knows jerk or torque rate)."""
    return Planner(model.copy(), PlannerSettings(grid_size=TEST_GRID, jerk_limits=False,
                                                 friction_map_dirs=(str(map_dir),)))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(2024)
