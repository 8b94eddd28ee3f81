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
               coef=None, terms=None, order: str = "combine_first", coef2=None):
    """A BiasModel from explicit settings (combiner None: FTR).  ``coef``: 17 values (default:
    a smooth model of a few deg/h).  ``order`` "regress_first" makes a two-bank model with bank 2
    ``coef2`` (default: ``coef`` with the signs of k1, k4, k8 flipped: a damping term that
    reverses with the mode)."""
    from host_tools.golden.model import BiasModel, ModelConfig
    from host_tools.golden.proxy import ProxyConfig
    from host_tools.golden.rate import RateConfig
    from host_tools.golden.reversal import ReversalConfig

    if coef is None:
        coef = [1.5, -4.0, 0.3, 1.1, -1.2, -0.2, 0.9, 0.0, 0.05, 1.8, -0.1, 1.9, 0.7, 0.7, -0.02, -1.1, 0.9]
    coef = np.asarray(coef, np.float64)
    two = combiner is not None and order == "regress_first"
    if two:
        if coef2 is None:
            coef2 = coef.copy()
            coef2[[1, 4, 8]] *= -1.0
        coef2 = np.asarray(coef2, np.float64)
    if terms is None:
        nz = coef != 0.0
        if two:
            nz |= coef2 != 0.0
        terms = tuple(k for k in range(N_TERMS) if nz[k])
    rev = None if combiner is None else ReversalConfig(combiner, max_stale_s, settle_s, order=order)
    cfg = ModelConfig(ProxyConfig(kind, ref, span), RateConfig(estimator, n, shift, rate_span, fs), rev)
    return BiasModel(cfg, terms, coef, source="<vectors>", coef_mode2=coef2 if two else None)


def random_coef(rng: np.random.Generator, with_k7: bool = True, spread: float = 6.0, scale: float = 10.0):
    """17 coefficients with random signs and log-uniform magnitudes over ``spread`` decades below
    ``scale`` deg/h; some zero."""
    mag = scale * 10.0 ** -rng.uniform(0.0, spread, N_TERMS)
    c = mag * rng.choice([-1.0, 1.0], N_TERMS)
    c[rng.random(N_TERMS) < 0.15] = 0.0
    if not with_k7:
        c[7] = 0.0
    return c


def random_model(rng: np.random.Generator, reversal: bool = True, estimator: str | None = None,
                 order: str = "combine_first"):
    """A model with a random data flow (proxy kind, range, estimator, combiner, settle, staleness)
    and random coefficients (including k7).  ``order`` "regress_first": two banks (common +-
    damping, the damping a random fraction of the common part per term) and combiner pair,
    trend or none."""
    kind = str(rng.choice(["freq", "temp"]))
    est = estimator or str(rng.choice(["diff", "diffn", "lsq", "iir"]))
    n = int(rng.integers(2, 12))
    shift = int(rng.integers(0, 6))
    if kind == "freq":
        ref, span = float(rng.uniform(1000.0, 15000.0)), float(10 ** rng.uniform(-2, 1.5))
    else:
        ref, span = float(rng.uniform(-50.0, 80.0)), float(10 ** rng.uniform(-0.5, 2))
    rate_span = span * float(10 ** rng.uniform(-4, -1.5))
    # at least 4 word LSB per sample: a slower rate span has no rate gain in int32 (quantize refuses)
    rate_span = max(rate_span, 4.0 * 2.0 ** -(F.FREQ_FRAC if kind == "freq" else F.TEMP_FRAC))
    two = reversal and order == "regress_first"
    comb = str(rng.choice(["pair", "trend", "none"] if two else ["pair", "trend"])) if reversal else None
    coef = random_coef(rng, scale=float(10 ** rng.uniform(-1, 3)))
    coef2 = None
    if two:
        damping = coef * rng.uniform(-0.5, 0.5, N_TERMS)
        coef, coef2 = coef + damping, coef - damping
    return make_model(kind, ref, span, est, n, shift, rate_span, 1.0, comb,
                      settle_s=float(rng.integers(0, 4)), max_stale_s=float(rng.integers(10, 80)),
                      coef=coef, order=order if reversal else "combine_first", coef2=coef2)


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


