"""Tests of host_tools.fitting.metrics: every statistic against an independent numpy computation."""
from __future__ import annotations

import json
import os
import warnings

import numpy as np
from pathlib import Path
import pytest

from host_tools.fitting import metrics
from host_tools.cli import main
from host_tools.golden.runlog import RunLog, RunLogError, RunLogWarning, write

MEASURED = str(Path(__file__).parent / "data" / "psim-tvac-lsm6dsm")
MEASURED_X = os.path.join(MEASURED, "psim-tvac-x.csv")
MEASURED_Y = os.path.join(MEASURED, "psim-tvac-y.csv")


def _np_stats(means):
    means = np.asarray(means)
    return np.max(means) - np.min(means), np.std(means, ddof=1), np.mean(means)


def _check(row, means):
    pp, sd, mu = _np_stats(means)
    assert row["supported"] and row["bins"] == len(means)
    assert row["variation_dph"] == pytest.approx(pp, rel=1e-12, abs=1e-12)
    assert row["stability_dph"] == pytest.approx(sd, rel=1e-12, abs=1e-12)
    assert row["mean_dph"] == pytest.approx(mu, rel=1e-12, abs=1e-12)


def _ftr_log(t, rate, **extra):
    return RunLog.from_arrays(t_s=np.asarray(t, float), rate_dph=np.asarray(rate, float),
                              temp_c=np.full(len(t), 25.0), **extra)


# -- bias statistics ------------------------------------------------------------------------

