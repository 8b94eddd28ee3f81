"""The closed loop starts from hdrg fit's model and never ends worse than it on a figure it reports
(host_tools.fitting.diagnose: base_model, versus_fit; host_tools.fitting.diagnose_confirm: the
start-up figures and worse_figures; the benches' loop-versus-fit records)."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from host_tools.bench import loop as bench_loop
from host_tools.bench import startup as bench_startup
from host_tools.cli import main
from host_tools.fitting import diagnose as loop
from host_tools.fitting.diagnose_confirm import (START_NOISE, START_NOISE_SHARE, confirmed_on_holdout, error_stats,
                                                 worse_figures)
from host_tools.fitting.diagnose_scan import FIT_BLOCK, chip_terms, explicit_weights, fit_block, poly_terms
from host_tools.simulation import sim
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

OFF = ["turn_on", "electronics", "damping_asym"]
PERIODIC = {"periodic": {"amp_dph": 0.5, "period_s": 600.0}}


def _world(seed, undeclared=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sim.simulate("paper-mr-cycle-4dpm", seed=seed, off=OFF, undeclared=undeclared or {},
                            profile=sim.cycle_profile(2.0, hold_s=1200, n_cycles=1))


@pytest.fixture(scope="module")
def periodic_runs():
    return [_world(1, PERIODIC), _world(3, PERIODIC)], [_world(2, PERIODIC)]


def _fit(train):
    return loop.base_model(train, loop.base_options(reversal=train[0].reversal))[0]


def test_with_no_step_the_loop_writes_hdrg_fits_model_and_reports_its_figures_first(periodic_runs):
    train, hold = periodic_runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep, model = loop.diagnose(train, hold, plots=False, max_iter=0)
    fitted = _fit(train)
    assert rep["final_is"] == "hdrg fit's model" and rep["versus_fit"] is None
    assert model.config == fitted.config and model.terms == fitted.terms
    np.testing.assert_array_equal(model.coef, fitted.coef)
    want = error_stats(hold, fitted)
    for key in ("std_dph", "std100_dph"):
        assert rep["baseline"]["holdout"][key] == pytest.approx(want[key], rel=1e-9)
        assert rep["final"][key] == pytest.approx(want[key], rel=1e-9)


def test_a_final_model_that_loses_to_hdrg_fit_on_a_figure_is_not_written(periodic_runs, monkeypatch, tmp_path):
    """The periodic effect is found (a step kept); with a tolerance under which any figure counts as
    lost, the loop writes hdrg fit's model, says on which figure, and marks the steps undone."""
    train, hold = periodic_runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep, model = loop.diagnose(train, hold, plots=False, max_iter=1)
    assert rep["verdict"] == "effect found" and rep["final_is"] == "the loop's model"
    assert rep["versus_fit"]["kept"] == "loop" and rep["versus_fit"]["on"] == "the held-out runs"
    v = rep["versus_fit"]["figures"]
    assert v["std100_dph"]["loop"] < v["std100_dph"]["fit"]
    monkeypatch.setattr(loop, "FIT_TOL", -0.999)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep, model = loop.diagnose(train, hold, plots=False, max_iter=1, out_dir=tmp_path)
    fitted = _fit(train)
    assert rep["verdict"] == loop.NOT_KEPT and rep["final_is"] == "hdrg fit's model"
    assert "std of 100-s averages" in rep["versus_fit"]["why"] and "hdrg fit's model is written" in rep["verdict_detail"]
    np.testing.assert_array_equal(model.coef, fitted.coef)
    assert model.fit["diagnose"]["effects"] == [] and model.fit["diagnose"]["final_is"] == "hdrg fit's model"
    kept = [it for it in rep["iterations"] if it["confirmed"]]
    assert kept and all(it["undone"] and "undone" in it["status"] for it in kept)
    assert loop.NOT_KEPT in (tmp_path / "diagnose.md").read_text()


@pytest.fixture(scope="module")
def startups():
    """Device 0 of the start-up benchmark: its calibration runs and hdrg fit's model of them."""
    dev = foreign_device(0)
    runs = bench_startup.calibration_runs(dev)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return dev, runs, _fit(runs)


def test_start_up_figures_are_given_for_start_ups_only(startups):
    """A run from its power-on at a constant ambient over 45 min has the start-up figures; a chamber
    run from its power-on (its first 45 min judge the temperature compensation) and a start-up
    recorded from 10 min after power-on do not."""
    dev, runs, fitted = startups
    chamber, room = runs[0], runs[2]
    got = error_stats([chamber, room], fitted)
    assert [r["start_std_dph"] is None for r in got["runs"]] == [True, False]
    r = got["runs"][1]
    assert r["start_std_dph"] > 0 and got["start_std_dph"] == pytest.approx(r["start_std_dph"])
    assert got["start_rep_dph"] == pytest.approx(abs(r["start_turn_on_dph"]))
    late = room.select(np.asarray(room.t_s) >= 600.0)
    assert error_stats([late], fitted)["start_std_dph"] is None


