"""`hdrg bench accuracy`: held-out accuracy of every pipeline option on random FOREIGN devices
(host_tools.simulation.sim_foreign), relative to each run's own noise floor.

Per device (seed ``S * 100000 + i``, i = 0 .. N-1) and per run type (FTR, mode reversal):

* **train** on one run: chamber rate ``--train-rate`` (4 degC/min), power-on 0, noise seed 0;
* **hold out** another: ``--holdout-rate`` (2 degC/min), power-on 1 (another damping change),
  noise seed 1;
* **floor**: the held-out run simulated again with ``thermal=False`` (same noise, no bias);
  floor = std at 1 s of its rate (FTR), or of ``c = s * rate`` over its mode-1/2 samples (MR: the
  floor of ONE mode's output).

For every option: ModelConfig from the training run (host_tools.golden.compensate.fit_config_from_logs
with the option's rate estimator and reversal settings), 17 terms fitted (host_tools.fitting.fit.fit_logs,
terms 'all', or the cross-validated selection 'auto' in the '+auto' options), the held-out run compensated (float golden model); **metric = std at 1 s of the
compensated output over its valid samples / floor** (dimensionless; 1 = down to the noise floor;
below 1 is possible for MR, whose combined output averages two modes), scored from power-on:
every sample from power-on + 180 s (MR) / + 10 s (FTR) is servable except exchanges and 10 s
after each (:func:`servable`); an option valid on less than 99 % of them fails (what is not
served is not scored, so a start-up blanked by a warm-up must not win); the summary gives each
option's lowest valid share.  ``*/raw`` rows: no
model (FTR raw output; MR the combiner alone).

Options: ``ftr/EST``, ``mr-pair/EST``, ``mr-trend/EST`` (combine first: the combiner, then one
bias), and, when host_tools.golden.reversal.ReversalConfig has an ``order`` field,
``rf-none/EST``, ``rf-pair/EST``, ``rf-trend/EST`` (regress first: per-mode banks, residuals
combined); ``+auto`` variants for EST in AUTO_ESTIMATORS.  EST: ``diff``, ``diffn4``, ``diffn16``, ``lsq8``, ``lsq32``, ``iir4``, ``iir7``,
``iir9`` (host_tools.golden.rate).  A fit or compensation that fails is counted per option, never
dropped silently.

Summary per option: median and 90th percentile of the metric over devices, on all devices and on
the **damping-change subset**: devices whose held-out power-on damping change, sized as
``|d_scale(1) - d_scale(0)| * std(B_D over the held-out run) `` [deg/h], exceeds
``DAMPING_CHANGE_DPH`` (the power-on offset change moves the mean only, not the std).
"""
from __future__ import annotations

import dataclasses
import fnmatch
import functools
import math
import time
from dataclasses import dataclass

import numpy as np

from host_tools.golden.compensate import compensate, fit_config_from_logs
from host_tools.fitting.fit import fit_logs
from host_tools.fitting.fit_rate import fit_auto_rate
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.golden.reversal import ReversalConfig, combine
from host_tools.simulation.sim_foreign import ForeignDevice, damping_bias, foreign_device, simulate_foreign

ESTIMATORS = {"diff": ("diff", 8, 4), "diffn4": ("diffn", 4, 4), "diffn16": ("diffn", 16, 4),
              "lsq8": ("lsq", 8, 4), "lsq32": ("lsq", 32, 4), "iir4": ("iir", 8, 4), "iir7": ("iir", 8, 7),
              "iir9": ("iir", 8, 9)}
AUTO_ESTIMATORS = ("diff", "iir9")   # 'auto' costs ~0.5 s per fit (forward selection): two estimators only
# est 'auto': the rate estimator chosen by host_tools.fitting.fit_rate.fit_auto_rate (fits every RATE_CANDIDATE)
# variants of the defaults: settle_s after each exchange, stricter term selection
VARIANTS = ((("rf-pair", "diff", "auto"), ({"settle": 3.0}, {"settle": 5.0}, {"settle": 10.0}, {"sig": 2.0})),
            (("rf-pair", "auto", "auto"), ({}, {"settle": 5.0}, {"sig": 2.0})),
            (("ftr", "diff", "auto"), ({"sig": 2.0},)),
            (("ftr", "auto", "auto"), ({}, {"sig": 2.0})))
