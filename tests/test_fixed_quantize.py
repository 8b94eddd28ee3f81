"""The quantizer (interval analysis: no in-range input overflows any intermediate; bound on
|fixed - golden|; refusals) and the coefficient table layout (pack/unpack, CRC, memh, C header,
table.json)."""
import argparse
import json
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_ref import formats as F
from firmware_ref.evaluator import evaluate
from firmware_ref.kernel import evaluate_words
from firmware_ref import table as T
from firmware_ref.table import FIELD_INDEX, MAGIC, N_FIXED, Table, TableError
from firmware_ref.terms import K_AUX, N_TERMS, TERM_POWERS
from host_tools.vectors.builders import make_model
from host_tools.cli.quantize import configure, run
from host_tools.fixed.quantize import QuantizeError, quantize, read_table

CORNERS = [-F.ONE, -F.ONE + 1, -1, 0, 1, F.ONE - 1, F.ONE]


def traced_max(table, points):
    """max |accumulator| over the Python reference's trace at the given (u, v, z) points."""
    worst = 0
    for u, v, z in points:
        trace = []
        evaluate(u, v, z, table, trace)
        worst = max(worst, max(abs(x) for x in trace))
    return worst


def sign_patterns():
    i_pow = np.array([p[0] if p else 0 for p in TERM_POWERS])
    j_pow = np.array([p[1] if p else 0 for p in TERM_POWERS])
    yield "all +", np.ones(N_TERMS)
    yield "all -", -np.ones(N_TERMS)
    yield "(-1)^(i+j): every term + at u = v = -1", (-1.0) ** (i_pow + j_pow)
    yield "(-1)^j", (-1.0) ** j_pow
    yield "(-1)^i, k7 -", np.where(np.arange(N_TERMS) == K_AUX, -1.0, (-1.0) ** i_pow)


@pytest.mark.parametrize("magnitude", [2.0 ** 21 / 17.5, 1234.5, 1.0, 3e-4])
def test_interval_analysis_adversarial(magnitude):
    """All 17 coefficients at one (largest legal) magnitude, signs chosen so that every partial
    sum is maximal at some corner: every accumulator stays <= 2^31 - 1, and the bound is reached
    exactly (the analysis is tight, not just safe)."""
    grid = [(u, v, z) for u in CORNERS for v in CORNERS for z in (-F.ONE, 0, F.ONE)]
    for name, signs in sign_patterns():
        model = make_model(coef=magnitude * signs)
        q = quantize(model, n_random=200)
        bound = q.report["interval_bounds"]["sum"]
        assert bound <= F.ACC_LIMIT
        worst = traced_max(q.table, grid)
        assert worst <= F.ACC_LIMIT, name
        if name == "all +":
            assert worst == bound  # u = v = z = 1: t equals the sum of the aligned row bounds
        m = q.report["measured_dph"]
        assert max(m["corners"], m["random"]) <= q.report["bound_dph"]["bias_B"], name
        # finest exponents: one more bit would break the limit for the binding group
        assert bound > F.ACC_LIMIT // 2 or q.table.e_acc == F.EXP_MAX


def test_mixed_magnitudes_align_rows():
    """Rows of very different size: each row keeps its own fine exponent; alignment shifts <= 31."""
    coef = np.zeros(N_TERMS)
    coef[[0, 4, 5, 6]] = 5e4          # row u^0 large
    coef[[3, 14, 15, 16]] = 1e-6      # row u^3 tiny
    coef[[1, 8]] = -2.0
    coef[K_AUX] = 7e-3
    q = quantize(make_model(coef=coef))
    t = q.table
    assert t.e_row[3] == t.e_acc + F.ALIGN_MAX and t.e_row[0] < t.e_row[1]
    grid = [(u, v, z) for u in CORNERS for v in CORNERS for z in (-F.ONE, F.ONE)]
    assert traced_max(t, grid) <= F.ACC_LIMIT
    m = q.report["measured_dph"]
    assert max(m["corners"], m["random"]) <= q.report["bound_dph"]["bias_B"]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-7.0, 4.0), min_size=N_TERMS, max_size=N_TERMS),
       st.lists(st.sampled_from([-1.0, 1.0, 0.0]), min_size=N_TERMS, max_size=N_TERMS),
       st.lists(st.tuples(st.sampled_from(CORNERS + [12345, -98765432]), st.sampled_from(CORNERS + [555555]),
                          st.sampled_from([-F.ONE, F.ONE, 0, 2 * F.ONE])), min_size=1, max_size=12))
