"""Bit-for-bit agreement of the fixed-point implementations: the per-sample Python-integer
reference == the numba kernel on random streams (2 x 10^4 samples) and every corner stream, and
the numba kernel == an independent vectorized exact numpy path on 10^6 samples."""
import numpy as np
import pytest

from firmware_ref import formats as F
from firmware_ref.compensate import run_reference
from firmware_ref.kernel import evaluate_words, run_words
from firmware_ref.terms import K_AUX, POLY_INDEX
from host_tools.vectors.builders import (aux_stream, corner_stream, make_model, random_aux_model, random_model,
                                  random_stream)
from host_tools.fixed.quantize import quantize

KEYS = ("out", "bias", "valid", "flags", "u", "v", "z", "b", "y", "s", "state")


def assert_same(ref, got, what):
    for key in KEYS:
        if not np.array_equal(ref[key], got[key]):
            i = int(np.argmax(ref[key] != got[key]))
            raise AssertionError(f"{what}: {key} differs first at sample {i}: reference {ref[key][i]}, "
                                 f"numba {got[key][i]}")


def both(table, s, self_timed=False):
    ch = {k: s[k] for k in ("f", "t", "aux", "k") if s.get(k) is not None}
    ref = run_reference(table, s["p"], s["r"], None if self_timed else s["mode"], s["restart"], s["z"],
                        self_timed=self_timed, **ch)
    got = run_words(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], self_timed=self_timed, detail=True,
                    **ch)
    return ref, got


CASES = [(seed, rev, est) for seed, (rev, est) in enumerate(
    [(True, "diff"), (True, "diffn"), (True, "lsq"), (True, "iir"), (False, "diff"), (False, "lsq"),
     (True, None), (False, "iir")])]


@pytest.mark.parametrize("seed,reversal,estimator", CASES)
def test_reference_equals_numba_random(seed, reversal, estimator):
    rng = np.random.default_rng(100 + seed)
    model = random_model(rng, reversal=reversal, estimator=estimator)
    table = quantize(model, exchange_s=3.0, dwell_s=7.0, n_random=50).table
    s = random_stream(rng, table, 2500, reversal=reversal)
    ref, got = both(table, s)
    assert_same(ref, got, f"seed {seed}")
    # the streams do exercise the interesting paths
    fl = ref["flags"]
    assert (fl & F.FLAG_PROXY_CLAMPED).any() and (fl & F.FLAG_RATE_CLAMPED).any()
    assert (fl & F.FLAG_AUX_CLAMPED).any() and ref["valid"].any()
    if reversal:
        assert (fl & F.FLAG_STALE).any() and (fl & F.FLAG_EXCHANGE).any()


@pytest.mark.parametrize("reversal", [True, False])
def test_reference_equals_numba_self_timed(reversal):
    rng = np.random.default_rng(7)
    model = random_model(rng, reversal=reversal, estimator="diffn")
    table = quantize(model, exchange_s=2.0, dwell_s=5.0, power_on_s=3.0, n_random=50).table
    s = random_stream(rng, table, 1500, reversal=reversal)
    ref, got = both(table, s, self_timed=True)
    assert_same(ref, got, "self-timed")
    assert set(np.unique(ref["state"])) == ({0, 1, 2, 3, 4} if reversal else {0, 5})


@pytest.mark.parametrize("combiner", [None, "pair", "trend"])
@pytest.mark.parametrize("estimator", ["diff", "diffn", "lsq", "iir"])
def test_reference_equals_numba_corners(combiner, estimator):
    coef = np.array([3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1, 6e1, -5e1])
    model = make_model("temp" if estimator == "lsq" else "freq", ref=20.0 if estimator == "lsq" else 6227.0,
                       span=30.0 if estimator == "lsq" else 3.0, estimator=estimator, n=5, shift=2,
                       rate_span=0.5 if estimator == "lsq" else 0.003, combiner=combiner, settle_s=2.0,
                       max_stale_s=25.0, coef=coef)
    table = quantize(model, n_random=50).table
    s = corner_stream(table, reversal=combiner is not None)
    ref, got = both(table, s)
    assert_same(ref, got, "corners")
    fl = ref["flags"]
    assert (fl & F.FLAG_PROXY_CLAMPED).any() and (fl & F.FLAG_AUX_CLAMPED).any()
    if combiner == "trend":
        assert (fl & F.FLAG_SAT).any()  # +-2^31 rate words alternate: the slope clamps


