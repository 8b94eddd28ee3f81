"""`hdrg bench loop`: the closed loop (host_tools.fitting.diagnose) on random FOREIGN devices
(host_tools.simulation.sim_foreign) with undeclared effects: detection, false discovery, never worse.

Runs ``i = 0 .. N-1`` (``--runs``, default 120), device seed ``S * 100000 + i`` (``--seed`` S):

* every third run (i % 3 == 0) is **clean** (no effect); the others carry ONE undeclared effect,
  the kinds of host_tools.simulation.sim_foreign.EFFECT_KINDS in turn (9 kinds), at a random strength
  log-uniform in [STRENGTH_LO, STRENGTH_HI] (x the kind's nominal amplitude);
* run type: mode reversal for i % 2 == 1 or for the MR-only kinds (exchange_transient,
  imperfect_reversal), else FTR;
* **train** on one run (4 degC/min, power-on 0, noise seed 0), **hold out** another (2 degC/min,
  power-on 1: another damping change, noise seed 1): ``diagnose([train], [holdout])`` with its
  defaults (single training run: CV over time blocks; every step confirmed on the held-out run).
  ``--second-train CPM``: a second training run at CPM degC/min from the SAME power-on (noise seed
  SECOND_TRAIN_NOISE), ``diagnose([train, train2], [holdout])``: the loop's CV then leaves one run
  out, i.e. scores every candidate by how it carries to another chamber rate; the base model,
  ``effect_ratio`` and ``oracle_fit_ratio`` are taken on the same two runs.

Per run the record holds the verdict, every step (effect, parameters, held-out before/after,
confirmed), and ``effect_ratio``: the held-out error of the base model (the loop's starting
model = the product default of ``hdrg fit``, fitted on the training run) on the run WITH the effect over that on the same run without it (same device,
power-ons and noise: the foreign simulator draws the noise independently of the effects).
``effect_ratio >= 2`` means that modelling the true effect perfectly would halve the held-out
error: the runs where the loop must find it.  Error = std of 100-s averages of the compensated
output (diagnose.error_stats).

Summary (the loop's targets):

* ``detection``: among effect runs with effect_ratio >= 2, the fraction whose CONFIRMED, MATERIAL
  EFFECT steps (diagnose.EFFECT_RULE: held-out error down by >= 18 %, the steps that make the verdict
  "effect found") name the true family (aux: any aux_* column; ``detection_incl_minor``: minor
  effect steps counted too); ``detection_or_structure`` also counts a
  confirmed STRUCTURE step of the same family (the lag-state block of the proxy for thermal_lag,
  the second thermometer for board_temp: the structure phase of diagnose runs first and may
  take the injected effect as the device's structure);
* ``false_discovery``: among clean runs, the fraction with verdict "effect found"; also split by
  run type (``mr_control``: clean MR runs) and ``structural_only`` (clean runs whose confirmed
  steps are all structural, verdict "model structure improved": another rate estimator or
  the lag-state block, the second thermometer or the combiner, not an effect), ``minor_only``
  (clean runs whose only kept steps are minor effect steps, verdict "minor improvement confirmed")
  and ``minor_effect_steps_clean`` (minor effect steps kept on clean runs);
* ``clean_found_not_generalizing``: clean runs with "effect found" whose final model is not
  better than the base model on an independent THIRD run (3 degC/min, power-on 2, noise 2):
  a found "effect" that does not generalize is a false discovery in the strict sense; one that
  does is physics of the device the 16 terms lack (the foreign devices' lagged thermal nodes);
* ``clean_found_self_heating``: of the clean runs with "effect found", those whose named effects are
  all a turn-on at the time constant of the device's own power-on self-heating
  (:func:`self_heating_turn_on`): clean physics of the family, counted in ``false_discovery`` all
  the same;
* ``worse_confirmed``: confirmed steps whose held-out error went UP (target 0); a step's held-out
  error is the one the loop confirms it by (diagnose.step_errors, diagnose.HELDOUT_METRIC: std of
  100-s averages on the samples valid under both models), recorded in ``iterations[].heldout_error``;
* ``found_without_drop``: "effect found" runs whose final held-out error is not below the base
  model's (target 0).
"""
from __future__ import annotations

