"""`hdrg report`: before/after tables and figures of a model on run logs (host_tools.fitting.report)."""
from __future__ import annotations

import argparse
import os

from host_tools.cli.options import regular_input
from host_tools.fitting.report import REPORT_FILES, markdown_table, report, summary_lines


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", metavar="RUN", nargs="+", help="run logs to evaluate (CSV or .npz)")
    parser.add_argument("--model", required=True, help="bias model JSON (hdrg fit)")
    parser.add_argument("-o", "--out", required=True, help="output directory (report.md, report.json, PNG figures)")
    parser.add_argument("--train", nargs="*", default=None,
                        help="training runs for the flight-stack baseline (default: the model's recorded training runs, when they exist)")
    parser.add_argument("--no-plots", action="store_true", help="tables only")


def run(args) -> int:
    from host_tools.golden import runlog
    from host_tools.atomic import refuse_overwrite
    from host_tools.golden.checks import check_raw_logs, warn_mode_swaps
    from host_tools.golden.model import BiasModel

    refuse_overwrite([os.path.join(args.out, f) for f in REPORT_FILES], list(args.runs) + [args.model]
                     + list(args.train or []))
    for path in args.runs:
        regular_input(path, "run log")      # /dev/zero, a FIFO: refused before anything reads them
    model = BiasModel.from_json(args.model)
    train = args.train
    notes = []
    if train is None:
        recorded = list((model.fit or {}).get("train", []))
        # as recorded (relative to where hdrg fit ran), else relative to the model file's directory
        found = {p: next((c for c in (p, os.path.join(os.path.dirname(os.path.abspath(args.model)), p))
                          if os.path.exists(c)), None) for p in recorded}
        train = [c for c in found.values() if c]
        missing = [p for p, c in found.items() if not c]
        if missing and train:
            notes.append(f"baseline fitted on {len(train)} of the model's {len(recorded)} recorded training runs; not "
                         f"found from {os.getcwd()}: {', '.join(missing)} (give them with --train)")
    for path in train or []:
        regular_input(path, "training run log")
    logs = [runlog.read(p) for p in args.runs]
    train_logs = [runlog.read(p) for p in train] if train else None
    check_raw_logs(logs + (train_logs or []), "hdrg report (it applies the model to the raw output)")
    warn_mode_swaps(logs + (train_logs or []))
    doc = report(logs, model, args.out, train_logs, plots=not args.no_plots, notes=notes,
                 model_name=os.path.basename(args.model))
    print(markdown_table(doc["rows"]))
    for line in summary_lines(doc):
        print(line)
    for note in doc["notes"]:
        print(f"note: {note}")
    print(f"written: {os.path.join(args.out, 'report.md')}")
    return 0
