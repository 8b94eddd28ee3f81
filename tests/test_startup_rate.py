"""The rate estimator starts at power-on (the iir's start-up gear) and invalid rows carry no number.

* the iir's gear e = min(shift, floor(log2 k)): exact values at k = 1, 2, 4 on hand-made data,
  the fixed-point reference == the numba kernel bit for bit through the whole gear (shift 9 and
  10, restarts) and |fixed - golden| within the quantizer's bound;
* a model written with the old blanked warm-up is read with the gear; a wrong warm-up is refused;
  an iir table of layout version 2 is refused with a message saying what to do, other version-2
  tables are read;
* the paper's start-up (paper-startup-mr, a model fitted by the defaults on a chamber run): the
  first valid output at 185 s (the first settled sample with a window of each mode), not 1085 s;
* compensated output: rate_dph and bias_dph NaN where valid is 0 (empty in CSV), valid 0/1,
  round trips through CSV and NPZ; an empty cell of an input log's rate is an error naming file
  and line.
"""
import numpy as np
import pytest

from firmware_ref import table as T
from firmware_ref.compensate import run_reference
from firmware_ref.kernel import run_words
from firmware_ref.rate import iir_gear
from fixed_compare import fixed_vs_golden
from host_tools.fixed.quantize import quantize
from host_tools.golden import compensate as hc
from host_tools.golden import runlog as rl
from host_tools.golden.model import BiasModel
from host_tools.golden.rate import RateConfig, legacy_iir_warmup
from host_tools.vectors.builders import make_model, random_stream


# -- the gear --------------------------------------------------------------------------------------

def test_gear_steps():
    assert [iir_gear(k, 9) for k in (1, 2, 3, 4, 7, 8, 511, 512, 513, 10 ** 6)] == [0, 1, 1, 2, 2, 3, 8, 9, 9, 9]
    assert [iir_gear(k, 0) for k in (1, 2, 1000)] == [0, 0, 0]
    assert [iir_gear(k, 2) for k in (1, 3, 4, 100)] == [0, 1, 2, 2]


def test_golden_iir_from_the_first_difference():
    """k = 1: y = d1 (valid); k = 2, 3 (gear 1): y += (d - y) / 2; k = 4 (gear 2): y += (d - y) / 4."""
    p = np.array([10.0, 11.0, 14.0, 14.0, 22.0, 22.0])
    cfg = RateConfig("iir", shift=9, span=100.0, fs=1.0)
    assert cfg.warmup == 1
    dpdt, warm = cfg.slope(p)
    y1 = 1.0
    y2 = y1 + (3.0 - y1) / 2
    y3 = y2 + (0.0 - y2) / 2
    y4 = y3 + (8.0 - y3) / 4
    y5 = y4 + (0.0 - y4) / 4
    np.testing.assert_array_equal(warm, [True, False, False, False, False, False])
    np.testing.assert_array_equal(dpdt, [0.0, y1, y2, y3, y4, y5])
    # a restart starts the gear again: the sample after it is the first difference of the new segment
    dpdt, warm = cfg.slope(np.concatenate([p, [50.0, 53.0]]), [0, 6])
    assert warm[6] and not warm[7] and dpdt[7] == 3.0


def test_golden_iir_reaches_the_fixed_low_pass():
    """From k = 2**shift on the update is y += (d - y) 2**-shift, as the plain low-pass."""
    rng = np.random.default_rng(5)
    p = np.cumsum(rng.normal(0.0, 1.0, 300))
    shift = 4
    dpdt, _ = RateConfig("iir", shift=shift, span=1.0, fs=1.0).slope(p)
    d = np.diff(p)
    for k in range(16, 300):
        assert dpdt[k] == pytest.approx(dpdt[k - 1] + (d[k - 1] - dpdt[k - 1]) * 2.0 ** -shift, abs=1e-12)
    # and it differs from the plain low-pass before (the gear is not a no-op)
    assert dpdt[2] == pytest.approx(dpdt[1] + (d[1] - dpdt[1]) / 2)


