"""Figures of merit of run logs and compensated outputs: zero-bias variation, stability, mean, repeatability, Allan deviation.

All rates are in deg/h, times in s, ARW in deg/sqrt(h).

**Which output is measured** (:func:`output_of`):

* FTR log (every sample mode 0): ``rate_dph``, every sample valid but the input-invalid ones;
* raw mode-reversal log (modes 1/2/3): the combined output of
  ``host_tools.golden.reversal.combine(log, combiner, bad=...)`` (``out_dph`` where ``valid``);
  the input-invalid samples (``bad``) are never used and a window holding one is not paired;
* compensated log (metadata ``compensated: yes``, or a ``bias_dph`` or ``flags`` column: written
  by ``hdrg compensate``): ``rate_dph`` where the column ``valid`` is 1.

Exchange samples (mode 3) and invalid samples never enter any statistic (a mode-3 sample is
excluded even when a compensated log marks it valid).  A raw log's **input-invalid samples** are
those of ``host_tools.golden.input_check.input_flags`` on ``rate_dph`` (the column measured: a
sample at or beyond the declared rate full scale, by default the rate word's rail 2^21 deg/h),
named in a note; the proxy columns are not read here.

**Tau-averages.** For each averaging time tau the valid samples are cut into non-overlapping
*time* bins of tau seconds (not blocks of a sample count, so bursty and gapped logs work).  The
bin grid starts at the first valid sample of each gap-free segment (a gap is a time step longer
than 1.5x the median step, as in ``host_tools.golden.runlog``) and tiles the segment, so a bin never
straddles a gap.  The tau-average of a bin is the plain mean of its valid samples.  A bin is
**used only when it holds at least MIN_FILL = 50 % of the samples tau seconds hold at the
nominal rate** (``ceil(0.5 * tau * fs)`` samples, fs = 1/median step); emptier bins are dropped.
A tau is *supported* when at least 2 bins are used; otherwise its numbers are ``None`` with a
``reason`` (e.g. the bursty measured logs: 5-s bursts every ~305 s, so no 100-s bin is half
full) instead of a misleading number.  The count of bins used and their median fill are reported.

* zero-bias **variation** [deg/h]: peak-to-peak (max - min) of the tau-averages;
* zero-bias **stability** [deg/h]: 1 sigma (ddof=1) of the tau-averages;
* zero-bias **mean** [deg/h]: mean of the tau-averages (``mean_dph`` at the top level is the
  mean of all valid samples);
* zero-bias **repeatability** [deg/h] (:func:`repeatability`): std (ddof=1) of the per-run means
  of all valid samples, as the paper uses it (also given per tau, from the per-run tau-means).

**Which tau the paper's tables are.** The paper does not say.  Our position: its tables are
**100-s averages**.  The compensated stabilities of Table 4 (e.g. 0.0463 deg/h) are far below any
plausible 1-s noise of the HDRG, so they must be averages over a long time; at the paper's 1 Hz
sampling the 1-s figures are simply the raw samples.  Every printed number carries its tau, and
the default set is tau = 1, 10, 100 s.

**Allan deviation** (:func:`allan`): overlapping ADEV from ``allantools.oadev(x, rate=fs,
data_type="freq", taus=...)`` (rate data are *frequency* data; allantools' default "phase" would
be wrong), on every gap-free stretch of consecutive valid samples (>= 3 samples; exchanges and
time gaps break stretches), at octave taus m/fs, m = 1, 2, 4, ... plus tau = 1 s when it is a
whole number of samples.  The stretches are pooled: at each tau the Allan variances are averaged
weighted by their numbers of second differences (the same as the overlapping estimator with the
differences that would span a break left out).

* **bias instability** [deg/h]: min of ADEV / 0.664 over the taus that hold at least 8
  independent tau-averages (sum over stretches of floor(N_k / m) >= 8), with the tau where it
  occurs; ``bi_at_edge`` is True when that is the largest such tau (ADEV still falling: the
  number is an upper bound, the floor was not reached).
* **angle random walk** [deg/sqrt(h)]: ADEV at tau = 1 s / 60 (white rate noise: sigma(tau) =
  N / sqrt(tau), with N in deg/h*sqrt(s) = N/60 deg/sqrt(h)), method ``"adev_at_1s"``; when 1 s
  is not among the taus, from a fit of sigma = N / sqrt(tau) to the leading taus whose local
  log-log slope lies in [-0.75, -0.25] (method ``"fit_-1/2"``).  Both values are reported when
  available (``arw_at_1s_deg_rth``, ``arw_fit_deg_rth``).  Like the bias instability, only from
  taus that hold at least 8 independent tau-averages; with fewer at every tau both are n/a (None)
  and ``reason`` says so.

For a raw mode-reversal log the Allan figures are those of the combined output: within a window
it is (c + W_other)/2 with W_other constant, so its short-tau noise is about half the raw loop's
and the stretches are at most one dwell (120 s in the paper's timing) long.

CLI: ``hdrg metrics RUN... [--tau 1,10,100] [--combiner pair|trend] [--json [FILE]]`` (default
combiner host_tools.golden.reversal.DEFAULT_COMBINER, the one of `hdrg fit`).  Prints one
row per run per tau, then the Allan figures per run, then the repeatability when there are >= 2
runs.  ``--json`` (or ``--json -``) prints the JSON on stdout *instead of* the table; ``--json
FILE`` writes it to FILE and still prints the table (FILE may not end in .csv/.npz, so a run log
is never overwritten; put ``--json`` after the RUN paths, or use ``--json -``).
"""
from __future__ import annotations

