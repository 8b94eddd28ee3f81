"""Run logs whose columns or metadata say something other than the data: the NPZ reader behaves as
the CSV reader (column names, rate_dps, unknown columns, gaps), a mode column without the declared
exchanges, modes 1 and 2 swapped, a compensated log given to `hdrg report`, a non-finite output
blamed on the model and not on the log, RunLog.from_arrays."""
from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

from host_tools import cli
from host_tools.golden import checks, runlog
from host_tools.golden.runlog import RunLog, RunLogError, RunLogWarning


def hdrg(*argv) -> int:
    return cli.main([str(a) for a in argv])


@pytest.fixture(scope="module")
def mr_log():
    from host_tools.simulation.sim import simulate
    return simulate("paper-mr-cycle-4dpm", seed=0, duration_s=1800)


def _swapped(mode):
    return np.where(mode == 1, 2, np.where(mode == 2, 1, mode))


def _write_npz(path, cols: dict, meta: dict):
    """An NPZ written by hand (its column names need not be ones RunLog accepts in memory)."""
    header = json.dumps({"format": "hdrg-runlog", "version": 1, "columns": list(cols), "metadata": meta,
                         "notes": []})
    np.savez(path, header=np.array(header), **{f"col_{i}": np.asarray(v) for i, v in enumerate(cols.values())})


def _write_csv(path, cols: dict, meta: dict):
    text = "".join(f"# {k}: {v}\n" for k, v in meta.items()) + ",".join(cols) + "\n"
    rows = zip(*[np.asarray(v).tolist() for v in cols.values()])
    path.write_text(text + "".join(",".join(map(repr, r)) + "\n" for r in rows))


def _read(path):
    """("ok", log, warning texts) or ("error", problem); the file name stripped from the texts."""
    name = str(path)
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        try:
            log = runlog.read(path)
        except RunLogError as exc:
            return "error", exc.problem
    texts = [re.sub(rf"^{re.escape(name)}(:\d+)?: ", "", str(w.message)) for w in got
             if issubclass(w.category, RunLogWarning)]
    return "ok", log, [re.sub(r"before (line|row) \d+", "before _", t) for t in texts]


def _table(n=12, **change):
    t = np.arange(n, dtype=float)
    cols = {"t_s": t, "freq_hz": 6227.0 + 0.01 * t, "rate_dph": 0.5 * np.sin(t), "mode": np.where(t % 6 < 3, 1, 2),
            "temp_c": 20.0 + 0.1 * t}
    for k, v in change.items():
        if v is None:
            cols.pop(k)
        else:
            cols[k] = v
    return cols


def _rename(cols, old, new):
    return {new if k == old else k: v for k, v in cols.items()}


# == 1. the NPZ reader accepts, warns about and refuses what the CSV reader does ======================

CASES = {
    "Mode for mode": lambda: _rename(_table(), "mode", "Mode"),
    "Freq Hz for freq_hz": lambda: _rename(_table(temp_c=None), "freq_hz", "Freq Hz"),
    "T_S for t_s": lambda: _rename(_table(), "t_s", "T_S"),
    "rate_dps": lambda: _rename(_table(), "rate_dph", "rate_dps"),
    "unknown column": lambda: _table(extra=np.zeros(12)),
    "Mode next to mode": lambda: _table(Mode=np.ones(12)),
    "gap in time": lambda: _table(t_s=np.r_[np.arange(6.0), np.arange(6.0) + 20]),
    "no rate": lambda: _table(rate_dph=None),
    "plain": _table,
}


@pytest.mark.parametrize("case", list(CASES))
def test_npz_and_csv_readers_agree(tmp_path, case):
    cols = CASES[case]()
    _write_csv(tmp_path / "r.csv", cols, {"device": "d"})
    _write_npz(tmp_path / "r.npz", cols, {"device": "d"})
    a, b = _read(tmp_path / "r.csv"), _read(tmp_path / "r.npz")
    assert a[0] == b[0], (a, b)
    if a[0] == "error":
        assert a[1] == b[1]
        return
    assert a[2] == b[2]
    assert list(a[1].columns) == list(b[1].columns)
    for k in a[1].columns:
        np.testing.assert_array_equal(a[1][k], b[1][k])
    assert list(a[1].segments) == list(b[1].segments)


def test_npz_with_mode_renamed_is_refused_not_read_as_ftr(tmp_path, mr_log, capsys):
    cols = dict(mr_log.columns)
    cols["Mode"] = cols.pop("mode")
    _write_npz(tmp_path / "m.npz", cols, dict(mr_log.metadata))
    with pytest.raises(RunLogError, match=r"m\.npz: column 'Mode' is not 'mode'"):
        runlog.read(tmp_path / "m.npz")
    assert hdrg("metrics", tmp_path / "m.npz") == 2
    assert "column 'Mode' is not 'mode'" in capsys.readouterr().err


