"""Before/after report of a bias model on run logs: `hdrg report RUN... --model model.json --out DIR`.

For every run: the paper's figures of merit (host_tools.fitting.metrics: variation p-p, stability 1 sigma,
mean, at 1 s and 100 s averaging) of the uncompensated output (the FTR output, or the
mode-reversal combined output under the model's combiner), of the flight-stack baseline (cubic in
a temperature sensor, clamped: host_tools.fitting.baseline) fitted on the same training runs, and of the
model (labelled with how many of the 17 terms it has); PNG figures: time series before/after (paper Figs. 6, 8, 9), bias vs proxy
loops (Fig. 7: the hysteresis that the rate terms remove), Allan deviation before/after (invalid
samples bridged by linear interpolation, host_tools.fitting.diagnose._allan_bridged, so a mode-reversal
run reaches taus beyond one dwell).  Extrapolation/saturation of the model (host_tools.golden.flags) is
listed in the notes.
Writes DIR/report.md, DIR/report.json and DIR/*.png.
"""
from __future__ import annotations

import json
import os
import re

import numpy as np

from host_tools.fitting import metrics
from host_tools.atomic import atomic_open, atomic_path
from host_tools.golden.compensate import compensate, prepare
from host_tools.golden.flags import problems as flag_problems
from host_tools.golden.model import BiasModel

REPORT_TAUS = (1.0, 100.0)


def _stats(y, t, valid, taus=REPORT_TAUS) -> dict:
    m = metrics.bias_metrics(y, t, valid, taus=taus)
    out = {}
    for tau in taus:
        row = metrics.at_tau(m, tau)
        out[f"std{int(tau)}_dph"] = row["stability_dph"]
        out[f"pp{int(tau)}_dph"] = row["variation_dph"]
    out["mean_dph"] = m["mean_dph"]
    return out


def evaluate(log, model: BiasModel, impl: str = "float") -> dict:
    """Arrays and figures of merit of ``model`` on ``log``: before (the model's target output)
    and after (compensated), each {std1_dph, pp1_dph, std100_dph, pp100_dph, mean_dph}."""
    pr = prepare(log, model)
    out = compensate(log, model, impl=impl)
    after_valid = np.asarray(out["valid"]) == 1
    return {
        "source": log.source, "t_s": log.t_s, "p": pr.p, "proxy_kind": model.config.proxy.kind,
        "before": pr.y, "before_valid": pr.valid, "after": out.rate_dph, "after_valid": after_valid,
        "bias": out["bias_dph"],
        "stats_before": _stats(pr.y, log.t_s, pr.valid),
        "stats_after": _stats(out.rate_dph, log.t_s, after_valid),
        "problems": flag_problems(out),   # extrapolation / saturation (host_tools.golden.flags)
    }


def _fmt(x):
    return "   n/a" if x is None else f"{x:9.4f}"


_MD_SPECIAL = re.compile(r"([\\`|\[\]])")


def md_text(text) -> str:
    """``text`` as inline Markdown text that renders as itself: one line (control characters,
    newlines included, become spaces), HTML special characters as entities (``&lt;`` ...: no tag
    or comment can start), ``\\ ` | [ ]`` backslash-escaped (``\\|`` cannot end a table cell,
    ``\\[`` cannot start a link, a backtick cannot open code)."""
    s = re.sub(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]", " ", str(text))
    s = s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")
    return _MD_SPECIAL.sub(r"\\\1", s)


def _table(rows) -> str:
    head = "| run | output | std 1 s | p-p 1 s | std 100 s | p-p 100 s |\n|---|---|---:|---:|---:|---:|\n"
    return head + "".join(
        f"| {md_text(r['run'])} | {md_text(r['output'])} | {_fmt(r['std1_dph'])} | {_fmt(r['pp1_dph'])} | "
        f"{_fmt(r['std100_dph'])} | {_fmt(r['pp100_dph'])} |\n" for r in rows)


def model_label(model: BiasModel) -> str:
    """The report's name of a model: how many of the 17 terms it has, e.g. 'model (8 of 17 terms)'."""
    return f"model ({len(model.terms)} of 17 terms)"