import functools
import json
import math
import time
import warnings

import numpy as np
from pathlib import Path

from host_tools.atomic import atomic_open, atomic_path
from host_tools.fitting.diagnose_scan import poly_terms, refit_with
from host_tools.fitting.effects import effect_term, training_range
from host_tools.fitting.diagnose import heldout_score, base_model, base_options, diagnose, error_stats
from host_tools.fitting.diagnose_report import is_minor
from host_tools.simulation.sim_foreign import EFFECTS, EFFECT_KINDS, foreign_device, simulate_foreign

SEED_STRIDE = 100000
STRENGTH_LO, STRENGTH_HI = 1.0, 10.0
SECOND_TRAIN_NOISE = 3   # --second-train: the second training run's noise seed (power-on 0, as the first)
MATTERS_RATIO = 2.0
DETECTION_RULE = ("detection: effect runs with effect_ratio >= 2 whose CONFIRMED, MATERIAL steps of kind 'effect' "
                  "(diagnose.EFFECT_RULE: the ones that make the verdict 'effect found') name the injected family "
                  "(aux: any aux_* column); detection_or_structure: ... whose confirmed steps of either kind name it (the report names the family in both cases: a thermal_lag found as a lag "
                  "of the proxy, board_temp as the second thermometer); clean_runs_naming_family: clean runs whose "
                  "confirmed steps (either kind) name the family, the false-positive side of the same count")
IDENTIFIABLE_RULE = ("*_identifiable: the same counts over the effect runs whose oracle_fit_ratio is also >= 2: "
                     "the base model plus the TRUE effect signal as one k7 term, fitted on the training run, "
                     "halves the held-out error ('adding the true effect halves the error'); "
                     "effect_ratio alone removes the effect from the physics, which no model fitted on one "
                     "temperature rate may be able to do (u^4 absorbed by the cross terms of the 17)")


def plan(n_runs: int, seed: int = 0) -> list:
    """The runs of the benchmark: dicts {i, device, effect (None: clean), strength, reversal}."""
    rng = np.random.default_rng([seed, 7])
    out = []
    k = 0
    for i in range(n_runs):
        strength = float(math.exp(rng.uniform(math.log(STRENGTH_LO), math.log(STRENGTH_HI))))
        if i % 3 == 0:
            effect = None
        else:
            effect = EFFECT_KINDS[k % len(EFFECT_KINDS)]
            k += 1
        reversal = bool(i % 2 == 1 or (effect is not None and EFFECTS[effect].runs == "mr"))
        out.append({"i": i, "device": seed * SEED_STRIDE + i, "effect": effect,
                    "strength": strength if effect else 0.0, "reversal": reversal})
    return out


def _named(kind: str, family: str) -> bool:
    return family == kind or (kind == "aux" and family.startswith("aux_"))


def _logs(train) -> list:
    """One training RunLog or a list of them -> a list."""
    return list(train) if isinstance(train, (list, tuple)) else [train]


def _base_model(train):
    """The loop's starting model: the product default of ``hdrg fit`` (diagnose.base_model) on the
    training run(s) ``train`` (a RunLog or a list)."""
    logs = _logs(train)
    return base_model(logs, base_options(reversal=logs[0].reversal))[0]


def _base_error(train, hold) -> float:
    return heldout_score(error_stats([hold], _base_model(train)))[0]


