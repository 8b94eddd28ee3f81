"""The default fitting pipeline: what `hdrg fit RUN` does without rate options (and what the
`*/default` rows of `hdrg bench accuracy` measure).  It composes the fitter (host_tools.fitting.fit) and
the lag-state block (host_tools.fitting.fit_lag); neither of those imports this module.  The defaults
(host_tools.golden.compensate.DEFAULT_*) are read at call time; :func:`fit_policy` gathers every
default of the fit in one :class:`FitPolicy` (what `hdrg fit`, `hdrg diagnose` and their `--help`
read).  Several training runs: each run's offset per coefficient bank is removed before the fit
(:func:`fit_without_run_offsets`).  The refusals of a fitted result (:func:`check_fit_result`: no
degrees of freedom, too few samples per coefficient) are here too, so that the Python API
(host_tools.api.fit) and `hdrg fit` refuse alike."""
from __future__ import annotations

import math

import numpy as np

from host_tools.golden import compensate
from host_tools.golden.regressors import regressor_matrix
from dataclasses import dataclass

from host_tools.errors import UserError
from host_tools.golden import reversal as _reversal
from host_tools.fitting import fit as _fit
from host_tools.fitting import fit_lag as _fit_lag
from host_tools.fitting import fit_rate as _fit_rate
from host_tools.fitting.fit import check_cv_blocks, fit_logs
from host_tools.fitting.fit_rate import fit_auto_rate
from host_tools.fitting.fit_lag import add_lag_block
from host_tools.fitting import turn_on as _turn_on
from host_tools.fitting.turn_on import add_turn_on

RUN_OFFSET_PASSES = 2   # backfitting passes of the per-run offsets (docs/ACCURACY.md "Several training runs")
DEFAULT_CV_BLOCKS = 8   # time blocks of the cross-validation on a single run
DEFAULT_TURN_ON = "auto"   # the power-on transient term (host_tools.fitting.turn_on); "off"


@dataclass(frozen=True)
class FitPolicy:
    """Every default of the fit of `hdrg fit` (and of the starting model of `hdrg diagnose`), in one
    place; :func:`fit_policy` reads it from the modules that define each value.

    * ``rate_default``: the proxy-rate estimator (estimator, n, shift) of a fixed-rate fit;
      ``rate_selection_mr`` / ``rate_selection_ftr``: 'auto' (cross-validated choice among
      ``rate_candidates``, ``rate_preferred`` kept unless another's rms is below
      ``rate_prefer_margin`` x its own) or 'fixed' (``rate_default``), for mode-reversal / FTR logs;
    * ``terms``: the term selection ('auto': cross-validated, within ``significance`` standard errors);
    * ``lag_block``: 'auto' (the lag-state block as k7 when cross-validation lowers the rms by
      ``lag_margin`` of the kind, 'ftr' or 'mr') or 'off';
    * ``guard_margin`` / ``guard_margin_extrapolated``: the 17-term model must beat the best cubic's
      leave-one-leg-out rms by this fraction (the second with one leg of each sign of dT/dt);
    * ``cv_blocks``: time blocks of the cross-validation on one run;
    * ``turn_on``: 'auto' (the power-on transient as a k7 term when leave-one-power-on-out
      lowers the held-out start windows' error by ``turn_on_margin`` (run-weighted) and makes no
      power-on's start worse, host_tools.fitting.turn_on) or 'off';
    * ``order``, ``combiner``, ``settle_s`` [s], ``max_stale_s`` [s]: the mode-reversal settings;
    * ``run_offset_passes``, ``min_offset_overlap``: the per-run offsets of several runs;
    * ``min_samples_per_term``: fewer valid samples per coefficient are refused unless forced."""
    rate_default: tuple
    rate_selection_mr: str
    rate_selection_ftr: str
    rate_candidates: tuple
    rate_preferred: tuple
    rate_prefer_margin: float
    terms: str
    significance: float
    lag_block: str
    lag_margin: tuple
    guard_margin: float
    guard_margin_extrapolated: float
    cv_blocks: int
    turn_on: str
    turn_on_margin: float
    order: str
    combiner: str
    settle_s: float
    max_stale_s: float
    run_offset_passes: int
    min_offset_overlap: float
    min_samples_per_term: int

    def to_dict(self) -> dict:
        from dataclasses import asdict
        return asdict(self)


