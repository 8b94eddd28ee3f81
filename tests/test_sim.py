"""Tests of the virtual gyroscope (host_tools/simulation/sim.py) and of `hdrg simulate`."""
from __future__ import annotations

import math

import allantools
import numpy as np
import pytest

from host_tools.golden import runlog
from host_tools.simulation import sim, sim_params, sim_physics
from host_tools.cli import main

COLUMNS = ["t_s", "freq_hz", "rate_dph", "mode", "temp_c", "aux_vdd"]


# -- helpers: a private copy of the paper's pair combiner and the 100-s block statistics ----------

def pair_combine(mode, rate):
    """The paper's pairing combiner (private copy of host_tools.golden.reversal "pair", no settling):
    in a window of mode m (1 or 2), out = (c + W_other) / 2 with c = s * rate (s = +1 mode 1,
    -1 mode 2) and W_other the mean of c over the last complete window of the other mode; valid
    only in modes 1/2 once the other mode has a complete window.  FTR logs: out = rate."""
    mode = np.asarray(mode)
    rate = np.asarray(rate, float)
    if np.all(mode == 0):
        return rate.copy(), np.ones(len(rate), bool)
    out = np.zeros(len(rate))
    valid = np.zeros(len(rate), bool)
    edges = np.flatnonzero(np.diff(mode)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [len(mode)]])
    last = {}
    for a, b in zip(starts, ends):
        m = mode[a]
        if m not in (1, 2):
            continue
        c = (1.0 if m == 1 else -1.0) * rate[a:b]
        if 3 - m in last:
            out[a:b] = 0.5 * (c + last[3 - m])
            valid[a:b] = True
        if b < len(mode):  # complete (ended by a mode change)
            last[m] = c.mean()
    return out, valid


def block_stats(t_s, y, valid, block_s=100.0):
    """(std ddof=1, max-min) of the means of the valid samples in complete non-overlapping blocks."""
    k = np.floor(t_s / block_s).astype(int)
    nb = int(np.floor((t_s[-1] - t_s[0] + (t_s[1] - t_s[0])) / block_s))
    means = [y[(k == b) & valid].mean() for b in range(nb) if np.any((k == b) & valid)]
    means = np.asarray(means)
    return float(means.std(ddof=1)), float(means.max() - means.min())


def paper_stats(log):
    out, valid = pair_combine(log.mode, log.rate_dph)
    s100, pp100 = block_stats(log.t_s, out, valid)
    o = out[valid]
    return dict(std100=s100, pp100=pp100, std1=float(o.std(ddof=1)), pp1=float(o.max() - o.min()))


def cols_equal(a, b):
    return all(np.array_equal(a[c], b[c]) for c in COLUMNS)


# -- determinism ----------------------------------------------------------------------------------

def test_determinism_and_seeds():
    a = sim.simulate("paper-mr-cycle-4dpm", seed=5, duration_s=2000)
    b = sim.simulate("paper-mr-cycle-4dpm", seed=5, duration_s=2000)
    c = sim.simulate("paper-mr-cycle-4dpm", seed=6, duration_s=2000)
    assert list(a.columns) == COLUMNS
    assert cols_equal(a, b) and a.metadata == b.metadata
    assert not np.array_equal(a.rate_dph, c.rate_dph)
    assert not np.array_equal(a["freq_hz"], c["freq_hz"])
    assert np.array_equal(a.mode, c.mode) and np.array_equal(a.t_s, c.t_s)


def test_metadata():
    log = sim.simulate("paper-mr-cycle-4dpm", seed=3, duration_s=600)
    md = log.metadata
    assert md["device"] == "hdrg-sim" and md["sample_rate_hz"] == "1" and md["reversal"] == "on"
    assert md["exchange_s"] == "30" and md["dwell_s"] == "120"
    assert md["scenario"] == "paper-mr-cycle-4dpm" and md["seed"] == "3"
    assert md["effects"].split(",") == list(sim.DEFAULT_EFFECTS)
    ftr = sim.simulate("static", duration_s=100, sample_rate_hz=10)
    assert ftr.metadata["reversal"] == "off" and "exchange_s" not in ftr.metadata
    assert ftr.metadata["sample_rate_hz"] == "10" and len(ftr) == 1000
    assert "turn_on" not in ftr.metadata["effects"].split(",")  # static is warmed up
    assert np.all(ftr.mode == 0)


