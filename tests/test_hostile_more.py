"""More hostile inputs that used to give a number without a word: a model whose k7 generators run
at another sample rate than the model, a two-row log whose metadata sample rate contradicts its
t_s, a log with both rate columns, a compensated log without its metadata given to metrics."""
import dataclasses
import json
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
