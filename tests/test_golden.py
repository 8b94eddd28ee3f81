"""Golden model (float64): proxy, rate estimators, regressors, model file, compensation, CLI."""
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_ref.terms import K_AUX, N_TERMS, PAPER_TERMS, TERM_POWERS
from host_tools.golden import compensate as comp
from host_tools.golden import runlog as rl
from host_tools.cli import main as cli_main
from host_tools.golden.model import BiasModel, ModelConfig, ModelError
from host_tools.golden.proxy import ProxyConfig, parse_range
from host_tools.golden.rate import ESTIMATORS, RateConfig, parse_rate_range
from host_tools.golden.regressors import AuxConfig, aux_regressor, bias_horner, bias_plain, regressor_matrix
from host_tools.golden.reversal import ReversalConfig, combine

EST_PARAMS = [("diff", 8, 4), ("diffn", 1, 4), ("diffn", 5, 4), ("lsq", 2, 4), ("lsq", 7, 4),
              ("iir", 8, 0), ("iir", 8, 3), ("iir", 8, 5)]
DOC_WARMUP = {"diff": lambda n, s: 1, "diffn": lambda n, s: n, "lsq": lambda n, s: n - 1,
              "iir": lambda n, s: 1}


# -- reference implementations written from the module docs, sample by sample ---------------------

def ref_slope_per_sample(p, i, start, est, n, shift, state):
    """Slope [proxy units/sample] at i or None in warm-up; state: dict for the iir filter."""
    k = i - start
    if est == "iir":
        if k == 0:
            state["y"] = 0.0
            return None
        gear = min(shift, int(np.floor(np.log2(k))))   # a running mean at first, then 2**-shift
        state["y"] += ((p[i] - p[i - 1]) - state["y"]) * 2.0 ** -gear
        return state["y"]
    m = 1 if est == "diff" else n
    if est in ("diff", "diffn"):
        return (p[i] - p[i - m]) / m if k >= m else None
    if k < n - 1:
        return None
    return np.polyfit(np.arange(n), p[i - n + 1:i + 1], 1)[0]  # least-squares slope


def ref_rate(p, starts, est, n, shift, fs):
    out, state, start = [], {}, 0
    for i in range(len(p)):
        if i in starts:
            start = i
        out.append(ref_slope_per_sample(p, i, start, est, n, shift, state))
    return out


# -- proxy -------------------------------------------------------------------------------------------

def test_proxy_clamp_edges_and_flags():
    cfg = ProxyConfig.from_range("temp", 8.0, 12.0)
    assert (cfg.ref, cfg.span, cfg.unit, cfg.column) == (10.0, 2.0, "degC", "temp_c")
    p = np.array([8.0, 12.0, 10.0, 11.0, 12.5, 7.0, 1e9, np.nextafter(12.0, 13.0)])
    u, clamped = cfg.normalize(p)
    np.testing.assert_array_equal(u, [-1.0, 1.0, 0.0, 0.5, 1.0, -1.0, 1.0, 1.0])
    np.testing.assert_array_equal(clamped, [False, False, False, False, True, True, True, True])


def test_proxy_from_data_margin_and_errors():
    a, b = np.linspace(6227.0, 6228.0, 11), np.linspace(6226.5, 6227.2, 5)
    cfg = ProxyConfig.from_data([a, b], "freq", margin=0.1)
    u, clamped = cfg.normalize(np.concatenate([a, b]))
    assert not clamped.any()
    assert u.min() == pytest.approx(-1 / 1.2, abs=1e-9) and u.max() == pytest.approx(1 / 1.2, abs=1e-9)
    assert cfg.unit == "Hz" and cfg.column == "freq_hz"
    with pytest.raises(ValueError, match="constant"):
        ProxyConfig.from_data([np.full(5, 3.0)], "temp")
    with pytest.raises(ValueError, match="kind"):
        ProxyConfig("pressure", 0.0, 1.0)
    with pytest.raises(ValueError, match="span"):
        ProxyConfig("temp", 0.0, 0.0)
    assert parse_range("-40,85") == (-40.0, 85.0)
    for bad in ("5", "3,1", "a,b", "1,2,3"):
        with pytest.raises(ValueError, match="--proxy-range"):
            parse_range(bad)


