"""`hdrg bench loop`: the closed loop on random foreign runs with undeclared effects (host_tools.bench.loop)."""
from __future__ import annotations

import argparse
import json
import os
import sys

from host_tools.atomic import atomic_open
from host_tools.cli.options import add_engine_options
from host_tools.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--runs", type=int, default=120, help="runs (a third clean; default 120)")
    parser.add_argument("--seed", type=int, default=0, help="benchmark seed (devices S*100000 + i)")
    add_engine_options(parser, "run order")
    parser.add_argument("--shard", default="0/1", metavar="K/M",
                        help="only runs i with i %% M == K (one part per machine, without Dask; then --merge)")
    parser.add_argument("--merge", nargs="+", default=None, metavar="JSON",
                        help="instead: summarize the records of these --json files together")
    parser.add_argument("--duration", type=float, default=None, help="cut every run to this many seconds")
    parser.add_argument("--json", "-o", "--out", "--output", default=None, metavar="FILE",
                        help="write records and summary to FILE")
    parser.add_argument("--second-train", type=float, default=None, metavar="CPM",
                        help="train on a second run too, at this chamber rate [degC/min] from the same power-on "
                             "(the loop then cross-validates over the two runs); default: one training run")
    parser.add_argument("--hdrg-clean", action="store_true",
                        help="instead: false discovery on 20 clean runs of hdrg's own simulator (FTR/MR, 1 and 2 cycles)")
    parser.add_argument("--measured", default=None, metavar="DIR",
                        help="instead: run the loop on the measured logs (held out by leg and by blocks), "
                             "figures and measured.json into DIR")
    parser.add_argument("--calibrate", action="store_true",
                        help="instead: false discovery and detection on seeds disjoint from the benchmark's "
                             "(host_tools.bench.loop.calibration_study)")