def fit_policy() -> FitPolicy:
    """The defaults of the fit as they stand (read at call time from the modules that define them)."""
    rate = compensate.DEFAULT_RATE
    return FitPolicy(
        rate_default=(rate["estimator"], rate["n"], rate["shift"]),
        rate_selection_mr=compensate.DEFAULT_RATE_SELECTION_MR, rate_selection_ftr=compensate.DEFAULT_RATE_SELECTION_FTR,
        rate_candidates=tuple(_fit_rate.RATE_CANDIDATES), rate_preferred=tuple(_fit_rate.RATE_PREFERRED),
        rate_prefer_margin=_fit_rate.RATE_PREFER_MARGIN, terms=compensate.DEFAULT_TERMS,
        significance=compensate.DEFAULT_SIGNIFICANCE, lag_block=compensate.DEFAULT_LAG_BLOCK,
        lag_margin=tuple(sorted(_fit_lag.LAG_MARGIN.items())), guard_margin=GUARD_MARGIN,
        guard_margin_extrapolated=GUARD_MARGIN_EXTRAPOLATED, cv_blocks=DEFAULT_CV_BLOCKS,
        turn_on=DEFAULT_TURN_ON, turn_on_margin=_turn_on.MARGIN,
        order=_reversal.DEFAULT_ORDER, combiner=_reversal.DEFAULT_COMBINER, settle_s=_reversal.DEFAULT_SETTLE_S,
        max_stale_s=_reversal.DEFAULT_MAX_STALE_S, run_offset_passes=RUN_OFFSET_PASSES,
        min_offset_overlap=MIN_OFFSET_OVERLAP, min_samples_per_term=_fit.MIN_SAMPLES_PER_TERM)


# What a fit of several runs records (model.fit["several_runs"]) and `hdrg fit` warns.
SEVERAL_RUNS_NOTE = (
    "one coefficient set for all runs, each run's offset removed first (fit.run_offsets); a power-on's change "
    "of the damping scale is not modelled (docs/ACCURACY.md)")


class FitRefused(UserError):
    """A fit whose coefficients the data cannot support (the message says why and what to do)."""


def check_fit_result(res, force: bool = False) -> None:
    """The refusals of a fitted result (FitRefused): no degrees of freedom left (the error bars are
    undefined), or, unless ``force``, fewer than MIN_SAMPLES_PER_TERM valid samples per coefficient
    (the fit would follow the noise)."""
    if res.dof <= 0 or not np.all(np.isfinite(res.stderr)):
        raise FitRefused(f"{res.n} valid samples for {len(res.terms)} coefficients: no degrees of freedom left, "
                         f"the error bars are undefined; record more data or fit fewer terms (--terms)")
    if res.n < _fit.MIN_SAMPLES_PER_TERM * len(res.terms) and not force:
        raise FitRefused(f"{res.n} valid samples for {len(res.terms)} coefficients (fewer than "
                         f"{_fit.MIN_SAMPLES_PER_TERM} per coefficient): the fit would follow the noise; record more "
                         f"data, fit fewer terms (--terms), or force the fit (--force)")


