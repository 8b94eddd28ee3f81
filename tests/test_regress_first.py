"""Regress, then reverse: two coefficient banks by mode, the combiner on the residual.
Synthetic logs where the truth is known exactly."""
import json

import numpy as np
import pytest

from host_tools.golden import compensate as comp
from host_tools.golden import runlog as rl
from host_tools.fitting.fit import fit_logs
from host_tools.golden.model import BiasModel, ModelError
from host_tools.golden.reversal import ReversalConfig, combine, combine_values

PERIOD = (30, 120, 30, 120)  # exchange, mode 1, exchange, mode 2 [samples at 1 Hz]


def mr_modes(n_periods, timing=PERIOD):
    e1, d1, e2, d2 = timing
    return np.concatenate([np.r_[np.full(e1, 3), np.full(d1, 1), np.full(e2, 3), np.full(d2, 2)]] * n_periods)


def mr_log(n_periods=30, gap_at=None, rate=None):
    """1 Hz MR log, temperature cycles (so u and v both vary); raw rate 0 unless given."""
    mode = mr_modes(n_periods)
    n = len(mode)
    t = np.arange(n, dtype=float)
    if gap_at is not None:
        t[gap_at:] += 500.0
    temp = 20.0 + 15.0 * np.sin(2 * np.pi * t / 3000.0) + 3.0 * np.sin(2 * np.pi * t / 1100.0)
    return rl.RunLog.from_arrays(metadata={"sample_rate_hz": "1"}, t_s=t, mode=mode,
                                 rate_dph=np.zeros(n) if rate is None else rate, temp_c=temp)


def config(log, combiner="none", order="regress_first", rate_estimator=None, **kw):
    return comp.fit_config_from_logs([log], rate_estimator=rate_estimator,
                                     reversal={"combiner": combiner, "order": order, **kw})


def with_bias(log, cfg, common, damping, omega=0.0):
    """The log with raw rate = s*(omega + common(u, v)) + damping(u, v) (run-log sign convention),
    i.e. c = omega + common + s*damping; exchange samples hold garbage."""
    pr = comp.prepare(log, cfg)
    s = np.where(log.mode == 2, -1.0, 1.0)
    rate = s * (omega + common(pr.u, pr.v)) + damping(pr.u, pr.v)
    rate[log.mode == 3] = 1e6
    return log.with_columns(rate_dph=rate)


def common(u, v):
    return 3.0 + 20.0 * u - 4.0 * u ** 2 + 6.0 * v


def damping(u, v):
    return 40.0 - 7.0 * u + 2.5 * u * v


def test_two_banks_recovered_exactly():
    log = mr_log()
    cfg = config(log)
    log = with_bias(log, cfg, common, damping, omega=1.25)
    model, res = fit_logs([log], cfg, (0, 1, 2, 4, 8))
    # bank 1 = omega + common + damping, bank 2 = omega + common - damping
    b1 = np.zeros(17)
    b2 = np.zeros(17)
    b1[[0, 1, 2, 4, 8]] = [1.25 + 3.0 + 40.0, 20.0 - 7.0, -4.0, 6.0, 2.5]
    b2[[0, 1, 2, 4, 8]] = [1.25 + 3.0 - 40.0, 20.0 + 7.0, -4.0, 6.0, -2.5]
    np.testing.assert_allclose(model.coef, b1, atol=1e-8)
    np.testing.assert_allclose(model.coef_mode2, b2, atol=1e-8)
    assert model.banks.shape == (2, 17) and res.rms < 1e-8
    # compensated with 'none': the residual, 0 wherever valid; bias column = the bank of the mode
    out = comp.compensate(log, model)
    valid = out["valid"] == 1
    assert valid.sum() > 0.7 * len(log) and not valid[log.mode == 3].any()
    np.testing.assert_allclose(out.rate_dph[valid], 0.0, atol=1e-7)
    pr = comp.prepare(log, model)
    expect_b = np.where(log.mode == 2, 1.25 + common(pr.u, pr.v) - damping(pr.u, pr.v),
                        1.25 + common(pr.u, pr.v) + damping(pr.u, pr.v))
    np.testing.assert_allclose(out["bias_dph"][valid], expect_b[valid], atol=1e-7)