import json
import math
import os
import zipfile

import numpy as np

from host_tools.golden import runlog as _runlog
from host_tools.golden.runlog import GAP_FACTOR, MODE_EXCHANGE, RunLog, RunLogError

DEFAULT_TAUS = (1.0, 10.0, 100.0)
MIN_FILL = 0.5          # a bin needs >= 50 % of the samples tau seconds hold at the nominal rate
MIN_BINS = 2            # a tau is supported with >= 2 bins
BI_FACTOR = 0.664       # flicker floor: sigma_min = 0.664 B
BI_MIN_AVERAGES = 8     # bias instability and ARW only at taus with >= 8 independent averages
MIN_STRETCH = 3         # shortest stretch the Allan deviation uses [samples]
PAPER_TAU_S = 100.0     # the averaging time we take the paper's tables to be


# -- helpers ----------------------------------------------------------------------------------

def _segment_ids(t_s: np.ndarray) -> np.ndarray:
    """Gap-free segment id of every sample (a gap: step > GAP_FACTOR x median step)."""
    if len(t_s) < 3:
        return np.zeros(len(t_s), np.int64)
    d = np.diff(t_s)
    gap = d > GAP_FACTOR * float(np.median(d))
    return np.concatenate([[0], np.cumsum(gap)]).astype(np.int64)


def _nominal_fs(t_s: np.ndarray) -> float:
    """Nominal sample rate [Hz]: 1 / median time step, the step rounded to 10 significant digits."""
    if len(t_s) < 2:
        return float("nan")
    step = float(f"{float(np.median(np.diff(t_s))):.10g}")   # drop float noise of the time stamps
    return 1.0 / step


def _stretches(valid: np.ndarray, seg: np.ndarray) -> list:
    """(start, stop) index pairs of the maximal runs of consecutive valid samples within one segment."""
    v = np.asarray(valid, bool)
    if not v.any():
        return []
    same = np.concatenate([[False], (seg[1:] == seg[:-1]) & v[:-1] & v[1:]])  # i continues a run from i-1
    starts = np.flatnonzero(v & ~same)
    cont_next = np.concatenate([same[1:], [False]])                   # i + 1 continues i's run
    stops = np.flatnonzero(v & ~cont_next) + 1
    return [(int(a), int(b)) for a, b in zip(starts, stops)]


