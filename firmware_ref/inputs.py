"""Input words: float <-> integer conversion with round-half-up and saturation (host side).

The firmware receives integer words; the host converts run-log floats to them (and outputs back):

* drive frequency ``freq_hz`` -> F, uint32, LSB 2^-18 Hz, saturated to [0, 2^32 - 1];
* temperature ``temp_c`` -> T, int32, LSB 2^-16 degC, symmetric saturation +-(2^31 - 1);
* raw rate ``rate_dph`` -> R, int32, LSB 2^-10 deg/h, symmetric saturation;
* aux regressor z -> Z, int32 Q1.30 (the external word of aux_gen 0; the evaluator clamps it);
* an aux_* column -> A_c, int32, LSB 2^-AF_c of the column's unit (AF_c from the table);
* output words OUT, BIAS (int32, LSB 2^-10 deg/h) -> deg/h.

Rounding is round half up, exact for every float: ``w = floor(x 2^frac) + (frac part >= 1/2)``
(``x 2^frac`` is exact, a power-of-two scaling).  NaN is refused.  The ``*_words`` functions are
numpy-vectorized and return ``(words int64[n], saturated bool[n])``; :func:`word_of` is the scalar
Python-integer form (the specification, used by the tests).
"""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from firmware_ref import formats as F


def word_of(x: float, frac: int, signed: bool = True, width: int = 32) -> tuple[int, bool]:
    """Scalar spec: round-half-up ``x * 2**frac`` to an integer, then saturate (symmetric for
    signed words, [0, 2^w - 1] unsigned).  Returns (word, saturated)."""
    if isinstance(x, float) and math.isnan(x):
        raise ValueError("NaN cannot be converted to a fixed-point word")
    if isinstance(x, float) and math.isinf(x):
        w = 1 << 80 if x > 0 else -(1 << 80)
    else:
        w = math.floor(Fraction(x) * (1 << frac) + Fraction(1, 2))
    lim_lo, lim_hi = (-((1 << (width - 1)) - 1), (1 << (width - 1)) - 1) if signed else (0, (1 << width) - 1)
    if w > lim_hi:
        return lim_hi, True
    if w < lim_lo:
        return lim_lo, True
    return w, False


def to_words(x, frac: int, signed: bool = True, width: int = 32, what: str = "value") -> tuple[np.ndarray, np.ndarray]:
    """Vectorized :func:`word_of`: (int64 words, saturated flags)."""
    x = np.asarray(x, np.float64)
    if np.isnan(x).any():
        raise ValueError(f"{what}: NaN cannot be converted to a fixed-point word (row {int(np.argmax(np.isnan(x)))})")
    lo, hi = ((-((1 << (width - 1)) - 1), (1 << (width - 1)) - 1) if signed else (0, (1 << width) - 1))
    y = x * float(1 << frac)                       # exact (power of two), may be inf
    big = np.abs(y) >= 2.0 ** 52                   # already an integer, far outside any word
    ys = np.where(big, 0.0, y)
    fl = np.floor(ys)
    w = fl + ((ys - fl) >= 0.5)                    # ys - fl is exact
    sat_hi = big & (y > 0) | (w > hi)
    sat_lo = big & (y < 0) | (w < lo)
    out = np.clip(np.where(big, 0.0, w), lo, hi).astype(np.int64)
    out[sat_hi] = hi
    out[sat_lo] = lo
    return out, sat_hi | sat_lo


def freq_words(freq_hz):
    """Drive frequency [Hz] -> F (uint32, LSB 2^-18 Hz)."""
    return to_words(freq_hz, F.FREQ_FRAC, signed=False, what="freq_hz")


def temp_words(temp_c):
    """Temperature [degC] -> T (int32, LSB 2^-16 degC)."""
    return to_words(temp_c, F.TEMP_FRAC, what="temp_c")


def rate_words(rate_dph):
    """Raw rate [deg/h] -> R (int32, LSB 2^-10 deg/h)."""
    return to_words(rate_dph, F.RATE_FRAC, what="rate_dph")


def aux_words(z):
    """Aux regressor (dimensionless) -> Z (int32, Q1.30; the evaluator clamps to [-1, 1])."""
    return to_words(z, F.Q, what="z")


def proxy_words(p, kind: str):
    """Proxy column -> P: 'freq' F words, 'temp' T words."""
    if kind == "freq":
        return freq_words(p)
    if kind == "temp":
        return temp_words(p)
    raise ValueError(f"proxy kind must be 'freq' or 'temp', not {kind!r}")


def proxy_frac(kind: str) -> int:
    return F.FREQ_FRAC if kind == "freq" else F.TEMP_FRAC


def from_words(words, frac: int) -> np.ndarray:
    """Words -> float64 (exact: words * 2^-frac)."""
    return np.asarray(words, np.int64).astype(np.float64) * 2.0 ** -frac


def out_dph(words) -> np.ndarray:
    """OUT / BIAS words -> deg/h."""
    return from_words(words, F.OUT_FRAC)


def aux_channel_words(x, frac: int, what: str = "aux channel"):
    """An aux_* column -> A_c words (int32, LSB 2^-frac of the column's unit, frac = AF_c of the
    table, 0..formats.AUX_FRAC_MAX)."""
    if not 0 <= frac <= F.AUX_FRAC_MAX:
        raise ValueError(f"{what}: fractional bits {frac} not in 0..{F.AUX_FRAC_MAX}")
    return to_words(x, frac, what=what)