# -- rate estimators ---------------------------------------------------------------------------------

@pytest.mark.parametrize("est,n,shift", EST_PARAMS)
def test_rate_exact_slope_on_ramp_after_warmup(est, n, shift):
    fs, slope = 2.0, -0.375  # proxy units per second
    cfg = RateConfig(est, n, shift, span=1.5, fs=fs)
    assert cfg.warmup == DOC_WARMUP[est](n, shift)
    p = 6227.125 + (slope / fs) * np.arange(80)
    v, clamped, warm = cfg.normalize(p)
    W = cfg.warmup
    np.testing.assert_array_equal(warm, np.arange(80) < W)
    np.testing.assert_array_equal(v[:W], 0.0)
    np.testing.assert_allclose(v[W:], slope / 1.5, rtol=0, atol=1e-9)
    assert not clamped.any()
    dpdt, warm2 = cfg.slope(p)
    np.testing.assert_allclose(dpdt[W:], slope, rtol=0, atol=1e-9)


@pytest.mark.parametrize("est,n,shift", EST_PARAMS)
def test_rate_matches_reference_with_segment_restarts(est, n, shift):
    rng = np.random.default_rng(1)
    p = 20.0 + np.cumsum(rng.normal(0, 0.1, 90))
    starts = [0, 30, 33, 70]
    fs = 4.0
    cfg = RateConfig(est, n, shift, span=1e6, fs=fs)
    v, _, warm = cfg.normalize(p, starts)
    ref = ref_rate(p, set(starts), est, n, shift, fs)
    for i, r in enumerate(ref):
        if r is None:
            assert warm[i] and v[i] == 0.0, i
        else:
            assert not warm[i]
            assert v[i] == pytest.approx(r * fs / 1e6, rel=1e-9, abs=1e-15), i
    # the warm-up restarts at every segment start (power-on semantics)
    for s in starts:
        seg_end = min([t for t in starts if t > s] + [len(p)])
        np.testing.assert_array_equal(warm[s:seg_end], np.arange(seg_end - s) < cfg.warmup)


def test_rate_restart_ignores_samples_before_gap():
    cfg = RateConfig("lsq", 4, 0, span=1.0, fs=1.0)
    p = np.concatenate([np.zeros(10), 100.0 + 0.5 * np.arange(10)])
    v, _, warm = cfg.normalize(p, [0, 10])
    np.testing.assert_allclose(v[13:], 0.5, atol=1e-12)
    assert warm[10:13].all() and not warm[13:].any()
    v_no_restart, clamped, _ = cfg.normalize(p)
    assert clamped[10:13].all()  # without the restart the jump would be differenced


@settings(max_examples=40, deadline=None)
@given(data=st.data(), est=st.sampled_from(ESTIMATORS), n=st.integers(2, 9), shift=st.integers(0, 6))
def test_rate_is_causal(data, est, n, shift):
    size = data.draw(st.integers(2, 60))
    fin = st.floats(-1e3, 1e3, allow_nan=False)
    p = np.array(data.draw(st.lists(fin, min_size=size, max_size=size)))
    starts = sorted(set(data.draw(st.lists(st.integers(0, size - 1), max_size=4))))
    cut = data.draw(st.integers(1, size - 1))
    q = p.copy()
    q[cut:] = np.array(data.draw(st.lists(fin, min_size=size - cut, max_size=size - cut)))
    cfg = RateConfig(est, n, shift, span=7.0, fs=3.0)
    a, b = cfg.normalize(p, starts), cfg.normalize(q, starts)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x[:cut], y[:cut])
    # restarts after the cut do not change the past either
    c = cfg.normalize(p, sorted(set(starts) | {cut}))
    for x, y in zip(a, c):
        np.testing.assert_array_equal(x[:cut], y[:cut])


