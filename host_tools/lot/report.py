"""The lot report (host_tools.lot, module doc): ``lot.csv`` and ``lot.md`` (one row per device,
pass/fail, the first failing stage and every reason), ``lot.json`` (the spec, the summary, every
device's result, the worst devices) and ``lot_histograms.png`` (the figures over the lot, passing
and failing devices stacked, the spec limits dashed and labelled).

Everything is a function of the devices' results and of the spec, the devices in natural id order
(``foreign-2`` before ``foreign-10``; :func:`natural_key`): no time stamps, host names or worker
ids, so the same input gives the same bytes.  Numbers are written in plain notation: lot.csv with
every digit (seconds as integers), lot.md rounded for reading (deg/h to 4 significant digits,
shares in %, durations h:mm:ss, drive frequencies in kHz).

A result.json written before a field existed (``failures``, ``drive_freq_hz``, ``repaired_logs``,
...) reads as that field missing: an empty cell.
"""
from __future__ import annotations

import csv
import io
import json
import os
import re

import numpy as np

from host_tools.atomic import atomic_open, atomic_path
from host_tools.lot.inputs import LOT_FORMAT, LOT_VERSION

# (result key, table header, histogram axis label, scale to the axis unit, spec key, spec is a max, kind)
# kind: "dph" deg/h, "share" (0..1, shown in %)
FIGURES = (
    ("heldout_stability_dph", "held-out stability [deg/h]", "held-out stability, std of the tau-s means [deg/h]",
     1.0, "heldout_stability_max_dph", True, "dph"),
    ("residual_rms_dph", "residual rms [deg/h]", "training residual rms [deg/h]", 1.0, "residual_rms_max_dph", True,
     "dph"),
    ("valid_share", "valid share [%]", "valid share of the held-out run from power-on [%]", 100.0, "valid_share_min",
     False, "share"),
    ("proxy_coverage", "proxy coverage [%]", "held-out samples inside the proxy range [%]", 100.0, "coverage_min",
     False, "share"),
    ("rate_coverage", "rate coverage [%]", "held-out samples inside the rate range [%]", 100.0, "coverage_min", False,
     "share"),
    ("fixed_bound_dph", "\\|fixed - golden\\| bound [deg/h]", "bound on |fixed - golden| of the output [deg/h]", 1.0,
     "fixed_error_max_dph", True, "dph"),
)
COLUMNS = ("device", "status", "stage", "reason", "train_s", "drive_freq_hz", "proxy", "terms") + tuple(
    f[0] for f in FIGURES) + ("cv_rms_dph", "crc32", "repaired_logs", "warnings")
FILES = ("lot.csv", "lot.md", "lot.json", "lot_histograms.png")
PASS_COLOR, FAIL_COLOR, LIMIT_COLOR = "tab:green", "tab:red", "black"


def natural_key(device_id: str) -> tuple:
    """Sort key of a device id in natural order: digit runs compare as numbers (``foreign-2``
    before ``foreign-10``), letters without case; ties (``A01``, ``A1``, ``a1``) by the id itself."""
    parts = re.split(r"(\d+)", device_id)
    return tuple(int(p) if i % 2 else p.lower() for i, p in enumerate(parts)), device_id


def in_natural_order(results) -> list:
    """The results sorted by :func:`natural_key` of their device id."""
    return sorted(results, key=lambda r: natural_key(r["device"]))


def plain(x, digits: int | None = None) -> str:
    """``x`` in plain positional notation (never ``1e+04``): every digit of the float (``digits``
    None), or rounded to ``digits`` significant digits; '' for None."""
    if x is None:
        return ""
    if digits is None:
        return np.format_float_positional(float(x), trim="-")
    return np.format_float_positional(float(x), precision=digits, unique=False, fractional=False, trim="-")


def hms(seconds) -> str:
    """A duration [s] as h:mm:ss (rounded to the second); '' for None."""
    if seconds is None:
        return ""
    sec = int(round(float(seconds)))
    return f"{sec // 3600}:{sec % 3600 // 60:02d}:{sec % 60:02d}"


def percent(share) -> str:
    """A share (0..1) in % with 4 significant digits, never shown as 100 % when below 1."""
    if share is None:
        return ""
    text = plain(100.0 * share, 4)
    if share < 1.0 and float(text) >= 100.0:
        text = "99.99"
    return f"{text} %"


def khz(freq_hz) -> str:
    """A frequency [Hz] in kHz, to the Hz."""
    return "" if freq_hz is None else f"{freq_hz / 1000.0:.3f}"


