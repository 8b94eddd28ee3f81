"""Valid means valid: input-invalid samples (host_tools.golden.input_check; FORMATS.md "The
input-invalid bit") are flagged, and every output computed from them is not valid, alike in the
float golden model, the per-sample Python reference, the numba kernel and the C twin (the
`validity` vector set, tests/test_c_twin.py); `hdrg compensate` warns / refuses; the fit leaves
them out; a stuck proxy is named."""
import warnings
from pathlib import Path

import numpy as np
import pytest

from firmware_ref import formats as F
from firmware_ref.compensate import run_reference
from firmware_ref.kernel import run_words
from host_tools.fixed.fixed_point import compensate_log, dequantized_log, log_words
from host_tools.fixed.quantize import quantize
from host_tools.golden import compensate as hc
from host_tools.golden import flags as hflags
from host_tools.golden import input_check as ic
from host_tools.golden import runlog as rl
from host_tools.golden.reversal import ReversalConfig, combine_values
from host_tools.vectors.builders import make_model

DATA = Path(__file__).parent / "data"


def _mr_log(n=1500, seed=0, **metadata):
    """A log-driven mode-reversal log at 1 Hz: exchange 30 / dwell 120, a slow proxy ramp, a
    rate of a few deg/h with noise."""
    rng = np.random.default_rng(seed)
    mode = np.tile(np.r_[np.full(30, 3), np.full(120, 1), np.full(30, 3), np.full(120, 2)], n // 300 + 1)[:n]
    t = np.arange(n, dtype=float)
    freq = 6227.0 + 0.5 * np.sin(t / 900.0) + rng.normal(0, 1e-4, n)
    rate = np.where(mode == 2, -1.0, 1.0) * 3.0 + 1.5 + rng.normal(0, 0.2, n)
    return rl.RunLog.from_arrays({"sample_rate_hz": "1", "reversal": "on", **metadata}, source="<mr>",
                                 t_s=t, freq_hz=freq, rate_dph=rate, mode=mode.astype(np.int64))


def _model(order="regress_first", combiner="pair", estimator="diff", max_stale_s=160.0, settle_s=5.0):
    return make_model("freq", ref=6227.0, span=1.5, estimator=estimator, n=4, shift=3, rate_span=0.003,
                      combiner=combiner, settle_s=settle_s, max_stale_s=max_stale_s, order=order)


# -- the input test ----------------------------------------------------------------------------------

def test_defaults_and_declared_limits():
    log = _mr_log(300)
    r = np.array(log.rate_dph)
    r[[10, 20, 30]] = [1e9, -2.0 ** 21, 2.0 ** 21 - 2.0 ** -10]      # beyond, at the rail, the largest word
    mask, rep = ic.input_flags(log.with_columns(rate_dph=r))
    assert np.flatnonzero(mask).tolist() == [10, 20, 30] and rep.first_row == 10 and rep.counts["rate_dph"] == 3
    r[30] = 2.0 ** 21 - 2.0 ** -9                                     # one LSB inside: not flagged
    assert np.flatnonzero(ic.input_flags(log.with_columns(rate_dph=r))[0]).tolist() == [10, 20]
    # a declared full scale (deg/s), frequency range, temperature range
    lg = _mr_log(300, rate_full_scale_dps="0.01", freq_range_hz="6226.0..6228.0")
    r = np.array(lg.rate_dph)
    r[50] = 36.0                                                      # exactly the full scale: clipped
    f = np.array(lg["freq_hz"])
    f[60], f[70] = 6228.5, 6225.5
    mask, rep = ic.input_flags(lg.with_columns(rate_dph=r, freq_hz=f))
    assert np.flatnonzero(mask).tolist() == [50, 60, 70]
    assert rep.counts == {"rate_dph": 1, "freq_hz": 2} and "metadata freq_range_hz" in rep.limits["freq_hz"]
    lt = rl.RunLog.from_arrays({"temp_range_c": "-40..85"}, t_s=np.arange(4.0), rate_dph=np.zeros(4),
                               temp_c=np.array([20.0, 90.0, -41.0, 85.0]), mode=np.zeros(4, np.int64))
    assert np.flatnonzero(ic.input_flags(lt)[0]).tolist() == [1, 2]
    with pytest.raises(ValueError, match="freq_range_hz"):
        ic.input_flags(_mr_log(10, freq_range_hz="high"))
    # a drive frequency above the F word's range: fine for the float model, invalid for the words
    hi = _mr_log(10).with_columns(freq_hz=np.full(10, 2.0e5))
    assert not ic.input_flags(hi)[0].any() and ic.input_flags(hi, word_range=True)[0].all()


@pytest.mark.parametrize("path", sorted(DATA.glob("*/*.csv")), ids=lambda p: p.name)
def test_no_false_alarm_on_measured_logs(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = rl.read(path)
    mask, rep = ic.input_flags(log)
    assert not mask.any() and not rep.stuck and not rep.messages()


def test_stuck_proxy_runs():
    x = np.r_[np.arange(10.0), np.full(ic.STUCK_N, 5.5), np.arange(3.0), np.full(ic.STUCK_N - 1, 1.0)]
    assert ic.stuck_runs(x) == [(10, 10 + ic.STUCK_N - 1)]
    assert ic.longest_run(x) == ic.STUCK_N
    log = _mr_log(600)
    f = np.array(log["freq_hz"])
    f[100:400] = 6229.0
    _, rep = ic.input_flags(log.with_columns(freq_hz=f))
    assert rep.stuck == [("freq_hz", 100, 399)] and rep.flagged == 0
    assert "freq_hz rows 100..399 (300 samples)" in rep.messages()[0]


def test_rate_restarts():
    bad = np.zeros(10, bool)
    bad[[3, 4, 9]] = True
    assert ic.rate_restarts([0, 7], bad).tolist() == [0, 3, 4, 5, 7, 9]


# -- the golden combiner -------------------------------------------------------------------------------

def test_golden_combiner_taints_the_window():
    mode = np.r_[np.full(10, 1), np.full(5, 3), np.full(10, 2), np.full(5, 3), np.full(10, 1), np.full(5, 3),
                 np.full(10, 2)]
    x = np.ones(len(mode))
    ok = np.ones(len(mode), bool)
    cfg = ReversalConfig("pair", max_stale_s=100.0, settle_s=0.0, order="regress_first")
    _, v0, u0 = combine_values(mode, x, ok, [0], cfg, 1.0)
    bad = np.zeros(len(mode), bool)
    bad[4] = True                                       # in the first mode-1 window
    _, v1, u1 = combine_values(mode, x, ok, [0], cfg, 1.0, bad)
    assert v0[15:25].all() and not v1[15:25].any()      # mode 2 has no clean mode-1 window to pair with
    assert not u1[4] and u1[5] and v1[30:40].all()      # the mode-2 window itself is clean
    bad[:] = False
    bad[32] = True                                      # the second mode-1 window: mode 2 pairs with the first
    _, v2, _ = combine_values(mode, x, ok, [0], cfg, 1.0, bad)
    assert v2[45:55].all()
    cfg = ReversalConfig("pair", max_stale_s=20.0, settle_s=0.0, order="regress_first")
    _, v3, _ = combine_values(mode, x, ok, [0], cfg, 1.0, bad)
    assert not v3[45:55].any()                          # ... unless it is too old
    bad[:] = False
    bad[12] = True                                      # in an exchange: nothing is tainted
    np.testing.assert_array_equal(combine_values(mode, x, ok, [0], cfg, 1.0, bad)[1], combine_values(mode, x, ok, [0],
                                                                                                     cfg, 1.0)[1])


# -- float and fixed agree, and the 1e9 deg/h sample --------------------------------------------------------

def _spiked(log, rows, value=1e9):
    r = np.array(log.rate_dph)
    r[rows] = value
    return log.with_columns(rate_dph=r)


@pytest.mark.parametrize("order,combiner,estimator", [("regress_first", "pair", "diff"),
                                                      ("regress_first", "trend", "iir"),
                                                      ("regress_first", "none", "lsq"),
                                                      ("combine_first", "pair", "diffn"),
                                                      ("combine_first", "trend", "diff")])
def test_float_and_fixed_agree_on_flagged_samples(order, combiner, estimator):
    clean = _mr_log(1500)
    mode = np.asarray(clean.mode)
    # a mode-1 window's middle, a mode-2 window's first and last sample, an exchange, a burst
    rows = [30 + 60, 160, 180 + 0, 180 + 119, 330 + 40, 330 + 41, 330 + 42, 930 + 7]
    assert mode[rows].tolist() == [1, 3, 2, 2, 1, 1, 1, 1]
    log = _spiked(clean, rows)
    model = _model(order, combiner, estimator)
    q = quantize(model)
    fixed, fflags = compensate_log(log, model, table=q.table, return_flags=True)
    deq = dequantized_log(log, model)
    gold = hc.compensate(deq, model)
    prep = hc.prepare(deq, model)
    np.testing.assert_array_equal(fixed["valid"], gold["valid"])
    np.testing.assert_array_equal(fflags & (31 | F.FLAG_INPUT_SAT), prep.flags)
    assert np.flatnonzero(fflags & F.FLAG_INPUT_SAT).tolist() == rows
    v = gold["valid"] > 0
    assert np.max(np.abs(fixed.rate_dph[v] - gold.rate_dph[v])) < 0.002
    # every valid output of the spiked log equals the clean log's (nothing computed from a flagged sample)
    ref = hc.compensate(dequantized_log(clean, model), model)
    assert np.all(ref["valid"][v] > 0)
    if combiner != "trend" and estimator != "iir":
        np.testing.assert_array_equal(gold.rate_dph[v], ref.rate_dph[v])
    else:   # a restarted iir state, a trend extrapolated from the older clean window: close, not equal
        assert np.max(np.abs(gold.rate_dph[v] - ref.rate_dph[v])) < 0.5
    assert np.count_nonzero(v) < np.count_nonzero(ref["valid"] > 0) - len(rows)
    # the numba kernel and the per-sample Python reference
    w = log_words(log, model.config)
    kw = {name: w[name] for name in ("f", "t", "aux", "k", "invalid")}
    k = run_words(q.table, w["p"], w["r"], w["mode"], w["restart"], w["z"], detail=True, **kw)
    p = run_reference(q.table, w["p"], w["r"], w["mode"], w["restart"], w["z"], **kw)
    for name in ("out", "bias", "valid", "flags", "u", "v", "b", "y", "s"):
        np.testing.assert_array_equal(np.asarray(k[name], np.int64), np.asarray(p[name], np.int64), err_msg=name)


def test_one_giga_dph_sample_float_and_fixed():
    """The user's case: one raw sample of 1e9 deg/h in a mode-1 window."""
    clean = _mr_log(1500)
    log = _spiked(clean, [30 + 60])
    model = _model(max_stale_s=300.0)
    for impl in ("float", "fixed"):
        ref = hc.compensate(clean, model, impl=impl)
        out = hc.compensate(log, model, impl=impl)
        v = out["valid"] > 0
        assert np.all(ref["valid"][v] > 0) and np.max(np.abs(out.rate_dph[v] - ref.rate_dph[v])) == 0.0
        assert np.isnan(out.rate_dph[30 + 60]) and out["flags"][30 + 60] & F.FLAG_INPUT_SAT
        assert not v[180:300].any()          # the mode-2 window after the spiked mode-1 window: no clean pair
        assert out.metadata[ic.INPUT_KEY].startswith("1 samples; rate_dph 1, first row 90: 1e+09 (|x| >= 2097151.999 deg/h")
        with pytest.warns(hflags.CompensationWarning, match=r"input: 1 of 1500 samples .*: rate_dph 1, first row 90: 1e\+09"):
            hflags.report(out)
        with pytest.raises(ValueError, match=r"input: 1 of 1500 samples .*first row 90.*--strict"):
            hflags.report(out, strict=True)
        assert "\n" not in hflags.problems(out)[0]


def test_ftr_flagged_sample():
    n = 200
    t = np.arange(n, dtype=float)
    log = rl.RunLog.from_arrays({"sample_rate_hz": "1"}, source="<ftr>", t_s=t,
                                freq_hz=6227.0 + 1e-3 * t / n, rate_dph=np.ones(n), mode=np.zeros(n, np.int64))
    log = _spiked(log, [50])
    model = make_model("freq", ref=6227.0, span=1.5, estimator="diff", combiner=None, rate_span=0.003)
    for impl in ("float", "fixed"):
        out = hc.compensate(log, model, impl=impl)
        assert (np.flatnonzero(np.asarray(out["valid"]) == 0) == [0, 50, 51]).all()


def test_stuck_frequency_warns_and_strict_refuses():
    log = _mr_log(900)
    f = np.array(log["freq_hz"])
    f[:] = 6229.0
    model = _model()
    out = hc.compensate(log.with_columns(freq_hz=f), model)
    assert out.metadata[ic.STUCK_KEY] == "freq_hz rows 0..899 (900 samples)"
    with pytest.raises(ValueError, match=r"stuck proxy: freq_hz rows 0\.\.899"):
        hflags.report(out, strict=True)
    clean = hc.compensate(log, model)
    assert ic.INPUT_KEY not in clean.metadata and ic.STUCK_KEY not in clean.metadata


# -- the fit -----------------------------------------------------------------------------------------------------

def test_fit_excludes_flagged_samples():
    """fit_logs on a log with one 1e9 deg/h sample gives the clean log's coefficients to within
    the noise (before: the mode-2 k0 followed the one sample), and warn_inputs names the count."""
    from host_tools.fitting.fit import fit_logs

    clean = _mr_log(3000, seed=3)
    log = _spiked(clean, [30 + 60 + 300])
    cfg = hc.fit_config_from_logs([clean], reversal={"combiner": "pair", "order": "regress_first"})
    spiked_cfg = hc.fit_config_from_logs([log], reversal={"combiner": "pair", "order": "regress_first"})
    assert spiked_cfg.proxy == cfg.proxy and spiked_cfg.rate.span == pytest.approx(cfg.rate.span, rel=1e-3)
    m0, _ = fit_logs([clean], cfg, terms=[0, 1])
    m1, _ = fit_logs([log], cfg, terms=[0, 1])
    np.testing.assert_allclose(m1.coef, m0.coef, atol=0.05)
    np.testing.assert_allclose(m1.coef_mode2, m0.coef_mode2, atol=0.05)
    with pytest.warns(ic.InputWarning, match=r"1 of 3000 samples excluded from the fit"):
        masks = ic.warn_inputs([log])
    assert np.flatnonzero(~masks[0]).tolist() == [390]


# -- the aux generators (term k7) ---------------------------------------------------------------------------

_RATE_TERM = {"gen": "rate", "column": "freq_hz", "estimator": "iir", "n": 4, "shift": 3, "span": 0.003,
              "weight": 0.5, "sign": True}
_LAG_TERM = {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 1.5, "tau_s": 37.0, "weight": 0.5}


def _aux_model(terms):
    import dataclasses

    from host_tools.vectors.builders import with_aux

    m = with_aux(_model("regress_first", "pair", "iir"), terms)
    c, c2 = np.array(m.coef), np.array(m.coef_mode2)
    c[7] = c2[7] = 40.0                                 # z matters: 40 deg/h per unit
    return dataclasses.replace(m, coef=c, coef_mode2=c2)


def _aux_spiked_log():
    """_mr_log with a declared frequency range, 1e9 deg/h samples (a mode-1 window, an exchange,
    a mode-2 window's last sample, a burst) and two drive-frequency glitches beyond the range."""
    log = _spiked(_mr_log(1500, freq_range_hz="6200..6250"), [90, 160, 299, 370, 371, 372, 937])
    f = np.array(log["freq_hz"])
    f[[500, 700]] = 6300.0
    return log.with_columns(freq_hz=f)


@pytest.mark.parametrize("terms", [[_RATE_TERM], [_RATE_TERM, _LAG_TERM]], ids=["rate_iir", "rate_iir_lag"])
def test_aux_generators_float_and_fixed_agree_after_flagged_samples(terms):
    """An aux rate term (iir) re-warms with the model's estimator in the float model too, and an
    input filter holds its state over a flagged sample in both: |fixed - golden| stays within the
    quantizer's bound (measured 0.00065 deg/h, bound 0.00098; with the float generators blind to
    the bit: 0.25 deg/h)."""
    log = _aux_spiked_log()
    model = _aux_model(terms)
    q = quantize(model)
    fixed, fflags = compensate_log(log, model, table=q.table, return_flags=True)
    deq = dequantized_log(log, model)
    gold = hc.compensate(deq, model)
    np.testing.assert_array_equal(fixed["valid"], gold["valid"])
    assert np.flatnonzero(fflags & F.FLAG_INPUT_SAT).tolist() == [90, 160, 299, 370, 371, 372, 500, 700, 937]
    v = gold["valid"] > 0
    assert np.max(np.abs(fixed.rate_dph[v] - gold.rate_dph[v])) <= q.report["bound_dph"]["out"]
    # the per-sample Python reference and the numba kernel, every intermediate
    w = log_words(log, model.config)
    kw = {name: w[name] for name in ("f", "t", "aux", "k", "invalid")}
    k = run_words(q.table, w["p"], w["r"], w["mode"], w["restart"], w["z"], detail=True, **kw)
    p = run_reference(q.table, w["p"], w["r"], w["mode"], w["restart"], w["z"], **kw)
    for name in ("out", "bias", "valid", "flags", "u", "v", "z", "b", "y", "s"):
        np.testing.assert_array_equal(np.asarray(k[name], np.int64), np.asarray(p[name], np.int64), err_msg=name)


def test_aux_input_filter_holds_over_flagged_samples():
    """The float filter (host_tools.golden.regressors) and the fixed one (firmware_ref.aux) hold
    their state over a flagged sample, and a restart on a flagged sample zeroes the state and
    re-initializes the filter at the next clean one (PEND)."""
    from firmware_ref.aux import AuxStage
    from host_tools.golden import regressors as R

    q = np.linspace(-0.5, 0.5, 12)
    q[4] = 1.0                                          # the flagged sample's (clamped) input
    seg = np.zeros(12, bool)
    seg[[0, 8]] = True
    bad = np.zeros(12, bool)
    bad[[4, 8, 9]] = True                               # a flagged sample; a flagged restart and the next
    y = R.lowpass(q, seg, 3.0, 1.0, bad)
    assert y[4] == y[3] and y[8] == y[9] == 0.0 and y[10] == q[10]
    y0 = R.lowpass(q, seg, 3.0, 1.0)
    assert y0[4] != y0[3] and y0[8] == q[8]
    # the log's own mask when none is given (the fit's), and the explicit one of compensate
    log = _aux_spiked_log()
    g_own = R.generator_values(log, _LAG_TERM, 1.0)
    g_none = R.generator_values(log, _LAG_TERM, 1.0, np.zeros(len(log), bool))
    assert g_own[500] == g_own[499] and g_none[500] > g_none[499] + 0.01 and g_own[510] != g_none[510]
    # fixed point: a table with the lag term alone
    model = _aux_model([{**_LAG_TERM, "weight": 1.0}])
    table = quantize(model).table
    chan = [int(6227 * 2 ** 18), 0]
    st = AuxStage(table)
    zs = []
    for i, (inv, rs) in enumerate([(0, 1), (0, 0), (1, 0), (0, 0), (1, 1), (1, 0), (0, 0)]):
        c = [chan[0] + (2 ** 20 if i in (2, 4, 5) else 0) + 1000 * i, 0]
        zs.append(st.step(c, i, 1, bool(rs), 0, False, bool(inv))[0])
    assert zs[2] == zs[1] and zs[4] == zs[5] == 0 and zs[6] != zs[5]
    st2 = AuxStage(table)                               # the same stream restarted at sample 6, clean
    z6 = st2.step([chan[0] + 6000, 0], 6, 1, True, 0, False, False)[0]
    assert zs[6] == z6


def test_declared_frequency_range_above_the_word_is_compared_in_hz():
    from host_tools.golden.input_check import input_flags
    from host_tools.golden.runlog import RunLog
    t = np.arange(10.0)
    for md, f, flagged in (({"freq_range_hz": "200000..300000"}, 250000.0, 0), ({"freq_range_hz": "100000..140000"}, 131072.0, 0),
                           ({}, 250000.0, 0), ({"freq_range_hz": "200000..300000"}, 310000.0, 10)):
        log = RunLog.from_arrays(metadata=md, t_s=t, rate_dph=np.zeros(10), freq_hz=np.full(10, f))
        assert int(input_flags(log)[0].sum()) == flagged, (md, f)


def test_a_run_with_every_sample_invalid_is_refused_by_name():
    from host_tools.errors import UserError
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.runlog import RunLog
    t = np.arange(600.0)
    log = RunLog.from_arrays(metadata={"temp_range_c": "200..300"}, source="cold.csv", t_s=t, rate_dph=np.zeros(600),
                             freq_hz=6000 + t * 1e-3, temp_c=np.full(600, 20.0))
    with pytest.warns(Warning), pytest.raises(UserError, match=r"cold\.csv: every sample is outside"):
        fit_default([log])


def test_the_fit_s_look_at_its_runs_reports_what_compensate_reports():
    """api.fit checks its training runs with compensate.checked (no output copy: bounded memory
    at 100 Hz); it must find what a compensation would."""
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.compensate import checked, compensate
    from host_tools.golden.flags import problems
    log = _mr_log(3000)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, _ = fit_default([log])
    r = np.array(log.rate_dph)
    r[700] = 1e9
    for lg in (log, log.with_columns(rate_dph=r), log.select(np.arange(100, 2000))):
        assert problems(checked(lg, model)) == problems(compensate(lg, model))
    assert problems(checked(log.with_columns(rate_dph=r), model))
