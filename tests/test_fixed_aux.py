"""The k7 auxiliary regressor z in fixed point (table aux_gen 1, firmware_ref/aux.py): the
primitives (RHUW, the sine), every generator against the golden (host_tools.golden.regressors) within the
quantizer's bound, long filters without a dead band, exchange resets, the table's aux words, the
quantizer's refusals, the host path (``compensate(impl='fixed')`` computes z from the log's
channels), |fixed - golden| < 0.002 deg/h on models that ``hdrg diagnose`` finds, an aux table
uploaded to the virtual device, and the issue's acceptance test: the effect found is exported,
quantized and run through the fixed-point path with the same before/after numbers (within the
golden-vs-fixed bound)."""
import dataclasses
import math
import warnings

import numpy as np
import pytest

from firmware_ref import arith
from firmware_ref import formats as F
from firmware_ref import table as T
from firmware_ref import inputs
from firmware_ref.aux import sin_q30
from firmware_ref.compensate import run_reference
from host_tools.fixed.fixed_point import compensate_log, log_words
from firmware_ref.kernel import _rhu_wide, _sin_q30, run_words
from firmware_ref.table import FIELD_INDEX, Table, TableError, encode_aux
from host_tools.vectors.builders import make_model, with_aux
from host_tools.golden import compensate as hc
from host_tools.golden import runlog as rl
from host_tools.fitting.diagnose import stats_one, diagnose

STAT_KEYS = ("std_dph", "pp_dph", "std100_dph", "pp100_dph", "rms_dph")   # the figures stats_one gives
from host_tools.fitting.fit import fit_logs
from host_tools.fixed.quantize import QuantizeError, quantize, read_table
from host_tools.fixed.quantize_parts import aux_channel_fracs
from host_tools.golden.regressors import aux_regressor
from host_tools.fixed.fixed_point import dequantized_log
from fixed_compare import fixed_vs_golden
from test_diagnose import CASES, world

GOAL_DPH = 0.002
COEF = [3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1, 6e1, -5e1]


def check_close(log, model, what):
    c = fixed_vs_golden(log, model)
    q, flags, err, emax, bmax = c.q, c.flags, c.err, c.emax, c.bmax
    b = q.report["bound_dph"]
    print(f"\n{what}: |fixed - golden| max {emax:.3g}, 1 sigma {np.std(err[c.valid]):.3g} deg/h, bias max {bmax:.3g}; "
          f"bound {b['out']:.3g} (z part {b['parts']['z_error'] * b['parts']['k7_dph']:.2g}); z measured "
          f"{q.report['aux']['measured_z']['z_max']:.2g} <= {q.report['aux']['z_error']:.2g}")
    assert emax < GOAL_DPH and emax <= b["out"] and bmax <= b["bias_word"]
    assert q.report["aux"]["measured_z"]["z_max"] <= q.report["aux"]["z_error"]
    assert not (flags & (F.FLAG_SAT | F.FLAG_AUX_CLAMPED)).any()
    return q


# -- primitives -------------------------------------------------------------------------------------------

def test_rhuw_is_the_exact_wide_product():
    """RHUW(a, d, s) = RHU(a d, s) for products beyond int64: the kernel's split form equals the
    exact big-integer value, ties included, at the edges of its preconditions."""
    rng = np.random.default_rng(0)
    lim31, lim62 = (1 << 31) - 1, 1 << 62
    cases = [(a, d, s) for s in (31, 32, 47, 61, 62) for a in (lim31, -lim31, 1, -1, 0, 12345)
             for d in (lim62, -lim62, 1 << (s - 1), -(1 << (s - 1)), 3 << (s - 2), 0, 1, -1)]
    cases += [(int(rng.integers(-lim31, lim31)), int(rng.integers(-lim62, lim62)), int(rng.integers(31, 63)))
              for _ in range(3000)]
    for a, d, s in cases:
        exact = math.floor(a * d / 2 ** s + 0.5) if abs(a * d) < 2 ** 52 else (a * d + (1 << (s - 1))) >> s
        assert arith.mul_rshift_round_wide(a, d, s) == exact == int(_rhu_wide(np.int64(a), np.int64(d), s)), (a, d, s)
    with pytest.raises(AssertionError):
        arith.mul_rshift_round_wide(1 << 31, 1, 31)
    with pytest.raises(AssertionError):
        arith.mul_rshift_round_wide(1, 1, 30)


