"""`hdrg bench loop` (host_tools.bench.loop) on a fast subset: 3 foreign runs cut to 1500 s, 5 surrogates.
Structure and the never-worse invariants only; the 120-run numbers are measured with the command
(docs/LOOP.md)."""
import json

import pytest

from host_tools.bench import loop as bl
from host_tools import cli
from host_tools.cli import bench
from host_tools.fitting.diagnose_confirm import EFFECT_MIN_DROP
from host_tools.fitting.diagnose_report import VERDICTS
from host_tools.simulation.sim_foreign import EFFECT_KINDS


def test_plan_has_a_third_clean_runs_and_every_kind():
    p = bl.plan(120, seed=0)
    assert len(p) == 120 and sum(r["effect"] is None for r in p) == 40
    kinds = {r["effect"] for r in p if r["effect"]}
    assert kinds == set(EFFECT_KINDS) and len(kinds) >= 8
    for r in p:
        if r["effect"] in ("exchange_transient", "imperfect_reversal"):
            assert r["reversal"]
        if r["effect"]:
            assert bl.STRENGTH_LO <= r["strength"] <= bl.STRENGTH_HI
    assert bl.plan(120, seed=0) == p and bl.plan(120, seed=1) != p


@pytest.fixture(scope="module")
def result():
    return bl.run_benchmark(3, seed=0, duration_s=1500.0, n_surrogates=5)


def test_fast_subset_structure_and_never_worse(result):
    recs, s = result["records"], result["summary"]
    assert [r["i"] for r in recs] == [0, 1, 2] and recs[0]["effect"] is None
    for r in recs:
        assert r["verdict"] in VERDICTS
        assert r["final"] <= r["base"] * (1 + 1e-12)          # never worse on the held-out run
        for st in r["steps"]:
            if st["confirmed"]:
                assert st["after"] <= 0.95 * st["before"]
                assert st["material"] == (st["after"] <= (1 - EFFECT_MIN_DROP) * st["before"])
            else:
                assert st["material"] is False
        if r["effect"]:
            assert r["effect_ratio"] > 0
    assert s["runs"] == 3 and s["worse_confirmed"] == 0 and s["found_without_drop"] == 0 and s["never_worse"]
    assert s["false_discovery"]["n"] == 1


def _same(a: list, b: list) -> bool:
    """The records equal but for their wall-clock seconds (NaN equal to NaN)."""
    def strip(recs):
        return json.dumps([{k: v for k, v in r.items() if k != "seconds"} for r in recs], sort_keys=True)
    return strip(a) == strip(b)


def test_two_workers_and_shards_give_the_serial_records(result, tmp_path, capsys):
    """The engine of hdrg lot (host_tools.lot.parallel): 2 local processes give the serial run's
    records in run order; the shards of --shard K/M merged give them too (through the command)."""
    par = bl.run_benchmark(3, seed=0, duration_s=1500.0, n_surrogates=5, workers=2, json_path=tmp_path / "p.json")
    assert [r["i"] for r in par["records"]] == [0, 1, 2] and _same(par["records"], result["records"])
    assert par["summary"] == result["summary"]
    assert _same(json.loads((tmp_path / "p.json").read_text())["records"], result["records"])
    parts = [bl.run_benchmark(3, seed=0, duration_s=1500.0, n_surrogates=5, shard=(k, 2)) for k in (1, 0)]
    for k, part in zip((1, 0), parts):
        (tmp_path / f"s{k}.json").write_text(json.dumps(part))
    assert cli.main(["bench", "loop", "--merge", str(tmp_path / "s0.json"), str(tmp_path / "s1.json"),
                     "--json", str(tmp_path / "m.json")]) == 0
    capsys.readouterr()
    merged = json.loads((tmp_path / "m.json").read_text())
    assert merged["summary"] == json.loads(json.dumps(result["summary"]))
    assert _same(merged["records"], result["records"])          # in run order
    assert cli.main(["bench", "loop", "--merge", str(tmp_path / "s0.json"), str(tmp_path / "s0.json")]) == 2
    assert "share a run" in capsys.readouterr().err
    assert cli.main(["bench", "loop", "--runs", "1", "--workers", "0"]) == 2
    assert "--workers must be >= 1" in capsys.readouterr().err