DAMPING_CHANGE_DPH = 0.5
SEED_STRIDE = 100000


@dataclass(frozen=True)
class Option:
    """One pipeline option: ``kind`` ftr | mr-pair | mr-trend | rf-none | rf-pair | rf-trend (or
    ``ftr/default``, ``mr/default``: host_tools.fitting.fit_pipeline.fit_default, i.e. `hdrg fit RUN` without options),
    ``est`` a key of ESTIMATORS or 'raw' (no model), ``terms`` 'all' (17 terms) or 'auto'
    (cross-validated term selection of host_tools.fitting.fit; name suffix '+auto')."""

    kind: str
    est: str
    terms: str = "all"
    settle: float = 0.0   # settle_s [s] of the reversal config (name suffix '+sN')
    sig: float = 1.0      # significance of the 'auto' term selection (name suffix '+sigN'), pinned (not the default)

    @property
    def name(self) -> str:
        if self.est == "default":
            return f"{self.kind}/default"
        return (f"{self.kind}/{self.est}" + ("" if self.terms == "all" else f"+{self.terms}")
                + (f"+s{self.settle:g}" if self.settle else "") + (f"+sig{self.sig:g}" if self.sig != 1.0 else ""))

    @property
    def reversal(self) -> bool:
        return self.kind != "ftr"

    def reversal_config(self):
        if not self.reversal or self.kind == "mr":   # mr/default: the defaults of fit_config_from_logs
            return None
        order, combiner = self.kind.split("-")
        d = {"combiner": combiner, "settle_s": self.settle}
        if has_order():
            d["order"] = "regress_first" if order == "rf" else "combine_first"
        return ReversalConfig(**d)


def has_order() -> bool:
    """True when the pipeline has the regress_first order (ReversalConfig.order)."""
    return "order" in {f.name for f in dataclasses.fields(ReversalConfig)}


def all_options() -> list:
    kinds = ["ftr", "mr-pair", "mr-trend"] + (["rf-none", "rf-pair", "rf-trend"] if has_order() else [])
    out = [Option(k, "raw") for k in ("ftr", "mr-pair", "mr-trend")]
    out += [Option(k, e) for k in kinds for e in ESTIMATORS]
    out += [Option(k, e, "auto") for k in kinds for e in AUTO_ESTIMATORS]
    out += [Option("ftr", "default", "default"), Option("mr", "default", "default")]
    for (k, e, t), variants in VARIANTS:
        if k in kinds:
            out += [o for o in (Option(k, e, t, **v) for v in variants) if o not in out]
    return out


def select_options(patterns=None) -> list:
    """Options whose name matches any of the fnmatch ``patterns`` (None: all).  A pattern that
    matches nothing is an error naming the known options."""
    opts = all_options()
    if not patterns:
        return opts
    keep = []
    for pat in patterns:
        hit = [o for o in opts if fnmatch.fnmatchcase(o.name, pat)]
        if not hit:
            raise ValueError(f"--pipelines {pat!r} matches no option; known: {', '.join(o.name for o in opts)}")
        keep += [o for o in hit if o not in keep]
    return keep


def _std(x) -> float:
    return float(np.std(x)) if len(x) > 1 else float("nan")


def floor_of(floor_log) -> float:
    """Noise floor [deg/h] of a noise-only run: std at 1 s of rate (FTR) or of c = s * rate over
    the mode-1/2 samples (MR)."""
    m = floor_log.mode
    if floor_log.reversal:
        ok = (m == 1) | (m == 2)
        return _std((np.where(m == 2, -1.0, 1.0) * floor_log.rate_dph)[ok])
    return _std(floor_log.rate_dph)


SERVED_FROM_S = {"mr": 180.0, "ftr": 10.0}   # power-on + this: the output must exist (the paper's MR ~180 s)
SETTLE_AFTER_EXCHANGE_S = 10.0               # after an exchange, at most this long without output
MIN_VALID_SHARE = 0.99                       # of the servable samples, or the option fails


