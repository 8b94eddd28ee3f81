"""Why a device of a lot fails (host_tools.lot.device, host_tools.lot.report): every failed
criterion with its stage, the drive frequency checked against the table's word before the fit,
repaired run logs, re-judging a stored result, and a report in natural id order with the reasons,
the warnings and plain numbers."""
from __future__ import annotations

import csv
import io
import json

import pytest

from firmware_ref import formats as F
from host_tools.golden import runlog
from host_tools.lot import device, load_spec
from host_tools.lot.inputs import Device, Run
from host_tools.lot.report import markdown_text, natural_key, write_report, worst_devices
from host_tools.simulation.sim_foreign import simulate_foreign

# lax limits: the 20-min simulated device passes them
LAX = {"min_train_s": 600.0, "heldout_stability_max_dph": None, "residual_rms_max_dph": None,
       "allow_repaired_logs": False}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A simulated device (foreign seed 0, FTR): a 20-min training run and a 20-min held-out run."""
    d = tmp_path_factory.mktemp("lot_report")
    runlog.write(simulate_foreign(0, 4.0, False, 0, 0, 1200), d / "train.csv")
    runlog.write(simulate_foreign(0, 2.0, False, 1, 1, 1200), d / "holdout.csv")
    return d


def _spec(**given) -> dict:
    return {**load_spec(None), **LAX, **given}


def _job(dev_id, train, holdout=None, **spec) -> dict:
    dev = Device(dev_id, (Run(f"{dev_id}/train.csv", str(train)),),
                 (Run(f"{dev_id}/holdout.csv", str(holdout)),) if holdout else (),
                 (None,) if holdout else ())
    return {"device": dev, "spec": _spec(**spec), "input_hash": "test"}


def test_a_device_failing_at_quantize_lists_its_other_violations(runs, monkeypatch):
    from host_tools.fixed import quantize
    from host_tools.fixed.quantize import QuantizeError

    def refuse(*args, **kwargs):
        raise QuantizeError("proxy ref 99999 Hz is outside the drive-frequency word")

    monkeypatch.setattr(quantize, "quantize", refuse)
    out = device.calibrate(_job("Q1", runs / "train.csv", runs / "holdout.csv",
                                heldout_stability_max_dph=1e-4, residual_rms_max_dph=1e-4))
    r = out["result"]
    assert (r["status"], r["stage"]) == ("fail", "quantize")
    assert r["failures"] == [{"stage": "quantize", "reason": "proxy ref 99999 Hz is outside the drive-frequency word"}]
    assert r["reasons"][0].startswith("quantize: proxy ref 99999 Hz")
    # the figures are kept, and every spec limit they break is listed after the quantize failure
    assert r["residual_rms_dph"] > 1e-4 and r["heldout_stability_dph"] > 1e-4 and r["crc32"] is None
    assert any(t.startswith("spec: held-out stability") and "heldout_stability_max_dph" in t for t in r["reasons"])
    assert any(t.startswith("spec: training residual rms") and "residual_rms_max_dph" in t for t in r["reasons"])
    assert r["proxy"] == "freq" and 6e3 < r["drive_freq_hz"] < 30e3
    # every file produced is returned (the engine decides what to ship): no table was made here
    assert sorted(out["files"]) == ["model.json", "result.json"]
    assert json.loads(out["files"]["result.json"]) == r


def _scaled_train(runs, tmp_path, factor_of_top: float):
    """The training run with its drive frequency scaled so that its maximum is ``factor_of_top`` x
    the top of the table's frequency word."""
    log = runlog.read(runs / "train.csv")
    f = log.columns["freq_hz"]
    path = tmp_path / "train_hot.csv"
    runlog.write(log.with_columns(freq_hz=f * (factor_of_top * device.freq_word_max_hz() / f.max())), path)
    return path