def _stats(std1, start_std, turn_on, std100=1.0, name="r"):
    run = {"run": name, "std_dph": std1, "std100_dph": std100, "rms_dph": 1.0, "rms_legs_dph": [1.0],
           "start_std_dph": start_std, "start_turn_on_dph": turn_on}
    return {"std_dph": std1, "std100_dph": std100, "start_std_dph": start_std, "start_rep_dph": abs(turn_on),
            "runs": [run]}


def test_a_step_that_serves_a_start_up_worse_is_not_confirmed():
    """CONFIRM_RULE's start-up part: the held-out error down 10 % but one start-up's window 10 %
    worse (well beyond the noise slack) is refused; a rise within the slack is not a rise."""
    std1 = 0.3
    slack = START_NOISE_SHARE * START_NOISE["start_std_dph"] * std1
    before = _stats(std1, 0.05, 0.02)
    assert confirmed_on_holdout(before, _stats(std1, 0.05, 0.02, std100=0.9))
    assert not confirmed_on_holdout(before, _stats(std1, 0.05 * 1.1 + slack, 0.02, std100=0.9))
    assert confirmed_on_holdout(before, _stats(std1, 0.05 * 1.02 + 0.9 * slack, 0.02, std100=0.9))
    assert not confirmed_on_holdout(before, _stats(std1, 0.05, -0.05, std100=0.9))     # |0-5 min mean| up
    worse = worse_figures(before, _stats(std1, 0.09, 0.02), ("start_std_dph",), 0.02)
    assert [k for k, _, _ in worse] == ["start_std_dph", "start_std_dph (r)"]


def test_hdrg_fits_k7_enters_the_loop_as_one_column_of_its_own_shape(startups):
    """FIT_BLOCK: the loop refits hdrg fit's k7 sum as one column; alone, the explicit refit gives
    back its terms with their relative weights (sum |w| = 1)."""
    _, runs, fitted = startups
    block = fit_block(fitted)
    assert len(block) == 1 and block[0]["gen"] == FIT_BLOCK and chip_terms(block) == fitted.config.aux.terms
    got = explicit_weights(runs, fitted.config, poly_terms(fitted), block)
    w0 = np.array([t["weight"] for t in fitted.config.aux.terms])
    w1 = np.array([t["weight"] for t in got])
    assert sum(abs(w1)) == pytest.approx(1.0)
    np.testing.assert_allclose(w1 / w1[0], w0 / w0[0], rtol=1e-9)


def test_the_startup_bench_fails_a_device_where_the_loop_is_worse_than_the_fit(monkeypatch, capsys):
    def rec(seed, fit, lp):
        rows = [{p: {"stability": s, "turn_on": 0.1 * s, "variation": s, "mean": 0.0, "valid_share": 1.0}
                 for p, s in (("mode reversal alone", 1.0), ("hdrg fit defaults", fit), ("noise floor", 0.1),
                              (bench_startup.LOOP, lp))} for _ in range(2)]
        return {"seed": seed, "error": "", "startups": rows, "model_turn_on": None}
    records = [rec(1, 0.2, 0.2), rec(2, 0.2, 0.2 * 1.06)]
    s = bench_startup.summarize(records)
    assert s["loop_worse_than_fit"] == [2] and s["loop_vs_fit_max"]["stability"] == pytest.approx(1.06)
    result = {"config": {"seed": 0, "startups": 2, "startup_s": 2700.0, "effect": "turn_on"}, "records": records,
              "summary": s}
    monkeypatch.setattr(bench_startup, "run_benchmark", lambda *a, **k: result)
    assert main(["bench", "startup", "--loop", "--devices", "2"]) == 1
    out = capsys.readouterr()
    assert "more than 5 % worse than hdrg fit: 1 (2)" in out.out and "FAILED" in out.err


def test_the_loop_bench_records_gap_valid_share_and_fails_a_run_worse_than_the_fit(tmp_path, capsys):
    def rec(i, base, final, floor, ident=True):
        return {"i": i, "device": i, "effect": "periodic", "strength": 1.0, "reversal": True, "verdict": "effect found",
                "steps": [], "base": base, "final": final, "floor": floor,
                "gap_closed": (base - final) / (base - floor), "loop_vs_fit": final / base, "final_is": "the loop's model",
                "valid_share": 0.75, "valid_share_fit": 0.76, "third_base": 1.0, "third_final": 1.0,
                "effect_ratio": 3.0, "oracle_fit_ratio": 3.0 if ident else 1.0, "named": True,
                "named_or_structure": True, "artifacts": [], "seconds": 0.0}
    records = [rec(0, 1.0, 0.4, 0.1), rec(1, 1.0, 0.8, 0.1), rec(2, 1.0, 1.1, 0.1, ident=False)]
    s = bench_loop.summarize(records)
    assert s["gap_closed_half_identifiable"] == {"n": 2, "k": 1, "rate": 0.5}
    assert s["loop_worse_than_fit"] == [2] and s["valid_share"]["runs_below_fit"] == 3
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"records": records}))
    assert main(["bench", "loop", "--merge", str(path)]) == 1
    out = capsys.readouterr()
    assert "gap to the floor half closed" in out.out and "FAILED" in out.err