# -- effects ---------------------------------------------------------------------------------------

ALL_ON = {name: {} for name in sim.EFFECTS}
SHORT = sim.cycle_profile(4.0, hold_s=600.0, n_cycles=1)   # 4200 s: ramps, holds, power-on


def _run(**kw):
    return sim.simulate("paper-mr-cycle-4dpm", seed=11, duration_s=4200, profile=SHORT, return_truth=True, **kw)


RATE_ONLY = [n for n in sim.EFFECTS
             if n not in ("self_heating", "freq_noise", "pll_quant", "temp_sensor", "vdd_wander")]


@pytest.mark.parametrize("name", RATE_ONLY)
def test_effect_switch_rate_terms(name):
    """Off -> its contribution is zero: the difference of two runs with the same seed is exactly
    the effect's own term; every other column is unchanged."""
    full, tr = _run(effects=ALL_ON)
    off, tr_off = _run(effects=ALL_ON, off=[name])
    diff = full.rate_dph - off.rate_dph
    assert name in tr["parts"] and name not in tr_off["parts"]
    assert np.any(tr["parts"][name] != 0), f"{name} has no effect in this run"
    np.testing.assert_allclose(diff, tr["parts"][name], rtol=0, atol=1e-9)
    for c in ("freq_hz", "temp_c", "aux_vdd", "mode"):
        assert np.array_equal(full[c], off[c])
    for other, part in tr_off["parts"].items():
        assert np.array_equal(part, tr["parts"][other]), other
    assert name in full.metadata["effects"].split(",") and name not in off.metadata["effects"].split(",")


@pytest.mark.parametrize("name, column", [("freq_noise", "freq_hz"), ("pll_quant", "freq_hz"),
                                          ("temp_sensor", "temp_c"), ("vdd_wander", "aux_vdd"),
                                          ("self_heating", "freq_hz")])
def test_effect_switch_channels(name, column):
    full, _ = _run(effects=ALL_ON)
    off, tr_off = _run(effects=ALL_ON, off=[name])
    assert not np.array_equal(full[column], off[column])
    if name != "self_heating":  # self-heating moves every temperature, hence the biases too
        others = [c for c in ("freq_hz", "temp_c") if c != column]
        assert all(np.array_equal(full[c], off[c]) for c in others)
    if name in ("freq_noise", "pll_quant"):
        np.testing.assert_allclose(off["freq_hz"], tr_off["freq_hz"], rtol=0, atol=0)
        assert np.max(np.abs(full["freq_hz"] - off["freq_hz"])) < 1e-3  # 0.1 mHz noise, 0.36 uHz LSB
    if name == "pll_quant":
        lsb = sim_params.PllQuant().lsb_hz
        q = full["freq_hz"] / lsb
        assert np.max(np.abs(q - np.round(q))) < 1e-3
    if name == "temp_sensor":
        np.testing.assert_array_equal(off["temp_c"], tr_off["T_board"])
    if name == "vdd_wander":
        assert np.all(off["aux_vdd"] == 5.0)


def test_off_by_zero_amplitude_matches_switch_off():
    a, _ = _run(inject={"periodic": {"amp_dph": 0.0}, "aging": {"rate_dph_per_h": 0.0}})
    b, _ = _run()
    np.testing.assert_allclose(a.rate_dph, b.rate_dph, rtol=0, atol=1e-12)


