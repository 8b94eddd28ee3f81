"""Normalized proxy rate (golden model, float64): p -> v in [-1, 1], causal.

v is the time derivative of the temperature proxy p (``freq_hz`` [Hz] or ``temp_c`` [degC], see
host_tools.golden.proxy), normalized: ``v = (dp/dt) / span`` with ``span`` in proxy units per second
(Hz/s or degC/s) mapping to ``|v| = 1``.  Every estimator uses the NOMINAL sample period
``1/fs`` (``fs`` [Hz], stored in the config), never the log's ``t_s``: the firmware has no clock
but its sample counter and no divider.

Estimators
----------
Each estimator forms, at sample i, an integer-weighted sum ``S[i]`` of proxy values (proxy
units) and has a fixed positive integer divisor ``D`` such that ``S / D`` is the slope in proxy
units per sample; ``W`` is its warm-up length in samples:

=========  =====================================================================  ==============  =================
estimator  S[i]                                                                    D               W (warm-up)
=========  =====================================================================  ==============  =================
``diff``   ``p[i] - p[i-1]`` (paper section 4.3)                                   1               1
``diffn``  ``p[i] - p[i-n]``, n >= 1                                               n               n
``lsq``    ``sum_{j=0}^{n-1} w_j * (p[i-n+1+j] - p[i])``, ``w_j = 2*j - (n-1)``,  ``n(n^2-1)/6``  n - 1
           n >= 2 (least-squares slope over the last n samples; since
           ``sum w_j = 0`` this equals ``sum w_j p[i-n+1+j]``; the differences
           keep the fixed-point numbers small); summed in order j = 0 .. n-1
``iir``    the filter state y (below), 0 <= shift <= 24                            1               1
=========  =====================================================================  ==============  =================

``iir``: first-order recursive low-pass of the consecutive difference ``d[i] = p[i] - p[i-1]``
with coefficient ``a = 2**-shift`` once started.  At segment index k = 0 the state is ``y = 0``; at
k >= 1 ``y = y + (d[i] - y) * 2**-e`` with the *gear* ``e = min(shift, floor(log2(k)))`` (firmware:
``y += (d - y) >> e``): e = 0 at k = 1 (``y = d[i]``, so a ramp is exact at once), 1 at k = 2, 3,
2 at k = 4..7, ..., ``shift`` from k = 2**shift on.  ``S[i] = y`` after the update.

Start-up of the iir
-------------------
The gear makes the filter a running mean of the differences while it has fewer than 2**shift of
them (with coefficient 1/k exactly it would be ``(p[i] - p[start]) / k``; the power-of-two gear
gives the newest difference at most twice the running mean's weight 1/k, and needs no divider),
then the fixed low-pass: its
output is usable from k = 1 (W = 1).  Before, the filter ran at 2**-shift from k = 2 and its output
was blanked for W = 2**(shift+1) samples (1024 at the default shift 9: the first valid compensated
output of a mode-reversal start-up came at t = 1085 s).  A model written then carries
``"warmup": 2**(shift+1)`` in its rate config; :meth:`RateConfig.from_dict` reads it with the gear
(same coefficients; the samples that were blanked are now served).  A fixed-point table of layout
version < 3 with the iir was quantized for the blanked start-up and is refused (firmware_ref.table).

Chosen by measurement, held out (model from `hdrg fit` defaults on one run, applied to another run
from its power-on; medians; stability = std of the 100-s means, host_tools.fitting.metrics, over the
valid samples from 180 s; "late": from 1085 s, where the old output began):

=====================================  ===========  ===========  ===========  ==========  ===========
runs (held out)                        first valid  valid share  stability    stability   mode
                                       [s]          from 180 s   from 180 s   late        reversal
                                                                 [deg/h]      [deg/h]     alone
=====================================  ===========  ===========  ===========  ==========  ===========
paper start-up, blanked (before)       1085         62 %         0.057        0.057       0.40
paper start-up, gear                   185          96 %         0.406        0.065       0.40
foreign family, blanked (before)       1085         90 %         0.243        0.243       4.08
foreign family, gear                   185          96 %         0.221        0.226       4.08
=====================================  ===========  ===========  ===========  ==========  ===========

Paper start-up: ``hdrg simulate --scenario paper-mr-cycle-4dpm --seed S -o train.csv`` (S = 1, 2),
``hdrg fit train.csv -o m.json``, ``hdrg simulate --scenario paper-startup-mr --seed R -o s.csv``
(R = 11, 12, 13: 45 min at constant ambient), ``hdrg compensate s.csv --model m.json -o out.csv``,
``hdrg metrics out.csv`` (stability at 100 s; every valid sample is past 180 s), 6 pairs.
Foreign family (host_tools.simulation.sim_foreign): devices D = 0..7, ``hdrg simulate --family
random --seed D --chamber-rate 4 --reversal on --power-on 0 --noise-seed 1 -o train.csv``, held
out ``--chamber-rate 2 --power-on 1 --noise-seed 2``, the same fit / compensate / metrics.  The
valid share counts the mode 1/2 samples from 180 s.  On the paper's start-up the served minutes
between 185 s and 1085 s carry the turn-on transient, which no thermometer sees (mode reversal
alone has 0.40 deg/h there too): serving them is the point, the error there is the turn-on's; its
model is a separate term.  The late stability is 15 % higher with the gear on the paper's runs
(the fit now also uses the training run's first 1024 s, which hold its own turn-on) and 7 % lower
on the foreign family.

The first valid output is now the mode-reversal combiner's (the first settled sample with a window
of each mode: 180 s of exchange / dwell / exchange + 5 s of settling), no longer the rate
estimator's.  The other ways to start (a gear one step slower or faster, e = floor(log2 k) -+ 1;
the gear with a 64-sample warm-up) changed every stability above by less than 3 % on the same runs
(the rate term is small next to the turn-on): the plain running-mean start (e = floor(log2 k), W =
1) is the simplest and serves from the first difference.  A state seeded from a longer first
difference, or another estimator during start-up, were not built: they need a window of history or
a second sum in the firmware, and the variants above show that the start-up rate estimate is not
what sets the start-up error.

Per-sample semantics (exactly; the fixed-point reference copies them):

* ``k`` counts the samples since the last restart: k = 0 at sample 0 and at every *restart*
  sample (the start of each gap-free segment, ``RunLog.segments``), where all state is reset
  exactly as at power-on; k then increases by 1 per sample (the firmware saturates it at
  max(W, 2**shift) for the iir, at W otherwise: firmware_ref.rate).
  Past samples are only read within the current segment (``i - m >= segment start``).
* ``gain = fs / (D * span)`` is computed once (float64, that expression);
* if ``k < W`` (warm-up): ``v = 0.0``, ``warmup = True``, ``clamped = False`` (the iir state is
  still updated);
* else ``v_raw = S[i] * gain``; ``v = +1`` and ``clamped = True`` if ``v_raw > 1``; ``v = -1`` and
  ``clamped = True`` if ``v_raw < -1``; else ``v = v_raw``.  ``v_raw == +-1`` is not clamped.

Choosing ``span``: :meth:`RateConfig.from_data` takes the ``percentile`` (default 99.9) of
``|dp/dt|`` from the estimator itself over the training samples past warm-up, times
``1 + margin`` (default 0.1); or explicit (CLI ``--rate-range S``: ``|dp/dt| <= S`` proxy
units/s, parsed by :func:`parse_rate_range`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from firmware_ref.vocabulary import ESTIMATORS
from host_tools.golden.fields import check_fields
_CODE = {name: i for i, name in enumerate(ESTIMATORS)}
MAX_SHIFT = 24
IIR_WARMUP = 1   # W of the iir: only k = 0 (no difference yet); see "Start-up of the iir"
RATE_UNITS = {"freq": "Hz/s", "temp": "degC/s"}


@dataclass(frozen=True)
class RateConfig:
    """Rate estimator settings: ``estimator`` (one of ESTIMATORS), ``n`` (window for 'diffn'
    (>= 1) and 'lsq' (>= 2); ignored otherwise), ``shift`` (iir coefficient 2**-shift, 0..24;
    ignored otherwise), ``span`` [proxy units/s] (> 0; |dp/dt| = span maps to |v| = 1), ``fs``
    [Hz] nominal sample rate (> 0)."""

    estimator: str = "diff"
    n: int = 8
    shift: int = 4
    span: float = 1.0
    fs: float = 1.0

    def __post_init__(self):
        if self.estimator not in ESTIMATORS:
            raise ValueError(f"rate estimator must be one of {ESTIMATORS}, not {self.estimator!r}")
        for name in ("n", "shift"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"rate {name} must be an integer, not {value!r}")
            object.__setattr__(self, name, int(value))
        if self.estimator == "diffn" and self.n < 1:
            raise ValueError(f"rate n must be >= 1 for 'diffn', not {self.n}")
        if self.estimator == "lsq" and self.n < 2:
            raise ValueError(f"rate n must be >= 2 for 'lsq', not {self.n}")
        if not 0 <= self.shift <= MAX_SHIFT:
            raise ValueError(f"rate shift must be in 0..{MAX_SHIFT}, not {self.shift}")
        for name in ("span", "fs"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value) \
                    or not value > 0:
                raise ValueError(f"rate {name} must be a finite number > 0, not {value!r}")
            object.__setattr__(self, name, float(value))

    # -- the estimator's constants ---------------------------------------------------------------
    @property
    def divisor(self) -> int:
        """D: S / D is the slope in proxy units per sample."""
        if self.estimator == "diffn":
            return self.n
        if self.estimator == "lsq":
            return self.n * (self.n * self.n - 1) // 6
        return 1

    @property
    def warmup(self) -> int:
        """W: samples after each (re)start with ``v = 0`` and ``warmup = True``."""
        return warmup_length(self.estimator, self.n, self.shift)

    @property
    def gain(self) -> float:
        """``fs / (D * span)``: v_raw = S * gain."""
        return self.fs / (self.divisor * self.span)

    # -- evaluation ------------------------------------------------------------------------------
    def slope(self, p, restarts=None) -> tuple[np.ndarray, np.ndarray]:
        """``(dpdt, warmup)``: the estimator's dp/dt [proxy units/s] (0 during warm-up) and the
        warm-up flag, bool[n].  ``restarts``: segment start indices (default: only sample 0)."""
        p = np.ascontiguousarray(p, np.float64)
        s, warm = _rate_kernel(p, restart_mask(len(p), restarts), _CODE[self.estimator], self.n,
                               self.shift, self.warmup)
        return s * (self.fs / self.divisor), warm

    def normalize(self, p, restarts=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(v, clamped, warmup)`` per sample (see the module doc): v float64[n] in [-1, 1]."""
        p = np.ascontiguousarray(p, np.float64)
        s, warm = _rate_kernel(p, restart_mask(len(p), restarts), _CODE[self.estimator], self.n,
                               self.shift, self.warmup)
        v_raw = s * self.gain  # s == 0 in warm-up
        clamped = (v_raw > 1.0) | (v_raw < -1.0)
        return np.clip(v_raw, -1.0, 1.0), clamped, warm

    # -- construction / serialization ----------------------------------------------------------
    @classmethod
    def from_data(cls, p_arrays, fs: float, estimator: str = "diff", n: int = 8, shift: int = 4,
                  restarts=None, percentile: float = 99.9, margin: float = 0.1,
                  masks=None) -> "RateConfig":
        """``span`` from training data: the ``percentile`` of |dp/dt| (this estimator, proxy
        units/s) over all samples past warm-up, times ``1 + margin``.  ``restarts``: one array of
        segment starts per array of ``p_arrays`` (None: one segment each); ``masks``: optional
        bool arrays of samples to use (e.g. excluding mode-exchange samples)."""
        if not 0 < percentile <= 100 or not margin >= 0:
            raise ValueError(f"rate span from data: need 0 < percentile <= 100 and margin >= 0, "
                             f"not {percentile!r}, {margin!r}")
        probe = cls(estimator, n, shift, 1.0, fs)
        p_arrays = list(p_arrays)
        restarts = [None] * len(p_arrays) if restarts is None else list(restarts)
        masks = [None] * len(p_arrays) if masks is None else list(masks)
        rates = []
        for p, r, m in zip(p_arrays, restarts, masks):
            dpdt, warm = probe.slope(p, r)
            use = ~warm if m is None else (~warm & np.asarray(m, bool))
            rates.append(np.abs(dpdt[use]))
        rates = np.concatenate(rates) if rates else np.zeros(0)
        if rates.size == 0:
            raise ValueError(f"rate span from data: no training sample past the '{estimator}' "
                             f"warm-up ({probe.warmup} samples)")
        q = float(np.percentile(rates, percentile))
        if not q > 0:
            raise ValueError(f"rate span from data: the {percentile} percentile of |dp/dt| is 0 "
                             f"(proxy constant over the training data); give the range explicitly "
                             f"(--rate-range S)")
        return cls(estimator, n, shift, q * (1.0 + margin), fs)

    def to_dict(self) -> dict:
        return {"estimator": self.estimator, "n": self.n, "shift": self.shift, "span": self.span,
                "fs": self.fs, "divisor": self.divisor, "warmup": self.warmup}

    @classmethod
    def from_dict(cls, d: dict) -> "RateConfig":
        """Inverse of :meth:`to_dict`; 'divisor' and 'warmup' are derived and checked if present.  A
        missing or unknown key is an error naming it (a hand-edited model must not fall back to a
        default estimator constant behind the user's back)."""
        check_fields("rate config", d, ("estimator", "n", "shift", "span", "fs"), ("divisor", "warmup"))
        cfg = cls(d["estimator"], d["n"], d["shift"], d["span"], d["fs"])
        for name in ("divisor", "warmup"):
            if name == "warmup" and cfg.estimator == "iir" and d.get(name) == legacy_iir_warmup(cfg.shift):
                continue   # a model written before the iir's start-up gear: read with the gear (module doc)
            if name in d and d[name] != getattr(cfg, name):
                raise ValueError(f"rate {name} {d[name]!r} does not match the estimator settings "
                                 f"(expected {getattr(cfg, name)})")
        return cfg


