"""More hostile inputs that used to give a number without a word: a model whose k7 generators run
at another sample rate than the model, a two-row log whose metadata sample rate contradicts its
t_s, a log with both rate columns, a compensated log without its metadata given to metrics."""
import dataclasses
import json
import re
import warnings

import numpy as np
import pytest

from host_tools import cli
from host_tools.fitting import metrics
from host_tools.golden import runlog as rl
from host_tools.golden.model import BiasModel, ModelError
from host_tools.golden.regressors import AuxConfig
from host_tools.vectors.builders import make_model


def _ftr_model_with_lag(tmp_path):
    """An FTR model with a k7 lag term on temp_c (tau 60 s at 1 Hz), written to model.json."""
    coef = np.zeros(17)
    coef[[0, 1, 7]] = [1.0, 2.0, 5.0]
    model = make_model("temp", ref=20.0, span=20.0, combiner=None, coef=coef)
    aux = AuxConfig.from_terms([{"gen": "input", "weight": 1.0, "column": "temp_c", "ref": 20.0, "span": 20.0,
                                 "tau_s": 60.0, "power": 1}], model.config.rate.fs)
    model = dataclasses.replace(model, config=dataclasses.replace(model.config, aux=aux))
    path = tmp_path / "model.json"
    model.to_json(path)
    return path


def test_a_model_whose_aux_sample_rate_is_not_its_own_is_refused(tmp_path, capsys):
    path = _ftr_model_with_lag(tmp_path)
    assert BiasModel.from_json(path).config.aux.params["fs"] == 1.0
    d = json.loads(path.read_text())
    d["config"]["aux"]["params"]["fs"] = 10.0          # the lag would be 6 s, not 60 s
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError, match=r"model\.json: field 'config\.aux\.params\.fs': 10 Hz is not the "
                                         r"model's sample rate config\.rate\.fs 1 Hz"):
        BiasModel.from_json(path)
    log = tmp_path / "run.csv"
    log.write_text("# sample_rate_hz: 1\nt_s,rate_dph,temp_c\n" + "".join(f"{i},1.0,{20 + i / 100}\n" for i in range(50)))
    assert cli.main(["compensate", str(log), "--model", str(path), "-o", str(tmp_path / "c.csv")]) == 2
    assert "config.aux.params.fs" in capsys.readouterr().err and not (tmp_path / "c.csv").exists()


def test_a_two_row_log_whose_sample_rate_contradicts_t_s_is_refused(tmp_path):
    p = tmp_path / "two.csv"
    p.write_text("# sample_rate_hz: 1\nt_s,rate_dph,temp_c\n0,1.0,20.0\n10,1.1,20.5\n")
    with pytest.raises(rl.RunLogError, match=r"two\.csv: metadata 'sample_rate_hz: 1' does not match t_s "
                                             r"\(median step 10 s"):
        rl.read(p)
    p.write_text("# sample_rate_hz: 0.1\nt_s,rate_dph,temp_c\n0,1.0,20.0\n10,1.1,20.5\n")
    assert rl.read(p).sample_rate_hz == 0.1


def test_rate_dph_beside_rate_dps_is_refused(tmp_path):
    p = tmp_path / "both.csv"
    p.write_text("t_s,rate_dps,rate_dph,temp_c\n" + "".join(f"{i},0.5,7.0,20\n" for i in range(5)))
    with pytest.raises(rl.RunLogError, match=r"both\.csv:1: columns 'rate_dph' and 'rate_dps' are both present"):
        rl.read(p)
    log = rl.RunLog.from_arrays(t_s=np.arange(5.0), rate_dph=np.full(5, 7.0), temp_c=np.full(5, 20.0))
    log.columns["rate_dps"] = np.full(5, 0.5)
    rl.write_npz(log, tmp_path / "both.npz")
    with pytest.raises(rl.RunLogError, match=r"both\.npz: columns 'rate_dph' and 'rate_dps' are both present"):
        rl.read(tmp_path / "both.npz")


def test_metrics_reads_a_compensated_log_without_its_metadata_as_compensated(tmp_path):
    t = np.arange(200.0)
    valid = np.ones(200, np.int64)
    valid[:5] = 0
    rate = np.where(valid == 1, 0.1 * np.sin(t / 7.0), np.nan)
    comp = rl.RunLog.from_arrays(t_s=t, rate_dph=rate, temp_c=np.full(200, 20.0),
                                 bias_dph=np.where(valid == 1, 3.0, np.nan), valid=valid,
                                 flags=np.where(valid == 1, 0, 4))
    p = tmp_path / "comp_stripped.csv"
    rl.write(comp, p)                                   # no 'compensated: yes' line
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = metrics.run_metrics(p)
    assert res["kind"] == "compensated"
    assert res["mean_dph"] == pytest.approx(float(np.mean(rate[5:])))