def test_undeclared_effects_act_but_are_not_listed():
    base = sim.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=3000)
    hid, tr = sim.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=3000,
                           undeclared=["aging:rate_dph_per_h=2", "thermal_lag"], return_truth=True)
    listed = hid.metadata["effects"].split(",")
    assert "aging" not in listed and "thermal_lag" not in listed
    assert listed == base.metadata["effects"].split(",")
    np.testing.assert_allclose(tr["parts"]["aging"], 2.0 * hid.t_s / 3600.0)
    np.testing.assert_allclose(hid.rate_dph - base.rate_dph, tr["parts"]["aging"] + tr["parts"]["thermal_lag"],
                               atol=1e-9)
    # declared injection of the same effects does list them
    dec = sim.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=3000, inject=["aging:rate_dph_per_h=2"])
    assert "aging" in dec.metadata["effects"].split(",")
    # an effect that is on by default can be hidden too
    hid2 = sim.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=3000, undeclared={"turn_on": None})
    assert "turn_on" not in hid2.metadata["effects"] and cols_equal(hid2, base)


def test_missing_effect_families_behave():
    log, tr = _run(inject={"exchange_transient": {"amp_dph": 3.0, "tau_s": 10.0},
                           "imperfect_reversal": {"coef_dph_per_c": 0.1},
                           "proxy_high_order": {"amp_dph": 1.0, "power": 5},
                           "periodic": {"amp_dph": 1.0, "period_s": 500.0}})
    mode, s, t = log.mode, tr["sign"], log.t_s
    et = tr["parts"]["exchange_transient"]
    first = np.flatnonzero((mode[1:] != 3) & (mode[:-1] == 3)) + 1
    np.testing.assert_allclose(et[first], 3.0 * s[first])       # flips=True by default
    assert np.all(et[mode == 3] == 0)
    ir = tr["parts"]["imperfect_reversal"]
    x = tr["T_res"] - 20.0
    np.testing.assert_allclose(ir[mode == 2], 0.1 * x[mode == 2])
    assert np.all(ir[mode != 2] == 0)
    np.testing.assert_allclose(tr["parts"]["proxy_high_order"], s * (x / 40.0) ** 5)
    np.testing.assert_allclose(tr["parts"]["periodic"], s * np.sin(2 * np.pi * t / 500.0))
    # flips=False: the same term in every mode (but 3 also carries it)
    _, tr2 = _run(inject={"periodic": {"amp_dph": 1.0, "period_s": 500.0, "flips": False}})
    np.testing.assert_allclose(tr2["parts"]["periodic"], np.sin(2 * np.pi * t / 500.0))


def test_board_sensor_and_vdd_columns():
    log, tr = sim.simulate("paper-ftr-cycle-4dpm", seed=4, duration_s=8000, return_truth=True,
                           inject={"aux_vdd": {"coef_dph_per_v": 100.0},
                                   "vdd_wander": {"step_times_s": (4000.0,), "step_sizes_v": (0.05,)},
                                   "board_temp": {"coef_dph_per_c": 0.2}})
    assert abs(np.mean(log["temp_c"] - tr["T_board"])) < 0.01
    assert np.std(log["temp_c"] - tr["T_board"]) < 0.03
    v = log["aux_vdd"]
    assert abs(np.median(v[4000:4100]) - np.median(v[3900:4000]) - 0.05) < 0.01
    np.testing.assert_allclose(tr["parts"]["aux_vdd"], 100.0 * (v - 5.0))
    np.testing.assert_allclose(tr["parts"]["board_temp"], 0.2 * (tr["T_board"] - 20.0))


# -- thermal model and frequency --------------------------------------------------------------------

def test_lag_exact_for_ramp():
    dt, tau = 1.0, 50.0
    t = np.arange(0, 1000.0, dt)
    u = 0.1 * t
    y = sim_physics.lag(u, tau, dt)
    exact = 0.1 * (t - tau * (1.0 - np.exp(-t / tau)))
    np.testing.assert_allclose(y, exact, atol=1e-9)


def test_frequency_law_and_rate_resolution():
    log, tr = sim.simulate("paper-ftr-cycle-1dpm", seed=0, return_truth=True)
    x = tr["T_res"] - 20.0
    model = 6227.386 * (1 - 20.9e-6 * x - 1e-8 * x * x)
    assert np.max(np.abs(log["freq_hz"] - model)) < 6e-4  # 0.1 mHz white noise (6 sigma) + LSB
    # at 20 degC the format example's 6227.386 Hz
    assert abs(log["freq_hz"][0] - 6227.386) < 1e-3
    # the 1-s difference resolves the rate: during the ramps, |df/dt| up to ~2 mHz/s at 1 degC/min
    d = np.diff(log["freq_hz"])
    assert 1.0e-3 < np.max(np.abs(np.convolve(d, np.ones(60) / 60, "valid"))) < 2.3e-3
    assert np.std(d[:100]) < 2e-4  # noise of the difference at the start (hold): ~0.14 mHz


