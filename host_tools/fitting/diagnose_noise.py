"""The residual's characterization for the closed loop (host_tools.fitting.diagnose, step 2 of its module
doc): spectrum continuum and lines (:func:`spectral_lines`), the noise model fitted where effects
are not (:func:`noise_model`: white + flicker from the Allan variance at taus <= NOISE_TAU_MAX_S)
and its surrogates (:func:`surrogates`, through the combiner for mode-reversal logs), the
combiner's own lines (:func:`combiner_lines`: reversal cycle, harmonics, chamber sidebands;
reported as artifacts, never fitted) and :func:`characterize` (Allan deviation, lines, binned
correlations per run).  Residuals in deg/h, times in s, frequencies in Hz."""
from __future__ import annotations

import math

import numpy as np

from host_tools.fitting import metrics
from host_tools.fitting.diagnose_confirm import fmt_value


BAND_RATIO = 2 ** 0.25       # spectrum continuum: median over 1/4-octave bands
LINE_ALPHA = 0.01            # spectrum lines: false-alarm level over all bins (Bonferroni)
MAX_LINES = 3                # periodic candidates: at most this many lines ...


# ---------------------------------------------------------------------------------------------
# spectrum: continuum, lines, surrogates
# ---------------------------------------------------------------------------------------------

def filled(resid, valid):
    """The mean-free residual on the valid rows, linearly interpolated (in row index) across the
    invalid ones (mode exchanges, warm-up; held at the ends): a gap-free series for spectra.
    Zero-filling instead would modulate the residual by the exchange pattern (spurious lines)."""
    valid = np.asarray(valid, bool)
    r = np.asarray(resid, np.float64)
    if not valid.any():
        return np.zeros(len(r))
    rv = r[valid] - r[valid].mean()
    idx = np.flatnonzero(valid)
    return np.interp(np.arange(len(r)), idx, rv)


MIN_BAND_BINS = 5            # continuum bands with fewer bins: mean instead of median


def continuum(power) -> np.ndarray:
    """Smooth noise continuum of a periodogram ``power`` (bins 0..K, bin 0 ignored): per
    1/4-octave band of bins, the median / ln 2 (the mean of an exponential ordinate; the median
    ignores the few bins a line occupies) in bands of >= MIN_BAND_BINS bins, the plain mean in the
    narrower bands at the lowest frequencies; interpolated in log-log between band centres.  The
    lowest bins thus keep their own power: a slow residual counts as noise there, since one run
    cannot tell a slow effect from slow noise (conservative)."""
    K = len(power) - 1
    if K < 1:
        return np.zeros_like(power)
    edges = [1]
    while edges[-1] <= K:
        edges.append(max(edges[-1] + 1, int(math.ceil(edges[-1] * BAND_RATIO))))
    centres, levels = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = power[a:min(b, K + 1)]
        if len(seg) == 0:
            continue
        lev = float(np.mean(seg)) if len(seg) < MIN_BAND_BINS else float(np.median(seg)) / math.log(2.0)
        centres.append(math.sqrt(a * (a + len(seg) - 1)))
        levels.append(max(lev, 1e-300))
    k = np.arange(K + 1, dtype=np.float64)
    k[0] = 1.0
    out = np.exp(np.interp(np.log(k), np.log(centres), np.log(levels)))
    out[0] = 0.0
    return out