def test_a_drive_frequency_outside_the_word_is_refused_before_the_fit(runs, tmp_path, monkeypatch):
    calls, real = [], device._fit
    monkeypatch.setattr(device, "_fit", lambda logs: calls.append(logs) or real(logs))
    top = 2.0 ** (32 - F.FREQ_FRAC)
    out = device.calibrate(_job("HOT", _scaled_train(runs, tmp_path, 1.25), runs / "holdout.csv",
                                min_train_s=3600.0))
    r = out["result"]
    assert calls == []
    assert (r["status"], r["stage"]) == ("fail", "check")
    first = r["reasons"][0]
    assert first.startswith("check: HOT/train.csv: drive frequency ") and f"0 .. {top:g} Hz" in first
    assert f"FREQ_FRAC = {F.FREQ_FRAC}" in first and "not fitted" in first
    assert r["drive_freq_hz"] > device.freq_word_max_hz() and r["proxy"] == "freq"
    # the spec violation it would still have is listed too
    assert any(t.startswith("check: too short") and "min_train_s" in t for t in r["reasons"])
    assert r["residual_rms_dph"] is None and sorted(out["files"]) == ["result.json"]
    # just inside the word: fitted
    out = device.calibrate(_job("OK", _scaled_train(runs, tmp_path, 0.9), runs / "holdout.csv"))
    assert out["result"]["stage"] != "check" and out["result"]["residual_rms_dph"] is not None and len(calls) == 1


@pytest.mark.parametrize("frac", [19, 20])
def test_the_word_range_follows_the_format_constant(runs, monkeypatch, frac):
    """The range comes from formats.FREQ_FRAC: 2^(32 - 19) = 8192 Hz, 2^12 = 4096 Hz, both below
    the simulated device's drive frequency."""
    monkeypatch.setattr(F, "FREQ_FRAC", frac)
    r = device.calibrate(_job("W", runs / "train.csv"))["result"]
    assert r["stage"] == "check" and f"0 .. {2 ** (32 - frac)} Hz" in r["reasons"][0]
    assert device.freq_word_max_hz() == pytest.approx(2.0 ** (32 - frac))


def test_a_repaired_log_fails_unless_the_spec_allows_it(runs, tmp_path):
    cut = tmp_path / "holdout_cut.csv"
    data = (runs / "holdout.csv").read_bytes()
    cut.write_bytes(data[:-25])         # cut inside the last line
    job = _job("R", runs / "train.csv", cut)
    r = device.calibrate(job)["result"]
    assert (r["status"], r["stage"]) == ("fail", "check")
    assert r["repaired_logs"] == ["R/holdout.csv"] and r["log_repairs"] == {"R/holdout.csv": ["truncated last line"]}
    assert "R/holdout.csv (truncated last line)" in r["reasons"][0] and "allow_repaired_logs" in r["reasons"][0]
    assert any("truncated last line" in w for w in r["warnings"])
    assert r["heldout_stability_dph"] is not None        # measured on the rows kept
    assert device.judge(r, _spec(allow_repaired_logs=True)) == ("pass", "done", [])
    job["spec"]["allow_repaired_logs"] = True
    assert device.calibrate(job)["result"]["status"] == "pass"
    # named in lot.md, with the reader's warning, under the device
    md = markdown_text([r], _spec(), [r])
    warn = md[md.index("## Warnings"):md.index("## Histograms")]
    assert "- **R** (fail):" in warn and "repaired log R/holdout.csv (truncated last line)" in warn
    assert "R/holdout.csv:" in warn and "the partial line is discarded" in warn


def test_judge_re_judges_a_stored_result(runs):
    r = json.loads(device.calibrate(_job("J", runs / "train.csv", runs / "holdout.csv"))["files"]["result.json"])
    assert (r["status"], r["stage"], r["reasons"]) == ("pass", "done", [])
    stab = r["heldout_stability_dph"]
    status, stage, reasons = device.judge(r, _spec(heldout_stability_max_dph=stab / 2))
    assert (status, stage) == ("fail", "spec") and len(reasons) == 1
    assert f"{stab:.4g} deg/h" in reasons[0] and "heldout_stability_max_dph" in reasons[0]
    assert device.judge(r, _spec(heldout_stability_max_dph=stab * 2)) == ("pass", "done", [])
    status, stage, reasons = device.judge(r, _spec(min_train_s=7200.0, residual_rms_max_dph=0.0))
    assert (status, stage) == ("fail", "check") and reasons[0].startswith("check: too short")
    assert reasons[1].startswith("spec: training residual rms")
    # a failure that no spec changes stays; a result.json from before ``failures`` reads too
    assert device.judge({**r, "failures": [{"stage": "export", "reason": "x"}]}, _spec())[:2] == ("fail", "export")
    old = {k: v for k, v in r.items() if k != "failures"}
    assert device.judge({**old, "status": "fail", "stage": "read", "reasons": ["a.csv: no such file"]},
                        _spec()) == ("fail", "read", ["read: a.csv: no such file"])
    assert device.judge({**old, "status": "fail", "stage": "spec", "reasons": ["old limit"]}, _spec())[0] == "pass"


