"""The power-on transient of the default fit (host_tools.fitting.turn_on), its chip path, and the
start-up benchmark (host_tools.bench.startup)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from firmware_ref.formats import AUX_MAX_TERMS
from host_tools.bench import startup as bench
from host_tools.bench.accuracy import servable
from host_tools.fitting import turn_on
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.golden.compensate import compensate
from host_tools.simulation.sim_foreign import chamber_profile, foreign_device, simulate_foreign

DEVICE = 0      # a foreign device with a turn-on that the protocol lets the fit learn (f0 13.2 kHz: quantizable)


@pytest.fixture(scope="module")
def device():
    return foreign_device(DEVICE)


@pytest.fixture(scope="module")
def runs(device):
    return bench.calibration_runs(device)


@pytest.fixture(scope="module")
def fitted(runs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_default(runs)


def _startup(device, p=2, effect="turn_on"):
    return simulate_foreign(device, 1.0, True, p, p, effect=effect, ambient_c=bench.ambient_of(device, p))


def test_turn_on_learned_and_it_lowers_the_startup_error(device, fitted):
    model, _ = fitted
    info = model.fit["turn_on"]
    assert info["chosen"] and info["chosen"].startswith("decay_on"), info
    assert any(t["gen"] == "decay_on" for t in model.config.aux.terms) and 7 in model.terms
    for row in (r for r in info["candidates"] if "error" not in r):   # the rule as documented, from the recorded scores
        w = np.array(row["run_weight"])
        start, whole = np.array(row["start_ratio"], float), np.array(row["run_ratio"], float)
        tests = (w @ start / w.sum() - (1 - turn_on.MARGIN), start.max() - turn_on.START_TOLERANCE,
                 w @ whole / w.sum() - turn_on.RUN_TOLERANCE, turn_on.MIN_SIZE_T - row["size_t"])
        if all(np.isfinite(x) and abs(x) > 2e-3 for x in tests):      # the recorded scores are rounded
            assert row["kept"] == all(x <= 0 for x in tests), row
    assert any(not row["kept"] for row in info["candidates"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        off, _ = fit_default(bench.calibration_runs(device), turn_on="off")
    assert "turn_on" not in off.fit and 7 not in off.terms or all(t["gen"] != "decay_on" for t in off.config.aux.terms)
    log = _startup(device)
    serve = servable(log)
    stab = {}
    for name, m in (("with", model), ("without", off)):
        out = compensate(log, m)
        stab[name] = bench.startup_figures(log.t_s, out.rate_dph, (np.asarray(out["valid"]) > 0) & serve)["stability"]
    assert stab["with"] < 0.6 * stab["without"], stab


def test_turn_on_model_runs_in_fixed_point_within_the_bound(device, fitted):
    from host_tools import api

    model, _ = fitted
    q = api.quantize(model)
    log = _startup(device)
    gold = compensate(log, model)
    fixed = api.compensate(log, model, impl="fixed", table=q.table)
    vg, vf = np.asarray(gold["valid"]) > 0, np.asarray(fixed["valid"]) > 0
    assert np.array_equal(vg, vf) and vg.mean() > 0.7
    assert float(np.max(np.abs(gold.rate_dph[vg] - fixed.rate_dph[vg]))) <= 0.002   # deg/h


def test_not_learned_from_one_run_from_legs_or_from_one_temperature(device, runs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one, _ = fit_default(runs[:1])
        assert "power-ons" in one.fit["turn_on"]["why"] and one.fit["turn_on"]["chosen"] is None
        legs = [runs[0].select(np.arange(3000, 6000)), runs[1].select(np.arange(3000, 6000))]
        cut, _ = fit_default(legs)
        assert "does not start at its power-on" in cut.fit["turn_on"]["why"]
        warm = [runs[0], simulate_foreign(device, 2.0, True, 1, 1, effect="turn_on")]   # both soaked at the warm end
        same, _ = fit_default(warm)
        assert "span" in same.fit["turn_on"]["why"] and same.fit["turn_on"]["start_spread"] < turn_on.MIN_START_SPREAD


def test_turn_on_option_checked(runs):
    with pytest.raises(ValueError, match="turn_on must be 'auto' or 'off'"):
        fit_default(runs[:1], turn_on="yes")


def test_starts_at_power_on_and_start_spread(device, runs):
    assert all(turn_on.starts_at_power_on(r) for r in runs)
    assert not turn_on.starts_at_power_on(runs[0].select(np.arange(10, 100)))
    from host_tools.golden.compensate import fit_config_from_logs
    proxy = fit_config_from_logs(runs).proxy
    assert turn_on.start_spread(runs, proxy) > turn_on.MIN_START_SPREAD
    assert turn_on.start_spread([runs[0], runs[0]], proxy) == 0.0


def test_foreign_startup_and_cold_start(device):
    log = _startup(device)
    assert len(log) == int(bench.STARTUP_S) + 1 and "constant" in log.metadata["profile"]
    prof = chamber_profile(device, 2.0, start_low=True)
    assert prof[0, 1] == device.chamber["low_c"] and prof[-1, 1] == device.chamber["low_c"]
    for bad in (float("nan"), 500.0, "20"):
        with pytest.raises(ValueError, match="ambient_c"):
            simulate_foreign(device, 1.0, True, 2, 2, ambient_c=bad)


def test_startup_figures_follow_the_paper_table4_definitions():
    t = np.arange(2701.0)
    y = 1.0 + np.where(t < 1000, 2.0, 0.0)          # 2 deg/h above the settled bias for 1000 s
    f = bench.startup_figures(t, y, np.ones(len(t), bool))
    assert f["turn_on"] == pytest.approx(2.0) and f["variation"] == pytest.approx(2.0)
    assert f["mean"] == pytest.approx(2.0 * (1000 - 180) / (2701 - 180), rel=1e-6)
    none = bench.startup_figures(t, y, t < 2000)     # no valid sample in 40..45 min: no baseline
    assert np.isnan(none["stability"])


def test_startup_bench_small_run_and_cli_refusal(capsys):
    from host_tools.cli import main
    res = bench.run_benchmark(1, seed=0, startups=2)
    s = res["summary"]
    assert s["devices"] == 1 and s["failed"] == 0
    for name in bench.PIPELINES:
        assert s[name]["min_valid_share"] >= 0.99 and np.isfinite(s[name]["stability_dph"])
    assert "mode reversal alone" in bench.format_table(res)
    assert main(["bench", "startup", "--devices", "0"]) == 2
    assert "--devices must be an integer >= 1" in capsys.readouterr().err


def test_compensate_warns_when_the_power_on_term_meets_a_late_start_or_a_gap(device, fitted):
    from host_tools.golden.flags import problems
    model, _ = fitted
    log = _startup(device)
    assert not any("power-on term" in m for m in problems(compensate(log, model)))
    late = problems(compensate(log.select(np.arange(1000, len(log))), model))
    assert any("starts at t_s = 1000 s, not at its power-on" in m for m in late)
    gap = problems(compensate(log.select(np.r_[0:1500, 1504:len(log)]), model))
    assert any("1 gap(s) restart it (first at row 1500)" in m for m in gap)
    with pytest.raises(ValueError, match="power-on term"):
        from host_tools.golden.flags import report
        report(compensate(log.select(np.arange(1000, len(log))), model), strict=True)


def test_unscorable_start_window_fails_the_candidate():
    t = np.arange(3000.0)
    y = np.exp(-t / 240.0)
    ok = np.ones(len(t), bool)
    blind = ok & (t > 2000)                          # nothing valid in the start window
    assert np.isfinite(turn_on._binned_sq(y, t, ok, 720.0, shape=True))
    assert np.isnan(turn_on._binned_sq(y, t, blind, 720.0, shape=True))
    assert np.isinf(turn_on._ratio(float("nan"), 1.0)) and np.isinf(turn_on._wmean([0.1, float("inf")], [1.0, 1.0]))


def test_a_fold_never_sees_its_held_out_run_and_a_failed_fold_fails(runs):
    """_cv_ratios: fold i's fit with the term is made on the other runs only (the refit is called
    without run i); a fold whose base could not be fitted (None) fails the candidate."""
    from host_tools.fitting.effects import effect_term
    from host_tools.fitting.fit_pipeline import _fixed_terms_fit
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        off, _ = fit_default(runs, turn_on="off")
        seen = []

        def refit(lg, cfg, terms):
            seen.append({log.source for log in lg})
            return _fixed_terms_fit(lg, cfg, terms, "auto")
        folds = [None]
        for i in range(1, len(runs)):
            others = [r for j, r in enumerate(runs) if j != i]
            fold = refit(others, off.config, off.terms)[0]
            folds.append((fold, [compensate(r, fold) for r in others], compensate(runs[i], fold)))
        seen.clear()
        scores, models = turn_on._cv_ratios(runs, folds, effect_term("decay_on", "turn_on", tau_s=340.0), refit,
                                            (1020.0,))
    assert scores[0] == turn_on.FAILED and models[0] is None
    assert len(seen) == len(runs) - 1
    for i, sources in zip(range(1, len(runs)), seen):
        assert runs[i].source not in sources and len(sources) == len(runs) - 1
        assert all(np.isfinite(scores[i])) and models[i] is not None
    check = turn_on.start_up_check(runs, models)
    assert [r["source"] for r in check["runs"]] == [r.source for r in runs[1:]]      # no model: not judged


def test_the_start_is_scored_by_its_shape_not_its_level():
    """A held-out chamber run's soaked start sits at a level that only that run teaches the
    polynomial: an offset over the start window is not the turn-on's error, its decay is."""
    t = np.arange(3000.0)
    ok = np.ones(len(t), bool)
    level = np.where(t < 1200, 1.5, 0.0)
    decay = np.exp(-t / 240.0)
    assert turn_on._binned_sq(level, t, ok, 720.0, shape=True) < 1e-20
    assert turn_on._binned_sq(level + decay, t, ok, 720.0, shape=True) > 0.1
    assert turn_on._binned_sq(level, t, ok, 720.0) > 1.0


