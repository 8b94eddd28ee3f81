"""Report files of the closed loop (host_tools.fitting.diagnose, step 6 of its module doc): DIR/diagnose.json,
DIR/diagnose.md, DIR/model.json and the figures (residual vs the candidate, Allan deviation and
spectrum before/after; matplotlib), and the one-line verdict detail.  Errors in deg/h."""
from __future__ import annotations

import json
import os

import numpy as np

from firmware_ref.terms import K_AUX, TERM_NAMES
from host_tools.atomic import atomic_open, atomic_path
from host_tools.golden.compensate import prepare, residual
from host_tools.fitting.diagnose_confirm import STAT_KEYS, fmt_value, residuals
from host_tools.fitting.diagnose_noise import allan_bridged, filled
from host_tools.fitting.diagnose_scan import TIE_TOLERANCE
from host_tools.golden.model import jsonable
from host_tools.golden.regressors import generator_values


VERDICTS = ("effect found", "model structure improved", "minor improvement confirmed", "no confirmed effect",
            "no significant missing effect", "hdrg fit's model kept")
# the last: steps held one by one, but the final model lost to hdrg fit's on a figure (diagnose.versus_fit)


def is_minor(step) -> bool:
    """A kept effect step below EFFECT_RULE's bar: confirmed on held-out, kind 'effect', not material."""
    return bool(step["confirmed"] and step["kind"] == "effect" and step.get("material") is False)


def verdict_of(iterations) -> str:
    """The loop's verdict (:data:`VERDICTS`, strongest first) from its steps: "effect found" when a
    kept step of kind 'effect' is material (diagnose_confirm.EFFECT_RULE; ``material`` None = no
    held-out runs, counts), "model structure improved" when a structure step was kept, "minor
    improvement confirmed" when only minor effect steps were kept, "no confirmed effect" when
    steps were tried and none kept, "no significant missing effect" when none passed."""
    kept = [e for e in iterations if e["confirmed"] is not False]
    if any(e["kind"] == "effect" and e.get("material") is not False for e in kept):
        return VERDICTS[0]
    if any(e["kind"] == "structure" for e in kept):
        return VERDICTS[1]
    if kept:
        return VERDICTS[2]
    return VERDICTS[3] if iterations else VERDICTS[4]


GAP_WARN = 10.0   # the report warns when the final held-out error is >= this x its training error


def generalization(train_dph: float, holdout_dph: float) -> dict:
    """The final model's held-out error against its training error (the loop's metric, deg/h):
    {"train_dph", "holdout_dph", "ratio", "warning": text or None}.  A ratio >= GAP_WARN means the
    model fits its training runs far better than a run it has not seen, and the cause is not in the
    training residual, which is all the loop selects on.  Chosen on the loop bench's calibration
    seed 1 (base models: clean FTR runs 4/20 at >= 10 x, clean MR 0/20; docs/LOOP.md)."""
    ratio = holdout_dph / train_dph if train_dph > 0 else float("inf")
    warning = None
    if ratio >= GAP_WARN:
        warning = (f"the held-out error ({holdout_dph:.3g} deg/h) is {ratio:.1f} x the training error "
                   f"({train_dph:.3g} deg/h): the model fits its training runs far better than a run it "
                   f"has not seen, and what limits it there is not in the training residual, which is all "
                   f"the loop selects on; train on more runs (another chamber rate, another power-on)")
    return {"train_dph": train_dph, "holdout_dph": holdout_dph, "ratio": ratio, "warning": warning}


SEVERAL_RUNS_CAVEAT = (
    "{n} training runs: the cross-validation leaves one run out.  The loop's thresholds were calibrated "
    "with ONE training run.  Measured with two (4 and 3 degC/min, one power-on; `hdrg bench loop "
    "--second-train 3`, seeds 0, 1 and 2, 390 runs, docs/LOOP.md): the final held-out error x0.65 .. x0.68 "
    "of the one-run loop's (geometric means), the family named in 92 of the 111 runs whose effect doubles "
    "the error against 88 of 104, and 'effect found' on 4 of 130 clean runs (0 with one run; each improves "
    "an independent third run; 3 of the 4 are a turn-on with the time constant of the simulated device's "
    "self-heating after power-on, which one run cannot fit and two can): read an effect found from several "
    "runs as a reproducible feature of this device (a turn-on: most likely self-heating, which repeats at "
    "every power-on from the same soak), and check it on another held-out run")


