"""Test vectors for the fixed-point implementations (Python reference, numba kernel, C twin):
models with chosen or random configurations and coefficients, and input word streams that hit
rounding ties, clamps, saturations, restarts, settling and staleness.

All generators are deterministic for a ``numpy.random.Generator``.
"""
from __future__ import annotations

import numpy as np

from firmware_ref import formats as F
from firmware_ref.terms import N_TERMS


def make_model(kind: str = "freq", ref: float = 6227.0, span: float = 3.0, estimator: str = "diff",
               n: int = 8, shift: int = 4, rate_span: float = 0.003, fs: float = 1.0,
               combiner: str | None = "pair", settle_s: float = 0.0, max_stale_s: float = 300.0,
               coef=None, terms=None):
    """A BiasModel from explicit settings (combiner None: FTR).  ``coef``: 17 values (default:
    a smooth model of a few deg/h)."""
    from host_tools.model import BiasModel, ModelConfig
    from host_tools.proxy import ProxyConfig
    from host_tools.rate import RateConfig
    from host_tools.reversal import ReversalConfig

    if coef is None:
        coef = [1.5, -4.0, 0.3, 1.1, -1.2, -0.2, 0.9, 0.0, 0.05, 1.8, -0.1, 1.9, 0.7, 0.7, -0.02, -1.1, 0.9]
    coef = np.asarray(coef, np.float64)
    if terms is None:
        terms = tuple(k for k in range(N_TERMS) if coef[k] != 0.0)
    rev = None if combiner is None else ReversalConfig(combiner, max_stale_s, settle_s)
    cfg = ModelConfig(ProxyConfig(kind, ref, span), RateConfig(estimator, n, shift, rate_span, fs), rev)
    return BiasModel(cfg, terms, coef, source="<vectors>")


def random_coef(rng: np.random.Generator, with_k7: bool = True, spread: float = 6.0, scale: float = 10.0):
    """17 coefficients with random signs and log-uniform magnitudes over ``spread`` decades below
    ``scale`` deg/h; some zero."""
    mag = scale * 10.0 ** -rng.uniform(0.0, spread, N_TERMS)
    c = mag * rng.choice([-1.0, 1.0], N_TERMS)
    c[rng.random(N_TERMS) < 0.15] = 0.0
    if not with_k7:
        c[7] = 0.0
    return c


def random_model(rng: np.random.Generator, reversal: bool = True, estimator: str | None = None):
    """A model with a random data flow (proxy kind, range, estimator, combiner, settle, staleness)
    and random coefficients (including k7)."""
    kind = str(rng.choice(["freq", "temp"]))
    est = estimator or str(rng.choice(["diff", "diffn", "lsq", "iir"]))
    n = int(rng.integers(2, 12))
    shift = int(rng.integers(0, 6))
    if kind == "freq":
        ref, span = float(rng.uniform(1000.0, 15000.0)), float(10 ** rng.uniform(-2, 1.5))
    else:
        ref, span = float(rng.uniform(-50.0, 80.0)), float(10 ** rng.uniform(-0.5, 2))
    rate_span = span * float(10 ** rng.uniform(-4, -1.5))
    comb = str(rng.choice(["pair", "trend"])) if reversal else None
    return make_model(kind, ref, span, est, n, shift, rate_span, 1.0, comb,
                      settle_s=float(rng.integers(0, 4)), max_stale_s=float(rng.integers(10, 80)),
                      coef=random_coef(rng, scale=float(10 ** rng.uniform(-1, 3))))


