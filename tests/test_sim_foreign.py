"""The foreign simulator family (host_tools.simulation.sim_foreign): determinism, sign convention, the
noise-only floor run, every effect kind, the drive-frequency range, the temperature-only devices
(fitted and compensated end to end), CLI and bad arguments."""
import copy
import json
import warnings

import numpy as np
import pytest

from host_tools import api, cli
from host_tools.bench.accuracy import floor_of, servable
from host_tools.golden import runlog
from host_tools.golden.reversal import combine
from host_tools.simulation.sim_foreign import (EFFECT_KINDS, EFFECTS, G0, TEMP_ONLY_SHARE, T_REF_C, T_SCALE_C,
                                               chamber_profile, foreign_device, node_temperatures, simulate_foreign)

DUR = 3000.0


def _run(dev, reversal=True, **kw):
    kw.setdefault("duration_s", DUR)
    return simulate_foreign(dev, kw.pop("rate", 4.0), reversal, kw.pop("power_on", 0), kw.pop("noise_seed", 0), **kw)


def test_determinism_and_device_summary():
    a, b = foreign_device(11), foreign_device(11)
    assert a.to_dict() == b.to_dict()
    assert json.loads(a.to_json())["seed"] == 11
    assert "resonator" in a.describe()
    assert foreign_device(12).to_dict() != a.to_dict()
    r1, r2 = _run(a), _run(b)
    for col in r1.columns:
        np.testing.assert_array_equal(r1[col], r2[col])
    # another noise seed: same physics, different noise; another power-on: different damping change
    r3 = _run(a, noise_seed=1)
    assert not np.array_equal(r1.rate_dph, r3.rate_dph)
    assert a.damping_change(0) != a.damping_change(1)


def test_structure_is_randomized_within_the_documented_ranges():
    devs = [foreign_device(s) for s in range(40)]
    assert {len(d.nodes) for d in devs} == {2, 3, 4}
    assert all(60 <= n["tau_s"] <= 1500 for d in devs for n in d.nodes)
    assert all(d.sensor_node != d.resonator_node for d in devs if d.logs_freq)   # temperature-only: below
    assert any(d.damping_node != d.resonator_node for d in devs) and any(d.damping_node == d.resonator_node for d in devs)
    assert any(n["parent"] >= 0 for d in devs for n in d.nodes[1:])      # series chains
    assert any(n["parent"] < 0 for d in devs for n in d.nodes[1:])       # parallel branches


def test_drive_frequency_spans_3_to_40_khz():
    f0 = np.array([foreign_device(s).drive["f0_hz"] for s in range(400)])
    assert f0.min() >= 3e3 and f0.max() <= 40e3
    assert f0.min() < 3.5e3 and f0.max() > 39.5e3                       # both ends reached
    # roughly uniform: every 5-kHz band from 3 to 38 kHz holds some devices
    assert all(np.any((f0 >= lo) & (f0 < lo + 5e3)) for lo in np.arange(3e3, 38e3, 5e3))
    assert np.any(f0 < 6e3) and np.any(f0 > 30e3)                      # beyond the former 6..30 kHz


# Version-1 draws (f0 then 6..30 kHz) of two devices: the same random number gives f0 now, and
# every other parameter is unchanged (seed 25 is temperature-only: its sensor moved to the resonator).
V1 = {0: {"f0_hz": 13193.085372897236, "omega_dph": 2.2449088969366753, "c1": 29.513778288034487,
          "white_dph": 0.1908630374133519, "nco_step_hz": 0.00013055825716208348, "sensor_node": 1},
      25: {"f0_hz": 19001.48536837229, "omega_dph": 1.3053740744307747, "c1": 28.157761960774092,
           "white_dph": 0.3336704850637673, "nco_step_hz": 0.0007288424023632229, "sensor_node": 1}}