def extrapolation(stats) -> list:
    """'source: message' for every extrapolation or saturation in ``stats`` (diagnose_confirm.error_stats
    of a model on the held-out runs; each run's ``problems``, host_tools.golden.flags.problems: proxy,
    rate or aux input outside the model's range): a held-out error measured where the model
    extrapolates judges the extrapolation as much as the model, and the report must say so."""
    return [f"{r['run']}: {m}" for r in stats["runs"] for m in r.get("problems", [])]


def not_scanned(logs) -> list:
    """'column: lacking in run ...' for every aux_* or temp_c column that some of ``logs`` (training and
    held-out) have and others lack: the candidates that read it (aux, second thermometer) are not
    tried, which the report must say rather than let 'no effect' stand for 'not looked at'."""
    cols = [set(log.columns) for log in logs]
    if not cols:
        return []
    partial = sorted({c for s in cols for c in s if c.startswith("aux_") or c == "temp_c"} - set.intersection(*cols))
    return [f"{c}: lacking in {', '.join(log.source for log in logs if c not in log.columns)}; the candidates that "
            f"read it were not tried" for c in partial]


def several_runs_caveat(n_train: int):
    """The caveat of a loop trained on several runs (text), or None for one run."""
    return SEVERAL_RUNS_CAVEAT.format(n=n_train) if n_train > 1 else None


def line_or_drift(family, params, train_logs):
    """The caveat of a periodic step whose period the training runs cannot tell from a slow drift:
    fewer than two cycles in every gap-free training segment (``RunLog.segments``).  A sinusoid
    that long fitted across a gap (e.g. two cooling passes around a held-out heating leg) is a
    smooth function of time there; the step is kept on its held-out result, the name says less
    than it seems.  None when the period fits twice in some segment, or for other families."""
    if family != "periodic" or not params.get("period_s"):
        return None
    longest = 0.0
    for log in train_logs:
        t = np.asarray(log.t_s, np.float64)
        ends = list(log.segments[1:]) + [len(t)]
        longest = max([longest] + [float(t[e - 1] - t[b]) for b, e in zip(log.segments, ends) if e > b])
    if 2.0 * params["period_s"] <= longest:
        return None
    return (f"period {params['period_s']:.0f} s: fewer than two cycles in any gap-free training segment "
            f"(longest {longest:.0f} s), so a line and a slow drift in time cannot be told apart; "
            f"read it as a time-varying term of unknown shape")


def kept_step_notes(entry) -> list:
    """What a kept step's name does not say (its status and the verdict detail): the ``caveat``
    of :func:`line_or_drift` and the ``rivals`` (diagnose_scan.rivals).  [] for a reverted step."""
    if entry["confirmed"] is False:
        return []
    notes = [entry["caveat"]] if entry.get("caveat") else []
    if entry.get("rivals"):
        notes.append(f"the training runs explain it about as well by {', '.join(entry['rivals'])} (CV gain within "
                     f"{TIE_TOLERANCE:.0%}): the held-out runs confirm the step, not which of these the device has")
    return notes


def verdict_detail_text(iterations, where="on held-out") -> str:
    """The verdict's detail: each step's fate; ``where`` the steps were confirmed ('on held-out',
    'leaving one training run out'; None: not confirmed)."""
    if not iterations:
        return "no candidate passed the selection rule on the training runs"
    parts = []
    for k, e in enumerate(iterations, 1):
        tag = {True: f"confirmed {where}", False: f"not confirmed {where} (reverted)",
               None: "not confirmed (no held-out runs)"}[e["confirmed"]]
        if is_minor(e):
            tag += " (minor: kept, not named as an effect)"
        tag += "".join(f" ({n})" for n in kept_step_notes(e))
        parts.append(f"step {k} {e['effect']}: {tag}")
    kept = [k for k, e in enumerate(iterations, 1) if e["confirmed"] is not False]
    final = f"final model: after step {kept[-1]}" if kept else "final model: the base model"
    return "; ".join(parts) + "; " + final


def _stats_line(s):
    return " | ".join(fmt_value(s.get(k)) for k in STAT_KEYS)