def test_joint_fit_equals_sign_interacted_least_squares():
    """Bank by mode == the joint least-squares fit of [x_k, s*x_k] (common + s*damping)."""
    rng = np.random.default_rng(3)
    log = mr_log(n_periods=12)
    cfg = config(log)
    log = with_bias(log, cfg, common, damping)
    log = log.with_columns(rate_dph=log.rate_dph + rng.normal(0, 2.0, len(log)))
    terms = (0, 1, 4)
    model, _ = fit_logs([log], cfg, terms)
    pr = comp.prepare(log, cfg)
    s = np.where(pr.mode == 2, -1.0, 1.0)
    X = np.column_stack([pr.u ** 0, pr.u, pr.v])
    A = np.column_stack([X, s[:, None] * X])[pr.used]
    sol = np.linalg.lstsq(A, pr.y[pr.used], rcond=None)[0]
    common_c, damp_c = sol[:3], sol[3:]
    np.testing.assert_allclose(model.coef[list(terms)], common_c + damp_c, atol=1e-9)
    np.testing.assert_allclose(model.coef_mode2[list(terms)], common_c - damp_c, atol=1e-9)


def test_pair_on_residual_cancels_a_power_on_damping_change():
    log = mr_log()
    cfg = config(log, combiner="pair")
    train = with_bias(log, cfg, common, damping)
    model, _ = fit_logs([train], cfg, (0, 1, 2, 4, 8))
    # held-out power-on: damping term x1.05 + 2 deg/h, not a function of (u, v) the model knows
    test = with_bias(log, cfg, common, lambda u, v: 1.05 * damping(u, v) + 2.0)
    outs = {}
    for combiner in ("none", "pair", "trend"):
        m = BiasModel(model.config.__class__(model.config.proxy, model.config.rate,
                                             ReversalConfig(combiner, order="regress_first"), model.config.aux),
                      model.terms, model.coef, coef_mode2=model.coef_mode2)
        out = comp.compensate(test, m)
        outs[combiner] = out.rate_dph[out["valid"] == 1]
    # regression alone leaves s * (0.05 * damping + 2): tens of deg/h, alternating with the mode
    assert np.abs(outs["none"]).min() > 1.0 and np.abs(outs["none"]).max() > 3.0
    # pairing the residual cancels it up to the change of 0.05*damping between windows
    assert np.abs(outs["pair"]).max() < 0.1 * np.abs(outs["none"]).max()
    assert np.std(outs["pair"]) < 0.05 * np.std(outs["none"])
    assert np.std(outs["trend"]) < 0.05 * np.std(outs["none"])


def test_pair_on_residual_exact_for_a_constant_offset():
    log = mr_log(n_periods=8)
    cfg = config(log, combiner="pair")
    train = with_bias(log, cfg, common, damping)
    model, _ = fit_logs([train], cfg, (0, 1, 2, 4, 8))
    test = with_bias(log, cfg, common, lambda u, v: damping(u, v) + 2.0)
    out = comp.compensate(test, model)
    v = out["valid"] == 1
    np.testing.assert_allclose(out.rate_dph[v], 0.0, atol=1e-7)