def servable(log) -> np.ndarray:
    """bool[n]: the samples a user expects an output for: from power-on (the log's first sample)
    + SERVED_FROM_S, except mode exchanges and the SETTLE_AFTER_EXCHANGE_S after each."""
    t = np.asarray(log.t_s, np.float64) - float(log.t_s[0])
    mode = np.asarray(log.mode)
    ok = t >= SERVED_FROM_S["mr" if log.reversal else "ftr"]
    if log.reversal:
        exch = mode == 3
        ends = np.flatnonzero(exch[:-1] & ~exch[1:]) + 1          # first sample after each exchange
        last_end = np.full(len(t), -np.inf)
        last_end[ends] = t[ends]
        last_end = np.maximum.accumulate(last_end)
        ok &= ~exch & (t - last_end >= SETTLE_AFTER_EXCHANGE_S)
    return ok


def heldout_valid(model, holdout) -> np.ndarray:
    """The compensated output [deg/h] of ``holdout`` under ``model`` at its valid servable samples
    (:func:`servable`): the benchmark's metric is its std at 1 s (over the run's floor,
    :func:`floor_of`)."""
    return heldout_output(model, holdout)[0]


def heldout_output(model, holdout) -> tuple:
    """(output at the valid servable samples [deg/h], valid share of the servable samples)."""
    out = compensate(holdout, model)
    serve = servable(holdout)
    valid = (out["valid"] > 0) & serve
    return out.rate_dph[valid], float(valid.sum() / max(serve.sum(), 1))


def heldout_ratio(model, holdout, floor) -> float:
    """np.std of :func:`heldout_valid` over ``floor``: the held-out ratio the study scripts
    (docs/studies) record (the benchmark's ratio, without its guard for fewer than two valid samples)."""
    return float(np.std(heldout_valid(model, holdout)) / floor)


def set_devices(seeds, reversals=(False, True)):
    """For the study scripts (docs/studies): per seed of ``seeds`` a pair (rec, cases), rec =
    {'seed', 'dc': :func:`damping_change_dph`}, cases = a lazy iterator over ``reversals`` of
    (key 'ftr' / 'mr', train, hold, floor) from :func:`device_runs` (consume it before the next seed)."""
    for seed in seeds:
        dev = foreign_device(seed)
        yield ({"seed": seed, "dc": damping_change_dph(dev)},
               (("mr" if rev else "ftr",) + device_runs(dev, rev) for rev in reversals))


def evaluate_option(opt: Option, train, holdout) -> tuple[float, str, float]:
    """(held-out std at 1 s over the valid servable samples [deg/h], error text or '', valid share
    of the servable samples).  A share below MIN_VALID_SHARE is an error: what is not served is
    not scored, so an option that blanks the start-up must not win by it."""
    serve = servable(holdout)
    try:
        rev = opt.reversal_config()
        if opt.est == "raw":
            if rev is None:
                return _std(holdout.rate_dph[serve]), "", 1.0
            c = combine(holdout, rev.combiner)
            v = np.asarray(c.valid, bool) & serve
            return _std(c.out_dph[v]), "", float(v.sum() / max(serve.sum(), 1))
        if opt.est == "default":   # exactly `hdrg fit RUN` without options
            model, _ = fit_default([train])
        elif opt.est == "auto":
            model, _ = fit_auto_rate([train], opt.terms, reversal=rev, significance=opt.sig)
        else:
            est, n, shift = ESTIMATORS[opt.est]
            cfg = fit_config_from_logs([train], rate_estimator=est, n=n, shift=shift, reversal=rev)
            model, _ = fit_logs([train], cfg, terms=opt.terms, significance=opt.sig)
        x, share = heldout_output(model, holdout)
        if len(x) < 2:
            return float("nan"), "no valid held-out sample", share
        if share < MIN_VALID_SHARE:
            return _std(x), (f"valid on {100 * share:.1f} % of the servable held-out samples (< "
                             f"{100 * MIN_VALID_SHARE:g} %: from power-on + {SERVED_FROM_S['mr' if holdout.reversal else 'ftr']:g} s, "
                             f"exchanges and {SETTLE_AFTER_EXCHANGE_S:g} s after them excepted)"), share
        return _std(x), "", share
    except (ValueError, np.linalg.LinAlgError) as exc:
        return float("nan"), f"{type(exc).__name__}: {exc}", 0.0


def damping_change_dph(dev, holdout_rate=2.0, duration_s=None) -> float:
    """Size of device ``dev``'s non-repeatable damping change between power-ons 0 and 1 [deg/h]:
    |scale change| x std of its damping bias on the held-out run."""
    sc0, _ = dev.damping_change(0)
    sc1, _ = dev.damping_change(1)
    return float(abs(sc1 - sc0) * np.std(damping_bias(dev, holdout_rate, duration_s)))