def _result(dev_id, status="pass", stab=0.05, res=0.2, **extra) -> dict:
    r = {"device": dev_id, "status": status, "stage": "done" if status == "pass" else "spec",
         "reasons": [] if status == "pass" else [f"spec: held-out stability {stab} deg/h > 0.1 deg/h"],
         "failures": [], "train_s": 10760.3, "drive_freq_hz": 14089.9145, "proxy": "freq", "terms": "k0,k1",
         "heldout_stability_dph": stab, "residual_rms_dph": res, "valid_share": 0.99944, "proxy_coverage": 1.0,
         "rate_coverage": 0.997, "fixed_bound_dph": 0.00048863, "cv_rms_dph": 1.07e-5, "crc32": "0x1",
         "warnings": [], "repaired_logs": [], "log_repairs": {}}
    r.update(extra)
    return r


def test_the_report_is_in_natural_order_with_reasons_warnings_and_plain_numbers(tmp_path):
    results = [_result("foreign-10"), _result("foreign-2"), _result("foreign-1", "fail", stab=0.5),
               _result("foreign-3", warnings=["foreign-3/train.csv: 2 gap(s) in time"]),
               {"device": "legacy-9", "status": "fail", "stage": "read", "reasons": ["a.csv: no such file"]}]
    assert sorted(["foreign-10", "foreign-2", "A01", "a1", "foreign-1"], key=natural_key) == \
        ["A01", "a1", "foreign-1", "foreign-2", "foreign-10"]
    spec = _spec()
    write_report(tmp_path, results, spec, worst_k=10)
    order = ["foreign-1", "foreign-2", "foreign-3", "foreign-10", "legacy-9"]
    rows = list(csv.DictReader(io.StringIO((tmp_path / "lot.csv").read_text())))
    assert [r["device"] for r in rows] == order
    assert rows[1]["train_s"] == "10760" and rows[1]["cv_rms_dph"] == "0.0000107"
    assert rows[4]["reason"] == "read: a.csv: no such file"      # an old result.json: its stage in front
    lot = json.loads((tmp_path / "lot.json").read_text())
    assert [r["device"] for r in lot["devices"]] == order
    md = (tmp_path / "lot.md").read_text()
    assert [md.index(f"| {d} |") for d in order] == sorted(md.index(f"| {d} |") for d in order)
    assert "e+" not in md and "e-0" not in md
    assert "| 2:59:20 | 14.090 |" in md and "| 0.0004886 |" in md and "| 99.94 % |" in md
    # the worst devices: the reason column, ties in natural order
    worst = md[md.index("## Worst devices"):md.index("## Warnings")]
    assert worst.splitlines()[2].endswith("| reason |")
    assert "| foreign-1 | fail |" in worst and "spec: held-out stability 0.5 deg/h > 0.1 deg/h |" in worst
    assert [r["device"] for r in worst_devices(results, 10)] == ["foreign-1", "foreign-2", "foreign-3", "foreign-10"]
    assert [w["device"] for w in lot["worst"]] == ["foreign-1", "foreign-2", "foreign-3", "foreign-10"]
    # each device's warnings, in a section of their own
    warn = md[md.index("## Warnings"):]
    assert "- **foreign-3** (pass):\n  - foreign-3/train.csv: 2 gap(s) in time" in warn
    assert "foreign-10" not in warn
    assert (tmp_path / "lot_histograms.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