def test_saturating_outputs_agree():
    """A model with |B| near the output range and extreme rate words: the OUT word saturates."""
    coef = np.zeros(17)
    coef[0] = 2.0 ** 21 * 0.9
    model = make_model(combiner=None, coef=coef)
    table = quantize(model, n_random=10).table
    n = 50
    s = {"p": np.full(n, table.p_ref), "r": np.where(np.arange(n) % 2, -F.INT32_SYM, F.INT32_SYM),
         "mode": np.zeros(n, np.int64), "restart": np.r_[1, np.zeros(n - 1)].astype(np.uint8),
         "z": np.zeros(n, np.int64)}
    ref, got = both(table, s)
    assert_same(ref, got, "saturation")
    assert (ref["out"] == -F.INT32_SYM).any() and (ref["flags"] & F.FLAG_SAT).any()


# -- aux generators (aux_gen 1) -----------------------------------------------------------------------------

AUX_TERMS = (3, 4, 5, 6, 3, 8, 11, 6, 14, 16)      # terms of the random aux table of each seed (at most AUX_MAX_TERMS)


@pytest.mark.parametrize("seed", range(10))
def test_reference_equals_numba_aux(seed):
    """Random aux tables (3..16 terms of every kind: signs, powers, filters up to 10^6 samples,
    decays, exchange resets, ramps, oscillators) on random streams with restarts, K gaps, negative
    K and K near 2^62: the Python reference == the numba kernel, z included (logged and
    self-timed)."""
    rng = np.random.default_rng(700 + seed)
    reversal = seed % 4 != 3
    model = random_aux_model(rng, reversal=reversal, estimator=("diff", "diffn", "lsq", "iir")[seed % 4],
                             n_terms=AUX_TERMS[seed])
    table = quantize(model, exchange_s=3.0, dwell_s=7.0, n_random=10).table
    s = aux_stream(rng, table, 2000, reversal=reversal)
    ref, got = both(table, s)
    assert_same(ref, got, f"aux seed {seed}")
    assert len(np.unique(ref["z"])) > 50
    if reversal and seed % 2:
        ref, got = both(table, s, self_timed=True)
        assert_same(ref, got, f"aux seed {seed}, self-timed")


def test_aux_kinds_are_all_covered_by_the_random_tables():
    kinds = set()
    for seed in range(10):
        rng = np.random.default_rng(700 + seed)
        model = random_aux_model(rng, reversal=seed % 4 != 3, estimator=("diff", "diffn", "lsq", "iir")[seed % 4],
                                 n_terms=AUX_TERMS[seed])
        kinds |= {t["gen"] for t in model.config.aux.terms}
    assert kinds == set(F.AUX_KINDS) and max(AUX_TERMS) == F.AUX_MAX_TERMS


def test_aux_internal_counter_equals_explicit_k():
    """Without K the pipeline counts 0, 1, 2, ... from power-on (restarts do not reset it)."""
    rng = np.random.default_rng(3)
    model = random_aux_model(rng, kinds=("ramp", "osc", "decay_on"), n_terms=3)
    table = quantize(model, exchange_s=3.0, dwell_s=7.0, n_random=10).table
    s = aux_stream(rng, table, 1500, k_jumps=False)
    ref, got = both(table, s)
    s.pop("k")
    ref2, got2 = both(table, s)
    assert_same(ref, ref2, "reference, internal counter")
    assert_same(got, got2, "numba, internal counter")


# -- 10^6 samples: numba vs an independent vectorized exact path ------------------------------------