def run(args) -> int:
    from host_tools.bench.loop import (LOOP_TOLERANCE, calibration_study, hdrg_clean_study, measured_study,
                                       run_benchmark, summarize)
    from host_tools.fitting.diagnose_confirm import EFFECT_MIN_DROP
    from host_tools.lot.parallel import check_workers

    engine = {"workers": check_workers(args.workers), "scheduler": args.scheduler}
    if args.calibrate:
        res = calibration_study(progress=lambda m: print(m, file=sys.stderr, flush=True), **engine)
        for part in ("clean", "effect"):
            print(f"{part}: " + json.dumps({k: v for k, v in res[part].items() if k != "records"}, default=float))
        hd = res["hdrg_clean"]
        print(f"hdrg-sim clean runs: {len(hd)}, 'effect found' {sum(r['verdict'] == 'effect found' for r in hd)}")
        if args.json:
            with atomic_open(args.json, "w", encoding="utf-8") as fh:
                json.dump(res, fh, indent=1, default=float)
        return 0
    if args.hdrg_clean:
        rows = hdrg_clean_study(progress=lambda m: print(m, file=sys.stderr, flush=True), **engine)
        fd = sum(r["verdict"] == "effect found" for r in rows)
        st = sum(r["verdict"] == "model structure improved" for r in rows)
        print(f"hdrg-sim clean runs: {len(rows)}, 'effect found' {fd} ({100 * fd / len(rows):.1f} %), "
              f"'model structure improved' {st}")
        if args.json:
            with atomic_open(args.json, "w", encoding="utf-8") as fh:
                json.dump(rows, fh, indent=1)
        return 0
    if args.measured:
        res = measured_study(args.measured, progress=lambda m: print(m, file=sys.stderr, flush=True))
        with atomic_open(os.path.join(args.measured, "measured.json"), "w", encoding="utf-8") as fh:
            json.dump(res, fh, indent=1, default=float)
            fh.write("\n")
        for key, r in res.items():
            b, f = r["base"], r["final"]
            print(f"{key:24s} {r['verdict']:30s} held-out std 1 s {b['std_dph']:.4g} -> {f['std_dph']:.4g}, "
                  f"100 s {b['std100_dph'] if b['std100_dph'] is None else round(b['std100_dph'], 3)} -> "
                  f"{f['std100_dph'] if f['std100_dph'] is None else round(f['std100_dph'], 3)} deg/h; {r['detail']}")
        return 0
    if args.merge:
        records = []
        for path in args.merge:
            with open(path, encoding="utf-8") as fh:
                records += json.load(fh)["records"]
        devices = [r["device"] for r in records]
        if len(set(devices)) != len(devices):
            raise UserError("--merge: the files share a run (the same device in two of them): merge the shards of "
                            "one benchmark, each once")
        records.sort(key=lambda r: (r["i"], r["device"]))      # the serial run's order
        res = {"summary": summarize(records), "records": records}
    else:
        if args.runs < 1:
            raise UserError("--runs must be >= 1")
        k, m = (int(x) for x in args.shard.split("/"))
        if not 0 <= k < m:
            raise UserError(f"--shard K/M needs 0 <= K < M, not {args.shard}")
        if args.second_train is not None and not args.second_train > 0:
            raise UserError(f"--second-train must be a chamber rate > 0 degC/min, not {args.second_train}")
        res = run_benchmark(args.runs, args.seed, args.duration, shard=(k, m), json_path=args.json,
                            second_train=args.second_train, progress=lambda msg: print(msg, file=sys.stderr, flush=True),
                            **engine)
    s = res["summary"]
    print(f"hdrg bench loop: {s['runs']} foreign runs (seed {args.seed}), {s['effect_runs']} with an undeclared effect")
    print("  detection counts effect runs with effect_ratio >= 2 whose confirmed steps name the injected family: "
          "'effect steps' only material steps of kind effect (held-out error down >= "
          f"{EFFECT_MIN_DROP:.0%}: 'effect found'), 'family named, either kind' also structure steps "
          "(a thermal_lag as a lag of the proxy, board_temp as the second thermometer)")
    print(_line("  clean runs", {"k": s["runs"] - s["effect_runs"], "n": s["runs"], "rate": None}))
    print(_line("detection, effect steps", s["detection"]))
    for kind, f in s["detection_per_kind"].items():
        print(_line(f"  {kind}", f))
    if "detection_incl_minor" in s:
        print(_line("  ... minor effect steps too", s["detection_incl_minor"]))
    print(_line("family named, either kind", s["detection_or_structure"]))
    for kind, f in s["detection_or_structure_per_kind"].items():
        print(_line(f"  {kind}", f))
    if "detection_identifiable" in s:
        print("  identifiable from the training run: effect runs whose oracle_fit_ratio >= 2 too (the true effect "
              "as one k7 term fitted on the training run halves the held-out error)")
        print(_line("  identifiable: effect steps", s["detection_identifiable"]))
        print(_line("  identifiable: either kind", s["detection_or_structure_identifiable"]))
    named = s.get("clean_runs_naming_family", {})
    print(f"  clean runs naming each family in a confirmed step (either kind), of {named.get('n')}: "
          + ", ".join(f"{k} {v}" for k, v in named.items() if k != "n"))
    print(_line("false discovery (clean)", s["false_discovery"]))
    print(_line("  FTR clean", s["false_discovery_ftr"]))
    print(_line("  MR control", s["mr_control"]))
    if "clean_found_self_heating" in s:
        print(f"    of the clean 'effect found': {s['clean_found_self_heating']} a turn-on at the time constant of the "
              f"device's own power-on self-heating (clean physics of the family; docs/LOOP.md)")
    print(f"  clean runs with 'model structure improved' (rate estimator, lag block, board_temp, combiner): {s['structural_only']}")
    if "minor_only" in s:
        print(f"  clean runs with 'minor improvement confirmed': {s['minor_only']}; minor effect steps kept on clean "
              f"runs (confirmed, held-out drop < {EFFECT_MIN_DROP:.0%}, not named): {s['minor_effect_steps_clean']}")
    print(f"  clean runs with 'effect found' that do NOT improve an independent third run: "
          f"{s['clean_found_not_generalizing']}; their third-run gains (base/final): {s['clean_found_third_run_gain']}")
    print(f"  'effect found' runs worse on the third run: {s['found_third_run_worse']}")
    print(f"  confirmed steps {s['confirmed_steps']}, held-out-worse confirmed {s['worse_confirmed']}, "
          f"'effect found' without a held-out drop {s['found_without_drop']}, never worse: {s['never_worse']}")
    if "gap_closed_half_identifiable" in s:
        print(_line("gap to the floor half closed, identifiable", s["gap_closed_half_identifiable"]))
        v = s["valid_share"]
        print(f"  final model = hdrg fit's on {s['final_is_fit']} runs; valid share of the held-out run: loop min "
              f"{_pct(v['min'])}, hdrg fit min {_pct(v['min_fit'])}, runs where the loop serves fewer samples: {v['runs_below_fit']}")
        print(f"  runs where the loop ends more than {100 * (LOOP_TOLERANCE - 1):.0f} % worse than hdrg fit: "
              f"{len(s['loop_worse_than_fit'])}"
              + (f" (runs {s['loop_worse_than_fit']})" if s["loop_worse_than_fit"] else ""))
    if args.json:
        with atomic_open(args.json, "w", encoding="utf-8") as fh:
            json.dump(res, fh, indent=1)
            fh.write("\n")
    if s.get("loop_worse_than_fit"):
        print(f"FAILED: the loop ends more than 5 % worse than hdrg fit on {len(s['loop_worse_than_fit'])} run(s)",
              file=sys.stderr)
        return 1
    return 0


def _pct(x):
    return "n/a" if x is None else f"{100 * x:.1f} %"


def _line(name, f):
    rate = "n/a" if f["rate"] is None else f"{100 * f['rate']:.1f} %"
    return f"  {name:<28s} {f['k']:>4d} / {f['n']:<4d} {rate}"
