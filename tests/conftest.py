"""Shared test fixtures: paths to the measured data copied into the project (with its MIT license),
and the `hdrg compensate --strict` check of the compensation warnings."""
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


@pytest.fixture
def strict_refuses_then_warns(capsys):
    """A function (run, model, target, impl, needle): `hdrg compensate RUN --model MODEL -o TARGET
    --impl IMPL --strict` exits 2 with ``needle`` on stderr and writes nothing; the same without
    --strict exits 0, writes TARGET and warns with ``needle``."""
    from host_tools import cli

    def check(run, model, target, impl, needle):
        argv = ["compensate", str(run), "--model", str(model), "-o", str(target), "--impl", impl]
        assert cli.main(argv + ["--strict"]) == 2
        assert needle in capsys.readouterr().err and not target.exists()
        assert cli.main(argv) == 0
        assert needle in capsys.readouterr().err
    return check
