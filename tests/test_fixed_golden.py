"""|fixed - golden| on the simulator's paper scenarios (the golden fed with exactly the dequantized
input words), and `hdrg compensate --impl fixed`."""
import numpy as np
import pytest

from firmware_ref import formats as F
from host_tools.fixed.fixed_point import compensate_log
from host_tools.golden import compensate as comp
from host_tools.golden import runlog as rl
from host_tools.cli import main as cli_main
from host_tools.fitting.fit import fit, fit_logs
from host_tools.golden.model import BiasModel
from host_tools.fixed.fixed_point import dequantized_log
from host_tools.fixed.quantize import quantize
from host_tools.golden.reversal import ReversalConfig
from host_tools.simulation.sim import simulate
from fixed_compare import fixed_vs_golden

GOAL_DPH = 0.002


def fitted(log, order="combine_first", **kw):
    kw.setdefault("reversal", ReversalConfig("pair", order=order) if log.reversal else None)
    cfg = comp.fit_config_from_logs([log], **kw)
    if cfg.reversal is not None and cfg.reversal.order == "regress_first":
        model, _ = fit_logs([log], cfg, terms="all")
        model.source = "<fit>"
        return model
    prep = comp.prepare(log, cfg)
    res = fit(prep.u, prep.v, None, prep.y, prep.valid, terms="all")
    return BiasModel(cfg, res.terms, res.coef, source="<fit>")


@pytest.mark.parametrize("scenario,combiner,order", [
    ("paper-mr-cycle-4dpm", "pair", "combine_first"), ("paper-mr-cycle-4dpm", "trend", "combine_first"),
    ("paper-mr-cycle-4dpm", "none", "regress_first"), ("paper-mr-cycle-4dpm", "pair", "regress_first"),
    ("paper-mr-cycle-4dpm", "trend", "regress_first"), ("paper-ftr-cycle-4dpm", None, None)])
def test_fixed_vs_golden_paper_scenarios(scenario, combiner, order):
    """|fixed - golden| on the same input words, measured against the quantizer's bound and the
    0.002 deg/h goal, for the legacy order (combine_first), the regress_first residual combiner
    (two banks: none, pair, trend) and FTR."""
    log = simulate(scenario, seed=0)
    model = fitted(log, reversal=None if combiner is None else ReversalConfig(combiner, order=order))
    c = fixed_vs_golden(log, model)
    q, fixed, gold, flags, err, v = c.q, c.fixed, c.gold, c.flags, c.err, c.valid
    assert q.table.n_banks == (2 if order == "regress_first" else 1)
    emax, esig, bmax = c.emax, float(np.std(err[v])), c.bmax
    print(f"\n{scenario} {combiner} {order}: |fixed - golden| max {emax:.3g} deg/h, 1 sigma {esig:.3g} deg/h, "
          f"bias max {bmax:.3g} deg/h; bound {q.report['bound_dph']['out']:.3g} deg/h")
    assert emax < GOAL_DPH
    assert emax <= q.report["bound_dph"]["out"] and bmax <= q.report["bound_dph"]["bias_word"]
    # the error is the output rounding, not a bias: mean well below the half LSB
    assert abs(float(np.mean(err[v]))) < 2.0 ** -F.OUT_FRAC / 8
    assert not (flags & (F.FLAG_SAT | F.FLAG_INPUT_SAT)).any()
    # and the compensation itself works: the fixed output is as flat as the golden one
    assert np.std(fixed.rate_dph[v]) == pytest.approx(np.std(gold.rate_dph[v]), rel=1e-3)