def _plot(results, baseline_results, out_dir, proxy_unit, label="model"):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    n = len(results)
    fig, axes = plt.subplots(n, 1, figsize=(10, 3.2 * n), squeeze=False)
    for ax, r, b in zip(axes[:, 0], results, baseline_results):
        t_h = r["t_s"] / 3600
        ax.plot(t_h[r["before_valid"]], r["before"][r["before_valid"]], ",", alpha=0.5, label="before")
        if b is not None:
            ax.plot(t_h[b["after_valid"]], b["after"][b["after_valid"]], ",", alpha=0.5, label="baseline (cubic in temp)")
        ax.plot(t_h[r["after_valid"]], r["after"][r["after_valid"]], ",", label=label)
        ax.set_title(os.path.basename(r["source"]), fontsize=9)
        ax.set_xlabel("time [h]")
        ax.set_ylabel("bias [deg/h]")
        ax.legend(markerscale=20, fontsize=8, loc="upper right")
    fig.tight_layout()
    files.append(os.path.join(out_dir, "timeseries.png"))
    with atomic_path(files[-1]) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for r in results:
        name = os.path.basename(r["source"])
        axes[0].plot(r["p"][r["before_valid"]], r["before"][r["before_valid"]], ",", label=name)
        axes[1].plot(r["p"][r["after_valid"]], r["after"][r["after_valid"]], ",", label=name)
    for ax, title in zip(axes, ("before: bias vs proxy (hysteresis loops)", "after compensation")):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel(f"proxy [{proxy_unit}]")
        ax.set_ylabel("bias [deg/h]")
    axes[0].legend(markerscale=20, fontsize=7)
    fig.tight_layout()
    files.append(os.path.join(out_dir, "loops.png"))
    with atomic_path(files[-1]) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)

    from host_tools.fitting.diagnose import _allan_bridged

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for r in results:
        name = os.path.basename(r["source"])
        for key, style in (("before", "--"), ("after", "-")):
            # invalid samples (mode exchanges, warm-up) bridged as in hdrg diagnose: the valid
            # stretches of a mode-reversal run are one dwell long, which would end the curve there
            a = _allan_bridged(r[key], r["t_s"], r[f"{key}_valid"])
            if a.get("tau_s"):
                ax.loglog(a["tau_s"], a["adev_dph"], style, label=f"{name} {key}")
    ax.set_xlabel("averaging time [s]")
    ax.set_ylabel("Allan deviation [deg/h]")
    ax.set_title("invalid samples (exchanges, warm-up) bridged by linear interpolation", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    files.append(os.path.join(out_dir, "allan.png"))
    with atomic_path(files[-1]) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    return files


def report(logs, model: BiasModel, out_dir, train_logs=None, plots: bool = True, notes=()) -> dict:
    """Evaluate ``model`` (and the baseline fitted on ``train_logs``, if given) on ``logs``;
    write report.md, report.json and figures to ``out_dir``.  Returns the JSON dict.  ``notes``:
    lines the caller adds to the notes (e.g. recorded training runs it did not find).  A run that
    is one of the model's training runs (the same path as in ``model.fit['train']``, or the same
    data as one of ``train_logs``) is named in the notes: its numbers are in-sample."""
    from host_tools.fitting.baseline import fit_baseline
    from host_tools.golden.checks import same_runs

    if os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise NotADirectoryError(f"{out_dir}: exists and is not a directory (--out names the directory to write into)")
    os.makedirs(out_dir, exist_ok=True)
    results = [evaluate(log, model) for log in logs]
    baseline = None
    notes = list(notes)
    recorded = {os.path.abspath(p) for p in (model.fit or {}).get("train", [])}
    same = {b for _, b in same_runs(list(train_logs or []), list(logs))}
    notes += [f"{os.path.basename(log.source)} is one of the model's training runs: its numbers are in-sample, "
              f"not a held-out check" for log in logs if os.path.abspath(log.source) in recorded or log.source in same]
    if train_logs:
        try:
            baseline = fit_baseline(train_logs, like=model.config)
        except ValueError as exc:
            notes.append(f"baseline not fitted: {exc}")
    else:
        notes.append("baseline not fitted: no training runs given (--train) or found in the model")
    base_results = [evaluate(log, baseline) if baseline is not None else None for log in logs]
    notes += [f"{os.path.basename(r['source'])}: {p}" for r in results for p in r["problems"]]
    rows = []
    for r, b in zip(results, base_results):
        name = os.path.basename(r["source"])
        rows.append({"run": name, "output": "before (uncompensated)", **r["stats_before"]})
        if b is not None:
            rows.append({"run": name, "output": "baseline: cubic in temp_c, clamped", **b["stats_after"]})
        rows.append({"run": name, "output": model_label(model), **r["stats_after"]})
    doc = {"model": {"terms": list(model.terms), "coef_dph": list(map(float, model.coef)),
                     "config": model.config.to_dict() if hasattr(model.config, "to_dict") else None},
           "rows": rows, "notes": notes}
    unit = "Hz" if model.config.proxy.kind == "freq" else "degC"
    if plots:
        doc["figures"] = [os.path.basename(f) for f in _plot(results, base_results, out_dir, unit, model_label(model))]
    with atomic_open(os.path.join(out_dir, "report.json"), "w") as fh:
        json.dump(doc, fh, indent=1, default=float)
    with atomic_open(os.path.join(out_dir, "report.md"), "w") as fh:
        fh.write("# Compensation report\n\nFigures of merit in deg/h (host_tools.fitting.metrics): stability = 1 sigma, "
                 "variation = peak-to-peak, of non-overlapping 1-s and 100-s averages of valid samples.\n\n")
        fh.write(_table(rows))
        for note in notes:
            fh.write(f"\n* {md_text(note)}\n")
        for f in doc.get("figures", []):
            fh.write(f"\n![{f}]({f})\n")       # the figures' own fixed names
    return doc


REPORT_FILES = ("report.md", "report.json", "timeseries.png", "loops.png", "allan.png")