# -- modes and sign convention ------------------------------------------------------------------

def test_mode_sequence_paper_and_custom():
    t = np.arange(0, 600.0)
    m = sim_physics.mode_sequence(t, True, 30.0, 120.0)
    expect = np.concatenate([np.full(30, 3), np.full(120, 1), np.full(30, 3), np.full(120, 2)])
    np.testing.assert_array_equal(m, np.tile(expect, 2))
    log = sim.simulate("static", duration_s=260, reversal=True, exchange_s=10, dwell_s=50, sample_rate_hz=2)
    period = np.concatenate([np.full(20, 3), np.full(100, 1), np.full(20, 3), np.full(100, 2)])  # 2 Hz
    np.testing.assert_array_equal(log.mode, np.concatenate([period, period, np.full(20, 3), np.full(20, 1)]))
    assert sim.simulate("paper-ftr-cycle-4dpm", duration_s=100).mode.max() == 0


def test_sign_convention_mode2():
    """Earth rate, B_E and turn-on flip in mode 2; B_D does not; mode 3 is garbage."""
    kw = dict(duration_s=600, profile=[(0, 0.0), (600, 0.0)], reversal=True)   # 0 degC: B_D, B_E != 0
    er = sim.simulate("static", effects=["earth_rate"], **kw)
    omega = 15.041067 * math.sin(math.radians(28.2))
    np.testing.assert_allclose(er.rate_dph[er.mode == 1], omega)
    np.testing.assert_allclose(er.rate_dph[er.mode == 2], -omega)
    assert np.all(er.rate_dph[er.mode == 3] == 0)
    bd = sim.simulate("static", effects=["damping_asym"], **kw)
    bd1, bd2 = bd.rate_dph[bd.mode == 1], bd.rate_dph[bd.mode == 2]
    assert abs(bd1.mean()) > 10 and np.allclose(bd1.mean(), bd2.mean())
    be = sim.simulate("static", effects=["electronics"], **kw)
    be1, be2 = be.rate_dph[be.mode == 1], be.rate_dph[be.mode == 2]
    assert abs(be1.mean()) > 1 and np.allclose(be1.mean(), -be2.mean())
    to, tr = sim.simulate("static", effects=["turn_on"], return_truth=True, **kw)
    np.testing.assert_allclose(to.rate_dph, tr["sign"] * -2.0 * np.exp(-to.t_s / 400.0))
    full = sim.simulate("paper-mr-cycle-4dpm", seed=1, duration_s=1200)
    ex = full.rate_dph[full.mode == 3]
    ok = full.rate_dph[full.mode != 3]
    assert np.std(ex) > 20 * np.std(ok)


# -- noise: Allan deviation -------------------------------------------------------------------------