def test_cli_is_registered_and_merges_shards(result, tmp_path, capsys):
    assert bench.available()["loop"] == ("host_tools.cli.bench_loop", "host_tools.bench.loop")
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps({"records": result["records"][:1]}))
    b.write_text(json.dumps({"records": result["records"][1:]}))
    assert cli.main(["bench", "loop", "--merge", str(a), str(b), "--json", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "detection" in out and "false discovery" in out and "held-out-worse confirmed 0" in out
    assert json.loads((tmp_path / "m.json").read_text())["summary"]["runs"] == 3


def test_measured_splits_are_disjoint_and_cover_both_legs():
    import numpy as np

    import os

    from host_tools.golden import runlog
    path = f"{bl.MEASURED_ROOT}/{bl.MEASURED['tofupilot-x']}"
    if not os.path.exists(path):
        pytest.skip(f"measured data not here: {path}")
    log = runlog.read(path)
    sp = bl.splits(log)
    assert set(sp) == {"cool->heat", "heat->cool", "blocks"}
    for tr, ho in sp.values():
        assert not np.any(tr & ho) and np.all(tr | ho)
    temp = np.asarray(log["temp_c"])
    cool, heat = sp["cool->heat"]
    assert temp[heat].max() > 70 and temp[cool].min() < -15


def test_summary_counts_a_family_named_by_a_structure_step_separately():
    """A thermal_lag found as a lag of the proxy (kind structure) names the family: it counts in
    detection_or_structure, not in detection; the same naming on a clean run is counted as its
    false-positive side (clean_runs_naming_family)."""
    def rec(i, effect, steps, verdict, ratio=3.0):
        return {"i": i, "effect": effect, "reversal": False, "effect_ratio": ratio if effect else None,
                "verdict": verdict, "base": 1.0, "final": 0.5, "third_base": 1.0, "third_final": 0.9,
                "steps": [{"effect": f, "kind": k, "confirmed": True, "before": 1.0, "after": 0.5} for f, k in steps],
                "named": bool(effect and any(k == "effect" and bl._named(effect, f) for f, k in steps)),
                "named_or_structure": bool(effect and any(bl._named(effect, f) for f, _ in steps))}
    recs = [rec(0, None, [("thermal_lag", "structure")], "model structure improved"),
            rec(1, "thermal_lag", [("thermal_lag", "structure")], "model structure improved"),
            rec(2, "aux", [("aux_vdd", "effect")], "effect found"),
            rec(3, None, [], "no significant missing effect")]
    s = bl.summarize(recs)
    assert s["detection"]["k"] == 1 and s["detection"]["n"] == 2
    assert s["detection_or_structure"]["k"] == 2
    assert s["clean_runs_naming_family"]["n"] == 2 and s["clean_runs_naming_family"]["thermal_lag"] == 1
    assert s["clean_runs_naming_family"]["aux"] == 0 and s["false_discovery"]["k"] == 0
    assert "structure" in s["detection_rule"]


def test_a_minor_effect_step_is_neither_a_detection_nor_a_false_discovery():
    """EFFECT_RULE: a confirmed effect step whose held-out drop is below EFFECT_MIN_DROP stays in the model but
    names nothing: it does not count as a detection, and on a clean run it is not "effect found"
    (counted under minor_only / minor_effect_steps_clean instead)."""
    def rec(i, effect, step, verdict):
        st = {"effect": step[0], "kind": "effect", "confirmed": True, "material": step[1], "before": 1.0,
              "after": 0.7 if step[1] else 0.9}
        return {"i": i, "effect": effect, "reversal": True, "effect_ratio": 3.0 if effect else None,
                "verdict": verdict, "base": 1.0, "final": st["after"], "third_base": 1.0, "third_final": 0.9,
                "steps": [st], "named": bool(effect and bl._names_effect(st) and bl._named(effect, st["effect"])),
                "named_or_structure": bool(effect and bl._named(effect, st["effect"]))}
    recs = [rec(0, None, ("turn_on", False), "minor improvement confirmed"),
            rec(1, "periodic", ("periodic", False), "minor improvement confirmed"),
            rec(2, "aux", ("aux_vdd", True), "effect found"),
            rec(3, None, ("aux_vdd", True), "effect found")]
    s = bl.summarize(recs)
    assert s["detection"] == {"n": 2, "k": 1, "rate": 0.5}
    assert s["false_discovery"]["k"] == 1 and s["mr_control"]["k"] == 1
    assert s["minor_only"] == 1 and s["minor_effect_steps_clean"] == 1
    assert "MATERIAL" in s["detection_rule"]
    old = {k: v for k, v in recs[2]["steps"][0].items() if k != "material"}      # records before the rule
    assert bl._names_effect(old) and not bl._names_effect({**old, "material": False})


def test_second_training_run_is_another_rate_of_the_same_power_on_and_keeps_the_invariants(capsys):
    dev = bl.foreign_device(1)
    one = bl._training_runs(dev, True, 1500.0, None)
    two = bl._training_runs(dev, True, 1500.0, 3.0, effect="thermal_lag", strength=2.0)
    assert len(one) == 1 and len(two) == 2
    assert [r.metadata["profile"] for r in two] == ["trapezoid 4 degC/min", "trapezoid 3 degC/min"]
    assert [r.metadata["power_on"] for r in two] == ["0", "0"]
    assert two[1].metadata["noise_seed"] == str(bl.SECOND_TRAIN_NOISE)
    spec = bl.plan(3, seed=0)[1]                      # an effect run
    r = bl.run_one(spec, duration_s=1500.0, n_surrogates=5, second_train=3.0)
    assert r["final"] <= r["base"] * (1 + 1e-12)
    assert all(st["after"] <= 0.95 * st["before"] for st in r["steps"] if st["confirmed"])
    assert r["effect_ratio"] > 0 and r["oracle_fit_ratio"] > 0
    # the base model of two runs is fitted on both: it differs from the one-run base
    b1, b2 = bl._base_model(one), bl._base_model(bl._training_runs(dev, True, 1500.0, 3.0))
    assert b1.coef.tolist() != b2.coef.tolist()
    assert cli.main(["bench", "loop", "--runs", "1", "--second-train", "0"]) == 2
    assert "--second-train must be a chamber rate > 0" in capsys.readouterr().err


def test_a_clean_turn_on_at_the_devices_self_heating_time_constant_is_told_apart():
    """The strict false discovery counts it; ``clean_found_self_heating`` says which of them is the
    device's own power-on self-heating (clean physics of the foreign family)."""
    from host_tools.bench.loop import SELF_HEATING_TAU_FACTOR, self_heating_turn_on, summarize
    from host_tools.simulation.sim_foreign import foreign_device
    tau = foreign_device(99).self_heating["tau_s"]

    def rec(steps, effect=None, verdict="effect found"):
        return {"i": 99, "device": 99, "effect": effect, "strength": 0.0, "reversal": True, "verdict": verdict,
                "steps": steps, "base": 1.0, "final": 0.8, "third_base": 1.0, "third_final": 0.9,
                "effect_ratio": None, "oracle_fit_ratio": None, "named": False, "named_or_structure": False}

    def step(effect, t, material=True):
        return {"effect": effect, "params": {"tau_s": t}, "kind": "effect", "confirmed": True, "material": material,
                "before": 1.0, "after": 0.8}

    assert self_heating_turn_on(rec([step("turn_on", 0.75 * tau)]))
    assert not self_heating_turn_on(rec([step("turn_on", 1.1 * SELF_HEATING_TAU_FACTOR * tau)]))
    assert not self_heating_turn_on(rec([step("turn_on", tau), step("aux_vdd", 1000.0)]))
    assert not self_heating_turn_on(rec([step("turn_on", tau)], effect="turn_on"))
    assert not self_heating_turn_on(rec([step("turn_on", tau, material=False)], verdict="minor improvement confirmed"))
    s = summarize([rec([step("turn_on", tau)])])
    assert s["false_discovery"]["k"] == 1 and s["clean_found_self_heating"] == 1