def _oracle_fit_error(base, train, hold, ctrain, chold) -> float:
    """Held-out error of the base model ``base`` (fitted on ``train``, a RunLog or a list) plus the
    TRUE effect as one more k7 input term fitted on the training run(s): the effect's own signal
    (each run with the effect minus the same run without it, ``ctrain`` in the same order: the
    foreign simulator draws the noise independently of the effects), column ``aux_truth``,
    sign-interacted on mode-reversal runs (it enters the rate as s * flipping + non-flipping
    effects, so c = s * rate holds it whole).  What a loop that names the family AND its
    parameters exactly can reach from these training runs; base / this = ``oracle_fit_ratio``."""
    tr = [t.with_columns(aux_truth=t.rate_dph - c.rate_dph) for t, c in zip(_logs(train), _logs(ctrain))]
    ho = hold.with_columns(aux_truth=hold.rate_dph - chold.rate_dph)
    ref, span = training_range(tr, "aux_truth")
    truth = effect_term("input", "truth", column="aux_truth", ref=ref, span=span, sign=bool(tr[0].reversal))
    oracle, _ = refit_with(tr, base.config, poly_terms(base), [truth])
    return heldout_score(error_stats([ho], oracle))[0]


def _training_runs(dev, rev, duration_s, second_train, **effect) -> list:
    """The training run (4 degC/min, power-on 0, noise 0) and, with ``second_train`` (degC/min), a
    second one at that chamber rate from the SAME power-on (noise SECOND_TRAIN_NOISE)."""
    runs = [simulate_foreign(dev, 4.0, rev, 0, 0, duration_s=duration_s, **effect)]
    if second_train:
        runs.append(simulate_foreign(dev, float(second_train), rev, 0, SECOND_TRAIN_NOISE, duration_s=duration_s, **effect))
    return runs


def run_one(spec: dict, duration_s=None, n_surrogates=None, second_train=None) -> dict:
    """One benchmark run (module doc): the record.  ``second_train``: None, or the chamber rate
    [degC/min] of a second training run from the same power-on (``hdrg bench loop
    --second-train``): the loop then cross-validates over the two runs."""
    dev = foreign_device(spec["device"])
    eff, rev, st = spec["effect"], spec["reversal"], spec["strength"]
    t0 = time.time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        train = _training_runs(dev, rev, duration_s, second_train, effect=eff, strength=st or 1.0)
        hold = simulate_foreign(dev, 2.0, rev, 1, 1, duration_s=duration_s, effect=eff, strength=st or 1.0)
        kw = {} if n_surrogates is None else {"n_surrogates": n_surrogates}
        rep, model = diagnose(train, [hold], plots=False, **kw)
        third = simulate_foreign(dev, 3.0, rev, 2, 2, duration_s=duration_s, effect=eff, strength=st or 1.0)
        base = _base_model(train)
        base3 = heldout_score(error_stats([third], base))[0]
        final3 = heldout_score(error_stats([third], model))[0]
        ratio = fit_ratio = None
        if eff is not None:
            ctrain = _training_runs(dev, rev, duration_s, second_train)
            chold = simulate_foreign(dev, 2.0, rev, 1, 1, duration_s=duration_s)
            ratio = heldout_score(rep["baseline"]["holdout"])[0] / _base_error(ctrain, chold)
            fit_ratio = heldout_score(rep["baseline"]["holdout"])[0] / _oracle_fit_error(base, train, hold, ctrain, chold)
    steps = [{"effect": it["effect"], "params": it["params"], "kind": it["kind"], "confirmed": it["confirmed"],
              "material": it["material"], "undone": bool(it.get("undone")),
              "before": it["heldout_error"]["before"], "after": it["heldout_error"]["after"]}
             for it in rep["iterations"]]
    b, f = heldout_score(rep["baseline"]["holdout"])[0], heldout_score(rep["final"])[0]
    nf = rep["noise_floor"]
    floor = nf["std100_dph"] if (rep["baseline"]["holdout"].get("std100_dph") is not None) else nf["std_dph"]
    return {**spec, "verdict": rep["verdict"], "steps": steps,
            "base": b, "final": f, "floor": floor,
            "gap_closed": (b - f) / (b - floor) if floor is not None and b > floor else None,
            "loop_vs_fit": f / b if b else None, "final_is": rep.get("final_is"),
            "valid_share": _valid_share(hold, model), "valid_share_fit": _valid_share(hold, base),
            "third_base": base3, "third_final": final3,
            "effect_ratio": ratio, "oracle_fit_ratio": fit_ratio,
            "named": bool(eff and any(_names_effect(s) and _named(eff, s["effect"]) for s in steps)),
            "named_or_structure": bool(eff and any(s["confirmed"] and not s["undone"] and _named(eff, s["effect"]) for s in steps)),
            "artifacts": [a["period_s"] for a in (rep["artifacts"] or {}).get("lines", [])],
            "seconds": round(time.time() - t0, 2)}