@pytest.mark.parametrize("shift", [9, 10])
def test_fixed_reference_equals_numba_through_the_gear(shift):
    """The per-sample Python reference and the numba kernel agree bit for bit on 2600 samples of an
    iir at shift 9 / 10 (k saturates at 2**shift) with a restart after the saturation."""
    model = make_model(estimator="iir", shift=shift, combiner="pair", settle_s=1.0)
    table = quantize(model).table
    assert table.rate_warmup == 1 and table.rate_shift == shift
    s = random_stream(np.random.default_rng(shift), table, 2600)
    s["restart"][:] = 0
    s["restart"][[0, 1900]] = 1
    ref = run_reference(table, s["p"], s["r"], s["mode"], s["restart"], s["z"])
    got = run_words(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], detail=True)
    for key in ("out", "bias", "valid", "flags", "v", "s"):
        np.testing.assert_array_equal(ref[key], got[key], err_msg=key)
    # warm-up only at the two segment starts
    assert np.flatnonzero(np.asarray(got["flags"]) & 4).tolist() == [0, 1900]


def test_fixed_vs_golden_from_power_on(mr_log_from_power_on):
    """|fixed - golden| on the same input words within the quantizer's bound, including the start-up
    samples the gear now serves."""
    log, model = mr_log_from_power_on
    c = fixed_vs_golden(log, model)
    first = int(np.argmax(c.valid))
    assert first < 300                      # served from the first settled windows, not after 1024 samples
    assert c.emax <= c.q.report['bound_dph']['out'] and c.emax <= 0.002


@pytest.fixture(scope="module")
def mr_log_from_power_on():
    from host_tools.simulation.sim import simulate
    log = simulate("paper-mr-cycle-4dpm", seed=3, duration_s=1500.0)
    model = make_model(estimator="iir", shift=9, combiner="pair", settle_s=5.0, ref=float(np.mean(log["freq_hz"])),
                       span=float(np.ptp(log["freq_hz"])), rate_span=0.01)
    return log, model


# -- models and tables of the old start-up -----------------------------------------------------------

def test_old_model_with_blanked_warmup_is_read_with_the_gear(mr_log_from_power_on):
    log, model = mr_log_from_power_on
    d = model.to_dict()
    assert d["config"]["rate"]["warmup"] == 1
    d["config"]["rate"]["warmup"] = legacy_iir_warmup(9)            # 1024: written before the gear
    old = BiasModel.from_dict(d, "old.json")
    assert old.config.rate.warmup == 1
    np.testing.assert_array_equal(hc.compensate(log, old)["valid"], hc.compensate(log, model)["valid"])
    d["config"]["rate"]["warmup"] = 7                                 # neither: refused, naming the field
    with pytest.raises(ValueError, match="warmup 7 does not match"):
        BiasModel.from_dict(d, "bad.json")


def _with_version(words, version):
    words = list(words)
    words[1] = version
    words[-1] = T.crc32_words(words[:-1])
    return words


def test_version2_iir_table_is_refused_other_version2_tables_are_read():
    iir = quantize(make_model(estimator="iir", shift=9)).table
    with pytest.raises(T.TableError, match="quantize the model again"):
        T.Table.from_words(_with_version(iir.to_words(), 2), "old.bin")
    assert T.Table.from_words(iir.to_words(), "new.bin").rate_warmup == 1
    diff = quantize(make_model(kind="temp", ref=20.0, span=40.0, estimator="diff")).table
    assert T.Table.from_words(_with_version(diff.to_words(), 2), "old.bin") == diff
    assert iir.to_words()[1] == T.VERSION == 4


# -- the paper's start-up ------------------------------------------------------------------------------