def reason_text(r: dict) -> str:
    """Every reason of a device, ``"STAGE: text"``, joined with '; '.  A result written before
    reasons carried their stage: its stage is put in front."""
    reasons = list(r.get("reasons") or [])
    stage = r.get("stage")
    if "failures" not in r and stage and stage != "done":
        reasons = [t if t.startswith(f"{stage}: ") else f"{stage}: {t}" for t in reasons]
    return "; ".join(reasons)


def _row(r: dict) -> dict:
    return {"device": r["device"], "status": r["status"], "stage": r.get("stage"), "reason": reason_text(r),
            "train_s": r.get("train_s"), "drive_freq_hz": r.get("drive_freq_hz"), "proxy": r.get("proxy"),
            "terms": r.get("terms"), **{f[0]: r.get(f[0]) for f in FIGURES}, "cv_rms_dph": r.get("cv_rms_dph"),
            "crc32": r.get("crc32"), "repaired_logs": r.get("repaired_logs") or [],
            "warnings": r.get("warnings") or []}


def _csv_cell(key: str, value) -> str:
    if value is None:
        return ""
    if key == "train_s":
        return str(int(round(float(value))))
    if key == "repaired_logs":
        return ";".join(value)
    if isinstance(value, list):
        return str(len(value))
    if isinstance(value, float):
        return plain(value)
    return str(value)


def csv_text(results) -> str:
    """lot.csv: one row per device (COLUMNS), natural id order; numbers with every digit in plain
    notation, ``train_s`` in whole seconds, ``drive_freq_hz`` in Hz, shares 0..1, ``warnings`` the
    count (lot.md lists them), ``repaired_logs`` the run names separated by ';'."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in in_natural_order(results):
        row = _row(r)
        w.writerow([_csv_cell(c, row[c]) for c in COLUMNS])
    return buf.getvalue()


def _kind(key: str) -> str | None:
    return next((f[6] for f in FIGURES if f[0] == key), "dph" if key.endswith("_dph") else None)


def _md_cell(key: str, value) -> str:
    """A lot.md cell: rounded, plain, units in the column head."""
    if value is None:
        return ""
    if key == "train_s":
        text = hms(value)
    elif key == "drive_freq_hz":
        text = khz(value)
    elif _kind(key) == "share":
        text = percent(value)
    elif _kind(key) == "dph":
        text = plain(value, 4)
    elif key in ("warnings", "repaired_logs"):
        text = str(len(value)) if value else ""
    elif isinstance(value, float):
        text = plain(value, 4)
    else:
        text = str(value)
    return text.replace("|", "\\|").replace("\n", " ")


HEADS = {"train_s": "training [h:mm:ss]", "drive_freq_hz": "drive freq [kHz]", "cv_rms_dph": "CV rms [deg/h]",
         "repaired_logs": "repaired logs", **{f[0]: f[1] for f in FIGURES}}


def _table(rows, cols) -> list:
    lines = ["| " + " | ".join(HEADS.get(c, c) for c in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        row = _row(r)
        lines.append("| " + " | ".join(_md_cell(c, row[c]) for c in cols) + " |")
    return lines


def _sort_key(r: dict):
    """Worst first: the held-out stability, then the residual (devices without a figure last);
    ties in natural id order."""
    s, res = r.get("heldout_stability_dph"), r.get("residual_rms_dph")
    return (s is None, -(s or 0.0), res is None, -(res or 0.0), natural_key(r["device"]))


def worst_devices(results, k: int) -> list:
    """The ``k`` processed devices (a fit exists) with the largest held-out stability, then residual."""
    fitted = [r for r in results if r.get("residual_rms_dph") is not None]
    return sorted(fitted, key=_sort_key)[:max(k, 0)]


def _reason_stages(r: dict) -> list:
    """The stages of a device's reasons, each once, in their order."""
    stages = []
    for text in r.get("reasons") or []:
        stage = text.split(": ", 1)[0] if "failures" in r else r.get("stage")
        if stage and stage not in stages:
            stages.append(stage)
    return stages


