"""Two answers that were silent, now said:

* a mode-reversal schedule with windows longer than max_stale_s allows (a 400-s dwell): ``hdrg fit``
  derives max_stale_s from the training runs' schedule, and ``hdrg compensate`` counts the samples
  lost only to a window too old (metadata ``stale_by_age``), warns above 1 % and ``--strict``
  refuses, float and fixed;
* a CSV column that is not in the run-log format: a warning names it; one that differs from a
  missing format column only in case (``Mode``) is an error, since the log would be read without it.
"""
import warnings

import numpy as np
import pytest

from host_tools import cli
from host_tools.fitting.fit import fit_logs
from host_tools.golden import flags as hflags, runlog
from host_tools.golden.compensate import compensate, fit_config_from_logs, stale_by_age
from host_tools.golden.reversal import DEFAULT_MAX_STALE_S, ReversalConfig, max_stale_for, schedule_ages_s
from host_tools.simulation import sim


def _mr(dwell_s, seed, duration_s=3000):
    return sim.simulate("paper-mr-cycle-4dpm", seed=seed, duration_s=duration_s, dwell_s=dwell_s)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("sched")
    short, long_ = _mr(120.0, 3), _mr(400.0, 4)
    model, _ = fit_logs([short], fit_config_from_logs([short]), "all")
    model.to_json(d / "m120.json")
    runlog.write(long_, d / "long.csv")
    return {"dir": d, "short": short, "long": long_, "model": model}


def test_schedule_ages_are_exchange_plus_dwell(runs):
    for log, age in ((runs["short"], 150.0), (runs["long"], 430.0)):
        ages = schedule_ages_s(log.mode, log.segments, 1.0)
        assert stale_by_age(log, fit_config_from_logs([log]))[1] == age
        assert len(ages) >= 3 and np.all(ages[:-1] == age) and ages[-1] <= age   # the last one may be cut
    # a segment start restarts the schedule: the first window after it has no age
    mode = np.array([1] * 5 + [3] * 2 + [2] * 5 + [1] * 5 + [2] * 5)
    assert list(schedule_ages_s(mode, [0], 1.0)) == [7.0, 5.0, 5.0]
    assert list(schedule_ages_s(mode, [0, 12], 1.0)) == [7.0, 5.0]


def _schedule(windows, exchange=30):
    """A mode column: ``windows`` a list of (mode, dwell [samples]), each after an exchange."""
    return np.concatenate([np.r_[[3] * exchange, [m] * d] for m, d in windows]).astype(np.int64)


def _log(mode):
    n = len(mode)
    return runlog.RunLog({"t_s": np.arange(n, dtype=float), "rate_dph": np.zeros(n),
                          "freq_hz": 2e4 * (1 - 20.9e-6 * np.linspace(0, 1, n)), "mode": np.asarray(mode, np.int64)})


def test_fit_derives_max_stale_from_the_training_schedule(runs):
    assert max_stale_for([runs["short"]], 1.0) == DEFAULT_MAX_STALE_S
    assert max_stale_for([runs["long"]], 1.0) == 480.0                 # 1.1 x 430 s, up to 10 s
    # uneven dwells: the long mode's age, whichever mode the log starts in
    for first, second in ((120, 400), (400, 120)):
        assert max_stale_for([_log(_schedule([(1, first), (2, second)] * 3))], 1.0) == 480.0
    # a single stalled window does not set it; the rounding is to 10 s exactly (1.1 x 400 s = 440 s)
    assert max_stale_for([_log(_schedule([(1, 120), (2, 120)] * 4 + [(1, 900)] + [(2, 120), (1, 120)] * 2))], 1.0) == 300.0
    assert max_stale_for([_log(_schedule([(1, 370), (2, 370)] * 3))], 1.0) == 440.0
    assert fit_config_from_logs([runs["long"]]).reversal.max_stale_s == 480.0
    assert fit_config_from_logs([runs["short"]]).reversal.max_stale_s == DEFAULT_MAX_STALE_S
    given = fit_config_from_logs([runs["long"]], reversal={"max_stale_s": 200.0})
    assert given.reversal.max_stale_s == 200.0
    assert fit_config_from_logs([runs["long"]], reversal=ReversalConfig("pair", 250.0)).reversal.max_stale_s == 250.0