def _valid_share(log, model) -> float:
    """The share of ``log``'s servable samples that ``model``'s output serves (the accuracy
    benchmark's count: host_tools.bench.accuracy.heldout_output)."""
    from host_tools.bench.accuracy import heldout_output
    return heldout_output(model, log)[1]


LOOP_TOLERANCE = 1.05     # a run (a start-up device: bench.startup) fails when the loop's final model is more than 5 % worse than hdrg fit's
GAP_HALF = 0.5            # the loop should close at least half of the gap between the start and the noise floor


def _confirmed_effect(step) -> bool:
    """A confirmed effect step still in the final model (not undone because the final model lost
    to hdrg fit's)."""
    return bool(step["confirmed"] and step["kind"] == "effect" and not step.get("undone"))


def _names_effect(step) -> bool:
    """A step that names an effect: confirmed, kind 'effect' and material (diagnose.EFFECT_RULE;
    records written before that rule have no ``material`` and count as material)."""
    return _confirmed_effect(step) and not is_minor(step)


SELF_HEATING_TAU_FACTOR = 3.0   # a turn-on within this factor of the device's self-heating time constant


def self_heating_turn_on(rec) -> bool:
    """A clean foreign run whose "effect found" is the device's OWN power-on self-heating: every step
    that names an effect is a turn_on whose time constant lies within SELF_HEATING_TAU_FACTOR of the
    self-heating's (sim_foreign: part of the family's clean physics; a node the proxy does not share
    with the bias heats up after power-on).  The strict false discovery still counts such a run;
    docs/LOOP.md, "Self-heating: the clean runs' own turn-on"."""
    steps = [s for s in rec["steps"] if _names_effect(s)]
    if rec["effect"] or rec["verdict"] != "effect found" or not steps or any(s["effect"] != "turn_on" for s in steps):
        return False
    tau = foreign_device(rec["device"]).self_heating["tau_s"]
    return all(1.0 / SELF_HEATING_TAU_FACTOR <= s["params"]["tau_s"] / tau <= SELF_HEATING_TAU_FACTOR for s in steps)


def _frac(num, den):
    return {"n": den, "k": num, "rate": (num / den) if den else None}


