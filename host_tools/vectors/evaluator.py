"""The ``evaluator`` set's case generator (FORMATS.md step 5 on random, one-hot, bound and
quantized tables) and its recomputation (numba kernel, cross-checked with firmware_ref.evaluator).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from firmware_ref import formats as F
from firmware_ref.evaluator import evaluate
from firmware_ref.table import Table, horner_bounds
from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX
from host_tools.vectors.spec import EVAL_EXTRA, EVAL_FIELDS, EVAL_INPUTS, VectorsError
from host_tools.vectors.files import VectorSet


# -- helpers ------------------------------------------------------------------------------------------

def reference_rows(table, u, v, z, bank=None) -> dict:
    """The evaluator's intermediates, read from the Python reference's own trace
    (firmware_ref.evaluator.evaluate, ``trace``: per row i = 3, 2, 1, 0 the values p, p, q, a[i],
    then the three Horner accumulators t and the final t after k7 z): ``row0..row3`` = a[i], the
    Horner row of u^i aligned to the accumulator (LSB 2^-E deg/h), ``zterm`` = RHU(m_7 z, 30 + e_7
    - E), ``t`` the accumulator after k7 z, ``b`` = B (LSB 2^-21 deg/h), ``zclamped``; int64
    arrays.  ``bank``: int array (1, 2) of the bank of each sample (None: bank 1)."""
    n = len(u)
    out = {name: np.zeros(n, np.int64) for name in ("row0", "row1", "row2", "row3", "zterm", "t", "b", "zclamped")}
    banks = np.ones(n, np.int64) if bank is None else np.asarray(bank, np.int64)
    for i, (ui, vi, zi, bi) in enumerate(zip(np.asarray(u).tolist(), np.asarray(v).tolist(), np.asarray(z).tolist(),
                                             banks.tolist())):
        trace = []
        b, zc = evaluate(ui, vi, zi, table, trace=trace, bank=bi if table.n_banks == 2 else 1)
        for r in range(4):
            out[f"row{r}"][i] = trace[4 * (3 - r) + 3]
        out["t"][i] = trace[19]
        out["zterm"][i] = trace[19] - trace[18]
        out["b"][i] = b
        out["zclamped"][i] = int(zc)
    return out


# -- tables -----------------------------------------------------------------------------------------

def qtable(est="diff", combiner="pair", n=5, shift=2, settle_s=2.0, max_stale_s=25.0, coef=None, kind=None,
            order="combine_first", coef2=None, ref=None, span=None, rate_span=None, **timing) -> Table:
    """A quantized table of host_tools.vectors.builders.make_model (as tests/test_c_twin.py's table_of);
    ``order`` "regress_first": two banks (``coef2``: make_model's default).  ``ref``, ``span``,
    ``rate_span``: the proxy centre and span and the rate span (default: a 6227-Hz drive or 20 degC)."""
    from host_tools.vectors.builders import make_model
    from host_tools.fixed.quantize import quantize

    if coef is None:
        coef = [3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1, 6e1, -5e1]
    temp = (kind or ("temp" if est == "lsq" else "freq")) == "temp"
    ref = (20.0 if temp else 6227.0) if ref is None else ref
    span = (30.0 if temp else 3.0) if span is None else span
    rate_span = (0.5 if temp else 0.003) if rate_span is None else rate_span
    model = make_model("temp" if temp else "freq", ref=ref, span=span,
                       estimator=est, n=n, shift=shift, rate_span=rate_span, combiner=combiner,
                       settle_s=settle_s, max_stale_s=max_stale_s, coef=coef, order=order, coef2=coef2)
    return quantize(model, n_random=10, **timing).table


def _fit_bounds(e_row, e_7, e_acc, mant) -> list:
    """Halve the mantissas (towards zero) until the Horner interval bounds hold."""
    mant = list(mant)
    while True:
        rows, bounds = horner_bounds(e_row, e_7, e_acc, mant)
        if max(rows) <= F.ACC_LIMIT and sum(bounds) <= F.ACC_LIMIT:
            return mant
        mant = [m >> 1 if m >= 0 else -((-m) >> 1) for m in mant]


def _two_banks(t1: Table, t2: Table) -> Table:
    """An order-1 two-bank table: t1 with bank 2 = bank 1 of t2 (combiner pair)."""
    from host_tools.vectors.builders import two_bank_table

    return two_bank_table(t1 if t1.combiner else dataclasses.replace(t1, combiner=1), t2, None)


def _random_eval_table(rng, base: Table) -> Table:
    E = int(rng.integers(0, F.EXP_MAX + 1))
    e = [E + int(rng.integers(0, min(F.ALIGN_MAX, F.EXP_MAX - E) + 1)) for _ in range(5)]
    mant = []
    for _ in range(N_TERMS):
        bits = int(rng.integers(0, 32))
        m = int(rng.integers(0, 1 << bits)) if bits and rng.random() > 0.1 else 0
        mant.append(m if rng.random() < 0.5 else -m)
    mant = _fit_bounds(e[:4], e[4], E, mant)
    return dataclasses.replace(base, e_row=tuple(e[:4]), e_7=e[4], e_acc=E, mant=tuple(mant))


# -- evaluator --------------------------------------------------------------------------------------

def evaluator_set(rng) -> VectorSet:
    from host_tools.vectors.builders import random_model
    from host_tools.fixed.quantize import quantize

    base = qtable()
    tables, cases, parts = [], [], []
    edge = np.array([F.ONE, -F.ONE, F.ONE - 1, -F.ONE + 1, 0, 1, -1], np.int64)
    zedge = np.array([0, F.ONE, -F.ONE, F.ONE + 1, -F.ONE - 1, F.INT32_SYM, -F.INT32_SYM - 1, 12345], np.int64)

    def add(name, desc, table, u, v, z, bank=None):
        cases.append({"name": name, "description": desc, "table": len(tables)})
        tables.append(table)
        u = np.asarray(u, np.int64)
        bank = np.ones(len(u), np.int64) if bank is None else np.asarray(bank, np.int64)
        parts.append((u, np.asarray(v, np.int64), np.asarray(z, np.int64), bank))

    def random_points(n):
        u = rng.integers(-F.ONE, F.ONE, n, endpoint=True)
        v = rng.integers(-F.ONE, F.ONE, n, endpoint=True)
        z = rng.integers(-F.ONE - (F.ONE >> 2), F.ONE + (F.ONE >> 2), n, endpoint=True)
        pick = rng.random(n) < 0.1
        u[pick] = rng.choice(edge, int(pick.sum()))
        pick = rng.random(n) < 0.1
        v[pick] = rng.choice(edge, int(pick.sum()))
        pick = rng.random(n) < 0.05
        z[pick] = rng.choice(zedge, int(pick.sum()))
        return u, v, z

    grid_u, grid_v, grid_z = (a.ravel() for a in np.meshgrid(edge, edge, zedge, indexing="ij"))
    for k in range(N_TERMS):                       # one-hot: one mantissa at +-(2^31 - 1)
        for sign, (E, shift) in ((1, (21, 0)), (-1, (30, 22))):
            mant = [0] * N_TERMS
            mant[k] = sign * F.INT32_SYM
            e = [E + shift] * 5
            if k == K_AUX:
                e[4] = E + min(shift, F.EXP_MAX - E)
            t = dataclasses.replace(base, e_row=tuple(e[:4]), e_7=e[4], e_acc=E, mant=tuple(mant))
            u, v, z = random_points(12)
            add(f"onehot_k{k}_{'pos' if sign > 0 else 'neg'}",
                f"only m_{k} = {sign * F.INT32_SYM}, E = {E}, shift {shift}",
                t, np.r_[grid_u[::7], u], np.r_[grid_v[::7], v], np.r_[grid_z[::7], z])
    # tables at the accumulator bound: every row sum 2^31 - 5 aligned by 2 (2^29 - 1 each) + k7 bound 1
    row = [F.INT32_SYM - 4 - 3 * (1 << 29), 1 << 29, 1 << 29, 1 << 29]
    mant = [0] * N_TERMS
    for i in range(4):
        for j in range(4):
            mant[POLY_INDEX[i][j]] = row[j] * (1 if (i + j) % 2 == 0 else -1)
    mant[K_AUX] = F.INT32_SYM
    bound = dataclasses.replace(base, e_row=(23, 23, 23, 23), e_7=52, e_acc=21, mant=tuple(mant))
    extremes = {
        "acc_bound": ("every row's |mantissa| sum at 2^31 - 5, aligned bounds summing to 2^31 - 3", bound),
        "acc_bound_same_sign": ("as acc_bound with all mantissas positive",
                                dataclasses.replace(bound, mant=tuple(abs(m) for m in bound.mant))),
        "acc_bound_neg": ("as acc_bound_same_sign negated",
                          dataclasses.replace(bound, mant=tuple(-abs(m) for m in bound.mant))),
        "e_acc_0": ("E = 0 (B = t << 21, |B| up to 2^52), row exponents 0, 7, 19, 31, k7 at 31",
                    dataclasses.replace(base, e_row=(0, 7, 19, 31), e_7=31, e_acc=0,
                                        mant=tuple(_fit_bounds((0, 7, 19, 31), 31, 0, [F.INT32_SYM // 5 * (-1) ** k
                                                                                       for k in range(N_TERMS)])))),
        "e_acc_52": ("every exponent 52: B = RHU(t, 31), ties at 2^30",
                     dataclasses.replace(base, e_row=(52,) * 4, e_7=52, e_acc=52,
                                         mant=tuple(_fit_bounds((52,) * 4, 52, 52, [(1 << 30) + k * 12345 - 99999
                                                                                   for k in range(N_TERMS)])))),
        "k7_extreme": ("only m_7 = 2^31 - 1, e_7 = E = 30: RHU(m_7 z, 30) with z clamped",
                       dataclasses.replace(base, e_row=(30,) * 4, e_7=30, e_acc=30,
                                           mant=tuple(F.INT32_SYM if k == K_AUX else 0 for k in range(N_TERMS)))),
    }
    for name, (desc, t) in extremes.items():
        add(name, desc + "; u, v, z on the edge grid", t, grid_u, grid_v, grid_z)
    for k in range(24):
        u, v, z = random_points(160)
        add(f"random_{k}", "random legal integer table (exponents, mantissas), random points", _random_eval_table(rng, base),
            u, v, z)
    for k in range(8):
        t = quantize(random_model(rng), exchange_s=3.0, dwell_s=7.0, n_random=10).table
        u, v, z = random_points(100)
        add(f"quantized_{k}", "host_tools.vectors.builders.random_model quantized by host_tools.fixed.quantize", t, u, v, z)
    # two banks (regress_first, order 1): the bank input selects the coefficients and exponents
    two = [("two_bank_extremes", "bank 1 = e_acc_0 (E = 0, B = t << 21), bank 2 = e_acc_52 (B = RHU(t, 31))",
            _two_banks(extremes["e_acc_0"][1], extremes["e_acc_52"][1])),
           ("two_bank_bound_signs", "bank 1 = acc_bound_same_sign, bank 2 = acc_bound_neg: B of opposite sign",
            _two_banks(extremes["acc_bound_same_sign"][1], extremes["acc_bound_neg"][1]))]
    for name, desc, t in two:
        bank = np.resize(np.array([1, 2], np.int64), len(grid_u))
        add(name, desc + "; u, v, z on the edge grid, banks alternating", t, grid_u, grid_v, grid_z, bank)
        add(name + "_swapped", desc + "; banks in the other order", t, grid_u, grid_v, grid_z, 3 - bank)
    for k in range(6):
        t = quantize(random_model(rng, order="regress_first"), exchange_s=3.0, dwell_s=7.0, n_random=10).table
        u, v, z = random_points(120)
        add(f"quantized_two_bank_{k}", "host_tools.vectors.builders.random_model(order='regress_first') quantized: two "
            "banks with their own exponents, random bank per point", t, u, v, z, rng.integers(1, 3, 120))
    case_col = np.concatenate([np.full(len(p[0]), c, np.int64) for c, p in enumerate(parts)])
    cols = {"case": case_col, "u": np.concatenate([p[0] for p in parts]), "v": np.concatenate([p[1] for p in parts]),
            "z": np.concatenate([p[2] for p in parts]), "bank": np.concatenate([p[3] for p in parts])}
    start = 0
    for c, p in zip(cases, parts):
        c["rows"] = [start, start + len(p[0])]
        start += len(p[0])
    vs = VectorSet("evaluator", "the Horner evaluator alone (FORMATS.md step 5): B (LSB 2^-21 deg/h) and "
                   "zclamped at (u, v, z) with coefficient bank `bank` (1, or 2 of a two-bank table) for table "
                   "`case`; row0..row3 = the Horner rows a[i] aligned to 2^-E, "
                   "zterm = RHU(m_7 z, 30 + e_7 - E), t = the accumulator after k7 z (LSB 2^-E)",
                   cols, EVAL_INPUTS, EVAL_FIELDS, cases, tables)
    compute_evaluator(vs)
    return vs


def compute_evaluator(vs: VectorSet) -> None:
    """Fill b, zclamped and the intermediates from case/u/v/z: the Python evaluator's trace
    (:func:`reference_rows`) and the numba kernel's B, which must agree on every row."""
    from firmware_ref.kernel import evaluate_words

    c = vs.columns
    if np.any(np.abs(c["u"]) > F.ONE) or np.any(np.abs(c["v"]) > F.ONE):
        raise VectorsError("evaluator: u and v must be in [-2^30, 2^30]")
    n = len(c["u"])
    res = {name: np.zeros(n, np.int64) for name in EVAL_EXTRA + ("b", "zclamped")}
    for case in vs.cases:
        lo, hi = case["rows"]
        t = vs.tables[case["table"]]
        u, v, z, bank = c["u"][lo:hi], c["v"][lo:hi], c["z"][lo:hi], c["bank"][lo:hi]
        if not np.all((bank == 1) | ((bank == 2) & (t.n_banks == 2))):
            raise VectorsError(f"evaluator case {case['name']}: bank must be 1, or 2 with a two-bank table")
        rows = reference_rows(t, u, v, z, bank)
        kb = evaluate_words(t, u, v, z)
        if t.n_banks == 2:
            kb = np.where(bank == 2, evaluate_words(t, u, v, z, bank=2), kb)
        if not np.array_equal(kb, rows["b"]):
            i = int(np.argmax(kb != rows["b"]))
            raise VectorsError(f"evaluator case {case['name']}: numba B {kb[i]} != Python reference B {rows['b'][i]} "
                               f"at u={u[i]} v={v[i]} z={z[i]}")
        for name in res:
            res[name][lo:hi] = rows[name]
    cols = {k: c[k] for k in EVAL_INPUTS}
    cols.update((k, res[k]) for k in EVAL_EXTRA + ("b", "zclamped"))
    vs.columns = cols
