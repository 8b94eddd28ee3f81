"""Shared test fixtures: paths to the measured data copied into the project (with its MIT license)."""
import os

# one BLAS thread per process (set before numpy loads OpenBLAS): the small solves of the fitter
# and the diagnosis thrash with multithreaded OpenBLAS on a loaded 2-core machine
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402

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