def test_allan_deviation_of_static_run():
    """ARW slope -1/2 and 60 N at tau = 1 s, a floor near 0.664 B, the RRW rise K sqrt(tau/3 h).

    Tolerances: with n = 2e5 samples the overlapping Allan deviation at tau has about n/tau
    independent averages, i.e. a relative 1-sigma error ~ 1/sqrt(2 (n/tau - 1)) (< 1 % at 1 s,
    ~ 8 % at 4096 s, ~ 13 % at 16384 s); the model (quadrature sum of the three terms) is checked
    within 3 sigma + 3 %."""
    n = 200_000
    # the damping-axis wander (a Gauss-Markov bias, cancelled by mode reversal) is not a noise term of the model
    log = sim.simulate("static", seed=3, duration_s=n, off=("damping_wander",))
    arw, bi, rrw = sim_params.Arw().arw_deg_per_sqrt_h, sim_params.BiasInstability().bi_dph, sim_params.Rrw().rrw_dph_per_sqrt_h
    taus, adev, _, _ = allantools.oadev(log.rate_dph, rate=1.0, data_type="freq", taus="octave")
    keep = taus <= n / 12
    taus, adev = taus[keep], adev[keep]
    model = np.sqrt((60 * arw) ** 2 / taus + (0.664 * bi) ** 2 + rrw ** 2 * taus / 10800.0)
    err = 1.0 / np.sqrt(2.0 * (n / taus - 1.0))
    assert np.all(np.abs(adev / model - 1.0) < 3 * err + 0.03), list(zip(taus, adev / model))
    # ARW region: value at 1 s and slope over 1..8 s
    assert abs(adev[0] / (60 * arw) - 1.0) < 0.05
    slope = np.polyfit(np.log(taus[:4]), np.log(adev[:4]), 1)[0]
    assert -0.5 < slope < -0.4                          # -1/2 bent slightly by the flicker floor
    # floor: minimum near 0.664 B (the other two terms add at most ~10 % there)
    assert 0.95 < adev.min() / (0.664 * bi) < 1.25
    # RRW rise after the floor: the model expects ~2x the floor at the last tau (~16000 s), whose
    # estimate has ~13 % 1-sigma error -> at least 1.2x
    assert adev[-1] > 1.2 * adev.min() and taus[np.argmin(adev)] < taus[-1] / 8
    # the flicker alone: flat at 0.664 B over 4..256 s (the Gauss-Markov sum ripples by < 5 %)
    fl = sim.simulate("static", seed=3, duration_s=n, effects=["bias_instability"])
    _, a2, _, _ = allantools.oadev(fl.rate_dph, rate=1.0, data_type="freq", taus=[4, 16, 64, 256])
    assert np.all(np.abs(a2 / (0.664 * bi) - 1.0) < 0.1)


# -- calibration to the paper ------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1])
def test_calibration(seed):
    """FTR at -20..20 degC, 4 degC/min: 27.8 deg/h (1 sigma) and 66 deg/h (p-p) within 15 %; mode
    reversal (pair combiner): 2.57 and 6.12 within 15 %; on 100-s block means; 1-s std within 5 %
    of the 100-s std (noise floor ~0.2 deg/h)."""
    ftr = paper_stats(sim.simulate("paper-ftr-cycle-4dpm", seed=seed))
    assert abs(ftr["std100"] / 27.8 - 1) < 0.15, ftr
    assert abs(ftr["pp100"] / 66.0 - 1) < 0.15, ftr
    assert abs(ftr["std1"] / ftr["std100"] - 1) < 0.05, ftr
    mr = paper_stats(sim.simulate("paper-mr-cycle-4dpm", seed=seed))
    assert abs(mr["std100"] / 2.57 - 1) < 0.15, mr
    assert abs(mr["pp100"] / 6.12 - 1) < 0.15, mr
    assert abs(mr["std1"] / mr["std100"] - 1) < 0.05, mr
    # mode reversal suppresses the drift by about an order of magnitude (paper: 27.8 -> 2.57)
    assert 7 < ftr["std100"] / mr["std100"] < 15


def test_pair_combiner_copy_matches_reversal_module():
    reversal = pytest.importorskip("host_tools.golden.reversal")
    log = sim.simulate("paper-mr-cycle-4dpm", seed=0, duration_s=3000)
    out, valid = pair_combine(log.mode, log.rate_dph)
    comb = reversal.combine(log, "pair")
    np.testing.assert_array_equal(valid, comb.valid)
    np.testing.assert_allclose(out[valid], comb.out_dph[valid], atol=1e-9)
    assert log.t_s[np.argmax(valid)] == 180.0


