"""The 17-term bias in fixed point: nested Horner in two variables (Python-integer reference).

Coefficient k is ``m_k * 2^-e_g`` deg/h with one exponent per group g: the Horner rows u^i
(e_0..e_3: row i holds the terms u^i v^j, j = 0..3) and k7 (e_7).  With ``c[i][j] =
m[POLY_INDEX[i][j]]`` and u, v, z int32 Q1.30 (z clamped to [-2^30, 2^30], flag), exactly::

    for i in 3, 2, 1, 0:                                     # 12 multiply-adds
        p = c[i][3]
        p = RHU(p * v, 30) + c[i][2]
        p = RHU(p * v, 30) + c[i][1]
        q = RHU(p * v, 30) + c[i][0]                         # q_i, LSB 2^-e_i deg/h
        a[i] = RHU(q, e_i - E)                               # aligned to the accumulator, 2^-E
    t = a[3]
    t = RHU(t * u, 30) + a[2]                                 # 3 multiply-adds
    t = RHU(t * u, 30) + a[1]
    t = RHU(t * u, 30) + a[0]
    t = t + RHU(m_7 * z, 30 + e_7 - E)                        # k7 z
    B = RHU(t, E - 21) if E >= 21 else t << (21 - E)          # B: int64, LSB 2^-21 deg/h

Two banks (a regress_first table, order 1): ``bank`` 2 (mode-2 samples) evaluates the same scheme
with bank 2's mantissas and exponents (m2_k, e2_g, E2); every other sample uses bank 1.

host_tools.fixed.quantize chooses the exponents so that every p, q, a and t satisfies
``|.| <= 2^31 - 1`` for every |u|, |v|, |z| <= 2^30 (interval analysis; the rounded product
``RHU(x * w, 30)`` with |w| <= 2^30 never exceeds |x|), hence every product is below 2^61.
"""
from __future__ import annotations

from firmware_ref import formats as F
from firmware_ref.arith import clamp, mul_rshift_round, rshift_round
from firmware_ref.terms import K_AUX, POLY_INDEX


def evaluate(u: int, v: int, z: int, table, trace: list | None = None, bank: int = 1) -> tuple[int, bool]:
    """``(B, z_clamped)``: the bias B (int64, LSB 2^-21 deg/h) of coefficient ``bank`` (1 or 2;
    table.bank_of_mode gives it).  ``trace``: if a list, every accumulator value (p, q, a, t) is
    appended (the overflow proof of the tests reads it)."""
    z, z_clamped = clamp(z, -F.ONE, F.ONE)
    table = table.bank(bank) if hasattr(table, "bank") else table
    m, E = table.mant, table.e_acc
    a = [0, 0, 0, 0]
    for i in (3, 2, 1, 0):
        c = [m[POLY_INDEX[i][j]] for j in range(4)]
        p = c[3]
        p = mul_rshift_round(p, v, F.Q) + c[2]
        if trace is not None:
            trace.append(p)
        p = mul_rshift_round(p, v, F.Q) + c[1]
        if trace is not None:
            trace.append(p)
        q = mul_rshift_round(p, v, F.Q) + c[0]
        a[i] = rshift_round(q, table.e_row[i] - E)
        if trace is not None:
            trace += [q, a[i]]
    t = a[3]
    for i in (2, 1, 0):
        t = mul_rshift_round(t, u, F.Q) + a[i]
        if trace is not None:
            trace.append(t)
    t = t + mul_rshift_round(m[K_AUX], z, F.Q + table.e_7 - E)
    if trace is not None:
        trace.append(t)
    b = rshift_round(t, E - F.Y_FRAC) if E >= F.Y_FRAC else t << (F.Y_FRAC - E)
    return b, z_clamped