def summarize(records: list) -> dict:
    """The summary of module doc from the records."""
    matters = [r for r in records if r["effect"] and r["effect_ratio"] is not None and r["effect_ratio"] >= MATTERS_RATIO]
    ident = [r for r in matters if (r.get("oracle_fit_ratio") or 0) >= MATTERS_RATIO]
    clean = [r for r in records if not r["effect"]]
    found = [r for r in records if r["verdict"] == "effect found"]
    structural = [r for r in records if r["verdict"] in ("model structure improved", "minor improvement confirmed")]
    confirmed = [s for r in records for s in r["steps"] if s["confirmed"]]
    struct = [r for r in clean if r["verdict"] == "model structure improved"]
    per_kind, per_kind_s = {}, {}
    for kind in EFFECT_KINDS:
        rs = [r for r in matters if r["effect"] == kind]
        per_kind[kind] = _frac(sum(r["named"] for r in rs), len(rs))
        per_kind_s[kind] = _frac(sum(r.get("named_or_structure", r["named"]) for r in rs), len(rs))
    # the specificity of naming a family: clean runs whose confirmed steps (any kind) name it
    clean_named = {kind: sum(1 for r in clean if any(s["confirmed"] and _named(kind, s["effect"]) for s in r["steps"]))
                   for kind in EFFECT_KINDS}
    return {"runs": len(records), "effect_runs": sum(1 for r in records if r["effect"]),
            "detection_rule": DETECTION_RULE,
            "clean_runs_naming_family": {"n": len(clean), **clean_named},
            "detection": _frac(sum(r["named"] for r in matters), len(matters)), "detection_per_kind": per_kind,
            "detection_incl_minor": _frac(sum(any(_confirmed_effect(s) and _named(r["effect"], s["effect"])
                                                  for s in r["steps"]) for r in matters), len(matters)),
            "detection_or_structure": _frac(sum(r.get("named_or_structure", r["named"]) for r in matters), len(matters)),
            "detection_or_structure_per_kind": per_kind_s,
            "identifiable": IDENTIFIABLE_RULE,
            "detection_identifiable": _frac(sum(r["named"] for r in ident), len(ident)),
            "detection_or_structure_identifiable": _frac(sum(r["named_or_structure"] for r in ident), len(ident)),
            "false_discovery": _frac(sum(r["verdict"] == "effect found" for r in clean), len(clean)),
            "false_discovery_ftr": _frac(sum(r["verdict"] == "effect found" for r in clean if not r["reversal"]),
                                         sum(1 for r in clean if not r["reversal"])),
            "mr_control": _frac(sum(r["verdict"] == "effect found" for r in clean if r["reversal"]),
                                sum(1 for r in clean if r["reversal"])),
            "clean_found_self_heating": sum(self_heating_turn_on(r) for r in clean),
            "structural_only": len(struct),
            "minor_only": sum(1 for r in clean if r["verdict"] == "minor improvement confirmed"),
            "minor_effect_steps_clean": sum(is_minor(s) for r in clean for s in r["steps"]),
            "clean_found_not_generalizing": sum(1 for r in clean if r["verdict"] == "effect found"
                                                and not r["third_final"] < r["third_base"]),
            "clean_found_third_run_gain": [round(r["third_base"] / r["third_final"], 3) for r in clean
                                           if r["verdict"] == "effect found"],
            "found_third_run_worse": sum(1 for r in found if not r["third_final"] < r["third_base"]),
            "confirmed_steps": len(confirmed),
            "worse_confirmed": sum(1 for s in confirmed if not s["after"] < s["before"]),
            "found_without_drop": sum(1 for r in found + structural if not r["final"] < r["base"]),
            "never_worse": sum(1 for r in records if r["final"] > r["base"] * (1 + 1e-12)) == 0,
            "gap_rule": (f"gap closed: (start - final) / (start - noise floor) of the held-out error, the start being "
                         f"hdrg fit's model and the floor the held-out residual's white noise (diagnose.noise_floor); "
                         f">= {GAP_HALF:g} counts"),
            "gap_closed_half_identifiable": _frac(sum((r.get("gap_closed") or 0.0) >= GAP_HALF for r in ident), len(ident)),
            "loop_worse_than_fit": [r["i"] for r in records if r.get("loop_vs_fit") is not None
                                    and r["loop_vs_fit"] > LOOP_TOLERANCE],
            "final_is_fit": sum(1 for r in records if r.get("final_is") == "hdrg fit's model"),
            "valid_share": {"min": min((r["valid_share"] for r in records if r.get("valid_share") is not None), default=None),
                            "min_fit": min((r["valid_share_fit"] for r in records if r.get("valid_share_fit") is not None),
                                           default=None),
                            "runs_below_fit": sum(1 for r in records if r.get("valid_share") is not None
                                                  and r["valid_share"] < r["valid_share_fit"] - 1e-9)}}


