"""Temperature proxy normalization (golden model, float64): p -> u in [-1, 1].

The proxy p is one column of the run log:

* ``kind = "freq"``: ``freq_hz``, the drive-mode resonant frequency [Hz] (self-sensed temperature,
  paper section 3.2);
* ``kind = "temp"``: ``temp_c``, a temperature sensor [degC].

A :class:`ProxyConfig` holds ``ref`` (the centre of the operating range) and ``span`` (its
half-width, > 0; in a model file at least one LSB of the firmware's proxy word, SPAN_MIN, and a
drive frequency's ref > 0), both in proxy units (Hz or degC).  The operating range is
``[ref - span, ref + span]``.

Exact semantics, per sample i (the fixed-point reference copies them step for step):

1. ``inv_span = 1.0 / span`` is computed once (the firmware stores a precomputed reciprocal; it has
   no divider);
2. ``u_raw = (p[i] - ref) * inv_span``;
3. clamp: ``u = +1`` and ``clamped = True`` if ``u_raw > 1``; ``u = -1`` and ``clamped = True`` if
   ``u_raw < -1``; otherwise ``u = u_raw`` and ``clamped = False``.  A sample exactly on an edge
   (``u_raw == +-1``) is *not* clamped.

There is no state and no warm-up: u is defined at every sample, including mode-exchange samples
(their output is invalid anyway, see host_tools.golden.compensate).

Choosing the range:

* :meth:`ProxyConfig.from_data`: the training range ``[lo, hi]`` (min and max over all training
  samples given) widened on each side by ``margin * (hi - lo)``; ``ref`` is its centre, ``span``
  its half-width.  So the training data map into ``[-1/(1+2*margin), +1/(1+2*margin)]``.
* :meth:`ProxyConfig.from_range`: an explicit range ``LO,HI`` in proxy units (CLI
  ``--proxy-range LO,HI``, parsed by :func:`parse_range`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_ref import formats as F
from firmware_ref.vocabulary import PROXY_KINDS as KINDS
from host_tools.golden.fields import check_fields
UNITS = {"freq": "Hz", "temp": "degC"}
COLUMNS = {"freq": "freq_hz", "temp": "temp_c"}
# the smallest meaningful span: one LSB of the firmware's proxy input word (firmware_ref/FORMATS.md)
SPAN_MIN = {"freq": 2.0 ** -F.FREQ_FRAC, "temp": 2.0 ** -F.TEMP_FRAC}


@dataclass(frozen=True)
class ProxyConfig:
    """Normalization of the temperature proxy: ``u = (p - ref) / span``, clamped to [-1, 1].

    ``kind`` 'freq' (p = ``freq_hz`` [Hz]) or 'temp' (p = ``temp_c`` [degC]); ``ref`` and ``span``
    (half-width, > 0) in the same unit.
    """

    kind: str
    ref: float
    span: float

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"proxy kind must be one of {KINDS}, not {self.kind!r}")
        for name in ("ref", "span"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value):
                raise ValueError(f"proxy {name} must be a finite number, not {value!r}")
            object.__setattr__(self, name, float(value))
        if not self.span > 0:
            raise ValueError(f"proxy span must be > 0 ({UNITS[self.kind]}), not {self.span!r}")

    # -- construction --------------------------------------------------------------------------
    @classmethod
    def from_range(cls, kind: str, lo: float, hi: float) -> "ProxyConfig":
        """Explicit operating range ``[lo, hi]`` in proxy units (Hz or degC), ``hi > lo``."""
        if not (math.isfinite(lo) and math.isfinite(hi)) or not hi > lo:
            raise ValueError(f"proxy range must be LO,HI with finite LO < HI ({UNITS.get(kind, '?')}), "
                             f"not {lo!r},{hi!r}")
        return cls(kind, 0.5 * (lo + hi), 0.5 * (hi - lo))

    @classmethod
    def from_data(cls, p_arrays, kind: str, margin: float = 0.1) -> "ProxyConfig":
        """Range from training data: ``[min, max]`` over all arrays in ``p_arrays`` (proxy units),
        widened on each side by ``margin * (max - min)``.  Raises ValueError if the proxy does not
        vary (use an explicit range then)."""
        if not margin >= 0:
            raise ValueError(f"proxy margin must be >= 0, not {margin!r}")
        arrays = [np.asarray(p, np.float64).ravel() for p in p_arrays]
        arrays = [a for a in arrays if a.size]
        if not arrays:
            raise ValueError("proxy range from data: no training samples")
        lo = min(float(a.min()) for a in arrays)
        hi = max(float(a.max()) for a in arrays)
        if not hi > lo:
            raise ValueError(f"proxy range from data: the {kind} proxy is constant ({lo!r} "
                             f"{UNITS.get(kind, '')}) over the training data; give the range "
                             f"explicitly (--proxy-range LO,HI)")
        w = margin * (hi - lo)
        return cls.from_range(kind, lo - w, hi + w)

    # -- use -----------------------------------------------------------------------------------
    @property
    def unit(self) -> str:
        return UNITS[self.kind]

    @property
    def column(self) -> str:
        """Run-log column of this proxy ('freq_hz' or 'temp_c')."""
        return COLUMNS[self.kind]

    @property
    def lo(self) -> float:
        return self.ref - self.span

    @property
    def hi(self) -> float:
        return self.ref + self.span

    def normalize(self, p) -> tuple[np.ndarray, np.ndarray]:
        """``(u, clamped)``: u float64[n] in [-1, 1] and the per-sample clamp flag bool[n]."""
        p = np.asarray(p, np.float64)
        inv_span = 1.0 / self.span
        u_raw = (p - self.ref) * inv_span
        clamped = (u_raw > 1.0) | (u_raw < -1.0)
        return np.clip(u_raw, -1.0, 1.0), clamped

    def to_dict(self) -> dict:
        return {"kind": self.kind, "unit": self.unit, "ref": self.ref, "span": self.span}

    @classmethod
    def from_dict(cls, d: dict) -> "ProxyConfig":
        """Inverse of :meth:`to_dict` ('unit' is informative and checked if present; no other key;
        ``span`` at least SPAN_MIN, a drive frequency's ``ref`` > 0)."""
        for key in ("kind", "ref", "span"):    # a missing key: KeyError, the model reader names config.proxy.<key>
            if key not in d:
                raise KeyError(key)
        check_fields("proxy config", d, ("kind", "ref", "span"), ("unit",))
        cfg = cls(d["kind"], d["ref"], d["span"])
        if cfg.span < SPAN_MIN[cfg.kind]:
            raise ValueError(f"proxy span {cfg.span!r} {cfg.unit} is below one LSB of the {cfg.column} input "
                             f"word ({SPAN_MIN[cfg.kind]:g} {cfg.unit}): u would be the quantization noise of "
                             f"the proxy")
        if cfg.kind == "freq" and not cfg.ref > 0:
            raise ValueError(f"proxy ref {cfg.ref!r} Hz: a drive frequency is positive")
        if "unit" in d and d["unit"] != cfg.unit:
            raise ValueError(f"proxy unit {d['unit']!r} does not match kind {cfg.kind!r} ({cfg.unit})")
        return cfg


def parse_range(text: str, what: str = "--proxy-range") -> tuple[float, float]:
    """Parse ``'LO,HI'`` (two finite numbers, LO < HI) for ``--proxy-range``."""
    parts = [s.strip() for s in str(text).split(",")]
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"{what}: expected LO,HI (two numbers), not {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or not hi > lo:
        raise ValueError(f"{what}: expected finite LO < HI, not {text!r}")
    return lo, hi
