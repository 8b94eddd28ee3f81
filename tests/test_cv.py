"""host_tools.fitting.cv: the one fold definition and held-out SSE algebra of fit.py and diagnose."""
import numpy as np
import pytest

from host_tools.fitting import cv
from host_tools.fitting.diagnose_scan import cv_groups
from host_tools.fitting.fit import block_groups


def test_folds_are_contiguous_blocks_dealt_round_robin():
    f = cv.fold_ids(1000, 16, 4)
    blocks = cv.block_ids(1000, 16)
    assert np.all(np.diff(blocks) >= 0) and set(blocks) == set(range(16))
    assert np.array_equal(f, blocks % 4)
    assert np.array_equal(cv.fold_ids(1000, 8), block_groups(1000, 8))      # fit.py: every block a fold
    groups = cv_groups([np.ones(1000, bool)], 16, 4)                          # diagnose: the same folds
    for k, (_, idx) in enumerate(groups):
        assert np.array_equal(idx, np.flatnonzero(f == k))
    with pytest.raises(ValueError):
        cv.fold_ids(100, 3, 4)


def test_heldout_sse_is_the_sum_of_squared_held_out_errors():
    rng = np.random.default_rng(1)
    X, Y = rng.normal(size=(50, 3)), rng.normal(size=(50, 2))
    b = rng.normal(size=(3, 2))
    direct = ((Y - X @ b) ** 2).sum(axis=0)
    S, B, A = (Y ** 2).sum(axis=0), X.T @ Y, X.T @ X
    assert np.allclose(cv.heldout_sse(b, S, B, A), direct)
    assert cv.heldout_sse(b[:, 0], S[0], B[:, 0], A) == pytest.approx(direct[0])
