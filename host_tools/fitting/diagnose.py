"""Close the loop on measured data: find the residual of a bias model, trace it to an effect the
model lacks, add that effect through the auxiliary term k7, and report the error before and after:
``hdrg diagnose RUN... [--holdout RUN...] --out DIR [--json report.json]``.

Procedure (:func:`diagnose`)
----------------------------
0. **What is not an effect of temperature** (several training runs only): each power-on moves
   the bias by its own offset, and every run recorded from its power-on holds the device's
   turn-on.  ``hdrg fit``'s model of the training runs (host_tools.fitting.fit_pipeline.fit_default, the
   loop's options; :func:`taken_from_fit`) gives the power-on term when it chose one
   (host_tools.fitting.turn_on): it is taken out of the training and held-out runs
   (turn_on.without_term: size x g x the mode sign), and each training run's offset per
   coefficient bank (its mean residual under that model, the term included) out of that run
   (fit_pipeline.run_offsets, fit_pipeline.without_run_offsets).  The loop works on those runs
   (its report's errors are on them), does not offer a second power-on term (family
   ``turn_on``), keeps AUX_RESERVED k7 terms free, and the model it writes holds the term again
   (turn_on.with_decay; the same output on every valid sample of the runs as given).  Without
   this the per-power-on offsets and the turn-on are structure the loop explains with whatever
   channel wanders like them (`hdrg bench startup --loop`, set 0: the loop's start-up error 0.94
   x mode reversal alone's against hdrg fit's 0.39 x; docs/LOOP.md "Several power-ons").
1. **Fit** the starting model on the training runs exactly as ``hdrg fit`` does with its defaults
   (:func:`base_options` / :func:`base_model`: the options not given are None, so
   host_tools.golden.compensate's DEFAULT_RATE / DEFAULT_ORDER / DEFAULT_COMBINER / DEFAULT_TERMS apply:
   one place); ``--proxy``, ``--rate-estimator``, ``--terms``, ``--order``, ``--combiner`` as in
   ``hdrg fit``.  A regress_first model (two coefficient banks by mode) is scanned with the banked
   design: every column once per mode, on the per-mode used samples, target c = s * rate, raw
   noise surrogates (no combiner in the target).
2. **Residual** = the model's target (FTR output or mode-reversal combined output) minus the
   model, on the valid samples; characterized per run (:func:`characterize`): Allan deviation
   against the white-noise line extrapolated from the shortest tau (taus where it is > 2x that line
   hold structure above white noise), spectrum lines (:func:`spectral_lines`: Hann-windowed
   periodogram of the mean-free residual, invalid samples interpolated, over a local median
   continuum; gap-free logs only), and the binned means / correlation of the residual against
   time, proxy rate, mode and every logged channel.
3. **Trace**: every candidate of host_tools.fitting.effects (physically motivated regressor families,
   computed causally from the log, parameters scanned on coarse grids) is scored by
   cross-validation: groups are the training runs (leave one run out) or, with a single training
   run, ``cv_blocks`` contiguous time blocks dealt round-robin into ``cv_folds`` folds (each fold
   holds out contiguous blocks spread over the run, so no fold extrapolates the polynomial in u);
   never random samples.  In each fold the base terms (the polynomial terms plus the generators
   already added, each its own column) AND the candidate are refitted on the training part and
   scored on the held-out part (:class:`_Scanner`).  The score is on SCORE_TAU_S = 1-s means of
   the valid samples (the samples themselves at <= 1 Hz; at 50 Hz the white noise of single
   samples would swamp any slow effect): ``gain = 1 - SSE_heldout(with candidate) /
   SSE_heldout(base)``, summed over folds.  A candidate may also be another rate estimator (lsq
   over 16 or 64 s, iir with 2^shift / fs = 8, 32, 128 or 512 s; family ``rate_estimator``): it
   replaces the v terms instead of adding a column, and is scored on the samples valid under
   both estimators (a longer warm-up must not win by hiding the start of a run); effects are
   preferred to it when both pass (its warm-up would hide a turn-on).
4. **Selection rule** (:data:`RULE`): the best candidate is accepted only when

   a. its CV gain >= ``g_min`` (default 0.02: it explains at least 2 % of the held-out residual
      variance of 1-s means), and
   b. its CV gain >= the gain it needs under max-T: every candidate is rescored on
      ``n_surrogates`` (39) surrogate noise series per training run (:func:`noise_model`: white +
      flicker fitted to the residual's Allan variance at taus <= NOISE_TAU_MAX_S, where effects
      are not; :func:`surrogates`: Gaussian, no wrap-around, through the model's combiner for
      mode-reversal logs, absolute level, never rescaled to the residual); each candidate's gain
      is standardized by its own null (median, 84th percentile - median); the 95 % level of the
      scan's LARGEST standardized null gain over the surrogates, mapped back through each
      candidate's own null, is the gain that candidate needs (``null95``).  So the threshold
      counts every candidate and scan point, and a candidate that fits noise easily (a wandering
      aux channel) does not raise the bar for the others; and
   c. it is consistent: it lowers the held-out error in a strict majority of the folds (all folds
      with 2 runs).

   Ties: among the candidates within 5 % (relative) of the best gain, one computed from the proxy,
   the mode and the sample counter alone is preferred to one that needs another logged channel
   (board_temp, aux, aux_*) (:func:`_preferred`).  The winner's continuous parameter (tau or period)
   is then refined on finer grids (ratios 2^(+-1/4, +-1/2), then 2^(+-1/8); periods +-2, 4 %,
   then +-1 %) by the same CV gain.  Periodic candidates: at the periods of significant lines of
   the training residual (power / continuum > ln(bins / 0.01)) and on a period grid (120 s ..
   half the run: two cycles, ratio 2^(1/4)); never at a **combiner line** (:func:`combiner_lines`: the
   reversal cycle, its harmonics and their sidebands with the chamber cycle), which is reported
   in ``artifacts`` with the combiner as the cause and the structural fix.
   **Firmware capacity**: the k7 sum holds at most AUX_MAX_TERMS (6) terms, so a candidate that
   would not fit beside the accepted generators is not offered (``not_offered`` in ``stopped``).
5. **Add the effect**: the polynomial terms plus every accepted generator as its own column are
   refitted by a small explicit least-squares solve on the training runs; the generator weights
   are normalized by the sum of their magnitudes (so |z| <= 1 everywhere, host_tools.golden.regressors)
   and baked into ``AuxConfig('sum', ...)``; the fitter then fits the 17 coefficients with k7.
   (A rate_estimator winner changes the model's rate estimator instead.)  **Confirm** it on the
   held-out runs (:data:`CONFIRM_RULE`; with no held-out runs and several training runs, on
   each training run in turn, both models refitted on the other runs,
   diagnose_confirm.step_errors_leaving_runs_out, the rows pooled as held-out runs; the whole-model
   structural steps below too): if the held-out error does not drop, the step is
   reported ``confirmed: false`` and reverted, its family is not offered again (a periodic
   step: the periods within PERIOD_EXCLUDE_RATIO = 2^(1/2) of it).  Iterate while a
   candidate passes the rule, until ``max_iter`` (3) steps are kept in the phase or
   TRIES_PER_STEP x max_iter (6) have been tried: a reverted step uses a try, not one of the
   max_iter (with 3 tries an unconfirmed long lag or drift fitting the training run's slow
   residual took the turns of the u^4 that held out 1.28 -> 0.36 deg/h; docs/LOOP.md).  **Structure first**
   (:data:`PHASES`): phase 1 offers only the structural candidates (:func:`kind_of`: the rate
   estimator, the lag-state block of the proxy, board_temp = the second thermometer, lags <=
   STRUCT_TAU_FRACTION of the run; for per-mode banks the exchange settling: a decay after each
   exchange with ONE coefficient for both banks, i.e. a transient that follows the mode sign like
   the rate, tau <= 2 x the settle window), then for mode-reversal logs the order/combiner
   (:func:`order_step`: regress_first with each other combiner, whole-model CV), confirmed the
   same way.  Beside the structure phase 1 also scores the drift in time (``COMPETE_FAMILIES``:
   aging, a ramp or a decay longer than any turn-on), which a lag of the proxy of thousands of
   seconds mimics; it is taken there, as an effect step, only when it leaves at most
   1/DRIFT_MARGIN (1.7) of the residual variance the best structural candidate leaves (chosen on
   calibration seed 1, docs/LOOP.md "A drift beside the structure"); else phase 2 has it as
   before.  Phase 2 offers the effect families on the residual of the structured base, and the
   higher powers of the proxy (u^4, u^5: reported as structure, the order of the model's own
   polynomial, but scanned here: ``SCANNED_WITH_EFFECTS``).  Steps
   carry ``kind`` 'structure' / 'effect'; the verdict is "effect found" only for a kept effect
   step that is material (:data:`EFFECT_RULE`: held-out error down by >= EFFECT_MIN_DROP; a
   smaller confirmed effect step stays in the model, ``material: false``, verdict "minor
   improvement confirmed" when nothing else held).  The confirmation (:data:`CONFIRM_RULE`) also
   counts the mean offset: per held-out run, the quadratic mean over its legs (gap-free segments) of their rms with the mean may rise by at
   most CONFIRM_TOL_RMS (:func:`offsets_hold`).
6. **Report**: per iteration the effect, its parameters, the evidence (CV gain, threshold, folds,
   ranking; PNG: residual vs the candidate, Allan deviation and spectrum before/after) and the
   error before and after (:func:`error_stats`: stability 1 sigma and variation p-p of 1-s and
   100-s averages, host_tools.fitting.metrics) on the held-out runs (the training runs when none are
   given; several runs: the mean over runs), next to the noise floor (white noise: the Allan
   deviation at 1 s, and that / 10 for 100 s).  A kept periodic step whose period fits less than
   twice in every gap-free training segment carries a ``caveat`` (in its status and the verdict
   detail): a line and a slow drift in time cannot be told apart there (diagnose_report.line_or_drift).
   A kept step also lists its ``rivals`` (diagnose_scan.rivals): significant candidates of other
   families whose CV gain is within TIE_TOLERANCE of its own; the held-out runs confirm the step,
   not which of them the device has (a lag of the proxy and a lagged second thermometer).  DIR/diagnose.json (also ``--json``),
   DIR/diagnose.md, DIR/model.json (the final model, usable by ``hdrg compensate``) and
   DIR/*.png.

Modules: this one holds the loop driver (:func:`diagnose`, :func:`base_model`) and the CLI;
host_tools.fitting.diagnose_scan the CV engine, the candidates and the selection rule (steps 3-4; folds and
held-out SSE from host_tools.fitting.cv); host_tools.fitting.diagnose_noise the residual's characterization, noise
model, surrogates and combiner lines (step 2); host_tools.fitting.diagnose_confirm the error statistics,
THE held-out metric of a step and the confirmation rule (steps 5-6); host_tools.fitting.diagnose_structure
the whole-model structural steps (order/combiner, settling window); host_tools.fitting.diagnose_report the
report files.  The names tests and tools import from host_tools.fitting.diagnose are re-exported here.

Limits: with a single training run, slow candidates (aging, long lags) cannot be told from the
run's own slow noise as well as across runs; a turn-on transient or anything else that only a
part of a run holds needs two runs to be identified.  Tau-scans of filters/decays assume the
nominal sample rate.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from host_tools.fitting.diagnose_confirm import (CONFIRM_MIN_DROP, CONFIRM_RULE, CONFIRM_TOL_1S, CONFIRM_TOL_RMS,  # noqa: F401
                                         EFFECT_RULE, HELDOUT_METRIC, REPORT_TAUS, STAT_KEYS, clean_stats, fmt_value, residuals, heldout_score,
                                         stats_one, step_metric, confirmed_on_holdout, error_stats, leg_rms, step_errors_leaving_runs_out,
                                         confirmation, LEAVING_ONE_OUT,
                                         material_on_holdout, noise_floor, offsets_hold, step_errors)
from host_tools.fitting.diagnose_noise import (allan_bridged, noise_series, artifact_of, characterize,  # noqa: F401
                                       combiner_lines, noise_model, spectral_lines, surrogates)
from host_tools.fitting.diagnose_report import (verdict_detail_text, extrapolation, generalization, is_minor, kept_step_notes,
                                                line_or_drift, not_scanned, several_runs_caveat, verdict_of, write_report)
from host_tools.fitting.diagnose_scan import (CV_BLOCKS, CV_FOLDS, DRIFT_MARGIN, G_MIN, MAX_ITER, N_SURROGATES,  # noqa: F401
                                      NULL_QUANTILE, PHASES, STRUCT_TAU_FRACTION, STRUCTURAL, TRIES_PER_STEP, Accepted,
                                      loop_config, poly_terms, scan_candidates, step_key, kind_of, refit_with, rivals)
from host_tools.fitting.diagnose_structure import order_step, settle_step
from host_tools.fitting.effects import FAMILIES
from host_tools.fitting.fit import check_cv_blocks, fit_logs
from host_tools.fitting.fit_pipeline import fit_default, run_offsets, without_run_offsets
from host_tools.fitting.turn_on import chosen_term, with_decay, without_term
from host_tools.golden.checks import check_distinct_runs, same_runs
from host_tools.golden.model import jsonable


RULE = ("accept the best candidate iff (a) its cross-validated gain (1 - held-out SSE of 1-s means "
        "with it / without it, the base terms refitted with it in every fold; folds: runs, or "
        "contiguous blocks of one run) >= g_min, (b) that gain >= the gain it needs under max-T: "
        "the 95 % level of the scan's largest standardized gain on surrogate noise (white + flicker "
        "fitted to the residual's Allan variance at short taus, through the combiner), mapped back "
        "through the candidate's own null, and (c) it lowers the held-out error in a strict "
        "majority of the folds; ties within 5 % prefer a regressor of the proxy alone; then refine "
        f"its parameter; stop when no candidate passes, after max_iter kept steps or {TRIES_PER_STEP} x max_iter tried steps per phase "
        "(a step not confirmed on held-out is reverted and counts as tried only); in the structure phase a "
        "drift in time (aging) is scored beside the structure, outside its max-T, and taken there only when it "
        f"leaves <= 1/{DRIFT_MARGIN:g} of the CV residual of the best structural candidate")


CROSS_NOTE = ("; with no held-out runs, on each training run in turn, both models refitted on the other runs "
              "(the rows pooled as held-out runs)")
AUX_RESERVED = 2   # k7 terms kept free for the power-on term taken from hdrg fit (with its sign twin)
COMPETE = False   # structure phase: score the effect candidates too and yield to a better one (see diagnose())
COMPETE_FAMILIES = ("aging",)   # ... these always, under diagnose_scan.DRIFT_MARGIN: a drift in time, which a long lag mimics


def base_options(*, proxy=None, rate_estimator=None, rate_n=None, rate_shift=None, combiner=None, order=None,
                 settle_s=None, proxy_range=None, rate_range=None, reversal=False) -> dict:
    """The keyword arguments of host_tools.golden.compensate.fit_config_from_logs for the loop's starting
    model: every option the user did not give is None there, so the starting model is the product
    default of ``hdrg fit`` (compensate.DEFAULT_RATE / DEFAULT_ORDER / DEFAULT_COMBINER, the one
    place those are defined)."""
    return dict(proxy_kind=proxy, rate_estimator=rate_estimator, n=rate_n, shift=rate_shift,
                proxy_range=proxy_range, rate_range=rate_range,
                reversal={"combiner": combiner, "settle_s": settle_s, "order": order} if reversal else None)


RATE_KEYS = ("rate_estimator", "n", "shift")


def fit_options(opts) -> dict:
    """``opts`` (:func:`base_options`) as keyword arguments of fit_default: the rate options only
    when one of them is given (else fit_default's own choice of the rate estimator)."""
    given = any(opts.get(k) is not None for k in RATE_KEYS)
    return {k: v for k, v in opts.items() if given or k not in RATE_KEYS}


def base_model(train, opts, terms=None):
    """(model, config): the loop's starting model, fitted like ``hdrg fit`` (host_tools.fitting.fit.fit_logs;
    ``terms`` None -> compensate.DEFAULT_TERMS; terms the data cannot identify are dropped).  With no
    rate option given, mode-reversal runs get the rate estimator `hdrg fit` chooses by default
    (host_tools.fitting.fit_pipeline.fit_default: compensate.DEFAULT_RATE_SELECTION_MR), so the loop starts
    from the model `hdrg fit` writes WITHOUT its lag-state block (``lag_block='off'``): the loop's
    k7 is rebuilt from the generators it accepts, and its structure phase offers the lag-state
    block itself under the same CV and held-out confirmation as every other step.  The start's rate
    estimator is the candidate of least CV rms (``rate_prefer=None``), not `hdrg fit`'s preference
    for iir 9 (host_tools.fitting.fit_rate.RATE_PREFERRED): the loop's thresholds were calibrated from
    that start, and from the preferred start the loop bench's MR control got an "effect found"
    (seed 2, run 33: periodic 1153 s; docs/LOOP.md "Rate preference").  The structure phase still
    offers the rate estimator, iir 9 included, under CV and held-out confirmation.  No per-run offsets
    (run_offsets="off": step 0 takes `hdrg fit`'s out of several runs) and no power-on term
    (turn_on="off": step 0 takes `hdrg fit`'s out, or the loop offers its turn_on family)."""
    if all(opts.get(k) is None for k in RATE_KEYS):
        model = fit_default(train, terms, drop_unidentifiable=True, lag_block="off", rate_prefer=None,
                            run_offsets="off", turn_on="off", **fit_options(opts))[0]
        return model, model.config
    cfg = loop_config(train, opts)
    return fit_logs(train, cfg, terms, drop_unidentifiable=True)[0], cfg


def taken_from_fit(train, hold, opts, terms=None) -> tuple:
    """Step 0 (module doc): with several training runs, ``hdrg fit``'s model of them
    (``fit_default``, the loop's options) gives what is not an effect of temperature: its power-on
    term, when it chose one (host_tools.fitting.turn_on), comes out of the training and held-out
    runs, and each training run's offset per coefficient bank (its mean residual under that model,
    the term included: fit_pipeline.run_offsets) out of that run.  Returns (training runs, held-out
    runs, ``given`` {"run_offsets_dph", "turn_on"}, ``term``: (decay term, scale) for the final
    model, or None).  One run: nothing is taken."""
    import warnings

    given = {"run_offsets_dph": None, "turn_on": None}
    if len(train) < 2:
        return train, hold, given, None
    with warnings.catch_warnings():     # the base model's fit warns about the inputs once
        warnings.simplefilter("ignore")
        fitted = fit_default(train, terms, drop_unidentifiable=True, **fit_options(opts))[0]
    if fitted.fit.get("run_offsets", {}).get("offsets_dph"):      # the fit removed offsets per run
        given["run_offsets_dph"] = run_offsets(train, fitted)
        train = without_run_offsets(train, given["run_offsets_dph"])
    term = chosen_term(fitted)
    if term is not None:
        fs = fitted.config.rate.fs
        train = [without_term(log, *term, fs) for log in train]
        hold = [without_term(log, *term, fs) for log in hold]
        given["turn_on"] = fitted.fit["turn_on"]["chosen"]
    return train, hold, given, term


def taken_text(given) -> str | None:
    """What step 0 took out (``given`` {"run_offsets_dph", "turn_on"}), for the report; None: nothing."""
    parts = (["each training run's offset (per coefficient bank, its mean residual under hdrg fit's model)"]
             if given["run_offsets_dph"] else []) + \
        ([f"hdrg fit's power-on term ({given['turn_on']})"] if given["turn_on"] else [])
    if not parts:
        return None
    return (f"taken out of the runs before the loop: {' and '.join(parts)}"
            + ("; the final model holds the power-on term" if given["turn_on"] else ""))


FLOOR_RATIO = 1.05   # the final model's held-out error may exceed the flight stack's cubic's by this factor at most


def cubic_floor(train, hold, model) -> tuple:
    """The loop's floor: the flight stack's cubic in the temperature sensor
    (host_tools.fitting.baseline.fit_baseline on the training runs, ``model``'s reversal
    settings) against ``model`` on the held-out runs, the same metric as every step
    (host_tools.fitting.diagnose_confirm.HELDOUT_METRIC, samples valid under both).
    ``(info, final)``: info {"cubic_dph", "model_dph", "limit", "replaced" (model_dph > limit x
    cubic_dph)}, or {"error": why} when the cubic cannot be fitted (no temp_c); final: the cubic
    when replaced, else ``model``."""
    from host_tools.fitting.baseline import fit_baseline
    if not all("temp_c" in log for log in train + hold):
        return {"error": "no temp_c column: no flight-stack cubic to compare with"}, model
    try:
        cubic = fit_baseline(train, model.config)
        c, m = (heldout_score(st)[0] for st in step_errors(hold, cubic, model))
    except ValueError as exc:
        return {"error": str(exc)}, model
    replaced = bool(c is not None and m is not None and m > FLOOR_RATIO * c)
    return {"cubic_dph": c, "model_dph": m, "limit": FLOOR_RATIO, "replaced": replaced}, (cubic if replaced else model)


def _metric_text(entry) -> str:
    """The step's outcome with its metric named, for the progress lines: the held-out error
    (diagnose_confirm.HELDOUT_METRIC) before -> after, or without held-out runs the training one."""
    h = entry.get("heldout_error") or {}
    if entry.get("confirmed") is not None and h.get("before") is not None:
        tau = "1-s" if (entry.get("before") or {}).get("std100_dph") is None else "100-s"
        return f"held-out error, std of {tau} averages: {fmt_value(h['before'])} -> {fmt_value(h['after'])} deg/h"
    b, a = (entry.get("train_before") or {}).get("std100_dph"), (entry.get("train_after") or {}).get("std100_dph")
    return f"training error, std of 100-s averages: {fmt_value(b)} -> {fmt_value(a)} deg/h"


def diagnose(train_logs, holdout_logs=(), *, proxy=None, rate_estimator=None, rate_n=None, rate_shift=None,
             terms=None, combiner=None, order=None, settle_s=None, proxy_range=None, rate_range=None,
             max_iter=MAX_ITER, n_surrogates=N_SURROGATES, g_min=G_MIN, cv_blocks=CV_BLOCKS,
             cv_folds=CV_FOLDS, seed=0, families=None, max_tries=None, rate_alternatives=True, out_dir=None,
             plots=True, progress=None, phases=None) -> tuple:
    """Run the closed loop (module doc) on RunLogs.  Returns ``(report, model)``: the report dict
    (the JSON of the module doc) and the final BiasModel (the last step confirmed on the held-out
    runs; without held-out runs the last accepted one).  With ``out_dir`` the files are written
    there (:func:`write_report`).  ``progress``: a callable(str) told what is being done.
    ``phases``: the phases to run (default both, structure first; ``("effect",)`` searches the
    effects on the starting model as it is, e.g. to test one effect family)."""
    check_cv_blocks(cv_blocks)
    say = progress or (lambda msg: None)
    train = list(train_logs)
    hold = list(holdout_logs)
    if not train:
        raise ValueError("no training runs")
    check_distinct_runs(train)
    rev = any(log.reversal for log in train)
    max_tries = TRIES_PER_STEP * max_iter if max_tries is None else max_tries
    opts = base_options(proxy=proxy, rate_estimator=rate_estimator, rate_n=rate_n, rate_shift=rate_shift,
                        combiner=combiner, order=order, settle_s=settle_s, proxy_range=proxy_range,
                        rate_range=rate_range, reversal=rev)
    train_in, hold_in = train, hold
    train, hold, given, term = taken_from_fit(train, hold, opts, terms)
    given["text"] = taken_text(given)
    if given["text"]:
        say(given["text"])
    if term is not None:     # the loop does not offer a second power-on term, and keeps k7 room for it
        families = tuple(f for f in (FAMILIES if families is None else families) if f != "turn_on")
    say(f"fitting the base model on {len(train)} training run(s)")
    model, cfg = base_model(train, opts, terms)
    if all(opts.get(k) is None for k in RATE_KEYS):
        # keep the rate estimator `hdrg fit` chose (auto on MR): every later refit builds its config
        # from opts, which must not fall back to DEFAULT_RATE behind the step's back
        r = cfg.rate
        opts = {**opts, "rate_estimator": r.estimator, "n": r.n, "shift": r.shift}
    poly = poly_terms(model)
    evals = hold if hold else train
    where = confirmation(train, hold)
    cross, checked = where == LEAVING_ONE_OUT, where is not None
    checked_on = "on the held-out runs" if hold else where or "on the training runs"
    rng = np.random.default_rng(seed)
    accepted: list[Accepted] = []
    gen_terms: list = []
    rate_choice = None
    iterations = []
    stopped = None
    excluded: set = set()
    first_stats = error_stats(evals, model)
    report = {"train": [log.source for log in train], "holdout": [log.source for log in hold],
              "evaluated_on": "holdout" if hold else "train", "rule": RULE,
              "confirm_rule": CONFIRM_RULE + ("" if hold else CROSS_NOTE) if checked else "no held-out runs: steps are not confirmed",
              "effect_rule": EFFECT_RULE if checked else "no held-out runs: every accepted effect step is named",
              "settings": {"g_min": g_min, "n_surrogates": n_surrogates, "null_quantile": NULL_QUANTILE,
                           "cv": "runs" if len(train) >= 2 else f"{cv_blocks} blocks round-robin in {cv_folds} folds",
                           "max_iter": max_iter, "max_tries": max_tries, "seed": seed, "terms": [int(k) for k in poly]},
              "baseline": {"holdout" if hold else "train": first_stats,
                           "train": error_stats(train, model) if hold else first_stats},
              "noise_floor": noise_floor(evals, model),
              "holdout_in_training": [f"held-out run {b} has the same data as training run {a}: its 'confirmation' "
                                      f"is not independent" for a, b in same_runs(train_in, hold_in)],
              "not_scanned": not_scanned(train_in + hold_in), "taken_from_fit": given}
    characterization = None
    artifacts = None
    it = 0
    stops = {}
    # structure first (module doc): the model's own structure (rate estimator, lag-state block of
    # the proxy, second thermometer, order/combiner), then the effects on the structured base
    phases = PHASES if phases is None else tuple(phases)
    unknown = set(phases) - set(PHASES)
    if unknown:
        raise ValueError(f"unknown diagnose phases {sorted(unknown)}: choose from {PHASES}")
    for phase in [p for p in PHASES if p in phases]:
        stopped = None
        kept = tries = 0
        while kept < max_iter and tries < max_tries:
            tries += 1
            it += 1
            number = len(iterations) + 1     # the number diagnose.md gives this step
            say(f"iteration {number} ({phase}): scoring the {phase} candidates (CV, {n_surrogates} noise-model surrogates)")
            # (tried: the structure phase also scoring the effect candidates and yielding to a better one;
            # on 76 bench runs it found 2 more aging/turn-on effects but raised "effect found" on clean
            # runs from 3/26 to 8/26: the clean devices' own dynamics then win as effects.  Not kept.)
            compete = COMPETE and phase == "structure" and "effect" in phases
            also = frozenset(COMPETE_FAMILIES) if phase == "structure" and "effect" in phases else frozenset()
            scan = scan_candidates(train, cfg, model, poly, gen_terms, rng, n_surrogates, g_min, cv_blocks, cv_folds,
                         families, rate_alternatives and rate_choice is None, frozenset(excluded),
                         phase=None if compete else phase, also=also, reserved=AUX_RESERVED if term else 0)
            if characterization is None:
                characterization = {"train": scan["characterization"],
                                    "holdout": [characterize(log, r, pr.valid, cfg.rate.fs, pr.v)
                                                for log, (pr, r) in zip(hold, residuals(hold, model))],
                                    "noise_models": [jsonable(nm, skip_private=True) if nm else None
                                                     for nm in scan["noise_models"]]}
                artifacts = {"lines": scan["artifacts"], "combiner_lines": scan["combiner_lines"]}
            if scan["accept"] and compete and kind_of(scan["winner"]["family"], scan["winner"]["params"]) == "effect":
                w = scan["winner"]
                scan = {**scan, "accept": False,
                        "reason": f"an effect candidate ({w['label']}, CV gain {w['gain']:.3f}) explains more than "
                                  f"every structural candidate: the effect phase takes it"}
            if not scan["accept"]:
                stopped = {k: scan[k] for k in ("best", "threshold", "ranking", "reason", "null_max", "not_offered")}
                stopped["phase"] = phase
                say(f"iteration {number} ({phase}): no {phase} candidate passes ({scan['reason']}); the {phase} "
                    f"phase stops")
                break
            best = scan["winner"]
            say(f"iteration {number}: {best['label']} passes (CV gain {best['gain']:.3f} >= {scan['threshold']:.3f}); "
                f"refitting and checking it {checked_on}")
            before_model, before_cfg, before_gen, before_rate = model, cfg, gen_terms, rate_choice
            before = error_stats(evals, model)
            if best["family"] == "rate_estimator":
                bp = best["params"]
                rate_choice = {"estimator": bp["estimator"], "n": bp.get("n", cfg.rate.n), "shift": bp.get("shift", cfg.rate.shift)}
                acc = Accepted("rate_estimator", dict(best["params"]), [], rate_choice)
            else:
                acc = Accepted(best["family"], dict(best["params"]), [dict(t) for t in best["terms"]])
                gen_terms = gen_terms + acc.terms
            model, cfg = refit_with(train, loop_config(train, opts, rate=rate_choice), poly, gen_terms)
            after = error_stats(evals, model)
            if cross:    # no held-out runs: each training run is held out of a refit of both models
                fit_with = lambda rate, gens: lambda runs: refit_with(runs, loop_config(runs, opts, rate=rate), poly, gens)[0]   # noqa: E731
                cb, ca = step_errors_leaving_runs_out(train, fit_with(before_rate, before_gen), fit_with(rate_choice, gen_terms))
            else:
                cb, ca = step_errors(evals, before_model, model)     # the one metric (HELDOUT_METRIC)
            confirmed = confirmed_on_holdout(cb, ca) if checked else None
            material = (confirmed and material_on_holdout(cb, ca)) if checked else None
            entry = {"effect": acc.family, "params": acc.params, "kind": kind_of(acc.family, acc.params),
                     "before": clean_stats(before), "after": clean_stats(after), "confirmed": confirmed, "material": material,
                     "heldout_error": step_metric(cb, ca),
                     "train_before": clean_stats(error_stats(train, before_model)) if hold else clean_stats(before),
                     "train_after": clean_stats(error_stats(train, model)) if hold else clean_stats(after),
                     "cv_gain": best["gain"], "threshold": scan["threshold"], "refined_from": best["coarse"],
                     "folds_improved": best["folds_improved"], "folds": best["folds"],
                     "ranking": scan["ranking"], "null_max": scan["null_max"],
                     "aux": model.config.aux.to_dict(), "rate": model.config.rate.to_dict(),
                     "before_runs": before["runs"], "after_runs": after["runs"]}
            entry["caveat"] = line_or_drift(acc.family, acc.params, train)
            entry["rivals"] = rivals(scan["ranking"], best)
            entry["_plot"] = (before_model, model, best)
            iterations.append(entry)
            if confirmed is False:
                say(f"iteration {number}: {acc.family} NOT confirmed {checked_on} ({_metric_text(entry)}): reverted")
                entry["status"] = f"not confirmed {where}: reverted (the model stays the last confirmed one)"
                model, cfg, gen_terms, rate_choice = before_model, before_cfg, before_gen, before_rate
                excluded.add(step_key(acc.family, acc.params))
            else:
                entry["status"] = f"confirmed {where}" if confirmed else "accepted (no held-out runs)"
                if is_minor(entry):
                    h = entry["heldout_error"]
                    entry["status"] += (f" (minor: held-out error down {1 - h['after'] / h['before']:.0%} only; kept, "
                                        f"not named as an effect)")
                entry["status"] += "".join(f" ({n})" for n in kept_step_notes(entry))
                accepted.append(acc)
                kept += 1
                say(f"iteration {number}: {acc.family} {'confirmed ' + checked_on if confirmed else 'accepted (no held-out runs)'} "
                    f"({_metric_text(entry)}): kept")
        else:
            if max_iter > 0:
                stopped = {"reason": f"max_iter ({max_iter}) reached" if kept >= max_iter else
                           f"{tries} steps tried, {kept} kept (at most {max_tries} tries per phase)", "best": None, "threshold": None,
                           "ranking": [], "null_max": [], "phase": phase}
        if phase == "structure" and rev and max_iter > 0:
            say("structural candidates: regress-then-reverse (per-mode banks) with each combiner, and the "
                "settling window after each exchange, by CV")
            for step in (order_step, settle_step):
                entry, alt_model = step(train, hold, evals, cfg, model, cv_blocks, cv_folds)
                if entry is not None and "skipped" in entry:
                    report.setdefault("structural_skipped", []).append(entry["skipped"])
                    say(entry["skipped"])
                elif entry is not None:
                    iterations.append(entry)
                    if entry["confirmed"] is not False:
                        model = alt_model
                        cfg = replace(cfg, reversal=alt_model.config.reversal)
                        opts = {**opts, "reversal": {**opts["reversal"], **entry["params"]}}
                        accepted.append(Accepted(entry["effect"], entry["params"]))
                    say(f"iteration {len(iterations)}: structural {entry['effect']} {entry['params']}: {entry['status']}"
                        f" ({_metric_text(entry)})")
        stops[phase] = stopped
    stopped = stops.get("effect") or stops.get("structure")
    loop_train, loop_hold = train, hold
    final_model = with_decay(model, term[0], term[1]) if term is not None else model   # what is written
    floor, chosen = cubic_floor(train_in, hold_in, final_model) if hold else (None, final_model)
    if floor and floor.get("replaced"):
        say(f"the final model's held-out error {floor['model_dph']:.4g} deg/h is above {FLOOR_RATIO:g} x the "
            f"flight stack's cubic ({floor['cubic_dph']:.4g} deg/h): the cubic is the final model")
        model, train, hold, evals = chosen, train_in, hold_in, hold_in
    # else the loop's model without the term on the loop's runs: the final model's output on the runs as given
    final = error_stats(evals, model)
    verdict = verdict_of(iterations)
    final_train = error_stats(train, model) if hold else final
    report.update({"iterations": iterations, "final": clean_stats(final), "final_runs": final["runs"],
                   "final_train": clean_stats(final_train),
                   "generalization": generalization(heldout_score(final_train)[0], heldout_score(final)[0]) if hold else None,
                   "several_runs": several_runs_caveat(len(train)),
                   "extrapolation": extrapolation(final) if hold else [],
                   "verdict": verdict, "verdict_detail": verdict_detail_text(iterations, where), "cubic_floor": floor,
                   "artifacts": artifacts, "stopped": stopped, "characterization": characterization})
    model = chosen
    model.fit["diagnose"] = {"taken_from_fit": given["text"], "effects": [] if floor and floor.get("replaced") else
                             [{"effect": a.family, "params": a.params} for a in accepted],
                             "verdict": report["verdict"]}
    if out_dir is not None:
        write_report(report, model, out_dir, loop_train, loop_hold, plots=plots)
    for entry in iterations:
        entry.pop("_plot", None)
    return report, model


