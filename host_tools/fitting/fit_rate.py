"""Rate estimator 'auto' of the host fitter: every candidate estimator fitted with
cross-validation (host_tools.fitting.fit.fit_logs), the preferred one kept unless another is
clearly better (:func:`fit_auto_rate`)."""
from __future__ import annotations

import numpy as np

from host_tools.fitting.fit import UnidentifiableError, fit_logs

# candidates of the rate estimator 'auto' (estimator, n, shift), host_tools.golden.rate
RATE_CANDIDATES = (("diff", 8, 4), ("diffn", 16, 4), ("lsq", 32, 4), ("iir", 8, 7), ("iir", 8, 9))
# 'auto' keeps RATE_PREFERRED (iir 9, the smoothest rate) unless another candidate's CV rms is below
# (1 - RATE_PREFER_MARGIN) x its own: in-run CV hardly tells them apart (docs/ACCURACY.md "Rate preference").
RATE_PREFERRED = ("iir", 8, 9)
RATE_PREFER_MARGIN = 0.5


def _rate_label(est, n, shift):
    return {"diff": "diff", "diffn": f"diffn n={n}", "lsq": f"lsq n={n}", "iir": f"iir shift={shift}"}[est]


def fit_auto_rate(logs, terms=None, *, candidates=RATE_CANDIDATES, cv_blocks=8, significance=None, min_gain=0.02,
                  drop_unidentifiable=True, samples="own", prefer="default", prefer_margin=None, **config_kw):
    """Rate estimator 'auto': for every candidate (estimator, n, shift) build the config
    (host_tools.golden.compensate.fit_config_from_logs with ``config_kw``), fit ``terms`` with
    cross-validation over the runs (one run: ``cv_blocks`` time blocks, see :func:`fit_logs`), and
    keep the ``prefer`` candidate ('default': RATE_PREFERRED; None: no preference) unless the
    candidate of least cross-validated rms beats it by ``prefer_margin`` (None: RATE_PREFER_MARGIN),
    i.e. has a CV rms < (1 - margin) x the preferred one's; then that one.  A preferred candidate
    that is not among ``candidates`` or cannot be fitted leaves the plain least-CV choice.

    ``samples`` 'own' (default): each candidate is fitted and scored on its own used samples (an
    estimator with a longer warm-up is scored on fewer, later samples: iir 9 skips 1024 samples,
    the power-on transient of a run).  'common': every candidate on the samples used by EVERY
    candidate, then the chosen one refitted on all its own samples (no refit when they are the
    common ones).  'common' changed the pick on 5 of 40 foreign mode-reversal devices and made the
    held-out p90 worse (docs/ACCURACY.md "Rate and lag selection"), hence not the default.
    A candidate that cannot be fitted (e.g. no sample past its warm-up) is skipped and reported
    (one whose configuration cannot be built is also left out of the common set).  Returns
    (model, FitResult); the model's fit info holds
    "rate_selection": {"method", "samples", "chosen", "candidates": [{"estimator", "cv_rms" or
    "error"}]} (written to model.json).  ``drop_unidentifiable`` as in :func:`fit_logs`; when no
    candidate fits and one failed as unidentifiable, that UnidentifiableError is raised."""
    from host_tools.golden.compensate import fit_config_from_logs, prepare

    if samples not in ("common", "own"):
        raise ValueError(f"samples must be 'common' or 'own', not {samples!r}")
    prefer = RATE_PREFERRED if prefer == "default" else prefer
    prefer_margin = RATE_PREFER_MARGIN if prefer_margin is None else prefer_margin
    if not 0.0 <= prefer_margin < 1.0:
        raise ValueError(f"prefer_margin must be in [0, 1), not {prefer_margin!r}")
    preferred = None if prefer is None else _rate_label(*prefer)
    logs = list(logs)
    kw = dict(cv_blocks=cv_blocks, blocks=True, drop_unidentifiable=drop_unidentifiable,
              significance=significance, min_gain=min_gain)
    rows, cfgs, unidentifiable = {}, {}, None
    for est, n, shift in candidates:
        label = _rate_label(est, n, shift)
        try:
            cfgs[label] = fit_config_from_logs(logs, rate_estimator=est, n=n, shift=shift, **config_kw)
        except ValueError as exc:
            rows[label] = {"estimator": label, "error": str(exc)}
    masks = own = None
    if samples == "common" and cfgs:
        own = {label: [prepare(log, cfg).used for log in logs] for label, cfg in cfgs.items()}
        masks = [np.logical_and.reduce([m[i] for m in own.values()]) for i in range(len(logs))]
        if not all(m.any() for m in masks):   # no common sample: fall back to each candidate's own
            masks = None
    best = pref = None
    for label, cfg in cfgs.items():
        try:
            model, res = fit_logs(logs, cfg, terms, masks=masks, **kw)
        except ValueError as exc:
            rows[label] = {"estimator": label, "error": str(exc)}
            unidentifiable = unidentifiable or (exc if isinstance(exc, UnidentifiableError) else None)
            continue
        rows[label] = {"estimator": label, "cv_rms": res.cv["cv_rms"]}
        if best is None or res.cv["cv_rms"] < best[0]:
            best = (res.cv["cv_rms"], model, res, label)
        if label == preferred:
            pref = (res.cv["cv_rms"], model, res, label)
    if best is None and unidentifiable is not None:
        raise unidentifiable   # (drop_unidentifiable=False) the caller can name the remedy
    if best is None:
        raise ValueError("rate estimator 'auto': no candidate could be fitted: "
                         + "; ".join(f"{r['estimator']}: {r['error']}" for r in rows.values()))
    rows = [rows[_rate_label(*c)] for c in candidates]
    if pref is not None and not best[0] < (1.0 - prefer_margin) * pref[0]:
        best = pref
    _, model, res, label = best
    if masks is not None and any((o != m).any() for o, m in zip(own[label], masks)):
        model, res = fit_logs(logs, cfgs[label], terms, **kw)   # the chosen one on all its samples
    method = ("least cross-validated rms (time blocks of one run, or runs)" if pref is None else
              f"{preferred} unless another candidate's cross-validated rms (time blocks of one run, or runs) "
              f"is below {1.0 - prefer_margin:g} x its own")
    model.fit["rate_selection"] = {"method": method, "preferred": preferred, "prefer_margin": prefer_margin,
                                   "samples": "common" if masks is not None else "own",
                                   "chosen": label, "candidates": rows}
    return model, res
