"""The lot report (host_tools.lot, module doc): ``lot.csv`` and ``lot.md`` (one row per device,
pass/fail and the reason), ``lot.json`` (the spec, the summary, every device's result, the worst
devices) and ``lot_histograms.png`` (the figures over the lot, the spec limits dashed).

Everything is a function of the devices' results in device-id order and of the spec: no time
stamps, host names or worker ids, so the same input gives the same bytes.
"""
from __future__ import annotations

import csv
import io
import json
import os

import numpy as np

from host_tools.atomic import atomic_open, atomic_path
from host_tools.lot.inputs import LOT_FORMAT, LOT_VERSION

# (result key, table header, unit text for the histogram axis, scale for the axis, spec key, spec is a max)
FIGURES = (
    ("heldout_stability_dph", "held-out stability [deg/h]", "held-out stability (std of the tau-s means) [deg/h]",
     1.0, "heldout_stability_max_dph", True),
    ("residual_rms_dph", "residual rms [deg/h]", "training residual rms [deg/h]", 1.0, "residual_rms_max_dph", True),
    ("valid_share", "valid share", "valid share of the held-out run from power-on [%]", 100.0, "valid_share_min", False),
    ("proxy_coverage", "proxy coverage", "held-out samples inside the proxy range [%]", 100.0, "coverage_min", False),
    ("rate_coverage", "rate coverage", "held-out samples inside the rate range [%]", 100.0, "coverage_min", False),
    ("fixed_bound_dph", "|fixed - golden| bound [deg/h]", "bound on |fixed - golden| of the output [deg/h]", 1.0,
     "fixed_error_max_dph", True),
)
COLUMNS = ("device", "status", "stage", "reason", "train_s", "terms") + tuple(f[0] for f in FIGURES) + (
    "cv_rms_dph", "crc32", "warnings")
FILES = ("lot.csv", "lot.md", "lot.json", "lot_histograms.png")


def _cell(value, fmt: str = "r") -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value) if fmt == "r" else format(value, fmt)
    if isinstance(value, list):
        return str(len(value))
    return str(value)


def _row(r: dict) -> dict:
    return {"device": r["device"], "status": r["status"], "stage": r.get("stage"),
            "reason": "; ".join(r.get("reasons") or []), "train_s": r.get("train_s"), "terms": r.get("terms"),
            **{f[0]: r.get(f[0]) for f in FIGURES}, "cv_rms_dph": r.get("cv_rms_dph"), "crc32": r.get("crc32"),
            "warnings": r.get("warnings") or []}


def csv_text(results) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in results:
        row = _row(r)
        w.writerow([_cell(row[c]) for c in COLUMNS])
    return buf.getvalue()


def _md(value, fmt=".4g") -> str:
    return _cell(value, fmt).replace("|", "\\|").replace("\n", " ")


def _sort_key(r: dict):
    """Worst first: the held-out stability, then the residual (devices without a figure last)."""
    s, res = r.get("heldout_stability_dph"), r.get("residual_rms_dph")
    return (s is None, -(s or 0.0), res is None, -(res or 0.0), r["device"])


def worst_devices(results, k: int) -> list:
    """The ``k`` processed devices (a fit exists) with the largest held-out stability, then residual."""
    fitted = [r for r in results if r.get("residual_rms_dph") is not None]
    return sorted(fitted, key=_sort_key)[:max(k, 0)]


def summary(results) -> dict:
    stages = {}
    for r in results:
        if r["status"] != "pass":
            stages[r.get("stage") or "?"] = stages.get(r.get("stage") or "?", 0) + 1
    return {"devices": len(results), "pass": sum(r["status"] == "pass" for r in results),
            "fail": sum(r["status"] != "pass" for r in results), "fail_by_stage": dict(sorted(stages.items()))}


