import numpy as np
import pytest
from irb_description.model import RobotModel
from irb_description.path import thesis_circle


@pytest.fixture(scope='session')
def model() -> RobotModel:
    return RobotModel.load()


@pytest.fixture(scope='session')
def circle():
    return thesis_circle()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(4242)
