"""The k7 generators of host_tools.golden.regressors (AuxConfig 'sum'): each recursion against an
independent closed form, causality, segment resets, validation and the model-file round trip."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from firmware_ref.terms import PAPER_TERMS
from host_tools.golden import runlog as rl
from host_tools.golden.model import BiasModel, ModelConfig
from host_tools.golden.proxy import ProxyConfig
from host_tools.golden.rate import RateConfig
from host_tools.golden.regressors import AuxConfig, aux_regressor, generator_values, normalize_term

FS = 2.0


def make_log(n=400, fs=FS, gap_at=None, mode=None, seed=0):
    """A log at fs with columns x (aux_x), temp_c, freq_hz; a 100-s gap before row gap_at."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    if gap_at is not None:
        t[gap_at:] += 100.0
    cols = dict(t_s=t, rate_dph=rng.normal(size=n), temp_c=20 + np.cumsum(rng.normal(0, 0.05, n)),
                freq_hz=6000 + np.cumsum(rng.normal(0, 0.01, n)), aux_x=rng.normal(0, 2, n))
    if mode is not None:
        cols["mode"] = mode
    return rl.RunLog.from_arrays(**cols)


def mr_modes(n, exchange=6, dwell=20):
    m = []
    while len(m) < n:
        m += [3] * exchange + [1] * dwell + [3] * exchange + [2] * dwell
    return np.array(m[:n])


def term(gen, **kw):
    return {"gen": gen, "weight": 1.0, **kw}


# -- each generator against a closed form ---------------------------------------------------------

def test_decay_on_is_exp_of_time_and_restarts_at_segments():
    log = make_log(300)
    g = generator_values(log, term("decay_on", tau_s=40.0), FS)
    np.testing.assert_allclose(g, np.exp(-log.t_s / 40.0), rtol=1e-12)
    gap = make_log(300, gap_at=120)
    g = generator_values(gap, term("decay_on", tau_s=40.0), FS)
    assert list(gap.segments) == [0, 120]
    np.testing.assert_allclose(g[120:], np.exp(-np.arange(180) / FS / 40.0), rtol=1e-12)
    np.testing.assert_allclose(g[:120], np.exp(-np.arange(120) / FS / 40.0), rtol=1e-12)


@pytest.mark.parametrize("power", [1, 2, 4, 5])
def test_input_filter_is_lfilter_per_segment_after_the_clamp(power):
    log = make_log(400, gap_at=250)
    ref, span, tau = 0.5, 3.0, 7.5
    g = generator_values(log, term("input", column="aux_x", ref=ref, span=span, tau_s=tau, power=power), FS)
    q = np.clip((log["aux_x"] - ref) / span, -1, 1)
    assert np.any(np.abs((log["aux_x"] - ref) / span) > 1)          # the clamp is exercised
    a = math.exp(-1 / (FS * tau))
    want = np.empty_like(q)
    for s, e in ((0, 250), (250, 400)):
        want[s:e] = lfilter([1 - a], [1, -a], q[s:e], zi=[a * q[s]])[0]
    np.testing.assert_allclose(g, want ** power, rtol=1e-12, atol=1e-15)
    # tau 0: the normalized column itself
    g0 = generator_values(log, term("input", column="aux_x", ref=ref, span=span, power=power), FS)
    np.testing.assert_allclose(g0, q ** power, rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(g) <= 1)


def test_decay_exchange_closed_form():
    n = 200
    mode = mr_modes(n)
    log = make_log(n, mode=mode)
    tau = 3.0
    g = generator_values(log, term("decay_exchange", tau_s=tau), FS)
    want = np.zeros(n)                 # 0 in mode 3 and before the first exchange ends
    end = None                         # first sample after the last exchange
    for i in range(n):
        if mode[i] == 3:
            continue
        if i > 0 and mode[i - 1] == 3:
            end = i
        if end is not None:
            want[i] = math.exp(-(i - end) / (FS * tau))
    np.testing.assert_allclose(g, want, rtol=1e-12, atol=0)
    assert np.all(g[mode == 3] == 0) and g[np.flatnonzero(mode != 3)[0]] == 1.0
    # before the first exchange (a log that starts in mode 1): 0
    log1 = make_log(60, mode=np.array([1] * 10 + list(mr_modes(50))))
    assert np.all(generator_values(log1, term("decay_exchange", tau_s=tau), FS)[:10] == 0)