def test_cli_compensate_fixed(tmp_path, capsys):
    log = simulate("paper-mr-cycle-4dpm", seed=1, duration_s=4000.0)
    rl.write(log, tmp_path / "run.csv")
    model = fitted(log)
    model.to_json(tmp_path / "model.json")
    args = [str(tmp_path / "run.csv"), "--model", str(tmp_path / "model.json")]
    assert cli_main(["compensate", *args, "-o", str(tmp_path / "fx.csv"), "--impl", "fixed"]) == 0
    assert cli_main(["compensate", *args, "-o", str(tmp_path / "fl.csv")]) == 0
    fx, fl = rl.read(tmp_path / "fx.csv"), rl.read(tmp_path / "fl.csv")
    assert fx.columns.keys() == fl.columns.keys()
    assert fx.metadata["compensation_impl"] == "fixed" and fx.metadata["compensated"] == "yes"
    np.testing.assert_array_equal(fx["valid"], fl["valid"])
    run = rl.read(tmp_path / "run.csv")
    # the words, exactly (hdrg compensate writes no number where not valid: NaN at the same rows)
    np.testing.assert_array_equal(fx.rate_dph, comp.blank_invalid(compensate_log(run, model)).rate_dph)
    gold = comp.compensate(dequantized_log(run, model), model)
    assert np.nanmax(np.abs(fx.rate_dph - gold.rate_dph)) < GOAL_DPH   # NaN at the same (invalid) rows
    # with a table file: the same words
    from host_tools.cli.quantize import configure, run
    import argparse
    p = argparse.ArgumentParser()
    configure(p)
    assert run(p.parse_args([str(tmp_path / "model.json"), "-o", str(tmp_path / "table.json"),
                                 "--memh", str(tmp_path / "t.memh")])) == 0
    for table in ("table.json", "t.memh"):
        assert cli_main(["compensate", *args, "-o", str(tmp_path / "fx2.csv"), "--impl", "fixed",
                         "--table", str(tmp_path / table)]) == 0
        np.testing.assert_array_equal(rl.read(tmp_path / "fx2.csv").rate_dph, fx.rate_dph)
    capsys.readouterr()
    # a table of another model is refused, and --table needs --impl fixed
    other = fitted(simulate("paper-mr-cycle-4dpm", seed=2, duration_s=4000.0))
    other.to_json(tmp_path / "other.json")
    assert cli_main(["compensate", str(tmp_path / "run.csv"), "--model", str(tmp_path / "other.json"), "-o",
                     str(tmp_path / "x.csv"), "--impl", "fixed", "--table", str(tmp_path / "table.json")]) == 2
    assert "does not match the model" in capsys.readouterr().err
    assert cli_main(["compensate", *args, "-o", str(tmp_path / "x.csv"), "--table", str(tmp_path / "table.json")]) == 2
    assert "--impl fixed" in capsys.readouterr().err


def test_fixed_refuses_like_golden():
    log = simulate("paper-ftr-cycle-4dpm", seed=0, duration_s=600.0)
    model = fitted(simulate("paper-mr-cycle-4dpm", seed=0, duration_s=2000.0))
    with pytest.raises(ValueError, match="FTR"):
        compensate_log(log, model)
    done = comp.compensate(log, fitted(log))
    with pytest.raises(ValueError, match="already compensated"):
        compensate_log(done, fitted(log))
    with pytest.raises(ValueError, match="sample rate"):
        compensate_log(simulate("paper-ftr-cycle-4dpm", seed=0, duration_s=600.0, sample_rate_hz=2.0), fitted(log))


def test_fixed_residual_pairing_on_a_power_on_damping_change():
    """regress_first in fixed point on a held-out power-on whose damping term moved by 2 deg/h
    (raw rate + 2: c = s R gets s 2, which the banks do not know): |fixed - golden| stays within
    the bound and 0.002 deg/h for none and pair, and the residual pairing removes the +-2 deg/h
    alternation that regression alone (none) leaves."""
    train = simulate("paper-mr-cycle-4dpm", seed=0, duration_s=6000.0)
    hold = simulate("paper-mr-cycle-4dpm", seed=5, duration_s=6000.0)
    hold = hold.with_columns(rate_dph=np.asarray(hold.rate_dph) + 2.0)
    spread = {}
    for comb in ("none", "pair"):
        model = fitted(train, reversal=ReversalConfig(comb, order="regress_first"))
        q = quantize(model)
        gold = comp.compensate(dequantized_log(hold, model), model)
        fixed = compensate_log(hold, model, table=q.table)
        np.testing.assert_array_equal(fixed["valid"], gold["valid"])
        v = gold["valid"] > 0
        emax = float(np.max(np.abs(fixed.rate_dph[v] - gold.rate_dph[v])))   # golden: NaN where not valid
        print(f"\nheld-out damping change, {comb}: |fixed - golden| max {emax:.3g} deg/h, bound "
              f"{q.report['bound_dph']['out']:.3g}; fixed output std {np.std(fixed.rate_dph[v]):.3g} deg/h")
        assert emax < GOAL_DPH and emax <= q.report["bound_dph"]["out"]
        spread[comb] = float(np.std(fixed.rate_dph[v]))
    assert spread["none"] > 1.5 and spread["pair"] < spread["none"] / 5


