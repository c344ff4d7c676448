import numpy as np
import pytest

from irb_description.model import RobotModel


@pytest.fixture(scope='session')
def model() -> RobotModel:
    return RobotModel.load()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
