import warnings

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


class PlatformStall(Exception):
    """A correct, latched safe stop caused by the machine (the watchdog or the axis computer's
    comm timeout saw a gap in the data) before the behaviour a process test is about."""


class StallRetries:
    """Runs a real-time process scenario again (fresh processes, limits unchanged) when it
    raised PlatformStall; at most ``attempts`` times. Any other failure fails at once. The
    stop itself was the right reaction; what the test is about was then not reached. CI VMs
    deschedule processes for up to 330 ms (fresh-clone CI run, 2026-11-24: "joint_states
    refused: 332.5 ms old"), which no real-time limit survives; each retry is reported as a
    warning with the stop reason, so the rate stays visible in the suite's summary."""

    WORDS = ('watchdog', 'stall', 'comm timeout', 'no command')
    Stall = PlatformStall

    @classmethod
    def is_stall(cls, reason: str) -> bool:
        return any(w in reason for w in cls.WORDS)

    def __call__(self, scenario, attempts: int = 3):
        stalls = []
        for _ in range(attempts):
            try:
                return scenario()
            except PlatformStall as e:
                stalls.append(str(e))
                warnings.warn(f'platform stall, scenario run again: {e}')
        raise AssertionError(f'all {attempts} attempts ended in a platform stall before the '
                             f'subject: {stalls}')


@pytest.fixture
def stall_retries() -> StallRetries:
    return StallRetries()