def test_cli_regress_first_fit_quantize_export_compensate(tmp_path, capsys):
    """The default flow for a mode-reversal log (`hdrg fit` now makes regress_first models):
    fit -> quantize -> export (memh) -> compensate --impl fixed --table: a two-bank table, the same
    words as compensate_log, within 0.002 deg/h of the golden on the dequantized words."""
    log = simulate("paper-mr-cycle-4dpm", seed=3, duration_s=4000.0)
    rl.write(log, tmp_path / "run.csv")
    assert cli_main(["fit", str(tmp_path / "run.csv"), "-o", str(tmp_path / "m.json"), "--order", "regress_first",
                     "--combiner", "pair"]) == 0
    model = BiasModel.from_json(tmp_path / "m.json")
    assert model.coef_mode2 is not None
    assert cli_main(["quantize", str(tmp_path / "m.json"), "-o", str(tmp_path / "t.json")]) == 0
    assert cli_main(["export", str(tmp_path / "t.json"), "--format", "mem", "-o", str(tmp_path / "exp")]) == 0
    assert cli_main(["compensate", str(tmp_path / "run.csv"), "--model", str(tmp_path / "m.json"), "-o",
                     str(tmp_path / "fx.csv"), "--impl", "fixed", "--table",
                     str(tmp_path / "exp" / "hdrg_table.memh")]) == 0
    capsys.readouterr()
    fx = rl.read(tmp_path / "fx.csv")
    run = rl.read(tmp_path / "run.csv")
    np.testing.assert_array_equal(fx.rate_dph, comp.blank_invalid(compensate_log(run, model)).rate_dph)
    gold = comp.compensate(dequantized_log(run, model), model)
    np.testing.assert_array_equal(fx["valid"], gold["valid"])
    assert np.nanmax(np.abs(fx.rate_dph - gold.rate_dph)) < GOAL_DPH   # NaN at the same (invalid) rows


def test_fixed_vs_golden_with_input_invalid_samples():
    """A simulated run with raw-rate samples beyond the full scale (one in a mode-1 window, a burst
    in a mode-2 window, one in an exchange): fixed and golden mark the same samples valid, flag the
    same ones 64, and agree within the goal where valid."""
    log = simulate("paper-mr-cycle-4dpm", seed=2, duration_s=4000.0)
    model = fitted(log, "regress_first")
    mode = np.asarray(log.mode)
    rows = [int(np.flatnonzero(mode == 1)[300]), *range(int(np.flatnonzero(mode == 2)[500]),
                                                         int(np.flatnonzero(mode == 2)[500]) + 4),
            int(np.flatnonzero(mode == 3)[200])]
    r = np.array(log.rate_dph)
    r[rows] = [1e9, -3e6, 5e6, 1e9, 2.5e6, 1e9]
    log = log.with_columns(rate_dph=r)
    fixed, flags = compensate_log(log, model, return_flags=True)
    deq = dequantized_log(log, model)
    gold = comp.compensate(deq, model)
    np.testing.assert_array_equal(fixed["valid"], gold["valid"])
    np.testing.assert_array_equal(flags & (31 | F.FLAG_INPUT_SAT), comp.prepare(deq, model).flags)
    assert np.flatnonzero(flags & F.FLAG_INPUT_SAT).tolist() == sorted(rows)
    v = gold["valid"] > 0
    assert np.max(np.abs(fixed.rate_dph[v] - gold.rate_dph[v])) < GOAL_DPH
    assert np.max(np.abs(gold.rate_dph[v])) < 100.0       # no output near the spikes' scale