def fit_default(logs, terms=None, *, drop_unidentifiable=None, lag_block=None, cv_blocks=DEFAULT_CV_BLOCKS,
                rate_prefer="default", run_offsets="auto", guard="auto", turn_on=None, **config_kw):
    """What `hdrg fit RUN` does without rate flags: :func:`fit_model` (the 17-term pipeline) on
    what the training runs identify, then the guard against the flight stack's cubic.

    1. What the runs identify (host_tools.fitting.legs.identifiability): unless the training
       runs hold both signs of dT/dt (a cooling-only run cannot tell a rate term from a proxy
       term), ``terms`` None / 'auto' gives the cubic in the proxy (k0..k3), clamped to the
       calibrated range (no margin): what the data identify.  model.fit["identifiability"]
       says which term groups the runs identify and what chamber run would identify the rest.
    2. Else :func:`fit_model` (rate estimator, term selection, lag block, per-run offsets).
    3. ``guard`` 'auto' and ``terms`` None / 'auto' (terms given are the caller's): the model is compared, by leave-one-leg-out cross-validation
       (host_tools.fitting.legs.leg_cv: legs of the training runs, samples beyond the other
       legs' range counted, not scored), with the candidates
       :data:`GUARD_CANDIDATES`: the flight stack's cubic in the temperature sensor
       (host_tools.fitting.baseline) and the cubic in the model's proxy.  The 17-term model is
       kept when its cross-validated rms is below (1 - GUARD_MARGIN) x the best cubic's, else
       that cubic is the model; (1 - GUARD_MARGIN_EXTRAPOLATED) x when the runs hold one leg of
       each sign (every fold then scores the rate terms on a sign they were not fitted on; on
       the measured consumer-IMU legs such wins did not hold out: 1.74x and 1.28x the cubic).  'off': step 3 skipped.
       model.fit["guard"]: the candidates' cross-validated rms and the choice.
    4. ``turn_on`` 'auto', ``terms`` None / 'auto' and no aux given: the power-on transient
       (host_tools.fitting.turn_on.add_turn_on: a ``decay_on`` term in k7 when
       leave-one-power-on-out supports it, the other coefficients refitted with it taken out; two
       or more runs; it also checks each held-out power-on's first 45 min against mode reversal
       alone).  'off': skipped.
    5. The floor (:func:`_floor`, ``guard`` 'auto'): the model shipped against no temperature
       compensation (the offset k0 alone) on the same leave-one-leg-out folds and samples;
       model.fit["floor"] says where the model loses (`hdrg fit` warns; the model is kept).
    6. model.fit["start_up"] (:func:`start_up_status`): whether the first minutes after power-on
       are calibrated (the power-on term learned, or held out no worse than mode reversal alone).
    Returns (model, FitResult of the model kept)."""
    from host_tools.fitting.legs import PROXY_TERMS, identifiability

    if guard not in ("auto", "off"):
        raise ValueError(f"guard must be 'auto' or 'off', not {guard!r}")
    turn_on = DEFAULT_TURN_ON if turn_on is None else turn_on
    if turn_on not in ("auto", "off"):
        raise ValueError(f"turn_on must be 'auto' or 'off', not {turn_on!r}")
    check_cv_blocks(cv_blocks)
    _check_options(lag_block, run_offsets)
    check_terms(terms)
    logs = list(logs)
    from host_tools.golden.input_check import warn_inputs
    warn_inputs(logs)   # per log: samples left out of the fit (count, column, first row), a stuck proxy
    # the range the model will meet: the training runs' (no margin) or the given one
    calibrated = compensate.fit_config_from_logs(
        logs, **{**{k: v for k, v in config_kw.items() if k != "aux"}, "proxy_margin": 0.0})
    ident = identifiability(logs, calibrated)
    auto_terms = terms is None or (isinstance(terms, str) and terms.strip().lower() == "auto")
    if not ident["rate_terms_identified"] and auto_terms:   # one sign of dT/dt
        model, res = _cubic(logs, calibrated, config_kw)
        ident["restricted_to"] = list(PROXY_TERMS)
        model.fit["identifiability"] = ident
        model.fit["guard"] = {"chosen": GUARD_CANDIDATES[1], "why": "the rate terms are not identified: the cubic in "
                              "the proxy, clamped to the calibrated range"}
    else:
        model, res = fit_model(logs, terms, drop_unidentifiable=drop_unidentifiable, lag_block=lag_block,
                               cv_blocks=cv_blocks, rate_prefer=rate_prefer, run_offsets=run_offsets, **config_kw)
        ident["restricted_to"] = None
        model.fit["identifiability"] = ident
        if guard == "auto" and auto_terms:
            margin = GUARD_MARGIN_EXTRAPOLATED if ident.get("rate_cv_extrapolated") else GUARD_MARGIN
            model, res = _guard(logs, model, res, config_kw, margin)
    tried = turn_on == "auto" and auto_terms and config_kw.get("aux") is None
    if tried:
        model, res = add_turn_on(logs, model, res, lambda lg, cfg, t: _fixed_terms_fit(lg, cfg, t, run_offsets))
    if guard == "auto":
        model.fit["floor"] = _floor(logs, model, cv_blocks)
    model.fit["start_up"] = start_up_status(model, tried, turn_on)
    return model, res


