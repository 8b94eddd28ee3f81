"""Proxy normalization in fixed point: the proxy word P -> u, int32 Q1.30 (Python-integer reference).

Copies host_tools.golden.proxy step for step (the golden doc is the spec)::

    dP = P - P_REF                       (clamped to +-(2^31 - 1), an int32, where u saturates anyway)
    u_raw = RHU(dP * G_U + U_OFF, SH_U)  (G_U < 2^31: the product is below 2^62, |U_OFF| <= G_U/2)
    u = clamp(u_raw, -2^30, 2^30)        clamped = |u_raw| > 2^30 (an exact edge is not clamped)

``G_U = RHU(2^(30 + SH_U) * LSB_P / span)`` is the firmware's precomputed reciprocal of the span
(host_tools.fixed.quantize chooses SH_U); ``P_REF = RHU(ref / LSB_P)`` and ``U_OFF = RHU((P_REF -
ref / LSB_P) * G_U)`` carries the fraction of the centre that P_REF drops, so the centre costs no
accuracy.  No state, no warm-up.
"""
from __future__ import annotations

from firmware_ref import formats as F
from firmware_ref.arith import check_int64, clamp, rshift_round


def proxy_u(p: int, table) -> tuple[int, bool]:
    """``(u, clamped)`` for one proxy word ``p`` (F or T word) under ``table`` (firmware_ref.table.Table)."""
    dp, _ = clamp(p - table.p_ref, -F.DP_CLAMP, F.DP_CLAMP)  # int32: the product is 32 x 32 bits
    u_raw = rshift_round(check_int64(dp * table.g_u + table.u_off, "u product"), table.sh_u)
    return clamp(u_raw, -F.ONE, F.ONE)