def test_interval_analysis_random(log_mag, signs, points):
    coef = np.array(signs) * 10.0 ** np.array(log_mag)
    q = quantize(make_model(coef=coef), n_random=100)
    assert traced_max(q.table, points) <= F.ACC_LIMIT
    u, v, z = (np.array(a, np.int64) for a in zip(*points))
    b = evaluate_words(q.table, u, v, z) * 2.0 ** -F.Y_FRAC
    gold = q.model.evaluate(u * 2.0 ** -30, v * 2.0 ** -30, np.clip(z, -F.ONE, F.ONE) * 2.0 ** -30)
    assert np.max(np.abs(b - gold)) <= q.report["bound_dph"]["bias_B"]


def test_quantized_table_fields():
    model = make_model(kind="freq", ref=6227.386, span=3.0, estimator="lsq", n=7, rate_span=0.003,
                       combiner="trend", settle_s=2.0, max_stale_s=300.0)
    q = quantize(model, exchange_s=30.0, dwell_s=120.0, power_on_s=1.0)
    t = q.table
    assert (t.proxy_kind, t.rate_est, t.rate_n, t.rate_warmup, t.combiner) == (0, 2, 7, 6, 2)
    assert (t.settle_n, t.max_stale_n, t.power_on_n, t.exchange_n, t.dwell_n) == (2, 300, 1, 30, 120)
    assert t.p_ref == round(6227.386 * 2 ** F.FREQ_FRAC) and 2 ** 30 <= t.g_u < 2 ** 31 and 2 ** 30 <= t.g_v < 2 ** 31
    lsb = 2.0 ** -F.FREQ_FRAC
    assert t.g_u * 2.0 ** -(30 + t.sh_u) == pytest.approx(lsb / 3.0, rel=1e-9)
    assert t.g_v * 2.0 ** -(30 + t.sh_v) == pytest.approx(1.0 / (model.config.rate.divisor * 0.003 / lsb), rel=1e-9)
    assert (1 << t.s_bits) - 1 > model.config.rate.divisor * 0.003 / lsb >= (1 << (t.s_bits - 2))
    np.testing.assert_allclose(q.coef_quantized(), model.coef, rtol=0, atol=2.0 ** -(t.e_acc))
    b = q.report["bound_dph"]
    assert b["out"] < 0.002 and b["bias_B"] < 1e-4 and b["out"] >= b["parts"]["output_rounding"]


@pytest.mark.parametrize("kw,coef,match", [
    ({}, {0: 3e9}, "row u\\^0: the sum of \\|coefficients\\|"),
    ({}, {7: 5e9}, "k7 \\(aux\\)"),
    ({}, {0: 2e6, 1: 2e5}, "exceeds the output word range"),
    ({"span": 1e-7}, {}, "below one word LSB"),
    ({"kind": "temp", "ref": 0.0, "span": 1e5}, {}, "exceeds 2\\^30 word LSB"),
    ({"ref": 2.0e5}, {}, "outside the drive-frequency word"),
    ({"rate_span": 1e-9}, {}, "below one word LSB per sample"),
    ({"rate_span": 1e12}, {}, "rate-sum range"),
    ({"estimator": "lsq", "n": 5000}, {}, "history buffer"),
])
def test_quantize_refuses(kw, coef, match):
    c = np.zeros(N_TERMS)
    c[0] = 1.0
    for k, val in coef.items():
        c[k] = val
    with pytest.raises(QuantizeError, match=match):
        quantize(make_model(coef=c, **kw))


def test_quantize_refuses_bound_above_max_error():
    model = make_model()
    assert quantize(model, max_error_dph=0.002).report["bound_dph"]["out"] < 0.002
    with pytest.raises(QuantizeError, match="max-error"):
        quantize(model, max_error_dph=1e-4)
    with pytest.raises(QuantizeError, match="dwell_s"):
        quantize(model, dwell_s=0.0)


# -- the table layout ------------------------------------------------------------------------------

@pytest.fixture
def table():
    return quantize(make_model(combiner="trend", settle_s=2.0), n_random=10).table


def test_table_roundtrips(table):
    words = table.to_words()
    assert words[0] == MAGIC and words[1] == T.VERSION == 4 and words[2] == len(words) == N_FIXED + 1 == 73
    assert Table.from_words(words) == table
    data = table.to_bytes()
    assert data[:4] == b"HDRG" and len(data) == 4 * len(words)
    assert Table.from_bytes(data) == table
    assert Table.from_memh(table.to_memh()) == table
    import zlib
    assert words[-1] == zlib.crc32(data[:-4])
    negative = [k for k, m in enumerate(table.mant) if m < 0]
    assert negative and all(words[28 + k] >= 2 ** 31 for k in negative)  # two's complement