def test_paper_startup_first_valid_output_at_185_s():
    """hdrg fit defaults on a chamber run, applied to a 45-min start-up: the first valid output at
    185 s (exchange 0..30 s, mode 1 30..150 s, exchange to 180 s, settling 5 s), no longer 1085 s."""
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.simulation.sim import simulate
    model, _ = fit_default([simulate("paper-mr-cycle-4dpm", seed=1)])
    assert model.config.rate.estimator == "iir" and model.config.rate.warmup == 1
    out = hc.compensate(simulate("paper-startup-mr", seed=11), model)
    t, valid = out.t_s, out["valid"] == 1
    assert t[valid][0] == 185.0
    # from 180 s every mode 1/2 sample more than 10 s after an exchange is served (issue target >= 99 %)
    exchange = out.mode == 3
    last_exchange = np.maximum.accumulate(np.where(exchange, t, -np.inf))
    serve = (t >= 180.0) & ~exchange & (t - last_exchange > 10.0)
    assert serve.sum() > 1500 and np.mean(valid[serve]) >= 0.99
    assert np.flatnonzero(out["flags"] & hc.FLAG_WARMUP).tolist() == [0]


# -- invalid rows carry no number ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def compensated(mr_log_from_power_on):
    log, model = mr_log_from_power_on
    return log, model, hc.compensate(log, model)


@pytest.mark.parametrize("impl", ["float", "fixed"])
def test_invalid_rows_are_nan_valid_is_0_1(mr_log_from_power_on, impl):
    log, model = mr_log_from_power_on
    out = hc.compensate(log, model, impl=impl)
    valid = out["valid"]
    assert valid.dtype == np.int64 and set(np.unique(valid)) == {0, 1}
    for col in ("rate_dph", "bias_dph"):
        assert np.isnan(out[col][valid == 0]).all() and np.isfinite(out[col][valid == 1]).all()
    assert (valid == 0).sum() > 100 and (valid == 1).sum() > 100
    assert "bias_dph" not in log and np.isfinite(log.rate_dph).all()     # the raw input stays in the input


def test_csv_and_npz_round_trip_blank_cells(tmp_path, compensated):
    _, _, out = compensated
    for name in ("out.csv", "out.npz"):
        rl.write(out, tmp_path / name)
        back = rl.read(tmp_path / name)
        for col in ("rate_dph", "bias_dph", "valid"):
            np.testing.assert_array_equal(back[col], out[col])   # NaN at the same rows
        assert back["valid"].dtype == np.int64
    lines = (tmp_path / "out.csv").read_text().splitlines()
    header = next(line for line in lines if not line.startswith("#")).split(",")
    i_rate, i_bias, i_valid = header.index("rate_dph"), header.index("bias_dph"), header.index("valid")
    rows = [line.split(",") for line in lines[lines.index(",".join(header)) + 1:]]
    assert {r[i_valid] for r in rows} == {"0", "1"}
    assert all((r[i_rate] == "" and r[i_bias] == "") == (r[i_valid] == "0") for r in rows)


def test_empty_input_rate_is_an_error_naming_file_and_line(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text("t_s,rate_dph,freq_hz\n0,1.5,6227.0\n1,,6227.1\n2,1.0,6227.2\n")
    with pytest.raises(rl.RunLogError, match=r"run\.csv:3: column 'rate_dph': empty cell"):
        rl.read(p)


def test_blank_only_where_not_valid(tmp_path):
    head = "t_s,rate_dph,freq_hz,bias_dph,valid\n"
    ok = tmp_path / "ok.csv"
    ok.write_text(head + "0,,6227.0,,0\n1,2.5,6227.1,0.5,1\n2,,6227.2,,0\n")
    log = rl.read(ok)
    assert np.isnan(log.rate_dph[[0, 2]]).all() and log.rate_dph[1] == 2.5 and len(log) == 3
    bad = tmp_path / "bad.csv"
    bad.write_text(head + "0,,6227.0,,0\n1,,6227.1,0.5,1\n")
    with pytest.raises(rl.RunLogError, match=r"bad\.csv:3: column 'rate_dph' is empty \(NaN\) at a valid sample"):
        rl.read(bad)
    other = tmp_path / "other.csv"
    other.write_text(head + "0,,,,0\n")
    with pytest.raises(rl.RunLogError, match=r"other\.csv:2: column 'freq_hz': empty cell"):
        rl.read(other)
    with pytest.raises(rl.RunLogError, match="NaN/inf is not a value"):
        rl.RunLog.from_arrays(t_s=np.arange(2.0), rate_dph=np.array([np.nan, 1.0]), freq_hz=np.full(2, 6227.0))