def run_benchmark(n_runs: int, seed: int = 0, duration_s=None, n_surrogates=None, progress=None,
                  shard=(0, 1), json_path=None, second_train=None, workers: int = 1, scheduler=None) -> dict:
    """The benchmark (module doc); ``shard`` (k, m): only the runs with i % m == k; with
    ``json_path`` the result so far is written after every run (the records finished so far, in
    run order); ``second_train``: see :func:`run_one`.  ``workers``: local processes, or
    ``scheduler``: a Dask distributed scheduler address (host_tools.lot.parallel); the records
    are the serial run's, in run order, whatever the engine."""
    from host_tools.lot.parallel import run_jobs

    specs = [sp for sp in plan(n_runs, seed) if sp["i"] % shard[1] == shard[0]]
    one = functools.partial(run_one, duration_s=duration_s, n_surrogates=n_surrogates, second_train=second_train)
    done = {}
    run = run_jobs(one, specs, workers, scheduler)
    try:
        for spec, rec in run:
            done[spec["i"]] = rec
            if json_path:
                so_far = [done[i] for i in sorted(done)]
                with atomic_open(json_path, "w", encoding="utf-8") as fh:
                    json.dump({"summary": summarize(so_far), "records": so_far}, fh, indent=1)
            if progress:
                progress(f"[{len(done)}/{len(specs)}] device {rec['device']} {rec['effect'] or 'clean'} "
                         f"{'MR' if rec['reversal'] else 'FTR'} x{rec['strength']:.2f}: {rec['verdict']} "
                         f"{[(s['effect'], s['confirmed']) for s in rec['steps']]} {rec['base']:.3g} -> {rec['final']:.3g}"
                         f" (ratio {rec['effect_ratio'] if rec['effect_ratio'] is None else round(rec['effect_ratio'], 2)},"
                         f" {rec['seconds']} s)")
    finally:
        run.close()
    records = [done[sp["i"]] for sp in specs]
    return {"config": {"runs": n_runs, "seed": seed, "duration_s": duration_s, "n_surrogates": n_surrogates,
                       "train": "4 degC/min, power-on 0, noise 0" + (
                           f"; and {second_train:g} degC/min, power-on 0, noise {SECOND_TRAIN_NOISE}" if second_train else ""),
                       "holdout": "2 degC/min, power-on 1, noise 1",
                       "strength": [STRENGTH_LO, STRENGTH_HI], "matters_ratio": MATTERS_RATIO},
            "summary": summarize(records), "records": records}


# ---------------------------------------------------------------------------------------------
# calibration on seeds disjoint from the benchmark's
# ---------------------------------------------------------------------------------------------

CALIBRATION_SEED = 1                  # plan(seed=1): devices 100000 + i, disjoint from the bench's seed 0
CALIBRATION_SHORT_S = 5000.0          # every other clean run cut to this many seconds
CALIBRATION_HDRG_SEEDS = (200, 210)   # hdrg-sim seed triples b+1, b+3 (train), b+2 (held out)


def _run_cut(item) -> dict:
    """:func:`run_one` of ``item`` = (spec, duration_s)."""
    return run_one(item[0], duration_s=item[1])


def calibration_study(n_clean: int = 16, n_effect: int = 18, seed: int = CALIBRATION_SEED, progress=None,
                      workers: int = 1, scheduler=None) -> dict:
    """Calibration runs on seeds disjoint from the benchmark's (``seed`` != the bench's 0):
    the first ``n_clean`` clean runs of ``plan(3 n, seed)`` (every other one cut to
    CALIBRATION_SHORT_S; run type as in the plan: i odd = mode reversal), clean hdrg-sim runs
    (FTR/MR, 1 and 2 cycles, CALIBRATION_HDRG_SEEDS) and the first ``n_effect`` effect runs.
    ``workers``/``scheduler``: the engine (:func:`run_benchmark`).
    Returns {"clean": summary + records, "hdrg_clean": rows, "effect": summary + records}."""
    from host_tools.lot.parallel import map_ordered

    say = progress or (lambda msg: None)
    cut = [(sp, None if k % 2 == 0 else CALIBRATION_SHORT_S)
           for k, sp in enumerate([s for s in plan(3 * n_clean, seed) if s["effect"] is None][:n_clean])]
    clean = map_ordered(_run_cut, cut, workers, scheduler,
                        on_result=lambda k, rec, n: say(f"clean {rec['i']}: {rec['verdict']}"))
    hdrg = hdrg_clean_study(CALIBRATION_HDRG_SEEDS, progress=say, workers=workers, scheduler=scheduler)
    eff = map_ordered(_run_cut, [(sp, None) for sp in plan(3 * n_effect, seed) if sp["effect"] is not None][:n_effect],
                      workers, scheduler, on_result=lambda k, rec, n: say(f"effect {rec['i']} {rec['effect']}: "
                                                                          f"{rec['verdict']}"))
    return {"seed": seed, "clean": {"summary": summarize(clean), "records": clean}, "hdrg_clean": hdrg,
            "effect": {"summary": summarize(eff), "records": eff}}


