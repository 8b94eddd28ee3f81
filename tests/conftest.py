"""Shared test fixtures: paths to the measured data copied into the project (with its MIT license)."""
from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"
MEASURED_DIR = DATA / "psim-tvac-lsm6dsm"
MEASURED_X = MEASURED_DIR / "psim-tvac-x.csv"
MEASURED_Y = MEASURED_DIR / "psim-tvac-y.csv"


@pytest.fixture
def measured_x():
    return MEASURED_X


@pytest.fixture
def measured_y():
    return MEASURED_Y
