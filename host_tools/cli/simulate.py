"""`hdrg simulate`: a run log from host_tools.simulation.sim (the hdrg family) or host_tools.simulation.sim_foreign
(``--family random``); ``--lot N -o DIR``: a lot of N foreign devices for `hdrg lot`
(host_tools.lot.simulated.write_lot)."""
from __future__ import annotations

import argparse
import sys

from host_tools.cli.options import add_random_family_options


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default=None, help="named scenario (see --list)")
    parser.add_argument("-o", "--output", "--out", help="output run log (.csv or .npz); with --lot the lot's directory")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="duration [s] (default: the scenario's)")
    parser.add_argument("--rate", type=float, default=1.0, metavar="HZ", help="sample rate [Hz] (default 1)")
    parser.add_argument("--profile", metavar="CSV", help="chamber profile table t_s,temp_c (replaces the scenario's)")
    parser.add_argument("--reversal", choices=("on", "off"), help="mode reversal on/off (default: the scenario's)")
    parser.add_argument("--exchange-s", type=float, help="mode-exchange duration [s] (default 30)")
    parser.add_argument("--dwell-s", type=float, help="mode-1/2 window duration [s] (default 120)")
    parser.add_argument("--inject", action="append", default=[], metavar="NAME[:p=v,...]",
                        help="switch an effect on (declared) and/or set its parameters; repeatable")
    parser.add_argument("--undeclared", action="append", default=[], metavar="NAME[:p=v,...]",
                        help="switch an effect on without listing it in the metadata; repeatable")
    parser.add_argument("--off", action="append", default=[], metavar="NAME", help="switch an effect off; repeatable")
    parser.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE",
                        help="set a base parameter (e.g. tau_pkg_s=900, device=hdrg-02); repeatable")
    parser.add_argument("--list", action="store_true",
                        help="list scenarios and effects, and which runs identify the 17-term model, then exit")
    add_random_family_options(parser)
    parser.add_argument("--lot", type=int, default=None, metavar="N",
                        help="a lot of N devices of the random (foreign) family, seeds --seed .. --seed+N-1: in DIR "
                             "(-o) one folder per device (id foreign-SEED) with train.csv (--chamber-rate, --power-on, "
                             "--noise-seed) and holdout.csv (--holdout-rate, the next power-on and noise seed), and "
                             "manifest.csv for hdrg lot")
    parser.add_argument("--holdout-rate", type=float, default=2.0, metavar="CPM",
                        help="--lot: chamber rate of the held-out runs [degC/min] (default 2)")
    parser.add_argument("--no-holdout", action="store_true", help="--lot: training runs only")
    parser.epilog = ("examples:\n  hdrg simulate --scenario paper-mr-cycle-4dpm --seed 1 -o run.csv\n"
                     "  hdrg simulate --scenario mr-one-cycle-2dpm --seed 2 -o run_2dpm.csv\n"
                     "  hdrg simulate --list")


LIST_NOTE = """training runs for the 17-term model: both signs of dT/dt (two cooling and two heating legs) at two
  chamber rates, e.g. mr-one-cycle-4dpm --seed 2 and mr-one-cycle-2dpm --seed 3 (check on mr-one-cycle-4dpm --seed 4);
  one of them alone, or runs of one sign (a paper-* cycle cut before it heats again), give the cubic in the proxy.
  --reversal on/off switches mode reversal in any scenario."""


def _set_overrides(items) -> dict:
    """--set PARAM=VALUE items -> simulate() keyword overrides (device: text, reversal: on/off,
    anything else: a number)."""
    overrides = {}
    for item in items:
        key, eq, val = item.partition("=")
        key = key.strip()
        if not eq:
            raise ValueError(f"--set {item!r}: expected PARAM=VALUE")
        if key == "device":
            overrides[key] = val.strip()
        elif key == "reversal":
            flag = val.strip().lower()
            if flag not in ("on", "off", "true", "false", "yes", "no"):
                raise ValueError(f"--set reversal={val!r}: use on or off")
            overrides[key] = flag in ("on", "true", "yes")
        else:
            try:
                overrides[key] = float(val)
            except ValueError:
                raise ValueError(f"--set {key}: {val!r} is not a number") from None
    return overrides


