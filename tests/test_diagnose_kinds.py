"""The closed loop's structural candidates: the exchange settling of per-mode
banks and the higher powers of the proxy are kind 'structure' (host_tools.fitting.effects,
host_tools.fitting.diagnose_scan.kind_of)."""
import warnings

import numpy as np

from host_tools.fitting import effects
from host_tools.fitting.diagnose_scan import _cand_columns, kind_of, phase_of


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
    assert kind_of("proxy_high_order", {"power": 4}) == "structure"
    # reported as structure, scanned with the effects (the search order kept tofupilot x's accelerometer step)
    assert phase_of("proxy_high_order", {"power": 4}) == "effect"
    assert phase_of("exchange_settling", {"tau_s": 4.0}) == "structure" and phase_of("aging", {}) == "effect"
    for rev in ({"order": "regress_first", "combiner": "pair", "settle_s": 0.0},
                {"order": "combine_first", "combiner": "pair", "settle_s": 5.0}):
        cfg = fit_config_from_logs([log], reversal=rev)
        assert not [c for c in effects.library([log], cfg) if c.family == "exchange_settling"]


def test_the_settling_column_is_shared_by_both_mode_banks():
    """In the scan a banked candidate has one column per mode bank; exchange_settling has ONE column
    for both (a transient that follows the mode sign, the same in the target s * rate)."""
    from dataclasses import replace

    from host_tools.golden.compensate import fit_config_from_logs, prepare
    from host_tools.golden.regressors import AuxConfig
    log = _mr_log()
    cfg = fit_config_from_logs([log], reversal={"order": "regress_first", "combiner": "pair", "settle_s": 5.0})
    pr = prepare(log, replace(cfg, aux=AuxConfig()))
    lib = effects.library([log], cfg)
    settle = next(c for c in lib if c.family == "exchange_settling")
    trans = next(c for c in lib if c.family == "exchange_transient" and not c.params["sign"])
    shared, banked = _cand_columns(settle, log, pr, cfg.rate.fs), _cand_columns(trans, log, pr, cfg.rate.fs)
    assert shared.shape == (len(log), 1) and banked.shape == (len(log), 2)
    assert np.any(shared[pr.mode == 1] != 0) and np.any(shared[pr.mode == 2] != 0)
