"""The aux generators in RTL (vectors/hdl/hdrg_aux.v, driven by tb_aux.v through host_tools.bench.cost_aux):
bit-exact z and flag 32 against the aux vector set and against the Python reference on directed
worst-case tables (every term the longest kind), the schedule's cycle count, a deliberately broken
build that fails, lint and synthesis figures.

Default suite: Icarus on a per-case subset of the aux set and on the directed tables (a few seconds).
Exhaustive (`pytest -m exhaustive`, not in the default run or CI: the whole pipeline hdrg_top is checked
on the aux set under both simulators by tests/test_cost.py and tests/test_rtl.py): the module alone on
the whole set under Icarus and Verilator for OP_CYCLES 2 and 4, its broken build, lint, Yosys.
"""
from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from firmware_ref import formats as F
from firmware_ref.table import AuxTerm, Table, encode_aux
from host_tools import vectors as V
from host_tools.bench import cost_aux as CA

needs_iverilog = pytest.mark.skipif(shutil.which("iverilog") is None, reason="iverilog not installed")
needs_verilator = pytest.mark.skipif(shutil.which("verilator") is None, reason="verilator not installed")
needs_yosys = pytest.mark.skipif(shutil.which("yosys") is None, reason="yosys not installed")

OPS_PER_TERM_MAX = 13          # osc: 3 phase products, r, x, x^2, 5 Horner steps, min, weight (the header)


def _base_table() -> Table:
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["aux"]
    words = [int(w, 16) for w in (V.DEFAULT_DIR / meta["tables_mem"]).read_text().split()]
    off = meta["table_offsets"]
    return Table.from_words(words[off[0]:off[1]])


def _with_terms(base, terms, fracs=()) -> Table:
    return dataclasses.replace(base, aux_gen=1, aux_params=encode_aux(tuple(fracs), tuple(terms)))


