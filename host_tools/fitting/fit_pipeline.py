"""The default fitting pipeline: what `hdrg fit RUN` does without rate options (and what the
`*/default` rows of `hdrg bench accuracy` measure).  It composes the fitter (host_tools.fitting.fit) and
the lag-state block (host_tools.fitting.fit_lag); neither of those imports this module.  The defaults
(host_tools.golden.compensate.DEFAULT_*) are read at call time.  Several training runs: each run's
offset per coefficient bank is removed before the fit (:func:`fit_without_run_offsets`)."""
from __future__ import annotations

import numpy as np

from host_tools.golden import compensate
from host_tools.golden.regressors import regressor_matrix
from host_tools.fitting.fit import fit_auto_rate, fit_logs
from host_tools.fitting.fit_lag import add_lag_block

RUN_OFFSET_PASSES = 2   # backfitting passes of the per-run offsets (docs/ACCURACY.md "Several training runs")


def fit_default(logs, terms=None, *, drop_unidentifiable=None, lag_block=None, cv_blocks=8, rate_prefer="default",
                run_offsets="auto", **config_kw):
    """What `hdrg fit` does without rate flags: mode-reversal logs with
    host_tools.golden.compensate.DEFAULT_RATE_SELECTION_MR 'auto' -> :func:`fit_auto_rate`, else
    :func:`fit_logs` with the default configuration (host_tools.golden.compensate.fit_config_from_logs
    with ``config_kw``).  Then, with ``lag_block`` 'auto' (None: host_tools.golden.compensate.DEFAULT_LAG_BLOCK;
    'off' skips it) and no aux given, the lag-state block of the proxy as k7 when cross-validation
    supports it (host_tools.fitting.fit_lag.add_lag_block).  ``drop_unidentifiable`` None: each path's own default
    (auto True, else False); ``cv_blocks``: the time blocks of cross-validation on a single run;
    ``rate_prefer``: fit_auto_rate's ``prefer`` ('default': host_tools.fitting.fit.RATE_PREFERRED;
    None: plain least CV rms, the start of `hdrg diagnose`).  ``run_offsets`` 'auto': with several
    runs, :func:`fit_without_run_offsets` around all of this; 'off': never.  Returns (model, FitResult)."""
    if run_offsets not in ("auto", "off"):
        raise ValueError(f"run_offsets must be 'auto' or 'off', not {run_offsets!r}")
    logs = list(logs)
    if run_offsets == "auto":
        return fit_without_run_offsets(logs, lambda lg: fit_default(
            lg, terms, drop_unidentifiable=drop_unidentifiable, lag_block=lag_block, cv_blocks=cv_blocks,
            rate_prefer=rate_prefer, run_offsets="off", **config_kw))
    lag_block = compensate.DEFAULT_LAG_BLOCK if lag_block is None else lag_block
    if lag_block not in ("auto", "off"):
        raise ValueError(f"lag_block must be 'auto' or 'off', not {lag_block!r}")
    lag = lag_block == "auto" and config_kw.get("aux") is None
    reversal = bool(logs) and all(log.reversal for log in logs)
    selection = compensate.DEFAULT_RATE_SELECTION_MR if reversal else compensate.DEFAULT_RATE_SELECTION_FTR
    rate_given = any(config_kw.get(k) is not None for k in ("rate_estimator", "n", "shift"))
    if selection == "auto" and logs and not rate_given:
        model, res = fit_auto_rate(logs, terms, drop_unidentifiable=drop_unidentifiable is not False,
                                   cv_blocks=cv_blocks, prefer=rate_prefer, **config_kw)
    else:
        model, res = fit_logs(logs, compensate.fit_config_from_logs(logs, **config_kw), terms, blocks=True if lag else None,
                              drop_unidentifiable=bool(drop_unidentifiable), cv_blocks=cv_blocks)
    if lag:
        model, res = add_lag_block(logs, model, res, terms, cv_blocks=cv_blocks,
                                   drop_unidentifiable=drop_unidentifiable is not False)
    return model, res


def run_offsets(logs, model) -> list:
    """Per log, per coefficient bank (one for FTR, mode 1 and mode 2 for regress_first): the mean
    residual [deg/h] of ``model`` over the samples its fit uses (``Prepared.used``), target minus
    the model's regression (no pairing).  combine_first models: [] (their target is a combination
    of windows, not one run's rate)."""
    cfg = model.config
    two = cfg.reversal is not None and cfg.reversal.order == "regress_first"
    if cfg.reversal is not None and not two:
        return []
    out = []
    for log in logs:
        pr = compensate.prepare(log, cfg)
        X = regressor_matrix(pr.u, pr.v, pr.z)
        banks = ((pr.used & (pr.mode == 1), model.coef), (pr.used & (pr.mode == 2), model.coef_mode2)) if two \
            else ((pr.used, model.coef),)
        out.append([float(np.mean(pr.y[m] - X[m] @ np.asarray(c, np.float64))) if m.any() else 0.0 for m, c in banks])
    return out


def _shifted(log, offsets):
    """``log`` with its rate moved so that the fit target of each bank loses its offset (one bank:
    target y = rate; two banks (regress_first): y = s * rate, so mode 2 moves the other way)."""
    rate = np.array(log.rate_dph, np.float64)
    if len(offsets) == 2:
        mode = np.asarray(log.mode)
        rate[mode == 1] -= offsets[0]
        rate[mode == 2] += offsets[1]
    else:
        rate -= offsets[0]
    return log.with_columns(rate_dph=rate)


def fit_without_run_offsets(logs, fit):
    """Several training runs share one coefficient set, but each power-on moves the bias by its own
    offset (the damping change's offset, the turn-on offset).  Backfitting: ``fit(logs)`` ->
    (model, FitResult); then RUN_OFFSET_PASSES times: per run and bank the mean residual
    (:func:`run_offsets`) is removed from that run's rate and ``fit`` repeated on the shifted runs.
    The model's k0 stays the level of all runs together; every fit decision (rate estimator, lag
    block, terms, cross-validation over runs) is taken on the shifted runs.  model.fit
    ``run_offsets``: {"passes", "offsets_dph": per run the total offset removed per bank, "runs"}.
    One run: ``fit(logs)`` as it is (no offset to tell from the model's k0).
    Measured on foreign devices (docs/ACCURACY.md "Several training runs")."""
    model, res = fit(logs)
    if len(logs) < 2:
        return model, res
    total = 0.0
    shifted = logs
    for _ in range(RUN_OFFSET_PASSES):
        off = run_offsets(shifted, model)
        if not off:
            return model, res
        total = total + np.asarray(off)
        shifted = [_shifted(log, o) for log, o in zip(shifted, off)]
        model, res = fit(shifted)
    model.fit["run_offsets"] = {"passes": RUN_OFFSET_PASSES, "offsets_dph": total.tolist(),
                                "runs": [log.source for log in logs],
                                "method": "per run and coefficient bank, the mean training residual removed "
                                          "from the run before the fit (host_tools.fitting.fit_pipeline)"}
    return model, res
