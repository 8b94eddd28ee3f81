"""The closed loop's noise model with its random-walk term (host_tools.fitting.diagnose_noise.with_random_walk)
and the exchange-settling structural candidate (host_tools.fitting.effects, kind 'structure')."""
import math
import warnings

import numpy as np
import pytest

from host_tools.fitting import effects
from host_tools.fitting.diagnose_noise import _noise_series, noise_model, with_random_walk
from host_tools.fitting.diagnose_scan import kind_of


def _psd(white, flicker, k_rw):
    """The one-sided PSD coefficients (h0, h-1, h-2) of white sigma [deg/h], a flat Allan level
    ``flicker`` [deg/h] and a rate random walk K [deg/h/sqrt(s)] (AVAR = K^2 tau / 3)."""
    return (2.0 * white ** 2, flicker ** 2 / (2.0 * math.log(2.0)), k_rw ** 2 / (2.0 * math.pi ** 2))


def _poly_projection(t, order=3):
    """The projection on a polynomial in time (a base fit that absorbs part of a slow noise)."""
    X = np.column_stack([(t / t[-1]) ** k for k in range(order + 1)])
    Q = np.linalg.qr(X)[0]
    return lambda W: Q @ (Q.T @ W)


@pytest.mark.parametrize("k_rw", [0.002, 0.006])
def test_random_walk_is_recovered_through_the_base_projection(k_rw):
    rng = np.random.default_rng(11)
    n = 20000
    t = np.arange(n, dtype=float)
    noise = _noise_series({"_psd": _psd(0.3, 0.02, k_rw), "fs": 1.0}, n, 1, rng)[:, 0]
    project = _poly_projection(t)
    resid = noise - project(noise[:, None])[:, 0]
    valid = np.ones(n, bool)
    nm = noise_model(resid, t, valid, 1.0)
    assert nm["rw_dph_per_sqrt_s"] == 0.0            # the short-tau model has no random walk
    got = with_random_walk(nm, resid, t, valid, 1.0, project=project, rng=np.random.default_rng(3))
    assert k_rw / 2.0 <= got["rw_dph_per_sqrt_s"] <= 2.0 * k_rw
    assert got["_psd"][:2] == nm["_psd"][:2] and got["_psd"][2] > 0


def test_no_random_walk_is_invented_on_white_and_flicker_noise():
    rng = np.random.default_rng(12)
    n = 20000
    t = np.arange(n, dtype=float)
    noise = _noise_series({"_psd": _psd(0.3, 0.02, 0.0), "fs": 1.0}, n, 1, rng)[:, 0]
    nm = noise_model(noise, t, np.ones(n, bool), 1.0)
    got = with_random_walk(nm, noise, t, np.ones(n, bool), 1.0, rng=np.random.default_rng(4))
    # far below the smallest random walk of the foreign family (0.02 deg/h/sqrt(h) = 3.3e-4 deg/h/sqrt(s))
    assert got["rw_dph_per_sqrt_s"] < 3.3e-4


def test_a_short_record_keeps_the_model_without_random_walk():
    t = np.arange(300, dtype=float)
    r = np.random.default_rng(1).standard_normal(300)
    nm = noise_model(r, t, np.ones(300, bool), 1.0)
    assert with_random_walk(nm, r, t, np.ones(300, bool), 1.0) is nm       # no tau in 64 s .. 0.2 x 300 s
    assert with_random_walk(None, r, t, np.ones(300, bool), 1.0) is None


def _mr_log(seconds=3000):
    from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate_foreign(foreign_device(7), 4.0, True, 0, 0, duration_s=seconds)


def test_exchange_settling_is_offered_only_for_per_mode_banks_with_a_settle_window():
    from host_tools.golden.compensate import fit_config_from_logs
    log = _mr_log()
    rf = fit_config_from_logs([log], reversal={"order": "regress_first", "combiner": "pair", "settle_s": 5.0})
    cands = [c for c in effects.library([log], rf) if c.family == "exchange_settling"]
    assert cands and all(c.extra["shared"] and c.params["tau_s"] <= 10.0 for c in cands)
    assert all(c.extra["max_tau_s"] == effects.SETTLING_TAU_FACTOR * 5.0 for c in cands)
    assert kind_of("exchange_settling", cands[0].params) == "structure"
    assert kind_of("exchange_transient", {"tau_s": 4.0}) == "effect"
    for rev in ({"order": "regress_first", "combiner": "pair", "settle_s": 0.0},
                {"order": "combine_first", "combiner": "pair", "settle_s": 5.0}):
        cfg = fit_config_from_logs([log], reversal=rev)
        assert not [c for c in effects.library([log], cfg) if c.family == "exchange_settling"]
