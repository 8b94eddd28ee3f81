"""Close the loop on measured data: find the residual of a bias model, trace it to an effect the
model lacks, add that effect through the auxiliary term k7, and report the error before and after:
``hdrg diagnose RUN... [--holdout RUN...] --out DIR [--json report.json]``.

Procedure (:func:`diagnose`)
----------------------------
0. **The start is hdrg fit's model** (:func:`base_model`): host_tools.fitting.fit_pipeline.fit_default
   on the training runs with the loop's options, exactly the model ``hdrg fit`` writes for them
   (rate estimator, terms, lag-state block, power-on term, per-run offsets, guard); its held-out
   figures are the report's ``baseline``.  When the loop keeps no step, the model it writes IS
   that model.
1. **What is not an effect of temperature** (several training runs only): each power-on moves
   the bias by its own offset, and every run recorded from its power-on holds the device's
   turn-on.  The start's power-on term, when it chose one (host_tools.fitting.turn_on), is taken
   out of the training and held-out runs (turn_on.without_term: size x g x the mode sign) and out
   of the start (turn_on.without_decay: the same output on every valid sample), and each training
   run's offset per coefficient bank (its mean residual under that model, the term included) out
   of that run (fit_pipeline.run_offsets, fit_pipeline.without_run_offsets)
   (:func:`taken_from_fit`).  The loop works on those runs (its report's errors are on them),
   does not offer a second power-on term (family ``turn_on``), keeps AUX_RESERVED k7 terms free,
   and the model it writes holds the term again (turn_on.with_decay).  Without this the
   per-power-on offsets and the turn-on are structure the loop explains with whatever channel
   wanders like them (docs/LOOP.md "Several power-ons").  The start's k7 (its lag-state block and
   the rest of its generators) enters the loop as ONE column (diagnose_scan.FIT_BLOCK: its shape
   kept, its size refitted with every step), beside which the loop adds its own generators: the
   chip's k7 sum holds AUX_MAX_TERMS (16) terms.  Options given to the loop
   (``--proxy``, ``--rate-estimator``, ``--terms``, ``--order``, ``--combiner``) are given to
   the fit as in ``hdrg fit``.  A regress_first model (two coefficient banks by mode) is scanned
   with the banked design: every column once per mode, on the per-mode used samples, target c = s
   * rate, raw noise surrogates (no combiner in the target).
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
   **Firmware capacity**: the k7 sum holds at most AUX_MAX_TERMS (16) terms, so a candidate that
   would not fit beside the start's and the accepted generators is not offered (``not_offered``
   in ``stopped``).
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
   **Never worse than hdrg fit** (:func:`versus_fit`): a step is confirmed only when it raises no
   figure the report gives (CONFIRM_RULE: the std of 1-s averages by <= 1 %, the start-up figures
   of held-out runs recorded from a power-on by <= 2 %); and the final model is compared with the
   start on every figure (VERSUS_KEYS: std of 100-s and 1-s averages, the start window's
   stability and the 0-5 min repeatability) on the held-out runs, or leaving each training run
   out (both refitted on the others); when it raises any by more than FIT_TOL (2 %), the model
   written is hdrg fit's, the verdict NOT_KEPT ("hdrg fit's model kept") and the report says
   on which figure it lost (``versus_fit``; the steps stay listed, ``undone``).
   **Second pass**: with held-out runs, when the final held-out error is above SECOND_PASS_FLOOR x
   the noise floor and the start has a k7 sum, the loop runs again from the start without it (a
   lag-state block fitted to the training runs can take an effect's shape there and hide it from
   the scan) and that pass's model replaces the first's only when it beats it as a step would
   (CONFIRM_RULE; ``fit_block_replaced`` in the report).  **Fit only**: a confirmed effect step
   whose terms stay below SERVED_MIN_G of their size on every sample the output serves (a decay
   over the first mode window after power-on, which the per-mode fit uses and the combined output
   does not serve) is counted as structure (``fit_only``): it changes the fit, not the output.
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

import copy
from dataclasses import replace

import numpy as np

from host_tools.fitting.diagnose_confirm import (CONFIRM_MIN_DROP, CONFIRM_RULE, CONFIRM_TOL_1S, CONFIRM_TOL_RMS,  # noqa: F401
                                         EFFECT_RULE, HELDOUT_METRIC, REPORT_TAUS, STAT_KEYS, clean_stats, fmt_value, residuals, heldout_score,
                                         stats_one, step_metric, confirmed_on_holdout, error_stats, leg_rms, step_errors_leaving_runs_out,
                                         confirmation, LEAVING_ONE_OUT, pooled_step_errors, worse_figures,
                                         material_on_holdout, noise_floor, offsets_hold, step_errors)
from host_tools.fitting.diagnose_noise import (allan_bridged, noise_series, artifact_of, characterize,  # noqa: F401
                                       combiner_lines, noise_model, spectral_lines, surrogates)
from host_tools.fitting.diagnose_report import (VERDICTS, verdict_detail_text, extrapolation, generalization, is_minor, kept_step_notes,
                                                line_or_drift, not_scanned, several_runs_caveat, verdict_of, write_report)
from host_tools.fitting.diagnose_scan import (CV_BLOCKS, CV_FOLDS, DRIFT_MARGIN, G_MIN, MAX_ITER, N_SURROGATES,  # noqa: F401
                                      NULL_QUANTILE, PHASES, STRUCT_TAU_FRACTION, STRUCTURAL, TRIES_PER_STEP, Accepted,
                                      loop_config, poly_terms, scan_candidates, step_key, kind_of, refit_with, rivals, fit_block)
from host_tools.fitting.diagnose_structure import order_step, settle_step
from host_tools.fitting.effects import FAMILIES
from host_tools.fitting.fit import check_cv_blocks, fit_logs
from host_tools.fitting.fit_pipeline import fit_default, run_offsets, without_run_offsets
from host_tools.fitting.turn_on import chosen_term, with_decay, without_decay, without_term
from host_tools.golden.checks import check_distinct_runs, same_runs
from host_tools.golden.model import jsonable
from host_tools.golden.regressors import AuxConfig


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


def base_model(train, opts, terms=None) -> tuple:
    """(model, its config): ``hdrg fit``'s model of the training runs with the loop's options
    (host_tools.fitting.fit_pipeline.fit_default: rate estimator, terms, lag-state block, power-on
    term, per-run offsets, guard; ``terms`` None -> its defaults), terms the data cannot identify
    dropped.  The model the loop starts from (:func:`start_model`) and compares its final model
    with (:func:`versus_fit`)."""
    import warnings

    given = any(opts.get(k) is not None for k in RATE_KEYS)
    with warnings.catch_warnings():     # the fit warns about the inputs once (hdrg fit shows them)
        warnings.simplefilter("ignore")
        model = fit_default(train, terms, drop_unidentifiable=True,
                            **{k: v for k, v in opts.items() if given or k not in RATE_KEYS})[0]
    return model, model.config


def start_model(train, fitted, term, opts, terms=None, with_block=True) -> tuple:
    """(model, config, generators) the loop starts from on its runs ``train`` (step 1 done):
    with no rate option, ``fitted`` (hdrg fit's model) without its power-on ``term`` (which step 1
    took out of the runs: the same output), its k7 as one FIT_BLOCK generator; with a rate option
    given, that estimator's fit of the terms (host_tools.fitting.fit.fit_logs) with no k7, the
    start the loop's family thresholds were calibrated from."""
    if all(opts.get(k) is None for k in RATE_KEYS):
        model = without_decay(fitted, term[0]) if term is not None else fitted
        if not with_block and fit_block(model):     # the second pass (module doc): the fit's k7 left out
            model, cfg = refit_with(train, replace(model.config, aux=AuxConfig()), poly_terms(model), [])
            return model, cfg, []
        return model, model.config, fit_block(model)
    cfg = loop_config(train, opts)
    return fit_logs(train, cfg, terms, drop_unidentifiable=True)[0], cfg, []