def _both_valid(log, a, b):
    ra, rb = compensate(log, a), compensate(log, b)
    ok = (np.asarray(ra["valid"]) > 0) & (np.asarray(rb["valid"]) > 0)
    return ra.rate_dph, rb.rate_dph, ok


def test_the_output_is_linear_in_the_size_of_the_term(device, runs):
    """with_decay's contract: out(size) = out(0) + size x response, and the decay adds ``size`` deg/h
    at power-on to every coefficient bank alike: alone in k7, and beside generators whose k7
    differs between the banks (then with its sign twin, the weights renormalized)."""
    from host_tools.fitting.effects import effect_term
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lagged, _ = fit_default(runs, turn_on="off")
        plain, _ = fit_default(runs, turn_on="off", lag_block="off")
    assert lagged.config.aux.terms and not (7 in plain.terms and plain.config.aux.terms)
    k7 = np.array(lagged.banks)[:, 7]
    assert len(k7) == 2 and not np.isclose(k7[0], k7[1]) and turn_on.decay_terms_needed(lagged) == 2
    log = _startup(device)
    decay = effect_term("decay_on", "turn_on", tau_s=240.0)
    for base, size in ((plain, -2.5), (lagged, 3.0)):
        resp = turn_on.responses([log], base, decay)[0]
        new = turn_on.with_decay(base, decay, size)
        y0, y1, ok = _both_valid(log, base, new)
        assert ok.mean() > 0.6 and np.abs(resp[ok]).max() > 0.05     # MR: exchanges are not valid
        assert np.allclose(y1[ok], y0[ok] + size * resp[ok], atol=1e-9)
        assert np.allclose(turn_on.decay_size(new, 240.0), size, rtol=1e-9)
        assert sum(abs(t["weight"]) for t in new.config.aux.terms) <= 1.0 + 1e-12
    full = turn_on.with_decay(lagged, decay, 1.0)
    while len(full.config.aux.terms) + 2 <= AUX_MAX_TERMS:
        full = turn_on.with_decay(full, effect_term("decay_on", "turn_on", tau_s=60.0 * len(full.config.aux.terms)), 0.1)
    with pytest.raises(ValueError, match="chip's limit"):
        turn_on.with_decay(full, effect_term("decay_on", "turn_on", tau_s=999.0), 1.0)