def rhu(x, s):
    x = np.asarray(x, np.int64)
    return x if s == 0 else (x + np.int64(1 << (s - 1))) >> np.int64(s)


def vec_evaluate(t, u, v, z):
    z = np.clip(z, -F.ONE, F.ONE)
    acc = None
    for i in (3, 2, 1, 0):
        c = [np.int64(t.mant[POLY_INDEX[i][j]]) for j in range(4)]
        q = np.full(u.shape, c[3], np.int64)
        for j in (2, 1, 0):
            q = rhu(q * v, 30) + c[j]
        a = rhu(q, t.e_row[i] - t.e_acc)
        acc = a if acc is None else rhu(acc * u, 30) + a
    acc = acc + rhu(np.int64(t.mant[K_AUX]) * z, 30 + t.e_7 - t.e_acc)
    return rhu(acc, t.e_acc - 21) if t.e_acc >= 21 else acc << np.int64(21 - t.e_acc)


def vec_ftr_pipeline(t, p, r, restart, z):
    """FTR tables only (no combiner state): every stage vectorized in int64."""
    n = len(p)
    idx = np.arange(n)
    dp = np.clip(p - t.p_ref, -(1 << 31), 1 << 31)
    u = rhu(dp * t.g_u + t.u_off, t.sh_u)
    uc = np.abs(u) > F.ONE
    u = np.clip(u, -F.ONE, F.ONE)
    k = idx - np.maximum.accumulate(np.where(restart != 0, idx, 0))
    s = np.zeros(n, np.int64)
    nn = t.rate_n
    if t.rate_est in (0, 1):
        m = 1 if t.rate_est == 0 else nn
        s[m:] = p[m:] - p[:-m]
        s[k < m] = 0
    else:
        assert t.rate_est == 2
        for j in range(nn):
            back = nn - 1 - j
            sh = np.zeros(n, np.int64)
            sh[back:] = p[:n - back] if back else p
            s += (2 * j - (nn - 1)) * (sh - p)
        s[k < nn - 1] = 0
    warm = k < t.rate_warmup
    lim = (1 << t.s_bits) - 1
    sc = np.clip(s, -lim, lim)
    v = rhu(sc * t.g_v, t.sh_v)
    vc = ((np.abs(v) > F.ONE) | (np.abs(s) > lim)) & ~warm
    v = np.where(warm, 0, np.clip(v, -F.ONE, F.ONE))
    b = vec_evaluate(t, u, v, z)
    y = r << np.int64(11)
    o = rhu(y - b, 11)
    bw = rhu(b, 11)
    sat = (np.abs(o) > F.INT32_SYM) | (np.abs(bw) > F.INT32_SYM)
    o = np.clip(o, -F.INT32_SYM, F.INT32_SYM)
    bw = np.clip(bw, -F.INT32_SYM, F.INT32_SYM)
    valid = ~warm
    last = np.maximum.accumulate(np.where(valid, idx, -1))
    out = np.where(last >= 0, o[np.maximum(last, 0)], 0)
    bias = np.where(last >= 0, bw[np.maximum(last, 0)], 0)
    flags = (uc * 1 | vc * 2 | warm * 4 | (np.abs(z) > F.ONE) * 32 | (sat & valid) * 128).astype(np.uint8)
    return {"out": out, "bias": bias, "valid": valid.astype(np.uint8), "flags": flags, "u": u, "v": v, "b": b}


@pytest.mark.parametrize("estimator,n", [("diff", 1), ("diffn", 6), ("lsq", 9)])
def test_numba_equals_vectorized_1e6(estimator, n):
    rng = np.random.default_rng(11)
    model = make_model(estimator=estimator, n=n, combiner=None, coef=rng.choice([-1, 1], 17) * 10 ** rng.uniform(-3, 3, 17))
    table = quantize(model, n_random=10).table
    s = random_stream(rng, table, 1_000_000, reversal=False)
    got = run_words(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], detail=True)
    exp = vec_ftr_pipeline(table, s["p"], s["r"], s["restart"], s["z"])
    for key, val in exp.items():
        if not np.array_equal(got[key], val):
            i = int(np.argmax(got[key] != val))
            raise AssertionError(f"{key} differs first at {i}: numba {got[key][i]}, vectorized {val[i]}")
    assert (exp["flags"] & F.FLAG_RATE_CLAMPED).any() and (exp["flags"] & F.FLAG_SAT).any()


