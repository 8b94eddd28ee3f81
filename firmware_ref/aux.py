"""The auxiliary regressor z in fixed point: the generators of aux_gen 1 ('sum') per sample
(Python-integer reference of host_tools.golden.regressors.aux_regressor, whose module doc is the spec).

Inputs per sample: the channel words (code 0 F, 1 T, 2 + c the aux word A_c; firmware_ref.inputs),
the sample counter K since power-on, the mode m (logged or the timer's), restart, the input-invalid
bit INV (FORMATS.md "The input-invalid bit"), and the rate stage's sum S (before its clamp) and
warm-up flag (the rate stage restarts at an invalid sample and the one after it, so a rate term
re-warms with it).  With ``s_m`` = +1 (m = 0, 1), -1 (m = 2),
0 (m = 3) and ``kk = max(K, 0)``, every term j gives g_j (Q1.30), then::

    acc = sum_j w_j (s_m g_j if sign_j else g_j)         (exact int64: |.| <= (2^30 + n_terms) 2^30 < 2^61,
                                                          sum |w_j| <= 2^30 + n_terms checked by the table)
    z   = clamp(RHU(acc, 30), -2^30, 2^30)               (flag 32 when clamped)

Terms (table.AUX_COEF names the coefficients; RHUW = arith.mul_rshift_round_wide; Y_j, ex_j the
term's state, reset at power-on and at every restart as the golden's seg_start; PEND one bit of
the stage, 0 at power-on: a restart met on an invalid sample, which the input filters take at the
next valid one; ``rs = restart or PEND``)::

    input:  dX = clamp(X - REF, +-(2^31 - 1));  q = clamp(RHU(dX G + OFF, SH), +-2^30)
            SB = 0: y = q
            else:   if INV: Y_j = 0 if rs else held;  elif rs: Y_j = q 2^30
                    else: Y_j = Y_j + RHUW(B, q 2^30 - Y_j, SB)
                    y = RHU(Y_j, 30)
            g = y; then power - 1 times g = RHU(g y, 30)
    rate:   g = 0 in warm-up, else clamp(RHU(clamp(S, +-(2^SB - 1)) G_V, SH_V), +-2^30)
    one:    g = 2^30
    decay_on:        Y_j = 2^60 if restart else Y_j + RHUW(B, -Y_j, SB);  g = RHU(Y_j, 30)
    decay_exchange:  if restart: Y_j = 0, ex_j = 0
                     if m == 3: Y_j = 0, ex_j = 1
                     elif ex_j: Y_j = 2^60, ex_j = 0
                     else:      Y_j = Y_j + RHUW(B, -Y_j, SB)
                     g = RHU(Y_j, 30)
    ramp:   g = 2^30 if kk >= N else RHU(kk G, SH)
    osc:    g = sin_q30((kk W + part 2^62) mod 2^64)          (part 1: cos = sin + a quarter turn)
    after the terms: PEND = INV and rs

decay_on, decay_exchange, ramp, osc and one read no input word (restart, mode, K only) and an
unfiltered input no past one: INV does not change them.

:func:`sin_q30` of a uint64 phase (turns x 2^64): quadrant ``Q = phase >> 62``, the quarter-turn
fraction ``r = RHU(phase mod 2^62, 32)`` (0..2^30), ``x = r`` (Q even) or ``2^30 - r`` (Q odd),
``x2 = RHU(x x, 30)``, Horner ``p = S_5; p = RHU(p x2, 30) + S_i`` for i = 4..0 (formats.SIN_POLY),
``s = min(RHU(p x, 30), 2^30)``, negated for Q >= 2.
"""
from __future__ import annotations

import numpy as np

from firmware_ref import formats as F
from firmware_ref.arith import clamp, mul_rshift_round, mul_rshift_round_wide, rshift_round
from firmware_ref.table import (KIND_DECAY_EXCHANGE, KIND_DECAY_ON, KIND_INPUT, KIND_ONE, KIND_OSC, KIND_RAMP,
                                KIND_RATE)

MASK64 = (1 << 64) - 1
STATE_ONE = 1 << F.AUX_STATE_FRAC        # 1.0 in the Q1.60 filter / decay state


def sin_q30(phase: int) -> int:
    """sin(2 pi phase / 2^64) in Q1.30 (phase a uint64; module doc); within SIN_ERR_LSB of the
    exact value."""
    phase &= MASK64
    quad = phase >> 62
    r = ((phase >> 32) & (F.ONE - 1)) + ((phase >> 31) & 1)
    x = F.ONE - r if quad & 1 else r
    x2 = mul_rshift_round(x, x, F.Q)
    p = F.SIN_POLY[5]
    for c in F.SIN_POLY[4::-1]:
        p = mul_rshift_round(p, x2, F.Q) + c
    s = min(mul_rshift_round(p, x, F.Q), F.ONE)
    return -s if quad >= 2 else s


def mode_sign(mode: int) -> int:
    """s_m: +1 in modes 0 and 1, -1 in mode 2, 0 in mode 3."""
    return F.MODE_SIGN[mode]


def normalize(x: int, ref: int, g: int, off: int, sh: int) -> int:
    """q = clamp(RHU(clamp(x - REF, +-(2^31 - 1)) G + OFF, SH), +-2^30) (the proxy's normalization)."""
    dx, _ = clamp(x - ref, -F.DP_CLAMP, F.DP_CLAMP)
    q, _ = clamp(rshift_round(dx * g + off, sh), -F.ONE, F.ONE)
    return q