def _sin_vec(x):
    """The quarter-wave polynomial of FORMATS.md on int64 arrays x in [0, 2^30]."""
    h = np.int64(1 << 29)
    x2 = (x * x + h) >> 30
    p = np.full_like(x, F.SIN_POLY[5])
    for c in F.SIN_POLY[4::-1]:
        p = ((p * x2 + h) >> 30) + c
    return np.minimum((p * x + h) >> 30, F.ONE)


def test_sine_accuracy_and_quadrants():
    """The quarter wave is within SIN_ERR_LSB of sin on a dense grid (every 251st argument and the
    neighbourhood of the worst one found over all 2^30 + 1); the uint64-phase sine (Python, numba)
    has that accuracy in every quadrant, exact zeros and ones at the quarter turns."""
    x = np.r_[np.arange(0, F.ONE + 1, 251, dtype=np.int64), np.arange(1073523179 - 5000, 1073523179 + 5000),
              np.arange(F.ONE - 3000, F.ONE + 1)]
    err = np.abs(_sin_vec(x) - np.sin(np.pi / 2 * x / F.ONE) * F.ONE)
    assert err.max() <= F.SIN_ERR_LSB and err.max() > 2.5        # tight: the documented 3.07 LSB
    rng = np.random.default_rng(1)
    phases = [int(p) for p in rng.integers(0, 1 << 64, 4000, dtype=np.uint64)] + [0, 1 << 62, 2 << 62, 3 << 62]
    for ph in phases:
        s = sin_q30(ph)
        assert s == int(_sin_q30(np.int64(ph - (1 << 64) if ph >= 1 << 63 else ph)))
        assert abs(s - math.sin(2 * math.pi * ph / 2.0 ** 64) * F.ONE) <= F.SIN_ERR_LSB + 0.6   # phase LSB 2^-32 turn
    assert [sin_q30(q << 62) for q in range(4)] == [0, F.ONE, 0, -F.ONE]


# -- every generator against the golden --------------------------------------------------------------------

TERMS = {
    "proxy_u": {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0},
    "proxy_u5_sign": {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0, "power": 5, "sign": True},
    "lag_proxy": {"gen": "input", "column": "freq_hz", "ref": 6227.3, "span": 2.5, "tau_s": 120.0, "power": 2},
    "board_temp_long": {"gen": "input", "column": "temp_c", "ref": 20.0, "span": 40.0, "tau_s": 50000.0},
    "aux_column": {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.05, "tau_s": 7.0, "sign": True},
    "rate_sign": {"gen": "rate", "column": "freq_hz", "estimator": "diff", "span": 0.01, "sign": True},
    "one_sign": {"gen": "one", "sign": True},
    "decay_on": {"gen": "decay_on", "tau_s": 300.0},
    "decay_on_long": {"gen": "decay_on", "tau_s": 2.0e6},
    "decay_exchange": {"gen": "decay_exchange", "tau_s": 15.0},
    "decay_exchange_sign": {"gen": "decay_exchange", "tau_s": 4.0, "sign": True},
    "ramp": {"gen": "ramp", "n_samples": 2500},
    "osc_sin": {"gen": "osc", "period_s": 600.0, "part": "sin"},
    "osc_cos_fast": {"gen": "osc", "period_s": 2.7, "part": "cos"},
}


@pytest.mark.parametrize("name", list(TERMS))
def test_each_generator_is_within_its_bound(name):
    """One term (weight 1): the quantizer's measured max |z_fixed - z_golden| (a 3000-sample run
    with clamps, a reversal cycle and a gap) is within its analytic bound, which is small."""
    model = with_aux(make_model(coef=COEF), [{**TERMS[name], "weight": 1.0}])
    q = quantize(model, n_random=10)
    aux = q.report["aux"]
    assert aux["measured_z"]["z_max"] <= aux["z_error"], aux
    assert aux["z_error"] < (3e-6 if name.startswith("osc") else 2e-8)
    assert q.table.aux_gen == 1 and q.table.aux().terms[0].weight == F.ONE


