"""`hdrg lot`: calibrate a production lot (host_tools.lot: manifest, spec, outputs, resume).

The help's lists (manifest columns, spec keys with their defaults and units, outputs) are made
from host_tools.lot.inputs (COLUMN_DOC, DEFAULT_SPEC, SPEC_DOC) and host_tools.lot.device.OUTPUTS,
so that they cannot drift from what the command does.
"""
from __future__ import annotations

import argparse
import json

from host_tools.cli.options import add_engine_options

# the lot report's files (host_tools.lot.report.FILES) -> what they hold
REPORT_DOC = {"lot.csv": "one row per device: status, stage and reason, the figures",
              "lot.md": "the same table, the spec, the worst devices",
              "lot.json": "the spec, the summary, every device's result, the worst devices",
              "lot_histograms.png": "the figures over the lot, the spec limits dashed"}


def help_text() -> str:
    """The epilog of `hdrg lot --help`: manifest columns, spec keys (default, unit), outputs."""
    from host_tools.lot.device import OUTPUTS
    from host_tools.lot.engine import MARKER, TABLE_FILES, WITHHELD
    from host_tools.lot.inputs import COLUMN_DOC, DEFAULT_SPEC, SPEC_DOC
    from host_tools.lot.report import FILES

    lines = ["manifest (CSV, UTF-8 with or without BOM, a header line; '#' lines and blank lines skipped; paths "
             "relative to the manifest's folder):"]
    lines += [f"  {name:<11} {text}" for name, text in COLUMN_DOC.items()]
    lines += ["  A row that repeats a device id, shares a run log with an earlier device or holds out its own training "
              "run fails alone (stage manifest), naming the other row.", "",
              "spec (--spec JSON object, every key optional; null disables a limit):"]
    for key, default in DEFAULT_SPEC.items():
        unit, text = SPEC_DOC.get(key, ("", ""))
        lines.append(f"  {key:<26} {json.dumps(default):<6} [{unit}] {text}")
    lines += ["", "outputs in OUT:"]
    for name, text in OUTPUTS.items():
        where = " (of a device that passes)" if name in TABLE_FILES else ""
        lines.append(f"  devices/ID/{name:<12} {text}{where}")
    lines.append(f"  devices/ID/{WITHHELD}/    the tables of a device that fails: never to be shipped; a later run whose spec "
                 f"passes it moves them up without a refit")
    lines.append(f"  devices/ID/{MARKER:<12} the done-marker (written last; the input hash, the spec limits, every "
                 f"file's sha256)")
    lines += [f"  {name:<23} {REPORT_DOC.get(name, 'lot report')}" for name in FILES]
    lines = [_wrap(line) for line in lines]
    lines += ["", "resume: run the same command again; finished devices are reused, a spec that changes only its limits "
              "re-judges them without a refit, temporary files of a killed run are removed.", "",
              "exit code: 0 every device passes, 1 some fail (report written), 2 an error, 130 interrupted.", "",
              "examples:\n  hdrg lot lot/ -o lot-out/\n  hdrg lot lot/manifest.csv -o lot-out/ --spec spec.json --workers 4"
              "\n  hdrg lot --print-spec"]
    return "\n".join(lines)


def _wrap(line: str, width: int = 100) -> str:
    """``line`` wrapped at ``width``, continuation lines indented under its text (after the name)."""
    import re
    import textwrap

    m = re.match(r"(\s*\S+\s+(?:\S+\s+)?)", line) if line.startswith("  ") else None
    indent = " " * (len(m.group(1)) if m and len(m.group(1)) < 40 else 4)
    return textwrap.fill(line, width=width, subsequent_indent=indent, break_on_hyphens=False) if line else line


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("manifest", metavar="MANIFEST", nargs="?",
                        help="manifest CSV (columns device,train[,holdout][,power_on_s]) or a directory (its "
                             "manifest.csv, else one sub-directory per device with train*/holdout* run logs)")
    parser.add_argument("-o", "--output", "--out", metavar="DIR", help="output directory (created; a second run resumes)")
    parser.add_argument("--spec", metavar="JSON", help="pass/fail spec (default: --print-spec)")
    add_engine_options(parser)
    parser.add_argument("--worst", type=int, default=10, metavar="K", help="rows of the worst-devices table (default 10)")
    parser.add_argument("--no-progress", action="store_true", help="no progress counter on stderr")
    parser.add_argument("--print-spec", action="store_true", help="print the default spec as JSON, then exit")
    parser.epilog = help_text()


def run(args) -> int:
    import sys

    from host_tools.lot import DEFAULT_SPEC, run_lot

    if args.print_spec:
        print(json.dumps(DEFAULT_SPEC, indent=2))
        return 0
    if not args.manifest:
        raise ValueError("MANIFEST is required (a manifest CSV or a directory)")
    if not args.output:
        raise ValueError("-o/--output is required")
    if args.worst < 0:
        raise ValueError(f"--worst must be >= 0, not {args.worst}")
    try:
        res = run_lot(args.manifest, args.output, spec=args.spec, workers=args.workers, scheduler=args.scheduler,
                      progress=not args.no_progress, worst=args.worst)
    except KeyboardInterrupt:
        print(f"\nhdrg lot: interrupted; every device with a done-marker in {args.output}/devices is complete and "
              f"is reused when the same command runs again", file=sys.stderr)
        return 130
    stages = ", ".join(f"{k} {v}" for k, v in res["fail_by_stage"].items())
    print(f"hdrg lot: {res['devices']} devices, {res['passed']} pass, {res['failed']} fail"
          + (f" (failed at: {stages})" if stages else "")
          + f"; {len(res['computed'])} calibrated, {len(res['reused'])} reused from an earlier run"
          + (f", {len(res['rejudged'])} judged again against the new spec limits (no refit)" if res["rejudged"] else ""))
    for name, path in res["report"].items():
        print(f"  {path}")
    if res["refused"]:
        print(f"hdrg lot: warning: {len(res['refused'])} manifest row(s) refused before calibration (see their reason "
              f"in the report): {', '.join(res['refused'][:5])}" + (" ..." if len(res["refused"]) > 5 else ""),
              file=sys.stderr)
    if res["removed_tmp"]:
        print(f"hdrg lot: removed {len(res['removed_tmp'])} temporary file(s) left by an interrupted run",
              file=sys.stderr)
    if res["stale"]:
        print(f"hdrg lot: warning: {len(res['stale'])} device folder(s) in {args.output} are not in the manifest "
              f"(left as they are, not in the report): {', '.join(res['stale'][:10])}"
              + (" ..." if len(res["stale"]) > 10 else ""), file=sys.stderr)
    return 0 if res["failed"] == 0 else 1