def summary(results) -> dict:
    """Counts: devices, pass, fail, ``fail_by_stage`` (failing devices per first failing stage)
    and ``reasons_by_stage`` (failing devices with at least one reason at each stage)."""
    stages, every = {}, {}
    for r in results:
        if r["status"] != "pass":
            first = r.get("stage") or "?"
            stages[first] = stages.get(first, 0) + 1
            for stage in _reason_stages(r) or [first]:
                every[stage] = every.get(stage, 0) + 1
    return {"devices": len(results), "pass": sum(r["status"] == "pass" for r in results),
            "fail": sum(r["status"] != "pass" for r in results), "fail_by_stage": dict(sorted(stages.items())),
            "reasons_by_stage": dict(sorted(every.items()))}


def _spec_value(key: str, value) -> str:
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, (int, float)):
        return plain(value)
    return str(value)


def _warnings_section(results) -> list:
    """Per device with any: its repaired logs, then its warnings (the reader's, the fit's, the
    quantizer's), each once."""
    lines = ["## Warnings", ""]
    n = 0
    for r in results:
        items = []
        kinds = r.get("log_repairs") or {}
        for name in r.get("repaired_logs") or []:
            items.append(f"repaired log {name}" + (f" ({', '.join(kinds[name])})" if kinds.get(name) else ""))
        for w in list(r.get("warnings") or []) + [f"quantize: {q}" for q in r.get("quantize_warnings") or []]:
            if w not in items:
                items.append(w)
        if items:
            n += 1
            lines.append(f"- **{r['device']}** ({r['status']}):")
            lines += [f"  - {_one_line(w)}" for w in items]
    if not n:
        lines.append("No device has a warning.")
    return lines


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def markdown_text(results, spec: dict, worst: list) -> str:
    results = in_natural_order(results)
    s = summary(results)
    by = ", ".join(f"{k} {v}" for k, v in s["fail_by_stage"].items())
    every = ", ".join(f"{k} {v}" for k, v in s["reasons_by_stage"].items())
    lines = ["# Lot report", "",
             f"{s['devices']} devices: {s['pass']} pass, {s['fail']} fail" + (f" (first failing stage: {by})" if by
                                                                            else "") + "."]
    if every and every != by:
        lines += ["", f"Failing devices with a reason at each stage: {every}."]
    lines += ["", "Spec (null: not checked):", "", "| key | value | unit |", "|---|---|---|"]
    from host_tools.lot.inputs import SPEC_DOC
    lines += [f"| {k} | {_spec_value(k, v)} | {SPEC_DOC[k][0] if k in SPEC_DOC else ''} |" for k, v in spec.items()]
    shown = ("device", "status", "reason", "train_s", "drive_freq_hz", "terms") + tuple(f[0] for f in FIGURES) + (
        "crc32", "warnings")
    lines += ["", "## Devices", "",
              "Reason: every reason the device fails, `stage: text`, in stage order (read, check, fit, heldout, "
              "quantize, export, spec).", ""]
    lines += _table(results, shown)
    lines += ["", f"## Worst devices (held-out stability, then training residual; {len(worst)} shown)", ""]
    if worst:
        lines += _table(worst, ("device", "status") + tuple(f[0] for f in FIGURES) + ("cv_rms_dph", "reason"))
    else:
        lines.append("No device was fitted.")
    lines += [""] + _warnings_section(results)
    lines += ["", "## Histograms", "", "![figures over the lot](lot_histograms.png)", ""]
    return "\n".join(lines)


def lot_json(results, spec: dict, worst: list) -> str:
    results = in_natural_order(results)
    d = {"format": LOT_FORMAT, "version": LOT_VERSION, "spec": spec, "summary": summary(results),
         "columns": list(COLUMNS), "devices": results,
         "worst": [{"device": r["device"], "status": r["status"], **{f[0]: r.get(f[0]) for f in FIGURES},
                    "reason": reason_text(r)} for r in worst]}
    return json.dumps(d, indent=2, allow_nan=False) + "\n"


def _limit_label(spec_key: str, value: float, kind: str, is_max: bool) -> str:
    shown = f"{plain(value * 100.0, 4)} %" if kind == "share" else f"{plain(value, 4)} deg/h"
    return f"spec {'max' if is_max else 'min'} {shown} ({spec_key})"


def _stacked(ax, passed, failed, lo, hi, n_bins) -> None:
    """Histogram of the passing and the failing devices' values, stacked, with a legend."""
    if hi <= lo:        # every value the same: a bin around it, a few ticks wide
        pad = max(abs(lo) * 0.05, 1e-9)
        lo, hi = lo - pad, hi + pad
    bins = np.linspace(lo, hi, n_bins + 1)
    ax.hist([passed, failed], bins=bins, stacked=True, color=[PASS_COLOR, FAIL_COLOR],
            label=[f"pass ({len(passed)})", f"fail ({len(failed)})"])


