"""Compensated output and status flags in fixed point: the whole per-sample pipeline.

Per sample (Python-integer reference :class:`Pipeline`; the numba kernel firmware_ref.kernel is
bit-identical)::

    state/mode  = sequencer timer (self-timed) or the logged mode
    u, uc       = proxy_u(P)                          (firmware_ref.proxy)
    v, vc, warm = rate.step(P, restart, invalid)      (firmware_ref.rate; restarts at an invalid
                                                       sample and the one after it)
    z, zc       = aux_gen 0: clamp(Z, +-2^30); aux_gen 1: the generators (firmware_ref.aux) on
                  the channel words (F, T, A_c), K, mode, restart (or power-on), S, warm, invalid
                  (an input filter holds its state over an invalid sample)
    B           = evaluate(u, v, z, bank)             (firmware_ref.evaluator, every sample; bank 2
                                                       on mode-2 samples of a two-bank table)
    cvalid, y   = combiner.step(mode, R, restart, B, warm, invalid)   (firmware_ref.sequencer; y
                                                       held; order 1 accumulates r = c - B; an
                                                       invalid sample taints its window)
    valid       = cvalid and not warm and mode != 3 and not invalid
    if valid:   OUT = symsat32(RHU(y - B, 11)) (order 0) or symsat32(RHU(y, 11)) (order 1: B is
                in y already); BIAS = symsat32(RHU(B, 11))   (held otherwise; 0 before the first)
    flags       = 1 uc | 2 vc | 4 warm | 8 (mode == 3) | 16 (not cvalid and mode != 3)
                  | 32 zc | 64 invalid | 128 (any saturation: window count, trend, residual r, OUT, BIAS)

``invalid`` is the sample's input-invalid bit (FORMATS.md "The input-invalid bit": the host input
stage sets it from the declared full scale, host_tools.golden.input_check; a sensor front end's
over-range flag).

OUT and BIAS are int32 words, LSB 2^-10 deg/h; the hold is not reset at restarts (as the golden
host_tools.golden.compensate).  K is the sample counter since power-on (the golden's ``rint(t_s fs)``);
when not given, the pipeline counts itself: K = the previous sample's K + 1, 0 at power-on.  Bit 64
of a saturated aux word (it does not set the invalid bit) is added by the host side
(host_tools.fixed.fixed_point.compensate_log, which is ``hdrg compensate --impl fixed``: run log +
model (+ optional table) -> compensated run log).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_ref import formats as F
from firmware_ref.arith import clamp, rshift_round, sat_signed
from firmware_ref.aux import AuxStage, channel_rows
from firmware_ref.evaluator import evaluate
from firmware_ref.proxy import proxy_u
from firmware_ref.rate import RateState
from firmware_ref.sequencer import Sequencer


@dataclass
class Sample:
    """One sample of the pipeline's outputs (words) and intermediates."""

    out: int
    bias: int
    valid: bool
    flags: int
    u: int
    v: int
    z: int
    b: int
    y: int
    s: int
    state: int
    vs: int
    sign: int
    acc: int
    cnt: int


class Pipeline:
    """The per-sample reference (see the module doc)."""

    def __init__(self, table, self_timed: bool = False):
        self.table = table
        self.rate = RateState(table)
        self.seq = Sequencer(table, self_timed)
        self.aux = AuxStage(table) if table.aux_gen == 1 else None
        self.kc = 0                  # the internal sample counter (K when not given)
        self.fresh = True            # power-on: the aux generators start as at a restart
        self.out_hold = 0
        self.bias_hold = 0

    def step(self, p: int, r: int, mode, restart: bool = False, z: int = 0, chan=(), k: int | None = None,
             invalid: bool = False) -> Sample:
        """One sample: proxy word ``p``, rate word ``r``, logged ``mode`` (None: self-timed),
        ``restart``, external ``z`` (aux_gen 0), channel words ``chan`` by code (aux_gen 1), the
        counter ``k`` (None: the internal count) and the input-invalid bit ``invalid``."""
        t = self.table
        invalid = bool(invalid)
        state, mode = self.seq.mode_step(mode, restart)
        u, uc = proxy_u(p, t)
        v, vc, warm, s = self.rate.step(p, restart, invalid)
        k = self.kc if k is None else int(k)
        self.kc = min(k + 1, F.K_LIMIT)
        if self.aux is not None:
            z, zc, _ = self.aux.step(chan, k, mode, restart or self.fresh, s, warm, invalid)
        else:
            z, zc = clamp(z, -F.ONE, F.ONE)
        self.fresh = False
        b, _ = evaluate(u, v, z, t, bank=t.bank_of_mode(mode))
        so = self.seq.combine_step(state, mode, r, restart, b, warm, invalid)
        valid = so.valid and not warm and mode != 3 and not invalid
        sat = so.sat
        if valid:
            o, s1 = sat_signed(rshift_round(so.y - (b if t.order == 0 else 0), F.OUT_SHIFT), 32)
            bw, s2 = sat_signed(rshift_round(b, F.OUT_SHIFT), 32)
            sat = sat or s1 or s2
            self.out_hold, self.bias_hold = o, bw
        flags = ((F.FLAG_PROXY_CLAMPED if uc else 0) | (F.FLAG_RATE_CLAMPED if vc else 0)
                 | (F.FLAG_WARMUP if warm else 0) | (F.FLAG_EXCHANGE if mode == 3 else 0)
                 | (F.FLAG_STALE if (not so.valid and mode != 3) else 0)
                 | (F.FLAG_AUX_CLAMPED if zc else 0) | (F.FLAG_INPUT_SAT if invalid else 0)
                 | (F.FLAG_SAT if sat else 0))
        return Sample(self.out_hold, self.bias_hold, valid, flags, u, v, z, b, so.y, s, so.state, so.vs, so.sign,
                      so.acc, so.cnt)


def run_reference(table, p, r, mode=None, restart=None, z=None, self_timed: bool = False, f=None, t=None,
                  aux=None, k=None, invalid=None) -> dict:
    """The Python reference over arrays; same arguments and the same dict as
    firmware_ref.kernel.run_words with ``detail=True`` (plus ``vs``, ``sign``, ``acc``, ``cnt``),
    as int64/uint8 arrays.  ``invalid``: the input-invalid bits (None: none)."""
    n = len(p)
    pipe = Pipeline(table, self_timed)
    rows = channel_rows(table, n, p, f, t, aux) if table.aux_gen == 1 else []
    chans = list(zip(*[row.tolist() for row in rows])) if rows else [()] * n
    kin = None if k is None else np.asarray(k, np.int64).tolist()
    cols = {name: [] for name in ("out", "bias", "valid", "flags", "u", "v", "z", "b", "y", "s", "state", "vs",
                                  "sign", "acc", "cnt")}
    for i in range(n):
        s = pipe.step(int(p[i]), int(r[i]), None if mode is None else int(mode[i]),
                      bool(i == 0 or (restart is not None and restart[i])), 0 if z is None else int(z[i]),
                      chans[i], None if kin is None else kin[i], bool(invalid is not None and invalid[i]))
        for name in cols:
            cols[name].append(int(getattr(s, name)))
    out = {name: np.array(vals, np.int64) for name, vals in cols.items()}
    out["valid"] = out["valid"].astype(np.uint8)
    out["flags"] = out["flags"].astype(np.uint8)
    return out


# -- host side: run logs --------------------------------------------------------------------------
