"""firmware_ref/FORMATS.md agrees with firmware_ref/formats.py; the derivation meets its rules;
the op counts are consistent with the algorithm."""
import pytest

from firmware_ref import docgen
from firmware_ref import formats as F
from firmware_ref import vocabulary as VOC
from firmware_ref.table import LAYOUT
from host_tools.golden import compensate as hc


def test_formats_md_generated_blocks_are_current():
    path = docgen.formats_md_path()
    text = path.read_text(encoding="utf-8")
    blocks = docgen.render_blocks()
    assert docgen.splice(text, blocks) == text, ("FORMATS.md is out of date: run "
                                                "`python -m firmware_ref.docgen --update`")
    for name in blocks:
        assert f"<!-- BEGIN {name} -->" in text
    for s in F.SIGNALS:
        assert s.name in text
    for name, _, _ in LAYOUT:
        assert f"| {name} |" in text


def test_c_header_vocabulary_block_is_current():
    """firmware_ref/c/hdrg_fw.h's constants block is generated from firmware_ref.vocabulary."""
    text = docgen.C_HEADER.read_text(encoding="utf-8")
    assert docgen.splice_c(text) == text, ("hdrg_fw.h's vocabulary block is out of date: run "
                                           "`python -m firmware_ref.docgen --update`")
    assert text.count(docgen.C_BEGIN) == 1 and text.count(docgen.C_END) == 1
    block = text[text.index(docgen.C_BEGIN):text.index(docgen.C_END)]
    for k, name in enumerate(VOC.ESTIMATORS):
        assert f"#define HDRG_EST_{name.upper()} {k}u" in block
    for bit, (name, _) in VOC.FLAGS.items():
        assert f" {bit}u " in block
    assert "HDRG_ST_EXCH_TO_2 = 3," in block and "HDRG_AUX_OSC = 6\n" in block
    # a changed vocabulary would be caught: the block renders from it
    stale = text.replace("#define HDRG_EST_IIR 3u", "#define HDRG_EST_IIR 4u")
    assert docgen.splice_c(stale) != stale


def test_vocabulary_names_every_stage_and_code():
    assert {s.stage for s in F.SIGNALS} <= set(VOC.STAGES)
    assert F.FLAGS is VOC.FLAGS and F.COMBINERS is VOC.COMBINERS and VOC.REVERSAL_COMBINERS == ("pair", "trend", "none")
    assert sorted(VOC.FLAGS) == [1 << k for k in range(8)]
    assert set(VOC.GOLDEN_FLAG_NAMES) == {1, 2, 4, 8, 16}


def test_formats_md_states_the_algorithm_constants():
    text = docgen.formats_md_path().read_text(encoding="utf-8")
    for needle in ("div_round_scaled(acc, cnt, 10)", "RHU(slope[o] * d, 16)", "RHU(y_hold - B, 11)",
                   "RHU(dP * T.g_u + T.u_off, T.sh_u)", "iy += RHU(((P - P[i-1]) << 24) - iy, e)", "e = min(T.rate_shift, floor(log2(k)))",
                   "min(2*age[o] + span[o], 2^22 - 1)", "clamp(div_round_scaled(mean - W[cur], dc2, 16), +-(2^40 - 1))"):
        assert needle in text, needle
    assert F.W_FRAC - F.RATE_FRAC == F.MEAN_EXTRA == 10 and F.SLOPE_EXTRA == 16 and F.OUT_SHIFT == 11
    assert F.D_MAX == 2 ** 22 - 1 and F.SLOPE_MAX == 2 ** 40 - 1
    assert F.SLOPE_MAX * F.D_MAX < 2 ** 62 and (2 ** 31) * (2 ** 31) <= 2 ** 62  # the int64 products


def test_derivation_meets_its_rules():
    d = F.derivation()
    rule = F.NoiseFigures().max_noise_increase
    assert d["f_frac_min"] <= F.FREQ_FRAC
    for key in ("f_noise_increase", "f_noise_increase_diff"):
        assert d[key] < rule                        # the 1 % rule (0.39 % at 2^-15 Hz)
    for key in ("r_noise_increase", "t_noise_increase"):
        assert d[key] < 0.01 * rule                 # 100x margin on the 1 % rule
    assert 2.0 ** -F.RATE_FRAC <= d["q_r_max_dph"] and 2.0 ** -F.TEMP_FRAC <= d["q_t_max_c"]
    # the word holds every supported drive frequency, and the rule holds at the stated noise
    assert d["f_range_hz"] >= 1.3 * F.FREQ_SUPPORTED_HZ[1] and F.FREQ_SUPPORTED_HZ[0] <= 1e3
    assert d["f_sigma_min_hz"] < F.NoiseFigures().sigma_f_hz
    # 1 degC/min is one LSB per sample to better than 0.1 degC/min even at the lowest drive frequency
    assert d["rate_resolution_lo_c_per_min"] < 0.1 and d["df_per_sample_lsb"] > 50
    assert d["r_range_dps"] >= 500
    assert 2 * d["out_rounding_dph"] < 0.002       # the final rounding leaves room in the goal
    # the rule itself: a noise of sigma plus an LSB of max_lsb_for_noise grows by exactly 1 %
    assert F.noise_increase(1.0, F.max_lsb_for_noise(1.0, 0.01)) == pytest.approx(0.01)


def test_flags_and_state_tables_match_the_golden():
    assert (F.FLAG_PROXY_CLAMPED, F.FLAG_RATE_CLAMPED, F.FLAG_WARMUP, F.FLAG_EXCHANGE, F.FLAG_STALE) == (
        hc.FLAG_PROXY_CLAMPED, hc.FLAG_RATE_CLAMPED, hc.FLAG_WARMUP, hc.FLAG_EXCHANGE, hc.FLAG_STALE)
    assert len(set(F.FLAGS)) == len(F.FLAGS) and max(F.FLAGS) < 256
    assert F.STATE_MODE[F.ST_MODE_1] == 1 and F.STATE_MODE[F.ST_MODE_2] == 2 and F.STATE_MODE[F.ST_FTR] == 0
    for st, vs in enumerate(F.STATE_VS):
        drive = vs & (F.VS_DRV_X | F.VS_DRV_Y)
        assert drive in (F.VS_DRV_X, F.VS_DRV_Y)             # exactly one drive axis, always
        assert not (vs & F.VS_SNS_X and vs & F.VS_SNS_Y)
        if vs & F.VS_SNS_X:
            assert drive == F.VS_DRV_Y                       # sense on the axis that is not driven
        if vs & F.VS_SNS_Y:
            assert drive == F.VS_DRV_X
        assert bool(vs & F.VS_NEG) == (F.STATE_SIGN[st] == -1)


def test_op_counts():
    base = F.op_counts("diff", 1, "pair")
    assert base["mul"] >= 16                                 # 15 Horner multiply-adds + k7 z
    assert F.op_counts("diff", 1, "ftr")["div_per_window"] == 0 and base["div_per_window"] == 1
    assert F.op_counts("diff", 1, "trend")["div_per_window"] == 2
    assert F.op_counts("diff", 1, "trend")["mul"] == base["mul"] + 1
    l8, l32 = F.op_counts("lsq", 8, "pair"), F.op_counts("lsq", 32, "pair")
    assert l32["mul"] - l8["mul"] == 24 and l32["mem"] - l8["mem"] == 24
    with pytest.raises(ValueError):
        F.op_counts("kalman", 1, "pair")
