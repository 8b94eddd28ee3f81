"""Honest figures: the report's before does not depend on the model (mode reversal alone for a
mode-reversal run, the same numbers as `hdrg metrics`), the figures say what they show, the
Allan curve has confidence intervals and stops at a tenth of the run; the demo fits with `hdrg
fit`'s defaults; every table of diagnose.md has as many cells per row as its header; `-o` and
`--out` both work."""
from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from host_tools import cli
from host_tools.golden import runlog
from host_tools.simulation import sim


@pytest.fixture(scope="module")
def mr(tmp_path_factory):
    """Two 2-h mode-reversal chamber runs (seeds 1 and 2) and `hdrg fit` of the first."""
    d = tmp_path_factory.mktemp("honest")
    for seed, name in ((1, "a.csv"), (2, "b.csv")):
        runlog.write(sim.simulate("paper-mr-cycle-4dpm", seed=seed, duration_s=7200), d / name)
    assert cli.main(["fit", str(d / "a.csv"), "-o", str(d / "m.json")]) == 0
    return d


def _metrics_json(capsys, path):
    capsys.readouterr()
    assert cli.main(["metrics", str(path), "--tau", "1,100", "--json", "-"]) == 0
    run = json.loads(capsys.readouterr().out)["runs"][0]
    return {row["tau_s"]: row for row in run["per_tau"]}, run


def test_mode_reversal_alone_row_equals_hdrg_metrics(mr, tmp_path, capsys):
    assert cli.main(["report", str(mr / "b.csv"), "--model", str(mr / "m.json"), "-o", str(tmp_path / "r"),
                     "--no-plots"]) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "r" / "report.json").read_text())
    before = [r for r in doc["rows"] if r["role"] == "before"]
    assert len(before) == 1 and before[0]["output"].startswith("mode reversal alone (pair combiner")
    per_tau, run = _metrics_json(capsys, mr / "b.csv")
    assert run["kind"] == "reversal" and run["combiner"] == "pair"
    for tau in (1, 100):
        assert before[0][f"std{tau}_dph"] == pytest.approx(per_tau[float(tau)]["stability_dph"], rel=1e-12)
        assert before[0][f"pp{tau}_dph"] == pytest.approx(per_tau[float(tau)]["variation_dph"], rel=1e-12)
    roles = [r["role"] for r in doc["rows"]]
    assert roles == ["raw_per_mode", "before", "baseline", "model"]
    raw = doc["rows"][0]
    assert "raw output per mode" in raw["output"] and raw["std100_dph"] > 5 * before[0]["std100_dph"]
    # the gain is quoted against mode reversal alone, not against the raw per-mode output
    g = doc["runs"][0]["gain"]
    model = [r for r in doc["rows"] if r["role"] == "model"][0]
    assert g["before_dph"] == before[0]["std100_dph"] and g["after_dph"] == model["std100_dph"]
    assert g["gain"] == pytest.approx(before[0]["std100_dph"] / model["std100_dph"])
    assert "against mode reversal alone" in out
    md = (tmp_path / "r" / "report.md").read_text()
    assert "Model: m.json" in md and "training runs: a.csv" in md
    assert "held-out run" in md and "valid share" in md and "flags: " in md and "exchange " in md


def test_before_does_not_change_with_the_model(mr, tmp_path):
    from host_tools.fitting.fit import fit_logs
    from host_tools.fitting.report import report
    from host_tools.golden.compensate import fit_config_from_logs
    from host_tools.golden.model import BiasModel

    a, b = runlog.read(mr / "a.csv"), runlog.read(mr / "b.csv")
    default = BiasModel.from_json(mr / "m.json")
    other, _ = fit_logs([a], fit_config_from_logs([a], reversal={"combiner": "trend", "order": "combine_first"}),
                        "k0,k1")
    docs = [report([b], m, tmp_path / name, plots=False) for m, name in ((default, "d"), (other, "o"))]
    pick = [{r["role"]: r for r in d["rows"]} for d in docs]
    for role in ("raw_per_mode", "before"):
        assert pick[0][role] == pick[1][role]
    assert pick[0]["model"]["std100_dph"] != pick[1]["model"]["std100_dph"]


def test_ftr_before_is_the_raw_output(tmp_path):
    from host_tools.fitting.metrics import run_metrics, at_tau
    from host_tools.fitting.report import report
    from host_tools.fitting.fit_pipeline import fit_default

    a = sim.simulate("paper-ftr-cycle-4dpm", seed=1, duration_s=3600)
    b = sim.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=3600)
    model, _ = fit_default([a])
    doc = report([b], model, tmp_path / "r", train_logs=[a], plots=False)
    assert [r["role"] for r in doc["rows"]] == ["before", "baseline", "model"]
    ref = run_metrics(b, taus=(1.0, 100.0))
    assert doc["rows"][0]["std100_dph"] == pytest.approx(at_tau(ref, 100.0)["stability_dph"], rel=1e-12)