# ---------------------------------------------------------------------------------------------
# hdrg's own simulator, clean runs (`hdrg bench loop --hdrg-clean`)
# ---------------------------------------------------------------------------------------------

HDRG_OFF = ("turn_on", "electronics", "damping_asym")      # the clean world of tests/test_diagnose.py


def hdrg_clean_row(item) -> dict:
    """One row of :func:`hdrg_clean_study`: ``item`` = (scenario, cycles, base)."""
    from host_tools.simulation import sim
    scen, n_cyc, base = item
    prof = sim.cycle_profile(2.0, hold_s=1200, n_cycles=n_cyc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logs = [sim.simulate(scen, seed=base + k, off=list(HDRG_OFF), profile=prof) for k in (1, 3, 2)]
        rep, _ = diagnose(logs[:2], logs[2:], plots=False)
    return {"scenario": scen, "cycles": n_cyc, "seed": base, "verdict": rep["verdict"],
            "steps": [(i["effect"], i["confirmed"]) for i in rep["iterations"]]}


def hdrg_clean_study(bases=range(100, 150, 10), progress=None, workers: int = 1, scheduler=None) -> list:
    """False discovery on clean runs of host_tools.simulation.sim: FTR and MR (paper-ftr-cycle-4dpm,
    paper-mr-cycle-4dpm), short (one 2-degC/min cycle, 4800 s) and long (two, 9600 s), one seed
    triple per base b (seeds b+1, b+3 train, b+2 held out; default b = 100, 110, .., 140).
    ``workers``/``scheduler``: the engine (:func:`run_benchmark`); the rows in this order."""
    from host_tools.lot.parallel import map_ordered

    items = [(scen, n_cyc, base) for scen in ("paper-ftr-cycle-4dpm", "paper-mr-cycle-4dpm") for n_cyc in (1, 2)
             for base in bases]
    return map_ordered(hdrg_clean_row, items, workers, scheduler,
                       on_result=None if progress is None else lambda k, row, n: progress(str(row)))


# ---------------------------------------------------------------------------------------------
# measured data (`hdrg bench loop --measured DIR`)
# ---------------------------------------------------------------------------------------------

MEASURED = {"tofupilot-x": "tofupilot-imu-thermal/tofupilot-imu-x.csv",
            "tofupilot-y": "tofupilot-imu-thermal/tofupilot-imu-y.csv",
            "psim-x": "psim-tvac-lsm6dsm/psim-tvac-x.csv", "psim-y": "psim-tvac-lsm6dsm/psim-tvac-y.csv"}
# the measured logs the project carries (tests/data, each with its README and LICENSE); the
# shared folder beside a checkout otherwise
MEASURED_ROOT = next((str(p) for p in (Path(__file__).resolve().parents[2] / "tests" / "data",
                                       Path(__file__).resolve().parents[3] / "shared" / "data" / "measured")
                      if (p / "tofupilot-imu-thermal").is_dir()), "tests/data")
SPLIT_BLOCKS = 8


def splits(log) -> dict:
    """The held-out splits of one measured log: ``cool->heat`` / ``heat->cool`` (train on the
    samples where the smoothed temperature falls, hold out those where it rises, and the
    reverse; only when both legs span >= 20 degC) and ``blocks`` (SPLIT_BLOCKS contiguous time
    blocks, or the bursts of a bursty log: even ones train, odd ones held out)."""
    t = np.asarray(log.t_s)
    temp = np.asarray(log["temp_c"], np.float64)
    out = {}
    if len(log.segments) == 1:
        k = max(1, int(round(60.0 * log.sample_rate_hz)))          # 60-s moving mean
        sm = np.convolve(temp, np.ones(k) / k, mode="same")
        rising = np.gradient(sm) > 0
        legs = {"cool": ~rising, "heat": rising}
        if all(np.ptp(temp[m]) >= 20.0 for m in legs.values()):
            out["cool->heat"] = (legs["cool"], legs["heat"])
            out["heat->cool"] = (legs["heat"], legs["cool"])
        block = (np.arange(len(t)) * SPLIT_BLOCKS) // len(t)
    else:
        block = np.searchsorted(log.segments, np.arange(len(t)), side="right") - 1
    out["blocks"] = (block % 2 == 0, block % 2 == 1)
    return out


def measured_study(out_dir: str, root: str = MEASURED_ROOT, progress=None) -> dict:
    """Run the loop on every measured log and split (module doc of diagnose; default options):
    per case the verdict, the steps and the held-out error (std of 1-s and 100-s averages, deg/h)
    of the base and final models; figures (held-out Allan deviation and residual vs time, base
    and final) in ``out_dir``."""
    import os

    from host_tools.golden import runlog
    os.makedirs(out_dir, exist_ok=True)
    results = {}
    for name, rel in MEASURED.items():
        path = os.path.join(root, rel)
        if not os.path.exists(path):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            log = runlog.read(path)
        for split, (tr, ho) in splits(log).items():
            key = f"{name} {split}"
            if progress:
                progress(f"measured: {key}")
            train, hold = log.select(tr), log.select(ho)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rep, model = diagnose([train], [hold], plots=False)
            base_model = _measured_base(train)
            fig = _measured_figure(key, hold, base_model, model, out_dir)
            results[key] = {"verdict": rep["verdict"], "detail": rep["verdict_detail"],
                            "base": rep["baseline"]["holdout"], "final": rep["final"],
                            "noise_floor": rep["noise_floor"],
                            "steps": [{"effect": it["effect"], "params": it["params"], "confirmed": it["confirmed"],
                                       "cv_gain": it["cv_gain"], "threshold": it["threshold"],
                                       "before": it["before"], "after": it["after"]} for it in rep["iterations"]],
                            "stopped": (rep["stopped"] or {}).get("reason"),
                            "ranking": (rep["stopped"] or {}).get("ranking", [])[:5],
                            "noise_model": rep["characterization"]["noise_models"][0],
                            "figure": fig}
    return results


def _measured_base(train):
    return _base_model(train)


def _measured_figure(key, hold, base_model, final_model, out_dir) -> str:
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from host_tools.fitting import metrics
    from host_tools.golden.compensate import compensate
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for label, m, style in (("base model (hdrg fit default)", base_model, "--"), ("after the loop", final_model, "-")):
        out = compensate(hold, m)
        v = np.asarray(out["valid"]) == 1
        a = metrics.allan(out.rate_dph, hold.t_s, v)
        if a["tau_s"]:
            a1.loglog(a["tau_s"], a["adev_dph"], style, label=label)
        tt, yy = hold.t_s[v] / 60.0, np.asarray(out.rate_dph)[v]
        brk = np.flatnonzero(np.diff(tt) > 5.0 / 60.0) + 1         # no line across gaps (> 5 s)
        a2.plot(np.insert(tt, brk, np.nan), np.insert(yy, brk, np.nan), style, lw=0.6, label=label)
    a1.axvline(1.0, color="0.6", lw=0.8)
    a1.axvline(100.0, color="0.6", lw=0.8)
    a1.set_xlabel("averaging time tau [s]")
    a1.set_ylabel("Allan deviation of the held-out output [deg/h]")
    a1.grid(True, which="both", alpha=0.3)
    a1.legend(fontsize=8)
    a2.set_xlabel("time since start [min]")
    a2.set_ylabel("compensated held-out output [deg/h]")
    a2.grid(True, alpha=0.3)
    a2.legend(fontsize=8)
    fig.suptitle(f"{key}: held-out samples", fontsize=10)
    fig.tight_layout()
    name = key.replace(" ", "_").replace(">", "").replace("-", "_") + ".png"
    with atomic_path(os.path.join(out_dir, name)) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)
    return name