def device_runs(dev, reversal: bool, train_rate=4.0, holdout_rate=2.0, duration_s=None):
    """The benchmark's runs of device ``dev``: (training run at ``train_rate`` [degC/min], power-on 0;
    held-out run at ``holdout_rate``, power-on 1; the held-out run's white-noise floor [deg/h],
    from the same run without thermal terms)."""
    train = simulate_foreign(dev, train_rate, reversal, 0, 0, duration_s)
    hold = simulate_foreign(dev, holdout_rate, reversal, 1, 1, duration_s)
    floor = floor_of(simulate_foreign(dev, holdout_rate, reversal, 1, 1, duration_s, thermal=False))
    return train, hold, floor


def evaluate_device(seed, options, train_rate=4.0, holdout_rate=2.0, duration_s=None) -> dict:
    """Every option on device ``seed`` (a seed or a ForeignDevice): {'seed', 'device', 'damping_change_dph', 'floor': {ftr, mr},
    'std': {option: deg/h}, 'ratio': {option: std/floor}, 'errors': {option: text}}."""
    dev = seed if isinstance(seed, ForeignDevice) else foreign_device(seed)
    seed = dev.seed
    rec = {"seed": seed, "device": dev.describe(), "floor": {}, "std": {}, "ratio": {}, "errors": {}, "valid_share": {}}
    rec["damping_change_dph"] = damping_change_dph(dev, holdout_rate, duration_s)
    for reversal in (False, True):
        opts = [o for o in options if o.reversal == reversal]
        if not opts:
            continue
        train, hold, floor = device_runs(dev, reversal, train_rate, holdout_rate, duration_s)
        rec["floor"]["mr" if reversal else "ftr"] = floor
        for opt in opts:
            std, err, share = evaluate_option(opt, train, hold)
            rec["std"][opt.name] = std
            rec["ratio"][opt.name] = std / floor if not err else float("nan")   # an error fails the option
            rec["valid_share"][opt.name] = share
            if err:
                rec["errors"][opt.name] = err
    return rec


def summarize(records, options) -> dict:
    """Per option: n, failed, median, p90 (all devices) and the same on the damping-change subset."""
    big = [r for r in records if r["damping_change_dph"] > DAMPING_CHANGE_DPH]
    out = {}
    for opt in options:
        row = {}
        for label, recs in (("all", records), ("damping_change", big)):
            vals = np.array([r["ratio"].get(opt.name, np.nan) for r in recs], float)
            ok = vals[np.isfinite(vals)]
            row[label] = {"n": int(ok.size), "failed": int(vals.size - ok.size),
                          "median": float(np.median(ok)) if ok.size else float("nan"),
                          "p90": float(np.percentile(ok, 90)) if ok.size else float("nan"),
                          "min_valid_share": min((r.get("valid_share", {}).get(opt.name, float("nan")) for r in recs),
                                                 default=float("nan"))}
        out[opt.name] = row
    return out


def run_benchmark(n_devices: int = 50, seed: int = 0, patterns=None, train_rate: float = 4.0,
                  holdout_rate: float = 2.0, duration_s=None, progress=None, start: int = 0, workers: int = 1,
                  scheduler=None) -> dict:
    """The benchmark (module doc) on devices ``start`` .. ``start + n_devices - 1`` of set ``seed``.
    ``workers``: local processes, or ``scheduler``: a Dask distributed scheduler address
    (host_tools.lot.parallel); the records are the serial run's, in device order, whatever the
    engine.  Returns {'config', 'records', 'summary'} (JSON-able)."""
    if not (isinstance(n_devices, int) and n_devices >= 1):
        raise ValueError(f"--devices must be a positive integer, not {n_devices!r}")
    if not (isinstance(seed, int) and seed >= 0):
        raise ValueError(f"--seed must be a non-negative integer, not {seed!r}")
    for what, r in (("--train-rate", train_rate), ("--holdout-rate", holdout_rate)):
        if not (math.isfinite(r) and r > 0):
            raise ValueError(f"{what} must be a positive number of degC/min, not {r!r}")
    if not (isinstance(start, int) and start >= 0):
        raise ValueError(f"--start must be a non-negative integer, not {start!r}")
    from host_tools.lot.parallel import map_ordered

    options = select_options(patterns)
    t0 = time.time()
    one = functools.partial(evaluate_device, options=options, train_rate=train_rate, holdout_rate=holdout_rate,
                            duration_s=duration_s)
    seeds = [seed * SEED_STRIDE + start + i for i in range(n_devices)]
    say = None if not progress else (lambda i, rec, done: progress(f"device {done}/{n_devices} ({time.time() - t0:.0f} s)"))
    records = map_ordered(one, seeds, workers, scheduler, on_result=say)
    config = {"devices": n_devices, "start": start, "seed": seed, "options": [o.name for o in options], "train": {"rate_c_per_min": train_rate, "power_on": 0, "noise_seed": 0},
              "holdout": {"rate_c_per_min": holdout_rate, "power_on": 1, "noise_seed": 1},
              "duration_s": duration_s, "damping_change_dph": DAMPING_CHANGE_DPH, "regress_first": has_order(),
              "elapsed_s": round(time.time() - t0, 1)}
    return {"config": config, "records": records, "summary": summarize(records, options)}


