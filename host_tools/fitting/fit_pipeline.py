"""The default fitting pipeline: what `hdrg fit RUN` does without rate options (and what the
`*/default` rows of `hdrg bench accuracy` measure).  It composes the fitter (host_tools.fitting.fit) and
the lag-state block (host_tools.fitting.fit_lag); neither of those imports this module.  The defaults
(host_tools.golden.compensate.DEFAULT_*) are read at call time."""
from __future__ import annotations

from host_tools.golden import compensate
from host_tools.fitting.fit import fit_auto_rate, fit_logs
from host_tools.fitting.fit_lag import add_lag_block


def fit_default(logs, terms=None, *, drop_unidentifiable=None, lag_block=None, cv_blocks=8, rate_prefer="default",
                **config_kw):
    """What `hdrg fit` does without rate flags: mode-reversal logs with
    host_tools.golden.compensate.DEFAULT_RATE_SELECTION_MR 'auto' -> :func:`fit_auto_rate`, else
    :func:`fit_logs` with the default configuration (host_tools.golden.compensate.fit_config_from_logs
    with ``config_kw``).  Then, with ``lag_block`` 'auto' (None: host_tools.golden.compensate.DEFAULT_LAG_BLOCK;
    'off' skips it) and no aux given, the lag-state block of the proxy as k7 when cross-validation
    supports it (host_tools.fitting.fit_lag.add_lag_block).  ``drop_unidentifiable`` None: each path's own default
    (auto True, else False); ``cv_blocks``: the time blocks of cross-validation on a single run;
    ``rate_prefer``: fit_auto_rate's ``prefer`` ('default': host_tools.fitting.fit.RATE_PREFERRED;
    None: plain least CV rms, the start of `hdrg diagnose`).  Returns (model, FitResult)."""
    logs = list(logs)
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