def test_npz_rate_dps_gaps_and_unknown_columns(tmp_path):
    cols = _rename(_table(t_s=np.r_[np.arange(6.0), np.arange(6.0) + 20], extra=np.ones(12)), "rate_dph", "rate_dps")
    _write_npz(tmp_path / "x.npz", cols, {})
    with pytest.warns(RunLogWarning) as got:
        log = runlog.read(tmp_path / "x.npz")
    texts = [str(w.message) for w in got]
    assert any("column(s) 'extra' not in the run-log format" in t for t in texts)
    assert any("1 gap(s) in time" in t and "before row 6" in t for t in texts)
    np.testing.assert_array_equal(log.rate_dph, cols["rate_dps"] * 3600.0)
    assert list(log.segments) == [0, 6] and any("rate_dps" in n for n in log.notes)


# == 2a. exchanges declared, none in the mode column ==================================================

def test_declared_exchanges_missing_from_the_mode_column_are_refused(tmp_path, mr_log):
    mode = mr_log.mode.copy()
    ex = mode == 3
    mode[ex] = np.where(np.arange(len(mode))[ex] % 300 < 150, 1, 2)     # exchanges labelled as dwell
    lied = RunLog.from_arrays(dict(mr_log.metadata), **{**mr_log.columns, "mode": mode})
    for name in ("n.csv", "n.npz"):
        runlog.write(lied, tmp_path / name)
        with pytest.raises(RunLogError, match=r"metadata 'exchange_s: 30' declares 30 s of mode exchange.*straight "
                                              r"to mode.*no sample has mode 3"):
            runlog.read(tmp_path / name)
    with pytest.raises(RunLogError) as err:
        runlog.read(tmp_path / "n.csv")
    assert err.value.line == len(mr_log.metadata) + 2 + 150    # row 150: the first straight 1 -> 2 switch
    assert hdrg("fit", tmp_path / "n.csv", "-o", tmp_path / "m.json") == 2
    # without the metadata, or with the switch across a gap in time, nothing contradicts
    meta = {k: v for k, v in mr_log.metadata.items() if k != "exchange_s"}
    runlog.write(RunLog.from_arrays(meta, **{**mr_log.columns, "mode": mode}), tmp_path / "ok.csv")
    assert runlog.read(tmp_path / "ok.csv").reversal
    runlog.write(mr_log, tmp_path / "good.csv")
    assert runlog.read(tmp_path / "good.csv").reversal
    gap = "# exchange_s: 5\nt_s,rate_dph,temp_c,mode\n" + "".join(f"{t},1,20,{1 + (t > 20)}\n" for t in
                                                                  list(range(10)) + list(range(50, 60)))
    (tmp_path / "gap.csv").write_text(gap)
    with pytest.warns(RunLogWarning, match="1 gap"):
        assert runlog.read(tmp_path / "gap.csv").reversal


# == 2b. modes 1 and 2 swapped ========================================================================