def check_terms(terms) -> None:
    """ValueError, once, for a term selection string that names no term (before any fit tries it)."""
    if isinstance(terms, str) and terms.strip().lower() != "auto":
        from firmware_ref.terms import parse_terms
        parse_terms(terms)


START_UP_RECORD = ("to calibrate them, record one chamber run from a power-on soaked at each end of the range and "
                   "two 45-min power-ons at room temperature (README, lab engineer: record the runs)")


def start_up_risk(model) -> str:
    """What the first minutes after power-on risk under ``model`` when its start-up is not calibrated."""
    if model.config.reversal is not None:
        return "may be worse than mode reversal alone"
    return "keep the turn-on uncompensated"


def start_up_status(model, tried: bool, turn_on: str = "auto") -> dict:
    """model.fit["start_up"]: {"calibrated": bool, "why": str, "record": str (empty when calibrated)}.
    Calibrated: the power-on term (k7 decay_on) is learned, or it was tried and not needed, and
    held out no power-on's first minutes lose to mode reversal alone (host_tools.fitting.turn_on).
    Else "why" says what the first minutes risk and "record" what to do."""
    info = model.fit.get("turn_on") or {}
    check = info.get("start_up_check") or {}
    if check.get("worse"):
        ratio = {r["source"]: r["ratio"] for r in check["runs"]}
        return {"calibrated": False, "record": "check the model on a power-on before trusting it at start-up (hdrg "
                                               "report on a start-up log)",
                "why": f"held out, the first {check['window_s'] / 60:g} min after power-on of "
                       + ", ".join(f"{s} ({ratio[s]:.3g}x)" for s in check["worse"])
                       + " are worse than mode reversal alone (1 sigma of 100-s means)"}
    if info.get("chosen"):
        return {"calibrated": True, "why": f"the power-on term is learned: {info['chosen']}", "record": ""}
    if check.get("runs"):
        return {"calibrated": True, "record": "",
                "why": f"no power-on term held out, and held out no power-on's first {check['window_s'] / 60:g} min "
                       f"lose to mode reversal alone"}
    if not tried:
        why = ("the power-on term is off" if turn_on == "off" else
               "the power-on term is tried only with the default terms and no aux channel")
    else:
        why = "the power-on term is not learned: " + info.get("why", "")
    return {"calibrated": False, "why": f"{why}; the first minutes after power-on {start_up_risk(model)}",
            "record": START_UP_RECORD}


def _fixed_terms_fit(logs, config, terms, run_offsets):
    """``terms`` fitted with ``config`` (each run's offset removed as in :func:`fit_model`)."""
    fit = lambda lg: fit_logs(lg, config, terms, drop_unidentifiable=True)   # noqa: E731
    return fit_without_run_offsets(list(logs), fit) if run_offsets == "auto" else fit(list(logs))


GUARD_MARGIN = 0.05   # the 17-term model must beat the best cubic's leave-one-leg-out rms by this fraction
GUARD_MARGIN_EXTRAPOLATED = 0.5   # ... by this one with one leg of each sign (rate terms scored on the other sign)
GUARD_CANDIDATES = ("cubic in the temperature sensor (flight stack)", "cubic in the proxy")


