"""Extrapolation said where the user looks, beyond the clamp flags:

* an aux input outside the range its k7 term was fitted on (clamped alone: the aux_clamped flag,
  which sees the sum z, cannot fire) -> metadata, warning, ``--strict`` refuses; float and fixed;
* ``hdrg diagnose`` says when the held-out run lies outside the final model's range;
* ``hdrg fit`` with a training run that covers a sliver of the proxy range, and term selection
  that keeps only the offset, says so.
"""
import dataclasses

import numpy as np
import pytest

from host_tools import cli
from host_tools.fitting.diagnose_confirm import error_stats
from host_tools.fitting.diagnose_report import extrapolation
from host_tools.fitting.fit import fit_logs
from host_tools.golden import flags as hflags, runlog
from host_tools.golden.checks import coverage_advice
from host_tools.golden.compensate import compensate, fit_config_from_logs
from host_tools.golden.regressors import AuxConfig, aux_inputs_clamped
from host_tools.simulation import sim


@pytest.fixture(scope="module")
def vdd(tmp_path_factory):
    """An FTR run whose bias follows aux_vdd, a model with an aux_vdd input term fitted on it, and the
    same run with the supply 20 x the training half-span higher."""
    d = tmp_path_factory.mktemp("vdd")
    log = sim.simulate("paper-ftr-cycle-4dpm", seed=11, duration_s=4000,
                       undeclared=["aux_vdd:coef_dph_per_v=400"])
    x = np.asarray(log["aux_vdd"], np.float64)
    ref, span = float(np.mean(x)), float(1.1 * np.max(np.abs(x - np.mean(x))))
    cfg = fit_config_from_logs([log])
    cfg = dataclasses.replace(cfg, aux=AuxConfig.from_terms(
        [{"gen": "input", "weight": 1.0, "column": "aux_vdd", "ref": ref, "span": span, "tau_s": 0.0, "power": 1,
          "sign": False, "effect": "aux_vdd"}], cfg.rate.fs))
    model, _ = fit_logs([log], cfg, "all")
    model.to_json(d / "m.json")
    runlog.write(log, d / "in.csv")
    high = log.with_columns(aux_vdd=x + 20.0 * span)
    runlog.write(high, d / "high.csv")
    return {"dir": d, "log": log, "high": high, "model": model, "span": span}


def test_an_aux_input_inside_its_range_is_not_flagged(vdd):
    assert aux_inputs_clamped(vdd["log"], vdd["model"].config.aux) == {}
    out = compensate(vdd["log"], vdd["model"])
    assert hflags.AUX_INPUTS_KEY not in out.metadata and hflags.problems(out) == []


@pytest.mark.parametrize("impl", ["float", "fixed"])
def test_an_aux_input_outside_its_range_is_counted_warned_and_refused_by_strict(vdd, strict_refuses_then_warns, impl):
    n = len(vdd["high"])
    assert aux_inputs_clamped(vdd["high"], vdd["model"].config.aux) == {"aux_vdd": n}
    out = compensate(vdd["high"], vdd["model"], impl=impl)
    assert out.metadata[hflags.AUX_INPUTS_KEY] == f"aux_vdd {n}"
    assert not np.any(np.asarray(out["flags"]) & 32)           # the firmware flag cannot see it ...
    msgs = hflags.problems(out)                                  # ... the host check does
    assert len(msgs) == 1 and "aux input 'aux_vdd'" in msgs[0] and f"{n} of {n}" in msgs[0]
    d = vdd["dir"]
    target = d / f"c_{impl}.csv"
    strict_refuses_then_warns(d / "high.csv", d / "m.json", target, impl, "aux input 'aux_vdd'")
    assert runlog.read(target).metadata[hflags.AUX_INPUTS_KEY] == f"aux_vdd {n}"


def test_a_few_samples_outside_are_recorded_but_not_warned(vdd):
    x = np.asarray(vdd["log"]["aux_vdd"], np.float64).copy()
    x[:5] += 20.0 * vdd["span"]                                  # 5 samples: below the 1 % of WARN_FRACTION
    out = compensate(vdd["log"].with_columns(aux_vdd=x), vdd["model"])
    assert out.metadata[hflags.AUX_INPUTS_KEY] == "aux_vdd 5" and hflags.problems(out) == []