def _num(x):
    """float -> JSON-safe float (None for NaN/inf/None)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


# -- bias statistics ------------------------------------------------------------------------

def tau_bins(out_dph, t_s, valid, tau_s: float, fs_hz: float | None = None):
    """The tau-averages of ``out_dph`` [deg/h] over time bins of ``tau_s`` [s] (see module doc).

    Returns ``(means, counts, min_count)``: the means of the used bins (float64), their sample
    counts, and the minimum count a bin needed.  ``fs_hz`` defaults to 1/median step of ``t_s``.
    """
    out = np.asarray(out_dph, np.float64)
    t = np.asarray(t_s, np.float64)
    v = np.asarray(valid, bool) & np.isfinite(out)
    fs = _nominal_fs(t) if fs_hz is None else float(fs_hz)
    if not fs > 0:
        fs = 1.0
    min_count = max(1, int(math.ceil(MIN_FILL * tau_s * fs - 1e-6)))
    if not v.any():
        return np.zeros(0), np.zeros(0, np.int64), min_count
    seg = _segment_ids(t)[v]
    tv, ov = t[v], out[v]
    # anchor: the first valid sample of each segment
    first = np.concatenate([[True], seg[1:] != seg[:-1]])
    anchor = np.maximum.accumulate(np.where(first, np.arange(len(tv)), 0))
    idx = np.floor((tv - tv[anchor]) / tau_s + 1e-9).astype(np.int64)
    key = seg * (int(idx.max()) + 1) + idx
    _, inverse = np.unique(key, return_inverse=True)
    counts = np.bincount(inverse)
    sums = np.bincount(inverse, weights=ov)
    used = counts >= min_count
    return sums[used] / counts[used], counts[used], min_count


def bias_metrics(out_dph, t_s, valid, taus=DEFAULT_TAUS, fs_hz: float | None = None) -> dict:
    """Zero-bias variation, stability and mean of an output at each averaging time.

    ``out_dph`` float[n] deg/h, ``t_s`` float[n] s (increasing), ``valid`` bool[n] (False
    samples and non-finite outputs are ignored).  Returns ``{"n_valid", "mean_dph", "fs_hz", "min_fill", "per_tau":
    [...]}`` where each ``per_tau`` entry is ``{"tau_s", "supported", "reason", "bins",
    "min_count", "fill_median", "variation_dph" (peak-to-peak), "stability_dph" (1 sigma,
    ddof=1), "mean_dph"}``; the three numbers are None when the tau is not supported.
    """
    out = np.asarray(out_dph, np.float64)
    t = np.asarray(t_s, np.float64)
    v = np.asarray(valid, bool)
    if not (out.shape == t.shape == v.shape) or out.ndim != 1:
        raise ValueError(f"bias_metrics: out_dph, t_s and valid must be 1-D of one length, "
                         f"got {out.shape}, {t.shape}, {v.shape}")
    v = v & np.isfinite(out)
    fs = _nominal_fs(t) if fs_hz is None else float(fs_hz)
    step = 1.0 / fs if fs > 0 else float("nan")
    seg = _segment_ids(t)
    longest = 0.0
    for a, b in _stretches(v, seg):
        longest = max(longest, (b - a) * step)
    per_tau = []
    for tau in taus:
        tau = float(tau)
        if not tau > 0:
            raise ValueError(f"bias_metrics: tau must be > 0 s, not {tau}")
        row = {"tau_s": tau, "supported": False, "reason": None, "bins": 0, "min_count": None,
               "fill_median": None, "variation_dph": None, "stability_dph": None, "mean_dph": None}
        if not v.any():
            row["reason"] = "no valid samples"
        elif math.isfinite(step) and tau < step * (1 - 1e-6):
            row["reason"] = f"tau {tau:g} s is shorter than the sample step {step:.4g} s"
        else:
            means, counts, min_count = tau_bins(out, t, v, tau, fs)
            row["bins"], row["min_count"] = int(len(means)), min_count
            if len(means):
                row["fill_median"] = float(np.median(counts) / (tau * fs))
            if len(means) < MIN_BINS:
                row["reason"] = (f"not supported by the sampling: {len(means)} bin(s) of {tau:g} s hold >= "
                                 f"{MIN_FILL:.0%} of their samples (need {MIN_BINS}); longest gap-free "
                                 f"valid stretch {longest:.4g} s")
            else:
                row.update(supported=True, variation_dph=float(np.ptp(means)),
                           stability_dph=float(np.std(means, ddof=1)), mean_dph=float(np.mean(means)))
        per_tau.append(row)
    return {"n_valid": int(v.sum()), "mean_dph": _num(np.mean(out[v])) if v.any() else None,
            "fs_hz": _num(fs), "min_fill": MIN_FILL, "longest_stretch_s": _num(longest), "per_tau": per_tau}


def at_tau(metrics: dict, tau_s: float) -> dict:
    """The ``per_tau`` entry of a :func:`bias_metrics`/:func:`run_metrics` result for ``tau_s``."""
    for row in metrics["per_tau"]:
        if abs(row["tau_s"] - float(tau_s)) <= 1e-9 * max(1.0, abs(tau_s)):
            return row
    raise KeyError(f"tau {tau_s} s was not computed (have {[r['tau_s'] for r in metrics['per_tau']]})")


# -- Allan deviation ----------------------------------------------------------------------

def allan(out_dph, t_s, valid, fs_hz: float | None = None) -> dict:
    """Pooled overlapping Allan deviation of the valid gap-free stretches (see module doc).

    Returns ``{"stretches", "samples", "longest_s", "tau_s": [...], "adev_dph": [...],
    "n_terms": [...], "bias_instability_dph", "bi_tau_s", "bi_at_edge", "arw_deg_rth",
    "arw_method", "arw_at_1s_deg_rth", "arw_fit_deg_rth", "adev_1s_dph", "reason"}``.
    """
    import allantools

    out = np.asarray(out_dph, np.float64)
    t = np.asarray(t_s, np.float64)
    v = np.asarray(valid, bool) & np.isfinite(out)
    fs = _nominal_fs(t) if fs_hz is None else float(fs_hz)
    res = {"stretches": 0, "samples": 0, "longest_s": None, "tau_s": [], "adev_dph": [], "n_terms": [],
           "bias_instability_dph": None, "bi_tau_s": None, "bi_at_edge": None, "arw_deg_rth": None,
           "arw_method": None, "arw_at_1s_deg_rth": None, "arw_fit_deg_rth": None, "adev_1s_dph": None,
           "reason": None}
    spans = [(a, b) for a, b in _stretches(v, _segment_ids(t)) if b - a >= MIN_STRETCH]
    if not spans or not fs > 0:
        res["reason"] = f"no gap-free stretch of >= {MIN_STRETCH} valid samples"
        return res
    lengths = np.array([b - a for a, b in spans])
    res.update(stretches=len(spans), samples=int(lengths.sum()), longest_s=float(lengths.max() / fs))
    max_m = int((lengths.max() - 1) // 2)       # oadev of N rate samples needs N + 1 - 2m >= 2
    ms = {1 << k for k in range(max(1, max_m).bit_length()) if (1 << k) <= max_m}
    m1 = fs * 1.0
    if abs(m1 - round(m1)) < 1e-6 * max(1.0, m1) and 1 <= round(m1) <= max_m:
        ms.add(int(round(m1)))
    ms = np.array(sorted(ms), np.int64)
    sum_sq = np.zeros(len(ms))
    n_terms = np.zeros(len(ms))
    for (a, b) in spans:
        n = b - a
        ok = ms <= (n - 1) // 2
        if not ok.any():
            continue
        taus2, ad, _, ns = allantools.oadev(out[a:b], rate=fs, data_type="freq", taus=ms[ok] / fs)
        m_ret = np.round(np.asarray(taus2) * fs).astype(np.int64)
        pos = np.searchsorted(ms, m_ret)
        sum_sq[pos] += np.asarray(ns) * np.asarray(ad) ** 2
        n_terms[pos] += np.asarray(ns)
    have = n_terms > 0
    ms, adev, n_terms = ms[have], np.sqrt(sum_sq[have] / n_terms[have]), n_terms[have]
    taus = ms / fs
    res.update(tau_s=taus.tolist(), adev_dph=adev.tolist(), n_terms=n_terms.astype(int).tolist())
    # bias instability over the taus with enough independent averages
    n_avg = np.array([int(np.sum(lengths // m)) for m in ms])
    adm = np.flatnonzero(n_avg >= BI_MIN_AVERAGES)
    if len(adm):
        k = adm[np.argmin(adev[adm])]
        res.update(bias_instability_dph=float(adev[k] / BI_FACTOR), bi_tau_s=float(taus[k]),
                   bi_at_edge=bool(k == adm[-1]))
    else:
        res["reason"] = (f"fewer than {BI_MIN_AVERAGES} independent averages at every tau ({res['samples']} "
                         f"samples in {len(spans)} stretch(es)): no ARW or bias instability")
    # ARW at 1 s (n_avg falls with tau: the taus with enough averages are the first len(adm))
    one = np.flatnonzero(np.abs(taus - 1.0) < 1e-9)
    if len(one):
        res["adev_1s_dph"] = float(adev[one[0]])
        if n_avg[one[0]] >= BI_MIN_AVERAGES:
            res["arw_at_1s_deg_rth"] = float(adev[one[0]] / 60.0)
    # ARW from the -1/2 region at the short taus
    if len(adm) >= 2:
        slopes = np.diff(np.log(adev[:len(adm)])) / np.diff(np.log(taus[:len(adm)]))
        good = (slopes >= -0.75) & (slopes <= -0.25)
        nlead = int(np.argmin(good)) if not good.all() else len(good)
        if nlead >= 1:
            sel = slice(0, nlead + 1)
            logn = np.mean(np.log(adev[sel]) + 0.5 * np.log(taus[sel]))
            res["arw_fit_deg_rth"] = float(np.exp(logn) / 60.0)
    if res["arw_at_1s_deg_rth"] is not None:
        res.update(arw_deg_rth=res["arw_at_1s_deg_rth"], arw_method="adev_at_1s")
    elif res["arw_fit_deg_rth"] is not None:
        res.update(arw_deg_rth=res["arw_fit_deg_rth"], arw_method="fit_-1/2")
    return res


# -- run logs -----------------------------------------------------------------------------

# -- the first 45 min after power-on (the paper's Table 4; `hdrg bench startup`, the closed loop) -------

START_FIRST_S = 180.0               # the first mode-reversal output after power-on [s]
START_TURN_ON_S = 300.0             # the turn-on window ends 5 min after power-on [s]
START_LATE_S = (2400.0, 2700.0)     # the offset baseline: the mean over 40..45 min [s]
START_BIN_S = 100.0                 # averaging of the start-up stability [s]
START_MIN_BIN_SHARE = 0.5           # a 100-s mean needs valid samples on at least this share of its span


def start_figures(t_s, out, valid, end_s: float | None = None) -> dict:
    """The start-up figures [deg/h] of one output ``out`` (deg/h) at its ``valid`` samples, ``t_s``
    the time since power-on [s] (a log recorded from its power-on): from START_FIRST_S to ``end_s``
    (None: the end of the log), the output less its mean over START_LATE_S: ``stability`` = 1
    sigma (ddof=1) of the START_BIN_S means (bins from START_FIRST_S on; a bin with valid samples on
    less than START_MIN_BIN_SHARE of its span is left out), ``variation`` their peak-to-peak,
    ``mean`` the mean of the valid samples, ``turn_on`` the mean over START_FIRST_S ..
    START_TURN_ON_S (the repeatability of start-ups is the rms of it over power-ons).  All NaN
    when the late window holds fewer than 2 valid samples (a log shorter than 45 min)."""
    t = np.asarray(t_s, np.float64) - float(t_s[0])
    ok = np.asarray(valid, bool) & np.isfinite(out) & (t >= START_FIRST_S)
    if end_s is not None:
        ok &= t < end_s
    late = ok & (t >= START_LATE_S[0]) & (t < START_LATE_S[1])
    if late.sum() < 2:
        return {"stability": float("nan"), "variation": float("nan"), "mean": float("nan"), "turn_on": float("nan")}
    y = np.asarray(out, np.float64) - float(np.mean(np.asarray(out)[late]))
    bins = ((t[ok] - START_FIRST_S) // START_BIN_S).astype(np.int64)
    cnt = np.bincount(bins)
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    full = cnt >= START_MIN_BIN_SHARE * START_BIN_S * rate            # partial bins (the last) left out
    means = np.bincount(bins, weights=y[ok])[full] / cnt[full]
    early = ok & (t < START_TURN_ON_S)
    return {"stability": float(np.std(means, ddof=1)) if len(means) > 1 else float("nan"),
            "variation": float(np.ptp(means)) if len(means) else float("nan"), "mean": float(np.mean(y[ok])),
            "turn_on": float(np.mean(y[early])) if early.any() else float("nan")}


def _is_compensated(log: RunLog) -> bool:
    """The output of `hdrg compensate`: metadata ``compensated: yes`` or its columns (``bias_dph``,
    ``flags``; host_tools.golden.checks.is_compensated, the rule of compensate, fit and report)."""
    from host_tools.golden.checks import is_compensated
    return (str(log.metadata.get("compensated", "")).strip().lower() in ("yes", "true", "1")
            or is_compensated(log))


def output_of(log: RunLog, combiner: str | None = None, max_stale_s: float | None = None,
              settle_s: float = 0.0):
    """The measured output of a run log: ``(kind, out_dph, valid, notes)``.

    ``kind`` is ``"ftr"``, ``"reversal"`` or ``"compensated"``; ``valid`` excludes mode-3
    samples always.  See the module doc for which column/combination each kind uses.  ``combiner``
    None: host_tools.golden.reversal.DEFAULT_COMBINER (the one of `hdrg fit`).
    """
    notes = []
    not_exchange = log.mode != MODE_EXCHANGE
    if _is_compensated(log):
        if "valid" not in log.columns:
            raise RunLogError(log.source, None, "compensated log (metadata 'compensated: yes' or a bias_dph/flags "
                                                "column) lacks the column 'valid'")
        vcol = log.columns["valid"]
        bad = (vcol != 0) & (vcol != 1)
        if bad.any():
            row = int(np.argmax(bad))
            raise RunLogError(log.source, log.line_of(row),
                              f"column 'valid' must be 0 or 1, row {row} holds {vcol[row]!r}")
        if "flags" in log.columns:
            from host_tools.golden.flags import counts, format_counts, problems
            notes.append(f"flags: {format_counts(counts(log['flags']))}")
            notes.extend(problems(log))
        return "compensated", log.rate_dph.copy(), (vcol == 1) & not_exchange, notes
    from host_tools.golden.input_check import input_flags

    bad, rep = input_flags(log, ("rate_dph",))
    if rep.flagged:
        notes.append(f"input: {rep.flagged} of {rep.n} samples outside what the sensor can report "
                     f"({rep.invalid_text().split('; ', 1)[1]}): not valid"
                     + ("; a mode-reversal window holding one is not paired" if log.reversal else ""))
    if not log.reversal:
        return "ftr", log.rate_dph.copy(), ~bad, notes
    from host_tools.golden import reversal

    combiner = reversal.DEFAULT_COMBINER if combiner is None else combiner
    comb = reversal.combine(log, combiner=combiner, max_stale_s=max_stale_s, settle_s=settle_s, bad=bad)
    notes.append(f"mode-reversal log: output = reversal.combine(combiner={combiner!r}); its Allan "
                 f"figures are those of the combined output (within a window out = (c + W_other)/2, "
                 f"so its short-tau noise is about half the raw loop's), not the raw sensor's")
    return "reversal", np.asarray(comb.out_dph, np.float64), np.asarray(comb.valid, bool) & not_exchange, notes


def load(path) -> RunLog:
    """Read a run log (CSV or NPZ) for metrics; any unreadable file raises :class:`RunLogError`."""
    source = os.fspath(path)
    if os.path.isdir(source):
        raise RunLogError(source, None, "is a directory, not a run log")
    try:
        return _runlog.read(source)
    except (RunLogError, FileNotFoundError):
        raise
    except (OSError, zipfile.BadZipFile, EOFError) as exc:
        raise RunLogError(source, None, f"not a readable run log ({exc})") from None


def run_metrics(log, taus=DEFAULT_TAUS, combiner: str | None = None, max_stale_s: float | None = None,
                settle_s: float = 0.0) -> dict:
    """All figures of merit of one run log (a :class:`RunLog` or a path).

    Returns the :func:`bias_metrics` dict plus ``"source"``, ``"kind"`` (ftr / reversal /
    compensated), ``"combiner"`` (None unless reversal), ``"n"`` (samples in the log),
    ``"duration_s"`` (last - first t_s), ``"segments"`` (gap-free segments), ``"allan"``
    (:func:`allan`) and ``"notes"`` (list of str).
    """
    if not isinstance(log, RunLog):
        log = load(log)
    kind, out, valid, notes = output_of(log, combiner, max_stale_s, settle_s)
    t = log.t_s
    fs = _nominal_fs(t)
    res = bias_metrics(out, t, valid, taus, fs)
    res["allan"] = allan(out, t, valid, fs)
    nseg = len(log.segments)
    duration = float(t[-1] - t[0])
    if nseg > 1:
        covered = res["n_valid"] / fs if fs > 0 else float("nan")
        notes.append(f"{nseg} gap-free segments (bursty or gapped sampling); valid data cover "
                     f"{covered:.4g} s of {duration:.4g} s; longest gap-free valid stretch "
                     f"{res['longest_stretch_s']:.4g} s; bins never straddle a gap")
    for row in res["per_tau"]:
        if row["supported"] and row["fill_median"] is not None and row["fill_median"] < 0.9:
            notes.append(f"tau {row['tau_s']:g} s: bins are only {row['fill_median']:.0%} filled (median); "
                         f"each is the mean of less than {row['tau_s']:g} s of data")
    if kind == "compensated" and combiner is not None:
        notes.append("combiner ignored: the log is a compensated output")
    if kind == "reversal" and combiner is None:
        from host_tools.golden.reversal import DEFAULT_COMBINER as combiner
    res = {"source": log.source, "kind": kind, "combiner": combiner if kind == "reversal" else None,
           "n": len(log), "duration_s": duration, "segments": nseg, **res, "notes": notes}
    return res


def repeatability(runs: list) -> dict:
    """Zero-bias repeatability across runs: std (ddof=1) of the per-run means [deg/h].

    ``runs`` is a list of :func:`run_metrics` (or :func:`bias_metrics`) results.  Returns
    ``{"n_runs", "means_dph", "repeatability_dph", "per_tau": [{"tau_s", "n_runs",
    "repeatability_dph"}]}``; a value is None with fewer than 2 runs that have it.
    """
    means = [r.get("mean_dph") for r in runs]
    have = [m for m in means if m is not None]
    out = {"n_runs": len(runs), "means_dph": means,
           "repeatability_dph": float(np.std(have, ddof=1)) if len(have) >= 2 else None, "per_tau": []}
    taus = []
    for r in runs:
        for row in r.get("per_tau", []):
            if row["tau_s"] not in taus:
                taus.append(row["tau_s"])
    for tau in taus:
        vals = []
        for r in runs:
            for row in r.get("per_tau", []):
                if row["tau_s"] == tau and row["mean_dph"] is not None:
                    vals.append(row["mean_dph"])
        out["per_tau"].append({"tau_s": tau, "n_runs": len(vals),
                               "repeatability_dph": float(np.std(vals, ddof=1)) if len(vals) >= 2 else None})
    return out


# -- output -------------------------------------------------------------------------------

def _f(x, width=11, prec=5):
    return f"{'n/a':>{width}}" if x is None else f"{x:>{width}.{prec}g}"


def format_table(runs: list, rep: dict | None = None) -> str:
    """Plain-text tables: one row per run per tau, the Allan figures per run, the repeatability."""
    lines = [f"Zero-bias figures of merit over tau-second averages [deg/h] (bins >= {MIN_FILL:.0%} filled; "
             f"the paper's tables are taken as tau = {PAPER_TAU_S:g} s)",
             f"{'run':<28} {'kind':<14} {'tau_s':>6} {'bins':>5} {'variation':>11} {'stability':>11} "
             f"{'mean':>11}  note",
             f"{'':<28} {'':<14} {'':>6} {'':>5} {'(p-p)':>11} {'(1 sigma)':>11} {'':>11}"]
    for r in runs:
        name = os.path.basename(r.get("source", "?"))
        kind = r.get("kind", "?") + (f"/{r['combiner']}" if r.get("combiner") else "")
        for row in r["per_tau"]:
            note = "" if row["supported"] else (row["reason"] or "")
            lines.append(f"{name:<28} {kind:<14} {row['tau_s']:>6g} {row['bins']:>5d} "
                         f"{_f(row['variation_dph'])} {_f(row['stability_dph'])} {_f(row['mean_dph'])}  {note}")
    lines.append("")
    lines.append("Allan deviation (overlapping, data_type='freq', pooled over gap-free valid stretches)")
    lines.append(f"{'run':<28} {'n':>7} {'valid':>7} {'dur_s':>9} {'stretches':>9} {'longest_s':>9} "
                 f"{'ADEV(1s)':>10} {'ARW':>10} {'BI':>10} {'BI_tau_s':>9}")
    lines.append(f"{'':<28} {'':>7} {'':>7} {'':>9} {'':>9} {'':>9} {'[deg/h]':>10} {'[deg/rt-h]':>10} "
                 f"{'[deg/h]':>10}")
    for r in runs:
        a = r.get("allan") or {}
        name = os.path.basename(r.get("source", "?"))
        arw = _f(a.get("arw_deg_rth"), 10, 4)
        bi_tau = "n/a" if a.get("bi_tau_s") is None else f"{a['bi_tau_s']:g}" + ("*" if a.get("bi_at_edge") else "")
        lines.append(f"{name:<28} {r.get('n', 0):>7d} {r.get('n_valid', 0):>7d} {r.get('duration_s', 0):>9.6g} "
                     f"{a.get('stretches', 0):>9d} {_f(a.get('longest_s'), 9, 5)} {_f(a.get('adev_1s_dph'), 10, 4)} "
                     f"{arw} {_f(a.get('bias_instability_dph'), 10, 4)} {bi_tau:>9}")
        if a.get("arw_method") == "fit_-1/2":
            lines.append(f"{'':<28}   ARW from a fit of the -1/2 slope region (tau = 1 s not available)")
        if a.get("reason"):
            lines.append(f"{'':<28}   {a['reason']}")
    if any((r.get("allan") or {}).get("bi_at_edge") for r in runs):
        lines.append("* ADEV still falling at the largest usable tau: BI is an upper bound")
    notes = [(os.path.basename(r.get("source", "?")), n) for r in runs for n in r.get("notes", [])]
    if notes:
        lines.append("")
        lines.append("Notes")
        lines.extend(f"  {name}: {n}" for name, n in notes)
    if rep is not None and rep["n_runs"] >= 2:
        lines.append("")
        lines.append(f"Zero-bias repeatability over {rep['n_runs']} runs (std, ddof=1, of the per-run means) [deg/h]")
        lines.append(f"  all valid samples: {_f(rep['repeatability_dph']).strip()}")
        for row in rep["per_tau"]:
            lines.append(f"  tau {row['tau_s']:>6g} s means: {_f(row['repeatability_dph']).strip()} ({row['n_runs']} runs)")
    return "\n".join(lines) + "\n"


def to_json(runs: list, rep: dict | None = None) -> str:
    """The JSON document of the CLI: ``{"min_fill", "paper_tau_s", "runs": [...], "repeatability"}``."""
    def clean(o):
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, (bool, np.bool_)):
            return bool(o)
        if isinstance(o, (int, np.integer)):
            return int(o)
        if isinstance(o, (float, np.floating)):
            return _num(o)
        return o
    return json.dumps(clean({"min_fill": MIN_FILL, "paper_tau_s": PAPER_TAU_S, "runs": runs,
                             "repeatability": rep}), indent=1)