def local_continuum(power, exact_upto=256) -> np.ndarray:
    """Continuum of a periodogram for the line test: at bin k the median / ln 2 of the bins k'
    with 2 <= |k' - k| <= max(6, ceil(k / 4)), 1 <= k' <= K (the bin and its direct neighbours,
    where a line leaks, excluded); above ``exact_upto`` the band :func:`continuum` (a line is a
    negligible part of a band there)."""
    K = len(power) - 1
    out = continuum(power)
    kmax = min(K, exact_upto)
    if kmax < 1:
        return out
    ks = np.arange(1, kmax + 1)
    hs = np.maximum(6, np.ceil(ks / 4.0).astype(np.int64))
    H = int(hs.max())
    pad = H + 2
    padded = np.concatenate([np.full(pad, np.nan), np.asarray(power, np.float64), np.full(pad, np.nan)])
    padded[pad] = np.nan                     # bin 0 never enters
    offs = np.concatenate([np.arange(-H, -1), np.arange(2, H + 1)])
    win = padded[pad + ks[:, None] + offs[None, :]]
    win[np.abs(offs)[None, :] > hs[:, None]] = np.nan
    count = np.sum(~np.isnan(win), axis=1)
    srt = np.sort(win, axis=1)                    # NaN sort last
    med = 0.5 * (np.take_along_axis(srt, (count // 2)[:, None], 1)[:, 0]
                 + np.take_along_axis(srt, np.maximum((count - 1) // 2, 0)[:, None], 1)[:, 0])
    ok = count >= 3
    out[ks[ok]] = np.maximum(med[ok] / math.log(2.0), 1e-300)
    return out


def spectral_lines(resid, valid, fs, max_lines=MAX_LINES, alpha=LINE_ALPHA) -> list:
    """Significant lines of a residual: periodogram (Hann window) of the mean-free residual
    (invalid samples interpolated, :func:`filled`)
    over its :func:`local_continuum`; a bin is a line when power / continuum > ln(K / alpha) (K
    bins: about alpha false alarms per spectrum) and a local maximum, with a period between 4
    samples and a third of the record.  Returns up to ``max_lines`` dicts {period_s, ratio,
    amp_dph} (strongest first; amp: the sinusoid amplitude estimate)."""
    valid = np.asarray(valid, bool)
    r = filled(np.asarray(resid, np.float64), valid)
    n = len(r)
    if n < 16 or not valid.any():
        return []
    X = np.fft.rfft(r * np.hanning(n))
    power = np.abs(X) ** 2
    cont = local_continuum(power)
    K = len(power) - 1
    thr = math.log(K / alpha)
    ratio = np.where(cont > 0, power / np.where(cont > 0, cont, 1.0), 0.0)
    k = np.arange(len(power))
    ok = (k >= 3) & (k <= n / 4.0)
    cand = [i for i in np.flatnonzero(ok & (ratio > thr))
            if ratio[i] >= ratio[i - 1] and ratio[i] >= ratio[min(i + 1, K)]]
    cand.sort(key=lambda i: -ratio[i])
    frac = float(valid.mean())
    return [{"period_s": float(n / (i * fs)), "ratio": float(ratio[i]),
             "amp_dph": float(4.0 * np.abs(X[i]) / (n * max(frac, 1e-12)))} for i in cand[:max_lines]]


SURROGATE_OVERSAMPLE = 4     # surrogates are cut from a series this many times longer (no wrap-around)
NOISE_TAU_MAX_S = 64.0       # the noise model is fitted to the Allan variance at taus <= this [s]


def noise_model(resid, t_s, valid, fs, reversal=False) -> dict:
    """The noise of a residual, fitted where slow effects are not: the overlapping Allan variance
    of the valid gap-free stretches (host_tools.fitting.metrics.allan, allantools; a mode-reversal log's
    stretches are single dwells) at taus <= NOISE_TAU_MAX_S is fitted (non-negative least squares,
    relative errors) by ``AVAR(tau) = A / tau + B + C tau + D tau^2``: white noise (A = sigma^2 /
    fs, sigma the per-sample std), flicker / bias instability (B = 2 ln2 h_-1), rate random walk
    (C = 2 pi^2 h_-2 / 3) and a drift (D, deterministic: dropped).  So the noise is what the
    short-tau statistics say, extrapolated to long taus by its white and flicker laws; a slow
    effect in the residual (power at long taus only) does not enter it.  The random-walk and
    drift terms are fitted but NOT kept: at taus <= 64 s a rate random walk cannot be told from
    the start of a slow effect (on the foreign devices with an undeclared effect the fitted C was
    50x the true random walk), so keeping it would let the noise swallow the effect.  A real
    random walk does not repeat from run to run or block to block: the cross-validation and the
    held-out confirmation are what stand against it.

    For a mode-reversal residual (``reversal``) the combined output within a window is half the
    raw output plus a deterministic part of the other window, so the raw noise is twice the
    fitted one: the returned coefficients are for the RAW per-sample output (the surrogates pass
    it through the combiner, :func:`surrogates`).  Returns {white_dph (sigma), flicker_dph
    (sqrt B: the flat Allan level), rw_dph_per_sqrt_s (0, see above), slow_dropped (the tau /
    tau^2 terms were non-zero), taus_s, fs, raw_scale} or None when fewer than 3 taus are available."""
    from scipy.optimize import nnls
    a = metrics.allan(resid, t_s, valid, fs)
    taus = np.asarray(a["tau_s"], np.float64)
    adev = np.asarray(a["adev_dph"], np.float64)
    keep = (taus <= NOISE_TAU_MAX_S) & (adev > 0)
    if keep.sum() < 3:
        return None
    taus, avar = taus[keep], adev[keep] ** 2
    cols = [1.0 / taus, np.ones_like(taus)] + ([taus, taus ** 2] if keep.sum() >= 5 else [])
    M = np.column_stack(cols) / avar[:, None]
    coef = nnls(M, np.ones(len(taus)))[0]
    scale = 2.0 if reversal else 1.0
    A, B = coef[:2] * scale ** 2
    C = 0.0      # the tau and tau^2 terms absorb slow structure (effects): not noise
    return {"white_dph": float(math.sqrt(A * fs)), "flicker_dph": float(math.sqrt(B)),
            "rw_dph_per_sqrt_s": float(math.sqrt(3.0 * C)), "slow_dropped": bool(len(coef) > 2 and np.any(coef[2:] > 0)),
            "taus_s": taus.tolist(), "fs": float(fs), "raw_scale": scale,
            "_psd": (2.0 * A, B / (2.0 * math.log(2.0)), 3.0 * C / (2.0 * math.pi ** 2))}


def noise_series(nm, n, count, rng) -> np.ndarray:
    """``count`` Gaussian series (n, count) with the one-sided PSD ``h0 + h1 / f + h2 / f^2`` of
    the noise model ``nm`` (:func:`noise_model`), each a random window of a SURROGATE_OVERSAMPLE x
    longer series (no wrap-around: it drifts and wanders like a real record)."""
    h0, h1, h2 = nm["_psd"]
    fs = nm["fs"]
    L = SURROGATE_OVERSAMPLE * n
    f = np.arange(L // 2 + 1) * (fs / L)
    f[0] = 1.0
    amp = np.sqrt((h0 + h1 / f + h2 / f ** 2) * L * fs / 2.0)
    amp[0] = 0.0
    out = np.zeros((n, count))
    for c in range(count):
        spec = amp * (rng.standard_normal(len(amp)) + 1j * rng.standard_normal(len(amp))) / math.sqrt(2.0)
        x = np.fft.irfft(spec, L)
        start = int(rng.integers(0, L - n + 1))
        out[:, c] = x[start:start + n]
    return out


def combined_noise(cfg) -> bool:
    """The model's target is a combiner output (mode reversal, order combine_first); regress_first
    regresses the per-sample signed output (the noise is raw)."""
    return cfg.reversal is not None and cfg.reversal.order != "regress_first"


def surrogates(nm, log, cfg, count, rng, project=None):
    """``(noise, residual)``: ``count`` surrogate noise series (n, count) of a training log from
    its noise model ``nm`` (:func:`noise_model`; absolute level, not rescaled to the residual)
    and their residuals after the base fit (``noise - project(noise)``).  On a mode-reversal log
    the raw noise goes through the model's combiner (host_tools.golden.reversal, the same kernel), so the
    surrogate carries what the combiner does to noise (window means, trend extrapolation)."""
    n = len(log)
    if count == 0 or nm is None:
        z = np.zeros((n, count))
        return z, z
    w = noise_series(nm, n, count, rng)
    if combined_noise(cfg):
        from host_tools.golden.reversal import combine_values
        mode = np.asarray(log.mode, np.int64)
        ok = np.ones(n, np.bool_)
        for c in range(count):
            w[:, c] = combine_values(mode, w[:, c], ok, log.segments, cfg.reversal, cfg.rate.fs)[0]
    rs = w - project(w) if project is not None else w
    return w, rs


ARTIFACT_HARMONICS = 4       # combiner artifacts: lines at m f_rev + k f_chamber, m = 1..4 ...
ARTIFACT_SIDEBANDS = 3       # ... |k| <= 3


def combiner_lines(train, cfg) -> dict | None:
    """Where the mode-reversal combiner puts spectral lines: the reversal cycle f_rev (median time
    between the starts of mode-1 windows), its harmonics m f_rev (m <= ARTIFACT_HARMONICS) and
    their sidebands with the chamber cycle m f_rev + k f_ch (|k| <= ARTIFACT_SIDEBANDS; f_ch: the
    strongest bin of the Hann periodogram of the mean-free proxy).  A residual the combiner leaves
    (a mode-sign term times a slowly varying envelope) is a square wave at f_rev modulated by the
    chamber cycle: exactly these lines.  None for FTR logs or without two reversal cycles.  Keys:
    reversal_period_s, chamber_period_s, tolerance_hz, combiner, order (of the model's reversal)."""
    if cfg.reversal is None:
        return None
    fs = cfg.rate.fs
    starts, fch = [], []
    for log in train:
        mode = np.asarray(log.mode)
        st = np.flatnonzero((mode[1:] == 1) & (mode[:-1] != 1)) + 1
        if len(st) >= 3:
            starts.append(np.diff(log.t_s[st]))
        _, prx = log.proxy(cfg.proxy.kind)
        prx = np.asarray(prx, np.float64) - np.mean(prx)
        P = np.abs(np.fft.rfft(prx * np.hanning(len(prx)))) ** 2
        if len(P) > 2:
            fch.append((1 + int(np.argmax(P[1:]))) * fs / len(prx))
    if not starts:
        return None
    t_rev = float(np.median(np.concatenate(starts)))
    f_ch = float(np.median(fch)) if fch else 0.0
    dur = max(float(log.t_s[-1] - log.t_s[0]) for log in train)
    tol = min(1.5 / dur, f_ch / 3.0) if f_ch > 0 else 1.5 / dur
    return {"reversal_period_s": t_rev, "chamber_period_s": 1.0 / f_ch if f_ch > 0 else None,
            "tolerance_hz": tol, "combiner": cfg.reversal.combiner, "order": cfg.reversal.order}


def artifact_of(period_s, cl) -> str | None:
    """'m f_rev + k f_ch' when a line at ``period_s`` is a combiner line of :func:`combiner_lines`
    ``cl``, else None."""
    if cl is None:
        return None
    f, f_rev = 1.0 / period_s, 1.0 / cl["reversal_period_s"]
    f_ch = 1.0 / cl["chamber_period_s"] if cl["chamber_period_s"] else 0.0
    for m in range(1, ARTIFACT_HARMONICS + 1):
        for k in range(-ARTIFACT_SIDEBANDS, ARTIFACT_SIDEBANDS + 1) if f_ch else (0,):
            if abs(f - (m * f_rev + k * f_ch)) <= cl["tolerance_hz"]:
                return f"{m} f_rev {'+' if k >= 0 else '-'} {abs(k)} f_chamber"
    return None


def artifact_entry(line, cl, why) -> dict:
    if cl.get("order") == "regress_first":    # already regress-then-reverse: only the residual's combiner is left
        others = " or ".join(c for c in ("none", "pair", "trend") if c != cl["combiner"])
        fix = (f"regress-then-reverse is already in use (residual combiner {cl['combiner']}): another residual "
               f"combiner ({others}; the structure phase scores them)")
    else:
        fix = ("another combiner (--combiner pair or trend), or regress-then-reverse (the bias model applied "
               "per mode before the combiner: order regress_first, combiner none)")
    return {"period_s": line["period_s"], "amp_dph": line["amp_dph"], "ratio": line["ratio"], "at": why,
            "cause": f"the mode-reversal combiner ({cl['combiner']}): a line at the reversal cycle "
                     f"({cl['reversal_period_s']:g} s), its harmonics or their sidebands with the chamber cycle "
                     f"({fmt_value(cl['chamber_period_s'])} s); not a periodic bias of the sensor",
            "structural_fix": fix}


# ---------------------------------------------------------------------------------------------
# residual characterization
# ---------------------------------------------------------------------------------------------

def _binned(x, r, bins=10):
    """Binned means of r by quantile bins of x (unique values when x has few): list of
    {"x": centre, "mean_dph", "n"}."""
    vals = np.unique(x)
    if len(vals) <= bins:
        return [{"x": float(v), "mean_dph": float(r[x == v].mean()), "n": int(np.sum(x == v))} for v in vals]
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    out = []
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            out.append({"x": float(x[sel].mean()), "mean_dph": float(r[sel].mean()), "n": int(sel.sum())})
    return out


def allan_bridged(resid, t_s, valid, fs=None) -> dict:
    """metrics.allan of the residual with its invalid samples (mode exchanges, warm-up) bridged by
    linear interpolation (:func:`filled`), so a mode-reversal log reaches long taus (its valid
    stretches are at most one dwell long); time gaps still break the stretches."""
    return metrics.allan(filled(resid, valid), t_s, np.ones(len(resid), bool), fs)


def characterize(log, resid, valid, fs, v=None) -> dict:
    """The residual of one run against its own noise floor (see the module doc): ``allan``
    (:func:`allan_bridged`: tau_s, adev_dph, white_dph = the white-noise line through the
    shortest tau, structure_taus_s = the taus where adev > 2 x white_dph), ``lines`` (:func:`spectral_lines`),
    ``dependence`` {channel: {corr, range_dph, bins}} over time_s, proxy_rate (v), mode and every
    logged channel but t_s/rate_dph, ``rms_dph``."""
    valid = np.asarray(valid, bool)
    out = {"source": log.source, "n_valid": int(valid.sum()),
           "rms_dph": float(np.std(resid[valid])) if valid.any() else None}
    a = allan_bridged(resid, log.t_s, valid, fs)
    taus = np.asarray(a["tau_s"], np.float64)
    adev = np.asarray(a["adev_dph"], np.float64)
    white = adev[0] * np.sqrt(taus[0] / taus) if len(taus) else np.zeros(0)
    out["allan"] = {"tau_s": taus.tolist(), "adev_dph": adev.tolist(), "white_dph": white.tolist(),
                    "structure_taus_s": taus[adev > 2.0 * white].tolist(),
                    "adev_1s_dph": a["adev_1s_dph"], "bias_instability_dph": a["bias_instability_dph"]}
    out["lines"] = spectral_lines(resid, valid, fs) if len(log.segments) == 1 else []
    dep = {}
    if valid.sum() >= 20:
        r = resid[valid]
        chans = {"time_s": log.t_s}
        if v is not None:
            chans["proxy_rate"] = v
        chans["mode"] = log.mode
        for name in log.columns:
            if name not in ("t_s", "rate_dph", "mode"):
                chans[name] = log[name]
        for name, x in chans.items():
            x = np.asarray(x, np.float64)[valid]
            sd = float(np.std(x))
            corr = float(np.corrcoef(x, r)[0, 1]) if sd > 0 and np.std(r) > 0 else 0.0
            bins = _binned(x, r)
            means = [b["mean_dph"] for b in bins]
            dep[name] = {"corr": corr, "range_dph": float(max(means) - min(means)) if means else 0.0, "bins": bins}
    out["dependence"] = dep
    return out