class AuxStage:
    """The aux_gen 1 stage of one table (module doc): :meth:`step` per sample."""

    def __init__(self, table):
        self.table = table
        self.aux = table.aux()
        n = 0 if self.aux is None else len(self.aux.terms)
        self.y = [0] * n
        self.ex = [0] * n
        self.pend = False            # a restart on an invalid sample, for the input filters

    def step(self, chan, k: int, mode: int, restart: bool, s: int, warm: bool,
             invalid: bool = False) -> tuple[int, bool, list]:
        """``(z, clamped, g)`` of one sample: ``chan`` the channel words by code (F, T, A_0..),
        ``k`` the counter K, ``mode`` 0..3, ``restart``, ``s`` and ``warm`` from the rate stage,
        ``invalid`` the input-invalid bit; ``g`` the terms' values (sign applied, weight not)."""
        kk = max(int(k), 0)
        sm = mode_sign(mode)
        acc = 0
        gs = []
        rs = bool(restart) or self.pend
        self.pend = bool(invalid) and rs
        for j, t in enumerate(self.aux.terms):
            c = t.c
            if t.kind == KIND_INPUT:
                q = normalize(int(chan[t.src]), c[0], c[1], c[2], c[3])
                if c[5] == 0:
                    y = q
                else:
                    if invalid:              # the invalid word never enters the filter: held,
                        if rs:               # or 0 at a (pending) restart
                            self.y[j] = 0
                    elif rs:
                        self.y[j] = q << F.Q
                    else:
                        self.y[j] += mul_rshift_round_wide(c[4], (q << F.Q) - self.y[j], c[5])
                    y = rshift_round(self.y[j], F.Q)
                g = y
                for _ in range(t.power - 1):
                    g = mul_rshift_round(g, y, F.Q)
            elif t.kind == KIND_RATE:
                if warm:
                    g = 0
                else:
                    sc, _ = clamp(s, -((1 << c[0]) - 1), (1 << c[0]) - 1)
                    g, _ = clamp(mul_rshift_round(sc, c[1], c[2]), -F.ONE, F.ONE)
            elif t.kind == KIND_ONE:
                g = F.ONE
            elif t.kind == KIND_DECAY_ON:
                if restart:
                    self.y[j] = STATE_ONE
                else:
                    self.y[j] += mul_rshift_round_wide(c[0], -self.y[j], c[1])
                g = rshift_round(self.y[j], F.Q)
            elif t.kind == KIND_DECAY_EXCHANGE:
                if restart:
                    self.y[j], self.ex[j] = 0, 0
                if mode == 3:
                    self.y[j], self.ex[j] = 0, 1
                elif self.ex[j]:
                    self.y[j], self.ex[j] = STATE_ONE, 0
                else:
                    self.y[j] += mul_rshift_round_wide(c[0], -self.y[j], c[1])
                g = rshift_round(self.y[j], F.Q)
            elif t.kind == KIND_RAMP:
                g = F.ONE if kk >= c[0] else mul_rshift_round(kk, c[1], c[2])
            elif t.kind == KIND_OSC:
                g = sin_q30(kk * c[0] + (c[2] << 62))
            else:  # pragma: no cover - Table.validate refuses other kinds
                raise AssertionError(f"aux kind {t.kind}")
            if t.sign:
                g = sm * g
            gs.append(g)
            acc += t.weight * g
        z, clamped = clamp(rshift_round(acc, F.Q), -F.ONE, F.ONE)
        return z, clamped, gs


# -- host side: which channels a table reads -------------------------------------------------------------

def aux_columns(aux_config) -> list:
    """The run-log ``aux_*`` columns an AuxConfig reads through input terms, in channel order
    (sorted, unique): column ``aux_columns(cfg)[c]`` is the aux word A_c."""
    if aux_config is None or aux_config.generator == "none":
        return []
    return sorted({t["column"] for t in aux_config.terms if t["gen"] == "input" and t["column"].startswith("aux_")})


def needed_channels(table) -> set:
    """Channel codes (0 F, 1 T, 2 + c A_c) that the table's input terms read."""
    aux = table.aux()
    return set() if aux is None else {t.src for t in aux.terms if t.kind == KIND_INPUT}


def channel_rows(table, n: int, p, f=None, t=None, aux=None) -> list:
    """The channel words by code as int64 arrays of length n for ``table``: row 0 F (``f``, or the
    proxy words ``p`` of a freq table), row 1 T (``t``, or ``p`` of a temp table), rows 2.. the aux
    words (``aux``: int64[n, n_chan] or a list of arrays, A_0 first).  ValueError names a channel the
    table reads that is not given; channels it does not read are zeros."""
    info = table.aux()
    nch = 0 if info is None else info.n_chan
    need = needed_channels(table)
    rows = []
    given = {F.CH_F: f if f is not None else (p if table.proxy_kind == 0 else None),
             F.CH_T: t if t is not None else (p if table.proxy_kind == 1 else None)}
    if aux is not None:
        if isinstance(aux, (list, tuple)):
            cols = list(aux)
        else:
            a = np.asarray(aux, np.int64)
            a = a[:, None] if a.ndim == 1 else a
            cols = [a[:, c] for c in range(a.shape[1])]
        for c in range(min(nch, len(cols))):
            given[F.CH_A0 + c] = cols[c]
    names = {F.CH_F: "the drive-frequency words F", F.CH_T: "the temperature words T"}
    for code in range(F.CH_A0 + nch):
        arr = given.get(code)
        if arr is None:
            if code in need:
                raise ValueError(f"the table's aux generator reads {names.get(code, f'aux word A{code - 2}')}, "
                                 f"which were not given")
            arr = np.zeros(n, np.int64)
        arr = np.ascontiguousarray(arr, np.int64)
        if arr.shape != (n,):
            raise ValueError(f"channel {code} words: shape {arr.shape}, expected ({n},)")
        rows.append(arr)
    return rows
