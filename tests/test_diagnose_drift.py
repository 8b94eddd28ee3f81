"""The loop tells a drift in time (aging) from a long thermal lag of the proxy.

A slow drift A (1 - exp(-t/tau)) over a chamber cycle is fitted as well by a lag of the proxy of
thousands of seconds, which the structure phase offers first: aging runs of the loop benchmark were
"model structure improved" (a 2000-3800 s lag) and never named.  The aging candidates (the ramp and
decays beyond a turn-on) are now scored beside the structure and win there only when they leave at
most 1/DRIFT_MARGIN of the residual variance of the best structural candidate; else the effect phase
has them as before.  Both sides on foreign devices of the loop benchmark (seed 0): an aging run that
the lag used to take, and the mode-reversal control that, without the margin, was called "aging".
"""
from __future__ import annotations

import warnings

from host_tools.fitting import effects
from host_tools.fitting.diagnose import COMPETE_FAMILIES, diagnose
from host_tools.fitting.diagnose_scan import DRIFT_MARGIN
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.simulation.sim_foreign import simulate_foreign


def _runs(device, reversal, effect=None, strength=1.0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return (simulate_foreign(device, 4.0, reversal, 0, 0, effect=effect, strength=strength),
                simulate_foreign(device, 2.0, reversal, 1, 1, effect=effect, strength=strength))


def test_the_aging_candidates_are_a_ramp_and_decays_longer_than_any_turn_on():
    tr, _ = _runs(38, False)
    cfg = fit_default([tr], lag_block="off")[0].config
    dur = float(tr.t_s[-1] - tr.t_s[0])
    aging = effects.library([tr], cfg, families=("aging",))
    taus = [c.params["tau_s"] for c in aging if "tau_s" in c.params]
    assert sum("n_samples" in c.params for c in aging) == 1 and len(taus) >= 3
    assert min(taus) > effects.MAX_TURN_ON_FRACTION * dur and max(taus) <= effects.AGING_MAX_FRACTION * dur
    turn_on = [c.params["tau_s"] for c in effects.library([tr], cfg, families=("turn_on",))]
    assert max(turn_on) < min(taus)
    for c in aging:
        if "tau_s" in c.params:     # refinement never turns an aging decay into a turn-on
            assert all(r.params["tau_s"] > effects.MAX_TURN_ON_FRACTION * dur for r in effects.refine(c))
            assert all(r.terms[0]["gen"] == "decay_on" and r.family == "aging" for r in effects.refine(c))
    assert COMPETE_FAMILIES == ("aging",) and DRIFT_MARGIN > 1.0


def test_a_drift_in_time_is_named_aging_not_taken_as_a_long_lag():
    """Loop bench seed 0 run 38 (FTR, aging at 6.2x): before, board_temp lags of 1358-1481 s took it
    ("model structure improved").  From hdrg fit's model (held out 1.30 deg/h) the lags of the
    proxy and the sensor are tried first and reverted; the drift is kept as aging (1.30 -> 1.13),
    and u^5 then halves the rest."""
    tr, ho = _runs(38, False, "aging", 6.210906812571978)
    rep, _ = diagnose([tr], [ho], plots=False)
    kept = [it for it in rep["iterations"] if it["confirmed"]]
    assert kept[0]["effect"] == "aging" and kept[0]["kind"] == "effect"
    assert not any(it["confirmed"] and it["effect"] in ("thermal_lag", "board_temp") for it in rep["iterations"])
    assert rep["final"]["std100_dph"] < 0.55 * rep["baseline"]["holdout"]["std100_dph"]


def test_the_mode_reversal_control_is_not_called_aging():
    """Loop bench seed 0 run 33 (clean, mode reversal): its own slow thermal dynamics are fitted by a
    decay of 15360 s a little better (CV gain 0.106 against 0.087) than by any structural candidate;
    without the margin the loop said "effect found" (aging), held-out 0.102 -> 0.060 deg/h.  With it
    nothing is named; from today's start (0.064 deg/h) no step is confirmed."""
    tr, ho = _runs(33, True)
    rep, _ = diagnose([tr], [ho], plots=False)
    assert rep["verdict"] != "effect found"
    assert not any(it["effect"] == "aging" and it["confirmed"] for it in rep["iterations"])
    assert rep["iterations"][0]["kind"] == "structure"
    # the start (rate estimator from power-on) is already where the structure step used to bring it
    # (0.060 deg/h): a structure step is confirmed only if it still lowers the held-out error
    assert rep["final"]["std100_dph"] <= rep["baseline"]["holdout"]["std100_dph"] < 0.07


def test_without_the_margin_the_control_is_called_aging(monkeypatch):
    """The same control at margin 1 (the drift wins whenever it explains more) gets aging as its
    first step: the margin, not chance, keeps it out."""
    import host_tools.fitting.diagnose_scan as scan
    monkeypatch.setattr(scan, "DRIFT_MARGIN", 1.0)
    tr, ho = _runs(33, True)
    rep, _ = diagnose([tr], [ho], plots=False, max_iter=1)
    assert rep["iterations"][0]["effect"] == "aging"