# -- aux generators (aux_gen 1) ----------------------------------------------------------------------

AUX_COLUMNS = ("aux_a", "aux_b", "aux_c", "aux_d")


def random_aux_terms(rng: np.random.Generator, config, n_terms: int | None = None, kinds=None,
                     long_taus: bool = True) -> list:
    """Random generator terms (host_tools.golden.regressors) for a ModelConfig: every kind of
    formats.AUX_KINDS (or ``kinds``), input terms on freq_hz / temp_c / aux_a..aux_d with random
    ranges, filters (tau 0, short or up to ~10^6 samples), powers 1..5; rate terms on the model's
    own estimator with another span; random signs; weights normalized to sum |w| in (0.3, 1]."""
    fs = config.rate.fs
    kinds = [str(k) for k in rng.permutation(list(F.AUX_KINDS if kinds is None else kinds))]
    n_terms = int(rng.integers(1, F.AUX_MAX_TERMS + 1)) if n_terms is None else n_terms
    aux_cols = list(AUX_COLUMNS[:int(rng.integers(1, F.AUX_MAX_CHANNELS + 1))])
    terms = []
    for j in range(n_terms):
        kind = kinds[j % len(kinds)] if j < len(kinds) else str(rng.choice(kinds))
        t = {"gen": kind, "weight": float(rng.uniform(0.1, 1.0) * rng.choice([-1.0, 1.0])),
             "sign": bool(rng.random() < 0.4)}
        if kind == "input":
            col = str(rng.choice(["freq_hz", "temp_c"] + aux_cols))
            if col == "freq_hz":
                ref, span = float(rng.uniform(1000.0, 15000.0)), float(10 ** rng.uniform(-2, 1.5))
            elif col == "temp_c":
                ref, span = float(rng.uniform(-50.0, 80.0)), float(10 ** rng.uniform(-0.5, 2))
            else:
                ref, span = float(rng.uniform(-1e3, 1e3) * 10 ** rng.uniform(-3, 0)), float(10 ** rng.uniform(-3, 1))
            tau = 0.0 if rng.random() < 0.3 else float(10 ** rng.uniform(-1, 6 if long_taus else 3)) / fs
            t.update(column=col, ref=ref, span=span, tau_s=max(tau, 0.1 / fs) if tau else 0.0,
                     power=int(rng.integers(1, F.AUX_POWER_MAX + 1)))
        elif kind == "rate":
            r = config.rate
            t.update(column=config.proxy.column, estimator=r.estimator, n=r.n, shift=r.shift,
                     span=float(r.span * 10 ** rng.uniform(0, 1)))
        elif kind in ("decay_on", "decay_exchange"):
            t["tau_s"] = float(10 ** rng.uniform(-1, 6 if long_taus else 2.5)) / fs
        elif kind == "ramp":
            t["n_samples"] = int(10 ** rng.uniform(0, 9))
        elif kind == "osc":
            t.update(period_s=float(10 ** rng.uniform(0.4, 6)) / fs, part=str(rng.choice(["sin", "cos"])))
        terms.append(t)
    total = sum(abs(t["weight"]) for t in terms)
    scale = float(rng.uniform(0.3, 1.0)) / total
    for t in terms:
        t["weight"] = t["weight"] * scale
    return terms


def with_aux(model, terms):
    """The model with an aux 'sum' generator of ``terms`` (k7 kept; 1 deg/h if it was 0)."""
    import dataclasses

    from host_tools.golden.model import BiasModel
    from host_tools.golden.regressors import AuxConfig

    coef = np.array(model.coef, np.float64)
    if coef[7] == 0.0:
        coef[7] = 1.0
    coef2 = None
    if model.coef_mode2 is not None:
        coef2 = np.array(model.coef_mode2, np.float64)
        if coef2[7] == 0.0:
            coef2[7] = 1.0
    cfg = dataclasses.replace(model.config, aux=AuxConfig.from_terms(terms, model.config.rate.fs))
    return BiasModel(cfg, tuple(sorted(set(model.terms) | {7})), coef, source="<vectors aux>", coef_mode2=coef2)


