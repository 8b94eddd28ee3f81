"""`hdrg bench accuracy` (host_tools.bench.accuracy) on a fast subset: 4 foreign devices, short
runs.  Structure and sanity only; the 50-device table is measured with the command (docs/ACCURACY.md)."""
import copy
import json

import numpy as np
import pytest

from host_tools.bench import accuracy as ba
from host_tools import cli
from host_tools.cli import bench
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

PIPES = ["ftr/raw", "ftr/diff", "ftr/iir9", "mr-trend/raw", "mr-trend/diff", "mr-pair/diff"]
DUR = 4000.0


@pytest.fixture(scope="module")
def result():
    return ba.run_benchmark(4, seed=0, patterns=PIPES, duration_s=DUR)


def test_structure_and_sanity(result):
    recs, summ = result["records"], result["summary"]
    assert [r["seed"] for r in recs] == [0, 1, 2, 3]
    assert list(summ) == PIPES
    for r in recs:
        assert set(r["ratio"]) == set(PIPES) and not r["errors"]
        assert all(np.isfinite(v) and v > 0 for v in r["ratio"].values())
        for kind, fl in r["floor"].items():
            dev = foreign_device(r["seed"])
            assert 0.5 * dev.noise["white_dph"] < fl < 3.0 * dev.noise["white_dph"] + 0.2
        for name, std in r["std"].items():
            assert std / r["floor"]["mr" if name.startswith("mr") else "ftr"] == pytest.approx(r["ratio"][name])
    for row in summ.values():
        a = row["all"]
        assert a["n"] == 4 and a["failed"] == 0 and a["median"] <= a["p90"]
    # a clearly bad option (no model) against a good one
    assert summ["ftr/raw"]["all"]["median"] > 3 * summ["ftr/diff"]["all"]["median"]
    assert summ["mr-trend/raw"]["all"]["median"] > 1.5 * summ["mr-trend/diff"]["all"]["median"]
    assert result["config"]["duration_s"] == DUR


def test_floor_run_has_no_thermal_bias():
    dev = foreign_device(2)
    for reversal in (False, True):
        fl = simulate_foreign(dev, 2.0, reversal, 1, 1, DUR, thermal=False)
        run = simulate_foreign(dev, 2.0, reversal, 1, 1, DUR)
        m = fl.mode
        ok = m != 3
        c = np.where(m == 2, -1.0, 1.0) * fl.rate_dph
        assert abs(np.corrcoef(c[ok], fl["temp_c"][ok])[0, 1]) < 0.3
        assert ba.floor_of(fl) < 0.2 * np.std((np.where(m == 2, -1.0, 1.0) * run.rate_dph)[ok])


def test_damping_change_subset_is_defined_by_the_power_on_change(result):
    for r in result["records"]:
        dev = foreign_device(r["seed"])
        assert (r["damping_change_dph"] == 0.0) == (dev.damping_change(0)[0] == dev.damping_change(1)[0])
    big = [r for r in result["records"] if r["damping_change_dph"] > ba.DAMPING_CHANGE_DPH]
    assert result["summary"]["ftr/diff"]["damping_change"]["n"] == len(big)


def test_options_and_errors():
    names = [o.name for o in ba.all_options()]
    assert "ftr/diff" in names and "mr-trend/iir9" in names and "mr-pair/lsq32" in names
    assert any(n.startswith("rf-") for n in names) == ba.has_order()
    assert [o.name for o in ba.select_options(["ftr/iir*"])] == ["ftr/iir4", "ftr/iir7", "ftr/iir9", "ftr/iir9+auto"]
    assert "mr-trend/diff+auto" in names
    with pytest.raises(ValueError, match="matches no option; known: ftr/raw"):
        ba.select_options(["ftr/kalman"])
    for kw, match in (({"n_devices": 0}, "--devices"), ({"seed": -1}, "--seed"), ({"holdout_rate": 0.0}, "--holdout-rate")):
        with pytest.raises(ValueError, match=match):
            ba.run_benchmark(**{"n_devices": 1, **kw})


