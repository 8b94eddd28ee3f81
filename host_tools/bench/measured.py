"""Measured data, held out: the default fit against the flight stack's cubic and no compensation.

Every run log (``*.csv``) under the data folder (default: the measured sets shipped in
tests/data, each folder with its README and LICENSE) is cut into its chamber legs
(host_tools.fitting.legs.find_legs on the temperature proxy; a log of one leg is cut into its
first and second half in time).  Splits: every leg trained alone and applied to every other leg,
and, with three legs or more, every leg held out of the others (leave-one-leg-out).  On each
split, the held-out output of: no compensation, the flight stack's cubic in the temperature
sensor (host_tools.fitting.baseline.fit_baseline: PX4 / ArduPilot style, clamped to the
calibrated range), and `hdrg fit`'s defaults (host_tools.fitting.fit_pipeline.fit_default).

Figures per split [deg/h]: the std of 100-s means of the held-out output (its offset removed)
and the rms of the 100-s means (offset included); 100-s means over the samples present in each
window, so bursty logs count their bursts (host_tools.fitting.metrics.tau_bins with the log's
average sample rate); the valid share of the default's output.  The summary gives the ratio
default / cubic of the std per split, its median and maximum.
"""
from __future__ import annotations

import math
import os
from collections import Counter
import warnings
from pathlib import Path

import numpy as np

TAU_S = 100.0
DEFAULT_DATA = Path(__file__).resolve().parents[2] / "tests" / "data"


def stats_100s(out_dph, t_s, valid) -> dict:
    """{"std_dph", "rms_dph", "bins"} of the 100-s means of ``out_dph`` over its valid samples."""
    from host_tools.fitting.metrics import tau_bins
    t = np.asarray(t_s, np.float64)
    fs = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else 1.0
    means, _, _ = tau_bins(out_dph, t, valid, TAU_S, fs_hz=fs)
    if len(means) < 2:
        return {"std_dph": math.nan, "rms_dph": math.nan, "bins": int(len(means))}
    return {"std_dph": float(np.std(means)), "rms_dph": float(np.sqrt(np.mean(means ** 2))), "bins": int(len(means))}


def pieces(log) -> list:
    """[(name, RunLog)]: the chamber legs of ``log`` ('cool1', 'heat', 'cool2', ... in time
    order, numbered per kind; named by the temperature change, which a drive-frequency proxy
    shows with the opposite sign), or its two halves ('half1', 'half2') when it has one leg."""
    from host_tools.fitting.legs import find_legs, temperature_change
    column, p = log.proxy()
    legs = find_legs(log.t_s, p)
    if len(legs) < 2:
        h = len(log) // 2
        return [("half1", log.select(np.arange(h))), ("half2", log.select(np.arange(h, len(log))))]
    kind_of = "freq" if column == "freq_hz" else "temp"
    kinds = [{"heating": "heat", "cooling": "cool", "hold": "hold"}[temperature_change(s, kind_of)]
             for _, _, s in legs]
    total, seen, out = Counter(kinds), Counter(), []
    for kind, (a, b, _) in zip(kinds, legs):
        seen[kind] += 1
        out.append((kind if total[kind] == 1 else f"{kind}{seen[kind]}", log.select(np.arange(a, b))))
    return out


def splits(pcs) -> list:
    """[(train names, held-out name)]: every piece alone on every other, and leave-one-out
    with three pieces or more."""
    names = [n for n, _ in pcs]
    out = [((a,), b) for a in names for b in names if a != b]
    if len(names) >= 3:
        out += [(tuple(n for n in names if n != b), b) for b in names]
    return out


def run_split(train, held) -> dict:
    """One split: the held-out figures of no compensation, the cubic and the default fit."""
    from host_tools.fitting.baseline import fit_baseline
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.compensate import compensate

    row = {"raw": stats_100s(held.rate_dph, held.t_s, np.ones(len(held), bool))}
    cubic = fit_baseline(train)
    out = compensate(held, cubic)
    row["cubic"] = stats_100s(out.rate_dph, held.t_s, out["valid"] > 0)
    model, _ = fit_default(train)
    out = compensate(held, model)
    valid = out["valid"] > 0
    row["default"] = stats_100s(out.rate_dph, held.t_s, valid)
    row["valid_share"] = float(np.mean(valid))
    row["terms"] = [int(k) for k in model.terms]
    row["chosen"] = model.fit.get("guard", {}).get("chosen", "17-term model")
    row["rate_identified"] = bool(model.fit.get("identifiability", {}).get("rate_terms_identified", False))
    row["ratio"] = row["default"]["std_dph"] / row["cubic"]["std_dph"] if row["cubic"]["std_dph"] > 0 else math.nan
    return row


def logs_in(root) -> list:
    """Every ``*.csv`` run log under ``root`` (sorted), with its set (folder) name."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"measured data folder not found: {root}")
    files = sorted(root.glob("*/*.csv"))
    if not files:
        raise ValueError(f"{root}: no measured run log (*/*.csv)")
    return files


def run(root=DEFAULT_DATA, only: str | None = None, progress=None) -> dict:
    """Every split of every log under ``root`` (``only``: a substring of the file names).
    Returns {"rows": [{"set", "log", "train", "held_out", ...run_split}], "summary"}."""
    from host_tools.golden import runlog
    rows = []
    for path in logs_in(root):
        if only and only not in path.name:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", runlog.RunLogWarning)
            log = runlog.read(path)
        pcs = dict(pieces(log))
        for train, held in splits(list(pcs.items())):
            row = {"set": path.parent.name, "log": path.stem, "train": list(train), "held_out": held}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                row.update(run_split([pcs[n] for n in train], pcs[held]))
            rows.append(row)
            if progress:
                progress(row)
    if not rows:
        raise ValueError(f"{root}: no log matched {only!r}")
    ratios = np.array([r["ratio"] for r in rows], np.float64)
    summary = {"splits": len(rows), "median_ratio": float(np.nanmedian(ratios)), "max_ratio": float(np.nanmax(ratios)),
               "worse_than_cubic_by_5pct": int(np.sum(ratios > 1.05)),
               "min_valid_share": float(min(r["valid_share"] for r in rows)),
               "rate_terms_used": int(sum(r["chosen"] == "17-term model" for r in rows))}
    return {"rows": rows, "summary": summary, "data": os.path.relpath(root) if Path(root).is_absolute() else str(root)}


def table(result: dict) -> str:
    """Markdown table of :func:`run`'s result."""
    lines = ["| log | train -> held out | uncompensated | cubic in temp (flight stack) | `hdrg fit` default | default / cubic | valid | model |",
             "|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        f = "{:.2f} / {:.2f}".format
        lines.append(f"| {r['log']} | {' + '.join(r['train'])} -> {r['held_out']} | {f(r['raw']['std_dph'], r['raw']['rms_dph'])} | "
                     f"{f(r['cubic']['std_dph'], r['cubic']['rms_dph'])} | {f(r['default']['std_dph'], r['default']['rms_dph'])} | "
                     f"{r['ratio']:.2f} | {100 * r['valid_share']:.1f} % | {r['chosen']} |")
    s = result["summary"]
    lines.append("")
    lines.append(f"Std / rms of 100-s means of the held-out output [deg/h]. {s['splits']} splits: default / cubic median "
                 f"{s['median_ratio']:.2f}, max {s['max_ratio']:.2f}; worse than the cubic by > 5 % on "
                 f"{s['worse_than_cubic_by_5pct']}; the 17-term model kept on {s['rate_terms_used']}; valid share >= "
                 f"{100 * s['min_valid_share']:.1f} %.")
    return "\n".join(lines)