def test_the_training_schedule_loses_no_sample_to_age(runs):
    for log in (runs["short"], runs["long"]):
        cfg = fit_config_from_logs([log])
        assert stale_by_age(log, cfg) == (0, 150.0 if log is runs["short"] else 430.0)
        model, _ = fit_logs([log], cfg, "all")
        out = compensate(log, model)
        assert hflags.STALE_KEY not in out.metadata and hflags.problems(out) == []


@pytest.mark.parametrize("impl", ["float", "fixed"])
def test_a_longer_dwell_than_trained_is_counted_warned_and_refused_by_strict(runs, strict_refuses_then_warns, impl):
    model, log = runs["model"], runs["long"]
    out = compensate(log, model, impl=impl)
    k, age = stale_by_age(log, model)
    assert age == 430.0 and k > 0.2 * len(log)           # the last 130 s of each 400-s window
    # the count is exactly what the age limit costs: the same model without it has k more valid samples
    import dataclasses
    unlimited = dataclasses.replace(model, config=dataclasses.replace(
        model.config, reversal=dataclasses.replace(model.config.reversal, max_stale_s=1e9)))
    more = compensate(log, unlimited, impl="float")
    assert int(np.count_nonzero(more["valid"])) - int(np.count_nonzero(out["valid"])) == k
    assert out.metadata[hflags.STALE_KEY].startswith(f"{k} samples;")
    msgs = hflags.problems(out)
    assert len(msgs) == 1 and msgs[0].startswith(f"stale: {k} of {len(log)} samples") and "reach 430 s" in msgs[0]
    d = runs["dir"]
    target = d / f"c_{impl}.csv"
    strict_refuses_then_warns(d / "long.csv", d / "m120.json", target, impl, "stale:")
    assert runlog.read(target).metadata[hflags.STALE_KEY] == out.metadata[hflags.STALE_KEY]


def test_a_window_the_combiner_never_commits_is_counted_with_its_real_age():
    """A 3-s mode-2 glitch inside a 5-s settling time is never committed: the mode-1 window after it
    is paired with the older mode-2 window, and the message gives that real age (430 s), not the
    schedule's (230 s), so it cannot contradict the count."""
    log = _log(_schedule([(1, 200), (2, 200), (1, 200)]).tolist() + [2] * 3 + [3] * 30 + [1] * 200 + [3] * 30
               + [2] * 200)
    cfg = fit_config_from_logs([log], rate_estimator="diff", reversal={"max_stale_s": 300.0, "settle_s": 5.0})
    k, age = stale_by_age(log, cfg)
    assert k > 0 and age > 300.0
    import dataclasses
    lim = dataclasses.replace(cfg, reversal=dataclasses.replace(cfg.reversal, max_stale_s=1e9))
    from host_tools.golden.compensate import prepare
    assert int(np.count_nonzero(prepare(log, lim).valid)) - int(np.count_nonzero(prepare(log, cfg).valid)) == k


@pytest.mark.parametrize("text", ["770", "770 samples", "n/a", "770 samples: other words"])
def test_a_hand_edited_stale_entry_is_read_or_named_never_a_crash(runs, text):
    out = compensate(runs["short"], runs["model"])
    out.metadata[hflags.STALE_KEY] = text
    msgs = hflags.problems(out)
    if text.startswith("770 samples") and ":" not in text:
        assert len(msgs) == 1 and msgs[0].startswith("stale: 770 of")
    else:
        assert len(msgs) == 1 and f"'{hflags.STALE_KEY}: {text}'" in msgs[0]


