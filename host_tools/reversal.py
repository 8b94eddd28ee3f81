"""Mode-reversal combination (golden model, float64): the bias-cancelled output of eq. (5), causal.

Input per sample i: ``mode[i]`` (0 FTR, 1, 2, 3 exchange) and ``rate[i]``, the raw loop output in
deg/h with the run-log sign convention: in mode 2 the true rate and the non-reversing bias flip
sign, the damping-asymmetry term does not.  So the *rate-corrected* sample

    c[i] = s[i] * rate[i],    s = +1 in mode 1, -1 in mode 2

equals  Omega + B_E + s * B_D:  averaging a mode-1 and a mode-2 value cancels B_D (eq. 5).

A log is either FTR (every sample mode 0: output = rate, always valid, s = +1) or mode reversal
(modes 1, 2, 3 only; a mix with mode 0 is an error).

Exact semantics (the fixed-point sequencer in firmware_ref copies them):

* **Windows.** A window is a maximal run of consecutive samples of one mode m in {1, 2}.  The
  first ``settle_n = round(settle_s * fs)`` samples of every window are *settling*: they enter
  neither the window mean nor a valid output.  Every other sample adds c[i] to the open window's
  sum and count.  When the mode changes (to 3 or to the other mode), the open window is
  *committed* if its count >= 1: ``W[m] = sum / count`` (the mean of c over the used samples),
  ``centre[m]`` = mean of the first and last used sample index, ``end[m]`` = the last used index.
* **Segments (time gaps).** At the start of every gap-free segment (``RunLog.segments``) the state
  is reset as at power-on: the open window is discarded and no committed window remains.
* **Output** at a non-settling sample i of mode m, with o the other mode: the output is valid
  when o has a committed window and ``i - end[o] <= max_stale_n`` (``max_stale_n =
  round(max_stale_s * fs)``; default 300 s, the paper's period: the other mode's estimate may be
  at most one reversal period old).  Then

  - ``"pair"`` (the paper, section 3.4/4.4):   out = (c[i] + W[o]) / 2
  - ``"trend"`` (ours):  out = (c[i] + W[o] + slope[o] * (i - centre[o])) / 2, where
    ``slope[o] = (W[o] - W_prev[o]) / (centre[o] - centre_prev[o])`` [deg/h per sample] is the
    change between the last two committed windows of mode o (0 until o has two committed windows
    in this segment).  It extrapolates the other mode's bias linearly to the present sample, so
    the first-order effect of the temperature change between the two modes' windows (eq. 6)
    cancels too; on a static run it equals "pair" plus the noise of the slope.

  Both are valid from the first sample of the first mode-2 window after a complete mode-1 window
  (180 s after power-on in the paper's timing, as the paper says).
* **Invalid samples** (exchange, settling, before the first pair, stale) output the last valid
  output (0.0 before the first one) with ``valid = False``.  They never enter a fit or a statistic.

Note: the rate-corrected output also averages the *true rate* of the present sample with that of
the other window, so a rotation that changes between windows is seen at half amplitude: like the
paper, this is a method for bias, on a static or slowly turning gyroscope.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

COMBINERS = ("pair", "trend")
DEFAULT_MAX_STALE_S = 300.0
DEFAULT_COMBINER = "trend"  # the combiner of the CLI (hdrg fit / diagnose / metrics) unless --combiner says otherwise


@dataclass
class ReversalConfig:
    """Combination settings stored with a model: combiner name, staleness limit [s], settling time [s]."""

    combiner: str = "pair"
    max_stale_s: float = DEFAULT_MAX_STALE_S
    settle_s: float = 0.0

    def __post_init__(self):
        if self.combiner not in COMBINERS:
            raise ValueError(f"reversal combiner must be one of {COMBINERS}, not {self.combiner!r}")
        if not self.max_stale_s > 0:
            raise ValueError(f"reversal max_stale_s must be > 0, not {self.max_stale_s}")
        if not self.settle_s >= 0:
            raise ValueError(f"reversal settle_s must be >= 0, not {self.settle_s}")

    def to_dict(self) -> dict:
        return {"combiner": self.combiner, "max_stale_s": self.max_stale_s, "settle_s": self.settle_s}

    @classmethod
    def from_dict(cls, d: dict) -> "ReversalConfig":
        return cls(**{k: d[k] for k in ("combiner", "max_stale_s", "settle_s") if k in d})


@dataclass
class Combined:
    """Output of :func:`combine`: ``out_dph`` float64[n] [deg/h], ``valid`` bool[n], ``sign`` int8[n]
    (+1 mode 0/1, -1 mode 2, 0 exchange), the combiner used."""

    out_dph: np.ndarray
    valid: np.ndarray
    sign: np.ndarray
    combiner: str


@numba.njit(cache=True)
def _combine_kernel(mode, rate, seg_start, settle_n, max_stale_n, trend):
    n = mode.shape[0]
    out = np.zeros(n)
    valid = np.zeros(n, np.bool_)
    W = np.zeros(3)
    Wprev = np.zeros(3)
    centre = np.zeros(3)
    centre_prev = np.zeros(3)
    end = np.zeros(3, np.int64)
    ncommit = np.zeros(3, np.int64)
    slope = np.zeros(3)
    cur = 0
    acc = 0.0
    cnt = 0
    first = 0
    last = 0
    pos = 0
    hold = 0.0
    for i in range(n):
        m = mode[i]
        if seg_start[i]:
            cur = 0
            acc = 0.0
            cnt = 0
            pos = 0
            for k in range(3):
                ncommit[k] = 0
                slope[k] = 0.0
        if m != cur:
            if cur != 0 and cnt >= 1:
                mean = acc / cnt
                c_new = 0.5 * (first + last)
                if ncommit[cur] >= 1:
                    Wprev[cur] = W[cur]
                    centre_prev[cur] = centre[cur]
                    slope[cur] = (mean - Wprev[cur]) / (c_new - centre_prev[cur])
                W[cur] = mean
                centre[cur] = c_new
                end[cur] = last
                ncommit[cur] += 1
            cur = m if (m == 1 or m == 2) else 0
            acc = 0.0
            cnt = 0
            pos = 0
        if cur != 0:
            s = 1.0 if cur == 1 else -1.0
            c = s * rate[i]
            if pos >= settle_n:
                if cnt == 0:
                    first = i
                last = i
                acc += c
                cnt += 1
                o = 3 - cur
                if ncommit[o] >= 1 and i - end[o] <= max_stale_n:
                    other = W[o]
                    if trend:
                        other += slope[o] * (i - centre[o])
                    hold = 0.5 * (c + other)
                    valid[i] = True
            pos += 1
        out[i] = hold
    return out, valid


def combine(log, combiner: str = "pair", max_stale_s: float | None = None, settle_s: float = 0.0,
            fs_hz: float | None = None) -> Combined:
    """Combine a run log's raw output into the bias-cancelled output (see the module doc).

    ``log`` is a :class:`host_tools.runlog.RunLog`.  ``fs_hz`` defaults to the log's sample rate.
    """
    cfg = ReversalConfig(combiner, DEFAULT_MAX_STALE_S if max_stale_s is None else max_stale_s, settle_s)
    mode = np.asarray(log.mode, np.int64)
    rate = np.asarray(log.rate_dph, np.float64)
    sign = np.where(mode == 2, -1, np.where(mode == 3, 0, 1)).astype(np.int8)
    if not log.reversal:
        return Combined(rate.copy(), np.ones(len(rate), bool), sign, "ftr")
    if np.any(mode == 0):
        row = int(np.argmax(mode == 0))
        line = log.line_of(row)
        where = f"line {line}" if line is not None else f"row {row}"
        raise ValueError(f"{log.source}: {where}: mode 0 (FTR) sample in a mode-reversal log "
                         f"(a log is either all mode 0 or modes 1/2/3)")
    fs = log.sample_rate_hz if fs_hz is None else fs_hz
    seg_start = np.zeros(len(mode), np.bool_)
    seg_start[np.asarray(log.segments, np.int64)] = True
    out, valid = _combine_kernel(mode, rate, seg_start, int(round(cfg.settle_s * fs)),
                                 int(round(cfg.max_stale_s * fs)), cfg.combiner == "trend")
    return Combined(out, valid, sign, cfg.combiner)
