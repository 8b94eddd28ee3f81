"""Before/after report of a bias model on run logs: `hdrg report RUN... --model model.json -o DIR`.

For every run, the paper's figures of merit (host_tools.fitting.metrics: variation p-p,
stability 1 sigma, of 1-s and 100-s averages) of:

* **before**, which does not depend on the model: for a mode-reversal run, **mode reversal
  alone** (host_tools.fitting.metrics.output_of: reversal.combine with the default combiner on the
  raw output, no model; the same numbers as `hdrg metrics RUN`); for an FTR run, the raw output.
  For a mode-reversal run the raw output of each mode (sign-corrected, exchanges left out) is an
  extra row, labelled as such: it is not an output the instrument gives, mode reversal alone is.
* the flight stack's **baseline** (cubic in a temperature sensor, clamped:
  host_tools.fitting.baseline) fitted on the same training runs;
* the **model** (compensated output, host_tools.golden.compensate), labelled with how many of the
  17 terms it has.  Its gain is quoted against *before* (mode reversal alone for a mode-reversal run).

report.md names the model file, its training runs, whether each run is held out or one of them
(in-sample), the valid share and the flag counts of the compensated output; extrapolation and
saturation (host_tools.golden.flags) are in the notes.

Figures: timeseries.png (per run: every output at full scale; a zoomed panel whose y-range is set
by the model's output and mode reversal alone; the temperature, temp_c or the proxy), loops.png
(output vs proxy, :func:`loops_figure`: the raw output, and the model's output beside what it is
compared with, mode reversal alone: the hysteresis the rate terms remove) and allan.png
(:func:`allan_figure`: overlapping Allan deviation with 68 % confidence intervals; see
:func:`allan_curve` for how gaps are handled; no tau beyond a tenth of the run).
Writes DIR/report.md, DIR/report.json and DIR/*.png.
"""
from __future__ import annotations

import json
import math
import os
import re

import numpy as np

from host_tools.fitting import metrics
from host_tools.atomic import atomic_open, atomic_path
from host_tools.golden.compensate import compensate, prepare
from host_tools.golden.flags import counts as flag_counts, format_counts, problems as flag_problems
from host_tools.golden.model import BiasModel
from host_tools.golden.runlog import GAP_FACTOR, MODE_EXCHANGE

REPORT_TAUS = (1.0, 100.0)
ALLAN_MAX_FRACTION = 0.1     # no Allan tau beyond a tenth of the run
ALLAN_CI = 0.683             # confidence level of the Allan error bars (1 sigma)

MR_ALONE = "mode reversal alone ({combiner} combiner, no model)"
RAW_PER_MODE = "raw output per mode, sign-corrected (no reversal, no model)"
BEFORE_FTR = "before (uncompensated)"
BASELINE = "baseline: cubic in temp_c, clamped"


def _stats(y, t, valid, taus=REPORT_TAUS) -> dict:
    m = metrics.bias_metrics(y, t, valid, taus=taus)
    out = {}
    for tau in taus:
        row = metrics.at_tau(m, tau)
        out[f"std{int(tau)}_dph"] = row["stability_dph"]
        out[f"pp{int(tau)}_dph"] = row["variation_dph"]
    out["mean_dph"] = m["mean_dph"]
    out["valid_share"] = float(np.mean(np.asarray(valid, bool) & np.isfinite(y))) if len(y) else None
    return out


def before_of(log) -> dict:
    """What the report compares with, independent of any model: ``{"label", "y", "valid"}``.
    A mode-reversal run: mode reversal alone (metrics.output_of, the default combiner, as
    `hdrg metrics`); an FTR run: the raw output."""
    from host_tools.golden.reversal import DEFAULT_COMBINER
    kind, y, valid, _ = metrics.output_of(log)
    label = MR_ALONE.format(combiner=DEFAULT_COMBINER) if kind == "reversal" else BEFORE_FTR
    return {"label": label, "kind": kind, "y": np.asarray(y, np.float64), "valid": np.asarray(valid, bool)}