def test_long_filter_and_decay_have_no_dead_band():
    """fs tau = 2^14 samples: after a step the filter settles to its input within 1 LSB (a Q1.30
    state with RHU per step would stop up to fs tau / 2 LSB away), and the decay follows
    exp(-k / (fs tau)) within 2 LSB all the way down."""
    n_tau = 1 << 14
    base = make_model(coef=COEF, combiner=None)
    filt = quantize(with_aux(base, [{"gen": "input", "column": "temp_c", "ref": 0.0, "span": 100.0,
                                     "tau_s": float(n_tau), "weight": 1.0}]), n_random=10).table
    n = 30 * n_tau
    t_w = np.full(n, inputs.temp_words(np.array([37.5]))[0][0], np.int64)
    t_w[:10] = inputs.temp_words(np.array([-80.0]))[0][0]
    zero = np.zeros(n, np.int64)
    z = run_words(filt, np.full(n, filt.p_ref, np.int64), zero, zero, t=t_w, detail=True)["z"]
    assert z[0] == round(-0.8 * F.ONE) and abs(int(z[-1]) - round(0.375 * F.ONE)) <= 1
    dec = quantize(with_aux(base, [{"gen": "decay_on", "tau_s": float(n_tau), "weight": 1.0}]), n_random=10).table
    m = 20 * n_tau
    z = run_words(dec, np.full(m, dec.p_ref, np.int64), zero[:m], zero[:m], detail=True)["z"]
    gold = np.exp(np.arange(m) * math.log(math.exp(-1.0 / n_tau))) * F.ONE
    assert np.max(np.abs(z - gold)) <= 2.0 and z[-1] == round(gold[-1])