def test_validity_rules_none_pair_trend():
    rng = np.random.default_rng(5)
    mode = mr_modes(5, (3, 10, 3, 10))
    n = len(mode)
    x = rng.normal(size=n)
    ok = rng.random(n) > 0.2
    ok[:40] = True
    seg = np.array([0])
    for settle in (0.0, 2.0):
        used_expect = np.zeros(n, bool)
        pos = 0
        for i in range(n):
            pos = pos + 1 if i and mode[i] == mode[i - 1] else 0
            used_expect[i] = mode[i] in (1, 2) and pos >= settle and ok[i]
        out_n, valid_n, used_n = combine_values(mode, x, ok, seg, ReversalConfig("none", settle_s=settle,
                                                                                 order="regress_first"), 1.0)
        np.testing.assert_array_equal(used_n, used_expect)
        np.testing.assert_array_equal(valid_n, used_expect)
        np.testing.assert_array_equal(out_n[valid_n], x[valid_n])
        for comb in ("pair", "trend"):
            cfg = ReversalConfig(comb, max_stale_s=30.0, settle_s=settle, order="regress_first")
            out, valid, used = combine_values(mode, x, ok, seg, cfg, 1.0)
            np.testing.assert_array_equal(used, used_expect)
            assert not (valid & ~used).any()
            # first valid sample: in the first mode-2 window, after a complete mode-1 window
            assert mode[np.argmax(valid)] == 2
            # non-used samples never enter a window: garbage there changes nothing
            x2 = np.where(used, x, 1e9)
            out2, valid2, _ = combine_values(mode, x2, ok, seg, cfg, 1.0)
            np.testing.assert_array_equal(valid2, valid)
            np.testing.assert_array_equal(out2, out)
            # with every sample ok, the kernel is the legacy combiner on the same values
            all_ok = np.ones(n, bool)
            out3, valid3, _ = combine_values(mode, x, all_ok, seg, cfg, 1.0)
            log = rl.RunLog.from_arrays(t_s=np.arange(n, dtype=float), mode=mode,
                                        rate_dph=np.where(mode == 2, -x, x), freq_hz=np.full(n, 6e3))
            legacy = combine(log, comb, 30.0, settle, fs_hz=1.0)
            np.testing.assert_array_equal(out3, legacy.out_dph)
            np.testing.assert_array_equal(valid3, legacy.valid)
        # staleness: a max_stale of 5 samples invalidates the tail of each window
        _, v_stale, _ = combine_values(mode, x, np.ones(n, bool), seg,
                                       ReversalConfig("pair", max_stale_s=5.0, order="regress_first"), 1.0)
        _, v_long, _ = combine_values(mode, x, np.ones(n, bool), seg,
                                      ReversalConfig("pair", max_stale_s=300.0, order="regress_first"), 1.0)
        assert v_stale.sum() < v_long.sum() and not (v_stale & ~v_long).any()


def test_none_needs_regress_first_and_order_is_checked():
    with pytest.raises(ValueError, match="none.*regress_first"):
        ReversalConfig("none", order="combine_first")
    with pytest.raises(ValueError, match="order"):
        ReversalConfig("pair", order="regress_last")
    legacy = {"combiner": "pair", "max_stale_s": 300.0, "settle_s": 0.0}      # a model from before 'order'
    assert ReversalConfig.from_dict(legacy).order == "combine_first"
    rt = ReversalConfig("none", 100.0, 2.0, "regress_first")
    assert ReversalConfig.from_dict(rt.to_dict()) == rt


def test_segments_restart_windows_and_warmup():
    mode = mr_modes(10)
    gap = 300 * 4 + 100  # inside a mode-1 window
    log = mr_log(n_periods=10, gap_at=gap)
    assert list(log.segments) == [0, gap]
    cfg = comp.fit_config_from_logs([log], rate_estimator="lsq", n=16,
                                    reversal={"combiner": "pair", "order": "regress_first", "settle_s": 0.0})
    W = cfg.rate.warmup
    assert W > 1
    pr = comp.prepare(log, cfg)
    # warm-up restarts at the gap: those samples are not used
    assert not pr.used[gap:gap + W].any() and pr.used[gap + W]
    # after the gap the state is reset: the first valid pair is in the first mode-2 window after
    # the rest of the interrupted mode-1 window (its post-gap, post-warm-up part is committed)
    first_after = gap + int(np.argmax(pr.valid[gap:]))
    assert first_after == 300 * 4 + 180 and mode[first_after] == 2
    assert not pr.valid[gap:first_after].any() and pr.valid[gap - 1 - 30 - 120 - 30 - 1]
    none_cfg = comp.fit_config_from_logs([log], rate_estimator="lsq", n=16,
                                         reversal={"combiner": "none", "order": "regress_first"})
    pn = comp.prepare(log, none_cfg)
    assert pn.valid[gap + W] and not pn.valid[gap + W - 1]
    np.testing.assert_array_equal(pn.valid, pn.used)


def _legacy_model(log):
    cfg = comp.fit_config_from_logs([log], reversal={"combiner": "trend", "order": "combine_first"})
    return fit_logs([log], cfg, (0, 1, 4))[0]