def evaluate(log, model: BiasModel, impl: str = "float") -> dict:
    """Arrays and figures of merit of ``model`` on ``log``: before (:func:`before_of`, no model),
    for a mode-reversal run the raw output per mode (``raw``), and after (compensated), each
    {std1_dph, pp1_dph, std100_dph, pp100_dph, mean_dph, valid_share}; the compensated output's
    flag counts and problems."""
    pr = prepare(log, model)
    out = compensate(log, model, impl=impl)
    after_valid = np.asarray(out["valid"]) == 1
    b = before_of(log)
    res = {
        "source": log.source, "t_s": np.asarray(log.t_s, np.float64), "p": pr.p, "proxy_kind": model.config.proxy.kind,
        "before": b["y"], "before_valid": b["valid"], "before_label": b["label"], "reversal": b["kind"] == "reversal",
        "after": np.asarray(out.rate_dph, np.float64), "after_valid": after_valid, "bias": out["bias_dph"],
        "stats_before": _stats(b["y"], log.t_s, b["valid"]),
        "stats_after": _stats(out.rate_dph, log.t_s, after_valid),
        "flags": flag_counts(out["flags"]),
        "problems": flag_problems(out),   # extrapolation / saturation (host_tools.golden.flags)
        "temp": ("temp_c", np.asarray(log["temp_c"], np.float64)) if "temp_c" in log.columns else None,
    }
    if res["reversal"]:
        from host_tools.golden.reversal import sign_of
        raw = sign_of(log.mode) * np.asarray(log.rate_dph, np.float64)
        raw_valid = np.asarray(log.mode) != MODE_EXCHANGE
        res.update(raw=raw, raw_valid=raw_valid, stats_raw=_stats(raw, log.t_s, raw_valid))
    return res


def _fmt(x):
    return "   n/a" if x is None else f"{x:9.4f}"


_MD_SPECIAL = re.compile(r"([\\|\[\]])")


def md_text(text) -> str:
    """``text`` as inline Markdown text that renders as itself and reads as itself in the file: one
    line (control characters, newlines included, become spaces), ``<`` and ``>`` as the single angle
    quotation marks U+2039 and U+203A (no HTML tag, comment or autolink can start, and no entity is
    left to read), ``\\ | [ ]`` backslash-escaped (``\\|`` cannot end a table cell, ``\\[``
    cannot start a link).  Backticks are kept: a pair of them is code, as the text means it."""
    s = re.sub(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]", " ", str(text))
    s = s.replace("<", "\u2039").replace(">", "\u203a")
    return _MD_SPECIAL.sub(r"\\\1", s)


def markdown_table(rows) -> str:
    head = "| run | output | std 1 s | p-p 1 s | std 100 s | p-p 100 s |\n|---|---|---:|---:|---:|---:|\n"
    return head + "".join(
        f"| {md_text(r['run'])} | {md_text(r['output'])} | {_fmt(r['std1_dph'])} | {_fmt(r['pp1_dph'])} | "
        f"{_fmt(r['std100_dph'])} | {_fmt(r['pp100_dph'])} |\n" for r in rows)


def model_label(model: BiasModel) -> str:
    """The report's name of a model: how many of the 17 terms it has, e.g. 'model (8 of 17 terms)'."""
    return f"model ({len(model.terms)} of 17 terms)"


def gain_of(before: dict, after: dict) -> dict:
    """{"metric", "before_dph", "after_dph", "gain"} of an output against ``before`` (figures of
    :func:`_stats`), on the std of 100-s averages (1-s where 100 s is not supported by both)."""
    key = "std100_dph" if before.get("std100_dph") is not None and after.get("std100_dph") is not None else "std1_dph"
    b, a = before.get(key), after.get(key)
    name = "std of 100-s averages" if key == "std100_dph" else "std of 1-s averages"
    g = b / a if (b is not None and a is not None and a > 0) else None
    return {"metric": name, "before_dph": b, "after_dph": a, "gain": g}


# -- Allan deviation -------------------------------------------------------------------------------

def _gapfree_segments(t):
    """(start, stop) of the gap-free segments of ``t`` (a gap: a step > GAP_FACTOR x the median)."""
    t = np.asarray(t, np.float64)
    if len(t) < 3:
        return [(0, len(t))]
    d = np.diff(t)
    cut = np.flatnonzero(d > GAP_FACTOR * float(np.median(d))) + 1
    edges = [0, *cut.tolist(), len(t)]
    return list(zip(edges[:-1], edges[1:]))