def test_rate_clamp_edges_and_flags():
    cfg = RateConfig("diff", span=0.5, fs=1.0)
    d = np.array([0.5, -0.5, 0.25, 0.75, -0.625, 0.0])  # consecutive differences
    p = np.concatenate([[0.0], np.cumsum(d)])
    v, clamped, warm = cfg.normalize(p)
    np.testing.assert_array_equal(v, [0.0, 1.0, -1.0, 0.5, 1.0, -1.0, 0.0])
    np.testing.assert_array_equal(clamped, [False, False, False, False, True, True, False])
    np.testing.assert_array_equal(warm, [True] + [False] * 6)


def test_rate_config_validation_and_from_data():
    for kwargs in ({"estimator": "spline"}, {"estimator": "lsq", "n": 1}, {"estimator": "diffn", "n": 0},
                   {"shift": 25}, {"span": 0.0}, {"fs": -1.0}, {"n": 2.5}):
        with pytest.raises(ValueError):
            RateConfig(**kwargs)
    assert RateConfig("lsq", 5).divisor == 20 and RateConfig("diffn", 6).divisor == 6
    fs = 2.0
    p = np.concatenate([np.zeros(5), 0.01 * np.arange(100)])  # max |dp/dt| = 0.02/s
    cfg = RateConfig.from_data([p], fs, "diff", percentile=100, margin=0.25)
    assert cfg.span == pytest.approx(0.02 * 1.25)
    v, clamped, _ = cfg.normalize(p)
    assert not clamped.any() and v.max() == pytest.approx(0.8)
    with pytest.raises(ValueError, match="--rate-range"):
        RateConfig.from_data([np.ones(50)], fs)
    assert RateConfig.from_dict(cfg.to_dict()) == cfg
    assert parse_rate_range("0.05") == 0.05
    for bad in ("0", "-1", "x", "1,2"):
        with pytest.raises(ValueError, match="--rate-range"):
            parse_rate_range(bad)


# -- regressors --------------------------------------------------------------------------------------

unit = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(coef=st.lists(st.floats(-1e4, 1e4, allow_nan=False), min_size=N_TERMS, max_size=N_TERMS),
       uvz=st.lists(st.tuples(unit, unit, unit), min_size=1, max_size=20))
def test_horner_equals_plain_sum(coef, uvz):
    u, v, z = (np.array(c) for c in zip(*uvz))
    h, s = bias_horner(coef, u, v, z), bias_plain(coef, u, v, z)
    np.testing.assert_allclose(h, s, rtol=0, atol=1e-12 * (1 + np.abs(coef).sum()))


def test_regressor_matrix_terms():
    u, v, z = np.array([0.5, -0.25]), np.array([-0.75, 0.125]), np.array([0.3, -0.9])
    X = regressor_matrix(u, v, z)
    assert X.shape == (2, N_TERMS)
    for k, pw in enumerate(TERM_POWERS):
        expected = z if pw is None else u ** pw[0] * v ** pw[1]
        np.testing.assert_allclose(X[:, k], expected, rtol=1e-15)
    coef = np.zeros(N_TERMS)
    coef[K_AUX] = 2.0
    np.testing.assert_array_equal(bias_horner(coef, u, v, z), 2.0 * z)
    np.testing.assert_array_equal(bias_horner(coef, u, v), 0.0)
    with pytest.raises(ValueError, match="17"):
        bias_horner(np.zeros(16), u, v)


def test_aux_none_gives_zeros():
    log = rl.RunLog.from_arrays(t_s=np.arange(5.0), rate_dph=np.ones(5), temp_c=np.ones(5))
    np.testing.assert_array_equal(aux_regressor(log, AuxConfig()), np.zeros(5))
    with pytest.raises(ValueError, match="generator"):
        AuxConfig("decay")


