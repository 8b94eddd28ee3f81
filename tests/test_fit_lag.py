"""The lag-state block of the default fit (host_tools.fitting.fit_lag): the shared-Gram screen equals a direct
per-fold least squares, the packing into one k7 sum reproduces each bank's lag polynomial, the
block is found on a device whose bias sits on a lagged node (held out better), it is not taken
when the proxy sees every bias, and its model runs in fixed point within 0.002 deg/h of the golden."""
import copy

import numpy as np
import pytest

import host_tools.golden.compensate as hc
from host_tools.bench import accuracy as ba
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import block_groups, fit_logs
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.golden.regressors import aux_regressor, generator_values, regressor_matrix
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign
from test_fixed_aux import check_close

DUR = 4000.0
LAGGED = 131        # foreign device whose bias sits on a node the proxy sees only through a lag


@pytest.fixture(scope="module")
def lagged_mr():
    dev = foreign_device(LAGGED)
    tr = simulate_foreign(dev, 4.0, True, 0, 0, DUR)
    cfg = hc.fit_config_from_logs([tr], rate_estimator="iir", shift=7)
    model, res = fit_logs([tr], cfg, "auto", blocks=True, drop_unidentifiable=True)
    return dev, tr, model, res


def _std_held_out(model, ho):
    out = hc.compensate(ho, model)
    return float(np.std(out.rate_dph[out["valid"] > 0]))


def test_screen_equals_direct_fold_least_squares(lagged_mr):
    _, tr, model, _ = lagged_mr
    sc = FL.screen([tr], model, taus=(240.0, 960.0), orders=(3,))
    row = sc["rows"][0]
    (tau, order), = row["cand"]
    pr = hc.prepare(tr, model.config)
    poly = [0] + sorted(k for k in model.terms if k not in (0, 7))
    lag = generator_values(tr, FL.lag_term(model.config, tau, 1), model.config.rate.fs)
    X = np.column_stack([regressor_matrix(pr.u, pr.v)[:, poly]] + [lag ** k for k in range(1, order + 1)])
    g = block_groups(len(pr.y), 8)
    sse = n = 0.0
    for m in (pr.used & (pr.mode == 1), pr.used & (pr.mode == 2)):
        for f in range(8):
            test, train = m & (g == f), m & (g != f)
            c = np.linalg.lstsq(X[train], pr.y[train], rcond=None)[0]
            sse += float(np.sum((pr.y[test] - X[test] @ c) ** 2))
            n += test.sum()
    assert row["screen_cv_rms"] == pytest.approx(np.sqrt(sse / n), rel=1e-6)
    assert sc["base"] > min(r["screen_cv_rms"] for r in sc["rows"])


def test_packing_reproduces_each_bank(lagged_mr):
    """z on mode-1 samples = a_1 . g / T, on mode-2 samples = a_2 . g / T (sign terms), sum |w| = 1."""
    _, tr, model, _ = lagged_mr
    sc = FL.screen([tr], model, taus=(480.0,), orders=(3,))
    cand = sc["rows"][0]["cand"]
    a1, a2 = sc["coefs"](cand)
    assert not np.allclose(a1, a2) and not np.allclose(a1, -a2)   # needs the sign terms
    cfg = FL.lag_config(model.config, cand, [a1, a2])
    terms = cfg.aux.terms
    assert sum(abs(t["weight"]) for t in terms) == pytest.approx(1.0) and any(t["sign"] for t in terms)
    total = float(np.sum(np.abs((a1 + a2) / 2)) + np.sum(np.abs((a1 - a2) / 2)))
    z = aux_regressor(tr, cfg.aux)
    lag = generator_values(tr, FL.lag_term(model.config, 480.0, 1), model.config.rate.fs)
    G = np.column_stack([lag, lag ** 2, lag ** 3])
    mode = np.asarray(tr.mode)
    np.testing.assert_allclose(z[mode == 1], G[mode == 1] @ a1 / total, atol=1e-12)
    np.testing.assert_allclose(z[mode == 2], G[mode == 2] @ a2 / total, atol=1e-12)


def test_block_found_on_a_lagged_device_and_holds_out(monkeypatch):
    dev = foreign_device(LAGGED)
    tr = simulate_foreign(dev, 4.0, False, 0, 0, DUR)
    ho = simulate_foreign(dev, 2.0, False, 1, 1, DUR)
    base, _ = fit_default([tr], lag_block="off")
    assert base.config.aux.generator == "none" and "lag_block" not in base.fit
    monkeypatch.setattr(hc, "DEFAULT_LAG_BLOCK", "auto")
    model, res = fit_default([tr])
    info = model.fit["lag_block"]
    assert info["chosen"] and model.config.aux.generator == "sum" and 7 in model.terms
    assert info["margin"] == FL.LAG_MARGIN["ftr"] and info["cv_rms"] < (1 - info["margin"]) * info["base_cv_rms"]
    assert _std_held_out(model, ho) < 0.7 * _std_held_out(base, ho)
    assert model.to_dict()["fit"]["lag_block"]["chosen"] == info["chosen"]
    check_close(ho, model, "lag block, FTR")   # the FTR block (up to two taus) in fixed point too