def _guard(logs, model, res, config_kw, margin=GUARD_MARGIN):
    """Step 3 of :func:`fit_default`."""
    from host_tools.fitting.baseline import BASELINE_TERMS, baseline_config
    from host_tools.fitting.fit import fit_logs
    from host_tools.fitting.legs import leg_cv

    cfg = model.config
    cands = {}
    if all("temp_c" in log for log in logs):
        cands[GUARD_CANDIDATES[0]] = baseline_config(logs, cfg)
    cands[GUARD_CANDIDATES[1]] = _cubic_config(logs, cfg, config_kw)
    if cands.get(GUARD_CANDIDATES[0]) is not None and cands[GUARD_CANDIDATES[0]].proxy == cands[GUARD_CANDIDATES[1]].proxy:
        del cands[GUARD_CANDIDATES[1]]      # the proxy is the temperature sensor: one cubic
    label = "17-term model"
    scores = leg_cv(logs, {label: (cfg, model.terms), **{k: (c, BASELINE_TERMS) for k, c in cands.items()}},
                    cfg.proxy.kind)
    info = {"method": "leave-one-leg-out cross-validation (host_tools.fitting.legs.leg_cv)",
            "margin": margin}
    if scores is None:
        best = GUARD_CANDIDATES[1] if GUARD_CANDIDATES[1] in cands else GUARD_CANDIDATES[0]
        info.update(chosen=best, why="one leg: nothing to cross-validate across legs; the cubic, clamped to the "
                                     "calibrated range, is what the data support")
    else:
        info.update({k: scores[k] for k in ("folds", "scored", "out_of_range")}, cv_rms=scores["cv_rms"])
        cubic = min(cands, key=lambda k: scores["cv_rms"][k])
        keep = scores["cv_rms"][label] < (1.0 - margin) * scores["cv_rms"][cubic]
        best = label if keep else cubic
        info.update(chosen=best, why=(f"its cross-validated rms is below {1 - margin:g} x the {cubic}'s" if keep else
                                      f"the 17-term model's cross-validated rms is not below {1 - margin:g} x the {cubic}'s"))
    if best != label:
        fitted = model
        model, res = fit_logs(logs, cands[best], list(BASELINE_TERMS))
        model.fit["identifiability"] = fitted.fit.get("identifiability")
        info["replaced"] = {"terms": list(fitted.terms), "fit": {k: fitted.fit[k] for k in ("rate_selection", "lag_block", "run_offsets")
                                                                 if k in fitted.fit}}
    model.fit["guard"] = info
    return model, res


NO_COMPENSATION = "no temperature compensation (the offset k0 alone)"


def _floor(logs, model, cv_blocks=DEFAULT_CV_BLOCKS) -> dict:
    """Step 5 of :func:`fit_default`: ``model`` against no temperature compensation (the offset
    k0 alone, fitted on the other legs: the raw output's level) by leave-one-leg-out
    cross-validation on the same folds and samples (host_tools.fitting.legs.leg_cv), by the rms
    (level included, the guard's score) and the std about each held-out part's mean (a std of the
    output, as the benches score).  One leg: its ``cv_blocks`` time blocks are the folds (samples
    beyond the other blocks' proxy range not scored, as for legs).  The model is kept either way
    and the result says where it loses (model.fit["floor"]: {"checked", "cv_rms", "cv_std":
    {"model", "no compensation"}, "worse": [where it loses], "why"}): on the measured consumer IMU
    (x axis, the two cooling legs) the offset alone won both scores between the legs and then lost
    on the heating leg held out (23.3 against the cubic's 11.7 deg/h, `hdrg bench measured`), so
    two legs are not evidence enough to ship no compensation instead."""
    from host_tools.fitting.legs import block_ids, leg_cv, leg_ids

    cfg = model.config
    cands = {"model": (cfg, model.terms), NO_COMPENSATION: (cfg, (0,))}   # k0 alone: the same samples
    method = "leave-one-leg-out cross-validation (host_tools.fitting.legs.leg_cv), the same folds and samples"
    why = "nothing held out scored"
    try:
        folds = leg_ids(logs, cfg.proxy.kind)
        if len(folds[1]) < 2:      # one leg: its time blocks are the folds
            method = method.replace("leave-one-leg-out", f"leave-one-time-block-out ({cv_blocks} blocks of one leg)")
            folds = block_ids(logs, cv_blocks)
        scores = leg_cv(logs, cands, cfg.proxy.kind, folds=folds)
    except ValueError as exc:
        scores, why = None, f"not checked: {exc}"
    if scores is None or scores["scored"] == 0 or not all(math.isfinite(v) for v in scores["cv_rms"].values()):
        return {"checked": False, "worse": [], "why": why}
    info = {"checked": True, "method": method, "folds": scores["folds"], "scored": scores["scored"]}
    lost = []
    for key, what in (("cv_rms", "rms"), ("cv_std", "std about each held-out part's mean")):
        m, n = scores[key]["model"], scores[key][NO_COMPENSATION]
        info[key] = {"model": m, "no compensation": n}
        if m > n:
            lost.append(f"{what} {m:.4g} > {n:.4g} deg/h")
    info["worse"] = lost
    info["why"] = ("held out, the model is worse than no temperature compensation: " + "; ".join(lost) if lost else
                   "held out, the model is no worse than no temperature compensation (rms and std)")
    return info