def test_version1_model_file_loads_and_compensates_as_before(tmp_path):
    log = mr_log(n_periods=10)
    log = with_bias(log, config(log), common, damping)
    model = _legacy_model(log)
    d = model.to_dict()
    d["version"] = 1
    del d["config"]["reversal"]["order"]
    path = tmp_path / "v1.json"
    path.write_text(json.dumps(d))
    old = BiasModel.from_json(path)
    assert old.config.reversal.order == "combine_first" and old.coef_mode2 is None and len(old.banks) == 1
    out = comp.compensate(log, old)
    # the legacy semantics: combined output (combine_first) minus one bank
    c = combine(log, "trend", fs_hz=1.0)
    pr = comp.prepare(log, old)
    v = out["valid"] == 1
    np.testing.assert_array_equal(out.rate_dph[v], (c.out_dph - old.evaluate(pr.u, pr.v, pr.z))[v])
    # a version-1 file cannot carry version-2 fields
    d["coef_mode2_dph"] = [0.0] * 17
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError, match="coef_mode2_dph"):
        BiasModel.from_json(path)


def test_second_bank_required_iff_regress_first(tmp_path):
    log = mr_log(n_periods=6)
    cfg = config(log, combiner="pair")
    log = with_bias(log, cfg, common, damping)
    model, _ = fit_logs([log], cfg, (0, 1))
    with pytest.raises(ModelError, match="coef_mode2_dph.*second coefficient bank"):
        BiasModel(cfg, model.terms, model.coef)
    with pytest.raises(ModelError, match="coef_mode2_dph"):
        BiasModel(_legacy_model(log).config, model.terms, model.coef, coef_mode2=model.coef_mode2)
    with pytest.raises(ValueError, match="needs the mode"):
        model.evaluate(np.zeros(3), np.zeros(3))
    np.testing.assert_array_equal(model.evaluate(np.zeros(2), np.zeros(2), mode=np.array([1, 2])),
                                  [model.coef[0], model.coef_mode2[0]])
    d = model.to_dict()
    del d["coef_mode2_dph"]
    path = tmp_path / "m.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError) as exc:
        BiasModel.from_json(path)
    assert str(path) in str(exc.value) and "'coef_mode2_dph'" in str(exc.value)
    d = model.to_dict()
    del d["config"]["reversal"]["order"]
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError, match="config.reversal.order"):
        BiasModel.from_json(path)
    # round trip, bit for bit
    model.to_json(path)
    back = BiasModel.from_json(path)
    np.testing.assert_array_equal(back.banks, model.banks)
    assert back.config == model.config


def test_fit_needs_both_modes():
    log = mr_log(n_periods=6)
    one = log.with_columns(mode=np.where(log.mode == 2, 3, log.mode))
    cfg = config(one, combiner="none")
    with pytest.raises(ValueError, match="mode 2"):
        fit_logs([one], cfg, (0,))


def test_auto_terms_selected_jointly():
    """One term set for both banks: a term only in the damping part (bank difference) is kept."""
    rng = np.random.default_rng(11)
    logs = []
    for k in range(3):
        log = mr_log(n_periods=12)
        cfg = config(log)
        log = with_bias(log, cfg, lambda u, v: 5.0 + 0 * u, lambda u, v: 30.0 * u + 8.0 * v)
        logs.append(log.with_columns(rate_dph=log.rate_dph + rng.normal(0, 0.5, len(log))))
    cfg = comp.fit_config_from_logs(logs, reversal={"combiner": "none", "order": "regress_first"})
    model, res = fit_logs(logs, cfg, "auto")
    assert set(model.terms) == {0, 1, 4}, model.terms
    np.testing.assert_allclose(model.coef[[1, 4]], [30.0, 8.0], atol=0.5)
    np.testing.assert_allclose(model.coef_mode2[[1, 4]], [-30.0, -8.0], atol=0.5)
    assert res.cv["groups"] == 3