VERSUS_LABELS = {"std100_dph": "std 100 s [deg/h]", "std_dph": "std 1 s [deg/h]",
                 "start_std_dph": "start-up 1 sigma [deg/h]", "start_rep_dph": "0-5 min repeatability [deg/h]",
                 "served_share": "served share"}
STAT_HEADERS = {"std_dph": "std 1 s", "pp_dph": "p-p 1 s", "std100_dph": "std 100 s", "pp100_dph": "p-p 100 s",
                "rms_dph": "rms", "start_std_dph": "start 1 sigma 100 s", "start_rep_dph": "0-5 min repeatability", "served_share": "served"}
TABLE_HEADER = ("iteration", "effect", "params", *(STAT_HEADERS[k] for k in STAT_KEYS), "CV gain", "threshold",
                "held-out")


def _cell(text) -> str:
    """A table cell or a run name: one line, escaped for Markdown (host_tools.fitting.report.md_text:
    a parameter or status text cannot split the row, a run name cannot start HTML)."""
    from host_tools.fitting.report import md_text
    return md_text(" ".join(str(text).split()))


def _row(k, effect, params, stats, gain, threshold, status) -> str:
    """One row of diagnose.md's main table: as many cells as :data:`TABLE_HEADER`."""
    cells = [str(k), _cell(effect), _cell(params), *(fmt_value(stats.get(key)) for key in STAT_KEYS),
             "" if gain is None else fmt_value(gain), "" if threshold is None else fmt_value(threshold), _cell(status)]
    return "| " + " | ".join(cells) + " |"