def test_titles_say_held_out_or_training_and_allan_is_bounded(mr, tmp_path):
    held = tmp_path / "held"
    assert cli.main(["report", str(mr / "b.csv"), "--model", str(mr / "m.json"), "--out", str(held)]) == 0
    doc = json.loads((held / "report.json").read_text())
    title = doc["titles"]["timeseries"][0]
    assert "b.csv: held-out run" in title and "m.json" in title and "trained on a.csv" in title
    assert "held-out run" in doc["titles"]["allan"]
    for name in ("timeseries.png", "loops.png", "allan.png"):
        assert (held / name).stat().st_size > 0
    duration = 7199.0
    for key, curve in doc["allan"]["b.csv"].items():
        for part in ("gapfree", "bridged"):
            c = curve[part]
            if not c:
                continue
            assert max(c["tau_s"]) <= duration / 10
            lo, dev, hi = (np.asarray(c[k]) for k in ("lo_dph", "adev_dph", "hi_dph"))
            assert np.all(lo < dev) and np.all(dev < hi)
        assert max(curve["gapfree"]["tau_s"]) <= curve["longest_stretch_s"] / 2
    train = tmp_path / "train"
    assert cli.main(["report", str(mr / "a.csv"), "--model", str(mr / "m.json"), "-o", str(train)]) == 0
    doc = json.loads((train / "report.json").read_text())
    assert "a.csv: training run (in-sample)" in doc["titles"]["timeseries"][0]
    assert doc["runs"][0]["held_out"] is False


def test_allan_curve_stretches_and_bridging():
    from host_tools.fitting.report import allan_curve

    rng = np.random.default_rng(0)
    n = 4000
    t = np.arange(n, dtype=float)
    y = rng.normal(0, 1.0, n)
    valid = np.ones(n, bool)
    full = allan_curve(y, t, valid)
    assert full["bridged"] is None and max(full["gapfree"]["tau_s"]) <= 400
    # white noise: adev(1 s) ~ 1, within its interval
    assert full["gapfree"]["lo_dph"][0] < 1.0 < full["gapfree"]["hi_dph"][0]
    valid[::100] = False                    # one invalid sample every 100: stretches of 99
    gapped = allan_curve(y, t, valid)
    assert max(gapped["gapfree"]["tau_s"]) <= 49
    assert min(gapped["bridged"]["tau_s"]) > 49 and gapped["bridged_share"] == pytest.approx(0.01, abs=1e-3)


def test_diagnose_md_tables_have_as_many_cells_as_their_header(tmp_path):
    from host_tools.fitting.diagnose import diagnose
    from host_tools.fitting.diagnose_report import TABLE_HEADER

    undeclared = {"periodic": {"amp_dph": 0.5, "period_s": 600.0}}
    train = [sim.simulate("paper-ftr-cycle-4dpm", seed=1, duration_s=7200, undeclared=undeclared)]
    hold = [sim.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=7200, undeclared=undeclared)]
    said = []
    rep, _ = diagnose(train, hold, out_dir=tmp_path / "d", plots=False, max_iter=2, n_surrogates=9,
                      progress=said.append)
    md = (tmp_path / "d" / "diagnose.md").read_text()
    tables, current = [], None
    for line in md.splitlines():
        if line.startswith("|"):
            if current is None:
                current = []
                tables.append(current)
            current.append(line)
        else:
            current = None
    assert tables
    for table in tables:
        cells = [len(re.split(r"(?<!\\)\|", row.strip())) - 2 for row in table]
        assert all(c == cells[0] for c in cells), table
    main = tables[0]
    assert [c.strip() for c in main[0].strip("|").split("|")] == list(TABLE_HEADER)
    assert len(main) == 3 + len(rep["iterations"])
    # the console numbers the steps as the table does, and prints every step's outcome with its metric
    assert rep["iterations"], said
    for k, it in enumerate(rep["iterations"], 1):
        row = [c.strip() for c in re.split(r"(?<!\\)\|", main[2 + k].strip())[1:-1]]
        assert row[0] == str(k) and row[1] == it["effect"]
        outcome = [m for m in said if m.startswith(f"iteration {k}:") and ("kept" in m or "reverted" in m)]
        assert len(outcome) == 1, said
        assert "held-out error, std of" in outcome[0] and " -> " in outcome[0]
        if it["confirmed"]:
            assert "confirmed on the held-out runs" in outcome[0]


def test_demo_fits_with_hdrg_fits_defaults(tmp_path, monkeypatch, capsys):
    from host_tools import demo
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.model import BiasModel

    monkeypatch.setattr(demo, "_close_the_loop", lambda out_dir, duration_s: None)     # the fit, not the loop
    assert cli.main(["demo", "-o", str(tmp_path / "demo"), "--duration", "7200"]) == 0
    out = capsys.readouterr().out
    assert "hdrg fit's defaults" in out and "mode reversal alone" in out
    got = BiasModel.from_json(tmp_path / "demo" / "model.json")
    train = runlog.read(tmp_path / "demo" / "run-seed1.csv")
    want, _ = fit_default([train])
    assert got.terms == want.terms
    np.testing.assert_array_equal(got.coef, want.coef)
    assert got.config.to_dict() == want.config.to_dict()
    # and the same as `hdrg fit` on the training run
    assert cli.main(["fit", str(tmp_path / "demo" / "run-seed1.csv"), "-o", str(tmp_path / "fit.json")]) == 0
    fitted = BiasModel.from_json(tmp_path / "fit.json")
    np.testing.assert_array_equal(got.coef, fitted.coef)
    assert got.config.to_dict() == fitted.config.to_dict()
    md = (tmp_path / "demo" / "report" / "report.md").read_text()
    assert "hdrg fit's defaults" in md and "Model: model.json" in md


def test_report_and_demo_take_o_and_out():
    parser = cli.build_parser() if hasattr(cli, "build_parser") else None
    if parser is None:
        pytest.skip("no parser builder")
    for flag in ("-o", "--out"):
        args = parser.parse_args(["report", "r.csv", "--model", "m.json", flag, "d"])
        assert args.out == "d"
        args = parser.parse_args(["demo", flag, "d"])
        assert args.out == "d"