def _cubic_config(logs, like, config_kw):
    """The config of the cubic in ``like``'s proxy: the proxy range of the training runs (or the
    given one) with no margin (clamped to the calibrated range), ``like``'s rate estimator and
    reversal settings."""
    kw = {"reversal": like.reversal} if like.reversal is not None else {}
    if config_kw.get("proxy_range") is not None:
        kw["proxy_range"] = config_kw["proxy_range"]
    return compensate.fit_config_from_logs(logs, proxy_kind=like.proxy.kind, proxy_margin=0.0,
                                           rate_estimator=like.rate.estimator, n=like.rate.n, shift=like.rate.shift,
                                           fs=like.rate.fs, **kw)


def _cubic(logs, probe, config_kw):
    """The cubic in the proxy (k0..k3) fitted to ``logs``, as :func:`_cubic_config` of ``probe``."""
    from host_tools.fitting.baseline import BASELINE_TERMS
    from host_tools.fitting.fit import fit_logs
    return fit_logs(logs, _cubic_config(logs, probe, config_kw), list(BASELINE_TERMS))


def _check_options(lag_block, run_offsets) -> None:
    """ValueError for a ``lag_block`` (None, 'auto', 'off') or ``run_offsets`` ('auto', 'off') outside its choices."""
    if lag_block not in (None, "auto", "off"):
        raise ValueError(f"lag_block must be 'auto' or 'off', not {lag_block!r}")
    if run_offsets not in ("auto", "off"):
        raise ValueError(f"run_offsets must be 'auto' or 'off', not {run_offsets!r}")


def fit_model(logs, terms=None, *, drop_unidentifiable=None, lag_block=None, cv_blocks=DEFAULT_CV_BLOCKS,
              rate_prefer="default", run_offsets="auto", **config_kw):
    """What `hdrg fit` does without rate flags: mode-reversal logs with
    host_tools.golden.compensate.DEFAULT_RATE_SELECTION_MR 'auto' -> :func:`fit_auto_rate`, else
    :func:`fit_logs` with the default configuration (host_tools.golden.compensate.fit_config_from_logs
    with ``config_kw``).  Then, with ``lag_block`` 'auto' (None: host_tools.golden.compensate.DEFAULT_LAG_BLOCK;
    'off' skips it) and no aux given, the lag-state block of the proxy as k7 when cross-validation
    supports it (host_tools.fitting.fit_lag.add_lag_block).  ``drop_unidentifiable`` None: each path's own default
    (auto True, else False); ``cv_blocks``: the time blocks of cross-validation on a single run;
    ``rate_prefer``: fit_auto_rate's ``prefer`` ('default': host_tools.fitting.fit_rate.RATE_PREFERRED;
    None: plain least CV rms, the start of `hdrg diagnose`).  ``run_offsets`` 'auto': with several
    runs, :func:`fit_without_run_offsets` around all of this; 'off': never.  Returns (model, FitResult)."""
    _check_options(lag_block, run_offsets)
    logs = list(logs)
    if run_offsets == "auto":
        return fit_without_run_offsets(logs, lambda lg: fit_model(
            lg, terms, drop_unidentifiable=drop_unidentifiable, lag_block=lag_block, cv_blocks=cv_blocks,
            rate_prefer=rate_prefer, run_offsets="off", **config_kw))
    lag_block = compensate.DEFAULT_LAG_BLOCK if lag_block is None else lag_block
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