def _runs(mask):
    """(start, stop) of the runs of True in ``mask``."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _pooled_oadev(pieces, fs, ms):
    """Overlapping ADEV of several independent pieces of rate data, pooled at each averaging factor m:
    the Allan variances averaged weighted by their numbers of terms; the equivalent degrees of
    freedom summed over the pieces (Greenhall's edf for white FM noise, overlapping estimator);
    ``ALLAN_CI`` confidence interval (allantools.confidence_interval).  Returns a dict of lists
    tau_s, adev_dph, lo_dph, hi_dph, edf, n_terms (only the m some piece supports)."""
    import allantools

    out = {k: [] for k in ("tau_s", "adev_dph", "lo_dph", "hi_dph", "edf", "n_terms")}
    for m in ms:
        sum_sq = n_terms = edf = 0.0
        for x in pieces:
            n = len(x)
            if n < 2 * m + 1:
                continue
            _, ad, _, ns = allantools.oadev(x, rate=fs, data_type="freq", taus=np.array([m / fs]))
            if not len(ad):
                continue
            sum_sq += float(ns[0]) * float(ad[0]) ** 2
            n_terms += float(ns[0])
            edf += float(allantools.edf_greenhall(alpha=0, d=2, m=int(m), N=n + 1, overlapping=True, modified=False))
        if n_terms <= 0 or edf <= 0:
            continue
        dev = math.sqrt(sum_sq / n_terms)
        lo, hi = allantools.confidence_interval(dev, edf, ci=ALLAN_CI)
        for k, v in zip(out, (m / fs, dev, lo, hi, edf, n_terms)):
            out[k].append(float(v))
    return out


def allan_curve(y, t_s, valid, max_tau_s=None) -> dict:
    """The report's Allan deviation of an output, honest about gaps:

    * ``gapfree``: allantools.oadev (data_type='freq') on every stretch of consecutive valid
      samples within a gap-free segment of the log, pooled (:func:`_pooled_oadev`), with ``ALLAN_CI``
      confidence intervals; it reaches tau = half the longest stretch (a mode-reversal output:
      half a dwell);
    * ``bridged``: for the taus beyond that, the same on each gap-free segment with its invalid
      samples bridged by linear interpolation between the valid samples around them (samples before
      the first and after the last valid one left out); ``bridged_share`` is the share of the
      samples used that are bridged;
    * no tau above ``max_tau_s`` (default a tenth of the run: last - first t_s).
    """
    y = np.asarray(y, np.float64)
    t = np.asarray(t_s, np.float64)
    v = np.asarray(valid, bool) & np.isfinite(y)
    res = {"gapfree": None, "bridged": None, "bridged_share": 0.0, "max_tau_s": None, "longest_stretch_s": None}
    if len(t) < 3 or not v.any():
        return res
    fs = 1.0 / float(f"{float(np.median(np.diff(t))):.10g}")
    duration = float(t[-1] - t[0])
    max_tau = ALLAN_MAX_FRACTION * duration if max_tau_s is None else float(max_tau_s)
    res["max_tau_s"] = max_tau
    m_max = int(math.floor(max_tau * fs + 1e-9))
    ms = [1 << k for k in range(64) if (1 << k) <= m_max]
    if not ms:
        return res
    stretches, bridged = [], []
    n_bridged = n_used = 0
    for a, b in _gapfree_segments(t):
        va = v[a:b]
        stretches += [y[a + s:a + e] for s, e in _runs(va)]
        idx = np.flatnonzero(va)
        if len(idx) >= 3:
            lo, hi = idx[0], idx[-1] + 1
            seg = y[a + lo:a + hi].copy()
            ok = va[lo:hi]
            k = np.arange(hi - lo)
            seg[~ok] = np.interp(k[~ok], k[ok], seg[ok])
            bridged.append(seg)
            n_bridged += int((~ok).sum())
            n_used += hi - lo
    longest = max((len(s) for s in stretches), default=0)
    res["longest_stretch_s"] = longest / fs
    res["gapfree"] = _pooled_oadev(stretches, fs, [m for m in ms if 2 * m + 1 <= longest])
    beyond = [m for m in ms if 2 * m + 1 > longest]
    if beyond and n_bridged:
        res["bridged"] = _pooled_oadev(bridged, fs, beyond)
        res["bridged_share"] = n_bridged / n_used if n_used else 0.0
    elif beyond:      # no invalid sample inside a segment: the stretches are the segments
        res["gapfree"] = _pooled_oadev(stretches, fs, ms)
    return res


# -- figures ----------------------------------------------------------------------------------------

def _masked(y, valid):
    """``y`` with NaN where not valid (a line plot then breaks there instead of bridging)."""
    return np.where(np.asarray(valid, bool), np.asarray(y, np.float64), np.nan)


def _broken(t, *ys):
    """``t`` and ``ys`` with a NaN inserted at every time gap (:func:`_gapfree_segments`), so a line
    plot does not draw across a gap of the log."""
    starts = [a for a, _ in _gapfree_segments(t)[1:]]
    if not starts:
        return (np.asarray(t, np.float64), *[np.asarray(y, np.float64) for y in ys])
    return tuple(np.insert(np.asarray(a, np.float64), starts, np.nan) for a in (t, *ys))


def _save(fig, path):
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90, format="png", bbox_inches="tight")   # legends beside the axes included


def _legend(ax, **kw):
    leg = ax.legend(fontsize=7, **kw)
    for h in getattr(leg, "legend_handles", getattr(leg, "legendHandles", [])):
        if hasattr(h, "set_linewidth"):
            h.set_linewidth(2.5)
        if hasattr(h, "set_alpha"):
            h.set_alpha(1.0)
    return leg


def _zoom_limits(arrays):
    vals = np.concatenate([a[np.isfinite(a)] for a in arrays] or [np.zeros(0)])
    if not len(vals):
        return None
    lo, hi = np.percentile(vals, [0.1, 99.9])
    pad = 0.15 * (hi - lo) if hi > lo else 1.0
    return lo - pad, hi + pad


COLORS = {"raw": "0.7", "before": "tab:blue", "baseline": "tab:orange", "model": "tab:green", "temp": "tab:red"}


def _plot(results, baseline_results, out_dir, proxy_unit, label, context):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files, titles = [], {"timeseries": [], "allan": None}
    n = len(results)
    # -- time series: full scale, zoomed, temperature
    fig, axes = plt.subplots(3 * n, 1, figsize=(10, 7.8 * n), squeeze=False,
                             gridspec_kw={"height_ratios": [3, 3, 1.6] * n})
    for k, (r, b, ctx) in enumerate(zip(results, baseline_results, context)):
        full, zoom, temp = axes[3 * k:3 * k + 3, 0]
        t_h = r["t_s"] / 3600
        traces = []
        if r["reversal"]:
            traces.append(("raw", _masked(r["raw"], r["raw_valid"]), RAW_PER_MODE, 0.6))
        traces.append(("before", _masked(r["before"], r["before_valid"]), r["before_label"], 0.9))
        if b is not None:
            traces.append(("baseline", _masked(b["after"], b["after_valid"]), BASELINE, 0.9))
        traces.append(("model", _masked(r["after"], r["after_valid"]), label, 0.9))
        traces = [(key, _broken(t_h, y)[1], name, lw) for key, y, name, lw in traces]
        t_h = _broken(t_h)[0]
        for key, y, name, lw in traces:
            full.plot(t_h, y, "-", color=COLORS[key], lw=lw, label=name)
        titles["timeseries"].append(f"{md_plain(ctx['name'])}: {ctx['status']}; model {md_plain(ctx['model_name'])} "
                                    f"(trained on {md_plain(ctx['train'])})")
        full.set_title(titles["timeseries"][-1], fontsize=9)
        full.set_ylabel("rate output [deg/h]")
        _legend(full, loc="upper left", ncol=2)
        zoom_keys = ("before", "model") if r["reversal"] else ("model",)
        for key, y, name, lw in traces:
            if key != "raw":
                zoom.plot(t_h, y, "-", color=COLORS[key], lw=lw, label=name)
        lim = _zoom_limits([y for key, y, _, _ in traces if key in zoom_keys])
        if lim:
            zoom.set_ylim(*lim)
        scale_by = "the model's output and mode reversal alone" if r["reversal"] else "the model's output"
        zoom.set_title(f"zoom: y-range set by {scale_by} (other traces may leave it)", fontsize=8)
        zoom.set_ylabel("rate output [deg/h]")
        zoom.grid(True, alpha=0.3)
        _legend(zoom, loc="upper left", ncol=3)
        if r["temp"] is not None:
            temp.plot(t_h, _broken(r["t_s"], r["temp"][1])[1], "-", color=COLORS["temp"], lw=1.0)
            temp.set_ylabel("temp_c [degC]")
        else:
            temp.plot(t_h, _broken(r["t_s"], r["p"])[1], "-", color=COLORS["temp"], lw=1.0)
            temp.set_ylabel(f"proxy [{proxy_unit}]")
        temp.grid(True, alpha=0.3)
        temp.set_xlabel("time [h]")
        for ax in (full, zoom):
            ax.sharex(temp)
    fig.tight_layout()
    files.append(os.path.join(out_dir, "timeseries.png"))
    _save(fig, files[-1])
    plt.close(fig)

    fig = loops_figure(results, proxy_unit, label)
    files.append(os.path.join(out_dir, "loops.png"))
    _save(fig, files[-1])
    plt.close(fig)

    fig, titles["allan"] = allan_figure(results, baseline_results, label, context)
    files.append(os.path.join(out_dir, "allan.png"))
    _save(fig, files[-1])
    plt.close(fig)
    return files, titles


def loops_figure(results, proxy_unit, label):
    """loops.png: the output against the proxy.  Left: the raw output (per mode, sign-corrected, for
    mode reversal), one colour per run; right: what the model is compared with, mode reversal alone
    (the raw output for an FTR run: it is on the left), and the model's output, one colour per
    output.  Returns the Figure."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rev = any(r["reversal"] for r in results)
    several = len(results) > 1
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    for r in results:
        name = os.path.basename(r["source"])
        y, v = (r["raw"], r["raw_valid"]) if r["reversal"] else (r["before"], r["before_valid"])
        axes[0].plot(r["p"][v], y[v], ".", ms=1, alpha=0.5, label=name)
        pairs = [("before", r["before"], r["before_valid"], r["before_label"])] if r["reversal"] else []
        pairs.append(("model", r["after"], r["after_valid"], f"{label} output"))
        for key, y, v, lab in pairs:
            axes[1].plot(r["p"][v], y[v], ".", ms=1, alpha=0.5, color=COLORS[key],
                         label=f"{name}: {lab}" if several else lab)
    right = (f"mode reversal alone and the {label}" if rev else f"the {label}") + " vs proxy"
    for ax, title in zip(axes, ((RAW_PER_MODE if rev else "raw output") + " vs proxy", right)):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(f"proxy [{proxy_unit}]")
        ax.set_ylabel("rate output [deg/h]")
        ax.grid(True, alpha=0.3)
        _legend(ax, markerscale=8, loc="upper center", bbox_to_anchor=(0.5, -0.16))   # below: it hides no point
    fig.tight_layout()
    return fig


def allan_figure(results, baseline_results, label, context):
    """allan.png: the overlapping Allan deviation of every output with its confidence bars, the
    legend beside the axes (it hides no point).  Stores each curve in ``r["allan"]``.  Returns
    (Figure, title)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    fig, ax = plt.subplots(figsize=(10, 5))
    bridged_any = False
    for r, b in zip(results, baseline_results):
        name = os.path.basename(r["source"]) if n > 1 else ""
        outs = [("before", r["before"], r["before_valid"], r["before_label"])]
        if b is not None:
            outs.append(("baseline", b["after"], b["after_valid"], BASELINE))
        outs.append(("model", r["after"], r["after_valid"], label))
        for key, y, v, lab in outs:
            a = r.setdefault("allan", {})[key] = allan_curve(y, r["t_s"], v)
            color = COLORS[key]
            for part, fmt, suffix in (("gapfree", "o-", ""), ("bridged", "s:", ", bridged")):
                c = a.get(part)
                if not c or not c["tau_s"]:
                    continue
                bridged_any |= part == "bridged"
                dev = np.asarray(c["adev_dph"])
                err = np.vstack([dev - np.asarray(c["lo_dph"]), np.asarray(c["hi_dph"]) - dev])
                ax.errorbar(c["tau_s"], dev, yerr=err, fmt=fmt, ms=3, lw=1, capsize=2, color=color,
                            label=f"{name} {lab}{suffix}".strip())
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time tau [s]")
    ax.set_ylabel("Allan deviation [deg/h]")
    title = "Allan deviation" + (f": {md_plain(context[0]['name'])} ({context[0]['status']})" if n == 1 else "")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    _legend(ax, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    caption = (f"overlapping ADEV (allantools), gap-free stretches of valid samples; bars: {ALLAN_CI:.0%} "
               f"confidence (Greenhall edf, white FM); tau <= run length / {1 / ALLAN_MAX_FRACTION:g}")
    if bridged_any:
        caption += "\ndotted: taus beyond the longest gap-free stretch, invalid samples (exchanges) bridged linearly"
    fig.text(0.01, 0.005, caption, fontsize=6.5, va="bottom")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return fig, title


def md_plain(text) -> str:
    """A run or file name for a figure title: one line, no control characters, at most 60 characters."""
    s = re.sub(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]", " ", str(text)).replace("$", r"\$")
    return s if len(s) <= 60 else s[:57] + "..."


# -- the report -------------------------------------------------------------------------------------

def report(logs, model: BiasModel, out_dir, train_logs=None, plots: bool = True, notes=(),
           model_name: str | None = None) -> dict:
    """Evaluate ``model`` (and the baseline fitted on ``train_logs``, if given) on ``logs``;
    write report.md, report.json and figures to ``out_dir``.  Returns the JSON dict.  ``notes``:
    lines the caller adds to the notes (e.g. recorded training runs it did not find).  A run that
    is one of the model's training runs (the same path as in ``model.fit['train']``, or the same
    data as one of ``train_logs``) is named as such (in-sample), the others as held out.
    ``model_name``: the model's file name for the titles (default 'the model')."""
    from host_tools.fitting.baseline import fit_baseline
    from host_tools.golden.checks import same_runs

    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise NotADirectoryError(f"{out_dir}: exists and is not a directory (-o/--out names the directory to write into)")
    os.makedirs(out_dir, exist_ok=True)
    results = [evaluate(log, model) for log in logs]
    baseline = None
    notes = list(notes)
    recorded_train = list((model.fit or {}).get("train", []))
    recorded = {os.path.abspath(p) for p in recorded_train}
    same = {b for _, b in same_runs(list(train_logs or []), list(logs))}
    in_sample = [os.path.abspath(log.source) in recorded or log.source in same for log in logs]
    notes += [f"{os.path.basename(log.source)} is one of the model's training runs: its numbers are in-sample, "
              f"not a held-out check" for log, ins in zip(logs, in_sample) if ins]
    if train_logs:
        try:
            baseline = fit_baseline(train_logs, like=model.config)
        except ValueError as exc:
            notes.append(f"baseline not fitted: {exc}")
    else:
        notes.append("baseline not fitted: no training runs given (--train) or found in the model")
    base_results = [evaluate(log, baseline) if baseline is not None else None for log in logs]
    notes += [f"{os.path.basename(r['source'])}: {p}" for r in results for p in r["problems"]]
    for r, b in zip(results, base_results):
        if b is not None and np.array_equal(r["after_valid"], b["after_valid"]) and \
                np.allclose(r["after"][r["after_valid"]], b["after"][b["after_valid"]], rtol=0, atol=1e-9):
            notes.append(f"{os.path.basename(r['source'])}: the model and the baseline give the same output (the "
                         f"model is the flight stack's cubic, as hdrg fit's guard may choose): their rows and curves "
                         f"coincide")
    label = model_label(model)
    train_names = [os.path.basename(p) for p in recorded_train] or \
        [os.path.basename(log.source) for log in train_logs or []]
    train_text = ", ".join(train_names) if train_names else "training runs not recorded"
    model_name = model_name or "the model"
    rows, runs = [], []
    for r, b, ins in zip(results, base_results, in_sample):
        name = os.path.basename(r["source"])
        if r["reversal"]:
            rows.append({"run": name, "output": RAW_PER_MODE, "role": "raw_per_mode", **r["stats_raw"]})
        rows.append({"run": name, "output": r["before_label"], "role": "before", **r["stats_before"]})
        if b is not None:
            rows.append({"run": name, "output": BASELINE, "role": "baseline", **b["stats_after"]})
        rows.append({"run": name, "output": label, "role": "model", **r["stats_after"]})
        runs.append({"run": name, "held_out": not ins, "before": r["before_label"],
                     "gain": gain_of(r["stats_before"], r["stats_after"]),
                     "baseline_gain": gain_of(r["stats_before"], b["stats_after"]) if b is not None else None,
                     "valid_share": r["stats_after"]["valid_share"], "flags": r["flags"],
                     "before_valid_share": r["stats_before"]["valid_share"],
                     "n": int(len(r["t_s"])), "n_valid": int(np.count_nonzero(r["after_valid"]))})
    context = [{"name": os.path.basename(r["source"]),
                "status": "training run (in-sample)" if ins else "held-out run",
                "model_name": os.path.basename(str(model_name)), "train": train_text}
               for r, ins in zip(results, in_sample)]
    doc = {"model": {"file": os.path.basename(str(model_name)), "label": label, "train": recorded_train,
                     "terms": list(model.terms), "coef_dph": list(map(float, model.coef)),
                     "config": model.config.to_dict() if hasattr(model.config, "to_dict") else None},
           "rows": rows, "runs": runs, "notes": notes}
    unit = "Hz" if model.config.proxy.kind == "freq" else "degC"
    if plots:
        files, doc["titles"] = _plot(results, base_results, out_dir, unit, label, context)
        doc["figures"] = [os.path.basename(f) for f in files]
        doc["allan"] = {os.path.basename(r["source"]): r.get("allan", {}) for r in results}
    with atomic_open(os.path.join(out_dir, "report.json"), "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1, default=float)
    with atomic_open(os.path.join(out_dir, "report.md"), "w", encoding="utf-8") as fh:
        fh.write(markdown(doc, label))
    return doc


def _pct(x):
    return "n/a" if x is None else f"{100 * x:.1f} %"


def summary_lines(doc) -> list:
    """Per run: held out or in-sample, the model's gain against before (and the baseline's), the
    compensated output's valid share and flag counts (report.md and the console)."""
    lines = []
    for run in doc["runs"]:
        g, bg = run["gain"], run.get("baseline_gain")
        text = (f"{run['run']} ({'held-out run' if run['held_out'] else 'training run: in-sample'}): "
                f"{doc['model']['label']} against {run['before']}, {g['metric']}: ")
        if g["gain"] is None:
            text += "n/a"
        else:
            text += f"{g['before_dph']:.4g} deg/h to {g['after_dph']:.4g} deg/h, {g['gain']:.3g} x"
        if bg and bg["gain"] is not None:
            text += f"; the baseline: {bg['after_dph']:.4g} deg/h, {bg['gain']:.3g} x"
        text += (f"; valid share: {_pct(run['before_valid_share'])} before, compensated output "
                 f"{_pct(run['valid_share'])} of {run['n']} samples, "
                 f"flags: {format_counts(run['flags'])}")
        lines.append(text)
    return lines


def markdown(doc, label) -> str:
    m = doc["model"]
    train = ", ".join(os.path.basename(p) for p in m["train"]) or "not recorded in the model"
    out = ["# Compensation report", "",
           f"Model: {md_text(m['file'])}, {md_text(label)}: {md_text(', '.join(f'k{t}' for t in m['terms']))}; "
           f"training runs: {md_text(train)}.", "",
           "Figures of merit in deg/h (host_tools.fitting.metrics): stability = 1 sigma, variation = peak-to-peak, "
           "of non-overlapping 1-s and 100-s averages of valid samples.  *Before* does not depend on the model: "
           "for a mode-reversal run it is mode reversal alone (the combiner on the raw output, as `hdrg metrics`), "
           "for an FTR run the raw output; the raw output per mode of a mode-reversal run is shown for reference, "
           "it is not an output the instrument gives.", "",
           markdown_table(doc["rows"]).rstrip("\n"), ""]
    out += [f"* {md_text(line)}" for line in summary_lines(doc)]
    for note in doc["notes"]:
        out.append(f"* {md_text(note)}")
    for f in doc.get("figures", []):
        out += ["", f"![{f}]({f})"]       # the figures' own fixed names
    return "\n".join(out) + "\n"


REPORT_FILES = ("report.md", "report.json", "timeseries.png", "loops.png", "allan.png")