def test_evaluator_numba_equals_vectorized_1e6():
    rng = np.random.default_rng(5)
    for scale in (1e-3, 1.0, 1e4):
        model = make_model(coef=rng.choice([-1, 1], 17) * scale * 10 ** rng.uniform(-4, 0, 17))
        table = quantize(model, n_random=10).table
        n = 1_000_000
        g = np.array([-F.ONE, -F.ONE + 1, -1, 0, 1, F.ONE - 1, F.ONE], np.int64)
        u = rng.integers(-F.ONE, F.ONE + 1, n)
        v = rng.integers(-F.ONE, F.ONE + 1, n)
        z = rng.integers(-F.ONE - 5, F.ONE + 6, n)
        u[:343], v[:343], z[:343] = (a.ravel() for a in np.meshgrid(g, g, g, indexing="ij"))
        np.testing.assert_array_equal(evaluate_words(table, u, v, z), vec_evaluate(table, u, v, z))


# -- regress, then reverse (order 1: two banks, the residual combiner) -----------------------------------

def _rtr_table(rng, estimator, combiner, **kw):
    from host_tools.vectors.builders import two_bank_table
    t1 = quantize(random_model(rng, reversal=True, estimator=estimator), n_random=10, **kw).table
    t2 = quantize(random_model(rng, reversal=True, estimator=estimator), n_random=10, **kw).table
    return two_bank_table(t1, t2, combiner)


@pytest.mark.parametrize("seed,combiner", [(s, c) for s in range(4) for c in (1, 2, 3)])
def test_reference_equals_numba_regress_first(seed, combiner):
    """Two-bank tables with every residual combiner (pair, trend, none) on random streams with
    restarts, logged and self-timed: reference == numba, and both banks are evaluated."""
    rng = np.random.default_rng(900 + seed)
    est = ("diff", "diffn", "lsq", "iir")[seed]
    table = _rtr_table(rng, est, combiner, exchange_s=3.0, dwell_s=7.0)
    s = random_stream(rng, table, 2000, reversal=True)
    ref, got = both(table, s)
    assert_same(ref, got, f"regress_first seed {seed}")
    assert ref["valid"].any() and (ref["flags"] & F.FLAG_STALE).any()
    # bank select: B of mode-2 samples is bank 2's, of the others bank 1's
    m2 = s["mode"] == 2
    for bank, sel in ((1, ~m2), (2, m2)):
        b = evaluate_words(table, ref["u"][sel], ref["v"][sel], ref["z"][sel], bank=bank)
        assert np.array_equal(ref["b"][sel], b)
    if seed % 2:
        ref, got = both(table, s, self_timed=True)
        assert_same(ref, got, f"regress_first seed {seed}, self-timed")


@pytest.mark.parametrize("combiner", [1, 2, 3])
def test_reference_equals_numba_regress_first_corners(combiner):
    """Corner streams (+-2^31 rate words, clamped proxies, restarts) on a two-bank table whose
    bank 2 is large: the residual word saturates (flag 128) and both paths agree."""
    from host_tools.vectors.builders import two_bank_table
    coef = np.array([3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1, 6e1, -5e1])
    base = dict(estimator="diffn", n=5, combiner="pair", settle_s=2.0, max_stale_s=25.0)
    t1 = quantize(make_model(coef=coef, **base), n_random=10).table
    big = np.zeros(17)
    big[0] = 2.0 ** 21 * 0.9
    t2 = quantize(make_model(coef=big, **base), n_random=10).table
    table = two_bank_table(t1, t2, combiner)
    s = corner_stream(table, reversal=True)
    ref, got = both(table, s)
    assert_same(ref, got, "regress_first corners")
    assert (ref["flags"] & F.FLAG_SAT).any() and ref["valid"].any()