def _stream(rng, n: int, table) -> dict:
    """Random channel words across their whole ranges (clamps), K with gaps, negative values and values
    near 2^62, modes of a reversal cycle, restarts, random rate words."""
    k = np.cumsum(rng.integers(1, 3, n)) - 5
    k[n // 3: n // 3 + 5] = F.K_LIMIT - 5 + np.arange(5)
    k[n // 2] = -F.K_LIMIT
    nch = 0 if table.aux() is None else table.aux().n_chan
    return {"f": rng.integers(0, 1 << 32, n), "t": rng.integers(-(1 << 31) + 1, 1 << 31, n),
            "r": rng.integers(-(1 << 20), 1 << 20, n), "mode": np.resize([3, 3, 1, 1, 1, 3, 2, 2, 2], n),
            "restart": (rng.random(n) < 0.05).astype(np.int64), "z": rng.integers(-(1 << 31), 1 << 31, n),
            "k": k.astype(np.int64), "aux": rng.integers(-(1 << 31) + 1, 1 << 31, (n, nch))}


def _directed(rng) -> list:
    """Tables whose every term is the longest of its family: AUX_MAX_TERMS (16) osc terms (the worst
    case), 16 filtered power-5 input terms on every channel (the longest table: 255 words), decays and
    rate terms; plus an aux_gen 0 table (z = clamp(Z))."""
    base = _base_table()
    nt = F.AUX_MAX_TERMS
    w = (1 << 30) // nt
    osc = [AuxTerm(6, j % 2, 0, 1, w * (-1) ** j, (int(rng.integers(1, 1 << 63)), 0, j % 2, 0, 0, 0)) for j in range(nt)]
    inp = [AuxTerm(0, 1, src, 5, w, (int(rng.integers(0, 1 << 32)) if src == 0 else int(rng.integers(-1000, 1000)),
                                     int(rng.integers(1, 1 << 31)), 0, int(rng.integers(28, 40)),
                                     int(rng.integers(1, 1 << 31)), int(rng.integers(31, 40))))
           for src in (j % (2 + F.AUX_MAX_CHANNELS) for j in range(nt))]
    mix = [AuxTerm(3, 0, 0, 1, w, ((1 << 31) - 1, 33, 0, 0, 0, 0)), AuxTerm(4, 1, 0, 1, -w, (1 << 30, 32, 0, 0, 0, 0)),
           AuxTerm(1, 1, base.proxy_kind, 1, w, (20, 1 << 25, 12, 0, 0, 0)),
           AuxTerm(1, 0, base.proxy_kind, 1, w, (3, 1 << 30, 0, 0, 0, 0)),
           AuxTerm(5, 0, 0, 1, w, (1000, 1 << 30, 40, 0, 0, 0)), AuxTerm(2, 1, 0, 1, w + 1, (0,) * 6)]
    none = dataclasses.replace(base, aux_gen=0, aux_params=())
    tables = [_with_terms(base, osc), _with_terms(base, inp, fracs=(0, 20, 40, 48)), _with_terms(base, mix), none]
    assert len(tables[1].to_words()) == 255
    return [(t, _stream(rng, 120, t)) for t in tables]


@pytest.fixture(scope="module")
def directed(tmp_path_factory):
    work = tmp_path_factory.mktemp("aux_directed")
    return work, CA.write_directed(work, _directed(np.random.default_rng(20261123)))


def _subset(work, per_case: int = 60) -> tuple:
    """The aux set's first ``per_case`` rows of every case (a prefix: the generators' state carries
    from sample to sample): (parameters, plusargs) for tb_aux."""
    params, plus = CA.aux_params(work)
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["aux"]
    rows = (V.DEFAULT_DIR / meta["mem"]).read_text().split()
    keep = [r for c in meta["cases"] for i, r in enumerate(rows[c["rows"][0]:c["rows"][1]])
            if i < per_case]
    path = work / "aux_subset.mem"
    path.write_text("\n".join(keep) + "\n")
    plus = [f"+vectors={path}" if a.startswith("+vectors=") else f"+n_vec={len(keep)}" if a.startswith("+n_vec=")
            else a for a in plus]
    return params, plus


@needs_iverilog
def test_icarus_aux_subset_bit_exact(tmp_path):
    r = CA.rtl_aux_check(tmp_path, "icarus", files=_subset(tmp_path))
    assert r["vectors"] > 1000 and r["mismatches"] == 0, r


@needs_iverilog
@pytest.mark.parametrize("op_cycles", [2, 4])
def test_icarus_directed_worst_case_bit_exact(directed, op_cycles):
    work, files = directed
    r = CA.rtl_aux_check(work, "icarus", files=files, op_cycles=op_cycles)
    assert r["mismatches"] == 0, r
    # the schedule: 2 cycles (start, first read) + op_cycles per operation; the worst table is 16 osc terms
    assert r["cycles_max"] == 2 + op_cycles * (F.AUX_MAX_TERMS * OPS_PER_TERM_MAX + 1), r
    assert r["cycles_min"] == 2 + op_cycles * 1, r  # aux_gen 0: one operation (z = clamp(Z))


@pytest.mark.exhaustive
@needs_iverilog
def test_icarus_broken_rounding_fails(tmp_path):
    r = CA.rtl_aux_check(tmp_path, "icarus", defines=("HDRG_BREAK_ROUNDING",), files=_subset(tmp_path))
    assert r["mismatches"] > 100, r


@pytest.mark.exhaustive
@needs_iverilog
@pytest.mark.parametrize("op_cycles", [2, 4])
def test_icarus_aux_set_bit_exact(tmp_path, op_cycles):
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["aux"]
    r = CA.rtl_aux_check(tmp_path, "icarus", op_cycles=op_cycles)
    assert r["vectors"] == meta["rows"] and r["mismatches"] == 0, r


@pytest.mark.exhaustive
@needs_verilator
@pytest.mark.parametrize("op_cycles", [2, 4])
def test_verilator_aux_set_and_directed_bit_exact(tmp_path, directed, op_cycles):
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["aux"]
    r = CA.rtl_aux_check(tmp_path, "verilator", op_cycles=op_cycles)
    assert r["vectors"] == meta["rows"] and r["mismatches"] == 0, r
    work, files = directed
    r = CA.rtl_aux_check(work, "verilator", files=files, op_cycles=op_cycles)
    assert r["mismatches"] == 0, r
    assert r["cycles_max"] == 2 + op_cycles * (F.AUX_MAX_TERMS * OPS_PER_TERM_MAX + 1), r


@pytest.mark.exhaustive
@needs_verilator
@pytest.mark.parametrize("op_cycles", [2, 4])
def test_verilator_lint_clean(op_cycles):
    assert CA.lint_aux(op_cycles).strip() == ""


@pytest.mark.exhaustive
@needs_yosys
def test_yosys_ice40_fits_beside_the_evaluator(tmp_path):
    r = CA.synth_aux("ice40", tmp_path)
    assert r["dsps"] <= 4, r                        # one 32 x 32 multiplier
    assert 0 < r["luts"] <= 5280 - 1186, r          # an UP5K minus the evaluator (docs/COST.md)
