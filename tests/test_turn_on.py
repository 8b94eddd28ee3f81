"""The power-on transient of the default fit (host_tools.fitting.turn_on), its chip path, and the
start-up benchmark (host_tools.bench.startup)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

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
    assert all(row["kept"] == (max(row["start_ratio"]) <= 1 - turn_on.MARGIN and
                               max(row["run_ratio"]) <= turn_on.RUN_TOLERANCE and
                               row["size_t"] >= turn_on.MIN_SIZE_T) for row in info["candidates"])
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


def test_unscorable_held_out_power_on_fails_the_candidate():
    t = np.arange(3000.0)
    y = np.exp(-t / 240.0)
    ok = np.ones(len(t), bool)
    blind = ok & (t > 2000)                          # nothing valid in the start window
    outputs = [(t, y - y.mean(), ok), (t, y - y.mean(), blind)]
    _, scores = turn_on._fold_scores(outputs, [y, y], turn_on._run_weights(outputs), (720.0,))
    assert np.isinf(scores[1][0]) and scores[0][0] < 0.1


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
    while len(full.config.aux.terms) + 2 <= 6:
        full = turn_on.with_decay(full, effect_term("decay_on", "turn_on", tau_s=60.0 * len(full.config.aux.terms)), 0.1)
    with pytest.raises(ValueError, match="chip's limit"):
        turn_on.with_decay(full, effect_term("decay_on", "turn_on", tau_s=999.0), 1.0)


def test_the_shipped_term_is_the_scored_one_and_the_result_says_so(runs, fitted):
    """No refit after the choice: the model is the base (the fit without the term) plus the term at
    the size the held-out scoring fitted; the FitResult carries those coefficients and finite
    standard errors."""
    from host_tools.fitting.effects import effect_term
    model, res = fitted
    info = model.fit["turn_on"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        off, _ = fit_default(runs, turn_on="off")
    again = turn_on.with_decay(off, effect_term("decay_on", "turn_on", tau_s=info["tau_s"]), info["scale"])
    assert np.array_equal(again.coef, model.coef) and again.config.aux.terms == model.config.aux.terms
    assert np.array_equal(res.coef, model.coef) and tuple(res.terms) == tuple(model.terms)
    assert np.all(np.isfinite(res.stderr)) and res.stderr[7] > 0       # the fit's refusals pass (hdrg fit)
    assert info["size_stderr_dph"] > 0
    assert len(info["amp_dph"]) == len(model.banks) and "deg/h at power-on" in info["chosen"]
    true = foreign_device(DEVICE).effects["turn_on"]["amp_dph"]       # the device's, deg/h at power-on
    assert all(0.5 < a / true < 2.0 for a in info["amp_dph"]), (info["amp_dph"], true)


def test_a_run_the_model_fits_worse_weighs_less():
    t = np.arange(3000.0)
    ok = np.ones(len(t), bool)
    rng = np.random.default_rng(1)
    calm, rough = rng.normal(0, 0.1, len(t)), 5.0 * np.sin(t / 300.0)
    w = turn_on._run_weights([(t, calm, ok), (t, rough, ok), (t, np.zeros(len(t)), ok)])
    assert w[0] > 100 * w[1] > 0 and w[2] == 0.0


def test_hdrg_fit_writes_a_turn_on_model_and_says_its_size(runs, tmp_path, capsys):
    """The CLI end to end: the model with the term passes the fit's refusals (k7's standard error
    is a number), and the printout gives the term's size at power-on with its standard error."""
    from host_tools.cli import main
    from host_tools.golden.model import BiasModel
    from host_tools.golden.runlog import write
    names = []
    for i, run in enumerate(runs):
        names.append(str(tmp_path / f"run{i}.npz"))
        write(run, names[-1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["fit", *names, "-o", str(tmp_path / "model.json")]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("power-on transient"))
    assert "deg/h at power-on +- " in line and "nan" not in out.lower()
    model = BiasModel.from_json(tmp_path / "model.json")
    assert any(t["gen"] == "decay_on" for t in model.config.aux.terms)
    assert model.fit["turn_on"]["size_stderr_dph"] > 0