def test_square_wave_known_answer():
    A, mu = 3.0, 0.7
    t = np.arange(200.0)                                  # 1 Hz, 200 s
    out = mu + A * np.where((t // 10) % 2 == 0, 1.0, -1.0)  # period 20 s
    m = metrics.bias_metrics(out, t, np.ones(200, bool), taus=(1, 10, 20))
    r1, r10, r20 = m["per_tau"]
    # tau = 1 s: the samples themselves; analytic pp = 2A, 1 sigma = A sqrt(N/(N-1))
    assert r1["variation_dph"] == pytest.approx(2 * A)
    assert r1["stability_dph"] == pytest.approx(A * np.sqrt(200 / 199))
    assert r1["mean_dph"] == pytest.approx(mu)
    assert r1["bins"] == 200
    # tau = 10 s: bins align with half periods -> +-A, 20 bins
    assert r10["bins"] == 20
    assert r10["variation_dph"] == pytest.approx(2 * A)
    assert r10["stability_dph"] == pytest.approx(A * np.sqrt(20 / 19))
    # tau = 20 s: one full period per bin -> all equal mu
    assert r20["bins"] == 10
    assert r20["variation_dph"] == pytest.approx(0, abs=1e-12)
    assert r20["stability_dph"] == pytest.approx(0, abs=1e-12)
    assert r20["mean_dph"] == pytest.approx(mu)
    assert metrics.at_tau(m, 10) is r10


@pytest.mark.parametrize("n, last_used", [(205, True), (204, False)])
def test_random_blocks_and_min_fill(n, last_used):
    rng = np.random.default_rng(1)
    out = rng.normal(5, 2, n)
    t = 100.0 + np.arange(n)
    m = metrics.bias_metrics(out, t, np.ones(n, bool), taus=(10,))
    full = out[: n // 10 * 10].reshape(-1, 10).mean(axis=1)
    tail = out[n // 10 * 10:]                       # 5 samples = 50 % (used), 4 = 40 % (dropped)
    expected = np.append(full, tail.mean()) if last_used else full
    _check(m["per_tau"][0], expected)
    assert m["per_tau"][0]["min_count"] == 5
    assert m["mean_dph"] == pytest.approx(out.mean())


def test_bins_by_time_with_a_gap():
    rng = np.random.default_rng(2)
    t = np.concatenate([np.arange(0.0, 25.0), np.arange(1003.0, 1028.0)])   # 25 s, 978-s gap, 25 s
    out = rng.normal(0, 1, 50) + np.where(t > 500, 40.0, 0.0)
    m = metrics.bias_metrics(out, t, np.ones(50, bool), taus=(10, 100))
    r10, r100 = m["per_tau"]
    sl = [(0, 10), (10, 20), (20, 25), (25, 35), (35, 45), (45, 50)]   # grid restarts after the gap
    _check(r10, [out[a:b].mean() for a, b in sl])
    # binning by sample count would straddle the gap and give other numbers
    by_count = out[:50].reshape(-1, 10).mean(axis=1)
    assert r10["variation_dph"] != pytest.approx(np.ptp(by_count))
    # no 100-s bin is half full: not supported, numbers None with a reason
    assert not r100["supported"] and r100["bins"] == 0
    assert r100["variation_dph"] is None and r100["stability_dph"] is None and r100["mean_dph"] is None
    assert "not supported" in r100["reason"]


def test_invalid_samples_never_enter():
    rng = np.random.default_rng(3)
    t = np.arange(300.0)
    out = rng.normal(1, 1, 300)
    valid = np.ones(300, bool)
    valid[40:47] = False
    valid[150:230] = False                      # whole bins invalid
    garbage = out.copy()
    garbage[~valid] = 1e12
    a = metrics.bias_metrics(out, t, valid)
    b = metrics.bias_metrics(garbage, t, valid)
    assert a == b
    # independent: 10-s bins [0,10), ... over valid samples, >= 5 valid samples each
    exp = []
    for k in range(30):
        sel = valid[10 * k:10 * k + 10]
        if sel.sum() >= 5:
            exp.append(out[10 * k:10 * k + 10][sel].mean())
    _check(metrics.at_tau(b, 10), exp)
    _check(metrics.at_tau(b, 1), out[valid])
    assert b["n_valid"] == valid.sum()
    assert b["mean_dph"] == pytest.approx(out[valid].mean())


def test_tau_shorter_than_step_and_no_valid():
    t = np.arange(0.0, 100.0, 2.0)
    m = metrics.bias_metrics(np.ones(50), t, np.ones(50, bool), taus=(1, 4))
    assert not m["per_tau"][0]["supported"] and "shorter than the sample step" in m["per_tau"][0]["reason"]
    assert m["per_tau"][1]["supported"]
    m = metrics.bias_metrics(np.ones(50), t, np.zeros(50, bool), taus=(4,))
    assert m["per_tau"][0]["reason"] == "no valid samples" and m["mean_dph"] is None


# -- mode-reversal logs -------------------------------------------------------------------

def _mr_log(exchange_value, seed=4):
    """1 Hz MR log: [3]*5 + [1]*20 + [3]*5 + [2]*20, four times; B_D reverses, B_E flips with the axes."""
    rng = np.random.default_rng(seed)
    pattern = [3] * 5 + [1] * 20 + [3] * 5 + [2] * 20
    mode = np.array(pattern * 4, np.int64)
    n = len(mode)
    t = np.arange(n, dtype=float)
    b_e = 2.0 + 0.01 * t                      # non-reversing: flips sign in mode 2
    b_d = 50.0 + 0.05 * t                     # damping asymmetry: does not flip
    s = np.where(mode == 2, -1.0, 1.0)
    rate = s * b_e + b_d + rng.normal(0, 0.5, n)
    rate[mode == 3] = exchange_value
    return RunLog.from_arrays(t_s=t, rate_dph=rate, mode=mode, temp_c=np.full(n, 25.0)), mode, rate


def _pair_by_hand(mode, rate):
    """The pairing combiner written from its definition, window by window."""
    out = np.zeros(len(mode))
    valid = np.zeros(len(mode), bool)
    last = {}
    edges = np.flatnonzero(np.diff(mode)) + 1
    for a, b in zip(np.r_[0, edges], np.r_[edges, len(mode)]):
        m = mode[a]
        if m not in (1, 2):
            continue
        c = (1.0 if m == 1 else -1.0) * rate[a:b]
        if 3 - m in last:
            out[a:b] = (c + last[3 - m]) / 2
            valid[a:b] = True
        last[m] = c.mean()
    return out, valid


def test_default_combiner_is_the_fit_default():
    """metrics' default combiner is the one hdrg fit uses (reversal.DEFAULT_COMBINER)."""
    from host_tools.golden import reversal
    from host_tools.cli import build_parser

    log = _mr_log(0.0)[0]
    r = metrics.run_metrics(log, taus=(1, 10))
    assert r["combiner"] == reversal.DEFAULT_COMBINER
    parser = build_parser()
    fit_args = parser.parse_args(["fit", "a.csv", "-o", "m.json"])
    met_args = parser.parse_args(["metrics", "a.csv"])
    assert fit_args.combiner is None  # resolved by fit_config_from_logs to the default below
    assert met_args.combiner is None  # resolved to reversal.DEFAULT_COMBINER in run_metrics
    from host_tools.golden.compensate import fit_config_from_logs
    cfg = fit_config_from_logs([log], reversal={"combiner": fit_args.combiner}, proxy_range=(0.0, 50.0), rate_range=1.0)
    assert cfg.reversal.combiner == reversal.DEFAULT_COMBINER
    same = metrics.run_metrics(log, taus=(1, 10), combiner=cfg.reversal.combiner)
    assert same["per_tau"] == r["per_tau"]


def test_reversal_log_uses_pair_combiner():
    pytest.importorskip("host_tools.golden.reversal")
    from host_tools.golden import reversal

    log, mode, rate = _mr_log(1e9)
    exp_out, exp_valid = _pair_by_hand(mode, rate)
    comb = reversal.combine(log, combiner="pair")
    assert np.array_equal(comb.valid, exp_valid)
    assert np.allclose(comb.out_dph[exp_valid], exp_out[exp_valid], rtol=0, atol=1e-9)
    r = metrics.run_metrics(log, taus=(1, 10), combiner="pair")
    assert r["kind"] == "reversal" and r["combiner"] == "pair"
    ref = metrics.bias_metrics(exp_out, log.t_s, exp_valid, taus=(1, 10))
    for got, exp in zip(r["per_tau"], ref["per_tau"]):
        for key in ("bins", "variation_dph", "stability_dph", "mean_dph"):
            assert got[key] == pytest.approx(exp[key], rel=1e-9, abs=1e-9)
    # 1-s figures are the valid combined samples themselves
    _check(metrics.at_tau(r, 1), exp_out[exp_valid])
    # the combined output cancels B_D (~50 deg/h): its mean is near B_E (2..4 deg/h)
    assert 1.0 < r["mean_dph"] < 5.0


def test_exchange_garbage_moves_nothing():
    pytest.importorskip("host_tools.golden.reversal")
    a = metrics.run_metrics(_mr_log(1e9)[0])
    b = metrics.run_metrics(_mr_log(-7.0)[0])
    c = metrics.run_metrics(_mr_log(-3e12)[0])
    assert a["per_tau"] == b["per_tau"] == c["per_tau"]
    assert a["allan"] == b["allan"] == c["allan"]
    assert a["mean_dph"] == b["mean_dph"] and a["n_valid"] == b["n_valid"]
    assert all(abs(v) < 100 for v in a["allan"]["adev_dph"])


def test_trend_combiner_passed_through():
    pytest.importorskip("host_tools.golden.reversal")
    log = _mr_log(0.0)[0]
    p = metrics.run_metrics(log, combiner="pair")
    tr = metrics.run_metrics(log, combiner="trend")
    assert tr["combiner"] == "trend"
    assert tr["mean_dph"] != p["mean_dph"]


# -- compensated logs -----------------------------------------------------------------------

def _comp_log(seed=5):
    rng = np.random.default_rng(seed)
    n = 400
    t = np.arange(n, dtype=float)
    out = rng.normal(0.1, 0.3, n)
    valid = np.ones(n)
    valid[:37] = 0
    valid[200:215] = 0
    out[valid == 0] = 5e8
    log = RunLog.from_arrays(metadata={"compensated": "yes"}, t_s=t, rate_dph=out, temp_c=np.full(n, 20.0),
                             bias_dph=rng.normal(size=n), valid=valid)
    return log, out, valid.astype(bool)


def test_compensated_uses_valid(tmp_path):
    log, out, valid = _comp_log()
    r = metrics.run_metrics(log)
    assert r["kind"] == "compensated" and r["combiner"] is None
    ref = metrics.bias_metrics(out, log.t_s, valid)
    assert r["per_tau"] == ref["per_tau"]
    assert r["n_valid"] == valid.sum() and r["mean_dph"] == pytest.approx(out[valid].mean())
    _check(metrics.at_tau(r, 1), out[valid])
    # the same through a CSV file
    path = tmp_path / "comp.csv"
    write(log, path)
    assert metrics.run_metrics(str(path))["per_tau"] == r["per_tau"]


def test_compensated_bad_valid_column():
    log, out, valid = _comp_log()
    bad = log.with_columns(valid=np.where(valid, 1.0, 2.0))
    with pytest.raises(RunLogError, match="'valid' must be 0 or 1"):
        metrics.run_metrics(bad)
    cols = {k: v for k, v in log.columns.items() if k != "valid"}
    with pytest.raises(RunLogError, match="lacks the column 'valid'"):
        metrics.run_metrics(RunLog(cols, {"compensated": "yes"}))


# -- Allan deviation --------------------------------------------------------------------------

def test_allan_white_noise():
    sigma = 3.0
    x = np.random.default_rng(6).normal(0, sigma, 1 << 14)
    t = np.arange(len(x), dtype=float)
    a = metrics.allan(x, t, np.ones(len(x), bool))
    taus, adev = np.array(a["tau_s"]), np.array(a["adev_dph"])
    assert taus[0] == 1.0 and np.all(np.diff(np.log2(taus)) == 1)       # octave taus at 1 Hz
    sel = taus <= 64
    assert np.allclose(adev[sel], sigma / np.sqrt(taus[sel]), rtol=0.1)
    slope = np.polyfit(np.log(taus[sel]), np.log(adev[sel]), 1)[0]
    assert slope == pytest.approx(-0.5, abs=0.05)
    # the same numbers read as *phase* would give a -1 slope: data_type='freq' is used
    import allantools
    tp, ap, _, _ = allantools.oadev(x, rate=1.0, data_type="phase", taus=taus[sel])
    assert np.polyfit(np.log(tp), np.log(ap), 1)[0] < -0.8
    assert a["arw_method"] == "adev_at_1s"
    assert a["arw_deg_rth"] == pytest.approx(sigma / 60, rel=0.03)
    assert a["arw_fit_deg_rth"] == pytest.approx(sigma / 60, rel=0.05)
    assert a["bi_at_edge"] is True                          # white noise: no floor reached


def test_allan_rate_and_1s_tau():
    sigma, fs = 2.0, 10.0
    x = np.random.default_rng(7).normal(0, sigma, 20000)
    t = np.arange(len(x)) / fs
    a = metrics.allan(x, t, np.ones(len(x), bool))
    taus, adev = np.array(a["tau_s"]), np.array(a["adev_dph"])
    assert taus[0] == pytest.approx(0.1) and np.any(np.isclose(taus, 1.0, rtol=1e-12))
    # sigma(tau) = sigma / sqrt(tau * fs); ARW = sigma(1 s) / 60
    assert a["adev_1s_dph"] == pytest.approx(sigma / np.sqrt(fs), rel=0.05)
    assert a["arw_deg_rth"] == pytest.approx(sigma / np.sqrt(fs) / 60, rel=0.05)
    assert np.allclose(adev[taus <= 50], sigma / np.sqrt(taus[taus <= 50] * fs), rtol=0.12)


def test_allan_bias_instability_known_minimum():
    # white noise sigma plus a rate ramp R: ADEV^2 = sigma^2/tau + R^2 tau^2 / 2, minimum at
    # tau* = (sigma^2 / R^2)^(1/3) = 16 s for sigma = 1, R = 1/64
    sigma, ramp = 1.0, 1.0 / 64
    n = 1 << 13
    t = np.arange(n, dtype=float)
    x = np.random.default_rng(8).normal(0, sigma, n) + ramp * t
    a = metrics.allan(x, t, np.ones(n, bool))
    expected_min = np.sqrt(sigma ** 2 / 16 + ramp ** 2 * 16 ** 2 / 2)
    assert a["bias_instability_dph"] == pytest.approx(expected_min / 0.664, rel=0.1)
    assert a["bi_tau_s"] in (8.0, 16.0, 32.0) and a["bi_at_edge"] is False


def test_allan_stretches_pooled_not_concatenated():
    # valid stretches at very different levels: a difference across a break would dominate
    sigma = 1.0
    rng = np.random.default_rng(9)
    n = 6000
    t = np.arange(n, dtype=float)
    x = rng.normal(0, sigma, n) + 1000.0 * ((t // 500) % 2)
    valid = (t % 500) >= 20                                   # 20 invalid samples at each step
    a = metrics.allan(x, t, valid)
    assert a["stretches"] == 12 and a["longest_s"] == pytest.approx(480)
    taus, adev = np.array(a["tau_s"]), np.array(a["adev_dph"])
    assert np.allclose(adev, sigma / np.sqrt(taus), rtol=0.2)
    # a time gap also breaks a stretch
    t2 = t + 1000.0 * (t >= 3000)
    x2 = x.copy()
    x2[t >= 3000] += 5e4
    b = metrics.allan(x2, t2, valid)
    assert b["stretches"] == 12 and np.allclose(b["adev_dph"], a["adev_dph"])


def test_allan_too_short():
    a = metrics.allan(np.ones(5), np.arange(5.0), np.array([1, 1, 0, 1, 1], bool))
    assert a["reason"] and a["adev_dph"] == [] and a["arw_deg_rth"] is None


# -- repeatability ----------------------------------------------------------------------------

def test_repeatability():
    rng = np.random.default_rng(10)
    runs, means = [], []
    for k in range(4):
        x = rng.normal(k * 0.3, 1, 300)
        runs.append(metrics.bias_metrics(x, np.arange(300.0), np.ones(300, bool), taus=(10, 100)))
        means.append(x.mean())
    rep = metrics.repeatability(runs)
    assert rep["n_runs"] == 4
    assert rep["repeatability_dph"] == pytest.approx(np.std(means, ddof=1))
    m100 = [metrics.at_tau(r, 100)["mean_dph"] for r in runs]
    assert rep["per_tau"][1]["repeatability_dph"] == pytest.approx(np.std(m100, ddof=1))
    assert metrics.repeatability(runs[:1])["repeatability_dph"] is None


# -- the measured bursty logs -----------------------------------------------------------------

@pytest.fixture(scope="module")
def measured_x():
    if not os.path.exists(MEASURED_X):
        pytest.skip("measured data not present")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RunLogWarning)
        log = metrics.load(MEASURED_X)
    return log, metrics.run_metrics(log)


def test_measured_bursty(measured_x):
    log, r = measured_x
    r1, r10, r100 = r["per_tau"]
    for row in (r1, r10):
        assert row["supported"]
        assert all(np.isfinite(row[k]) for k in ("variation_dph", "stability_dph", "mean_dph"))
    # 10-s bins: one per 5-s burst, i.e. the burst means (independent: via the log's segments)
    bounds = np.r_[log.segments, len(log)]
    bursts = [log.rate_dph[a:b].mean() for a, b in zip(bounds[:-1], bounds[1:])]
    _check(r10, bursts)
    assert r10["fill_median"] == pytest.approx(0.5, abs=0.02)
    assert len(bursts) * 4 <= r1["bins"] <= len(bursts) * 6
    # 100 s: explicitly not supported, no number
    assert not r100["supported"] and r100["variation_dph"] is None and "not supported" in r100["reason"]
    a = r["allan"]
    assert a["stretches"] == len(bursts) and np.isfinite(a["arw_deg_rth"]) and a["arw_method"] == "adev_at_1s"
    assert any("gap-free segments" in n for n in r["notes"])


# -- CLI ------------------------------------------------------------------------------------------

def test_cli_table_and_json(tmp_path, capsys):
    log, out, valid = _comp_log()
    p1, p2 = tmp_path / "a.csv", tmp_path / "b.npz"
    write(log, p1)
    write(_ftr_log(np.arange(300.0), np.random.default_rng(11).normal(2, 1, 300)), p2)
    assert main(["metrics", str(p1), str(p2), "--tau", "1,10,100"]) == 0
    text = capsys.readouterr().out
    rows = [ln.split() for ln in text.splitlines() if ln.startswith(("a.csv", "b.npz"))]
    assert [(r[0], r[2]) for r in rows[:6]] == [(f, tau) for f in ("a.csv", "b.npz") for tau in ("1", "10", "100")]
    assert "repeatability" in text and "tau = 100 s" in text
    # --json on stdout
    assert main(["metrics", str(p1), str(p2), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    ref = metrics.run_metrics(str(p1))
    assert [r["tau_s"] for r in doc["runs"][0]["per_tau"]] == [1.0, 10.0, 100.0]
    assert doc["runs"][0]["per_tau"][2]["stability_dph"] == pytest.approx(ref["per_tau"][2]["stability_dph"])
    assert doc["runs"][1]["kind"] == "ftr"
    assert doc["repeatability"]["repeatability_dph"] == pytest.approx(
        np.std([doc["runs"][0]["mean_dph"], doc["runs"][1]["mean_dph"]], ddof=1))
    # --json FILE: file written, table still printed
    jf = tmp_path / "m.json"
    assert main(["metrics", str(p1), "--tau", "5", "--json", str(jf)]) == 0
    assert "a.csv" in capsys.readouterr().out
    assert json.loads(jf.read_text())["runs"][0]["per_tau"][0]["tau_s"] == 5.0


def test_cli_measured_unsupported_tau(measured_x, capsys):
    assert main(["metrics", MEASURED_X, "--json"]) == 0
    row = json.loads(capsys.readouterr().out)["runs"][0]["per_tau"][2]
    assert row["tau_s"] == 100.0 and row["stability_dph"] is None and "not supported" in row["reason"]


@pytest.mark.parametrize("kind", ["text", "binary_npz", "missing", "directory", "json_over_csv"])
def test_cli_not_a_run_log(tmp_path, capsys, kind):
    if kind == "text":
        p = tmp_path / "notes.txt"
        p.write_text("hello world\nthis is not a run log\n")
    elif kind == "binary_npz":
        p = tmp_path / "junk.npz"
        p.write_bytes(b"\x00\x01garbage" * 10)
    elif kind == "missing":
        p = tmp_path / "nope.csv"
    elif kind == "directory":
        p = tmp_path
    else:
        p = tmp_path / "a.csv"
        write(_ftr_log(np.arange(10.0), np.zeros(10)), p)
    args = ["metrics", str(p), "--json", str(p)] if kind == "json_over_csv" else ["metrics", str(p)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("hdrg metrics: error:") and str(p) in err
    if kind == "json_over_csv":
        assert "refusing" in err and p.read_text().count("\n") == 11     # the run log is untouched


def test_cli_bad_tau():
    with pytest.raises(SystemExit) as exc:
        main(["metrics", "x.csv", "--tau", "1,-3"])
    assert exc.value.code == 2


def test_compensated_log_flags_reach_the_notes():
    """metrics of a compensated log repeats its flag counts and the extrapolation warning."""
    n = 200
    flags = np.zeros(n, np.int64)
    flags[:50] = 1                       # proxy_clamped on 25 % of the samples
    flags[60] = 4                        # warm-up
    log = RunLog.from_arrays({"compensated": "yes"}, t_s=np.arange(float(n)),
                             rate_dph=np.random.default_rng(0).normal(size=n),
                             temp_c=np.zeros(n), bias_dph=np.zeros(n), valid=(flags != 4).astype(float),
                             flags=flags)
    notes = metrics.run_metrics(log, taus=(1,))["notes"]
    assert "flags: proxy_clamped 50, warmup 1" in notes
    assert any("extrapolation: 50 of 200 samples (25.0 %) proxy_clamped" in s for s in notes)
    clean = metrics.run_metrics(log.with_columns(flags=np.zeros(n, np.int64)), taus=(1,))["notes"]
    assert "flags: none" in clean and not any("extrapolation" in s for s in clean)


def test_raw_log_input_invalid_sample_is_left_out():
    """A raw mode-reversal log with one 1e9 deg/h sample in a mode-1 window: the sample is
    input-invalid (host_tools.golden.input_check): it is not valid, its window is never committed
    (the next mode-2 window pairs with the older clean mode-1 window), and the
    mode-reversal-alone figure stays near the clean log's (before: that window's mean, 5e7 deg/h,
    went into every pairing with it); an FTR log leaves the sample out."""
    log, mode, rate = _mr_log(0.0)
    spiked = rate.copy()
    row = 5 + 50 + 7                                    # the second mode-1 window
    assert mode[row] == 1
    spiked[row] = 1e9
    r = metrics.run_metrics(log.with_columns(rate_dph=spiked), taus=(1, 10))
    clean = metrics.run_metrics(log, taus=(1, 10))
    assert abs(r["mean_dph"] - clean["mean_dph"]) < 1.0 and max(abs(v) for v in r["allan"]["adev_dph"]) < 100
    assert r["n_valid"] == clean["n_valid"] - 1
    assert any(n.startswith("input: 1 of 200 samples") and "first row 62" in n for n in r["notes"])
    assert not any(n.startswith("input:") for n in clean["notes"])
    ftr = _ftr_log(np.arange(100.0), np.r_[np.ones(50), 1e9, np.ones(49)])
    f = metrics.run_metrics(ftr, taus=(1, 10))
    assert f["n_valid"] == 99 and f["mean_dph"] == pytest.approx(1.0)