def test_mr_residual_is_mostly_a_function_of_temperature_and_rate():
    """B_D cancels in the combination; what is left (B_E, turn-on) and the mode-pairing term are
    functions of T_res, T_el and their rates: a 17-term (u, v) fit plus z = s*v removes most of it."""
    log, tr = sim.simulate("paper-mr-cycle-4dpm", seed=0, return_truth=True)
    out, valid = pair_combine(log.mode, log.rate_dph)
    f = log["freq_hz"]
    u = (f - (f.max() + f.min()) / 2) / ((f.max() - f.min()) / 2)
    d = np.concatenate([[0.0], np.diff(f)])
    v = np.convolve(d, np.ones(8) / 8)[:len(f)]
    v /= np.abs(v).max()
    s = tr["sign"]
    x = np.stack([u ** i * v ** j for i in range(4) for j in range(4)] + [s * v], 1)
    coef, *_ = np.linalg.lstsq(x[valid], out[valid], rcond=None)
    before = block_stats(log.t_s, out, valid)[0]
    after = block_stats(log.t_s, out - x @ coef, valid)[0]
    assert after < 0.2 * before


# -- profiles --------------------------------------------------------------------------------------

def test_profile_from_table_and_csv(tmp_path):
    rows = [(0, 25.0), (600, 25.0), (1800, -5.0), (2400, -5.0)]
    p = tmp_path / "prof.csv"
    p.write_text("# chamber program\nt_s,temp_c\n" + "\n".join(f"{a},{b}" for a, b in rows) + "\n")
    prof = sim.Profile.from_csv(p)
    assert prof.t_s == (0.0, 600.0, 1800.0, 2400.0) and prof.temp_c == (25.0, 25.0, -5.0, -5.0)
    log, tr = sim.simulate("static", profile=str(p), return_truth=True)
    assert len(log) == 2400 and log.metadata["profile"] == "prof.csv"
    np.testing.assert_allclose(tr["T_ch"], np.interp(log.t_s, *zip(*rows)))
    log2, tr2 = sim.simulate("static", profile=rows, return_truth=True, duration_s=3000)
    assert np.all(tr2["T_ch"][2400:] == -5.0)
    assert cols_equal(log2.select(np.arange(2400)), log)   # causal: a longer run starts the same
    # package lags the chamber: still above the chamber at the end of the ramp
    assert tr["T_pkg"][1800] > -5.0 + 5.0


@pytest.mark.parametrize("text, msg", [
    ("t_s,temp_c\n0,20\n10,20\n5,20\n", "not strictly increasing"),
    ("0,20\n10,abc\n", "not two numbers"),
    ("0,20,1\n", "3 cells"),
    ("# only a comment\n", "no profile rows"),
    ("-5,20\n10,20\n", "negative"),
])
def test_profile_csv_errors(tmp_path, text, msg):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ValueError, match=msg) as exc:
        sim.Profile.from_csv(p)
    assert "bad.csv" in str(exc.value)


def test_builtin_profiles():
    c = sim.cycle_profile(2.0, hold_s=100.0, n_cycles=1)
    assert c.temp_c == (20.0, 20.0, -20.0, -20.0, 20.0, 20.0)
    assert np.allclose(np.diff(c.t_s), [50.0, 1200.0, 100.0, 1200.0, 50.0])
    r = sim.slow_ramp_profile()
    assert min(r.temp_c) == -40.0 and max(r.temp_c) == 60.0 and r.temp_c[-1] == 25.0
    assert set(sim.list_scenarios()) >= {"paper-ftr-cycle-1dpm", "paper-ftr-cycle-2dpm", "paper-ftr-cycle-4dpm",
                                         "paper-slow-ramp", "paper-mr-cycle-4dpm", "paper-startup-mr", "static"}
    st, tr = sim.simulate("paper-startup-mr", return_truth=True)
    assert len(st) == 2700 and np.all(tr["T_ch"] == 25.0)
    rise = tr["T_el"][-1] - tr["T_el"][0]
    assert 0.8 < rise < 1.1 and 0.2 < tr["T_res"][-1] - 25.0 < 0.5   # self-heating