# -- model file --------------------------------------------------------------------------------------

def make_model(terms=PAPER_TERMS, seed=0, reversal=None, fs=1.0, proxy=None, rate_span=0.05):
    rng = np.random.default_rng(seed)
    coef = np.zeros(N_TERMS)
    coef[list(terms)] = rng.normal(0, 10, len(terms))
    proxy = proxy or ProxyConfig.from_range("temp", -30.0, 70.0)
    cfg = ModelConfig(proxy, RateConfig("diff", span=rate_span, fs=fs), reversal, AuxConfig())
    coef2 = None
    if reversal is not None and reversal.order == "regress_first":
        coef2 = np.zeros(N_TERMS)
        coef2[list(terms)] = rng.normal(0, 10, len(terms))
    return BiasModel(cfg, terms, coef, {"rms": 0.123, "stderr": np.full(N_TERMS, np.nan), "n": np.int64(5)},
                     coef_mode2=coef2)


def test_model_json_round_trip(tmp_path):
    for order in ("regress_first", "combine_first"):
        model = make_model(reversal=ReversalConfig("trend", 240.0, 5.0, order=order))
        path = tmp_path / "m.json"
        model.to_json(path)
        back = BiasModel.from_json(path)
        assert back.config == model.config and back.terms == model.terms
        assert back.config.reversal.order == order and len(back.banks) == (2 if order == "regress_first" else 1)
        np.testing.assert_array_equal(back.banks, model.banks)  # bit for bit
        assert back.fit["rms"] == 0.123 and back.fit["n"] == 5 and back.fit["stderr"] == [None] * N_TERMS
        d = json.loads(path.read_text())
        assert (d["format"], d["version"]) == ("hdrg-model", 2)
        assert ("coef_mode2_dph" in d) == (order == "regress_first")
    ftr = make_model(terms=(0, 1, 4))
    ftr.to_json(path)
    assert BiasModel.from_json(path).config.reversal is None


def _write(tmp_path, d, name="bad.json"):
    path = tmp_path / name
    path.write_text(d if isinstance(d, str) else json.dumps(d))
    return path


@pytest.mark.parametrize("change,field", [
    (lambda d: d.update(version=3), "version"),
    (lambda d: d.pop("version"), "version"),
    (lambda d: d.update(format="something"), "format"),
    (lambda d: d["config"]["proxy"].pop("span"), "config.proxy.span"),
    (lambda d: d["config"]["proxy"].update(kind="pressure"), "config.proxy"),
    (lambda d: d["config"]["rate"].update(estimator="spline"), "config.rate"),
    (lambda d: d["config"]["rate"].update(warmup=99), "config.rate"),
    (lambda d: d["config"].pop("rate"), "config.rate"),
    (lambda d: d.update(coef_dph=[0.0] * 16), "coef_dph"),
    (lambda d: d.update(coef_dph=["1"] * 17), "coef_dph"),
    (lambda d: d.update(terms=[0, 17]), "terms"),
    (lambda d: d.update(terms=[0]), "coef_dph"),  # enabled terms lost: non-zero disabled coefficients
])
def test_model_bad_json_names_file_and_field(tmp_path, change, field):
    d = make_model().to_dict()
    change(d)
    path = _write(tmp_path, d)
    with pytest.raises(ModelError) as exc:
        BiasModel.from_json(path)
    msg = str(exc.value)
    assert str(path) in msg and f"'{field}'" in msg, msg
    if field == "version" and "version" in d:
        assert "unsupported" in msg and "3" in msg


def test_model_not_json(tmp_path):
    for text in ("{not json", "[1, 2]"):
        path = _write(tmp_path, text)
        with pytest.raises(ModelError, match=str(path)):
            BiasModel.from_json(path)


# -- compensation ------------------------------------------------------------------------------------

