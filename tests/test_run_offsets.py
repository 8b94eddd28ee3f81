"""Per-run offsets of the default fit with several training runs (host_tools.fitting.fit_pipeline.
fit_without_run_offsets; docs/ACCURACY.md "Several training runs")."""
import warnings

import numpy as np
import pytest

from host_tools.fitting.fit_pipeline import fit_default, run_offsets
from host_tools.golden.runlog import RunLog
from host_tools.simulation import sim

TERMS = "k0,k1,k2,k3,k4"


@pytest.fixture(scope="module")
def logs():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {name: sim.simulate(f"paper-{kind}-cycle-4dpm", seed=seed)
                for name, kind, seed in (("a", "ftr", 2), ("b", "ftr", 3), ("ma", "mr", 2), ("mb", "mr", 3))}


def moved(log, d1, d2=None):
    """``log`` with its rate moved by d1 deg/h (FTR), or d1 on mode 1 and d2 on mode 2."""
    cols = dict(log.columns)
    rate = np.array(log.rate_dph, np.float64)
    if d2 is None:
        rate += d1
    else:
        mode = np.asarray(log.mode)
        rate[mode == 1] += d1
        rate[mode == 2] += d2
    cols["rate_dph"] = rate
    return RunLog.from_arrays(metadata=dict(log.metadata), source=log.source, **cols)


def test_ftr_offset_of_one_run_is_removed_and_reported(logs):
    ref, _ = fit_default([logs["a"], logs["b"]], TERMS, rate_estimator="diff")
    got, _ = fit_default([logs["a"], moved(logs["b"], 5.0)], TERMS, rate_estimator="diff")
    r, g = ref.fit["run_offsets"], got.fit["run_offsets"]
    assert r["passes"] == g["passes"] >= 1 and len(g["offsets_dph"]) == 2
    # the 5 deg/h of run b are split around the common level: b - a grows by exactly 5
    diff = lambda o: o[1][0] - o[0][0]   # noqa: E731
    assert diff(g["offsets_dph"]) - diff(r["offsets_dph"]) == pytest.approx(5.0, abs=1e-9)
    assert got.coef[0] - ref.coef[0] == pytest.approx(2.5, abs=1e-9)          # k0: the level of both runs
    np.testing.assert_allclose(got.coef[1:5], ref.coef[1:5], rtol=0, atol=1e-9)
    # what is left of each run after the fit: no offset
    assert np.allclose(run_offsets([logs["a"], moved(logs["b"], 5.0)], got), [[-2.5 + r["offsets_dph"][0][0]],
                                                                                  [2.5 + r["offsets_dph"][1][0]]])


def test_mode_reversal_offsets_per_bank_follow_the_mode_sign(logs):
    ref, _ = fit_default([logs["ma"], logs["mb"]], TERMS, rate_estimator="diff")
    got, _ = fit_default([logs["ma"], moved(logs["mb"], 3.0, 1.0)], TERMS, rate_estimator="diff")
    assert got.config.reversal.order == "regress_first"
    r, g = np.array(ref.fit["run_offsets"]["offsets_dph"]), np.array(got.fit["run_offsets"]["offsets_dph"])
    assert g.shape == (2, 2)
    # bank 1 fits c = rate (+3 on run b), bank 2 fits c = -rate (-1 on run b)
    np.testing.assert_allclose((g[1] - g[0]) - (r[1] - r[0]), [3.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(got.coef[1:5], ref.coef[1:5], atol=1e-9)
    np.testing.assert_allclose(got.coef_mode2[1:5], ref.coef_mode2[1:5], atol=1e-9)


def test_one_run_or_off_leaves_the_fit_alone(logs):
    one, _ = fit_default([logs["a"]], TERMS, rate_estimator="diff")
    assert "run_offsets" not in one.fit
    off, _ = fit_default([logs["a"], moved(logs["b"], 5.0)], TERMS, rate_estimator="diff", run_offsets="off")
    assert "run_offsets" not in off.fit
    with pytest.raises(ValueError, match="run_offsets must be 'auto' or 'off'"):
        fit_default([logs["a"]], TERMS, run_offsets="on")
