"""`hdrg bench accuracy`: held-out accuracy of every pipeline option on random FOREIGN devices
(host_tools.sim_foreign), relative to each run's own noise floor.

Per device (seed ``S * 100000 + i``, i = 0 .. N-1) and per run type (FTR, mode reversal):

* **train** on one run: chamber rate ``--train-rate`` (4 degC/min), power-on 0, noise seed 0;
* **hold out** another: ``--holdout-rate`` (2 degC/min), power-on 1 (another damping change),
  noise seed 1;
* **floor**: the held-out run simulated again with ``thermal=False`` (same noise, no bias);
  floor = std at 1 s of its rate (FTR), or of ``c = s * rate`` over its mode-1/2 samples (MR: the
  floor of ONE mode's output).

For every option: ModelConfig from the training run (host_tools.compensate.fit_config_from_logs
with the option's rate estimator and reversal settings), 17 terms fitted (host_tools.fit.fit_logs,
terms 'all'), the held-out run compensated (float golden model); **metric = std at 1 s of the
compensated output over its valid samples / floor** (dimensionless; 1 = down to the noise floor;
below 1 is possible for MR, whose combined output averages two modes).  ``*/raw`` rows: no
model (FTR raw output; MR the combiner alone).

Options: ``ftr/EST``, ``mr-pair/EST``, ``mr-trend/EST`` (combine first: the combiner, then one
bias), and, when host_tools.reversal.ReversalConfig has an ``order`` field (branch rtr),
``rf-none/EST``, ``rf-pair/EST``, ``rf-trend/EST`` (regress first: per-mode banks, residuals
combined).  EST: ``diff``, ``diffn4``, ``diffn16``, ``lsq8``, ``lsq32``, ``iir4``, ``iir7``,
``iir9`` (host_tools.rate).  A fit or compensation that fails is counted per option, never
dropped silently.

Summary per option: median and 90th percentile of the metric over devices, on all devices and on
the **damping-change subset**: devices whose held-out power-on damping change, sized as
``|d_scale(1) - d_scale(0)| * std(B_D over the held-out run) `` [deg/h], exceeds
``DAMPING_CHANGE_DPH`` (the power-on offset change moves the mean only, not the std).
"""
from __future__ import annotations

import argparse
import dataclasses
import fnmatch
import json
import math
import sys
import time
from dataclasses import dataclass

import numpy as np

from host_tools.compensate import compensate, fit_config_from_logs
from host_tools.fit import fit_logs
from host_tools.reversal import ReversalConfig, combine
from host_tools.sim_foreign import damping_bias, foreign_device, simulate_foreign

ESTIMATORS = {"diff": ("diff", 8, 4), "diffn4": ("diffn", 4, 4), "diffn16": ("diffn", 16, 4),
              "lsq8": ("lsq", 8, 4), "lsq32": ("lsq", 32, 4), "iir4": ("iir", 8, 4), "iir7": ("iir", 8, 7),
              "iir9": ("iir", 8, 9)}
DAMPING_CHANGE_DPH = 0.5
SEED_STRIDE = 100000


@dataclass(frozen=True)
class Option:
    """One pipeline option: ``kind`` ftr | mr-pair | mr-trend | rf-none | rf-pair | rf-trend,
    ``est`` a key of ESTIMATORS or 'raw' (no model)."""

    kind: str
    est: str

    @property
    def name(self) -> str:
        return f"{self.kind}/{self.est}"

    @property
    def reversal(self) -> bool:
        return self.kind != "ftr"

    def reversal_config(self):
        if not self.reversal:
            return None
        order, combiner = self.kind.split("-")
        d = {"combiner": combiner}
        if has_order():
            d["order"] = "regress_first" if order == "rf" else "combine_first"
        return ReversalConfig(**d)


def has_order() -> bool:
    """True when the pipeline has the regress_first order (ReversalConfig.order, branch rtr)."""
    return "order" in {f.name for f in dataclasses.fields(ReversalConfig)}


def all_options() -> list:
    kinds = ["ftr", "mr-pair", "mr-trend"] + (["rf-none", "rf-pair", "rf-trend"] if has_order() else [])
    out = [Option(k, "raw") for k in ("ftr", "mr-pair", "mr-trend")]
    out += [Option(k, e) for k in kinds for e in ESTIMATORS]
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


def evaluate_option(opt: Option, train, holdout) -> tuple[float, str]:
    """(held-out std at 1 s over valid samples [deg/h], error text or '')."""
    try:
        rev = opt.reversal_config()
        if opt.est == "raw":
            if rev is None:
                return _std(holdout.rate_dph), ""
            c = combine(holdout, rev.combiner)
            return _std(c.out_dph[c.valid]), ""
        est, n, shift = ESTIMATORS[opt.est]
        cfg = fit_config_from_logs([train], rate_estimator=est, n=n, shift=shift, reversal=rev)
        model, _ = fit_logs([train], cfg)
        out = compensate(holdout, model)
        valid = out["valid"] > 0
        if valid.sum() < 2:
            return float("nan"), "no valid held-out sample"
        return _std(out.rate_dph[valid]), ""
    except (ValueError, np.linalg.LinAlgError) as exc:
        return float("nan"), f"{type(exc).__name__}: {exc}"


