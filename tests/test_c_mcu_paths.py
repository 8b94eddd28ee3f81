"""The C twin's Cortex-M paths (firmware_ref/c/hdrg_fw.c) against the Python integer reference,
as properties (hypothesis) through the driver protocol:

* the division built on 32-bit divisions (hdrg_udiv64: two 64 / 32 digit steps for d < 2^32,
  the normalized estimate for d >= 2^32) behind FLOORDIV, DIVROUND and DIVRS, on divisors around
  2^31, 2^32 and 2^33 (the path boundaries), the window means (|acc| <= (2^31 - 1) cnt) and
  numerators next to multiples of the divisor (the estimate corrections);
* RHU as ASR(ASR(x, s - 1) + 1, 1) at every shift, ties included;
* the 32-bit evaluator (one SMLAL per Horner step with the coefficient folded into a parse-time
  addend, 32-bit row alignments, the k7 product onto 2^(s-1)) on random tables that sit on the
  Horner interval bound: every exponent layout (E from 0 to 52, row alignments and e_7 - E from 0
  to 31), both banks, against firmware_ref.evaluator.evaluate;
* the build without aux generators (-DHDRG_AUX_GEN=0): the same answers for aux_gen 0 tables and
  aux_gen 1 tables refused at word aux_gen;
* the firmware entry point hdrg_step_out (driver -DHDRG_DRIVER_LEAN): the same outputs and state as
  hdrg_step_aux on every kind of table (logged and self-timed modes, aux generators);
* the configuration-specialized build (-DHDRG_FIX_*, host_tools.bench.cost.SPECIAL_DEFINES): the
  same answers for tables of its configuration, the others refused at the word of the fixed field.

One driver process per test (the requests of all examples are batched).
"""
import dataclasses

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from firmware_ref import arith
from firmware_ref import formats as F
from firmware_ref.evaluator import evaluate
from firmware_ref.table import FIELD_INDEX
from firmware_ref.terms import K_AUX, POLY_INDEX
from host_tools import vectors as V
from host_tools.bench.cost import LEAN_FIELDS, SPECIAL, SPECIAL_DEFINES
from test_c_twin import FIELDS, GCC, build, run_text, table_line, table_of, with_fields

pytestmark = pytest.mark.skipif(GCC is None, reason="gcc not found on PATH: the C twin cannot be built")

I64_MIN, I64_MAX = -(1 << 63), (1 << 63) - 1
LIM = F.INT32_SYM
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def exe(tmp_path_factory):
    return build(tmp_path_factory.mktemp("c_mcu"))


def _divisor():
    edges = st.sampled_from([1, 2, 3, (1 << 31) - 1, 1 << 31, (1 << 31) + 1, (1 << 32) - 1, 1 << 32, (1 << 32) + 1,
                             (1 << 33) - 1, 1 << 33, (1 << 62) + 1, I64_MAX])
    return st.one_of(edges, st.integers(1, (1 << 32) + 5), st.integers(1 << 31, 1 << 34),
                     st.integers(1, I64_MAX), st.integers(0, 62).map(lambda k: 1 << k))


@st.composite
def _division(draw):
    b = draw(_divisor())
    kind = draw(st.sampled_from(["any", "near_multiple", "window_mean"]))
    if kind == "any":
        a = draw(st.integers(I64_MIN, I64_MAX))
    elif kind == "near_multiple":
        q = draw(st.integers(I64_MIN // b, I64_MAX // b))
        a = min(max(q * b + draw(st.integers(-2, 2)), I64_MIN), I64_MAX)
    else:                                   # acc / cnt of a window: |acc| <= (2^31 - 1) cnt
        b = draw(st.integers(1, (1 << 31) - 1))
        a = draw(st.integers(-LIM * b, LIM * b))
    return a, b


def _batch(exe, cases, expect_rc=0):
    out = run_text(exe, [req for req, _ in cases], expect_rc=expect_rc)
    assert len(out) == len(cases)
    bad = [(req, exp, got) for (req, exp), got in zip(cases, out) if got != exp]
    assert not bad, bad[:5]


@SETTINGS
@given(st.lists(_division(), min_size=20, max_size=20), st.sampled_from([0, 1, 10, 16, 40]))
def test_division_equals_arith(exe, divisions, k):
    cases = []
    for a, b in divisions:
        cases.append((f"FLOORDIV {a} {b}", f"R {arith.floor_div(a, b)}"))
        if I64_MIN <= 2 * a + b <= I64_MAX and 2 * b <= I64_MAX:
            cases.append((f"DIVROUND {a} {b}", f"R {arith.div_round(a, b)}"))
        try:
            want = arith.div_round_scaled(a, b, k)
        except AssertionError:              # outside arith's int64 preconditions: ERR RANGE there
            continue
        cases.append((f"DIVRS {a} {b} {k}", f"R {want}"))
    _batch(exe, cases)


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 62), st.integers(I64_MIN, I64_MAX), st.integers(-2, 2),
                          st.booleans()), min_size=30, max_size=30))