def _panel(ax, results, key, scale, label, limit=None, limit_label=None, no_limit="no spec limit") -> None:
    from matplotlib.ticker import MaxNLocator

    passed = [r[key] * scale for r in results if r.get(key) is not None and r["status"] == "pass"]
    failed = [r[key] * scale for r in results if r.get(key) is not None and r["status"] != "pass"]
    vals = passed + failed
    if vals:
        ends = vals + ([limit] if limit is not None else [])
        _stacked(ax, passed, failed, min(ends), max(ends), min(30, max(5, len(vals) // 3)))
        if limit is not None:
            ax.axvline(limit, color=LIMIT_COLOR, linestyle="--", label=limit_label)
        ax.yaxis.get_major_locator().set_params(integer=True)
        ax.set_ylim(0, 1.8 * max(p.get_y() + p.get_height() for p in ax.patches))   # room for the legend
        ax.legend(fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no device has this figure", ha="center", va="center", transform=ax.transAxes)
    ax.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]))
    ax.ticklabel_format(axis="x", style="plain", useOffset=False)
    ax.set_xlabel(label, fontsize=8)
    ax.set_ylabel("devices [count]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(f"{len(vals)} of {len(results)} devices have it" + (f"; {no_limit}" if limit is None and no_limit
                                                                     else ""), fontsize=8)


def histograms(results, spec: dict, path) -> None:
    """One panel per figure (FIGURES), the training duration [h] and the drive frequency [kHz]:
    the passing and failing devices that have the figure, stacked; the spec limit dashed and
    labelled with its unit (the frequency word's top when the lot comes near it).  The title
    counts the failing devices per stage of their reasons."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from host_tools.lot.device import freq_word_max_hz

    fig = Figure(figsize=(16, 8.5))
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(2, 4, i + 1) for i in range(8)]
    tau = spec.get("stability_tau_s")
    for ax, (key, _, label, scale, spec_key, is_max, kind) in zip(axes, FIGURES):
        label = label.replace("tau-s", f"{tau:g}-s" if tau is not None else "tau")
        lim = spec.get(spec_key)
        _panel(ax, results, key, scale, label, None if lim is None else lim * scale,
               None if lim is None else _limit_label(spec_key, lim, kind, is_max))
    lim = spec.get("min_train_s")
    _panel(axes[6], results, "train_s", 1.0 / 3600.0, "training run(s), total duration [h]",
           None if lim is None else lim / 3600.0,
           None if lim is None else f"spec min {plain(lim / 3600.0, 4)} h = {int(round(lim))} s (min_train_s)")
    top_khz = freq_word_max_hz() / 1000.0
    freqs = [r["drive_freq_hz"] / 1000.0 for r in results if r.get("drive_freq_hz") is not None]
    near = bool(freqs) and max(freqs) > 0.5 * top_khz        # the word's top drawn when the lot comes near it
    _panel(axes[7], results, "drive_freq_hz", 1e-3,
           f"drive frequency, median of the training run(s) [kHz]\n(table word: 0 .. {top_khz:.4g} kHz)",
           top_khz if near else None, f"table word max {top_khz:.4g} kHz" if near else None, no_limit="")
    fig.subplots_adjust(left=0.045, right=0.99, bottom=0.09, top=0.91, wspace=0.25, hspace=0.4)
    by = summary(results)["reasons_by_stage"]
    fig.suptitle(f"{len(results)} devices: {sum(r['status'] == 'pass' for r in results)} pass, "
                 f"{sum(r['status'] != 'pass' for r in results)} fail"
                 + (" (failing devices with a reason at: " + ", ".join(f"{k} {v}" for k, v in by.items()) + ")"
                    if by else ""), fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100, metadata={"Software": None})


def write_report(out, results, spec: dict, worst_k: int = 10) -> dict:
    """Write the report files (FILES) into ``out``, the devices in natural id order; returns
    {name: path}."""
    results = in_natural_order(results)
    worst = worst_devices(results, worst_k)
    paths = {name: os.path.join(os.fspath(out), name) for name in FILES}
    for name, text in (("lot.csv", csv_text(results)), ("lot.md", markdown_text(results, spec, worst)),
                       ("lot.json", lot_json(results, spec, worst))):
        with atomic_open(paths[name], "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
    histograms(results, spec, paths["lot_histograms.png"])
    return paths