def evaluate_device(seed: int, options, train_rate=4.0, holdout_rate=2.0, duration_s=None) -> dict:
    """Every option on device ``seed``: {'seed', 'device', 'damping_change_dph', 'floor': {ftr, mr},
    'std': {option: deg/h}, 'ratio': {option: std/floor}, 'errors': {option: text}}."""
    dev = foreign_device(seed)
    rec = {"seed": seed, "device": dev.describe(), "floor": {}, "std": {}, "ratio": {}, "errors": {}}
    sc0, _ = dev.damping_change(0)
    sc1, _ = dev.damping_change(1)
    rec["damping_change_dph"] = float(abs(sc1 - sc0) * np.std(damping_bias(dev, holdout_rate, duration_s)))
    for reversal in (False, True):
        opts = [o for o in options if o.reversal == reversal]
        if not opts:
            continue
        train = simulate_foreign(dev, train_rate, reversal, 0, 0, duration_s)
        hold = simulate_foreign(dev, holdout_rate, reversal, 1, 1, duration_s)
        floor = floor_of(simulate_foreign(dev, holdout_rate, reversal, 1, 1, duration_s, thermal=False))
        rec["floor"]["mr" if reversal else "ftr"] = floor
        for opt in opts:
            std, err = evaluate_option(opt, train, hold)
            rec["std"][opt.name] = std
            rec["ratio"][opt.name] = std / floor
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
                          "p90": float(np.percentile(ok, 90)) if ok.size else float("nan")}
        out[opt.name] = row
    return out


def run_benchmark(n_devices: int = 50, seed: int = 0, patterns=None, train_rate: float = 4.0,
                  holdout_rate: float = 2.0, duration_s=None, progress=None) -> dict:
    """The benchmark (module doc).  Returns {'config', 'records', 'summary'} (JSON-able)."""
    if not (isinstance(n_devices, int) and n_devices >= 1):
        raise ValueError(f"--devices must be a positive integer, not {n_devices!r}")
    if not (isinstance(seed, int) and seed >= 0):
        raise ValueError(f"--seed must be a non-negative integer, not {seed!r}")
    for what, r in (("--train-rate", train_rate), ("--holdout-rate", holdout_rate)):
        if not (math.isfinite(r) and r > 0):
            raise ValueError(f"{what} must be a positive number of degC/min, not {r!r}")
    options = select_options(patterns)
    records = []
    t0 = time.time()
    for i in range(n_devices):
        records.append(evaluate_device(seed * SEED_STRIDE + i, options, train_rate, holdout_rate, duration_s))
        if progress:
            progress(f"device {i + 1}/{n_devices} ({time.time() - t0:.0f} s)")
    config = {"devices": n_devices, "seed": seed, "train": {"rate_c_per_min": train_rate, "power_on": 0, "noise_seed": 0},
              "holdout": {"rate_c_per_min": holdout_rate, "power_on": 1, "noise_seed": 1},
              "duration_s": duration_s, "damping_change_dph": DAMPING_CHANGE_DPH, "regress_first": has_order(),
              "elapsed_s": round(time.time() - t0, 1)}
    return {"config": config, "records": records, "summary": summarize(records, options)}


def format_table(result: dict) -> str:
    """Markdown table: option, median / p90 of held-out std / floor, all devices and the
    damping-change subset, failures."""
    s = result["summary"]
    nbig = sum(r["damping_change_dph"] > DAMPING_CHANGE_DPH for r in result["records"])
    lines = [f"| option | median | p90 | damping-change subset ({nbig}) median | p90 | failed |",
             "|---|---|---|---|---|---|"]
    for name, row in s.items():
        a, b = row["all"], row["damping_change"]
        lines.append(f"| {name} | {a['median']:.2f} | {a['p90']:.2f} | {b['median']:.2f} | {b['p90']:.2f} | "
                     f"{a['failed']} |")
    return "\n".join(lines)


def configure_cli(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--devices", type=int, default=50, help="number of random devices (default 50)")
    parser.add_argument("--seed", type=int, default=0, help="device set: seeds S*100000 + i (default 0)")
    parser.add_argument("--json", metavar="F", help="write config, per-device records and summary as JSON")
    parser.add_argument("--pipelines", nargs="+", metavar="PATTERN",
                        help="options to run (fnmatch patterns, e.g. 'ftr/*' 'mr-trend/iir9'; default all)")
    parser.add_argument("--train-rate", type=float, default=4.0, metavar="CPM", help="training chamber rate (4)")
    parser.add_argument("--holdout-rate", type=float, default=2.0, metavar="CPM", help="held-out chamber rate (2)")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="cut every run to S seconds (default: the whole chamber profile)")


def run_cli(args) -> int:
    res = run_benchmark(args.devices, args.seed, args.pipelines, args.train_rate, args.holdout_rate, args.duration,
                        progress=lambda msg: print(f"hdrg bench accuracy: {msg}", file=sys.stderr))
    print(f"held-out std at 1 s / noise floor; {args.devices} foreign devices (seed {args.seed}), train "
          f"{args.train_rate:g} degC/min power-on 0, hold out {args.holdout_rate:g} degC/min power-on 1; "
          f"{res['config']['elapsed_s']} s")
    print(format_table(res))
    nerr = sum(len(r["errors"]) for r in res["records"])
    if nerr:
        print(f"{nerr} option runs failed (see the JSON 'errors'); e.g. "
              + "; ".join(f"seed {r['seed']} {k}: {v}" for r in res["records"] for k, v in r["errors"].items())[:300])
    if args.json:
        from host_tools.model import jsonable
        with open(args.json, "w") as fh:
            json.dump(jsonable(res), fh, indent=1)
    return 0