def test_ramp_counts_time_since_power_on_and_clamps():
    log = make_log(300, gap_at=100)
    N = 400
    g = generator_values(log, term("ramp", n_samples=N), FS)
    np.testing.assert_allclose(g, np.minimum(np.rint(log.t_s * FS) / N, 1.0), rtol=1e-15)
    assert g[-1] == 1.0 and g[99] < g[100] - 0.4      # the gap of 100 s advances it by 200 samples


@pytest.mark.parametrize("part", ["sin", "cos"])
def test_oscillator_is_sin_cos_of_time_including_gaps(part):
    log = make_log(3000, gap_at=1000)
    P = 37.3
    g = generator_values(log, term("osc", period_s=P, part=part), FS)
    k = np.rint(log.t_s * FS)
    want = (np.sin if part == "sin" else np.cos)(2 * np.pi * k / (P * FS))
    np.testing.assert_allclose(g, want, atol=1e-11)


def test_sign_multiplies_by_the_mode_sign():
    mode = mr_modes(100)
    log = make_log(100, mode=mode)
    s = np.where(mode == 2, -1.0, np.where(mode == 3, 0.0, 1.0))
    np.testing.assert_array_equal(generator_values(log, term("one", sign=True), FS), s)
    u = generator_values(log, term("input", column="temp_c", ref=20, span=5), FS)
    signed = generator_values(log, term("input", column="temp_c", ref=20, span=5, sign=True), FS)
    np.testing.assert_array_equal(signed, s * u)


def test_rate_generator_is_the_rate_estimator():
    log = make_log(300, gap_at=150)
    rc = RateConfig("lsq", 8, 4, 0.02, FS)
    g = generator_values(log, term("rate", column="freq_hz", estimator="lsq", n=8, span=0.02), FS)
    np.testing.assert_array_equal(g, rc.normalize(log["freq_hz"], log.segments)[0])


# -- causality -----------------------------------------------------------------------------------

TERMS = [term("input", column="aux_x", ref=0.0, span=2.0, tau_s=5.0, power=3),
         term("input", column="temp_c", ref=20.0, span=1.0, sign=True),
         term("decay_on", tau_s=4.0), term("decay_exchange", tau_s=2.0, sign=True),
         term("rate", column="freq_hz", estimator="iir", shift=2, span=0.05),
         term("ramp", n_samples=50), term("osc", period_s=9.0, part="cos")]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, len(TERMS) - 1), st.integers(5, 55), st.integers(0, 10 ** 6))
def test_changing_the_future_never_changes_the_past(which, cut, seed):
    """Every logged value from row ``cut`` on (columns and mode) is changed; the time stamps are
    kept (the reader's gap detection uses the median step of the whole log)."""
    rng = np.random.default_rng(seed)
    n = 60
    mode = mr_modes(n)
    a = make_log(n, mode=mode, seed=seed)
    cols = {k: np.array(v) for k, v in a.columns.items()}
    for name in ("aux_x", "temp_c", "freq_hz", "rate_dph"):
        cols[name][cut:] = cols[name][cut:] + rng.normal(0, 5, n - cut)
    cols["mode"][cut:] = rng.choice([1, 2, 3], n - cut)
    b = rl.RunLog(cols)
    ga = generator_values(a, TERMS[which], FS)
    gb = generator_values(b, TERMS[which], FS)
    np.testing.assert_array_equal(ga[:cut], gb[:cut])


