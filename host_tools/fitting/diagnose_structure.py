"""Whole-model structural steps of the closed loop (host_tools.fitting.diagnose, structure phase): the
mode-reversal pipeline's order/combiner (regress-then-reverse with each combiner) and its settling
window after each exchange, each compared by refitting the whole model in every CV fold (folds:
host_tools.fitting.cv) and scoring THE held-out error (host_tools.fitting.diagnose_confirm.step_errors), then
confirmed on the held-out runs like every step.  Times in seconds."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from host_tools.fitting.cv import fold_ids
from host_tools.fitting.diagnose_confirm import (CONFIRM_MIN_DROP, clean_stats, heldout_score, step_metric, confirmed_on_holdout,
                                         error_stats, material_on_holdout, pooled_step_errors, step_errors,
                                         confirmation, LEAVING_ONE_OUT)
from host_tools.fitting.fit import fit_logs


ORDER_ALTERNATIVES = ("none", "pair", "trend")   # regress_first with each combiner


def _fold_logs(train, cv_blocks, cv_folds) -> list:
    """(training logs, held-out logs) per CV fold for whole-model refits: leave one run out, or
    with a single run its ``cv_blocks`` contiguous blocks dealt round-robin into ``cv_folds``
    folds (RunLog.select: the blocks become gap-separated segments)."""
    if len(train) >= 2:
        return [([g for j, g in enumerate(train) if j != f], [train[f]]) for f in range(len(train))]
    log = train[0]
    fold = fold_ids(len(log), cv_blocks, cv_folds)
    return [([log.select(fold != k)], [log.select(fold == k)]) for k in range(cv_folds)]


def order_step(train, hold, evals, cfg, model, cv_blocks, cv_folds):
    """The structural candidate 'regress-then-reverse' (host_tools.golden.reversal order regress_first:
    two coefficient banks by mode, the combiner applied to the residual) with each combiner of
    ORDER_ALTERNATIVES, the current terms and aux generators kept (:func:`_whole_model_step`).
    Returns (entry, model) or (None, None)."""
    from host_tools.golden.reversal import ReversalConfig
    rc = cfg.reversal
    alts = [({"order": "regress_first", "combiner": comb},
             replace(cfg, reversal=ReversalConfig(comb, rc.max_stale_s, rc.settle_s, order="regress_first")))
            for comb in ORDER_ALTERNATIVES if not (rc.order == "regress_first" and comb == rc.combiner)]
    return _whole_model_step("reversal_order", alts, train, hold, evals, cfg, model, cv_blocks, cv_folds)


SETTLE_FACTORS = (2.0, 4.0)   # settle-window candidates: the current window x these (2 s, 4 s from none)


def settle_step(train, hold, evals, cfg, model, cv_blocks, cv_folds):
    """The structural candidate 'settling window' (ReversalConfig.settle_s: the seconds after each
    mode exchange that the fit and the output skip): the current window x SETTLE_FACTORS.  A
    device whose loop settles for longer than the window leaves a transient after every exchange
    that is the mode-reversal pipeline's structure, not an effect (:func:`_whole_model_step`)."""
    rc = cfg.reversal
    cur = rc.settle_s
    values = sorted({round((cur if cur > 0 else 1.0) * f, 3) for f in SETTLE_FACTORS})
    alts = [({"settle_s": v}, replace(cfg, reversal=replace(rc, settle_s=v))) for v in values if v > cur]
    return _whole_model_step("reversal_settle", alts, train, hold, evals, cfg, model, cv_blocks, cv_folds)