def ftr_log(n=400, fs=1.0, gap_at=None):
    """FTR log with a temperature cycle; returns (log, temp)."""
    t = np.arange(n) / fs
    if gap_at is not None:
        t[gap_at:] += 50.0 / fs
    temp = 20.0 + 25.0 * np.sin(2 * np.pi * t / 300.0) + 0.01 * np.cos(t)
    meta = {"sample_rate_hz": str(fs)}
    return rl.RunLog.from_arrays(metadata=meta, t_s=t, rate_dph=np.zeros(n), temp_c=temp), temp


def explicit_bias(coef, u, v):
    return sum(coef[k] * u ** pw[0] * v ** pw[1] for k, pw in enumerate(TERM_POWERS) if pw is not None)


def test_compensate_removes_known_polynomial_ftr():
    log0, temp = ftr_log(n=600, fs=2.0, gap_at=350)
    model = make_model(fs=2.0, rate_span=1.0)
    # u, v written out from the docs: u = (p - ref)/span, v = (p[i] - p[i-1]) * fs / span_rate
    u = (temp - 20.0) / 50.0
    v = np.zeros_like(temp)
    v[1:] = (temp[1:] - temp[:-1]) * 2.0 / 1.0
    v[[0, 350]] = 0.0  # warm-up at power-on and after the gap
    assert np.abs(u).max() < 1 and np.abs(v).max() < 1
    true_rate = 15.0 + 0.01 * np.sin(np.arange(600.0))
    log = log0.with_columns(rate_dph=true_rate + explicit_bias(model.coef, u, v))
    assert list(log.segments) == [0, 350]
    prep = comp.prepare(log, model.config)
    np.testing.assert_allclose(prep.u, u, atol=1e-14)
    np.testing.assert_allclose(prep.v, v, atol=1e-12)
    np.testing.assert_array_equal(prep.valid, ~np.isin(np.arange(600), [0, 350]))
    np.testing.assert_array_equal(prep.flags, np.where(prep.valid, 0, comp.FLAG_WARMUP))
    out = comp.compensate(log, model)
    ok = out["valid"] == 1.0
    assert ok.sum() == 598
    np.testing.assert_allclose(out.rate_dph[ok], true_rate[ok], atol=1e-12 * np.abs(model.coef).sum())
    # invalid samples carry no number (NaN), in both columns
    assert np.isnan(out.rate_dph[[0, 350]]).all() and np.isnan(out["bias_dph"][[0, 350]]).all()
    assert np.isfinite(out.rate_dph[ok]).all() and out["valid"].dtype == np.int64
    assert out.metadata["compensated"] == "yes" and out.metadata["compensation_impl"] == "float"
    with pytest.raises(ValueError, match="already compensated"):
        comp.compensate(out, model)


def test_compensated_log_round_trip(tmp_path):
    log, _ = ftr_log(n=50)
    model = make_model()
    out = comp.compensate(log, model)
    for name in ("out.csv", "out.npz"):
        rl.write(out, tmp_path / name)
        back = rl.read(tmp_path / name)
        assert list(back.columns) == list(out.columns)
        for col in ("valid", "bias_dph", "rate_dph", "temp_c"):
            np.testing.assert_array_equal(back[col], out[col])
        assert back.metadata["compensated"] == "yes"


