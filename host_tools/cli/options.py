"""Option groups shared by several commands: the model options (`hdrg fit`, `hdrg diagnose`),
the serial port (`hdrg capture`, `hdrg upload`) and the random simulator family (`hdrg simulate`).
"""
from __future__ import annotations

import argparse

from firmware_ref.vocabulary import ESTIMATORS, PROXY_KINDS


def add_model_options(parser: argparse.ArgumentParser, what: str = "the model") -> None:
    """The options that configure a model (proxy, rate estimator, terms, combiner, ranges), shared by
    `hdrg fit` and `hdrg diagnose` (its starting model)."""
    parser.add_argument("--proxy", choices=PROXY_KINDS, default=None,
                        help="temperature proxy: freq (drive frequency, default when present) or temp (temp_c)")
    from host_tools.golden.compensate import (DEFAULT_COMBINER, DEFAULT_ORDER, DEFAULT_RATE, DEFAULT_RATE_SELECTION_MR,
                                       DEFAULT_SETTLE_S, DEFAULT_TERMS)
    from host_tools.golden.reversal import COMBINERS, ORDERS

    parser.add_argument("--rate-estimator", default=None, choices=ESTIMATORS + ("auto",),
                        help=f"proxy-rate estimator of {what} (default: {DEFAULT_RATE['estimator']}"
                             + ("; hdrg fit on mode-reversal logs: auto" if DEFAULT_RATE_SELECTION_MR == "auto" else "")
                             + f"; diff is the "
                             f"paper's consecutive difference; auto (hdrg fit only): iir 9 unless another of diff, diffn 16, "
                             f"lsq 32, iir 7 has a cross-validated rms below half of iir 9's, reported in model.json)")
    parser.add_argument("--rate-n", type=int, default=None,
                        help=f"window length n of diffn/lsq [samples] (default: {DEFAULT_RATE['n']})")
    parser.add_argument("--rate-shift", type=int, default=None,
                        help=f"iir coefficient 2^-shift (default: {DEFAULT_RATE['shift']})")
    parser.add_argument("--terms", default=None,
                        help=f"terms of {what}: all (the paper's 16 terms) | auto (cross-validated selection) "
                             f"| k0,k1,... | groups const,temp,rate,cross (default: {DEFAULT_TERMS})")
    parser.add_argument("--order", choices=ORDERS, default=None,
                        help=f"mode-reversal logs only: regress_first (two coefficient banks by mode, the combiner "
                             f"pairs the residuals) or combine_first (legacy: combine, then one bank) "
                             f"(default: {DEFAULT_ORDER})")
    parser.add_argument("--combiner", choices=COMBINERS, default=None,
                        help=f"mode-reversal combiner (mode-reversal logs only): pair (the paper), trend (ours) or "
                             f"none (regress_first only: joint regression alone) (default: {DEFAULT_COMBINER})")
    parser.add_argument("--settle", type=float, default=None,
                        help=f"mode-reversal logs only: settling time excluded after each exchange [s] "
                             f"(default: {DEFAULT_SETTLE_S:g})")
    parser.add_argument("--proxy-range", default=None, help="declared proxy range LO,HI in proxy units (default: training range +10%%)")
    parser.add_argument("--rate-range", default=None, help="declared largest |d proxy/dt| [proxy units/s] (default: from data)")


def add_port_options(parser: argparse.ArgumentParser) -> None:
    """--port and --baud of the commands that talk to the controller."""
    parser.add_argument("--port", required=True, help="serial port or pyserial URL (/dev/ttyUSB0, /dev/pts/5, loop://)")
    parser.add_argument("--baud", type=int, default=115200, help="baud rate (default 115200)")


def add_random_family_options(parser: argparse.ArgumentParser) -> None:
    """Options of the random (foreign) simulator family, added to `hdrg simulate`."""
    from host_tools.simulation.sim_foreign import EFFECT_KINDS

    parser.add_argument("--family", choices=("hdrg", "random"), default="hdrg",
                        help="simulator family: hdrg (the calibrated one, default) or random (the foreign, "
                             "randomized-physics devices of host_tools.simulation.sim_foreign; a device is --seed)")
    parser.add_argument("--chamber-rate", type=float, default=None, metavar="CPM",
                        help="random family: chamber ramp rate [degC/min] (default 4)")
    parser.add_argument("--power-on", type=int, default=0, metavar="K",
                        help="random family: power-on index (selects the damping change; default 0)")
    parser.add_argument("--noise-seed", type=int, default=0, help="random family: noise seed (default 0)")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help=f"random family: undeclared effect, repeatable; one of {', '.join(EFFECT_KINDS)}")
    parser.add_argument("--strength", type=float, default=1.0, help="random family: effect strength (default 1)")
    parser.add_argument("--no-thermal", action="store_true",
                        help="random family: the noise-only floor run (every bias term zeroed)")
    parser.add_argument("--describe", action="store_true",
                        help="random family: print the device's parameters as JSON, then exit")
