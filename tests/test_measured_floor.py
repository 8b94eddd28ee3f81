"""The default fit on measured data against the flight stack's cubic (host_tools.bench.measured),
what the training runs identify (host_tools.fitting.legs), and the guard of
host_tools.fitting.fit_pipeline.fit_default."""
from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from host_tools.golden import runlog as rl
from host_tools.golden.runlog import RunLog

ROOT = Path(__file__).resolve().parents[1]
TOFU = ROOT / "tests" / "data" / "tofupilot-imu-thermal"


def _read(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rl.read(path)


def _ftr(t, temp, rate):
    return RunLog.from_arrays({"sample_rate_hz": "1"}, source="<test>", t_s=np.asarray(t, float),
                              rate_dph=np.asarray(rate, float), temp_c=np.asarray(temp, float),
                              mode=np.zeros(len(t), np.int64))


def _cycle(n_cycles, seed=0, hyst=0.0):
    """An FTR chamber profile of n_cycles triangle cycles -20..60 degC at 2 degC/min (1 Hz) with a
    cubic bias in temperature, a hysteresis term hyst x sign(dT/dt) and white noise."""
    rng = np.random.default_rng(seed)
    period = 2 * 80 / 2.0 * 60.0                      # s per cycle
    t = np.arange(int(n_cycles * period), dtype=float)
    phase = (t % period) / period
    temp = np.where(phase < 0.5, 60 - 160 * phase, -20 + 160 * (phase - 0.5))
    dtemp = np.gradient(temp)
    bias = 3.0 + 0.8 * temp - 0.01 * temp ** 2 + hyst * np.sign(dtemp) + rng.normal(0, 1.0, len(t))
    return _ftr(t, temp, bias)


def test_legs_of_the_measured_cycle_are_cool_heat_cool():
    from host_tools.fitting.legs import find_legs
    log = _read(TOFU / "tofupilot-imu-y.csv")
    legs = find_legs(log.t_s, log["temp_c"])
    assert [s for _, _, s in legs] == [-1, 1, -1]
    assert legs[0][0] == 0 and legs[-1][1] == len(log)
    assert all(nxt[0] == prev[1] for prev, nxt in zip(legs, legs[1:]))     # contiguous, complete
    lo = int(np.argmin(log["temp_c"]))
    assert abs(legs[1][0] - lo) < 60                   # the turn at the coldest point (0.5-s samples)


def test_one_sign_of_dT_dt_does_not_identify_the_rate_terms_and_says_what_would():
    from host_tools.fitting.legs import identifiability
    log = _read(TOFU / "tofupilot-imu-y.csv")
    lo = int(np.argmin(log["temp_c"]))
    cooling = log.select(np.arange(lo))
    ident = identifiability([cooling])
    assert ident["rate_terms_identified"] is False
    rate = ident["groups"]["rate"]
    assert not rate["identified"] and "heating" in rate["record"]
    # a full cycle has one heating leg: identified; the fold that holds it out scores the rate terms
    # on a sign they were not fitted on, and it says what would help
    ident = identifiability([log])
    assert ident["legs_per_sign"] == {"rising": 1, "falling": 2, "hold": 0}
    assert ident["rate_terms_identified"] and not ident["rate_cv_extrapolated"]
    assert "another full chamber cycle" in ident["groups"]["rate"]["record"]
    # one leg of each sign: every fold does
    hi = int(np.argmax(log["temp_c"]))
    ident = identifiability([log.select(np.arange(lo, hi)), log.select(np.arange(hi, len(log)))])
    assert ident["legs_per_sign"] == {"rising": 1, "falling": 1, "hold": 0} and ident["rate_cv_extrapolated"]
    # two full cycles: nothing to add
    ident = identifiability([_cycle(2)])
    assert ident["rate_terms_identified"] and not ident["rate_cv_extrapolated"]
    assert ident["groups"]["rate"]["record"] == ""


def test_unidentified_rate_terms_give_the_cubic_clamped_to_the_calibrated_range():
    from host_tools.fitting.baseline import fit_baseline
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.compensate import compensate
    log = _read(TOFU / "tofupilot-imu-y.csv")
    lo = int(np.argmin(log["temp_c"]))
    cooling, heating = log.select(np.arange(lo)), log.select(np.arange(lo, len(log)))
    model, _ = fit_default([cooling])
    assert tuple(model.terms) == (0, 1, 2, 3)
    assert model.fit["identifiability"]["restricted_to"] == [0, 1, 2, 3]
    assert model.fit["guard"]["chosen"] == "cubic in the proxy"
    base = fit_baseline([cooling])
    a, b = compensate(heating, model), compensate(heating, base)
    np.testing.assert_allclose(a.rate_dph[a["valid"] > 0], b.rate_dph[a["valid"] > 0], atol=1e-6)
    # explicit terms are the user's: kept
    model, _ = fit_default([cooling], [0, 1, 4])
    assert tuple(model.terms) == (0, 1, 4)


def test_one_leg_of_each_sign_asks_the_rate_terms_to_halve_the_cubics_error():
    """Legs as runs, one heating and one cooling (the measured consumer IMU): the guard's margin is
    GUARD_MARGIN_EXTRAPOLATED and its choice follows its own figures; the whole cycle (two cooling
    legs) gets GUARD_MARGIN."""
    from host_tools.fitting.fit_pipeline import GUARD_MARGIN, GUARD_MARGIN_EXTRAPOLATED, fit_default
    log = _read(TOFU / "tofupilot-imu-x.csv")
    lo, hi = int(np.argmin(log["temp_c"])), int(np.argmax(log["temp_c"]))
    for runs, margin in (([log.select(np.arange(lo, hi)), log.select(np.arange(hi, len(log)))], GUARD_MARGIN_EXTRAPOLATED),
                         ([log], GUARD_MARGIN)):
        model, _ = fit_default(runs)
        g = model.fit["guard"]
        assert g["margin"] == margin and g["folds"] == len(runs) + (len(runs) == 1) * 2
        best_cubic = min(v for k, v in g["cv_rms"].items() if k != "17-term model")
        kept = g["cv_rms"]["17-term model"] < (1 - margin) * best_cubic
        assert (g["chosen"] == "17-term model") == kept


def test_the_guard_keeps_the_rate_terms_when_they_generalize_and_drops_them_when_not():
    from host_tools.fitting.fit_pipeline import fit_default
    # hysteresis of 8 deg/h against 1 deg/h noise, two cycles: the 17-term model is kept
    model, _ = fit_default([_cycle(2, hyst=8.0)])
    g = model.fit["guard"]
    assert g["chosen"] == "17-term model", g
    assert g["cv_rms"]["17-term model"] < 0.5 * g["cv_rms"]["cubic in the temperature sensor (flight stack)"]
    assert any(k >= 4 and k != 7 for k in model.terms) or 7 in model.terms
    # no rate effect at all: whatever the 17-term pipeline selects, the guard's choice is reported
    model, _ = fit_default([_cycle(2, seed=1)])
    g = model.fit["guard"]
    assert set(g["cv_rms"]) == {"17-term model", "cubic in the temperature sensor (flight stack)"}
    assert g["folds"] >= 4 and g["scored"] > 0
    if g["chosen"] != "17-term model":
        assert tuple(model.terms) == (0, 1, 2, 3) and "replaced" in g


def test_leg_cv_counts_what_it_does_not_score():
    from host_tools.fitting.legs import leg_cv
    from host_tools.golden.compensate import fit_config_from_logs
    log = _cycle(2)
    cfg = fit_config_from_logs([log], proxy_kind="temp")
    out = leg_cv([log], {"cubic": (cfg, (0, 1, 2, 3)), "k0": (cfg, (0,))}, "temp")
    assert out["folds"] >= 4
    assert out["scored"] + out["out_of_range"] <= len(log)
    assert out["cv_rms"]["cubic"] < out["cv_rms"]["k0"]
    assert out["cv_rms"]["cubic"] == pytest.approx(1.0, rel=0.15)     # the white noise, offsets removed
    # a leg beyond every other leg's range is counted, not scored
    half = log.select(np.arange(len(log) // 4))                          # one falling leg alone
    assert leg_cv([half], {"cubic": (cfg, (0, 1, 2, 3))}, "temp") is None


def test_run_offsets_need_overlapping_runs():
    from host_tools.fitting.fit_pipeline import offsets_identifiable
    log = _cycle(1)
    n = len(log)
    hot, cold = log.select(np.arange(n // 8)), log.select(np.arange(3 * n // 8, n // 2))
    assert "overlaps" in offsets_identifiable([hot, cold], "temp")
    assert offsets_identifiable([log, _cycle(1, seed=3)], "temp") is None


def test_bench_measured_never_loses_to_the_cubic_on_the_shipped_sets():
    """`hdrg bench measured` on the shipped measured sets: every split's held-out std of 100-s
    means of the default fit within 1.05 x the flight stack's cubic; valid share >= 99 %."""
    from host_tools.bench.measured import run, table
    result = run()
    s = result["summary"]
    assert s["splits"] == 22                        # 2 x 9 tofupilot (6 by leg + 3 leave-one-out) + 2 x 2 psim
    assert s["max_ratio"] <= 1.05, table(result)
    assert s["min_valid_share"] >= 0.99
    names = {(r["log"], " + ".join(r["train"]), r["held_out"]) for r in result["rows"]}
    assert ("tofupilot-imu-x", "cool1 + cool2", "heat") in names and ("psim-tvac-y", "half2", "half1") in names


def test_hdrg_bench_measured_cli_and_bad_data(tmp_path):
    out = tmp_path / "m.json"
    r = subprocess.run([sys.executable, "-m", "host_tools.cli", "bench", "measured", "--only", "psim-tvac-x",
                        "--json", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "| psim-tvac-x | half1 -> half2 |" in r.stdout
    data = json.loads(out.read_text())
    assert data["summary"]["splits"] == 2
    r = subprocess.run([sys.executable, "-m", "host_tools.cli", "bench", "measured", "--data", str(tmp_path / "none")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "not found" in r.stderr


def test_hdrg_fit_says_what_the_runs_identify(tmp_path):
    log = _read(TOFU / "tofupilot-imu-x.csv")
    lo = int(np.argmin(log["temp_c"]))
    path = tmp_path / "cool.csv"
    rl.write_csv(log.select(np.arange(lo)), path)
    r = subprocess.run([sys.executable, "-m", "host_tools.cli", "fit", str(path), "-o", str(tmp_path / "m.json")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "rate            NOT identified" in r.stdout and "record heating legs" in r.stdout
    assert "(0 heating, 1 cooling legs; the temp proxy rises when the device is heating)" in r.stdout
    assert "model kept: cubic in the proxy" in r.stdout
    model = json.loads((tmp_path / "m.json").read_text())
    assert model["fit"]["identifiability"]["rate_terms_identified"] is False


@pytest.mark.parametrize("blocks", [100000, 1, 0, -3, 2.5, True])
def test_cv_blocks_outside_its_range_is_refused_at_once(blocks):
    """`hdrg fit --cv-blocks 100000` ran for minutes: the fit and the loop refuse it with the range."""
    from host_tools.fitting.diagnose import diagnose
    from host_tools.fitting.fit_pipeline import fit_default
    log = _cycle(1)
    with pytest.raises(ValueError, match=r"2\.\.64"):
        fit_default([log], cv_blocks=blocks)
    with pytest.raises(ValueError, match=r"2\.\.64"):
        diagnose([log], cv_blocks=blocks, plots=False)


def test_the_loop_ends_no_worse_than_the_flight_stack_cubic_held_out():
    """hdrg diagnose's floor: a held-out run whose drive frequency left the model's range (the
    frequency proxy clamps) while its temp_c did not: the flight stack's cubic holds out better and
    is the final model, said in the report; on its own training run the model is kept."""
    from host_tools.fitting.diagnose import FLOOR_RATIO, diagnose
    from host_tools.simulation import sim
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = sim.simulate("paper-ftr-cycle-4dpm", seed=1, duration_s=7200.0)
    f = np.asarray(log["freq_hz"], np.float64)
    hot = log.with_columns(freq_hz=f + 0.5 * (f.max() - f.min()))
    rep, model = diagnose([log], [hot], plots=False, max_iter=0)
    fl = rep["cubic_floor"]
    assert fl["replaced"] and fl["model_dph"] > FLOOR_RATIO * fl["cubic_dph"]
    assert model.config.proxy.kind == "temp" and tuple(model.terms) == (0, 1, 2, 3)
    assert model.fit["diagnose"]["effects"] == []
    rep, model = diagnose([log], [log], plots=False, max_iter=0)
    assert not rep["cubic_floor"]["replaced"]