def _whole_model_step(family, alts, train, hold, evals, cfg, model, cv_blocks, cv_folds):
    """A structural change of the combiner pipeline, ``alts`` = [(params, config)]: every fold
    (:func:`_fold_logs`) refits the whole model (current and alternative; terms and aux generators
    kept) on its training part and scores both on its held-out part by THE held-out error
    (:func:`step_errors`: std of 100-s averages, 1-s where undefined, on the samples valid under
    both).  The best alternative is a step when it lowers the CV error by >= CONFIRM_MIN_DROP in
    total and in a strict majority of folds; then it is confirmed on the held-out runs like every
    step (with none and several training runs: on the folds' left-out runs, pooled).  Returns (entry, model), ({"skipped": why}, None) or (None, None)."""
    terms = tuple(model.terms)
    folds = _fold_logs(train, cv_blocks, cv_folds)
    try:
        base_fits = [fit_logs(tr, cfg, terms, drop_unidentifiable=True)[0] for tr, _ in folds]
    except ValueError:
        return None, None
    rows = []
    for params, alt in alts:
        e0, e1, pairs = [], [], []
        try:
            for (tr, te), mb in zip(folds, base_fits):
                ma = fit_logs(tr, alt, terms, drop_unidentifiable=True)[0]
                sb, sa = step_errors(te, mb, ma)
                pairs.append((sb, sa))
                e0.append(heldout_score(sb)[0])
                e1.append(heldout_score(sa)[0])
        except ValueError:
            continue
        if any(e is None for e in e0 + e1):
            continue
        e0, e1 = np.array(e0), np.array(e1)
        rows.append({"params": params, "cfg": alt, "gain": float(1.0 - e1.sum() / e0.sum()), "pairs": pairs,
                     "folds_improved": int(np.sum(e1 < e0)), "folds": len(folds)})
    if not rows:
        return None, None
    best = max(rows, key=lambda r: r["gain"])
    if not (best["gain"] >= CONFIRM_MIN_DROP and best["folds_improved"] > len(folds) // 2):
        return None, None
    alt_model, _ = fit_logs(train, best["cfg"], terms, drop_unidentifiable=True)
    label = f"{family}({', '.join(str(v) for v in best['params'].values())})"
    try:        # the model the loop writes must go to the firmware path (hdrg quantize)
        from host_tools.fixed.quantize import quantize
        quantize(alt_model, n_random=100)
    except (ValueError, ArithmeticError) as exc:
        return {"skipped": f"{label} gains {best['gain']:.3f} in CV but does not quantize on this build: {exc}"}, None
    before, after = error_stats(evals, model), error_stats(evals, alt_model)
    where = confirmation(train, hold)      # LEAVING_ONE_OUT: the folds left one training run out each
    cb, ca = pooled_step_errors(best["pairs"]) if where == LEAVING_ONE_OUT else step_errors(evals, model, alt_model)
    checked = where is not None
    confirmed = confirmed_on_holdout(cb, ca) if checked else None
    entry = {"effect": family, "params": dict(best["params"]), "kind": "structure",
             "before": clean_stats(before), "after": clean_stats(after), "confirmed": confirmed,
             "material": (confirmed and material_on_holdout(cb, ca)) if checked else None,
             "heldout_error": step_metric(cb, ca),
             "train_before": clean_stats(error_stats(train, model)), "train_after": clean_stats(error_stats(train, alt_model)),
             "cv_gain": best["gain"], "threshold": CONFIRM_MIN_DROP, "refined_from": None,
             "folds_improved": best["folds_improved"], "folds": best["folds"],
             "ranking": [{"label": f"{family}({', '.join(str(v) for v in r['params'].values())})", "family": family,
                          "gain": r["gain"], "folds_improved": r["folds_improved"], "folds": r["folds"]}
                         for r in sorted(rows, key=lambda r: -r["gain"])],
             "null_max": [], "aux": alt_model.config.aux.to_dict(), "rate": alt_model.config.rate.to_dict(),
             "before_runs": before["runs"], "after_runs": after["runs"],
             "status": (f"confirmed {where}" if confirmed else "accepted (no held-out runs)") if confirmed is not False
             else f"not confirmed {where}: reverted (the model stays the last confirmed one)"}
    return entry, alt_model