def test_lag_block_option_is_checked():
    with pytest.raises(ValueError, match="lag_block"):
        fit_default([simulate_foreign(foreign_device(LAGGED), 4.0, False, 0, 0, 600.0)], lag_block="on")


def test_block_not_taken_when_the_proxy_sees_every_bias(monkeypatch):
    dev = copy.deepcopy(foreign_device(LAGGED))
    ba.ABLATIONS["bias on the resonator node"](dev)
    tr = simulate_foreign(dev, 4.0, False, 0, 0, DUR)
    monkeypatch.setattr(hc, "DEFAULT_LAG_BLOCK", "auto")
    model, _ = fit_default([tr])
    # the guard may keep the cubic in the proxy (the proxy sees every bias): the 17-term model's
    # lag-block decision is then in the guard's record of what it replaced
    lag = model.fit.get("lag_block") or model.fit["guard"]["replaced"]["fit"]["lag_block"]
    assert lag["chosen"] is None and model.config.aux.generator == "none"
    assert lag["candidates"]


def test_lag_model_fixed_point_agrees_with_golden(lagged_mr):
    """Both banks and the sign terms through quantize -> table -> fixed-point compensation."""
    dev, tr, model, res = lagged_mr
    m2, _ = FL.add_lag_block([tr], model, res, "auto", margin=-1.0)   # take the best block whatever its gain
    assert m2.config.aux.generator == "sum" and m2.coef_mode2 is not None
    assert any(t["sign"] for t in m2.config.aux.terms) and 7 in m2.terms
    ho = simulate_foreign(dev, 2.0, True, 1, 1, DUR)
    check_close(ho, m2, "lag block, regress_first")


# -- sensor blocks: the temperature sensor (temp_c) as a second thermal observation -----------------

def test_sensor_candidates_only_when_the_proxy_is_not_the_sensor(lagged_mr):
    _, tr, model, _ = lagged_mr
    assert model.config.proxy.column == "freq_hz"
    col, ref, span = FL.sensor_source([tr], model.config)
    t = np.asarray(tr.columns["temp_c"])
    assert col == "temp_c" and ref - span < t.min() and t.max() < ref + span
    sc = FL.screen([tr], model, taus=(240.0,), orders=(3,), sensor_taus=(0.0, 480.0))
    assert [r["block"] for r in sc["rows"]] == ["lag(u, 240 s)^1..3", "lag(T, 0 s)^1..3", "lag(T, 480 s)^1..3"]
    temp_cfg = hc.fit_config_from_logs([tr], proxy_kind="temp", rate_estimator="iir", shift=7)
    assert FL.sensor_source([tr], temp_cfg) is None   # the proxy is the sensor: nothing new
    assert FL.candidates(4000.0, True, (240.0,), (3,), sensor_taus=(0.0, 60.0)) == [
        ((240.0, 3),), ((0.0, 3, "sensor"),), ((60.0, 3, "sensor"),)]


def test_sensor_block_packs_the_sensor_and_runs_in_fixed_point(lagged_mr):
    """A sensor block: z is the bank's polynomial of the normalized (lagged) sensor, and the model
    (both banks, sign terms, an input on temp_c) agrees in fixed point with the golden."""
    dev, tr, model, res = lagged_mr
    sc = FL.screen([tr], model, taus=(), orders=(3,), sensor_taus=(120.0,))
    cand = sc["rows"][0]["cand"]
    a1, a2 = sc["coefs"](cand)
    cfg = FL.lag_config(model.config, cand, [a1, a2], sc["sensor"])
    assert {t["column"] for t in cfg.aux.terms} == {"temp_c"}
    with pytest.raises(ValueError, match="sensor"):
        FL.lag_config(model.config, cand, [a1, a2])
    col, ref, span = sc["sensor"]
    q = np.clip((np.asarray(tr.columns["temp_c"], float) - ref) / span, -1, 1)
    g = generator_values(tr, FL.lag_term(model.config, 120.0, 1, sensor=sc["sensor"]), model.config.rate.fs)
    assert g[0] == pytest.approx(q[0]) and np.ptp(g) < np.ptp(q)   # restarted at the start, low-passed
    G = np.column_stack([g, g ** 2, g ** 3])
    total = float(np.sum(np.abs((a1 + a2) / 2)) + np.sum(np.abs((a1 - a2) / 2)))
    z = aux_regressor(tr, cfg.aux)
    mode = np.asarray(tr.mode)
    np.testing.assert_allclose(z[mode == 1], G[mode == 1] @ a1 / total, atol=1e-12)
    m2, _ = fit_logs([tr], cfg, "auto", blocks=True, drop_unidentifiable=True)
    if 7 not in m2.terms:
        m2, _ = fit_logs([tr], cfg, tuple(m2.terms) + (7,), blocks=True, drop_unidentifiable=True)
    assert 7 in m2.terms
    check_close(simulate_foreign(dev, 2.0, True, 1, 1, DUR), m2, "sensor block, regress_first")