def random_aux_model(rng: np.random.Generator, reversal: bool = True, estimator: str | None = None,
                     n_terms: int | None = None, kinds=None, long_taus: bool = True):
    """random_model with random aux terms (:func:`random_aux_terms`)."""
    model = random_model(rng, reversal=reversal, estimator=estimator)
    return with_aux(model, random_aux_terms(rng, model.config, n_terms, kinds, long_taus))


def _walk(rng, centre: int, span_lsb: float, n: int, lo: int, hi: int, extreme: float) -> np.ndarray:
    step = span_lsb * 10 ** rng.uniform(-4, -1, n) * rng.standard_normal(n)
    w = centre + np.cumsum(step) % (3.0 * span_lsb) - 1.5 * span_lsb
    w = np.clip(np.round(w), lo, hi).astype(np.int64)
    ext = rng.random(n) < extreme
    w[ext] = rng.choice([lo, hi, lo + 1, hi - 1, centre], int(ext.sum()))
    return w


def aux_stream(rng: np.random.Generator, table, n: int, reversal: bool = True, extreme: float = 0.01,
               k_jumps: bool = True) -> dict:
    """random_stream plus the channel words of an aux_gen 1 table: ``f``, ``t`` (the proxy words
    for the proxy's channel), ``aux`` (int64[n, n_chan]) random walks around the input terms'
    centres across 3 spans with extremes, and the counter ``k`` (mostly +1 per sample; with
    ``k_jumps`` gaps, a negative start and, rarely, values near 2^62)."""
    s = random_stream(rng, table, n, reversal=reversal, extreme=extreme)
    info = table.aux()
    nch = 0 if info is None else info.n_chan
    centre = {}
    for t in (() if info is None else info.terms):
        if t.kind == 0 and t.src not in centre:
            centre[t.src] = (t.c[0], max(2.0, (2.0 ** 30) * 2.0 ** t.c[3] / t.c[1]))
    lims = {F.CH_F: (0, F.UINT32_MAX)}
    chans = []
    for code in range(F.CH_A0 + nch):
        lo, hi = lims.get(code, (-F.INT32_SYM, F.INT32_SYM))
        c, span = centre.get(code, ((lo + hi) // 2 if code == F.CH_F else 0, 1e6))
        chans.append(_walk(rng, c, span, n, lo, hi, extreme))
    chans[table.proxy_kind] = np.asarray(s["p"], np.int64)
    s["f"], s["t"] = chans[F.CH_F], chans[F.CH_T]
    s["aux"] = np.stack(chans[F.CH_A0:], axis=1) if nch else np.zeros((n, 0), np.int64)
    if k_jumps:
        k = np.cumsum(np.where(rng.random(n) < 0.01, rng.integers(2, 5000, n), 1)) - int(rng.integers(0, 50))
        far = rng.random(n) < 0.002
        k[far] = rng.integers((1 << 62) - 10 ** 6, 1 << 62, int(far.sum()))
    else:
        k = np.arange(n, dtype=np.int64)
    s["k"] = k.astype(np.int64)
    return s


def two_bank_table(table, bank2, combiner: int | None = None):
    """A regress_first (order 1) table: ``table`` with bank 2 = bank 1 of ``bank2`` (a table of the
    same data flow, e.g. quantized from another coefficient set) and ``combiner`` (1 pair, 2 trend,
    3 none; default: the table's).  For equivalence tests and vectors, independent of the golden
    fitter."""
    import dataclasses

    comb = table.combiner if combiner is None else combiner
    if comb == 0:
        raise ValueError("a regress_first table needs a mode-reversal combiner (1, 2, 3)")
    return dataclasses.replace(table, order=1, n_banks=2, combiner=comb, e_row2=bank2.e_row, e_7_2=bank2.e_7,
                               e_acc2=bank2.e_acc, mant2=bank2.mant)