def test_a_log_sampled_off_the_model_rate_is_refused_whatever_its_metadata_says(tmp_path):
    from host_tools.golden import compensate as hc

    model = make_model("temp", ref=20.0, span=20.0, combiner=None)      # fs 1 Hz
    n = 400
    temp = 20.0 + 0.01 * np.arange(n)
    p = tmp_path / "fast.csv"
    for meta in ("# sample_rate_hz: 1\n", ""):                          # 1.019 Hz: 1.9 % off the model
        p.write_text(meta + "t_s,rate_dph,temp_c\n" + "".join(f"{i * 0.981!r},1.0,{x!r}\n" for i, x in enumerate(temp.tolist())))
        with pytest.raises(ValueError, match=r"fast\.csv: sample rate 1\.01937 Hz \(1 / its median t_s step 0\.981 s\) "
                                             r"does not match the model's nominal fs 1 Hz"):
            hc.compensate(rl.read(p), model)


def test_report_names_training_runs_of_the_other_kind_instead_of_blaming_the_held_out_run():
    from host_tools.fitting.baseline import baseline_config

    n = 600
    t = np.arange(float(n))
    ftr = rl.RunLog.from_arrays(t_s=t, rate_dph=np.ones(n), temp_c=20.0 + t / 100, source="ftr.csv")
    mode = np.tile(np.r_[np.full(30, 3), np.full(120, 1), np.full(30, 3), np.full(120, 2)], 2)[:n].astype(np.int64)
    mr = rl.RunLog.from_arrays(t_s=t, rate_dph=np.ones(n), temp_c=20.0 + t / 100, mode=mode, source="mr.csv")
    ftr_model = make_model("temp", ref=20.0, span=20.0, combiner=None)
    mr_model = make_model("temp", ref=20.0, span=20.0, combiner="pair")
    with pytest.raises(ValueError, match=r"mr\.csv: mode-reversal training run\(s\) for an FTR model"):
        baseline_config([mr], like=ftr_model.config)
    with pytest.raises(ValueError, match=r"ftr\.csv: FTR training run\(s\) for a mode-reversal model"):
        baseline_config([ftr], like=mr_model.config)
    assert baseline_config([ftr], like=ftr_model.config).reversal is None


@pytest.mark.parametrize("key, value, problem", [
    ("exchange_n", 50, r"field 'timing\.exchange_n': 50 disagrees with the word exchange_n 3"),
    ("fs_hz", 10, r"field 'timing\.fs_hz': 10 Hz disagrees with the word fs_q16 65536 \(1 Hz\)"),
    ("dwell_s", 9.0, r"field 'timing\.dwell_s': 9 s is 9 samples at 1 Hz, the word dwell_n says 7"),
    ("dwel_n", 7, r"field 'timing\.dwel_n': unknown"),
])
def test_export_refuses_a_table_json_whose_timing_contradicts_its_words(tmp_path, capsys, key, value, problem):
    from host_tools.fixed.quantize import quantize
    from host_tools.vectors.builders import random_model

    q = quantize(random_model(np.random.default_rng(21), estimator="lsq"), exchange_s=3.0, dwell_s=7.0, n_random=2)
    q.to_json(tmp_path / "table.json")
    d = json.loads((tmp_path / "table.json").read_text())
    d["timing"][key] = value
    for originals in (True, False):                     # with the model (it still quantizes to the words) and without
        if not originals:
            for k in ("model", "model_source", "coef_dph", "coef_mode2_dph"):
                d.pop(k, None)
        (tmp_path / "edited.json").write_text(json.dumps(d))
        assert cli.main(["export", str(tmp_path / "edited.json"), "-o", str(tmp_path / "out")]) == 2
        assert re.search(r"edited\.json: " + problem, capsys.readouterr().err)
        assert not (tmp_path / "out").exists()


def test_a_metadata_key_repeated_with_another_value_is_refused_with_both_lines(tmp_path):
    rows = "t_s,rate_dph,temp_c\n" + "".join(f"{i},1.0,20\n" for i in range(5))
    p = tmp_path / "rep.csv"
    p.write_text("# rate_full_scale_dph: 1000\n# device: a\n# rate_full_scale_dph: 100\n" + rows)
    with pytest.raises(rl.RunLogError, match=r"rep\.csv:3: metadata key 'rate_full_scale_dph' repeated with another "
                                             r"value: line 1 says '1000', line 3 says '100'"):
        rl.read(p)
    p.write_text("# device: a\n# rate_full_scale_dph: 1000\n#  rate_full_scale_dph :  1000\n" + rows)
    assert rl.read(p).metadata == {"device": "a", "rate_full_scale_dph": "1000"}


def test_a_negative_time_since_power_on_is_refused_by_line(tmp_path):
    p = tmp_path / "neg.csv"
    p.write_text("# sample_rate_hz: 1\nt_s,rate_dph,temp_c\n" + "".join(f"{i - 3},1.0,20\n" for i in range(6)))
    with pytest.raises(rl.RunLogError, match=r"neg\.csv:3: t_s -3\.0 is negative: t_s is the time since power-on"):
        rl.read(p)
    with pytest.raises(rl.RunLogError, match=r"row 0: t_s -0\.5 is negative"):
        rl.RunLog.from_arrays(t_s=np.arange(5.0) - 0.5, rate_dph=np.ones(5), temp_c=np.full(5, 20.0))
    p.write_text("t_s,rate_dph,temp_c\n" + "".join(f"{i},1.0,20\n" for i in range(6)))
    assert rl.read(p).t_s[0] == 0.0