def taken_from_fit(train, hold, fitted) -> tuple:
    """Step 0 (module doc): with several training runs, what ``fitted`` (:func:`base_model`)
    learned that is not an effect of temperature: its power-on term, when it chose one
    (host_tools.fitting.turn_on), comes out of the training and held-out runs, and each training
    run's offset per coefficient bank (its mean residual under that model, the term included:
    fit_pipeline.run_offsets) out of that run.  Returns (training runs, held-out runs, ``given``
    {"run_offsets_dph", "turn_on"}, ``term``: (decay term, scale) for the final model, or None).
    One run: nothing is taken."""
    given = {"run_offsets_dph": None, "turn_on": None}
    if len(train) < 2:
        return train, hold, given, None
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


NOT_KEPT = VERDICTS[5]   # "hdrg fit's model kept": the verdict when the final model lost to hdrg fit's (versus_fit)
FIT_TOL = 0.02     # the loop's final model loses to hdrg fit's when it raises a figure by more than 2 %
VERSUS_KEYS = ("std100_dph", "std_dph", "start_std_dph", "start_rep_dph", "served_share")
VERSUS_NAMES = {"std100_dph": "std of 100-s averages", "std_dph": "std of 1-s averages",
                "start_std_dph": "start window's stability", "start_rep_dph": "0-5 min repeatability",
                "served_share": "share of the samples served"}


