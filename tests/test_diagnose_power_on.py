"""The closed loop on several power-on runs (host_tools.fitting.diagnose): it takes hdrg fit's per-run
offsets and power-on term as given, keeps k7 room for the term, and with no held-out runs confirms
every step by leaving one training run out."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from firmware_ref.formats import AUX_MAX_TERMS
from host_tools.bench import startup as bench
from host_tools.fitting import turn_on
from host_tools.fitting.diagnose import diagnose
from host_tools.fitting.diagnose_confirm import step_errors_leaving_runs_out
from host_tools.fitting.effects import effect_term
from host_tools.fitting.fit_pipeline import fit_default, without_run_offsets
from host_tools.golden.compensate import compensate
from host_tools.golden.regressors import mode_sign
from host_tools.simulation.sim_foreign import foreign_device

DEVICE = 0      # a foreign device whose turn-on hdrg fit learns from the start-up protocol


@pytest.fixture(scope="module")
def runs():
    return bench.calibration_runs(foreign_device(DEVICE))


@pytest.fixture(scope="module")
def fitted(runs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_default(runs)[0]


@pytest.fixture(scope="module")
def looped(runs, tmp_path_factory):
    out = tmp_path_factory.mktemp("loop")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep, model = diagnose(runs, out_dir=out, plots=False, max_iter=1, n_surrogates=9)
    return rep, model, out


def test_taking_the_term_out_of_the_rate_equals_adding_it_to_the_model(runs):
    """without_term's contract: the model on the run without size x g gives what the model with the
    term (with_decay) gives on the run as it is, on every valid sample; alone in k7 and beside
    generators whose k7 differs between the banks."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lagged, _ = fit_default(runs, turn_on="off")
        plain, _ = fit_default(runs, turn_on="off", lag_block="off")
    decay = effect_term("decay_on", "turn_on", tau_s=340.0)
    log = runs[2]
    for base, size in ((plain, -2.0), (lagged, 2.7)):
        a = compensate(turn_on.without_term(log, decay, size, base.config.rate.fs), base)
        b = compensate(log, turn_on.with_decay(base, decay, size))
        ok = (np.asarray(a["valid"]) > 0) & (np.asarray(b["valid"]) > 0)
        assert ok.mean() > 0.6
        assert np.allclose(a.rate_dph[ok], b.rate_dph[ok], atol=1e-9)
        assert np.abs(a.rate_dph[ok] - compensate(log, base).rate_dph[ok]).max() > 0.5   # the term is there


def test_the_run_offsets_of_the_fit_come_out_of_the_runs_with_the_mode_sign(runs, fitted):
    offsets = fitted.fit["run_offsets"]["offsets_dph"]
    shifted = without_run_offsets(runs, offsets)
    for log, new, off in zip(runs, shifted, offsets):
        s = mode_sign(log.mode)
        d = np.asarray(new.rate_dph) - np.asarray(log.rate_dph)
        assert np.allclose(d[s > 0], -off[0]) and np.allclose(d[s < 0], off[1])
    with pytest.raises(ValueError, match="offsets of 4 runs, not of these 3"):
        without_run_offsets(runs[:3], offsets)
    assert all(a is b for a, b in zip(without_run_offsets(runs, None), runs))


def test_leaving_one_run_out_fits_each_model_on_the_other_runs(runs, fitted):
    calls = []

    def spy(runs_given):
        calls.append([next(i for i, r in enumerate(runs) if r is g) for g in runs_given])
        return fitted
    before, after = step_errors_leaving_runs_out(runs, spy, spy)
    assert calls == [[j for j in range(len(runs)) if j != i] for i in range(len(runs)) for _ in (0, 1)]
    assert len(before["runs"]) == len(after["runs"]) == len(runs)
    assert before["std100_dph"] == pytest.approx(after["std100_dph"])          # the same model both sides


def test_the_loop_takes_the_fits_power_on_term_and_keeps_it(looped, fitted):
    rep, model, out = looped
    info = fitted.fit["turn_on"]
    assert info["chosen"] and rep["taken_from_fit"]["turn_on"] == info["chosen"]
    offsets = np.array(rep["taken_from_fit"]["run_offsets_dph"])
    assert offsets.shape == (4, 2) and np.abs(offsets).max() > 0.05          # per run and coefficient bank
    assert np.allclose(turn_on.decay_size(model, info["tau_s"]), info["amp_dph"], rtol=1e-6)
    assert len(model.config.aux.terms) <= AUX_MAX_TERMS
    assert "hdrg fit's power-on term" in (out / "diagnose.md").read_text()
    assert "each training run's offset" in model.fit["diagnose"]["taken_from_fit"]


def test_the_scan_is_not_offered_a_second_power_on_term_and_keeps_k7_room(runs, monkeypatch):
    import host_tools.fitting.diagnose as loop
    seen = []
    real = loop.scan_candidates

    def spy(*args, **kw):
        seen.append((args[10], kw.get("reserved")))
        return real(*args, **kw)
    monkeypatch.setattr(loop, "scan_candidates", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loop.diagnose(runs, plots=False, max_iter=1, n_surrogates=0, phases=("effect",), families=("turn_on", "aging"))
    assert seen and all(fam == ("aging",) and reserved == loop.AUX_RESERVED for fam, reserved in seen)


def test_the_reported_error_is_the_written_models_on_the_runs_as_given(runs, fitted):
    """The loop works on the runs with the term taken out; what it reports on a held-out run is what
    the model it writes (with the term) does on that run as recorded."""
    from host_tools.fitting.diagnose import error_stats
    hold = runs[2]      # a room power-on, as a held-out run
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep, model = diagnose([runs[0], runs[1], runs[3]], [runs[2]], plots=False, max_iter=0)
    assert rep["taken_from_fit"]["turn_on"] and any(t["gen"] == "decay_on" for t in model.config.aux.terms)
    got = error_stats([hold], model)
    for key in ("std_dph", "std100_dph", "rms_dph"):
        assert rep["final"][key] == pytest.approx(got[key], rel=1e-9), key
    # no step: the model written is hdrg fit's (better than the flight stack's own cubic held out)
    assert rep["final_is"] == "hdrg fit's model" and rep["versus_fit"] is None
    assert rep["cubic_floor"]["cubic_dph"] > rep["cubic_floor"]["model_dph"]
    np.testing.assert_array_equal(model.coef, fit_default([runs[0], runs[1], runs[3]])[0].coef)


def test_with_no_held_out_runs_every_step_is_confirmed_leaving_one_run_out(looped):
    rep, _, _ = looped
    assert "each training run in turn" in rep["confirm_rule"]
    # (the whole-model structural steps, reversal_order / reversal_settle, are scored leaving one run out already)
    steps = [it for it in rep["iterations"] if it["effect"] not in ("reversal_order", "reversal_settle")]
    assert steps, "the loop tried no step: nothing to check"
    for it in steps:
        assert it["confirmed"] in (True, False)
        assert "leaving one training run out" in it["status"]
