"""`hdrg demo`: the whole job on embedded defaults, end to end, in about half a minute to 1.5 min.

simulate (two mode-reversal chamber runs at 4 degC/min, different seeds) -> fit on one with
exactly `hdrg fit`'s defaults (host_tools.fitting.fit_pipeline.fit_default, no options) ->
compensate the other (held out) -> report (tables and PNG figures: mode reversal alone, the
flight-stack baseline and the model) -> close the loop: `diagnose` on runs that
carry an effect nobody declared (a 600-s periodic bias, absent from the run logs' metadata and
from the model), which traces the residual to it, adds it through k7 and prints the error before
and after on a held-out run.  Everything is written to --out (default ./hdrg-demo).
"""
from __future__ import annotations

import os
import warnings

from host_tools.golden import runlog
from host_tools.simulation import sim
from host_tools.golden.compensate import compensate

DEFAULTS_NOTE = ("the model was fitted with hdrg fit's defaults (host_tools.fitting.fit_pipeline.fit_default, "
                 "no options): the same model as `hdrg fit` on the training run")


def fit_summary(model) -> str:
    """One line: what hdrg fit's defaults chose (rate estimator, lag block, guard) for ``model``."""
    fit = model.fit or {}
    parts = [f"rate estimator {model.config.rate.estimator}"]
    if model.config.reversal is not None:
        parts.append(f"combiner {model.config.reversal.combiner}, order {model.config.reversal.order}")
    lag = fit.get("lag_block") or {}
    if lag.get("chosen"):
        parts.append(f"lag block {lag['chosen']}")
    guard = fit.get("guard") or {}
    if guard.get("chosen"):
        parts.append(f"guard: {guard['chosen']}")
    return ", ".join(parts)


def run_demo(out_dir: str = "hdrg-demo", duration_s: float = 6 * 3600.0) -> None:
    """The demo: two simulated mode-reversal runs of ``duration_s`` seconds each, a fit, the
    compensation of the held-out run, a report and the closed-loop diagnosis, all written below
    ``out_dir`` (created); progress and tables are printed to stdout.  Returns nothing."""
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.fitting.report import markdown_table, report, summary_lines

    os.makedirs(out_dir, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        print("1. simulate: two mode-reversal runs, -20..20 degC cycles at 4 degC/min (seeds 1 and 2)")
        paths = []
        for seed in (1, 2):
            log = sim.simulate("paper-mr-cycle-4dpm", seed=seed, duration_s=duration_s)
            path = os.path.join(out_dir, f"run-seed{seed}.csv")
            runlog.write(log, path)
            paths.append(path)
            print(f"   {path}: {len(log)} samples")
        train, test = (runlog.read(p) for p in paths)
        print(f"2. fit on the seed-1 run with hdrg fit's defaults (the same model as `hdrg fit {paths[0]}`; "
              f"fit_default, no options)")
        model, res = fit_default([train])
        model_path = os.path.join(out_dir, "model.json")
        model.to_json(model_path)
        print(f"   {model_path}: {len(res.terms)} terms {['k%d' % k for k in res.terms]}, rms {res.rms:.4g} deg/h, "
              f"cond {res.cond:.3g}; {fit_summary(model)}")
        print("3. compensate the held-out seed-2 run")
        out = compensate(test, model)
        out_path = os.path.join(out_dir, "run-seed2-compensated.csv")
        runlog.write(out, out_path)
        from host_tools.golden.flags import problems, summary
        print(f"   {out_path}: {summary(out)}")
        for p in problems(out):
            print(f"   warning: {p}")
        print("4. report on the held-out run: mode reversal alone (no model) / flight-stack baseline / the model")
        doc = report([test], model, os.path.join(out_dir, "report"), train_logs=[train], model_name="model.json",
                     notes=[DEFAULTS_NOTE])
        print(markdown_table(doc["rows"]))
        for line in summary_lines(doc):
            print(f"   {line}")
        print(f"   figures: {', '.join(doc.get('figures', []))} in {os.path.join(out_dir, 'report')}")
        _close_the_loop(out_dir, duration_s)


def _close_the_loop(out_dir: str, duration_s: float) -> None:
    from host_tools.fitting.diagnose import diagnose

    print("5. diagnose: runs with an UNDECLARED effect (periodic 0.5 deg/h, 600 s; not in the metadata, "
          "not in the model); train on seeds 1 and 3, hold out seed 2")
    undeclared = {"periodic": {"amp_dph": 0.5, "period_s": 600.0}}
    train = [sim.simulate("paper-mr-cycle-4dpm", seed=s, duration_s=duration_s, undeclared=undeclared)
             for s in (1, 3)]
    hold = [sim.simulate("paper-mr-cycle-4dpm", seed=2, duration_s=duration_s, undeclared=undeclared)]
    out_dir = os.path.join(out_dir, "diagnose")
    rep, _ = diagnose(train, hold, out_dir=out_dir, progress=lambda msg: print(f"   ... {msg}", flush=True))
    keys = ("std_dph", "pp_dph", "std100_dph", "pp100_dph")
    print("| iteration | step (structure / effect) | parameters | held-out before: std 1 s, p-p 1 s, std 100 s, p-p 100 s "
          "| after | held-out |\n|---|---|---|---|---|---|")
    for k, it in enumerate(rep["iterations"], 1):
        params = ", ".join(f"{key}={val:.4g}" if isinstance(val, float) else f"{key}={val}"
                           for key, val in it["params"].items())
        before = " / ".join(f"{it['before'][key]:.3f}" for key in keys)
        after = " / ".join(f"{it['after'][key]:.3f}" for key in keys)
        print(f"| {k} | {it['effect']} ({it.get('kind', 'effect')}) | {params} | {before} | {after} | {it['status']} |")
    print(f"   {rep['verdict_detail']}")
    if (rep.get("generalization") or {}).get("warning"):
        print(f"   warning: {rep['generalization']['warning']}")
    print(f"   verdict: {rep['verdict']}; final held-out: "
          + ", ".join(f"{key} {rep['final'][key]:.3f}" for key in keys) + " deg/h")
    print(f"   report, figures and the extended model: {out_dir}")