def test_prepare_flags_clamps_and_refusals():
    log, temp = ftr_log(n=100)
    narrow = ModelConfig(ProxyConfig.from_range("temp", 0.0, 30.0), RateConfig("diffn", 3, span=0.1, fs=1.0))
    prep = comp.prepare(log, narrow)
    np.testing.assert_array_equal(prep.flags & comp.FLAG_PROXY_CLAMPED > 0, temp > 30.0)
    assert (prep.flags & comp.FLAG_RATE_CLAMPED).any()
    np.testing.assert_array_equal(prep.flags[:3] & comp.FLAG_WARMUP, comp.FLAG_WARMUP)
    assert prep.valid[3:].all() and not prep.valid[:3].any()  # clamping only flags
    assert prep.flag_counts()["warmup"] == 3
    with pytest.raises(ValueError, match="sample rate"):
        comp.prepare(log, make_model(fs=2.0))
    mr = log.with_columns(mode=np.full(100, 1))
    with pytest.raises(ValueError, match="mode reversal"):
        comp.prepare(mr, narrow)
    with pytest.raises(ValueError, match="FTR"):
        comp.prepare(log, make_model(reversal=ReversalConfig()))
    with pytest.raises(ValueError, match="--impl"):
        comp.compensate(log, make_model(), impl="double")


def mr_log(fs=1.0, cycles=4):
    """Mode-reversal log in the paper's timing: 30 s exchange, 120 s mode 1, 30 s, 120 s mode 2."""
    mode = np.concatenate([np.r_[np.full(30, 3), np.full(120, 1), np.full(30, 3), np.full(120, 2)]] * cycles)
    n = len(mode)
    t = np.arange(n) / fs
    temp = 10.0 + 0.05 * t
    rate = np.where(mode == 2, -1.0, 1.0) * (3.0 + 0.1 * temp) + 2.0  # flipping terms + damping term
    return rl.RunLog.from_arrays(metadata={"sample_rate_hz": "1"}, t_s=t, rate_dph=rate, mode=mode,
                                 temp_c=temp)


def test_prepare_mode_reversal():
    log = mr_log()
    model = make_model(reversal=ReversalConfig("pair", order="combine_first"), rate_span=0.2)
    prep = comp.prepare(log, model)
    c = combine(log, combiner="pair", max_stale_s=300.0, settle_s=0.0, fs_hz=1.0)
    np.testing.assert_array_equal(prep.y, c.out_dph)
    np.testing.assert_array_equal(prep.valid, c.valid & (log.mode != 3) & (np.arange(len(log)) >= 1))
    exch = log.mode == 3
    np.testing.assert_array_equal(prep.flags & comp.FLAG_EXCHANGE > 0, exch)
    np.testing.assert_array_equal(prep.flags & comp.FLAG_STALE > 0, ~c.valid & ~exch)
    assert not prep.valid[exch].any() and prep.valid.any()
    out = comp.compensate(log, model)
    B = model.evaluate(prep.u, prep.v, prep.z)
    np.testing.assert_allclose(out.rate_dph[prep.valid], (prep.y - B)[prep.valid], rtol=0, atol=1e-12)


def test_fit_config_from_logs():
    logs = [ftr_log(n=300)[0], ftr_log(n=200)[0]]
    cfg = comp.fit_config_from_logs(logs, rate_estimator="lsq", n=5)
    assert cfg.proxy.kind == "temp" and cfg.reversal is None and cfg.rate.estimator == "lsq"
    assert cfg.rate.fs == 1.0 and cfg.aux == AuxConfig()
    for log in logs:
        prep = comp.prepare(log, cfg)
        assert not (prep.flags & comp.FLAG_PROXY_CLAMPED).any()
        assert np.abs(prep.u).max() <= 1 / 1.2 + 1e-12
    explicit = comp.fit_config_from_logs(logs, proxy_range="-40,85", rate_range="0.5")
    assert (explicit.proxy.lo, explicit.proxy.hi, explicit.rate.span) == (-40.0, 85.0, 0.5)
    mr = comp.fit_config_from_logs([mr_log()], reversal={"combiner": "trend"})
    assert mr.reversal.combiner == "trend"
    assert comp.fit_config_from_logs([mr_log()]).reversal == ReversalConfig(comp.DEFAULT_COMBINER, settle_s=comp.DEFAULT_SETTLE_S, order=comp.DEFAULT_ORDER)
    assert comp.fit_config_from_logs([mr_log()], reversal={"combiner": "trend"}).reversal.order == comp.DEFAULT_ORDER
    legacy = comp.fit_config_from_logs([mr_log()], reversal=ReversalConfig("trend"))
    assert legacy.reversal == ReversalConfig("trend", order="combine_first")
    with pytest.raises(ValueError, match="mix"):
        comp.fit_config_from_logs([logs[0], mr_log()])
    with pytest.raises(ValueError, match="FTR"):
        comp.fit_config_from_logs(logs, reversal=ReversalConfig())
    with pytest.raises(rl.RunLogError, match="freq_hz"):
        comp.fit_config_from_logs(logs, proxy_kind="freq")