@pytest.mark.parametrize("seed", sorted(V1))
def test_the_wider_range_keeps_every_other_draw(seed):
    d, v1 = foreign_device(seed), V1[seed]
    assert (d.drive["f0_hz"] - 3e3) / 37e3 == pytest.approx((v1["f0_hz"] - 6e3) / 24e3, abs=1e-13)
    assert (d.omega_dph, d.damping["c1"], d.noise["white_dph"], d.drive["nco_step_hz"]) == (
        v1["omega_dph"], v1["c1"], v1["white_dph"], v1["nco_step_hz"])
    assert d.sensor_node == (v1["sensor_node"] if d.logs_freq else d.resonator_node)
    assert d.logs_freq == (seed != 25)


def test_temperature_only_devices_are_a_deterministic_minority():
    devs = [foreign_device(s) for s in range(800)]
    only = [d for d in devs if not d.logs_freq]
    share = len(only) / len(devs)
    assert abs(share - TEMP_ONLY_SHARE) < 0.035, share                 # 1 in 8, +- 3 binomial sigma
    assert all(d.sensor_node == d.resonator_node for d in only)         # an on-die sensor
    assert all(d.sensor_node != d.resonator_node for d in devs if d.logs_freq)
    assert [d.seed for d in only[:2]] == [25, 26]                       # deterministic
    assert "not logged" in only[0].describe() and "not logged" not in devs[0].describe()


def test_a_temperature_only_log_has_no_freq_hz_and_its_temp_c_tracks_the_resonator(tmp_path):
    dev = foreign_device(25)
    run = _run(dev, duration_s=None)
    assert "freq_hz" not in run.columns
    assert list(run.columns) == ["t_s", "rate_dph", "mode", "temp_c", "aux_vdd", "aux_acc_x", "aux_acc_y", "aux_acc_z"]
    floor = _run(dev, duration_s=None, thermal=False)
    np.testing.assert_array_equal(run["temp_c"], floor["temp_c"])
    # temp_c = gain x T_resonator + offset, up to the sensor's white noise and quantization
    t = run.t_s
    prof = chamber_profile(dev, 4.0)
    t_res = node_temperatures(dev, t, np.interp(t, prof[:, 0], prof[:, 1]))[dev.resonator_node]
    err = run["temp_c"] - (dev.sensor["gain"] * t_res + dev.sensor["offset_c"])
    assert np.std(err) < 1.2 * np.hypot(dev.sensor["noise_c"], dev.sensor["lsb_c"] / np.sqrt(12.0))
    assert np.ptp(t_res) > 30.0
    # the other columns are those the device would log with the frequency (same draws)
    with_f = copy.deepcopy(dev)
    with_f.logs_freq = True
    ref = _run(with_f, duration_s=None)
    assert "freq_hz" in ref.columns
    for col in run.columns:
        np.testing.assert_array_equal(run[col], ref[col])
    # written and read back without the column; the CLI writes the same
    path = tmp_path / "t.csv"
    runlog.write(run, path)
    back = runlog.read(path)
    assert "freq_hz" not in back.columns
    np.testing.assert_allclose(back["temp_c"], run["temp_c"])
    out = tmp_path / "cli.csv"
    assert cli.main(["simulate", "--family", "random", "--seed", "25", "--chamber-rate", "4", "--reversal", "on",
                     "--duration", "600", "-o", str(out)]) == 0
    assert "freq_hz" not in runlog.read(out).columns


