"""The ``primitives`` set's case generator (firmware_ref.arith at ties, extremes and sign edges)
and its recomputation.
"""
from __future__ import annotations

import numpy as np

from firmware_ref import arith, formats as F
from host_tools.vectors.spec import PRIM_FIELDS, PRIM_INPUTS, PRIM_OPS, VectorsError
from host_tools.vectors.files import VectorSet


# -- primitives -------------------------------------------------------------------------------------

def _prim_eval(op: str, a: int, b: int, c: int):
    """(result, flag) by firmware_ref.arith; AssertionError if a precondition is violated."""
    if op == "RHU":
        return arith.rshift_round(a, b), 0
    if op == "MULRHU":
        return arith.mul_rshift_round(a, b, c), 0
    if op == "FLOORDIV":
        return arith.floor_div(a, b), 0
    if op == "DIVROUND":
        return arith.div_round(a, b), 0
    if op == "DIVRS":
        return arith.div_round_scaled(a, b, c), 0
    if op == "CLAMP":
        assert b <= c
        v, f = arith.clamp(a, b, c)
        return v, int(f)
    if op == "RHUW":
        return arith.mul_rshift_round_wide(a, b, c), 0
    if op == "SIN":
        from firmware_ref.aux import sin_q30
        return sin_q30(a & 0xFFFFFFFFFFFFFFFF), 0
    assert 1 <= b <= 63
    v, f = arith.sat_signed(a, b)
    return v, int(f)