def test_swapped_modes_from_power_on_warn(tmp_path, mr_log):
    runlog.write(RunLog.from_arrays(dict(mr_log.metadata), **{**mr_log.columns, "mode": _swapped(mr_log.mode)}),
                 tmp_path / "s.csv")
    with pytest.warns(RunLogWarning, match=r"s\.csv:\d+: the first dwell after power-on is mode 2 \(row 30"):
        runlog.read(tmp_path / "s.csv")
    runlog.write(mr_log, tmp_path / "g.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runlog.read(tmp_path / "g.csv")


def test_swapped_modes_against_the_state_column(tmp_path):
    from firmware_ref.formats import STATE_MODE
    state = np.array([0, 1, 1, 2, 2, 3, 4, 4, 3, 2])
    mode = np.asarray(STATE_MODE)[state]
    base = dict(t_s=np.arange(10.0), rate_dph=np.ones(10), temp_c=np.full(10, 20.0), state=state)
    runlog.write(RunLog.from_arrays(t_s=base["t_s"], rate_dph=base["rate_dph"], temp_c=base["temp_c"], mode=mode,
                                    state=state), tmp_path / "c.csv")
    assert runlog.read(tmp_path / "c.csv").reversal
    runlog.write(RunLog.from_arrays({**base, "mode": _swapped(mode)}), tmp_path / "s.csv")
    with pytest.raises(RunLogError, match=r"s\.csv:5: mode 2 but state 2 \(mode_1\) is mode 1 \(5 samples disagree\)"):
        runlog.read(tmp_path / "s.csv")


def test_a_swapped_run_among_others_is_named(mr_log):
    from host_tools.simulation.sim import simulate
    other = simulate("paper-mr-cycle-4dpm", seed=1, duration_s=1800)
    cut = np.arange(len(mr_log)) >= 200                                 # a leg: no power-on exchange
    leg = RunLog.from_arrays(dict(mr_log.metadata), "leg.csv", **{**mr_log.columns, "mode": _swapped(mr_log.mode)})
    leg = leg.select(cut)
    assert checks.mode_swap_warnings([mr_log, other]) == []
    said = checks.mode_swap_warnings([mr_log, other, leg])
    assert len(said) == 1 and said[0].startswith("leg.csv: its combined mode-reversal output averages -")
    with pytest.warns(checks.ModeSwapWarning, match="leg.csv: its combined"):     # hdrg fit, hdrg diagnose
        checks.check_fit_inputs([mr_log, other, leg], None)


def _compensated(out, bias, n=400):
    mode = np.where(np.arange(n) % 150 < 30, 3, np.where(np.arange(n) % 300 < 150, 1, 2))
    valid = (mode != 3).astype(np.int64)
    rng = np.random.default_rng(0)
    return RunLog.from_arrays({"compensated": "yes"}, "comp.csv", t_s=np.arange(float(n)), freq_hz=np.full(n, 6227.0),
                              rate_dph=np.where(valid == 1, out + 0.3 * rng.standard_normal(n), np.nan),
                              bias_dph=np.where(valid == 1, bias, np.nan), valid=valid, mode=mode,
                              flags=np.where(valid == 1, 0, 8))


def test_a_compensated_log_with_swapped_modes_is_named(tmp_path, capsys):
    assert checks.compensated_swap_warning(_compensated(0.0, 7.0)) is None
    text = checks.compensated_swap_warning(_compensated(-14.0, 7.0))
    assert text.startswith("comp.csv: the compensated output averages -14") and "-2x the model's bias" in text
    runlog.write(_compensated(-14.0, 7.0), tmp_path / "c.csv")
    assert hdrg("metrics", tmp_path / "c.csv") == 0
    assert "modes 1 and 2 are swapped" in capsys.readouterr().err


# == 3. hdrg report on a compensated log ==============================================================

def _ftr_run(path, n=400):
    t = np.arange(float(n))
    runlog.write(RunLog.from_arrays({"sample_rate_hz": "1"}, t_s=t, freq_hz=6227.0 + np.sin(2 * np.pi * t / 300),
                                    rate_dph=3.0 + 0.01 * np.cos(2 * np.pi * t / 50)), path)
    return path


def test_report_refuses_a_compensated_log(tmp_path, capsys):
    from host_tools.vectors.builders import make_model
    make_model(combiner=None).to_json(tmp_path / "m.json")
    run = _ftr_run(tmp_path / "run.csv")
    assert hdrg("compensate", run, "--model", tmp_path / "m.json", "-o", tmp_path / "c.csv") == 0
    capsys.readouterr()
    assert hdrg("report", tmp_path / "c.csv", "--model", tmp_path / "m.json", "-o", tmp_path / "rep", "--no-plots") == 2
    err = capsys.readouterr().err
    assert "c.csv: this is a compensated log" in err and "needs the raw run log" in err and "Traceback" not in err
    assert not (tmp_path / "rep" / "report.md").exists()


# == 4. a non-finite output is the model's fault, not the log's line ==================================

def test_non_finite_output_names_the_model_not_the_line(tmp_path):
    from host_tools.golden.compensate import compensate
    from host_tools.vectors.builders import make_model
    model = make_model(combiner=None)
    model.coef = np.where(model.coef != 0, 1.7e308, 0.0)            # past what model files may hold
    log = runlog.read(_ftr_run(tmp_path / "run.csv"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.raises(RunLogError) as err:
            compensate(log, model)
    msg = str(err.value)
    assert err.value.line is None and not re.match(r"\S+:\d+:", msg)
    assert "the log's inputs there are finite" in msg and "bias model" in msg and "(line " in msg


# == 5. RunLog.from_arrays ============================================================================

def test_from_arrays_takes_a_mapping_or_keywords():
    cols = {"t_s": np.arange(3.0), "rate_dph": np.ones(3), "temp_c": np.full(3, 20.0)}
    assert "columns" in RunLog.from_arrays.__doc__ and "deg/h" in RunLog.from_arrays.__doc__
    logs = [RunLog.from_arrays(cols), RunLog.from_arrays(**cols), RunLog.from_arrays(cols, {"a": "b"}, "x"),
            RunLog.from_arrays({"a": "b"}, "x", **cols), RunLog.from_arrays(cols, metadata={"a": "b"}, source="x"),
            RunLog.from_arrays({"t_s": cols["t_s"]}, rate_dph=cols["rate_dph"], temp_c=cols["temp_c"])]
    for log in logs:
        assert list(log.columns)[:3] == ["t_s", "rate_dph", "temp_c"] and len(log) == 3
    assert logs[2].metadata == {"a": "b"} and logs[2].source == "x" and logs[3].source == "x"
    with pytest.raises(TypeError, match="given twice"):
        RunLog.from_arrays(cols, t_s=np.arange(3.0))
    with pytest.raises(TypeError, match="at most"):
        RunLog.from_arrays(cols, {}, "x", "y")