# -- CLI ---------------------------------------------------------------------------------------------

def test_cli_compensate(tmp_path, capsys):
    log, _ = ftr_log(n=80)
    rl.write(log, tmp_path / "run.csv")
    model = make_model()
    model.to_json(tmp_path / "model.json")
    out = tmp_path / "out.csv"
    assert cli_main(["compensate", str(tmp_path / "run.csv"), "--model", str(tmp_path / "model.json"),
                     "-o", str(out)]) == 0
    back = rl.read(out)
    assert back.metadata["compensated"] == "yes" and back["valid"].sum() == 79
    np.testing.assert_allclose(back["bias_dph"][1:], -back.rate_dph[1:], atol=1e-9)  # raw rate 0
    assert cli_main(["compensate", str(tmp_path / "run.csv"), "--model", str(tmp_path / "model.json"),
                     "-o", str(out), "--impl", "fixed"]) == 0
    fixed = rl.read(out)
    np.testing.assert_array_equal(fixed["valid"], back["valid"])
    np.testing.assert_allclose(fixed["bias_dph"], back["bias_dph"], atol=2e-3)  # |fixed - golden| bound
    capsys.readouterr()
    bad = _write(tmp_path, {"format": "hdrg-model", "version": 9})
    assert cli_main(["compensate", str(tmp_path / "run.csv"), "--model", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "version" in err


@pytest.mark.benchmark
@pytest.mark.parametrize("est", ESTIMATORS)
def test_benchmark_compensate_1e6(benchmark, est):
    """compensate() on a 10^6-sample FTR log (speed only; run with `pytest -m benchmark`)."""
    log, _ = ftr_log(n=1_000_000)
    model = make_model()
    model = BiasModel(ModelConfig(model.config.proxy, RateConfig(est, 16, 4, 0.05, 1.0)), model.terms, model.coef)
    out = benchmark(comp.compensate, log, model)
    assert len(out) == len(log)


def test_input_invalid_sample_golden():
    """An input-invalid sample (host_tools.golden.input_check): the sample and the rate estimator's
    re-warm after it are not valid (flags 64, 4); the proxy after it never enters the estimate."""
    n = 60
    t = np.arange(n, dtype=float)
    freq = 6227.0 + 1e-3 * t
    freq[20] = 20000.0                              # outside the declared plausible range
    log = rl.RunLog.from_arrays({"sample_rate_hz": "1", "freq_range_hz": "6000..6500"}, t_s=t, freq_hz=freq,
                                rate_dph=np.ones(n), mode=np.zeros(n, np.int64))
    cfg = ModelConfig(ProxyConfig("freq", 6226.9, 6227.2), RateConfig("diffn", 3, 4, 0.01, 1.0), None, AuxConfig())
    pr = comp.prepare(log, cfg)
    assert np.flatnonzero(~pr.valid).tolist() == [0, 1, 2, 20, 21, 22, 23]    # warm-up 3 after the restarts 20, 21
    assert pr.flags[20] & 64 and not (pr.flags[21:] & 64).any() and (pr.flags[21:24] & 4).all()
    np.testing.assert_allclose(pr.v[pr.valid], 1e-3 / 0.01)                  # the glitch is in no slope
    assert np.array_equal(combine(log, bad=~pr.valid).valid, pr.valid)