def merge(results) -> dict:
    """One result from several runs of the same options and protocol on disjoint devices (e.g.
    ``--start 0 --devices 25`` and ``--start 25 --devices 25``): records in device order (the
    serial run's), summary recomputed.  Runs that differ in options or protocol, or share a device, are an error."""
    results = list(results)
    if not results:
        raise ValueError("nothing to merge")
    key = ("seed", "train", "holdout", "duration_s", "damping_change_dph", "options")
    for r in results:   # runs written before config had "options": the summary's option names
        r["config"].setdefault("options", list(r["summary"]))
        r["config"].setdefault("start", 0)
    c0 = results[0]["config"]
    for r in results[1:]:
        diff = [k for k in key if r["config"].get(k) != c0.get(k)]
        if diff:
            raise ValueError(f"cannot merge benchmark runs that differ in {', '.join(diff)}")
    records = sorted((rec for r in results for rec in r["records"]), key=lambda rec: rec["seed"])   # the serial order
    seeds = [rec["seed"] for rec in records]
    if len(set(seeds)) != len(seeds):
        raise ValueError("cannot merge benchmark runs that share a device seed")
    options = select_options(c0["options"])
    config = {**c0, "devices": len(records), "start": min(r["config"].get("start", 0) for r in results),
              "elapsed_s": round(sum(r["config"]["elapsed_s"] for r in results), 1)}
    return {"config": config, "records": records, "summary": summarize(records, options)}


def format_table(result: dict) -> str:
    """Markdown table: option, median / p90 of held-out std / floor, all devices and the
    damping-change subset, failures."""
    s = result["summary"]
    nbig = sum(r["damping_change_dph"] > DAMPING_CHANGE_DPH for r in result["records"])
    lines = [f"| option | median | p90 | damping-change subset ({nbig}) median | p90 | failed | min valid share |",
             "|---|---|---|---|---|---|---|"]
    for name, row in s.items():
        a, b = row["all"], row["damping_change"]
        share = a.get("min_valid_share", float("nan"))
        lines.append(f"| {name} | {a['median']:.2f} | {a['p90']:.2f} | {b['median']:.2f} | {b['p90']:.2f} | "
                     f"{a['failed']} | {100 * share:.1f} % |")
    return "\n".join(lines)


def _same_node(d):
    d.damping_node = d.common_node = d.self_heating["node"] = d.resonator_node


ABLATIONS = {   # name -> in-place change of a device copy: which physics costs what
    "as drawn": lambda d: None,
    "no power-on change": lambda d: d.damping.update(change_sigma=0.0, change_offset_max_dph=0.0),
    "bias on the resonator node": _same_node,
    "no tanh (cubic-representable common mode)": lambda d: d.common.update(e3=0.0),
    "no settling tail": lambda d: d.exchange.update(tail_amp_dph=0.0),
    "no self-heating": lambda d: d.self_heating.update(rise_c=0.0),
}


