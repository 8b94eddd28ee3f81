"""`hdrg vectors generate|verify|check-impl` (also ``python -m host_tools.vectors ...``): argument
parsing over host_tools.vectors.build and host_tools.vectors.runner."""
from __future__ import annotations

import argparse

from host_tools.cli.options import seconds_type
from host_tools.vectors.runner import DEFAULT_TIMEOUT_S, MAX_TIMEOUT_S
from host_tools.vectors.spec import FORMAT_VERSION, GENERATOR_VERSION, O_NAMES
from host_tools.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    parser.epilog = ("examples:\n  hdrg vectors verify vectors/\n  hdrg vectors check-impl --cmd ./hdrg_fw vectors/\n"
                     "  hdrg vectors generate -o vectors/")
    g = sub.add_parser("generate", help="generate the vectors into a directory")
    g.add_argument("-o", "--out", "--output", dest="output", default="vectors", help="output directory (default: vectors/)")
    g.add_argument("--force", action="store_true", help="overwrite changed vectors without a version bump")
    v = sub.add_parser("verify", help="check the SHA-256s and recompute every vector from its inputs")
    v.add_argument("directory", nargs="?", default="vectors", help="vectors directory (default: vectors/)")
    v.add_argument("--sets", default=None, help="comma list of sets (default all)")
    c = sub.add_parser("check-impl", help="drive an external implementation through the stdin/stdout protocol "
                                          "(vectors/README.md) and compare")
    c.add_argument("--cmd", required=True, help="the program and its arguments, e.g. './hdrg_fw'")
    c.add_argument("directory", nargs="?", default="vectors", help="vectors directory (default: vectors/)")
    c.add_argument("--sets", default=None, help="comma list of sets (default all)")
    c.add_argument("--fields", default=None, help=f"compare only these O fields of the pipeline sets "
                                                  f"(default all: {','.join(O_NAMES)})")
    c.add_argument("--timeout", type=seconds_type("--timeout", MAX_TIMEOUT_S), default=DEFAULT_TIMEOUT_S, metavar="S",
                   help=f"seconds per set; the program is killed after it (default {DEFAULT_TIMEOUT_S:g})")
    c.add_argument("--first", type=int, default=None, metavar="N",
                   help="only the first N vectors of each case (every table is still loaded): a subset for a slow "
                        "simulator (default: every vector)")
    c.add_argument("--max-output", type=int, default=None, metavar="BYTES",
                   help="bytes of answers read per set before the program is killed (default: 4 x the expected "
                        "answers, at least 1 MiB)")


def _names(text, option: str):
    """The comma list ``text`` of ``option`` (None: not given); UserError when it names nothing
    (e.g. an unset shell variable: ``--fields ""``)."""
    if text is None:
        return None
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise UserError(f"{option} {text!r}: names nothing; give a comma list, or leave {option} out for all")
    return names


def run(args) -> int:
    from host_tools.vectors.build import generate, verify
    from host_tools.vectors.runner import check_impl

    if args.action == "generate":
        m = generate(args.output, force=args.force)
        total = sum(f["bytes"] for f in m["files"].values())
        for name, s in m["sets"].items():
            print(f"{name}: {s['rows']} rows, {len(s['cases'])} cases")
        print(f"wrote {len(m['files']) + 1} files ({total / 1e6:.2f} MB) to {args.output} "
              f"(format {FORMAT_VERSION}, generator {GENERATOR_VERSION})")
        return 0
    if args.action == "verify":
        problems = verify(args.directory, _names(args.sets, "--sets"))
        for p in problems:
            print(f"MISMATCH: {p}")
        print("vectors OK" if not problems else f"{len(problems)} problem(s)")
        return 0 if not problems else 1
    if args.max_output is not None and args.max_output <= 0:
        raise UserError(f"--max-output {args.max_output}: must be a positive number of bytes")
    rep = check_impl(args.cmd, args.directory, _names(args.sets, "--sets"), _names(args.fields, "--fields"),
                     args.timeout, max_output=args.max_output, first_rows=args.first)
    total = sum(s["rows"] for s in rep["sets"].values())
    if rep["mismatches"]:
        print(f"FAIL: {rep['mismatches']} mismatching answers ({total} vectors); first mismatch:\n{rep['first']}")
        return 1
    print(f"PASS: {total} vectors in {len(rep['sets'])} sets, no mismatch"
          + (f" (the first {args.first} of each case)" if args.first is not None else ""))
    return 0