def versus_fit(train, hold, fitted, final, refit_final, opts, terms, term) -> dict:
    """The loop's final model against ``fitted`` (hdrg fit's model of ``train``, the loop's start) on
    every figure the loop reports (VERSUS_KEYS: the std of 100-s and of 1-s averages and, where the
    runs start at a power-on and last 45 min, the start window's stability and the 0-5 min
    repeatability): on the held-out runs (``hold``) when there are any, else leaving one training
    run out (both refitted on the others: hdrg fit's model by :func:`base_model`, the loop's by
    ``refit_final`` on the others with the power-on ``term`` taken out and put back; None: the
    final model as it is), else not compared.  ``kept`` is 'fit' when the final model raises any
    figure by more than FIT_TOL (``why`` names them), else 'loop'.  The runs as given (no step 0)."""
    if hold:
        fb, fl = step_errors(hold, fitted, final)
        on = "the held-out runs"
    elif len(train) >= 2:
        pairs = []
        fs = fitted.config.rate.fs
        for i, log in enumerate(train):
            others = [lg for j, lg in enumerate(train) if j != i]
            f_i = base_model(others, opts, terms)[0]
            if refit_final is None:
                l_i = final
            else:
                inner = others
                if len(others) >= 2 and f_i.fit.get("run_offsets", {}).get("offsets_dph"):
                    inner = without_run_offsets(others, run_offsets(others, f_i))
                if term is not None:
                    inner = [without_term(lg, *term, fs) for lg in inner]
                l_i = refit_final(inner)
                l_i = with_decay(l_i, *term) if term is not None else l_i
            pairs.append(step_errors([log], f_i, l_i))
        fb, fl = pooled_step_errors(pairs)
        on = "each training run left out"
    else:
        return {"on": None, "kept": "loop", "why": "one training run and no held-out run: not compared", "figures": {}}
    figures = {k: {"fit": fb.get(k), "loop": fl.get(k)} for k in VERSUS_KEYS}
    worse = worse_figures(fb, fl, VERSUS_KEYS, FIT_TOL)
    why = "; ".join(f"{VERSUS_NAMES[k.split(' (')[0]]}{k[len(k.split(' (')[0]):]} {fmt_value(b)} -> {fmt_value(a)}"
                    + ("" if k.startswith("served") else " deg/h") for k, b, a in worse)
    return {"on": on, "tolerance": FIT_TOL, "figures": figures, "kept": "fit" if worse else "loop",
            "why": (why + f" ({on})") if worse else None}


SECOND_PASS_FLOOR = 2.0   # the second pass (without hdrg fit's k7) runs when the held-out error is above this x the noise floor
SERVED_MIN_G = 0.05   # an effect step whose terms stay below this (|g|) on every served sample changes the fit only