def test_table_readers_refuse_damage(table):
    words = table.to_words()
    for i, bad, match in [(0, 0x12345678, "magic"), (1, T.VERSION + 1, "version"), (1, 0, "version"), (2, 99, "length"), (30, words[30] ^ 1, "CRC")]:
        w = list(words)
        w[i] = bad
        with pytest.raises(TableError, match=match):
            Table.from_words(w)
    with pytest.raises(TableError, match="whole number"):
        Table.from_bytes(table.to_bytes()[:-1])
    with pytest.raises(TableError, match="hex word"):
        Table.from_memh("zz\n")
    # a table whose fields break the formats' preconditions is refused even with a valid CRC
    from dataclasses import replace
    with pytest.raises(TableError, match="minus E"):
        replace(table, e_acc=table.e_acc + 1, e_row=(table.e_acc,) + table.e_row[1:])
    with pytest.raises(TableError, match="g_v"):
        replace(table, g_v=1 << 31)


def _v1_words(table):
    """The version-1 words of a one-bank order-0 table (the 47-word fixed part, CRC last)."""
    from firmware_ref.table import N_FIXED_V1, crc32_words
    w = table.to_words()
    v1 = [w[0], 1, N_FIXED_V1 + len(table.aux_params) + 1] + w[3:N_FIXED_V1] + w[N_FIXED:-1]
    return v1 + [crc32_words(v1)]


def test_version_1_table_reads_as_combine_first_one_bank(table):
    temp = quantize(make_model(kind="temp", ref=20.0, span=40.0, combiner="trend", settle_s=2.0), n_random=10).table
    v1 = _v1_words(temp)
    t = Table.from_words(v1, "old.memh")
    assert t == temp and t.order == 0 and t.n_banks == 1
    assert t.to_words()[1] == T.VERSION                 # written back as the current version
    with pytest.raises(TableError, match=r"old drive-frequency word .* quantize the model again"):
        Table.from_words(_v1_words(table), "old.memh")  # a frequency proxy at the 2^-18 Hz word: refused
    bad = list(v1)
    bad[2] += 25                                        # a version-1 length that only v2 would fit
    with pytest.raises(TableError, match="length"):
        Table.from_words(bad)


def test_two_bank_table_fields_and_refusals(table):
    from dataclasses import replace
    from host_tools.vectors.builders import two_bank_table
    other = replace(table, mant=tuple(-m for m in table.mant))
    t2 = two_bank_table(table, other, 3)
    words = t2.to_words()
    assert words[FIELD_INDEX["order"]] == 1 and words[FIELD_INDEX["n_banks"]] == 2 and words[FIELD_INDEX["combiner"]] == 3
    assert [w - (1 << 32) if w >= 1 << 31 else w for w in words[FIELD_INDEX["m2_0"]:FIELD_INDEX["m2_0"] + N_TERMS]] \
        == list(other.mant)
    assert Table.from_words(words) == t2 and t2.bank(2).mant == other.mant and t2.bank_of_mode(2) == 2
    assert t2.bank_of_mode(1) == 1 and t2.bank_of_mode(3) == 1 and table.bank_of_mode(2) == 1
    for kw, match in [(dict(combiner=3), "none"), (dict(order=1), "n_banks"), (dict(n_banks=2), "n_banks"),
                      (dict(mant2=(1,) + (0,) * 16), "bank 2 words")]:
        with pytest.raises(TableError, match=match):
            replace(table, **kw)
    with pytest.raises(TableError, match="ftr"):
        replace(t2, combiner=0)
    with pytest.raises(TableError, match="bank 2: Horner"):
        replace(t2, mant2=((1 << 31) - 1,) * N_TERMS)