def test_diagnose_reports_a_held_out_run_outside_the_models_range(vdd):
    msgs = extrapolation(error_stats([vdd["high"]], vdd["model"]))
    assert len(msgs) == 1 and msgs[0].startswith(f"{vdd['high'].source}: extrapolation")
    assert extrapolation(error_stats([vdd["log"]], vdd["model"])) == []
    from host_tools.fitting.diagnose import diagnose
    from host_tools.golden.runlog import RunLog
    log = vdd["log"]
    # without temp_c: no flight-stack cubic to fall back on (diagnose's floor), so the final model is
    # the loop's own, whose proxy the held-out run leaves
    log = RunLog.from_arrays(log.metadata, log.source, **{k: v for k, v in log.columns.items() if k != "temp_c"})
    f = np.asarray(log["freq_hz"], np.float64)
    hot = log.with_columns(freq_hz=f + 0.5 * (f.max() - f.min()))       # half the range beyond it
    rep, _ = diagnose([log], [hot], plots=False, max_iter=0)            # the loop's own model: no aux term
    assert "error" in rep["cubic_floor"]
    assert len(rep["extrapolation"]) == 1 and "proxy_clamped" in rep["extrapolation"][0]
    assert rep["extrapolation"][0] == f"{hot.source}: {rep['final_runs'][0]['problems'][0]}"
    assert diagnose([log], [log.with_columns(freq_hz=f + 0.0)], plots=False, max_iter=0)[0]["extrapolation"] == []


def test_fit_names_a_training_run_that_covers_a_sliver_of_the_range(tmp_path, capsys):
    wide = sim.simulate("paper-mr-cycle-4dpm", seed=1, duration_s=6000)
    hold = sim.simulate("paper-mr-cycle-4dpm", seed=2, duration_s=6000).select(slice(0, 900))  # the 20 degC hold
    msgs = coverage_advice([wide, hold])
    assert len(msgs) == 1 and msgs[0].startswith(f"without {wide.source}") and "joint proxy range" in msgs[0]
    assert coverage_advice([wide]) == [] and coverage_advice([wide, wide]) == []
    runlog.write(wide, tmp_path / "wide.csv")
    runlog.write(hold, tmp_path / "hold.csv")
    assert cli.main(["fit", str(tmp_path / "wide.csv"), str(tmp_path / "hold.csv"), "-o", str(tmp_path / "m.json"),
                     "--rate-estimator", "diff"]) == 0
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if "joint proxy range" in x]
    assert len(line) == 1 and "without " in line[0] and "wide.csv the other training runs cover" in line[0], err


def test_fit_says_when_term_selection_keeps_only_the_offset(tmp_path, capsys):
    """A 4-h cycle and the first hour of another power-on (a hold): leave-one-run-out selection
    keeps k0 alone, and the console says the model does not compensate temperature."""
    runlog.write(sim.simulate("paper-mr-cycle-4dpm", seed=1, duration_s=14400), tmp_path / "cycle.csv")
    runlog.write(sim.simulate("paper-mr-cycle-4dpm", seed=2, duration_s=3600), tmp_path / "hour.csv")
    assert cli.main(["fit", str(tmp_path / "cycle.csv"), str(tmp_path / "hour.csv"), "-o", str(tmp_path / "m.json"),
                     "--rate-estimator", "diff"]) == 0
    out, err = capsys.readouterr()
    assert "1 terms ['k0']" in out and "hdrg fit: warning: term selection kept only the offset k0" in err
    assert "without " in err and "cycle.csv the other training runs cover" in err


def test_a_run_given_twice_is_refused_and_a_held_out_training_run_is_named(tmp_path, capsys):
    from host_tools.fitting.diagnose import diagnose
    from host_tools.golden.checks import same_runs
    log = sim.simulate("paper-ftr-cycle-4dpm", seed=3, duration_s=3000)
    other = sim.simulate("paper-ftr-cycle-4dpm", seed=4, duration_s=3000)
    runlog.write(log, tmp_path / "a.csv")
    runlog.write(runlog.read(tmp_path / "a.csv"), tmp_path / "copy.csv")
    runlog.write(other, tmp_path / "b.csv")
    assert cli.main(["fit", str(tmp_path / "a.csv"), str(tmp_path / "copy.csv"), "-o", str(tmp_path / "m.json")]) == 2
    assert "copy.csv: the same data as training run" in capsys.readouterr().err and not (tmp_path / "m.json").exists()
    assert cli.main(["diagnose", str(tmp_path / "a.csv"), "--holdout", str(tmp_path / "copy.csv"),
                     "--out", str(tmp_path / "d")]) == 2
    assert "the same data as training run" in capsys.readouterr().err
    with pytest.raises(ValueError, match="the same data as training run"):
        diagnose([log, runlog.read(tmp_path / "copy.csv")], plots=False, max_iter=0)
    rep, _ = diagnose([log], [log], plots=False, max_iter=0)
    assert len(rep["holdout_in_training"]) == 1 and "not independent" in rep["holdout_in_training"][0]
    assert diagnose([log], [other], plots=False, max_iter=0)[0]["holdout_in_training"] == []
    assert same_runs([log, other]) == []