def test_regress_first_outputs_are_the_residual_combination():
    """Independent check of the order-1 semantics on a warm, settled stream: none gives OUT =
    RHU(s R 2^11 - B, 11); pair gives OUT = RHU(r 2^10 + W_r[o], 11) with W_r[o] the rounded mean
    of the other mode's last window of r (computed here in numpy from the reference's B)."""
    from host_tools.vectors.builders import two_bank_table
    rng = np.random.default_rng(5)
    from dataclasses import replace
    t1 = replace(quantize(random_model(rng, reversal=True, estimator="diff"), n_random=10).table, settle_n=0,
                 max_stale_n=10 ** 6)
    t2 = quantize(random_model(rng, reversal=True, estimator="diff"), n_random=10).table
    n, w = 400, 20
    mode = np.where((np.arange(n) // w) % 2 == 0, 1, 2)
    s = {"p": np.full(n, t1.p_ref) + rng.integers(-3000, 3000, n), "r": rng.integers(-2 ** 20, 2 ** 20, n),
         "mode": mode, "restart": np.r_[1, np.zeros(n - 1)].astype(np.uint8), "z": rng.integers(-2 ** 30, 2 ** 30, n)}
    sign = np.where(mode == 2, -1, 1)
    for comb in (3, 1):
        table = two_bank_table(t1, t2, comb)
        ref, got = both(table, s)
        assert_same(ref, got, f"combiner {comb}")
        r = ((sign * s["r"]) * 2 ** 11 - ref["b"] + 1024) >> 11
        ok = ref["valid"].astype(bool)
        if comb == 3:
            assert ok[t1.rate_warmup:].all()
            assert np.array_equal(ref["out"][ok], r[ok])
        else:
            exp = np.zeros(n, np.int64)
            for i in np.flatnonzero(ok):
                k = i // w                          # the window of the other mode just before
                lo, hi = (k - 1) * w, k * w
                used = np.arange(lo, hi)[np.arange(lo, hi) >= t1.rate_warmup]
                mean = (int(r[used].sum()) * 2 ** 10 * 2 + len(used)) // (2 * len(used))
                exp[i] = ((int(r[i]) << 10) + mean + 1024) >> 11
            assert ok.sum() > n // 2 and np.array_equal(ref["out"][ok], exp[ok])


@pytest.mark.parametrize("seed,estimator,order", [(0, "diff", "combine_first"), (1, "diffn", "combine_first"),
                                                   (2, "lsq", "regress_first"), (3, "iir", "regress_first"),
                                                   (4, "iir", "combine_first"), (5, None, "regress_first")])
def test_reference_equals_numba_invalid_bit(seed, estimator, order):
    """The input-invalid bit (FORMATS.md): 3 % of the samples flagged, a burst, flags at restarts."""
    rng = np.random.default_rng(700 + seed)
    kw = {"order": order} if order == "regress_first" else {}
    table = quantize(random_model(rng, estimator=estimator, **kw), exchange_s=3.0, dwell_s=7.0, n_random=10).table
    s = random_stream(rng, table, 3000)
    inv = rng.random(3000) < 0.03
    inv[500:510] = True
    inv[np.flatnonzero(np.asarray(s["restart"]) != 0)[:3]] = True
    ref = run_reference(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], invalid=inv)
    got = run_words(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], detail=True, invalid=inv)
    assert_same(ref, got, f"seed {seed}")
    assert ((ref["flags"] & F.FLAG_INPUT_SAT) != 0).tolist() == inv.tolist() and not ref["valid"][inv].any()
    # without the bit, the same stream is unchanged by the new input
    ref0 = run_reference(table, s["p"], s["r"], s["mode"], s["restart"], s["z"])
    assert_same(ref0, run_words(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], detail=True,
                                invalid=np.zeros(3000, bool)), f"seed {seed} no bit")
