"""`hdrg cost`: build and run the pipeline on a target, cycles and size (host_tools.bench.cost); or
print the cost tables of records without measuring (host_tools.bench.cost_tables)."""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from host_tools.bench.cost import TARGETS


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--target", choices=TARGETS, help="measure this target (builds and runs it)")
    parser.add_argument("--json", "-o", "--out", "--output", default=None, metavar="FILE",
                        help="write the figures as JSON to this file")
    parser.epilog = ("examples:\n  hdrg cost --target host\n  hdrg cost --target cortex-m4 -o cost.json\n"
                     "  hdrg cost --tables\n  hdrg cost --tables cost.json\n  hdrg cost --fill README.md docs/COST.md")
    parser.add_argument("--keep", default=None, help="build directory to keep (default: a temporary one)")
    parser.add_argument("--tables", nargs="*", default=None, metavar="RECORD",
                        help="print the markdown cost tables of these records (JSON of `hdrg cost --json`; "
                             "default: the committed docs/studies/cost_*.json) without measuring")
    parser.add_argument("--fill", nargs="+", default=None, metavar="DOC",
                        help="rewrite the tables between the cost-table markers of these markdown files "
                             "from the records (those of --tables, default the committed ones)")


def run(args) -> int:
    if args.tables is not None or args.fill:
        return _tables(args)
    if args.target is None:
        from host_tools.errors import UserError
        raise UserError("give --target TARGET (measure) or --tables [RECORD ...] (print the tables of records)")
    from host_tools.bench.cost import measure, summary

    if args.keep:
        r = measure(args.target, Path(args.keep), log=print)
    else:
        with tempfile.TemporaryDirectory(prefix="hdrg-cost-") as d:
            r = measure(args.target, Path(d), log=print)
    print(summary(r))
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1, default=str) + "\n")
    return 0 if r["bit_exact"] else 1


def _tables(args) -> int:
    from host_tools.bench import cost_tables as T
    from host_tools.errors import UserError

    if args.target or args.json or args.keep:
        raise UserError("--tables and --fill print or fill tables from records: they measure nothing "
                        "(no --target, --json, --keep)")
    recs = T.load_records(args.tables or None)
    if not args.fill:
        print(T.print_tables(recs), end="")
        return 0
    for doc in args.fill:
        path = Path(doc)
        text = path.read_text(encoding="utf-8")
        new = T.fill(text, recs, where=doc)
        if new != text:
            path.write_text(new, encoding="utf-8")
        print(f"{doc}: {len(T.blocks(new, doc))} cost tables" + (", rewritten" if new != text else ", unchanged"))
    return 0