@pytest.mark.parametrize("reversal, most", [(True, 3.0), (False, 4.0)])
def test_a_temperature_only_device_fits_and_compensates_end_to_end(tmp_path, reversal, most):
    """`hdrg fit` (host_tools.api) on a log without freq_hz takes temp_c as the proxy; the model
    compensates a held-out run of another power-on and chamber rate close to the noise floor."""
    dev = foreign_device(25)
    train, hold = tmp_path / "train.csv", tmp_path / "hold.csv"
    runlog.write(simulate_foreign(dev, 4.0, reversal, 0, 0), train)
    runlog.write(simulate_foreign(dev, 2.0, reversal, 1, 1), hold)
    with pytest.warns(UserWarning, match="temp_c"):
        model = api.fit(train)
    assert model.config.proxy.kind == "temp" and model.config.proxy.column == "temp_c"
    held = runlog.read(hold)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = api.compensate(hold, model)
    serve = servable(held)
    ok = (out["valid"] > 0) & serve
    assert ok.sum() >= 0.99 * serve.sum()
    floor = floor_of(simulate_foreign(dev, 2.0, reversal, 1, 1, thermal=False))
    ratio = np.std(out.rate_dph[ok]) / floor                       # held-out std at 1 s / noise floor
    if reversal:
        c = combine(held, "pair")
        v = np.asarray(c.valid, bool) & serve
        raw = np.std(c.out_dph[v]) / floor                         # mode reversal alone
    else:
        raw = np.std(held.rate_dph[serve]) / floor                 # no model
    assert ratio < most and ratio < 0.15 * raw, (ratio, raw)


def _only(dev, keep):
    """A copy of ``dev`` with every bias zeroed except ``keep`` ('damping' or 'common')."""
    d = copy.deepcopy(dev)
    d.exchange.update(tail_amp_dph=0.0, ring_amp_dph=0.0)
    if keep != "damping":
        d.damping.update(c0=0.0, c1=0.0, c2=0.0, c3=0.0, change_offset_max_dph=0.0)
    if keep != "common":
        d.common.update(e1=0.0, e2=0.0, e3=0.0)
    return d


def test_mode2_sign_convention():
    dev = foreign_device(5)
    for keep in ("damping", "common"):
        d = _only(dev, keep)
        run, floor = _run(d), _run(d, thermal=False)
        m = run.mode
        diff = run.rate_dph - floor.rate_dph        # the bias alone (same noise)
        t = run.t_s
        temps = node_temperatures(d, t, np.interp(t, *_profile(d).T))
        if keep == "damping":
            y = (temps[d.damping_node] - T_REF_C) / T_SCALE_C
            c = d.damping
            sc, off = d.damping_change(0)
            expect = (1 + sc) * (c["c0"] + c["c1"] * y + c["c2"] * y ** 2 + c["c3"] * y ** 3) + off
            np.testing.assert_allclose(diff, expect, atol=1e-9)      # same sign in modes 1, 2 and 3
        else:
            te = temps[d.common_node]
            y = (te - T_REF_C) / T_SCALE_C
            e = d.common
            b_e = e["e1"] * y + e["e2"] * y ** 2 + e["e3"] * np.tanh((te - e["tk_c"]) / e["w_c"])
            s = np.where(m == 2, -1.0, np.where(m == 3, 0.0, 1.0))
            np.testing.assert_allclose(diff, s * b_e, atol=1e-9)       # flips in mode 2, absent in mode 3
            assert np.abs(b_e).max() > 1.0
    # the true rate flips too: the floor run's c = s * rate averages to Omega in both modes
    fl = _run(dev, thermal=False, duration_s=20000.0)
    m = fl.mode
    for k, s in ((1, 1.0), (2, -1.0)):
        assert abs(np.mean(s * fl.rate_dph[m == k]) - dev.omega_dph) < 0.2


def _profile(dev):
    from host_tools.simulation.sim_foreign import chamber_profile
    return chamber_profile(dev, 4.0)


@pytest.mark.parametrize("reversal", [False, True])
def test_floor_run_has_no_bias_and_the_same_noise(reversal):
    dev = foreign_device(3)
    run, floor = _run(dev, reversal, duration_s=None), _run(dev, reversal, duration_s=None, thermal=False)
    np.testing.assert_array_equal(run.columns["freq_hz"], floor.columns["freq_hz"])
    np.testing.assert_array_equal(run.columns["temp_c"], floor.columns["temp_c"])
    assert floor.metadata["thermal"] == "off"
    m = floor.mode
    ok = m != 3
    s = np.where(m == 2, -1.0, 1.0)
    c = (s * floor.rate_dph)[ok]
    # no temperature dependence: the bias run's c follows temperature strongly, the floor's not
    temp = floor["temp_c"][ok]
    r_floor = abs(np.corrcoef(c, temp)[0, 1])
    r_run = abs(np.corrcoef((s * run.rate_dph)[ok] if not reversal else run.rate_dph[ok], temp)[0, 1])
    assert r_floor < 0.3 < r_run
    # effects and the power-on change are zeroed as well: the same floor
    kinds = [k for k in EFFECT_KINDS if reversal or EFFECTS[k].runs != "mr"]
    other = _run(dev, reversal, duration_s=None, thermal=False, effect=kinds, strength=3.0, power_on=4)
    np.testing.assert_array_equal(other.rate_dph, floor.rate_dph)
    # 1-s floor within the documented white-noise range (plus flicker/rrw)
    assert 0.08 < np.std(np.diff(c)) / np.sqrt(2) < 0.6


