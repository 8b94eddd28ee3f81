"""Mode-reversal combination (golden model, float64): the bias-cancelled output of eq. (5), causal,
in two orders: **regress_first** (default for new models: subtract the model's bias per mode, then
pair the *residuals*) and **combine_first** (legacy: pair the raw outputs, then subtract one bias).

Input per sample i: ``mode[i]`` (0 FTR, 1, 2, 3 exchange) and ``rate[i]``, the raw loop output in
deg/h with the run-log sign convention: in mode 2 the true rate and the non-reversing bias flip
sign, the damping-asymmetry term does not.  So the *rate-corrected* sample

    c[i] = s[i] * rate[i],    s = +1 in mode 1, -1 in mode 2

equals  Omega + B_E + s * B_D:  averaging a mode-1 and a mode-2 value cancels B_D (eq. 5).

A log is either FTR (every sample mode 0: output = rate, always valid, s = +1) or mode reversal
(modes 1, 2, 3 only; a mix with mode 0 is an error).

Orders (``ReversalConfig.order``; docs/REGRESS_THEN_REVERSE.md):

* ``"combine_first"`` (legacy, model files of version 1): the value combined at sample i is
  x[i] = c[i]; the combined output minus one bias bank B(u, v, z) is the compensated output
  (host_tools.golden.compensate).  Combiners ``pair`` and ``trend``.
* ``"regress_first"``: the model has two coefficient banks, bank 1 for mode-1 samples and bank 2
  for mode-2 samples (a joint fit of common(u,v,z) + s * damping(u,v,z): bank1 = common + damping,
  bank2 = common - damping).  The value combined is the *residual*
  x[i] = r[i] = c[i] - B_m[i](u[i], v[i], z[i]); the combiner's output is the compensated output
  (no bias is subtracted after).  Combiners ``none`` (out = r: joint regression alone), ``pair``
  and ``trend`` (the paper's pairing / ours, applied to the residual: they cancel what the
  regression leaves of the damping term, e.g. its non-repeatable change at power-on, without the
  stale-window error of combine_first, because the residual varies slowly).  Why: combine_first
  estimates the other mode's output at the present sample from a window up to one period old;
  where temperature curves, the damping term changes non-linearly between the windows, and that
  error is no function of (u, v, z), so no regression after the pairing removes it.

Exact semantics (the fixed-point sequencer in firmware_ref copies them), with x[i] the value
combined (c for combine_first, r for regress_first):

* **Used samples.**  Sample i is *used* when mode[i] in {1, 2}, it is past its window's settling
  (``pos >= settle_n``, see Windows) and ``ok[i]``: for regress_first ``ok`` = the rate estimator
  is warm (not in warm-up, host_tools.golden.rate); for combine_first ``ok`` is always true (there the
  warm-up only invalidates the final output, host_tools.golden.compensate).  Only used samples enter the
  window sums and only used samples can be valid.
* **Windows.** A window is a maximal run of consecutive samples of one mode m in {1, 2}; ``pos``
  counts the samples of the open window from 0.  The first ``settle_n = round(settle_s * fs)``
  samples of every window are *settling*.  Every used sample adds x[i] to the open window's sum
  and count.  When the mode changes (to 3 or to the other mode), the open window is *committed*
  if its count >= 1: ``W[m] = sum / count`` (the mean of x over the used samples), ``centre[m]`` =
  mean of the first and last used sample index, ``end[m]`` = the last used index.
* **Segments (time gaps).** At the start of every gap-free segment (``RunLog.segments``) the state
  is reset as at power-on: the open window is discarded and no committed window remains.
* **Output** at a used sample i of mode m, with o the other mode:

  - ``"none"`` (regress_first only): out = x[i], valid.
  - ``"pair"`` (the paper, section 3.4/4.4):   out = (x[i] + W[o]) / 2
  - ``"trend"`` (ours):  out = (x[i] + W[o] + slope[o] * (i - centre[o])) / 2, where
    ``slope[o] = (W[o] - W_prev[o]) / (centre[o] - centre_prev[o])`` [deg/h per sample] is the
    change between the last two committed windows of mode o (0 until o has two committed windows
    in this segment).  It extrapolates the other mode's value linearly to the present sample, so
    the first-order effect of the temperature change between the two modes' windows (eq. 6)
    cancels too; on a static run it equals "pair" plus the noise of the slope.

  For pair and trend the output is valid when o has a committed window and ``i - end[o] <=
  max_stale_n`` (``max_stale_n = round(max_stale_s * fs)``; default 300 s, the paper's period:
  the other mode's estimate may be at most one reversal period old).  Both are valid from the
  first sample of the first mode-2 window after a complete mode-1 window (180 s after power-on in
  the paper's timing, as the paper says).
* **Input-invalid samples** (``bad[i]``, host_tools.golden.input_check: an input outside what the
  sensor can report).  A bad sample is never used (it enters no window sum and is not valid); a
  bad sample in a mode-1/2 window *taints* that window (at any position, settling included): a
  tainted window is not committed when it closes, so no pairing or trend ever uses it and the
  other mode keeps pairing with the last clean window of this mode (subject to max_stale_n, as
  ever) until a clean window replaces it.  A bad sample in an exchange taints nothing.  (The rate
  estimator's side: host_tools.golden.compensate restarts it at a bad sample and the one after.)
* **Invalid samples** (exchange, settling, not ok, bad, before the first pair, stale) output the
  last valid output (0.0 before the first one) with ``valid = False``.  They never enter a fit or a
  statistic.

Note: the rate-corrected output also averages the *true rate* of the present sample with that of
the other window, so a rotation that changes between windows is seen at half amplitude: like the
paper, this is a method for bias, on a static or slowly turning gyroscope (combiner ``none``
passes the present rate through).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from firmware_ref.vocabulary import ORDERS, REVERSAL_COMBINERS as COMBINERS
from host_tools.golden.fields import check_fields
DEFAULT_MAX_STALE_S = 300.0
# the defaults of new models (host_tools.golden.compensate.fit_config_from_logs, the CLI of hdrg fit / diagnose)
# and of the raw-log combination of hdrg metrics: chosen on the foreign benchmark (docs/REGRESS_THEN_REVERSE.md)
DEFAULT_ORDER = "regress_first"
DEFAULT_COMBINER = "pair"
DEFAULT_SETTLE_S = 5.0   # settling time excluded after each exchange [s] of new regress_first + pair models (fit_config_from_logs)
_KIND = {"pair": 0, "trend": 1, "none": 2}


@dataclass
class ReversalConfig:
    """Combination settings stored with a model: combiner name, staleness limit [s], settling time
    [s], order ('regress_first': per-mode bias banks, residuals combined; 'combine_first': legacy).
    An unspecified order (the dataclass default, or a dict without "order" such as a model file of
    version 1) is 'combine_first', so code written before the order existed keeps its meaning; new
    models get their order from host_tools.golden.compensate.fit_config_from_logs (default
    regress_first)."""

    combiner: str = "pair"
    max_stale_s: float = DEFAULT_MAX_STALE_S
    settle_s: float = 0.0
    order: str = "combine_first"

    def __post_init__(self):
        if self.combiner not in COMBINERS:
            raise ValueError(f"reversal combiner must be one of {COMBINERS}, not {self.combiner!r}")
        if self.order not in ORDERS:
            raise ValueError(f"reversal order must be one of {ORDERS}, not {self.order!r}")
        if self.combiner == "none" and self.order != "regress_first":
            raise ValueError("reversal combiner 'none' needs order 'regress_first' (with combine_first "
                             "nothing would cancel the damping term)")
        if not self.max_stale_s > 0:
            raise ValueError(f"reversal max_stale_s must be > 0, not {self.max_stale_s}")
        if not self.settle_s >= 0:
            raise ValueError(f"reversal settle_s must be >= 0, not {self.settle_s}")

    def to_dict(self) -> dict:
        return {"combiner": self.combiner, "max_stale_s": self.max_stale_s, "settle_s": self.settle_s,
                "order": self.order}

    @classmethod
    def from_dict(cls, d: dict) -> "ReversalConfig":
        """Inverse of :meth:`to_dict`.  'order' may be absent (models written before it existed:
        combine_first); any other missing or unknown key is an error naming it (a hand-edited model
        must not fall back to a default settling window or staleness limit)."""
        check_fields("reversal config", d, ("combiner", "max_stale_s", "settle_s"), ("order",))
        return cls(d["combiner"], d["max_stale_s"], d["settle_s"], d.get("order", "combine_first"))


@dataclass
class Combined:
    """Output of :func:`combine`: ``out_dph`` float64[n] [deg/h], ``valid`` bool[n], ``sign`` int8[n]
    (+1 mode 0/1, -1 mode 2, 0 exchange), the combiner used."""

    out_dph: np.ndarray
    valid: np.ndarray
    sign: np.ndarray
    combiner: str


@numba.njit(cache=True)
def _combine_kernel(mode, x, ok, bad, seg_start, settle_n, max_stale_n, kind):
    """The combiner of the module doc on values x (c or r), kind 0 pair, 1 trend, 2 none; ``bad``:
    the input-invalid samples (never used; they taint their window).
    Returns (out, valid, used, age): age[i] = i - end of the other mode's latest committed window
    [samples] at a used sample of pair/trend once that mode has one, else -1."""
    n = mode.shape[0]
    out = np.zeros(n)
    valid = np.zeros(n, np.bool_)
    used = np.zeros(n, np.bool_)
    age = np.full(n, -1, np.int64)
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
    taint = False
    for i in range(n):
        m = mode[i]
        if seg_start[i]:
            cur = 0
            acc = 0.0
            cnt = 0
            pos = 0
            taint = False
            for k in range(3):
                ncommit[k] = 0
                slope[k] = 0.0
        if m != cur:
            if cur != 0 and cnt >= 1 and not taint:
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
            taint = False
        if cur != 0:
            if bad[i]:
                taint = True
            if pos >= settle_n and ok[i] and not bad[i]:
                c = x[i]
                used[i] = True
                if cnt == 0:
                    first = i
                last = i
                acc += c
                cnt += 1
                o = 3 - cur
                if kind == 2:
                    hold = c
                    valid[i] = True
                elif ncommit[o] >= 1 and i - end[o] <= max_stale_n:
                    age[i] = i - end[o]
                    other = W[o]
                    if kind == 1:
                        other += slope[o] * (i - centre[o])
                    hold = 0.5 * (c + other)
                    valid[i] = True
                elif ncommit[o] >= 1:
                    age[i] = i - end[o]
            pos += 1
        out[i] = hold
    return out, valid, used, age


def sign_of(mode) -> np.ndarray:
    """s per sample, int8: +1 mode 0/1, -1 mode 2, 0 exchange (mode 3)."""
    mode = np.asarray(mode)
    return np.where(mode == 2, -1, np.where(mode == 3, 0, 1)).astype(np.int8)


def check_modes(log) -> None:
    """Refuse a mode-reversal log (some mode != 0) that also holds mode-0 (FTR) samples."""
    mode = np.asarray(log.mode)
    if log.reversal and np.any(mode == 0):
        row = int(np.argmax(mode == 0))
        line = log.line_of(row)
        where = f"line {line}" if line is not None else f"row {row}"
        raise ValueError(f"{log.source}: {where}: mode 0 (FTR) sample in a mode-reversal log "
                         f"(a log is either all mode 0 or modes 1/2/3)")


def combine_values(mode, x, ok, segments, cfg: ReversalConfig, fs_hz: float, bad=None):
    """The combiner of the module doc on per-sample values ``x`` [deg/h] (c for combine_first, the
    residual r = c - B_mode for regress_first), with ``ok`` bool[n] (regress_first: rate estimator
    warm), ``segments`` the segment start indices (RunLog.segments), ``bad`` bool[n] the
    input-invalid samples (None: none).  Returns (out float64[n], valid bool[n], used bool[n])."""
    return _combine_all(mode, x, ok, segments, cfg, fs_hz, bad)[:3]


def window_ages(mode, ok, segments, cfg: ReversalConfig, fs_hz: float, bad=None) -> np.ndarray:
    """Per sample, the age [samples] of the other mode's latest committed window where the pair or
    trend combiner of ``cfg`` uses a sample and that mode has a window (-1 elsewhere, and
    everywhere for 'none'): the sample is stale by age exactly where age > round(max_stale_s x
    fs).  ``ok``, ``bad`` as in :func:`combine_values`."""
    return _combine_all(mode, np.zeros(len(mode)), ok, segments, cfg, fs_hz, bad)[3]


def _combine_all(mode, x, ok, segments, cfg: ReversalConfig, fs_hz: float, bad=None):
    mode = np.ascontiguousarray(mode, np.int64)
    x = np.ascontiguousarray(x, np.float64)
    ok = np.ascontiguousarray(ok, np.bool_)
    bad = np.zeros(len(mode), np.bool_) if bad is None else np.ascontiguousarray(bad, np.bool_)
    if not (len(x) == len(mode) == len(ok) == len(bad)):
        raise ValueError(f"combine_values: mode, x, ok and bad differ in length ({len(mode)}, {len(x)}, {len(ok)}, "
                         f"{len(bad)})")
    seg_start = np.zeros(len(mode), np.bool_)
    seg_start[np.asarray(segments, np.int64)] = True
    return _combine_kernel(mode, x, ok, bad, seg_start, int(round(cfg.settle_s * fs_hz)),
                           int(round(cfg.max_stale_s * fs_hz)), _KIND[cfg.combiner])


def schedule_ages_s(mode, segments, fs_hz: float, with_modes: bool = False):
    """The window ages a log's mode schedule needs [s], one per mode-1/2 window that follows a window
    of the other mode in its segment: (its last sample - the last sample of the other mode's latest
    window) / ``fs_hz``, the age the pair/trend combiner's other-mode estimate reaches at the end of
    the window (:func:`window_ages` with no settling and every sample usable, at each window's last
    sample).  Every sample of such a window can be valid only when max_stale_s >= its age (the
    paper's 30 s exchange / 120 s dwell: 150 s).  ``segments``: RunLog.segments (ages restart).
    ``with_modes``: also return the mode (1 or 2) of each window, int64."""
    mode = np.asarray(mode, np.int64)
    n = len(mode)
    age = window_ages(mode, np.ones(n, np.bool_), segments, ReversalConfig("pair", DEFAULT_MAX_STALE_S, 0.0), fs_hz)
    last = np.ones(n, bool)                     # a window's last sample: the next one is another mode or a segment
    last[:-1] = mode[1:] != mode[:-1]
    last[np.asarray(segments, np.int64)[1:] - 1] = True
    ends = np.flatnonzero(last & (age >= 0))
    ages = age[ends] / fs_hz
    return (ages, mode[ends]) if with_modes else ages


def max_stale_for(logs, fs_hz: float) -> float:
    """The default max_stale_s for mode-reversal training ``logs`` [s]: DEFAULT_MAX_STALE_S, or 1.1 x
    the window age of their schedules rounded up to 10 s when that is longer (a dwell far above the
    paper's 120 s).  The age: the larger of the two modes' median ages (:func:`schedule_ages_s`,
    by the mode of the window), so that a schedule with a long mode-2 dwell and a short mode-1 one
    gets the long one's, and a single stalled window does not set it; such a window still goes
    stale, and hdrg compensate says so (metadata ``stale_by_age``)."""
    per_mode = {1: [], 2: []}
    for log in logs:
        ages, modes = schedule_ages_s(log.mode, log.segments, fs_hz, with_modes=True)
        for m in (1, 2):
            per_mode[m].extend(ages[modes == m].tolist())
    medians = [float(np.median(a)) for a in per_mode.values() if a]
    if not medians:
        return DEFAULT_MAX_STALE_S
    return max(DEFAULT_MAX_STALE_S, 10.0 * math.ceil(round(1.1 * max(medians), 6) / 10.0))


def combine(log, combiner: str = "pair", max_stale_s: float | None = None, settle_s: float = 0.0,
            fs_hz: float | None = None, bad=None) -> Combined:
    """Combine a run log's raw output into the bias-cancelled output, combine_first (legacy) order:
    x = c (see the module doc).  ``log`` is a :class:`host_tools.golden.runlog.RunLog`.  ``fs_hz``
    defaults to the log's sample rate.  ``bad``: the input-invalid samples (bool[n],
    host_tools.golden.input_check.input_flags; None: none); FTR: they are not valid."""
    cfg = ReversalConfig(combiner, DEFAULT_MAX_STALE_S if max_stale_s is None else max_stale_s, settle_s,
                         order="combine_first")
    mode = np.asarray(log.mode, np.int64)
    rate = np.asarray(log.rate_dph, np.float64)
    sign = sign_of(mode)
    if not log.reversal:
        return Combined(rate.copy(), np.ones(len(rate), bool) if bad is None else ~np.asarray(bad, bool), sign, "ftr")
    check_modes(log)
    fs = log.sample_rate_hz if fs_hz is None else fs_hz
    out, valid, _ = combine_values(mode, sign * rate, np.ones(len(mode), np.bool_), log.segments, cfg, fs, bad)
    return Combined(out, valid, sign, cfg.combiner)