def test_fit_says_when_its_own_ranges_clamp_the_training_run(tmp_path, capsys):
    log = sim.simulate("paper-ftr-cycle-4dpm", seed=5, duration_s=3000)
    runlog.write(log, tmp_path / "a.csv")
    f = np.asarray(log["freq_hz"], np.float64)
    lo, hi = np.percentile(f, 40), np.percentile(f, 60)
    assert cli.main(["fit", str(tmp_path / "a.csv"), "-o", str(tmp_path / "m.json"), "--proxy-range", f"{lo},{hi}",
                     "--rate-estimator", "diff", "--terms", "k0,k1"]) == 0
    err = capsys.readouterr().err
    assert "hdrg fit: warning: training run" in err and "proxy_clamped" in err
    assert cli.main(["fit", str(tmp_path / "a.csv"), "-o", str(tmp_path / "m2.json"), "--rate-estimator", "diff",
                     "--terms", "k0,k1"]) == 0
    assert "warning: training run" not in capsys.readouterr().err


def test_diagnose_names_a_column_some_runs_lack(vdd):
    from host_tools.fitting.diagnose_report import not_scanned
    log = vdd["log"]
    cols = {c: log[c] for c in log.columns if c != "aux_vdd"}
    lacking = runlog.RunLog.from_arrays(metadata=dict(log.metadata), source="no_vdd.csv", **cols)
    msgs = not_scanned([log, lacking])
    assert msgs == ["aux_vdd: lacking in no_vdd.csv; the candidates that read it were not tried"]
    assert not_scanned([log, log]) == [] and not_scanned([]) == []


def test_a_hand_edited_model_with_a_missing_or_misspelled_field_is_refused(tmp_path, capsys):
    """Before: a missing rate 'shift' became 4 and a misspelled 'settle_s' became 0 s, silently."""
    import json
    log = sim.simulate("paper-mr-cycle-4dpm", seed=6, duration_s=3000)
    runlog.write(log, tmp_path / "a.csv")
    assert cli.main(["fit", str(tmp_path / "a.csv"), "-o", str(tmp_path / "m.json"), "--rate-estimator", "iir",
                     "--rate-shift", "6", "--terms", "k0,k1"]) == 0
    capsys.readouterr()
    good = json.loads((tmp_path / "m.json").read_text())
    cases = {"no_shift": ("rate", lambda c: c.pop("shift"), "rate config: missing shift"),
             "typo": ("reversal", lambda c: c.__setitem__("setle_s", c.pop("settle_s")),
                      "reversal config: missing settle_s; unknown setle_s"),
             "no_stale": ("reversal", lambda c: c.pop("max_stale_s"), "reversal config: missing max_stale_s"),
             "extra": ("rate", lambda c: c.__setitem__("gain", 2), "rate config: unknown gain")}
    for name, (part, edit, text) in cases.items():
        doc = json.loads(json.dumps(good))
        edit(doc["config"][part])
        (tmp_path / f"{name}.json").write_text(json.dumps(doc))
        assert cli.main(["compensate", str(tmp_path / "a.csv"), "--model", str(tmp_path / f"{name}.json"),
                         "-o", str(tmp_path / f"{name}.csv")]) == 2, name
        assert text in capsys.readouterr().err, name
    assert cli.main(["compensate", str(tmp_path / "a.csv"), "--model", str(tmp_path / "m.json"),
                     "-o", str(tmp_path / "ok.csv")]) == 0
    capsys.readouterr()
    doc = json.loads(json.dumps(good))
    doc["coef_dph"][4] = 1.0                                    # a term the model does not enable
    (tmp_path / "k4.json").write_text(json.dumps(doc))
    assert cli.main(["compensate", str(tmp_path / "a.csv"), "--model", str(tmp_path / "k4.json"),
                     "-o", str(tmp_path / "k4.csv")]) == 2
    err = capsys.readouterr().err
    assert "k4 = 1.0 but term k4 is not enabled" in err and "np.float64" not in err


def test_report_names_an_in_sample_run_and_finds_the_training_runs_beside_the_model(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for i, name in enumerate(("a.csv", "b.csv", "c.csv")):
        runlog.write(sim.simulate("paper-ftr-cycle-4dpm", seed=20 + i, duration_s=3000), tmp_path / name)
    assert cli.main(["fit", "a.csv", "b.csv", "-o", "m.json", "--rate-estimator", "diff", "--terms", "k0,k1"]) == 0
    (tmp_path / "sub").mkdir()
    monkeypatch.chdir(tmp_path / "sub")                    # the recorded 'a.csv', 'b.csv' are not here
    capsys.readouterr()
    assert cli.main(["report", "--model", "../m.json", "--out", "r1", "--no-plots", "../b.csv", "../c.csv"]) == 0
    out = capsys.readouterr().out
    assert "b.csv is one of the model's training runs: its numbers are in-sample" in out
    assert "c.csv is one of" not in out and "baseline not fitted" not in out      # found beside the model
    (tmp_path / "a.csv").rename(tmp_path / "gone.csv")
    assert cli.main(["report", "--model", "../m.json", "--out", "r2", "--no-plots", "../c.csv"]) == 0
    out = capsys.readouterr().out
    assert "baseline fitted on 1 of the model's 2 recorded training runs" in out and "a.csv" in out
    assert "baseline fitted on 1 of" in (tmp_path / "sub" / "r2" / "report.md").read_text()