def _effect_diff(dev, name, reversal=True, strength=1.0, **kw):
    base = _run(dev, reversal, **kw)
    with_e = _run(dev, reversal, effect=name, strength=strength, **kw)
    for col in base.columns:
        if col != "rate_dph":
            np.testing.assert_array_equal(base[col], with_e[col])   # effects touch rate_dph only
    return base, with_e.rate_dph - base.rate_dph


@pytest.mark.parametrize("name", EFFECT_KINDS)
def test_every_effect_changes_the_output_only_as_documented(name):
    dev = foreign_device(7)
    p = dev.effects[name]
    base, d = _effect_diff(dev, name, duration_s=6000.0)
    m, t = base.mode, base.t_s
    s = np.where(m == 2, -1.0, np.where(m == 3, 0.0, 1.0))
    assert np.abs(d).max() > 0.1
    # linear in strength, zero at strength 0
    _, d2 = _effect_diff(dev, name, strength=2.5, duration_s=6000.0)
    np.testing.assert_allclose(d2, 2.5 * d, atol=1e-9)
    _, d0 = _effect_diff(dev, name, strength=0.0, duration_s=6000.0)
    assert np.abs(d0).max() < 1e-12
    # un-flip the flipping kinds: the effect's own term
    ok = m != 3
    term = np.where(ok, d * np.where(s == 0, 1.0, s), 0.0) if EFFECTS[name].flips else d
    if EFFECTS[name].flips:
        assert np.abs(d[m == 3]).max() < 1e-12          # s = 0 in an exchange
    if name == "turn_on":
        np.testing.assert_allclose(term[ok], (p["amp_dph"] * np.exp(-t / p["tau_s"]))[ok], atol=1e-9)
    elif name == "exchange_transient":
        assert np.abs(d[m == 3]).max() == 0.0
        first = np.flatnonzero((m[1:] != 3) & (m[:-1] == 3)) + 1
        assert np.allclose(d[first], p["amp_dph"])     # non-flipping: same sign entering mode 1 and 2
        assert np.abs(d[first + 100]).max() < np.abs(d[first]).max()
    elif name == "imperfect_reversal":
        assert np.abs(d[m != 2]).max() == 0.0 and np.abs(d[m == 2]).min() > 0
    elif name == "aging":
        np.testing.assert_allclose(term[ok], (p["amp_dph"] * (1 - np.exp(-t / p["tau_s"])))[ok], atol=1e-9)
    elif name == "periodic":
        np.testing.assert_allclose(term[ok], (p["amp_dph"] * np.sin(2 * np.pi * t / p["period_s"] + p["phase_rad"]))[ok],
                                   atol=1e-9)
    elif name == "aux":       # exactly linear in the logged aux columns
        X = np.column_stack([base["aux_vdd"], base["aux_acc_x"], base["aux_acc_y"], base["aux_acc_z"], np.ones(len(t))])
        coef, *_ = np.linalg.lstsq(X[ok], term[ok], rcond=None)
        assert np.abs(X[ok] @ coef - term[ok]).max() < 1e-6
        np.testing.assert_allclose(coef[:4], [p["kv_dph_per_v"]] + [g / G0 for g in p["g_dph_per_g"]], rtol=1e-6)
    elif name == "board_temp":  # follows the temp_c sensor (noise/quantization of the sensor aside)
        X = np.column_stack([base["temp_c"] ** k for k in range(3)])
        coef, *_ = np.linalg.lstsq(X[ok], term[ok], rcond=None)
        assert np.std(X[ok] @ coef - term[ok]) < 0.05 * np.std(term[ok])
    elif name == "proxy_high_order":  # a quartic function of the proxy (drive frequency)
        f = base["freq_hz"]
        x = (f - f.mean()) / f.std()
        X = np.column_stack([x ** k for k in range(5)])
        coef, *_ = np.linalg.lstsq(X[ok], term[ok], rcond=None)
        assert np.std(X[ok] @ coef - term[ok]) < 0.02 * np.std(term[ok])
    elif name == "thermal_lag":  # NOT a function of the proxy: hysteresis between the legs
        f = base["freq_hz"]
        x = (f - f.mean()) / f.std()
        X = np.column_stack([x ** k for k in range(6)])
        coef, *_ = np.linalg.lstsq(X[ok], term[ok], rcond=None)
        assert np.std(X[ok] @ coef - term[ok]) > 0.05 * np.std(term[ok])