# -- AuxConfig ------------------------------------------------------------------------------------

def sum_config():
    return AuxConfig("sum", {"fs": FS, "terms": [
        {"gen": "decay_on", "weight": -0.5, "tau_s": 30.0, "effect": "turn_on"},
        {"gen": "input", "weight": 0.25, "column": "aux_x", "ref": 0.0, "span": 4.0, "tau_s": 10.0},
        {"gen": "osc", "weight": 0.25, "period_s": 20.0, "part": "sin", "sign": True}]})


def test_sum_is_the_weighted_sum_of_the_terms_and_bounded():
    mode = mr_modes(500)
    log = make_log(500, mode=mode)
    cfg = sum_config()
    z = aux_regressor(log, cfg)
    want = sum(t["weight"] * generator_values(log, t, FS) for t in cfg.terms)
    np.testing.assert_allclose(z, want, rtol=0, atol=1e-15)
    assert np.all(np.abs(z) <= 1)


def test_aux_config_round_trips_through_the_model_file(tmp_path):
    cfg = ModelConfig(ProxyConfig.from_range("temp", 10.0, 30.0), RateConfig("diff", span=0.1, fs=FS), None,
                      sum_config())
    coef = np.zeros(17)
    coef[[0, 1, 7]] = (1.0, 2.0, 3.0)
    model = BiasModel(cfg, tuple(PAPER_TERMS) + (7,), coef)
    model.to_json(tmp_path / "m.json")
    back = BiasModel.from_json(tmp_path / "m.json")
    assert back.config.aux == cfg.aux and back.config.aux.to_dict() == cfg.aux.to_dict()
    log = make_log(200, mode=mr_modes(200))
    np.testing.assert_array_equal(aux_regressor(log, back.config.aux), aux_regressor(log, cfg.aux))
    assert AuxConfig.from_dict(AuxConfig().to_dict()) == AuxConfig()


@pytest.mark.parametrize("params, message", [
    ({"terms": [term("one")]}, "fs"),
    ({"fs": 1.0, "terms": []}, "non-empty"),
    ({"fs": 1.0, "terms": [term("decay")]}, "gen"),
    ({"fs": 1.0, "terms": [term("decay_on")]}, "tau_s"),
    ({"fs": 1.0, "terms": [term("decay_on", tau_s=-1.0)]}, "> 0"),
    ({"fs": 1.0, "terms": [term("input", column="temp_c", ref=0, span=1, power=6)]}, "power"),
    ({"fs": 1.0, "terms": [term("input", column="temp_c", ref=0, span=0)]}, "span"),
    ({"fs": 1.0, "terms": [term("one", tau_s=3.0)]}, "unknown"),
    ({"fs": 1.0, "terms": [term("osc", period_s=3.0, part="tan")]}, "part"),
    ({"fs": 1.0, "terms": [term("one"), term("one")]}, "sum |w| <= 1"),
    ({"fs": 1.0, "terms": [{"gen": "one"}]}, "weight"),
    ({"fs": 1.0, "terms": [term("rate", column="freq_hz", estimator="lsq", n=1, span=1.0)]}, "n must be >= 2"),
])
def test_bad_aux_params_are_refused_with_the_field(params, message):
    with pytest.raises(ValueError, match=message):
        AuxConfig("sum", params)


def test_missing_column_is_named():
    log = make_log(20)
    with pytest.raises(ValueError, match="aux_vdd"):
        generator_values(log, term("input", column="aux_vdd", ref=0, span=1), FS)


def test_normalize_term_fills_defaults():
    t = normalize_term({"gen": "input", "weight": 0.5, "column": "temp_c", "ref": 1, "span": 2})
    assert t == {"gen": "input", "weight": 0.5, "sign": False, "column": "temp_c", "ref": 1.0, "span": 2.0,
                 "tau_s": 0.0, "power": 1}