def run(args) -> int:
    from host_tools.golden import runlog

    if args.lot is not None:
        return _run_lot(args)
    for opt, given in (("--holdout-rate", args.holdout_rate != 2.0), ("--no-holdout", args.no_holdout)):
        if given:
            raise ValueError(f"{opt} belongs to --lot")
    if args.family == "random":
        return _run_random(args)
    from host_tools.simulation.sim import build_config, format_list, schedule_notes, simulate

    if args.list:
        print(format_list())
        print(LIST_NOTE)
        return 0
    if not args.scenario:
        raise ValueError("--scenario is required (see --list)")
    if not args.output:
        raise ValueError("-o/--output is required")
    overrides = _set_overrides(args.set)
    if args.profile:
        overrides["profile"] = args.profile
    if args.reversal:
        overrides["reversal"] = args.reversal == "on"
    if args.exchange_s is not None:
        overrides["exchange_s"] = args.exchange_s
    if args.dwell_s is not None:
        overrides["dwell_s"] = args.dwell_s
    if args.inject:
        overrides["inject"] = args.inject
    if args.off:
        overrides["off"] = [n.strip() for item in args.off for n in item.split(",") if n.strip()]
    log = simulate(args.scenario, seed=args.seed, duration_s=args.duration, sample_rate_hz=args.rate,
                   undeclared=args.undeclared, **overrides)
    runlog.write(log, args.output)
    print(f"hdrg simulate: {len(log)} samples ({args.scenario}, seed {args.seed}) -> {args.output}")
    for note in schedule_notes(build_config(args.scenario, args.duration, args.rate, args.undeclared, **overrides)):
        print(f"hdrg simulate: note: {note}", file=sys.stderr)
    return 0


def _run_random(args) -> int:
    """`hdrg simulate --family random`."""
    from host_tools.golden import runlog
    from host_tools.simulation.sim_foreign import foreign_device, format_effects, simulate_foreign

    if args.list:
        print(format_effects())
        return 0
    for opt, bad in (("--scenario", args.scenario), ("--profile", args.profile), ("--exchange-s", args.exchange_s),
                     ("--dwell-s", args.dwell_s), ("--inject", args.inject), ("--undeclared", args.undeclared),
                     ("--off", args.off), ("--set", args.set)):
        if bad:
            raise ValueError(f"{opt} belongs to the hdrg family; the random family takes --seed, --chamber-rate, "
                             f"--reversal, --power-on, --noise-seed, --effect, --strength, --no-thermal, --duration")
    if args.rate != 1.0:
        raise ValueError("--rate is the sample rate [Hz]; the random family samples at 1 Hz only "
                         "(the chamber ramp rate is --chamber-rate)")
    dev = foreign_device(args.seed)
    if args.describe:
        print(dev.to_json())
        return 0
    if not args.output:
        raise ValueError("-o/--output is required")
    cpm = 4.0 if args.chamber_rate is None else args.chamber_rate
    log = simulate_foreign(dev, cpm, (args.reversal or "on") == "on", args.power_on, args.noise_seed,
                           args.duration, not args.no_thermal, args.effect or None, args.strength)
    runlog.write(log, args.output)
    print(f"hdrg simulate: {len(log)} samples (random family, {dev.describe()}) -> {args.output}")
    return 0


def _run_lot(args) -> int:
    """`hdrg simulate --lot N -o DIR`."""
    import os

    for opt, bad in (("--scenario", args.scenario), ("--profile", args.profile), ("--exchange-s", args.exchange_s),
                     ("--dwell-s", args.dwell_s), ("--inject", args.inject), ("--undeclared", args.undeclared),
                     ("--off", args.off), ("--set", args.set), ("--list", args.list), ("--describe", args.describe)):
        if bad:
            raise ValueError(f"{opt} does not apply to --lot (a lot of the random family: --seed, --chamber-rate, "
                             f"--holdout-rate, --no-holdout, --reversal, --power-on, --noise-seed, --effect, "
                             f"--strength, --no-thermal, --duration)")
    if args.rate != 1.0:
        raise ValueError("--rate: the random family samples at 1 Hz only (the chamber ramp rate is --chamber-rate)")
    if not args.output:
        raise ValueError("-o/--output is required (the lot's directory)")
    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise ValueError(f"{args.output}: exists and is not a directory (--lot writes a directory)")
    from host_tools.lot.simulated import write_lot

    ids = write_lot(args.output, args.lot, args.seed, 4.0 if args.chamber_rate is None else args.chamber_rate,
                    None if args.no_holdout else args.holdout_rate, (args.reversal or "on") == "on", args.power_on,
                    args.noise_seed, args.duration, args.effect or None, args.strength, not args.no_thermal)
    print(f"hdrg simulate: {len(ids)} devices ({ids[0]} .. {ids[-1]}) -> {os.path.join(args.output, 'manifest.csv')}")
    return 0