@pytest.mark.parametrize("edit, field", [
    (lambda d: d["config"]["proxy"].update(spann=2.0), r"config\.proxy': proxy config: unknown spann"),
    (lambda d: d["config"].update(reversl=None), r"config\.reversl': unknown field"),
    (lambda d: d.update(coef_mode2=[0.0] * 17), r"coef_mode2': unknown field"),
    (lambda d: d["config"]["rate"].update(fss=1.0), r"config\.rate': rate config: unknown fss"),
    (lambda d: d["config"]["reversal"].update(max_stale=1.0), r"config\.reversal': reversal config: unknown max_stale"),
    (lambda d: d["config"]["proxy"].update(span=1e-300), r"config\.proxy': proxy span 1e-300 Hz is below one LSB"),
    (lambda d: d["config"]["proxy"].update(span=1e-320), r"config\.proxy': proxy span 1e-320 Hz is below one LSB"),
    (lambda d: d["config"]["proxy"].update(ref=-6227.0), r"config\.proxy': proxy ref -6227\.0 Hz: a drive frequency "
                                                         r"is positive"),
])
def test_a_model_with_a_misspelt_key_or_a_meaningless_proxy_is_refused_naming_the_field(tmp_path, edit, field):
    path = tmp_path / "model.json"
    make_model("freq", ref=6227.0, span=2.0, combiner="pair").to_json(path)
    d = json.loads(path.read_text())
    assert BiasModel.from_dict(d, "model.json").config.proxy.span == 2.0     # as written, it reads
    edit(d)
    path.write_text(json.dumps(d))
    with pytest.raises(ModelError, match=r"model\.json: field '" + field):
        BiasModel.from_json(path)


def test_a_temperature_proxy_may_have_a_negative_ref():
    assert make_model("temp", ref=-20.0, span=2.0 ** -16, combiner=None).config.proxy.ref == -20.0


def test_arw_needs_as_many_independent_averages_as_the_bias_instability(capsys):
    rng = np.random.default_rng(1)
    a = metrics.allan(rng.normal(0.0, 1.0, 5), np.arange(5.0), np.ones(5, bool))
    assert a["adev_dph"] and a["arw_deg_rth"] is None and a["arw_method"] is None and a["bias_instability_dph"] is None
    assert a["reason"] == ("fewer than 8 independent averages at every tau (5 samples in 1 stretch(es)): "
                           "no ARW or bias instability")
    text = metrics.format_table([{"source": "short.csv", "per_tau": [], "allan": a}])
    assert "no ARW or bias instability" in text
    a = metrics.allan(rng.normal(0.0, 1.0, 8), np.arange(8.0), np.ones(8, bool))
    assert a["arw_method"] == "adev_at_1s" and a["reason"] is None


def test_simulate_refuses_a_sub_sample_schedule_and_notes_one_that_is_not_whole_samples(tmp_path, capsys):
    base = ["simulate", "--scenario", "mr-one-cycle-2dpm", "--duration", "700"]
    for opt, value in (("--dwell-s", "0.2"), ("--exchange-s", "0.4"), ("--dwell-s", "0.6")):
        assert cli.main(base + [opt, value, "-o", str(tmp_path / "sub.csv")]) == 2
        assert f"{opt[2:].replace('-', '_')} {value} s is shorter than one sample at 1 Hz" in capsys.readouterr().err
        assert not (tmp_path / "sub.csv").exists()
    assert cli.main(base + ["--rate", "10", "--dwell-s", "0.2", "-o", str(tmp_path / "fast.csv")]) == 0
    assert "note" not in capsys.readouterr().err
    assert cli.main(base + ["--exchange-s", "30.4", "-o", str(tmp_path / "odd.csv")]) == 0
    assert ("note: exchange_s 30.4 s is 30.4 samples at 1 Hz: the schedule runs in continuous time, so each "
            "exchange lasts 30 or 31 samples") in capsys.readouterr().err


def test_quantize_refuses_a_sub_sample_time_and_notes_a_rounded_one(tmp_path, capsys):
    model = tmp_path / "m.json"
    make_model().to_json(model)                                          # fs 1 Hz
    assert cli.main(["quantize", str(model), "-o", str(tmp_path / "t.json"), "--dwell-s", "0.6"]) == 2
    assert "--dwell-s 0.6: shorter than one sample at the model's sample rate 1 Hz" in capsys.readouterr().err
    assert cli.main(["quantize", str(model), "-o", str(tmp_path / "t.json"), "--exchange-s", "30.4"]) == 0
    assert ("hdrg quantize: note: --exchange-s 30.4 s is 30.4 samples at the model's sample rate 1 Hz: the table "
            "holds 30 samples (30 s)") in capsys.readouterr().err
    assert json.loads((tmp_path / "t.json").read_text())["timing"]["exchange_n"] == 30
    assert cli.main(["quantize", str(model), "-o", str(tmp_path / "t2.json")]) == 0
    assert "note" not in capsys.readouterr().err