def test_table_json_and_cli(tmp_path, capsys):
    model = make_model(combiner="pair")
    model.to_json(tmp_path / "model.json")
    parser = argparse.ArgumentParser()
    configure(parser)
    out = tmp_path / "table.json"
    args = parser.parse_args([str(tmp_path / "model.json"), "-o", str(out), "--memh", str(tmp_path / "t.memh"),
                              "--header", str(tmp_path / "t.h"), "--bin", str(tmp_path / "t.bin")])
    assert run(args) == 0
    text = capsys.readouterr().out
    assert "CRC-32" in text and "bound" in text
    d = json.loads(out.read_text())
    assert d["format"] == "hdrg-fixed-table" and d["crc32"] == d["words"][-1]
    assert d["coef_dph"] == list(model.coef) and len(d["coef_quantized_dph"]) == N_TERMS
    for key in ("bound_dph", "measured_dph", "formats", "fields", "model", "interval_bounds"):
        assert key in d
    t = read_table(out)
    assert read_table(tmp_path / "t.memh") == t == read_table(tmp_path / "t.bin")
    from host_tools.fixed.export import decode_c_header
    assert decode_c_header((tmp_path / "t.h").read_text()) == t.to_words()   # the one header writer
    assert struct.unpack("<I", (tmp_path / "t.bin").read_bytes()[-4:])[0] == t.crc
    d["fields"]["m_0"] += 1
    (tmp_path / "edited.json").write_text(json.dumps(d))
    with pytest.raises(TableError, match="disagree"):
        read_table(tmp_path / "edited.json")
    (tmp_path / "other.json").write_text('{"format": "hdrg-model"}')
    with pytest.raises(TableError, match="not an hdrg table"):
        read_table(tmp_path / "other.json")


def test_hdrg_quantize_through_the_cli_registry(tmp_path, capsys, monkeypatch):
    """`hdrg quantize` as the lead registers it (host_tools.cli.COMMANDS); refusals exit 2."""
    from host_tools import cli
    monkeypatch.setitem(cli.COMMANDS, "quantize", ("host_tools.cli.quantize", "quantize a bias model"))
    make_model().to_json(tmp_path / "model.json")
    assert cli.main(["quantize", str(tmp_path / "model.json"), "-o", str(tmp_path / "t.json")]) == 0
    assert read_table(tmp_path / "t.json").combiner == 1
    c = np.zeros(N_TERMS)
    c[0], c[1] = 2e6, 2e5         # each |k| readable, their sum beyond the output word: quantize refuses
    make_model(coef=c).to_json(tmp_path / "big.json")
    capsys.readouterr()
    assert cli.main(["quantize", str(tmp_path / "big.json"), "-o", str(tmp_path / "x.json")]) == 2
    assert "cannot quantize" in capsys.readouterr().err and not (tmp_path / "x.json").exists()


# -- two banks (regress_first) -----------------------------------------------------------------------------

def test_two_banks_per_bank_exponents_bounds_and_refusals(tmp_path, capsys):
    """Each bank gets its own exponents (a bank 1000x smaller keeps ~10 more bits), its own
    interval bound, and the measured |B_fixed - B_golden| of both banks is within the bound; the
    residual-path bound grows none < pair < trend; a bank 2 that cannot be held is refused naming
    bank 2."""
    coef = np.array([1.5, -4.0, 0.3, 1.1, -1.2, -0.2, 0.9, 0.0, 0.05, 1.8, -0.1, 1.9, 0.7, 0.7, -0.02, -1.1, 0.9])
    outs = {}
    for comb in ("none", "pair", "trend"):
        q = quantize(make_model(combiner=comb, order="regress_first", coef=coef, coef2=coef * 1e-3), n_random=500)
        t = q.table
        assert (t.order, t.n_banks, t.combiner) == (1, 2, F.COMBINERS.index(comb))
        assert all(e2 >= e1 + 9 for e1, e2 in zip(t.e_row, t.e_row2))
        np.testing.assert_allclose(q.coef_quantized(2), coef * 1e-3, atol=2.0 ** -(min(t.e_row2) - 1))
        b = q.report["bound_dph"]
        assert len(b["banks"]) == 2 and q.report["measured_dph"]["random"] <= b["bias_B"]
        assert len(q.report["interval_bounds"]["banks"]) == 2 and "residual" in q.report["interval_bounds"]
        outs[comb] = b["out"]
        d = q.to_dict()
        assert d["coef_mode2_dph"] == list(coef * 1e-3) and len(d["coef_quantized_mode2_dph"]) == N_TERMS
    assert outs["none"] < outs["pair"] < outs["trend"] and outs["pair"] < 0.002
    big = coef.copy()
    big[0] = 3e9
    with pytest.raises(QuantizeError, match="bank 2"):
        quantize(make_model(combiner="pair", order="regress_first", coef=coef, coef2=big))
    make_model(combiner="trend", order="regress_first").to_json(tmp_path / "m.json")
    parser = argparse.ArgumentParser()
    configure(parser)
    assert run(parser.parse_args([str(tmp_path / "m.json"), "-o", str(tmp_path / "t.json")])) == 0
    assert "bank 2 rows" in capsys.readouterr().out and read_table(tmp_path / "t.json").n_banks == 2