def served_size(logs, model, terms) -> float:
    """The largest |g| of the generator ``terms`` (each at weight 1) over the samples ``model``'s
    output serves on ``logs``: how much of the term the user's output can ever carry."""
    from host_tools.golden.compensate import prepare
    from host_tools.golden.regressors import generator_values
    fs = model.config.rate.fs
    top = 0.0
    for log in logs:
        valid = prepare(log, model).valid           # the compensated output's valid column, without computing it
        if valid.any():
            top = max(top, max(float(np.max(np.abs(generator_values(log, t, fs)[valid]))) for t in terms))
    return top


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
             plots=True, progress=None, phases=None, _without_block=False, _fitted=None) -> tuple:
    """Run the closed loop (module doc) on RunLogs.  Returns ``(report, model)``: the report dict
    (the JSON of the module doc) and the final BiasModel (the last step confirmed on the held-out
    runs; without held-out runs the last accepted one).  With ``out_dir`` the files are written
    there (:func:`write_report`).  ``progress``: a callable(str) told what is being done.
    ``phases``: the phases to run (default both, structure first; ``("effect",)`` searches the
    effects on the starting model as it is, e.g. to test one effect family)."""
    call = dict(locals())       # this call's arguments: the second pass repeats them
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
    train_in, hold_in, opts0 = train, hold, opts
    say(f"fitting hdrg fit's model of {len(train)} training run(s): the loop's start")
    fitted, cfg = base_model(train, opts, terms) if _fitted is None else (_fitted, _fitted.config)
    train, hold, given, term = taken_from_fit(train, hold, fitted)
    given["text"] = taken_text(given)
    if given["text"]:
        say(given["text"])
    if term is not None:     # the loop does not offer a second power-on term, and keeps k7 room for it
        families = tuple(f for f in (FAMILIES if families is None else families) if f != "turn_on")
    model, cfg, gen_terms = start_model(train, fitted, term, opts, terms, with_block=not _without_block)
    start_block = bool(fit_block(model))
    if all(opts.get(k) is None for k in RATE_KEYS):
        # keep the rate estimator `hdrg fit` chose (auto on MR): every later refit builds its config
        # from opts, which must not fall back to DEFAULT_RATE behind the step's back
        r = cfg.rate
        opts = {**opts, "rate_estimator": r.estimator, "n": r.n, "shift": r.shift}
    if opts.get("proxy_kind") is None:
        opts = {**opts, "proxy_kind": cfg.proxy.kind}
    poly = poly_terms(model)
    evals = hold if hold else train
    where = confirmation(train, hold)
    cross, checked = where == LEAVING_ONE_OUT, where is not None
    checked_on = "on the held-out runs" if hold else where or "on the training runs"
    rng = np.random.default_rng(seed)
    accepted: list[Accepted] = []
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
            kind = kind_of(acc.family, acc.params)
            unserved = kind == "effect" and acc.terms and served_size(evals, model, acc.terms) < SERVED_MIN_G
            if unserved:      # the term is ~0 wherever the output is served: it changes the fit, not the output
                kind = "structure"
            entry = {"effect": acc.family, "params": acc.params, "kind": kind,
                     "before": clean_stats(before), "after": clean_stats(after), "confirmed": confirmed, "material": material,
                     "heldout_error": step_metric(cb, ca),
                     "train_before": clean_stats(error_stats(train, before_model)) if hold else clean_stats(before),
                     "train_after": clean_stats(error_stats(train, model)) if hold else clean_stats(after),
                     "cv_gain": best["gain"], "threshold": scan["threshold"], "refined_from": best["coarse"],
                     "folds_improved": best["folds_improved"], "folds": best["folds"],
                     "ranking": scan["ranking"], "null_max": scan["null_max"],
                     "aux": model.config.aux.to_dict(), "rate": model.config.rate.to_dict(),
                     "before_runs": before["runs"], "after_runs": after["runs"]}
            if unserved:
                entry["fit_only"] = (f"its term is below {SERVED_MIN_G:g} of its size on every sample the output "
                                     f"serves (e.g. a decay over the first mode window after power-on, which the "
                                     f"per-mode fit uses and the combined output does not serve): it changes how the "
                                     f"model is fitted, not the output, so it is counted as structure")
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
    changed = bool(accepted)
    final_model = fitted if not changed else with_decay(model, term[0], term[1]) if term is not None else model
    floor, chosen = cubic_floor(train_in, hold_in, final_model) if hold else (None, final_model)
    if floor and floor.get("replaced"):
        say(f"the final model's held-out error {floor['model_dph']:.4g} deg/h is above {FLOOR_RATIO:g} x the "
            f"flight stack's cubic ({floor['cubic_dph']:.4g} deg/h): the cubic is the final model")
    versus = None
    if changed and not (floor and floor.get("replaced")):
        refit_final = lambda runs: refit_with(runs, loop_config(runs, opts, rate=rate_choice), poly, gen_terms)[0]   # noqa: E731
        versus = versus_fit(train_in, hold_in, fitted, chosen, refit_final, opts0, terms, term)
        if versus["kept"] == "fit":
            say(f"the loop's final model loses to hdrg fit's on {versus['why']}: hdrg fit's model is the final model")
            chosen = fitted
    if chosen is not final_model or not changed:
        # the cubic or hdrg fit's model: judged on the runs as given
        model, train, hold, evals = chosen, train_in, hold_in, (hold_in if hold_in else train_in)
    # else the loop's model without the term on the loop's runs: the final model's output on the runs as given
    final = error_stats(evals, model)
    verdict = verdict_of(iterations)
    detail = verdict_detail_text(iterations, where)
    if versus and versus["kept"] == "fit":
        for entry in iterations:
            if entry.get("confirmed"):
                entry["undone"] = True
                entry["status"] += "; undone: the final model lost to hdrg fit's"
        verdict = NOT_KEPT
        detail = (f"steps held one by one ({verdict_of(iterations)}: {detail}), but the final model lost to hdrg fit's "
                  f"on {versus['why']}: hdrg fit's model is written")
    final_train = error_stats(train, model) if hold else final
    report.update({"iterations": iterations, "final": clean_stats(final), "final_runs": final["runs"],
                   "final_train": clean_stats(final_train),
                   "generalization": generalization(heldout_score(final_train)[0], heldout_score(final)[0]) if hold else None,
                   "several_runs": several_runs_caveat(len(train)),
                   "extrapolation": extrapolation(final) if hold else [],
                   "verdict": verdict, "verdict_detail": detail, "cubic_floor": floor, "versus_fit": versus,
                   "final_is": "hdrg fit's model" if chosen is fitted else "the flight stack's cubic"
                   if floor and floor.get("replaced") else "the loop's model",
                   "artifacts": artifacts, "stopped": stopped, "characterization": characterization})
    model = chosen
    written = [] if chosen is fitted or (floor and floor.get("replaced")) else accepted
    model.fit["diagnose"] = {"taken_from_fit": given["text"], "effects": [{"effect": a.family, "params": a.params}
                                                                          for a in written],
                             "verdict": report["verdict"], "final_is": report["final_is"]}
    nf = report["noise_floor"]["std100_dph"] if report["final"].get("std100_dph") is not None else report["noise_floor"]["std_dph"]
    far = nf is None or (heldout_score(report["final"])[0] or 0.0) > SECOND_PASS_FLOOR * nf
    if hold and start_block and not _without_block and max_iter > 0 and far:
        say("the loop again from hdrg fit's model without its k7 sum (a lag-state block fitted to the training "
            "runs can hide an effect from the scan)")
        alt_rep, alt_model = diagnose(**{**call, "train_logs": train_in, "holdout_logs": hold_in, "out_dir": None,
                                         "plots": False, "_without_block": True, "_fitted": copy.deepcopy(fitted)})
        if alt_rep["final_is"] == "the loop's model":
            sb, sa = step_errors(hold_in, model, alt_model)
            if confirmed_on_holdout(sb, sa):
                metric = step_metric(sb, sa)
                say(f"without hdrg fit's k7 the loop ends better on the held-out runs ({_metric_text({'confirmed': True, 'heldout_error': metric, 'before': sb})}): "
                    f"its model replaces it")
                alt_rep["fit_block_replaced"] = {
                    "why": "the loop from hdrg fit's model without its k7 sum (lag-state block) ended better on the "
                           "held-out runs than the loop from the model with it (judged as a step: confirm_rule)",
                    "with_block": metric["before"], "without_block": metric["after"],
                    "with_block_iterations": [{k: it[k] for k in ("effect", "params", "kind", "confirmed")}
                                              for it in iterations]}
                alt_rep["verdict_detail"] += ("; hdrg fit's lag-state block was left out: the loop without it "
                                              "ended better on the held-out runs")
                alt_rep["baseline_without_block"] = alt_rep["baseline"]
                alt_rep["baseline"] = report["baseline"]      # the figures of hdrg fit's model come first
                report, model = alt_rep, alt_model
    if out_dir is not None:
        write_report(report, model, out_dir, loop_train, loop_hold, plots=plots)
    for entry in report["iterations"]:
        entry.pop("_plot", None)
    for entry in iterations:
        entry.pop("_plot", None)
    return report, model