def test_rhu_equals_arith(exe, draws):
    cases = []
    for s, x, d, tie in draws:
        if tie and s > 0:                   # next to a tie k 2^s + 2^(s-1)
            x = (x >> s << s) + (1 << (s - 1)) + d
        x = min(max(x, I64_MIN), I64_MAX - (1 << max(s - 1, 0)))
        cases.append((f"RHU {x} {s}", f"R {arith.rshift_round(x, s)}"))
    _batch(exe, cases)


@st.composite
def _bank(draw):
    """(e_row, e_7, e_acc, mant): a bank whose Horner interval bound is used up to within a few LSB."""
    E = draw(st.integers(0, 52))
    room = min(31, 52 - E)
    align = [draw(st.integers(0, room)) for _ in range(4)]
    a7 = draw(st.integers(0, room))
    w = [draw(st.integers(1, 100)) for _ in range(5)]
    budget = LIM - 16                       # the RHU of each bound term may round up by one
    mant = [0] * 17
    for i in range(4):                      # row i's |mantissa| sum, aligned, gets its share
        row = min(LIM, (budget * w[i] // sum(w)) << align[i])
        parts = [draw(st.integers(0, 1000)) for _ in range(4)]
        for j in range(4):
            m = row * parts[j] // max(sum(parts), 1)
            mant[POLY_INDEX[i][j]] = m if draw(st.booleans()) else -m
    m7 = min(LIM, (budget * w[4] // sum(w)) << a7)
    mant[K_AUX] = m7 if draw(st.booleans()) else -m7
    return tuple(E + a for a in align), E + a7, E, tuple(mant)


@SETTINGS
@given(_bank(), _bank(), st.lists(st.tuples(st.integers(-F.ONE, F.ONE), st.integers(-F.ONE, F.ONE),
                                            st.integers(-(1 << 31), (1 << 31) - 1), st.sampled_from([1, 2])),
                                  min_size=40, max_size=40),
       st.booleans())
def test_evaluator_on_the_horner_bound_equals_reference(exe, bank1, bank2, points, two):
    base = table_of("diff", "pair")
    e_row, e_7, e_acc, mant = bank1
    table = with_fields(base, e_row=e_row, e_7=e_7, e_acc=e_acc, mant=mant)
    if two:                                 # a two-bank (regress_first) table: bank 2 on BANK 2
        e2, e27, e2acc, m2 = bank2
        table = with_fields(table, order=1, n_banks=2, combiner=1, e_row2=e2, e_7_2=e27, e_acc2=e2acc, mant2=m2)
    corners = [(F.ONE, F.ONE, F.ONE, 1), (-F.ONE, -F.ONE, -F.ONE, 2), (F.ONE, -F.ONE, (1 << 31) - 1, 1),
               (-F.ONE, F.ONE, -(1 << 31), 2)]
    cases = [(table_line(table), None)]
    for u, v, z, bank in corners + points:
        b, zc = evaluate(u, v, z, table, bank=bank if two else 1)   # the driver: bank 2 of one bank = bank 1
        cases.append((f"EVAL {u} {v} {z} {bank}", f"E {b} {int(zc)}"))
    out = run_text(exe, [req for req, _ in cases])
    assert out[0].startswith("T "), out[0]
    bad = [(req, exp, got) for (req, exp), got in zip(cases[1:], out[1:]) if got != exp]
    assert not bad, bad[:5]


def test_build_without_aux_generators(tmp_path):
    """-DHDRG_AUX_GEN=0: aux_gen 0 tables answer as in the full build; aux_gen 1 is refused."""
    full = build(tmp_path, "full")
    lean = build(tmp_path, "lean", defines=("HDRG_AUX_GEN=0",))
    table = table_of("diff", "trend")
    reqs = [table_line(table)] + [f"S {1632370688 + 500 * i} 0 {1024 + i} {(i // 7) % 4} {int(i == 0)} {i << 20}"
                                  for i in range(60)] + ["EVAL 536870912 -5 7"]
    assert run_text(lean, reqs) == run_text(full, reqs)
    aux_words = dataclasses.replace(table, aux_gen=1, aux_params=(1, 0) + (2, 0, 0, 1, 1 << 30) + (0,) * 6).to_words()
    out = run_text(lean, ["TABLE " + " ".join(f"{w:08x}" for w in aux_words)], expect_rc=1)
    assert out == [f"ERR FIELD word {FIELD_INDEX['aux_gen']} aux_gen"], out
    assert run_text(full, ["TABLE " + " ".join(f"{w:08x}" for w in aux_words)])[0].startswith("T ")


def _stream(n=80, self_timed=False, aux=False):
    """S lines: a drifting F word, R, logged modes cycling 0..3 (or -1), restarts, Z (K A0 with aux)."""
    return [f"S {1632370688 + 700 * i - 3 * i * i} {(i * 997) % 4000 - 2000} {1024 + 37 * i} "
            f"{-1 if self_timed else (i // 7) % 4} {int(i in (0, 41))} {(i - 40) << 24}" + (f" {i} {i * 1000}" if aux else "")
            for i in range(n)]


def _lean_view(lines):
    """The O lines reduced to the fields the lean driver answers (LEAN_FIELDS); the others must be 0."""
    pos = [1 + FIELDS.index(f) for f in LEAN_FIELDS]
    return [[ln.split()[p] for p in pos] if ln.startswith("O ") else ln for ln in lines]


@pytest.fixture(scope="module")
def full_and_lean(tmp_path_factory):
    d = tmp_path_factory.mktemp("c_lean")
    return build(d, "full"), build(d, "lean", defines=("HDRG_DRIVER_LEAN",))


@pytest.mark.parametrize("est,combiner,self_timed", [("diff", "pair", False), ("lsq", "trend", False),
                                                     ("iir", "pair", False), ("diffn", "pair", True)])
def test_lean_entry_point_equals_full_step(full_and_lean, est, combiner, self_timed):
    """hdrg_step_out: out, bias, valid, flags and the state (acc, cnt, y) as hdrg_step_aux, sample by sample."""
    full, lean = full_and_lean
    reqs = [table_line(table_of(est, combiner))] + _stream(self_timed=self_timed)
    got, exp = run_text(lean, reqs), run_text(full, reqs)
    assert _lean_view(got) == _lean_view(exp)
    others = [1 + i for i, f in enumerate(FIELDS) if f not in LEAN_FIELDS]
    assert all(ln.split()[p] == "0" for ln in got[1:] for p in others)
    if not self_timed:      # the outputs move (self-timed: 80 samples are power-on and exchanges)
        assert len({ln.split()[1 + FIELDS.index("out")] for ln in exp[1:]}) > 5


def test_lean_entry_point_on_the_vector_tables(full_and_lean):
    """The e2e tables (ftr; combine_first pair; regress_first pair, none, trend: two banks) and an aux
    generator table (aux_gen 1, K and A0 given)."""
    full, lean = full_and_lean
    manifest = V.read_manifest(V.DEFAULT_DIR)
    for name, case in [("e2e", c) for c in range(len(manifest["sets"]["e2e"]["cases"]))] + [("aux", -1)]:
        meta = manifest["sets"][name]
        table = V.load_set(V.DEFAULT_DIR, name, meta).tables[meta["cases"][case]["table"]]
        reqs = [table_line(table)] + _stream(aux=name == "aux")
        assert _lean_view(run_text(lean, reqs)) == _lean_view(run_text(full, reqs)), (name, case)


def test_specialized_build_accepts_its_configuration_only(tmp_path):
    """-DHDRG_FIX_* of the default configuration (regress_first pair, diff, freq, no aux generators): its
    tables answer as in the generic build; a table of another configuration is refused at the fixed word."""
    full = build(tmp_path, "full")
    spec = build(tmp_path, "spec", defines=("HDRG_DRIVER_LEAN", *SPECIAL_DEFINES))
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["e2e"]
    vs = V.load_set(V.DEFAULT_DIR, "e2e", meta)
    tables = [vs.tables[c["table"]] for c in meta["cases"]]
    mine = [t for t in tables if all(getattr(t, k) == v for k, v in SPECIAL.items())]
    assert mine, "no e2e table of the default configuration"
    reqs = [table_line(mine[0])] + _stream()
    assert _lean_view(run_text(spec, reqs)) == _lean_view(run_text(full, reqs))
    order0 = next(t for t in tables if t.order == 0 and t.combiner == mine[0].combiner)
    refused = {"combiner": with_fields(mine[0], combiner=2), "rate_est": with_fields(mine[0], rate_est=1),
               "proxy_kind": with_fields(mine[0], proxy_kind=1), "order": order0}
    for word, table in refused.items():
        assert run_text(full, [table_line(table)])[0].startswith("T "), word       # a legal table
        out = run_text(spec, [table_line(table)], expect_rc=1)
        assert out == [f"ERR FIELD word {FIELD_INDEX[word]} {word}"], (word, out)