def _prim_cases(rng) -> list:
    """(op, a, b, c) tuples: ties, extremes, sign edges and random values; only those that meet
    the preconditions of firmware_ref.arith (the C driver answers ERR RANGE otherwise)."""
    MAX, MIN = arith.INT64_MAX, arith.INT64_MIN

    def rnd(lo=MIN, hi=MAX):
        return int(rng.integers(lo, hi, dtype=np.int64, endpoint=True))

    cases = []
    for s in (0, 1, 2, 3, 7, 10, 11, 16, 24, 29, 30, 31, 32, 36, 40, 52, 60, 61, 62):
        h = 1 << (s - 1) if s else 0
        xs = [0, 1, -1, 2, -2, h, -h, h + 1, -h - 1, h - 1, -h + 1, 3 * h, -3 * h, MAX - h, MIN, MIN + 1, MAX]
        for _ in range(6):
            k = rnd(-(1 << max(0, 62 - s)), 1 << max(0, 62 - s))
            xs += [k * (1 << s) + h, k * (1 << s) - h, k * (1 << s)]     # ties and exact multiples
        xs += [rnd() for _ in range(4)] + [rnd(-(1 << 40), 1 << 40)]
        cases += [("RHU", x, s, 0) for x in xs]
    for s in (1, 2, 11, 16, 29, 30, 31, 45, 60, 61, 62):
        h = 1 << (s - 1)
        for a, b in ((1, h), (-1, h), (3, h), (-3, h), (h, 1), (h, -1), (F.INT32_SYM, F.ONE), (-F.INT32_SYM, F.ONE),
                     (F.INT32_SYM, -F.ONE), (-F.INT32_SYM, -F.ONE), (F.ONE, F.ONE), (-F.ONE, F.ONE),
                     (-(1 << 31), F.ONE), ((1 << 31) - 1, (1 << 31) - 1), (MAX, 1), (MIN + h, 1), (1 << 40, 1 << 21),
                     (-(1 << 40), 1 << 21), (0, MAX), (MAX, -1)):
            cases.append(("MULRHU", a, b, s))
        for _ in range(8):
            cases.append(("MULRHU", rnd(-(1 << 32), 1 << 32), rnd(-(1 << 30), 1 << 30), s))
            k = rnd(-1000, 1000)
            cases.append(("MULRHU", 2 * k + 1, h, s))                         # ties: odd * 2^(s-1)
    for a, b in ((0, 1), (1, 1), (-1, 1), (7, 2), (-7, 2), (-8, 2), (MAX, 1), (MIN, 1), (MIN, 2), (MAX, MAX),
                 (MIN, MAX), (-1, MAX), (MAX - 1, MAX), (5, 3), (-5, 3), (-6, 3)):
        cases.append(("FLOORDIV", a, b, 0))
    for _ in range(40):
        cases.append(("FLOORDIV", rnd(), rnd(1, MAX), 0))
        cases.append(("FLOORDIV", rnd(-1000, 1000), rnd(1, 20), 0))
    for a, b in ((0, 1), (1, 2), (-1, 2), (3, 2), (-3, 2), (5, 10), (-5, 10), (4, 10), (-4, 10), (6, 10), (-6, 10),
                 (1, 3), (-1, 3), (2, 3), (-2, 3), (MAX // 2 - 1, 1), (MIN // 2, 1), (MAX // 4, MAX // 2 - 1)):
        cases.append(("DIVROUND", a, b, 0))
    for _ in range(40):
        b = rnd(1, 1 << 40)
        k = rnd(-(1 << 20), 1 << 20)
        cases.append(("DIVROUND", k * 2 * b + b, 2 * b, 0))                  # ties (k + 1/2)
        cases.append(("DIVROUND", rnd(MIN // 4, MAX // 4), rnd(1, MAX // 4), 0))
    for k in (0, 1, 10, 16, 20, 30, 40):
        for a, b in ((1, 2), (-1, 2), (3, 2), (-3, 2), (1, 3), (-1, 3), (0, 5), (1 << 30, 3), (-(1 << 30), 3),
                     (F.INT32_SYM, 1), (-F.INT32_SYM, 7), ((1 << 62) - 1, 1 << 41), (-(1 << 62), (1 << 41) + 1),
                     (MAX, MAX), (MIN, MAX), (MIN + 1, 1 << 62)):
            cases.append(("DIVRS", a, b, k))
        for _ in range(10):
            cases.append(("DIVRS", rnd(-(1 << 50), 1 << 50), rnd(1, 1 << 30), k))
    for x, lo, hi in ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (5, -3, 4), (4, -3, 4), (-3, -3, 4), (-4, -3, 4),
                      (MAX, -F.ONE, F.ONE), (MIN, -F.ONE, F.ONE), (F.ONE + 1, -F.ONE, F.ONE),
                      (-F.ONE - 1, -F.ONE, F.ONE), (F.ONE, -F.ONE, F.ONE), (-F.ONE, -F.ONE, F.ONE),
                      (MIN, MIN, MAX), (MAX, MIN, MAX)):
        cases.append(("CLAMP", x, lo, hi))
    for _ in range(30):
        lo, hi = sorted((rnd(-(1 << 40), 1 << 40), rnd(-(1 << 40), 1 << 40)))
        cases.append(("CLAMP", rnd(-(1 << 41), 1 << 41), lo, hi))
    for w in (1, 2, 8, 16, 31, 32, 33, 48, 62, 63):
        lim = (1 << (w - 1)) - 1
        for x in (0, 1, -1, lim, -lim, lim + 1, -lim - 1, -lim - 2, MAX, MIN, MIN + 1):
            cases.append(("SAT", x, w, 0))
        for _ in range(3):
            cases.append(("SAT", rnd(), w, 0))
    lim31, lim62 = (1 << 31) - 1, 1 << 62
    for s in (31, 32, 40, 52, 61, 62):
        h = 1 << (s - 1)
        for a, d in ((lim31, lim62), (-lim31, lim62), (lim31, -lim62), (-lim31, -lim62), (1, h), (-1, h), (1, -h),
                     (3, h), (-3, h), (lim31, 0), (0, lim62), (1 << 30, 1 << 60), (-(1 << 30), 1 << 60),
                     (1 << 30, -(1 << 60)), (lim31, (1 << 31) - 1), (lim31, -(1 << 31)), (2, h - 1), (-2, h + 1)):
            cases.append(("RHUW", a, d, s))
        for _ in range(10):
            cases.append(("RHUW", rnd(-lim31, lim31), rnd(-lim62, lim62), s))
            k = rnd(-(1 << 20), 1 << 20)
            cases.append(("RHUW", 2 * k + 1, h, s))                           # ties: odd * 2^(s-1)
    quarter = 1 << 62
    for ph in (0, 1, quarter - 1, quarter, quarter + 1, 2 * quarter, 3 * quarter, -1, MIN, MAX, MIN + 1,
               (1 << 31) - 1, 1 << 31, (1 << 31) + 1, quarter - (1 << 31), quarter + (1 << 31), -(1 << 31),
               3 * quarter - (1 << 31) - 1):
        cases.append(("SIN", ph, 0, 0))
    for _ in range(120):
        cases.append(("SIN", rnd(), 0, 0))
    out = []
    for op, a, b, c in cases:
        if not (MIN <= a <= MAX and MIN <= b <= MAX and MIN <= c <= MAX):
            continue
        try:
            _prim_eval(op, a, b, c)
        except AssertionError:
            continue
        out.append((op, a, b, c))
    return out


def primitives_set(rng) -> VectorSet:
    cases = _prim_cases(rng)
    cols = {"op": np.array([PRIM_OPS.index(c[0]) for c in cases], np.int64),
            "a": np.array([c[1] for c in cases], np.int64),
            "b": np.array([c[2] for c in cases], np.int64),
            "c": np.array([c[3] for c in cases], np.int64)}
    vs = VectorSet("primitives", "fixed-point primitives (firmware_ref.arith): RHU(a, s=b), MULRHU(a, b, s=c), "
                   "FLOORDIV(a, b), DIVROUND(a, b), DIVRS(a, b, k=c), CLAMP(x=a, lo=b, hi=c), SAT(x=a, width=b), "
                   "RHUW(a, d=b, s=c) = RHU(a d, s) wider than int64, SIN(phase=a: the uint64 phase as int64 bits, "
                   "firmware_ref.aux.sin_q30); flag = clamped (CLAMP, SAT), else 0", cols, PRIM_INPUTS, PRIM_FIELDS,
                   cases=[{"name": op, "description": f"{op} requests"} for op in PRIM_OPS])
    compute_primitives(vs)
    return vs


def compute_primitives(vs: VectorSet) -> None:
    res, flag = [], []
    for op, a, b, c in zip(vs.columns["op"].tolist(), vs.columns["a"].tolist(), vs.columns["b"].tolist(),
                           vs.columns["c"].tolist()):
        try:
            r, f = _prim_eval(PRIM_OPS[op], a, b, c)
        except AssertionError as exc:
            raise VectorsError(f"primitives: {PRIM_OPS[op]} {a} {b} {c} violates a precondition ({exc})") from None
        res.append(r)
        flag.append(f)
    vs.columns["result"] = np.array(res, np.int64)
    vs.columns["flag"] = np.array(flag, np.int64)