def warmup_length(estimator: str, n: int, shift: int) -> int:
    """Warm-up length W [samples] of an estimator (see the module table)."""
    if estimator == "diff":
        return 1
    if estimator == "diffn":
        return n
    if estimator == "lsq":
        return n - 1
    if estimator == "iir":
        return IIR_WARMUP
    raise ValueError(f"rate estimator must be one of {ESTIMATORS}, not {estimator!r}")


def legacy_iir_warmup(shift: int) -> int:
    """The iir's warm-up before its start-up gear, ``2**(shift + 1)``: the 'warmup' a model written
    then carries (accepted on read, see "Start-up of the iir")."""
    return 2 ** (shift + 1)


def restart_mask(n: int, restarts=None) -> np.ndarray:
    """bool[n], True at sample 0 and at every index in ``restarts`` (segment starts)."""
    mask = np.zeros(n, np.bool_)
    if n:
        mask[0] = True
    if restarts is not None:
        idx = np.asarray(restarts, np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= max(n, 1)):
            raise ValueError(f"restart index out of range 0..{n - 1}: {idx.min()}..{idx.max()}")
        mask[idx] = True
    return mask


def parse_rate_range(text: str, what: str = "--rate-range") -> float:
    """Parse ``'S'`` (a finite number > 0, proxy units per second) for ``--rate-range``."""
    try:
        value = float(str(text).strip())
    except ValueError:
        raise ValueError(f"{what}: expected S, the largest |dp/dt| in proxy units/s, not {text!r}") from None
    if not math.isfinite(value) or not value > 0:
        raise ValueError(f"{what}: expected a finite S > 0, not {text!r}")
    return value


@numba.njit(cache=True)
def _rate_kernel(p, restart, code, n, shift, warm_len):
    """S[i] (0 during warm-up) and warm-up flags; see the module doc.  code: 0 diff, 1 diffn,
    2 lsq, 3 iir."""
    size = p.shape[0]
    out = np.zeros(size)
    warm = np.ones(size, np.bool_)
    if code == 0:
        n = 1
    k = 0
    y = 0.0
    for i in range(size):
        if restart[i] or i == 0:
            k = 0
            y = 0.0
        s = 0.0
        if code <= 1:
            if k >= n:
                s = p[i] - p[i - n]
        elif code == 2:
            if k >= n - 1:
                for j in range(n):
                    s += (2 * j - (n - 1)) * (p[i - n + 1 + j] - p[i])
        else:
            if k >= 1:
                e = shift                            # the gear: min(shift, floor(log2 k))
                if k < (1 << shift):
                    e = 0
                    kk = k
                    while kk >= 2:
                        kk >>= 1
                        e += 1
                y = y + ((p[i] - p[i - 1]) - y) * 2.0 ** -e
            s = y
        if k >= warm_len:
            out[i] = s
            warm[i] = False
        k += 1
    return out, warm