# -- errors -------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, msg", [
    (dict(scenario="nope"), "unknown scenario 'nope'"),
    (dict(inject={"nope": {}}), "unknown effect 'nope'"),
    (dict(inject={"aging": {"rate": 1}}), "effect 'aging' has no parameter 'rate'"),
    (dict(inject={"turn_on": {"tau_s": -1.0}}), "turn_on parameter tau_s must be > 0"),
    (dict(inject={"arw": {"arw_deg_per_sqrt_h": float("nan")}}), "must be a finite number"),
    (dict(inject={"proxy_high_order": {"power": 2.5}}), "power must be an integer"),
    (dict(undeclared=["aging:rate_dph_per_h"]), "expected param=value"),
    (dict(sample_rate_hz=0.0), "sample_rate_hz must be > 0"),
    (dict(duration_s=-5), "duration_s must be > 0"),
    (dict(duration_s=1.0), "need at least 2"),
    (dict(seed=-1), "seed must be an integer >= 0"),
    (dict(tau_pkg_s=0.0), "tau_pkg_s must be > 0"),
    (dict(reversal="yes"), "reversal must be true or false"),
    (dict(colour="red"), "unknown simulate option 'colour'"),
    (dict(profile=[(0, 20), (0, 30)]), "not strictly increasing"),
])
def test_bad_parameters(kwargs, msg):
    kwargs = dict(kwargs)
    scenario = kwargs.pop("scenario", "static")
    with pytest.raises(ValueError, match=msg):
        sim.simulate(scenario, **kwargs)


# -- CLI --------------------------------------------------------------------------------------------

def test_cli_simulate_csv_and_npz(tmp_path, capsys):
    out = tmp_path / "run.csv"
    args = ["simulate", "--scenario", "paper-mr-cycle-4dpm", "-o", str(out), "--seed", "3", "--duration", "900",
            "--inject", "periodic:amp_dph=1.5,period_s=300", "--undeclared", "aging:rate_dph_per_h=10",
            "--off", "rrw"]
    assert main(args) == 0
    back = runlog.read(out)
    ref = sim.simulate("paper-mr-cycle-4dpm", seed=3, duration_s=900, inject=["periodic:amp_dph=1.5,period_s=300"],
                       undeclared=["aging:rate_dph_per_h=10"], off=["rrw"])
    assert list(back.columns) == COLUMNS and cols_equal(back, ref)
    listed = back.metadata["effects"].split(",")
    assert "periodic" in listed and "aging" not in listed and "rrw" not in listed
    assert back.metadata["seed"] == "3" and back.metadata["reversal"] == "on"
    npz = tmp_path / "run.npz"
    assert main(["simulate", "--scenario", "static", "-o", str(npz), "--duration", "50", "--rate", "2",
                 "--reversal", "on", "--exchange-s", "5", "--dwell-s", "10", "--set", "device=hdrg-07"]) == 0
    b2 = runlog.read(npz)
    assert len(b2) == 100 and b2.metadata["device"] == "hdrg-07" and b2.metadata["exchange_s"] == "5"
    assert set(np.unique(b2.mode)) == {1, 2, 3}


def test_cli_profile_list_and_errors(tmp_path, capsys):
    prof = tmp_path / "p.csv"
    prof.write_text("0,10\n100,10\n200,30\n")
    out = tmp_path / "r.csv"
    assert main(["simulate", "--scenario", "static", "--profile", str(prof), "-o", str(out)]) == 0
    assert len(runlog.read(out)) == 200
    assert main(["simulate", "--list"]) == 0
    text = capsys.readouterr().out
    for name in list(sim.SCENARIOS) + list(sim.EFFECTS):
        assert name in text
    assert main(["simulate", "--scenario", "static", "-o", str(out), "--inject", "bogus"]) == 2
    assert "unknown effect 'bogus'" in capsys.readouterr().err
    assert main(["simulate", "--scenario", "static", "-o", str(out), "--set", "tau_res_s=abc"]) == 2
    assert "tau_res_s" in capsys.readouterr().err
    assert main(["simulate", "-o", str(out)]) == 2
    assert "--scenario is required" in capsys.readouterr().err


# -- speed -----------------------------------------------------------------------------------------

@pytest.mark.benchmark
def test_benchmark_1e6_samples(benchmark):
    """10^6 samples (mode reversal, all default effects): target < 2 s."""
    log = benchmark(sim.simulate, "paper-mr-cycle-4dpm", seed=0, duration_s=1_000_000)
    assert len(log) == 1_000_000