def without_run_offsets(logs, offsets) -> list:
    """``logs`` with ``offsets`` (per run, per coefficient bank [deg/h], as :func:`run_offsets`
    gives them for these runs in this order) taken out of their rates; ``logs`` as they are for
    none (None or [])."""
    if not offsets:
        return list(logs)
    if len(offsets) != len(logs):
        raise ValueError(f"got the offsets of {len(offsets)} runs, not of these {len(logs)}")
    return [_shifted(log, o) for log, o in zip(logs, offsets)]


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


MIN_OFFSET_OVERLAP = 0.5   # each run's proxy range must overlap the other runs' by this share of its width


def offsets_identifiable(logs, proxy_kind) -> str | None:
    """None when every run's proxy range overlaps the union of the other runs' ranges by at
    least MIN_OFFSET_OVERLAP of its own width (an offset per run can be told from the proxy
    terms); else why not (which run, how much overlap)."""
    from host_tools.golden.input_check import fit_mask
    rng = [(float(np.min(p[k])), float(np.max(p[k]))) for p, k in
           ((log.proxy(proxy_kind)[1], fit_mask(log)) for log in logs)]
    for i, (lo, hi) in enumerate(rng):
        olo = min(r[0] for j, r in enumerate(rng) if j != i)
        ohi = max(r[1] for j, r in enumerate(rng) if j != i)
        share = max(0.0, min(hi, ohi) - max(lo, olo)) / (hi - lo) if hi > lo else 1.0
        if share < MIN_OFFSET_OVERLAP:
            return (f"{logs[i].source}: its proxy range overlaps the other runs' on {100 * share:.0f} % of its width "
                    f"(< {100 * MIN_OFFSET_OVERLAP:.0f} %): no offset per run (it could not be told from the proxy terms)")
    return None


def fit_without_run_offsets(logs, fit):
    """Several training runs share one coefficient set, but each power-on moves the bias by its own
    offset (the damping change's offset, the turn-on offset).  Backfitting: ``fit(logs)`` ->
    (model, FitResult); then RUN_OFFSET_PASSES times: per run and bank the mean residual
    (:func:`run_offsets`) is removed from that run's rate and ``fit`` repeated on the shifted runs.
    The model's k0 stays the level of all runs together; every fit decision (rate estimator, lag
    block, terms, cross-validation over runs) is taken on the shifted runs.  model.fit
    ``run_offsets``: {"passes", "offsets_dph": per run the total offset removed per bank, "runs"}.
    One run: ``fit(logs)`` as it is (no offset to tell from the model's k0).  Runs whose proxy
    ranges do not overlap (:func:`offsets_identifiable`): ``fit(logs)`` as it is too, since an
    offset per run is then a step in the proxy that the polynomial cannot be told from (two
    legs of one chamber cycle: the offset would eat the temperature dependence); model.fit
    ``run_offsets`` says why.  Measured on foreign devices (docs/ACCURACY.md "Several training runs")."""
    model, res = fit(logs)
    if len(logs) < 2:
        return model, res
    overlap = offsets_identifiable(logs, model.config.proxy.kind)
    if overlap is not None:
        model.fit["run_offsets"] = {"passes": 0, "why": overlap}
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