def test_cli_fit_regress_first_and_compensate(tmp_path):
    from host_tools.cli import main

    log = mr_log(n_periods=10)
    log = with_bias(log, config(log), common, damping)
    run = tmp_path / "run.csv"
    rl.write(log, run)
    m = tmp_path / "m.json"
    assert main(["fit", str(run), "-o", str(m), "--terms", "k0,k1,k2,k4,k8", "--order", "regress_first",
                 "--combiner", "none"]) == 0
    d = json.loads(m.read_text())
    assert d["version"] == 2 and d["config"]["reversal"] == {"combiner": "none", "max_stale_s": 300.0,
                                                               "settle_s": 0.0, "order": "regress_first"}
    assert len(d["coef_mode2_dph"]) == 17
    out = tmp_path / "out.csv"
    assert main(["compensate", str(run), "--model", str(m), "-o", str(out)]) == 0
    res = rl.read(out)
    np.testing.assert_allclose(res.rate_dph[res["valid"] == 1], 0.0, atol=1e-6)
    with pytest.raises(SystemExit):
        main(["fit", str(run), "-o", str(m), "--combiner", "median"])


def test_rate_estimator_auto_keeps_least_cv_and_reports_it(tmp_path):
    from host_tools.fitting.fit_rate import RATE_CANDIDATES, fit_auto_rate

    log = mr_log(n_periods=3)  # 900 samples: shorter than 2**9, the iir shift-9 still starts at once (its gear)
    log = with_bias(log, config(log, rate_estimator="diff"), common, damping)
    model, res = fit_auto_rate([log], (0, 1, 4), reversal={"combiner": "pair", "order": "regress_first"},
                               prefer=None)   # no preferred candidate: the least CV rms
    sel = model.fit["rate_selection"]
    assert len(sel["candidates"]) == len(RATE_CANDIDATES)
    assert not [r for r in sel["candidates"] if "error" in r]
    ok = [r for r in sel["candidates"] if "cv_rms" in r]
    best = min(ok, key=lambda r: r["cv_rms"])
    assert sel["chosen"] == best["estimator"] and res.cv["cv_rms"] == best["cv_rms"]
    assert sel["chosen"].split()[0] == model.config.rate.estimator
    path = tmp_path / "m.json"
    model.to_json(path)
    assert json.loads(path.read_text())["fit"]["rate_selection"]["chosen"] == sel["chosen"]
    with pytest.raises(ValueError, match="auto"):
        comp.fit_config_from_logs([log], rate_estimator="auto")


def test_settle_and_mr_rate_selection_defaults_come_from_compensate(tmp_path, monkeypatch):
    from host_tools.cli import main

    log = mr_log(n_periods=10)
    monkeypatch.setattr(comp, "DEFAULT_SETTLE_S", 7.0)
    assert config(log, "pair").reversal.settle_s == 7.0   # the default pipeline
    assert config(log, "pair", settle_s=None).reversal.settle_s == 7.0
    assert config(log, "pair", settle_s=0.0).reversal.settle_s == 0.0
    assert comp.fit_config_from_logs([log]).reversal.settle_s == 7.0
    for comb, order in (("none", "regress_first"), ("trend", "regress_first"), ("pair", "combine_first")):
        assert config(log, comb, order).reversal.settle_s == 0.0   # not measured to help: 0 s
    log = with_bias(log, config(log, settle_s=0.0), common, damping)
    run = tmp_path / "run.csv"
    rl.write(log, run)
    models = {}
    for sel, extra in (("auto", []), ("auto", ["--rate-estimator", "diff"]), ("auto", ["--rate-shift", "5"]),
                       ("fixed", []), ("fixed", ["--settle", "2"])):
        monkeypatch.setattr(comp, "DEFAULT_RATE_SELECTION_MR", sel)
        m = tmp_path / f"m{len(models)}.json"
        assert main(["fit", str(run), "-o", str(m), "--terms", "k0,k1,k4", "--combiner", "pair", *extra]) == 0
        models[(sel, *extra)] = json.loads(m.read_text())
    assert "rate_selection" in models[("auto",)]["fit"]
    for key in (("auto", "--rate-estimator", "diff"), ("auto", "--rate-shift", "5"), ("fixed",)):
        assert "rate_selection" not in models[key]["fit"]
        assert models[key]["config"]["reversal"]["settle_s"] == 7.0
    assert models[("fixed",)]["config"]["rate"]["estimator"] == comp.DEFAULT_RATE["estimator"]
    assert models[("fixed", "--settle", "2")]["config"]["reversal"]["settle_s"] == 2.0