def markdown_text(results, spec: dict, worst: list) -> str:
    s = summary(results)
    by = ", ".join(f"{k} {v}" for k, v in s["fail_by_stage"].items())
    lines = ["# Lot report", "",
             f"{s['devices']} devices: {s['pass']} pass, {s['fail']} fail" + (f" (stage: {by})" if by else "") + ".",
             "", "Spec (null: not checked):", "", "| key | value |", "|---|---|"]
    lines += [f"| {k} | {json.dumps(v)} |" for k, v in spec.items()]
    shown = ("device", "status", "reason", "train_s", "terms") + tuple(f[0] for f in FIGURES) + ("crc32",)
    heads = {"train_s": "training [s]", **{f[0]: f[1] for f in FIGURES}}
    lines += ["", "## Devices", "", "| " + " | ".join(_md(heads.get(c, c)) for c in shown) + " |",
              "|" + "---|" * len(shown)]
    for r in results:
        row = _row(r)
        lines.append("| " + " | ".join(_md(row[c]) for c in shown) + " |")
    lines += ["", f"## Worst devices (held-out stability, then training residual; {len(worst)} shown)", ""]
    if worst:
        cols = ("device", "status") + tuple(f[0] for f in FIGURES) + ("cv_rms_dph",)
        lines += ["| " + " | ".join(_md(heads.get(c, c)) for c in cols) + " |", "|" + "---|" * len(cols)]
        lines += ["| " + " | ".join(_md(_row(r)[c]) for c in cols) + " |" for r in worst]
    else:
        lines.append("No device was fitted.")
    lines += ["", "## Histograms", "", "![figures over the lot](lot_histograms.png)", ""]
    return "\n".join(lines)


def lot_json(results, spec: dict, worst: list) -> str:
    d = {"format": LOT_FORMAT, "version": LOT_VERSION, "spec": spec, "summary": summary(results),
         "columns": list(COLUMNS), "devices": results,
         "worst": [{"device": r["device"], **{f[0]: r.get(f[0]) for f in FIGURES}} for r in worst]}
    return json.dumps(d, indent=2, allow_nan=False) + "\n"


def histograms(results, spec: dict, path) -> None:
    """One panel per figure (FIGURES), the devices that have it, the spec limit dashed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 7))
    FigureCanvasAgg(fig)
    for i, (key, _, label, scale, spec_key, _) in enumerate(FIGURES):
        label = label.replace("tau-s", f"{spec['stability_tau_s']:g}-s")
        ax = fig.add_subplot(2, 3, i + 1)
        vals = [r[key] * scale for r in results if r.get(key) is not None]
        lim = spec.get(spec_key)
        if vals:
            ends = vals + ([lim * scale] if lim is not None else [])
            lo, hi = min(ends), max(ends)
            pad = 0.5 * abs(lo) * 1e-3 + 1e-12 if hi == lo else 0.0
            ax.hist(vals, bins=np.linspace(lo - pad, hi + pad, min(30, max(5, len(vals) // 3)) + 1),
                    color="tab:blue")
        else:
            ax.text(0.5, 0.5, "no device has this figure", ha="center", va="center", transform=ax.transAxes)
        if lim is not None and vals:
            ax.axvline(lim * scale, color="tab:red", linestyle="--", label=f"spec {lim * scale:g}")
            ax.legend(fontsize=8)
        ax.set_xlabel(label, fontsize=8)
        ax.set_ylabel("devices")
        ax.set_title(f"{len(vals)} of {len(results)} devices", fontsize=9)
    # fixed margins: the labels are of known length, and tight_layout would cost the report a
    # third of its time (the report is the serial part of a lot)
    fig.subplots_adjust(left=0.06, right=0.985, bottom=0.08, top=0.96, wspace=0.22, hspace=0.32)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100, metadata={"Software": None})


def write_report(out, results, spec: dict, worst_k: int = 10) -> dict:
    """Write the report files (FILES) into ``out``; returns {name: path}."""
    worst = worst_devices(results, worst_k)
    paths = {name: os.path.join(os.fspath(out), name) for name in FILES}
    for name, text in (("lot.csv", csv_text(results)), ("lot.md", markdown_text(results, spec, worst)),
                       ("lot.json", lot_json(results, spec, worst))):
        with atomic_open(paths[name], "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
    histograms(results, spec, paths["lot_histograms.png"])
    return paths