def test_hdrg_fit_says_when_it_derived_a_longer_max_stale(runs, capsys):
    d = runs["dir"]
    assert cli.main(["fit", str(d / "long.csv"), "-o", str(d / "m400.json"), "--rate-estimator", "diff"]) == 0
    assert "max_stale_s 480 s" in capsys.readouterr().out


CSV = "t_s,{},rate_dph,freq_hz\n0,{},1.0,20000\n1,{},1.1,20000\n2,{},1.2,20000\n"


def test_a_column_that_is_mode_in_another_case_is_an_error(tmp_path):
    p = tmp_path / "Mode.csv"
    p.write_text("# reversal note\n" + CSV.format("Mode", 1, 1, 2))
    with pytest.raises(runlog.RunLogError, match=r"Mode\.csv:2: column 'Mode' is not 'mode'"):
        runlog.read(p)


@pytest.mark.parametrize("header, near", [("t_s,rate_dph,temp_c,Freq Hz", "freq_hz"),
                                          ("T_S,rate_dph,freq_hz", "t_s"), ("t_s,Rate-DPH,freq_hz", "rate_dph"),
                                          ("t_s,rate_dph,freq_hz,MODE", "mode")])
def test_near_misses_of_missing_format_columns_are_errors(tmp_path, header, near):
    p = tmp_path / "x.csv"
    p.write_text(header + "\n" + "\n".join(",".join(["1"] * 3 + ["1"] * (header.count(",") - 2))
                                             for _ in range(3)) + "\n")
    with pytest.raises(runlog.RunLogError, match=rf"x\.csv:1: column '[^']+' is not '{near}'"):
        runlog.read(p)


def test_rate_dps_beside_rate_dph_is_not_a_near_miss(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("t_s,rate_dph,freq_hz,Rate_DPS\n0,1,2e4,1\n1,1,2e4,1\n2,1,2e4,1\n")
    with pytest.warns(runlog.RunLogWarning, match="'Rate_DPS' not in the run-log format"):
        runlog.read(p)


@pytest.mark.parametrize("name", ["pressure", "Temp_C2"])
def test_an_unknown_column_is_kept_with_a_warning(tmp_path, name):
    p = tmp_path / "x.csv"
    p.write_text(CSV.format(name, 5, 6, 7))
    with pytest.warns(runlog.RunLogWarning, match=rf"x\.csv:1: column\(s\) '{name}' not in the run-log format"):
        log = runlog.read(p)
    assert list(log[name]) == [5.0, 6.0, 7.0] and any(name in n for n in log.notes)


@pytest.mark.parametrize("name", ["aux_pressure", "mode", "temp_c", "bias_dph", "comp_valid", "seq"])
def test_format_aux_and_hdrg_columns_are_read_silently(tmp_path, name):
    p = tmp_path / "x.csv"
    p.write_text(CSV.format(name, 1, 1, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runlog.read(p)


def test_mode_beside_Mode_is_only_a_warning(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("t_s,mode,Mode,rate_dph,freq_hz\n0,1,1,1.0,20000\n1,1,1,1.1,20000\n2,2,2,1.2,20000\n")
    with pytest.warns(runlog.RunLogWarning, match="'Mode' not in the run-log format"):
        log = runlog.read(p)
    assert list(log.mode) == [1, 1, 2]


def test_a_byte_order_mark_is_not_part_of_the_first_column(tmp_path):
    """Spreadsheets write UTF-8 with a BOM; before, the first column became '\\ufefft_s' and the log was
    refused as missing 't_s'."""
    p = tmp_path / "bom.csv"
    p.write_bytes("\ufefft_s,rate_dph,freq_hz\n0,1,2e4\n1,1,2e4\n2,1,2e4\n".encode("utf-8"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log = runlog.read(p)
    assert list(log.t_s) == [0.0, 1.0, 2.0]