def ablation(n_devices: int, seed: int, patterns, duration_s=None) -> str:
    """Median / p90 of every selected option with one piece of the foreign physics removed at a
    time (ABLATIONS), same devices: a markdown table."""
    import copy
    options = select_options(patterns)
    lines = ["| physics | " + " | ".join(o.name for o in options) + " |", "|---" * (len(options) + 1) + "|"]
    for label, change in ABLATIONS.items():
        recs = []
        for i in range(n_devices):
            dev = copy.deepcopy(foreign_device(seed * SEED_STRIDE + i))
            change(dev)
            recs.append(evaluate_device(dev, options, duration_s=duration_s))
        summ = summarize(recs, options)
        lines.append(f"| {label} | " + " | ".join(f"{summ[o.name]['all']['median']:.2f} / {summ[o.name]['all']['p90']:.2f}"
                                              for o in options) + " |")
    return "\n".join(lines)


def format_pivot(result: dict, subset: str = "all") -> str:
    """Markdown table: one row per rate estimator (and '+auto'), one column per kind, cells
    'median / p90' of held-out std / floor (``subset`` 'all' or 'damping_change')."""
    s = result["summary"]
    opts = [name.split("/") for name in s]
    kinds = list(dict.fromkeys(k for k, _ in opts))
    ests = list(dict.fromkeys(e for _, e in opts))
    lines = ["| estimator | " + " | ".join(kinds) + " |", "|---" * (len(kinds) + 1) + "|"]
    for e in ests:
        cells = []
        for k in kinds:
            row = s.get(f"{k}/{e}")
            cells.append("" if row is None else f"{row[subset]['median']:.2f} / {row[subset]['p90']:.2f}")
        lines.append(f"| {e} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def cubic_residual(log) -> float:
    """Std [deg/h] of the raw rate minus its own least-squares cubic in ``temp_c`` (self-fit): how
    much of an FTR run's bias is not a function of the temperature sensor's reading."""
    t = log["temp_c"]
    x = (t - t.mean()) / t.std()
    X = np.column_stack([x ** k for k in range(4)])
    coef, *_ = np.linalg.lstsq(X, log.rate_dph, rcond=None)
    return float(np.std(log.rate_dph - X @ coef))


def plausibility(n_devices: int, seed: int, measured=(), rate_c_per_min: float = 3.0) -> str:
    """The family against measured FTR runs: cubic-in-temp_c residual / white floor (foreign: the
    noise-only run's 1-s std; measured: std of consecutive differences / sqrt(2), per sample)."""
    from host_tools.golden.runlog import read
    r = []
    for i in range(n_devices):
        dev = foreign_device(seed * SEED_STRIDE + i)
        floor = floor_of(simulate_foreign(dev, rate_c_per_min, False, 0, 0, thermal=False))
        r.append(cubic_residual(simulate_foreign(dev, rate_c_per_min, False, 0, 0)) / floor)
    lines = [f"foreign ({n_devices} devices, FTR {rate_c_per_min:g} degC/min): cubic-in-temp_c residual / floor "
             f"median {np.median(r):.1f}, 10..90 % {np.percentile(r, 10):.1f}..{np.percentile(r, 90):.1f}"]
    for path in measured:
        log = read(path)
        white = float(np.std(np.diff(log.rate_dph)) / math.sqrt(2.0))
        res = cubic_residual(log)
        lines.append(f"{path}: cubic residual {res:.2f} deg/h, white {white:.2f} deg/h per sample "
                     f"({log.sample_rate_hz:.3g} Hz), ratio {res / white:.1f}")
    return "\n".join(lines)


def effect_sizes(n_devices: int, seed: int, rate_c_per_min: float = 2.0) -> dict:
    """Per effect kind: std of its term at strength 1 (the run with the effect minus the run
    without, same noise, raw rate over the mode-1/2 samples of an MR run) / the run's floor, over
    ``n_devices`` devices: {kind: [ratio per device]}.  Sizes the strengths of a loop benchmark."""
    from host_tools.simulation.sim_foreign import EFFECT_KINDS
    out = {k: [] for k in EFFECT_KINDS}
    for i in range(n_devices):
        dev = foreign_device(seed * SEED_STRIDE + i)
        base = simulate_foreign(dev, rate_c_per_min, True, 1, 1)
        floor = floor_of(simulate_foreign(dev, rate_c_per_min, True, 1, 1, thermal=False))
        ok = base.mode != 3
        for k in EFFECT_KINDS:
            diff = simulate_foreign(dev, rate_c_per_min, True, 1, 1, effect=k).rate_dph - base.rate_dph
            out[k].append(float(np.std(diff[ok]) / floor))
    return out