def random_stream(rng: np.random.Generator, table, n: int, reversal: bool = True, extreme: float = 0.02) -> dict:
    """Input words for ``table``: a proxy random walk around the table's centre (crossing the
    range edges now and then), raw rate words (normal, with a fraction ``extreme`` at the
    saturation edges), short mode runs (1..40 samples of 1, 2, 3; all 0 when not ``reversal``),
    restarts (about 1 in 500 samples) and z words (some beyond +-2^30)."""
    is_freq = table.proxy_kind == 0
    span_lsb = max(2.0, (2.0 ** 30) * 2.0 ** table.sh_u / table.g_u)   # proxy span in word LSB
    step = span_lsb * 10 ** rng.uniform(-4, -1, n) * rng.standard_normal(n)
    p = table.p_ref + np.cumsum(step) % (3.0 * span_lsb) - 1.5 * span_lsb
    p = np.round(p).astype(np.int64)
    ext = rng.random(n) < extreme
    lo, hi = (0, F.UINT32_MAX) if is_freq else (-F.INT32_SYM, F.INT32_SYM)
    p[ext] = rng.choice([lo, hi, lo + 1, hi - 1], int(ext.sum()))
    p = np.clip(p, lo, hi)
    r = np.round(rng.standard_normal(n) * 10 ** rng.uniform(2, 8, n)).astype(np.int64)
    ext = rng.random(n) < extreme
    r[ext] = rng.choice([F.INT32_SYM, -F.INT32_SYM, F.INT32_SYM - 1, 0], int(ext.sum()))
    r = np.clip(r, -F.INT32_SYM, F.INT32_SYM)
    if reversal:
        mode = np.empty(n, np.int64)
        i = 0
        cur = 3
        while i < n:
            run = int(rng.integers(1, 40))
            cur = {3: int(rng.choice([1, 2])), 1: int(rng.choice([3, 2, 3])), 2: int(rng.choice([3, 1, 3]))}[cur]
            mode[i:i + run] = cur
            i += run
    else:
        mode = np.zeros(n, np.int64)
    restart = (rng.random(n) < 0.002).astype(np.uint8)
    restart[0] = 1
    z = np.round(rng.uniform(-1.2, 1.2, n) * F.ONE).astype(np.int64)
    z[rng.random(n) < 0.05] = 0
    return {"p": p, "r": r, "mode": mode, "restart": restart, "z": z}


def corner_stream(table, reversal: bool = True) -> dict:
    """Deterministic corner cases: proxy words at 0, the word limits, the range edges +-1 LSB
    and the centre; rate words at +-(2^31 - 1) and 0; z at +-2^30 (+-1) and beyond; modes
    switching every sample, a settle-length window, long windows, restarts inside windows."""
    is_freq = table.proxy_kind == 0
    lo, hi = (0, F.UINT32_MAX) if is_freq else (-F.INT32_SYM, F.INT32_SYM)
    span_lsb = int((2 ** 30) * 2 ** table.sh_u // table.g_u)
    c = table.p_ref
    pvals = [lo, hi, c, c + span_lsb, c - span_lsb, c + span_lsb + 1, c - span_lsb - 1, c + 1, c - 1,
             lo + 1, hi - 1, c + 2 * span_lsb, c - 2 * span_lsb]
    pvals = [min(max(v, lo), hi) for v in pvals]
    rvals = [F.INT32_SYM, -F.INT32_SYM, 0, 1, -1, F.INT32_SYM - 1]
    zvals = [F.ONE, -F.ONE, F.ONE + 1, -F.ONE - 1, 0, F.INT32_SYM, -F.INT32_SYM, 1, -1]
    if reversal:
        modes = ([3] * 3 + [1] * 5 + [3] * 2 + [2] * 7 + [1, 2, 1, 2, 3, 1, 1, 2, 2, 3, 3] + [1] * 60 + [2] * 60
                 + [3] + [1] * 3 + [2] * 3)
    else:
        modes = [0] * 160
    n = len(modes) * 3
    mode = np.array((modes * 3)[:n], np.int64)
    p = np.array([pvals[(i * 7) % len(pvals)] if i % 3 else pvals[i % len(pvals)] for i in range(n)], np.int64)
    # a slow ramp through the centre in the middle third, so the rate estimators see real slopes
    mid = slice(n // 3, 2 * n // 3)
    p[mid] = np.clip(c + (np.arange(p[mid].shape[0]) - p[mid].shape[0] // 2) * max(1, span_lsb // 50), lo, hi)
    r = np.array([rvals[(i * 5) % len(rvals)] for i in range(n)], np.int64)
    r[mid] = np.where(mode[mid] == 2, -1, 1) * 1000 + np.arange(p[mid].shape[0])
    z = np.array([zvals[i % len(zvals)] for i in range(n)], np.int64)
    restart = np.zeros(n, np.uint8)
    restart[[0, 4, len(modes) + 10, 2 * len(modes) + 50]] = 1
    return {"p": p, "r": r, "mode": mode, "restart": restart, "z": z}
