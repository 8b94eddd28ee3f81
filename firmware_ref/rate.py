"""Normalized proxy rate in fixed point: proxy words -> v, int32 Q1.30 (Python-integer reference).

Copies host_tools.golden.rate (its module doc is the spec) with integer sums of proxy words:

* ``diff``  ``S = P[i] - P[i-1]``; ``diffn`` ``S = P[i] - P[i-n]``;
* ``lsq``   ``S = sum_{j=0}^{n-1} (2j - (n-1)) (P[i-n+1+j] - P[i])``, summed in order j = 0..n-1;
* ``iir``   state y with IIR_FRAC = 24 extra fractional bits: at k = 0 ``y = 0``; at k >= 1
  ``y += RHU((d << 24) - y, e)`` with the gear ``e = min(shift, floor(log2 k))``, d = P[i] - P[i-1]
  (at k = 1, e = 0: ``y = d << 24``); ``S = y``.

k counts samples since the last restart, saturating at ``K_SAT = max(W, 2^shift)`` for iir (the
gear needs k up to 2^shift) and at W otherwise; a restart (segment start) resets k and y as at
power-on, and past words are only read within the segment.  The estimator also restarts at an
input-invalid sample and at the sample after it (FORMATS.md "The input-invalid bit"; one bit of
state, the previous sample's bit): the flagged word never enters its memory, the estimator
re-warms (flag 4) as after a gap.  Then::

    warm-up (k < W):  v = 0, warmup, not clamped
    else:             Sc = clamp(S, +-(2^SB - 1));  v_raw = RHU(Sc * G_V, SH_V)
                      v = clamp(v_raw, -2^30, 2^30), clamped = |v_raw| > 2^30 or S was clamped

``G_V = RHU(2^(30 + SH_V) / S_span)`` with ``S_span = D span / (fs LSB_P)`` (x 2^24 for iir): the
golden ``gain = fs / (D span)`` in word units.  SB is chosen so that ``2^SB - 1 > S_span``
(a clamped S gives |v| > 1 anyway) and ``G_V < 2^(62 - SB)`` (the product fits int64).
"""
from __future__ import annotations

from collections import deque

from firmware_ref import formats as F
from firmware_ref.arith import clamp, mul_rshift_round, rshift_round

DIFF, DIFFN, LSQ, IIR = range(4)


def iir_gear(k: int, shift: int) -> int:
    """The iir's shift at segment index k >= 1: ``min(shift, floor(log2 k))`` (0 at k = 1)."""
    return min(shift, k.bit_length() - 1)


def k_saturation(rate_est: int, rate_shift: int, rate_warmup: int) -> int:
    """K_SAT, where the sample counter k stops: ``max(W, 2^shift)`` for iir, W otherwise."""
    return max(rate_warmup, 1 << rate_shift) if rate_est == IIR else rate_warmup


class RateState:
    """The estimator state: history of the last n + 1 words (within the segment), k, iir y."""

    def __init__(self, table):
        self.table = table
        self.n = table.rate_n if table.rate_est in (DIFFN, LSQ) else 1
        self.k_sat = k_saturation(table.rate_est, table.rate_shift, table.rate_warmup)
        self.prev_invalid = False    # the previous sample was input-invalid (not reset by reset())
        self.reset()

    def reset(self):
        self.hist = deque(maxlen=self.n + 1)   # hist[-1] is the present word
        self.k = 0
        self.y = 0

    def step(self, p: int, restart: bool, invalid: bool = False) -> tuple[int, bool, bool, int]:
        """One sample: ``(v, clamped, warmup, S)``; ``invalid``: the sample's input-invalid bit."""
        t = self.table
        if restart or invalid or self.prev_invalid:
            self.reset()
        self.prev_invalid = bool(invalid)
        self.hist.append(p)
        k, n = self.k, self.n
        s = 0
        if t.rate_est in (DIFF, DIFFN):
            if k >= n:
                s = p - self.hist[-1 - n]
        elif t.rate_est == LSQ:
            if k >= n - 1:
                for j in range(n):
                    s += (2 * j - (n - 1)) * (self.hist[-n + j] - p)
        else:
            if k >= 1:
                self.y += rshift_round(((p - self.hist[-2]) << F.IIR_FRAC) - self.y, iir_gear(k, t.rate_shift))
            s = self.y
        self.k = min(k + 1, self.k_sat)
        if k < t.rate_warmup:
            return 0, False, True, s
        sc, s_clamped = clamp(s, -((1 << t.s_bits) - 1), (1 << t.s_bits) - 1)
        v_raw = mul_rshift_round(sc, t.g_v, t.sh_v)
        v, v_clamped = clamp(v_raw, -F.ONE, F.ONE)
        return v, v_clamped or s_clamped, False, s