def test_cli(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert cli.main(["bench", "accuracy", "--devices", "1", "--duration", "2500", "--pipelines", "ftr/diff",
                     "ftr/raw", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| ftr/diff |" in text and "| ftr/raw |" in text and "| estimator | ftr |" in text
    data = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON {c}"))
    assert data["records"][0]["seed"] == 0 and set(data["summary"]) == {"ftr/diff", "ftr/raw"}
    assert cli.main(["bench", "accuracy", "--devices", "1", "--pipelines", "nope/*"]) == 2
    assert "matches no option" in capsys.readouterr().err
    two = tmp_path / "two.json"         # 2 local processes: the same records
    assert cli.main(["bench", "accuracy", "--devices", "1", "--duration", "2500", "--pipelines", "ftr/diff",
                     "ftr/raw", "--json", str(two), "--workers", "2"]) == 0
    capsys.readouterr()
    assert json.loads(two.read_text())["records"] == data["records"]
    assert cli.main(["bench", "accuracy", "--devices", "1", "--workers", "0"]) == 2
    assert "--workers must be >= 1" in capsys.readouterr().err


def test_bench_registry_offers_only_importable_benchmarks(monkeypatch):
    monkeypatch.setitem(bench.BENCHMARKS, "ghost", ("host_tools.cli.bench_accuracy", "host_tools.no_such_bench_module"))
    avail = bench.available()
    assert "accuracy" in avail and "ghost" not in avail


def test_easy_device_reaches_the_floor_so_the_family_adds_no_unfittable_artefact():
    """All bias on the resonator node (the proxy's node), cubic-representable, no power-on scale
    change: FTR + 17 terms must come down to the noise floor on the held-out run.  The same device
    with its bias on its own (other) nodes must not (the weakness the family is there to expose)."""
    dev = foreign_device(1)
    easy = copy.deepcopy(dev)
    easy.damping_node = easy.common_node = easy.self_heating["node"] = easy.resonator_node
    easy.damping["change_sigma"] = 0.0
    easy.common["e3"] = 0.0
    ratios = []
    for d in (easy, dev):
        train, hold = simulate_foreign(d, 4.0, False, 0, 0), simulate_foreign(d, 2.0, False, 1, 1)
        floor = ba.floor_of(simulate_foreign(d, 2.0, False, 1, 1, thermal=False))
        std, err, share = ba.evaluate_option(ba.Option("ftr", "diff"), train, hold)
        assert not err and share >= ba.MIN_VALID_SHARE
        ratios.append(std / floor)
    assert ratios[0] < 1.3 < 3.0 < ratios[1]


def test_plausibility_against_measured(tmp_path):
    log = simulate_foreign(3, 3.0, False, 0, 0, 3000.0)
    path = tmp_path / "m.csv"
    from host_tools.golden import runlog
    runlog.write(log, path)
    text = ba.plausibility(2, 0, [str(path)])
    assert text.startswith("foreign (2 devices") and f"{path}: cubic residual" in text
    # a run that IS a cubic in temp_c plus white noise has residual / white about 1
    t = log["temp_c"]
    rng = np.random.default_rng(0)
    fake = log.with_columns(rate_dph=3 + 2 * t - 0.01 * t ** 3 + 0.3 * rng.standard_normal(len(t)))
    assert ba.cubic_residual(fake) == pytest.approx(0.3, rel=0.05)


def test_effect_sizes_are_positive_for_every_kind():
    from host_tools.simulation.sim_foreign import EFFECT_KINDS
    sizes = ba.effect_sizes(1, 0)
    assert list(sizes) == list(EFFECT_KINDS)
    assert all(len(v) == 1 and 0.1 < v[0] < 100 for v in sizes.values())


def test_ablation_table():
    text = ba.ablation(1, 0, ["ftr/diff"], duration_s=2500.0)
    rows = text.splitlines()
    assert rows[0] == "| physics | ftr/diff |" and len(rows) == 2 + len(ba.ABLATIONS)
    assert all(" / " in r for r in rows[2:])


def test_the_self_heating_ablation_removes_only_the_rise_after_power_on():
    import copy
    from host_tools.simulation.sim_foreign import foreign_device, node_temperatures
    dev = foreign_device(3)
    quiet = copy.deepcopy(dev)
    ba.ABLATIONS["no self-heating"](quiet)
    t = np.arange(0.0, 3000.0)
    air = np.full_like(t, 20.0)                       # a soaked chamber: every node at 20 degC
    hot, cold = node_temperatures(dev, t, air), node_temperatures(quiet, t, air)
    k = dev.self_heating["node"]
    assert all(np.allclose(c, 20.0) for c in cold)
    assert hot[k][-1] - 20.0 > 0.5 * dev.self_heating["rise_c"] and abs(hot[k][0] - 20.0) < 1e-9
    assert dev.self_heating["rise_c"] > 0 and quiet.self_heating["tau_s"] == dev.self_heating["tau_s"]


def test_variant_options_and_split_runs_merge_to_the_whole():
    names = [o.name for o in ba.all_options()]
    if ba.has_order():
        assert {"rf-pair/diff+auto+s5", "rf-pair/auto+auto", "rf-pair/diff+auto+sig2"} <= set(names)
        o = ba.select_options(["rf-pair/diff+auto+s5"])[0]
        assert (o.settle, o.terms, o.reversal_config().settle_s) == (5.0, "auto", 5.0)
    assert {"ftr/auto+auto", "ftr/diff+auto+sig2"} <= set(names) and len(set(names)) == len(names)
    pipes = ["ftr/diff", "ftr/raw"]
    whole = ba.run_benchmark(2, patterns=pipes, duration_s=2500.0)
    parts = [ba.run_benchmark(1, patterns=pipes, duration_s=2500.0, start=i) for i in (1, 0)]
    merged = ba.merge(json.loads(json.dumps(p)) for p in parts)
    assert [r["seed"] for r in merged["records"]] == [0, 1] and merged["config"]["devices"] == 2
    assert json.dumps(merged["records"]) == json.dumps(whole["records"])         # the serial run's, in order
    for name in pipes:   # (the damping-change subset is empty here: nan == nan fails)
        assert merged["summary"][name]["all"] == whole["summary"][name]["all"]
        assert merged["summary"][name]["damping_change"]["n"] == whole["summary"][name]["damping_change"]["n"]
    for kw in ({"workers": 2}, {"scheduler": "dask"}):   # the engine of hdrg lot: the serial records, in order
        if "scheduler" in kw:
            distributed = pytest.importorskip("distributed")
            with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                          dashboard_address=None) as cluster:
                par = ba.run_benchmark(2, patterns=pipes, duration_s=2500.0, scheduler=cluster.scheduler_address)
        else:
            par = ba.run_benchmark(2, patterns=pipes, duration_s=2500.0, **kw)
        assert json.dumps(par["records"]) == json.dumps(whole["records"]), kw
        assert json.dumps(par["summary"]) == json.dumps(whole["summary"])
    with pytest.raises(ValueError, match="share a device"):
        ba.merge([parts[0], parts[0]])
    other = ba.run_benchmark(1, patterns=["ftr/raw"], duration_s=2500.0, start=2)
    with pytest.raises(ValueError, match="differ in options"):
        ba.merge([parts[0], other])


def test_servable_samples_start_at_power_on_and_skip_exchanges():
    """The availability-counting metric: an MR run is servable from power-on + 180 s except the
    exchanges and 10 s after each; an option valid on < 99 % of them fails with the share named."""
    log = simulate_foreign(3, 4.0, True, 0, 0, 3000.0)
    serve = ba.servable(log)
    t = log.t_s - log.t_s[0]
    assert not serve[t < 180].any() and serve.any()
    assert not serve[log.mode == 3].any()
    ends = np.flatnonzero((log.mode[:-1] == 3) & (log.mode[1:] != 3)) + 1
    for e in ends:
        after = (t >= t[e]) & (t < t[e] + ba.SETTLE_AFTER_EXCHANGE_S)
        assert not serve[after].any()
        assert serve[(t >= t[e] + ba.SETTLE_AFTER_EXCHANGE_S) & (t < t[e] + 60) & (t >= 180)].all()
    ftr = simulate_foreign(3, 4.0, False, 0, 0, 600.0)
    assert ba.servable(ftr).sum() == np.count_nonzero(ftr.t_s - ftr.t_s[0] >= 10.0)
    # a rate estimator whose warm-up blanks the first 20 minutes fails the option
    train = simulate_foreign(3, 4.0, True, 0, 0, 6000.0)
    hold = simulate_foreign(3, 2.0, True, 1, 1, 6000.0)
    std, err, share = ba.evaluate_option(ba.Option("mr-pair", "diffn16"), train, hold)
    assert not err and share >= ba.MIN_VALID_SHARE
    from host_tools.golden.compensate import fit_config_from_logs
    from host_tools.fitting.fit import fit_logs
    cfg = fit_config_from_logs([train], rate_estimator="diffn", n=1200, reversal={"combiner": "pair"})
    model, _ = fit_logs([train], cfg, terms=(0, 1, 4))
    x, share = ba.heldout_output(model, hold)
    assert share < ba.MIN_VALID_SHARE and len(x) > 0