def test_mr_only_effects_refuse_ftr_runs():
    dev = foreign_device(1)
    for name in EFFECT_KINDS:
        if EFFECTS[name].runs == "mr":
            with pytest.raises(ValueError, match="mode-reversal runs only"):
                _run(dev, False, effect=name)
        else:
            _run(dev, False, effect=name, duration_s=100.0)


@pytest.mark.parametrize("kw, match", [
    ({"effect": "wobble"}, "unknown effect 'wobble'"),
    ({"strength": -1.0}, "strength"),
    ({"strength": float("nan")}, "strength"),
    ({"rate": 0.0}, "chamber rate"),
    ({"power_on": 1.5}, "power_on"),
    ({"noise_seed": -2}, "noise_seed"),
    ({"duration_s": 1.0}, "duration_s"),
])
def test_bad_arguments(kw, match):
    with pytest.raises(ValueError, match=match):
        _run(foreign_device(0), **kw)
    with pytest.raises(ValueError, match="seed"):
        foreign_device(-1)


def test_cli(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert cli.main(["simulate", "--family", "random", "--seed", "4", "--chamber-rate", "5", "--reversal", "off",
                     "--duration", "600", "--effect", "periodic", "--strength", "2", "-o", str(out)]) == 0
    log = runlog.read(out)
    assert len(log) == 601 and not log.reversal and log.metadata["family"] == "random"
    assert "periodic" not in json.dumps(log.metadata)                    # undeclared
    ref = simulate_foreign(4, 5.0, False, 0, 0, 600.0, effect="periodic", strength=2.0)
    np.testing.assert_allclose(log.rate_dph, ref.rate_dph, rtol=1e-6, atol=1e-4)
    capsys.readouterr()
    assert cli.main(["simulate", "--family", "random", "--seed", "4", "--describe"]) == 0
    assert json.loads(capsys.readouterr().out) == foreign_device(4).to_dict()
    for argv, msg in ((["--effect", "wobble"], "unknown effect"), (["--rate", "2"], "--chamber-rate"),
                      (["--scenario", "static"], "belongs to the hdrg family"), (["--seed", "-3"], "seed")):
        assert cli.main(["simulate", "--family", "random", "-o", str(out)] + argv) == 2
        assert msg in capsys.readouterr().err
    assert cli.main(["simulate", "--family", "random", "--list"]) == 0
    listing = capsys.readouterr().out
    assert all(k in listing for k in EFFECT_KINDS)
    # the default family is still the calibrated simulator
    assert cli.main(["simulate", "--scenario", "static", "--duration", "10", "-o", str(out)]) == 0
    assert "family" not in runlog.read(out).metadata


def test_a_lag_starts_soaked_and_is_exact_for_a_ramp():
    """The nodes start soaked at the chamber's first temperature: a lag of a constant is that
    constant from the first sample (not a transient whose size depends on where 0 degC is), and a
    lag of a ramp from a soaked start is the exact first-order response r (t - tau (1 - e^(-t/tau)))."""
    from host_tools.simulation.sim_foreign import lag
    t = np.arange(0.0, 4000.0)
    for tau in (60.0, 500.0, 1500.0):
        assert np.max(np.abs(lag(np.full_like(t, 23.7), tau) - 23.7)) < 1e-12
        r = 0.05
        exact = 20.0 + r * (t - tau * (1.0 - np.exp(-t / tau)))
        assert np.max(np.abs(lag(20.0 + r * t, tau) - exact)) < 1e-9
    quiet = copy.deepcopy(foreign_device(3))
    quiet.self_heating["rise_c"] = 0.0
    assert all(np.max(np.abs(x - 20.0)) < 1e-12 for x in node_temperatures(quiet, t, np.full_like(t, 20.0)))


def test_sparse_sequence_layout_and_bad_arguments():
    """Power-on exchange, a mode-1 reference window, then an excursion (exchange, mode 2, exchange)
    every period from exchange_s + window_s; mode 1 everywhere else."""
    from host_tools.simulation.sim_physics import sparse_sequence
    t = np.arange(4000.0)
    m = sparse_sequence(t, 30.0, 45.0, 1200.0)
    assert (m[:30] == 3).all() and (m[30:75] == 1).all()
    for start in (75, 1275, 2475, 3675):
        assert (m[start:start + 30] == 3).all() and (m[start + 30:start + 75] == 2).all()
        assert (m[start + 75:start + 105] == 3).all() and m[start + 105] == 1
    assert set(np.unique(m[180:1275])) == {1} and np.count_nonzero(m == 2) == 4 * 45
    with pytest.raises(ValueError, match="period_s 150 s is shorter than an excursion"):
        sparse_sequence(t, 30.0, 45.0, 150.0)
    with pytest.raises(ValueError, match="window_s must be > 0"):
        sparse_sequence(t, 30.0, 0.0, 1200.0)


def test_an_explicit_schedule_keeps_the_physics():
    """A run in mode 1 throughout (explicit modes) is the FTR run of the same power-on and noise
    seed sample for sample (same temperatures, noise, bias; no exchange, no settling tail); in mode
    2 throughout, c = -rate keeps the flipping terms and negates the others."""
    dev = foreign_device(5)
    n = int(DUR) + 1
    ftr = _run(dev, reversal=False)
    one = _run(dev, modes=np.ones(n, int))
    two = _run(dev, modes=np.full(n, 2))
    floor_one = _run(dev, modes=np.ones(n, int), thermal=False)
    floor_two = _run(dev, modes=np.full(n, 2), thermal=False)
    assert (one.mode == 1).all() and one.metadata["schedule"] == "explicit" and "dwell_s" not in one.metadata
    np.testing.assert_array_equal(one.rate_dph, ftr.rate_dph)
    # rate = s (omega + flip) + keep + noise; the floor runs hold omega and the noise alone
    keep = (one.rate_dph + two.rate_dph) / 2 - (floor_one.rate_dph + floor_two.rate_dph) / 2
    flip = (one.rate_dph - two.rate_dph) / 2 - (floor_one.rate_dph - floor_two.rate_dph) / 2
    assert np.std(keep) > 1.0 and np.std(flip) > 0.1     # both kinds of bias are there
    np.testing.assert_allclose(ftr.rate_dph - floor_one.rate_dph, flip + keep, atol=1e-9)


@pytest.mark.parametrize("kw, match", [
    (dict(reversal=False, modes=np.ones(3001, int)), "needs reversal on"),
    (dict(modes=np.ones(10, int)), r"\(10,\) values for a run of 3001 samples"),
    (dict(modes=np.r_[np.ones(100, int), 0, np.ones(2900, int)]), "sample 100 has mode 0"),
])
def test_bad_explicit_schedules(kw, match):
    with pytest.raises(ValueError, match=match):
        _run(foreign_device(5), **kw)