def test_the_shipped_term_is_the_scored_one_and_the_result_says_so(runs, fitted):
    """The model is the scored fit with the term: the base's terms refitted on the runs with the
    turn-on at the chosen size taken out, plus the term at that size; the FitResult carries those
    coefficients and finite standard errors."""
    from host_tools.fitting.effects import effect_term
    from host_tools.fitting.fit_pipeline import _fixed_terms_fit
    model, res = fitted
    info = model.fit["turn_on"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        off, _ = fit_default(runs, turn_on="off")
        decay = effect_term("decay_on", "turn_on", tau_s=info["tau_s"])
        taken = [turn_on.without_term(r, decay, info["scale"], off.config.rate.fs) for r in runs]
        refitted, _ = _fixed_terms_fit(taken, off.config, off.terms, "auto")
    again = turn_on.with_decay(refitted, decay, info["scale"])
    assert np.allclose(again.coef, model.coef, rtol=1e-12, atol=1e-15) and again.config.aux.terms == model.config.aux.terms
    assert not np.allclose(np.array(off.coef)[:7], np.array(model.coef)[:7])     # the refit moved the polynomial
    assert np.array_equal(res.coef, model.coef) and tuple(res.terms) == tuple(model.terms)
    assert np.all(np.isfinite(res.stderr)) and res.stderr[7] > 0       # the fit's refusals pass (hdrg fit)
    assert info["size_stderr_dph"] > 0
    assert len(info["amp_dph"]) == len(model.banks) and "deg/h at power-on" in info["chosen"]
    true = foreign_device(DEVICE).effects["turn_on"]["amp_dph"]       # the device's, deg/h at power-on
    assert all(0.5 < a / true < 2.0 for a in info["amp_dph"]), (info["amp_dph"], true)


def test_a_run_the_model_fits_worse_weighs_less():
    """Weights from the misfit WITH the term (at each run's own size): a start-up the term explains
    weighs most even though its turn-on is large; a run with a misfit the term cannot explain
    weighs less; a run with nothing left weighs 0."""
    t = np.arange(3000.0)
    ok = np.ones(len(t), bool)
    rng = np.random.default_rng(1)
    g = np.exp(-t / 240.0)
    calm, rough = rng.normal(0, 0.1, len(t)), 5.0 * np.sin(t / 300.0)
    turned_on = calm - 3.0 * (g - g.mean())
    w = turn_on._run_weights([(t, turned_on, ok), (t, rough, ok), (t, np.zeros(len(t)), ok)], [g, g, g])
    assert w[0] > 100 * w[1] > 0 and w[2] == 0.0
    plain = 1.0 / np.mean(turn_on._bin_means(t, turned_on) ** 2)       # without the term it would weigh little
    assert w[0] > 100 * plain
    outputs = [(t, turned_on, ok), (t, rough, ok)]
    size = turn_on._size_of(outputs, [g, g], turn_on._run_weights(outputs, [g, g]))
    assert abs(size - 3.0) < 0.1


def _hdrg_fit(runs, folder) -> None:
    """`hdrg fit` on ``runs`` written as folder/run<i>.npz, the model to folder/model.json."""
    from host_tools.cli import main
    from host_tools.golden.runlog import write
    names = []
    for i, run in enumerate(runs):
        names.append(str(folder / f"run{i}.npz"))
        write(run, names[-1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["fit", *names, "-o", str(folder / "model.json")]) == 0


def test_hdrg_fit_writes_a_turn_on_model_and_says_its_size(runs, tmp_path, capsys):
    """The CLI end to end: the model with the term passes the fit's refusals (k7's standard error
    is a number), and the printout gives the term's size at power-on with its standard error."""
    from host_tools.golden.model import BiasModel
    _hdrg_fit(runs, tmp_path)
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("power-on transient"))
    assert "deg/h at power-on +- " in line and "nan" not in out.lower()
    model = BiasModel.from_json(tmp_path / "model.json")
    assert any(t["gen"] == "decay_on" for t in model.config.aux.terms)
    assert model.fit["turn_on"]["size_stderr_dph"] > 0


def test_a_model_worse_than_reversal_alone_at_start_up_is_named(runs, fitted, tmp_path, capsys):
    """The held-out start-up check: a device without a turn-on whose chamber-learned rate terms meet
    the self-heating's gradients (control device 9: about 20x worse than mode reversal alone over
    the room power-ons' first 45 min) is named by `hdrg fit`; device 0's model is not."""
    check = fitted[0].fit["turn_on"]["start_up_check"]
    assert len(check["runs"]) == len(runs) and check["worse"] == []
    assert all(r["ratio"] < 0.5 for r in check["runs"][:2])          # the chamber runs: far better than reversal alone
    _hdrg_fit(bench.calibration_runs(foreign_device(9), effect=None), tmp_path)
    err = capsys.readouterr().err
    named = [line for line in err.splitlines() if "worse than mode reversal alone" in line]
    assert len(named) == 1 and named[0].startswith("hdrg fit: warning: start-up not calibrated: held out"), err
    assert "run2.npz" in named[0] and "run3.npz" in named[0] and "run1.npz" not in named[0], err   # the room power-ons