def write_report(report, model, out_dir, train, hold, plots=True) -> None:
    """DIR/diagnose.json, DIR/diagnose.md, DIR/model.json and (plots) DIR/iter<k>_*.png."""
    os.makedirs(out_dir, exist_ok=True)
    evals = hold if hold else train
    for k, entry in enumerate(report["iterations"], 1):
        figs = []
        if plots and "_plot" in entry:
            figs = _plots(k, entry["_plot"], train, evals, out_dir)
        entry["figures"] = figs
    model.to_json(os.path.join(out_dir, "model.json"))
    report["model"] = "model.json"
    doc = jsonable(report, skip_private=True)
    with atomic_open(os.path.join(out_dir, "diagnose.json"), "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1, allow_nan=False)
        fh.write("\n")
    with atomic_open(os.path.join(out_dir, "diagnose.md"), "w", encoding="utf-8") as fh:
        fh.write(markdown(doc, model))


def markdown(doc, model) -> str:
    """The human report (diagnose.md) of a report dict."""
    on = doc["evaluated_on"]
    lines = ["# hdrg diagnose", "",
             f"Training runs: {', '.join(_cell(os.path.basename(s)) for s in doc['train'])}  ",
             "Held-out runs: " + (", ".join(_cell(os.path.basename(s)) for s in doc["holdout"])
                                  or "(none: figures on the training runs)"),
             "", f"**Verdict: {doc['verdict']}**", "",
             "Errors in deg/h on the " + ("held-out" if on == "holdout" else "training") + " runs: stability "
             "(1 sigma) and variation (p-p) of 1-s and 100-s averages of the compensated output.", "",
             "| " + " | ".join(TABLE_HEADER) + " |",
             "|---|---|---|" + "---:|" * (len(STAT_KEYS) + 2) + "---|"]
    first = doc["baseline"][on]
    terms = doc["settings"]["terms"]
    terms = ", ".join(f"k{k}" for k in terms) if isinstance(terms, (list, tuple)) else terms
    lines.append(_row(0, "(base model)", f"terms {terms}", first, None, None, ""))
    for k, it in enumerate(doc["iterations"], 1):
        params = ", ".join(f"{a}={fmt_value(b) if isinstance(b, float) else b}" for a, b in it["params"].items())
        lines.append(_row(k, it["effect"], params, it["after"], it.get("cv_gain"), it.get("threshold"), it["status"]))
    lines += ["", f"{doc['verdict_detail']}.  Confirmation: {doc['confirm_rule']}."]
    if (doc.get("taken_from_fit") or {}).get("text"):
        lines += ["", f"Before the loop: {doc['taken_from_fit']['text']}."]
    if doc.get("final_is"):
        lines += ["", f"The model written: {doc['final_is']} (the base model is hdrg fit's model of the training runs)."]
    vs = doc.get("versus_fit") or {}
    if vs.get("figures"):
        cells = "; ".join(f"{VERSUS_LABELS.get(k, k)} {fmt_value(f['fit'])} -> {fmt_value(f['loop'])}"
                          for k, f in vs["figures"].items() if f["fit"] is not None and f["loop"] is not None)
        lines += ["", f"Against hdrg fit's model ({vs['on']}; hdrg fit -> the loop): {cells}"
                      + (f".  Lost on {vs['why']}: hdrg fit's model is written." if vs["kept"] == "fit" else ".")]
    elif vs.get("why"):
        lines += ["", f"Against hdrg fit's model: {vs['why']}."]
    if doc.get("fit_block_replaced"):
        fb = doc["fit_block_replaced"]
        lines += ["", f"Second pass: {fb['why']}: {fmt_value(fb['with_block'])} -> {fmt_value(fb['without_block'])} deg/h "
                      f"(std of 100-s averages); the first pass's steps: "
                      + (", ".join(f"{it['effect']} ({'kept' if it['confirmed'] else 'reverted'})"
                                   for it in fb["with_block_iterations"]) or "none") + "."]
    fl = doc.get("cubic_floor") or {}
    if fl.get("cubic_dph") is not None and fl.get("model_dph") is not None:
        lines += ["", f"Floor: the flight stack's cubic in temperature gives {fmt_value(fl['cubic_dph'])} deg/h on the held-out "
                      f"runs, the loop's model {fmt_value(fl['model_dph'])} deg/h (std of 100-s averages, samples valid under both)"
                  + (f"; above {fl['limit']:g} x the cubic, so the cubic is the final model." if fl["replaced"] else ".")]
    if (doc.get("generalization") or {}).get("warning"):
        lines += ["", f"**Warning:** {doc['generalization']['warning']}."]
    for m in doc.get("holdout_in_training") or []:
        lines += ["", f"**Warning:** {m}."]
    for m in doc.get("not_scanned") or []:
        lines += ["", f"**Not scanned:** {m}."]
    for m in doc.get("extrapolation") or []:
        lines += ["", f"**Extrapolation (final model on the held-out run):** {m}."]
    if doc.get("several_runs"):
        lines += ["", f"**Several training runs:** {doc['several_runs']}."]
    for a in (doc.get("artifacts") or {}).get("lines", []):
        lines += ["", f"Line at {a['period_s']:.4g} s ({a['at']}, {a['amp_dph']:.3g} deg/h): {a['cause']}.  "
                      f"Structural fix: {a['structural_fix']}."]
    nf = doc["noise_floor"]
    lines += ["", f"Noise floor (white noise of the residual): {fmt_value(nf['std_dph'])} deg/h at 1 s, "
                  f"{fmt_value(nf['std100_dph'])} deg/h at 100 s.", "",
              f"Selection rule: {doc['rule']}.", ""]
    if doc.get("stopped"):
        st = doc["stopped"]
        lines += [f"Stopped: {st['reason']}.", ""]
        if st.get("not_offered"):
            lines += [f"Firmware capacity: {st['not_offered']}.", ""]
        if st.get("ranking"):
            lines += ["Best remaining candidates (CV gain, folds improved):", ""]
            lines += [f"* {r['label']}: {r['gain']:.4f} ({r['folds_improved']}/{r['folds']})"
                      for r in st["ranking"][:6]]
            lines.append("")
    for k, it in enumerate(doc["iterations"], 1):
        lines += [f"## Iteration {k}: {it['effect']}", "",
                  f"CV gain {it['cv_gain']:.4f} (threshold {it['threshold']:.4f}), improves "
                  f"{it['folds_improved']} of {it['folds']} folds.  Training: "
                  f"std 100 s {fmt_value(it['train_before']['std100_dph'])} -> {fmt_value(it['train_after']['std100_dph'])}; "
                  f"{'held-out' if on == 'holdout' else 'training'}: {fmt_value(it['before']['std100_dph'])} -> "
                  f"{fmt_value(it['after']['std100_dph'])} deg/h.", "", "Ranking:", ""]
        lines += [f"* {r['label']}: {r['gain']:.4f} ({r['folds_improved']}/{r['folds']})" for r in it["ranking"][:8]]
        lines.append("")
        for f in it.get("figures", []):
            lines.append(f"![{f}]({f})")
        lines.append("")
    ch = doc.get("characterization") or {}
    for which in ("train", "holdout"):
        for c in ch.get(which, []) or []:
            lines += [f"### Residual of the base model: {_cell(os.path.basename(c['source']))} ({which})", "",
                      f"rms {fmt_value(c['rms_dph'])} deg/h; Allan deviation above 2x the white-noise line at "
                      f"tau = {', '.join(fmt_value(t) for t in c['allan']['structure_taus_s']) or 'none'} s; "
                      f"spectrum lines: {', '.join(fmt_value(ln['period_s']) + ' s' for ln in c['lines']) or 'none'}.", ""]
            dep = sorted(c["dependence"].items(), key=lambda kv: -abs(kv[1]["corr"]))
            lines.append("Dependence (correlation, range of binned means in deg/h): " + "; ".join(
                f"{name} {d['corr']:+.2f} / {d['range_dph']:.3g}" for name, d in dep))
            lines.append("")
    lines += ["Final model: model.json (terms " + ", ".join(f"k{k} ({TERM_NAMES[k]})" for k in model.terms) + ").", ""]
    return "\n".join(lines)


def _plots(k, plot_info, train, evals, out_dir) -> list:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.signal import welch

    before_model, after_model, best = plot_info
    files = []
    # residual vs the candidate's fitted contribution (training runs)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    after_aux = after_model.config.aux
    for log, (pr, r) in zip(train, residuals(train, before_model)):
        if best["terms"]:
            cols = np.column_stack([generator_values(log, t, after_model.config.rate.fs) for t in best["terms"]])
            weights = [t2["weight"] for t2 in after_aux.terms[-len(best["terms"]):]]
            k7 = after_model.coef[K_AUX]
            if after_model.coef_mode2 is not None:      # two banks: the k7 of the sample's mode
                k7 = np.where(np.asarray(log.mode) == 2, after_model.coef_mode2[K_AUX], k7)
            x = cols @ np.asarray(weights) * k7
            xlabel = f"fitted {best['label']} [deg/h]"
        else:
            x = residual(prepare(log, after_model), after_model)[0] - r
            xlabel = f"{best['label']}: change of the residual [deg/h]"
        v = pr.valid
        ax.plot(x[v], r[v], ".", ms=1, alpha=0.4, label=f"training run {os.path.basename(log.source)}")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("residual before [deg/h]")
    ax.set_title(f"iteration {k}: residual vs {best['label']}", fontsize=9)
    ax.grid(True, alpha=0.3)
    leg = ax.legend(fontsize=7, markerscale=8, loc="best")
    for h in getattr(leg, "legend_handles", getattr(leg, "legendHandles", [])):
        h.set_alpha(1.0)
    fig.tight_layout()
    files.append(f"iter{k}_candidate.png")
    with atomic_path(os.path.join(out_dir, files[-1])) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    # Allan and spectrum before/after (evaluation runs)
    fig1, ax1 = plt.subplots(figsize=(6, 4.5))
    fig2, ax2 = plt.subplots(figsize=(6, 4.5))
    for name, m, style in (("before", before_model, "--"), ("after", after_model, "-")):
        for log, (pr, r) in zip(evals, residuals(evals, m)):
            a = allan_bridged(r, log.t_s, pr.valid)
            label = f"{os.path.basename(log.source)} {name}"
            if a["tau_s"]:
                ax1.loglog(a["tau_s"], a["adev_dph"], style, label=label)
            g = filled(r, pr.valid)
            nper = min(len(g), max(256, len(g) // 4))
            if nper >= 16:
                f, p = welch(g, fs=after_model.config.rate.fs, nperseg=nper)
                ax2.loglog(f[1:], p[1:], style, label=label, lw=0.8)
    ax1.set_xlabel("averaging time [s]")
    ax1.set_ylabel("Allan deviation of the residual [deg/h]\n(exchanges bridged)")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=7)
    ax2.set_xlabel("frequency [Hz]")
    ax2.set_ylabel("PSD of the residual [(deg/h)^2/Hz]")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    for fig, name in ((fig1, "allan"), (fig2, "spectrum")):
        fig.tight_layout()
        files.append(f"iter{k}_{name}.png")
        with atomic_path(os.path.join(out_dir, files[-1])) as tmp:
            fig.savefig(tmp, dpi=90, format="png")
        plt.close(fig)
    return files