def _exchange_log(n=900, gap_at=520):
    modes = np.resize(np.array([3] * 5 + [1] * 40 + [3] * 5 + [2] * 40), n)
    modes[:3] = 1                                            # no exchange before the first one
    t_s = np.arange(n, dtype=np.float64)
    t_s[gap_at:] += 7.0
    f = 6227.0 + np.sin(np.arange(n) / 50.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rl.RunLog.from_arrays(t_s=t_s, rate_dph=np.zeros(n), mode=modes, freq_hz=f, temp_c=np.full(n, 20.0),
                                     aux_vdd=3.3 + 0.01 * np.cos(np.arange(n) / 30.0))


def test_decay_exchange_resets_and_signs():
    """decay_exchange: 0 before the first exchange and during mode 3, exactly 1 at the first sample
    after it, decaying; the state restarts at a gap; with sign, s times it flips in mode 2; the
    fixed z equals the golden within 2^-30."""
    log = _exchange_log()
    for sign in (False, True):
        model = with_aux(make_model(coef=COEF), [{"gen": "decay_exchange", "tau_s": 6.0, "weight": 1.0, "sign": sign}])
        table = quantize(model, n_random=10).table
        w = log_words(log, model.config)
        res = run_words(table, w["p"], w["r"], w["mode"], w["restart"], detail=True, f=w["f"], t=w["t"],
                        aux=w["aux"], k=w["k"])
        ref = run_reference(table, w["p"], w["r"], w["mode"], w["restart"], f=w["f"], t=w["t"], aux=w["aux"], k=w["k"])
        np.testing.assert_array_equal(ref["z"], res["z"])
        z = res["z"]
        mode = np.asarray(log.mode)
        assert (z[:3] == 0).all() and (z[mode == 3] == 0).all()
        after = np.flatnonzero((mode[1:] != 3) & (mode[:-1] == 3)) + 1
        assert (np.abs(z[after]) == F.ONE).all() and ((z[after] < 0) == (sign & (mode[after] == 2))).all()
        assert z[520] == 0 and z[519] != 0                  # the gap restarts it (mode 2 at 520: no exchange yet)
        gold = aux_regressor(log, model.config.aux)
        assert np.max(np.abs(z * 2.0 ** -30 - gold)) <= 2.0 ** -30


# -- the table ----------------------------------------------------------------------------------------------

def aux_model():
    return with_aux(make_model(coef=COEF, combiner="trend"), [
        {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0, "tau_s": 300.0, "weight": 0.2},
        {"gen": "decay_exchange", "tau_s": 15.0, "weight": 0.15, "sign": True},
        {"gen": "one", "weight": -0.05, "sign": True},
        {"gen": "osc", "period_s": 600.0, "part": "cos", "weight": -0.1},
        {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.1, "power": 3, "weight": 0.2},
        {"gen": "ramp", "n_samples": 86400, "weight": 0.3}])


def test_aux_table_words_roundtrip_and_validate():
    q = quantize(aux_model(), n_random=10)
    t = q.table
    words = t.to_words()
    assert words[1] == T.VERSION and words[FIELD_INDEX["aux_gen"]] == 1
    assert len(words) == 73 + 2 + 1 + 6 * F.AUX_TERM_WORDS and words[2] == len(words)
    assert Table.from_words(words) == t == Table.from_bytes(t.to_bytes()) == Table.from_memh(t.to_memh())
    aux = t.aux()
    assert aux.fracs == (aux_channel_fracs(q.model.config.aux)[0],) and encode_aux(aux.fracs, aux.terms) == t.aux_params
    assert [F.AUX_KINDS[x.kind] for x in aux.terms] == ["input", "decay_exchange", "one", "osc", "input", "ramp"]
    assert t.param_names()[:3] == ["aux_n_terms", "aux_n_chan", "aux_af_0"] and t.param_names()[-1] == "aux_t5_c5"
    assert t.aux_array().shape == (6, F.AUX_TERM_WORDS)
    for change, match in [({"aux_gen": 2}, "aux_gen 2"), ({"aux_gen": 0}, "takes no parameters"),
                          ({"aux_params": t.aux_params[:-1]}, "need"),
                          ({"aux_params": (F.AUX_MAX_TERMS + 1,) + t.aux_params[1:]}, "n_terms 17 not in 1..16"),
                          ({"aux_params": t.aux_params[:3] + (9,) + t.aux_params[4:]}, "kind 9")]:
        with pytest.raises(TableError, match=match):
            dataclasses.replace(t, **change)
    d = q.to_dict()
    assert d["aux"]["channels"] == [{"column": "aux_vdd", "word": "A0", "frac": aux.fracs[0]}]
    assert d["bound_dph"]["parts"]["z_error"] == d["aux"]["z_error"] > 0


def test_aux_table_of_max_terms_roundtrips_and_one_more_is_refused():
    """AUX_MAX_TERMS (16) terms of every kind on all four aux words: the longest table (255 words,
    1020 bytes: one serial TABLE frame) quantizes and round-trips through words, bytes and memh, the
    link's table check accepts it and the kernel equals the Python reference on it; a 17th term (a
    legal one, weight 0, the words consistent) is refused naming n_terms, by the decoder, Table and
    from_words, and the quantizer refuses a 17-term model."""
    from host_tools import link as SL
    from host_tools.vectors.aux import MAX_TERMS_EVERY_KIND
    from host_tools.vectors.builders import aux_stream

    t = quantize(with_aux(make_model(coef=COEF), list(MAX_TERMS_EVERY_KIND)), n_random=10).table
    aux = t.aux()
    words = t.to_words()
    assert len(aux.terms) == F.AUX_MAX_TERMS == 16 and aux.n_chan == F.AUX_MAX_CHANNELS
    assert {F.AUX_KINDS[x.kind] for x in aux.terms} == set(F.AUX_KINDS)
    assert len(words) == T.N_FIXED + 2 + F.AUX_MAX_CHANNELS + F.AUX_MAX_TERMS * F.AUX_TERM_WORDS + 1 == 255
    assert words[2] == 255 and len(t.to_bytes()) == 1020 <= SL.MAX_PAYLOAD
    assert Table.from_words(words) == t == Table.from_bytes(t.to_bytes()) == Table.from_memh(t.to_memh())
    assert t.param_names()[-1] == "aux_t15_c5" and t.aux_array().shape == (16, F.AUX_TERM_WORDS)
    assert SL.validate_table_payload(t.to_bytes())[1] == SL.R_OK
    assert len(SL.encode_frame(SL.T_TABLE, 0, t.to_bytes())) == 1020 + SL.OVERHEAD
    s = aux_stream(np.random.default_rng(16), t, 600)
    p = s["p"]
    kw = dict(f=s["f"], t=s["t"], aux=s["aux"], k=s["k"])
    ref = run_reference(t, p, s["r"], s["mode"], s["restart"], s["z"], **kw)
    ker = run_words(t, p, s["r"], s["mode"], s["restart"], s["z"], detail=True, **kw)
    for name in ("z", "b", "out", "bias", "flags"):
        assert np.array_equal(np.asarray(ref[name], np.int64), np.asarray(ker[name], np.int64)), name
    assert len(np.unique(ker["z"])) > 100

    params = encode_aux(aux.fracs, aux.terms + (dataclasses.replace(aux.terms[-1], weight=0),))
    fixed = words[:T.N_FIXED]
    fixed[FIELD_INDEX["aux_nparams"]] = len(params)
    fixed[2] = T.N_FIXED + len(params) + 1
    body = fixed + [x & 0xFFFFFFFF for x in params]
    words17 = body + [T.crc32_words(body)]
    assert len(words17) == 266 == words17[2]
    for refuse in (lambda: T.decode_aux(params), lambda: dataclasses.replace(t, aux_params=params),
                   lambda: Table.from_words(words17, "t17")):
        with pytest.raises(TableError, match="aux n_terms 17 not in 1..16"):
            refuse()
    assert SL.validate_table_payload(T.struct.pack("<266I", *words17))[1] == SL.R_TABLE_RANGE
    with pytest.raises(QuantizeError, match=f"17 terms; the firmware holds at most {F.AUX_MAX_TERMS}"):
        quantize(with_aux(make_model(coef=COEF), list(MAX_TERMS_EVERY_KIND) + [{"gen": "one", "weight": 0.01}]))


@pytest.mark.parametrize("terms,match", [
    ([{"gen": "one", "weight": 0.05}] * (F.AUX_MAX_TERMS + 1), f"17 terms; the firmware holds at most {F.AUX_MAX_TERMS}"),
    ([{"gen": "input", "column": f"aux_{c}", "ref": 0.0, "span": 1.0, "weight": 0.1} for c in "abcde"], "4 aux input"),
    ([{"gen": "decay_on", "tau_s": 3.0e9, "weight": 1.0}], "outside"),
    ([{"gen": "decay_on", "tau_s": 0.01, "weight": 1.0}], "outside"),
    ([{"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0, "tau_s": 0.05, "weight": 1.0}], "outside"),
    ([{"gen": "osc", "period_s": 2.0, "part": "sin", "weight": 1.0}], "more than 2 samples"),
    ([{"gen": "ramp", "n_samples": 1 << 31, "weight": 1.0}], "exceeds 2\\^31 - 1"),
    ([{"gen": "rate", "column": "temp_c", "estimator": "diff", "span": 0.1, "weight": 1.0}], "only the proxy"),
    ([{"gen": "rate", "column": "freq_hz", "estimator": "lsq", "n": 4, "span": 0.1, "weight": 1.0}], "one rate sum"),
    ([{"gen": "input", "column": "rate_dph", "ref": 0.0, "span": 1.0, "weight": 1.0}], "no input word"),
    ([{"gen": "input", "column": "aux_p", "ref": 1e10, "span": 1.0, "weight": 1.0}], "aux word range"),
    ([{"gen": "input", "column": "aux_p", "ref": 0.0, "span": 1e-20, "weight": 1.0}], "below one word LSB"),
])
def test_quantize_refuses_aux(terms, match):
    with pytest.raises(QuantizeError, match=match):
        quantize(with_aux(make_model(coef=COEF), terms))


# -- the host path -----------------------------------------------------------------------------------------

def _sim_log(seed=4, duration=3000.0, **kw):
    from host_tools.simulation.sim import simulate
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = simulate("paper-mr-cycle-4dpm", seed=seed, duration_s=duration, **kw)
    n = len(log)
    return log.with_columns(aux_vdd=3.3 + 0.02 * np.sin(np.arange(n) / 400.0) + 1e-4 * np.cos(np.arange(n)))


def fitted_aux_model(log, terms, combiner="trend"):
    from host_tools.golden.reversal import ReversalConfig
    from host_tools.golden.regressors import AuxConfig
    cfg = hc.fit_config_from_logs([log], reversal=ReversalConfig(combiner))
    cfg = dataclasses.replace(cfg, aux=AuxConfig.from_terms(terms, cfg.rate.fs))
    model, _ = fit_logs([log], cfg, tuple(range(17)), drop_unidentifiable=True)
    return model


def test_compensate_fixed_computes_z_from_the_log():
    """impl='fixed' (host_tools.golden.compensate) runs the generators on the log's channels: numba ==
    the Python reference; the aux column matters; a table of other aux parameters is refused; a
    log without the aux column is refused naming it; 'none' keeps z = 0."""
    log = _sim_log(duration=1500.0)
    model = fitted_aux_model(log, [{"gen": "decay_on", "tau_s": 300.0, "weight": 0.4},
                                   {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.03, "tau_s": 20.0,
                                    "weight": 0.3},
                                   {"gen": "input", "column": "temp_c", "ref": 0.0, "span": 40.0, "weight": 0.3,
                                    "sign": True}])
    assert model.coef[7] != 0
    out = hc.compensate(log, model, impl="fixed")
    assert out.metadata["compensation_impl"] == "fixed"
    np.testing.assert_array_equal(out.rate_dph, hc.blank_invalid(compensate_log(log, model, impl="python")).rate_dph)
    other = log.with_columns(aux_vdd=np.asarray(log["aux_vdd"]) + 0.01)
    assert not np.array_equal(hc.compensate(other, model, impl="fixed")["bias_dph"], out["bias_dph"])
    q2 = quantize(with_aux(model, [{"gen": "one", "weight": 1.0}]))
    with pytest.raises(ValueError, match="aux_params"):
        compensate_log(log, model, table=q2.table)
    bare = rl.RunLog.from_arrays(t_s=log.t_s, rate_dph=log.rate_dph, mode=log.mode, freq_hz=log["freq_hz"],
                                 temp_c=log["temp_c"])
    with pytest.raises(ValueError, match="aux_vdd"):
        hc.compensate(bare, model, impl="fixed")
    w = log_words(log, dataclasses.replace(model.config, aux=type(model.config.aux)()))
    assert not w["z"].any() and w["k"] is None


def test_fixed_vs_golden_every_kind():
    """Models built with AuxConfig.from_terms (every kind, signs, powers, lags, the board sensor,
    an aux column, s v, a ramp and an oscillator pair), fitted on a simulated run: |fixed - golden|
    < 0.002 deg/h and within the quantizer's bound."""
    log = _sim_log()
    r = hc.fit_config_from_logs([log]).rate
    first = [{"gen": "decay_on", "tau_s": 300.0, "weight": 0.2},
             {"gen": "decay_exchange", "tau_s": 8.0, "weight": 0.2, "sign": True},
             {"gen": "one", "weight": -0.1, "sign": True},
             {"gen": "input", "column": "freq_hz", "ref": float(np.mean(log["freq_hz"])),
              "span": float(np.ptp(log["freq_hz"])), "tau_s": 600.0, "power": 2, "weight": 0.2},
             {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.03, "tau_s": 20.0, "weight": 0.15},
             {"gen": "rate", "column": "freq_hz", "estimator": r.estimator, "n": r.n, "shift": r.shift,
              "span": 2 * r.span, "weight": 0.15, "sign": True}]
    second = [{"gen": "ramp", "n_samples": 4000, "weight": 0.3},
              {"gen": "osc", "period_s": 600.0, "part": "sin", "weight": 0.2},
              {"gen": "osc", "period_s": 600.0, "part": "cos", "weight": -0.2},
              {"gen": "input", "column": "temp_c", "ref": 0.0, "span": 30.0, "tau_s": 90.0, "power": 3,
               "weight": 0.3, "sign": True}]
    for name, terms in (("decays, s, lag^2, aux, s v", first), ("ramp, osc pair, s board^3", second)):
        model = fitted_aux_model(log, terms)
        check_close(log, model, name)


@pytest.mark.parametrize("family", ["turn_on", "exchange_transient", "periodic", "aux_vdd", "imperfect_reversal"])
def test_fixed_vs_golden_on_diagnosed_models(family):
    """The final model of `hdrg diagnose` (an undeclared effect in the clean world of
    tests/test_diagnose.py): |fixed - golden| < 0.002 deg/h on the held-out run, within the bound;
    the same flags (1..16) and valid samples."""
    und, sim_kw, diag_kw = CASES[family]
    train = [world(s, und, **sim_kw) for s in (1, 3)]
    hold = world(2, und, **sim_kw)
    rep, model = diagnose(train, [hold], plots=False, **{"rate_estimator": "diff", "settle_s": 0.0, **diag_kw})
    assert rep["iterations"] and model.config.aux.generator == "sum"
    check_close(hold, model, f"diagnosed {family} ({[t['gen'] for t in model.config.aux.terms]})")


# -- the acceptance test ------------------------------------------------------------------------------

def test_acceptance_effect_found_exported_quantized_and_run_in_fixed_point(tmp_path, capsys):
    """`hdrg diagnose` finds an undeclared turn-on transient; the final model is quantized,
    exported (`hdrg export`) and the held-out run compensated with impl='fixed' from the exported
    table: before/after std and peak-to-peak at 1 s and 100 s equal the float ones (golden on the
    dequantized words) within the golden-vs-fixed bound (std) and twice it (pp: two samples),
    and the raw float numbers within the measured |fixed - float|; the effect is removed in
    fixed point as in float."""
    from host_tools.fixed import export as ex
    from host_tools.cli import COMMANDS, main
    from host_tools.golden.reversal import ReversalConfig

    und, sim_kw, diag_kw = CASES["turn_on"]
    train = [world(s, und, **sim_kw) for s in (1, 3)]
    hold = world(2, und, **sim_kw)
    rep, final = diagnose(train, [hold], plots=False, **{"rate_estimator": "diff", "settle_s": 0.0, **diag_kw})
    assert rep["iterations"][0]["effect"] == "turn_on"
    # the starting model of the loop (diagnose's defaults: trend combiner, settle 0, all 16 terms;
    # diagnose passes the reversal as a dict without "order", which reads as combine_first)
    cfg0 = hc.fit_config_from_logs(train, reversal=ReversalConfig("trend", settle_s=0.0, order="combine_first"))
    base, _ = fit_logs(train, cfg0, "all", drop_unidentifiable=True)
    before_float = stats_one(*_run(hc.compensate(hold, base), hold))
    assert before_float == pytest.approx({k: rep["baseline"]["holdout"][k] for k in before_float}, rel=1e-12)
    rows = {}
    for name, model in (("before", base), ("after", final)):
        model.to_json(tmp_path / f"{name}.model.json")
        q = quantize(model)
        q.to_json(tmp_path / f"{name}.table.json")
        outdir = tmp_path / f"export_{name}"
        if "export" in COMMANDS:
            assert main(["export", str(tmp_path / f"{name}.table.json"), "-o", str(outdir)]) == 0
        else:
            ex.export(q.table, outdir, info=q.to_dict())
        header_words = ex.decode_c_header((outdir / "hdrg_table.h").read_text())
        table = read_table(outdir / "hdrg_table.json")
        assert table == read_table(outdir / "hdrg_table.memh") == q.table and header_words == q.table.to_words()
        fixed = hc.compensate(hold, model, impl="fixed", table=table)
        np.testing.assert_array_equal(fixed.rate_dph, hc.blank_invalid(compensate_log(hold, model)).rate_dph)
        gold = hc.compensate(dequantized_log(hold, model), model)
        flt = hc.compensate(hold, model)
        rows[name] = {"float": stats_one(*_run(flt, hold)), "golden_deq": stats_one(*_run(gold, hold)),
                      "fixed": stats_one(*_run(fixed, hold)), "bound": q.report["bound_dph"]["out"],
                      "fixed_float_max": float(np.nanmax(np.abs(fixed.rate_dph - flt.rate_dph))),    # NaN: not valid
                      "fixed_golden_max": float(np.nanmax(np.abs(fixed.rate_dph - gold.rate_dph)))}
    capsys.readouterr()
    with capsys.disabled():
        print("\nacceptance (turn_on found by hdrg diagnose, held-out run):")
        for name, r in rows.items():
            for key in STAT_KEYS:
                print(f"  {name:6s} {key:10s} float {r['float'][key]:.6f}  golden(deq) {r['golden_deq'][key]:.6f}"
                      f"  fixed {r['fixed'][key]:.6f}  deg/h")
            print(f"  {name:6s} max |fixed - golden(deq)| {r['fixed_golden_max']:.3g} <= bound {r['bound']:.3g}; "
                  f"max |fixed - float| {r['fixed_float_max']:.3g} deg/h")
    for name, r in rows.items():
        assert r["fixed_golden_max"] <= r["bound"] < GOAL_DPH
        for key in STAT_KEYS:
            k = 2.0 if key.startswith("pp") else 1.0
            assert abs(r["fixed"][key] - r["golden_deq"][key]) <= k * r["bound"] + 1e-12, (name, key)
            assert abs(r["fixed"][key] - r["float"][key]) <= k * r["fixed_float_max"] + 1e-12, (name, key)
    for impl in ("float", "fixed"):
        assert rows["before"][impl]["std100_dph"] / rows["after"][impl]["std100_dph"] >= 2.0
    ratio = {impl: rows["before"][impl]["std100_dph"] / rows["after"][impl]["std100_dph"]
             for impl in ("float", "fixed")}
    assert ratio["fixed"] == pytest.approx(ratio["float"], rel=0.01)


def _run(out, log):
    return out.rate_dph, log.t_s, np.asarray(out["valid"]) == 1


# -- the virtual device ------------------------------------------------------------------------------------------

def test_aux_table_uploads_to_the_virtual_device():
    """An aux table (a lagged board-temperature term and a decay) passes the serial link's table
    checks and uploads (ACK); from the applied sample on the device computes it bit for bit as
    run_words with the F and T words (its aux words read 0)."""
    from host_tools.link import device as D
    from host_tools import link as SL
    from test_serial import PtyDevice, stream_around_upload

    from host_tools.golden.reversal import ReversalConfig
    log = _sim_log(seed=5, duration=1200.0)
    base = quantize(fit_logs([log], hc.fit_config_from_logs([log], reversal=ReversalConfig("pair")))[0]).table
    aux = quantize(fitted_aux_model(log, [{"gen": "decay_on", "tau_s": 60.0, "weight": 0.5},
                                          {"gen": "input", "column": "temp_c", "ref": 0.0, "span": 40.0,
                                           "tau_s": 30.0, "weight": 0.5}], "pair")).table
    assert aux.aux_gen == 1 and len(aux.to_bytes()) <= SL.MAX_PAYLOAD
    assert SL.validate_table_payload(aux.to_bytes())[1] == SL.R_OK
    with PtyDevice(log, base, speed=400.0) as pd:
        _, res, got = stream_around_upload(pd, aux, before=50, total=300)
        assert pd.dev.table.crc == aux.crc
    k = res.apply_sample
    dr = D.DeviceRun.from_log(log)
    after = run_words(aux, dr.freq[k:], dr.rate[k:], dr.mode[k:], f=dr.freq[k:], t=dr.temp[k:])["out"]
    assert np.array_equal(np.array([s[4] for s in got])[k:], after[:len(got) - k])
    assert len(got) - k > 50


# -- benchmark (pytest -m benchmark tests/test_fixed_aux.py -s) -------------------------------------------

BENCH_TERMS = [{"gen": "decay_on", "tau_s": 300.0, "weight": 0.2},
               {"gen": "decay_exchange", "tau_s": 15.0, "weight": 0.15, "sign": True},
               {"gen": "input", "column": "temp_c", "ref": 20.0, "span": 40.0, "tau_s": 900.0, "power": 2,
                "weight": 0.2},
               {"gen": "osc", "period_s": 600.0, "part": "sin", "weight": 0.15},
               {"gen": "osc", "period_s": 600.0, "part": "cos", "weight": -0.15},
               {"gen": "ramp", "n_samples": 10 ** 7, "weight": 0.15}]


@pytest.mark.benchmark
def test_bench_aux_stage(benchmark, tmp_path):
    """Cost of the aux stage: the numba kernel and the C twin (BENCH, records of width 11) with
    the 6-term table above against the same table without aux (aux_gen 0), 10^6 samples."""
    from test_bench_fixed import best_of, paper_stream
    from test_c_twin import GCC, CFLAGS, build, input_records, table_line

    model = with_aux(make_model(estimator="diff", combiner="pair", coef=COEF), BENCH_TERMS)
    table = quantize(model, n_random=10).table
    plain = dataclasses.replace(table, aux_gen=0, aux_params=())
    n = 1_000_000
    p, r, mode = paper_stream(table, n)
    t_w = np.round(np.linspace(-20, 60, n) * 2 ** 16).astype(np.int64)
    k = np.arange(n, dtype=np.int64)
    run_words(table, p[:1000], r[:1000], mode[:1000], t=t_w[:1000], k=k[:1000])
    benchmark.pedantic(run_words, args=(table, p, r, mode), kwargs={"t": t_w, "k": k}, rounds=5, iterations=1)
    aux_s = best_of(lambda: run_words(table, p, r, mode, t=t_w, k=k), 5)
    plain_s = best_of(lambda: run_words(plain, p, r, mode), 5)
    lines = [f"numba kernel: {1e9 * plain_s / n:.2f} ns/sample without aux, {1e9 * aux_s / n:.2f} with the 6-term "
             f"aux table (+{1e9 * (aux_s - plain_s) / n:.2f} ns/sample)"]
    benchmark.extra_info.update({"ns_numba_plain": 1e9 * plain_s / n, "ns_numba_aux": 1e9 * aux_s / n})
    if GCC is not None:
        exe = build(tmp_path, "hdrg_fw_o2", CFLAGS)
        s = {"p": p, "r": r, "mode": mode, "restart": None, "z": None, "f": p, "t": t_w,
             "aux": np.zeros((n, 0), np.int64), "k": k}
        rec = input_records(table, s)
        for name, tab in (("without aux", plain), ("6-term aux", table)):
            data = f"{table_line(tab)}\nBENCH {n} 5 11\n".encode() + rec.astype("<i8").tobytes()
            import subprocess
            out = subprocess.run([str(exe)], input=data, capture_output=True).stdout.decode().split("\n")[1].split()
            lines.append(f"C twin hdrg_step_aux ({name}): {int(out[2]) / n:.2f} ns/sample")
            benchmark.extra_info[f"ns_c_{name}"] = int(out[2]) / n
    print("\n" + "\n".join(lines))
