"""The ``check-impl`` runner: drives an external implementation through the stdin/stdout
protocol (vectors/README.md) and compares its answers with the vectors.
"""
from __future__ import annotations

import shlex
import subprocess
from pathlib import Path

import numpy as np

from host_tools.vectors.spec import (AUX_IN_FIELDS, DEFAULT_DIR, IN_FIELDS, O_NAMES, PRIM_ARITY, PRIM_FLAGGED,
                                     PRIM_OPS, VectorsError)
from host_tools.vectors.files import VectorSet, _sha256, read_manifest
from host_tools.vectors.build import _describe_row, load_set, _set_order


# -- check-impl ---------------------------------------------------------------------------------------

def requests(vs: VectorSet, fields) -> list:
    """(request line, expected response tokens, row index or None, compared token positions)."""
    c = vs.columns
    reqs = []
    if vs.name == "primitives":
        for i in range(len(vs)):
            op = PRIM_OPS[c["op"][i]]
            args = [c["a"][i], c["b"][i], c["c"][i]][:PRIM_ARITY[op]]
            exp = ["R", str(c["result"][i])] + ([str(c["flag"][i])] if op in PRIM_FLAGGED else [])
            reqs.append((f"{op} " + " ".join(map(str, args)), exp, i, None))
        return reqs
    pos = None if fields is None else [0] + [1 + O_NAMES.index(f) for f in fields]
    for case in vs.cases:
        t = vs.tables[case["table"]]
        words = t.to_words()
        reqs.append(("TABLE " + " ".join(f"{w:08x}" for w in words), ["T", str(len(words)), f"{words[-1]:08x}"],
                     None, None))
        lo, hi = case["rows"]
        if vs.name == "evaluator":
            for i in range(lo, hi):
                bank = f" {c['bank'][i]}" if c["bank"][i] != 1 else ""
                reqs.append((f"EVAL {c['u'][i]} {c['v'][i]} {c['z'][i]}{bank}", ["E", str(c["b"][i]),
                                                                                 str(c["zclamped"][i])], i, None))
        else:
            fin = AUX_IN_FIELDS if "K" in c else IN_FIELDS
            arr = np.stack([c[n] for n, _ in fin] + [c[n] for n in O_NAMES], axis=1)[lo:hi].tolist()
            w = len(fin)
            for k, row in enumerate(arr):
                reqs.append(("S " + " ".join(map(str, row[:w])), ["O"] + [str(x) for x in row[w:]], lo + k, pos))
    return reqs


def check_impl(cmd, directory=DEFAULT_DIR, names=None, fields=None, timeout: float = 600.0, log=print) -> dict:
    """Drive the program ``cmd`` (a command line, split like a POSIX shell; one process per set)
    through the protocol with every set's requests and compare its answers with the vectors.
    ``fields``: compare only these O fields of the pipeline sets (default all 16).  Returns
    ``{"sets": {name: {"requests", "rows", "mismatches", "first"}}, "mismatches": total,
    "first": text of the first mismatch or None}``."""
    directory = Path(directory)
    argv = shlex.split(cmd) if isinstance(cmd, str) else list(cmd)
    if not argv:
        raise ValueError("--cmd is empty")
    if fields is not None:
        bad = [f for f in fields if f not in O_NAMES]
        if bad:
            raise ValueError(f"--fields: unknown field(s) {', '.join(bad)}; fields: {', '.join(O_NAMES)}")
    manifest = read_manifest(directory)
    corrupt = [f for f, meta in manifest["files"].items()
               if not (directory / f).is_file() or _sha256((directory / f).read_bytes()) != meta["sha256"]]
    if corrupt:
        raise VectorsError(f"{directory}: files missing or changed since generation ({', '.join(corrupt)}); "
                           f"run `hdrg vectors verify`")
    report = {"sets": {}, "mismatches": 0, "first": None}
    for name in _set_order(manifest, names):
        meta = manifest["sets"][name]
        vs = load_set(directory, name, meta)
        reqs = requests(vs, fields)
        data = "".join(r[0] + "\n" for r in reqs) + "QUIT\n"
        try:
            pr = subprocess.run(argv, input=data.encode(), capture_output=True, timeout=timeout)
        except FileNotFoundError:
            raise ValueError(f"--cmd: program {argv[0]!r} not found") from None
        except subprocess.TimeoutExpired:
            raise ValueError(f"--cmd: {argv[0]} did not finish set {name} within {timeout:g} s") from None
        got = pr.stdout.decode(errors="replace").splitlines()
        nbad, first = 0, None
        for k, (line, exp, row, pos) in enumerate(reqs):
            ans = got[k].split() if k < len(got) else None
            if ans is not None and (ans == exp if pos is None else
                                    len(ans) == len(exp) and all(ans[p] == exp[p] for p in pos)):
                continue
            nbad += 1
            if first is None:
                where = (_describe_row(name, meta, vs.columns, row) if row is not None
                         else f"set {name}, table request {k}")
                if ans is None:
                    gtxt = (f"(no answer: the program exited with status {pr.returncode}; stderr: "
                            f"{pr.stderr.decode(errors='replace').strip()[-300:]!r})")
                else:
                    gtxt = got[k]
                first = f"{where}\n  request:  {line[:200]}\n  expected: {' '.join(exp)}\n  got:      {gtxt}"
                if ans is not None and exp[0] == "O" and len(ans) == len(exp):
                    diff = [f"{O_NAMES[p - 1]} {exp[p]} != {ans[p]}" for p in range(1, len(exp))
                            if ans[p] != exp[p] and (pos is None or p in pos)]
                    first += "\n  fields:   " + ", ".join(diff)
        rows = sum(1 for r in reqs if r[2] is not None)
        report["sets"][name] = {"requests": len(reqs), "rows": rows, "mismatches": nbad, "first": first}
        report["mismatches"] += nbad
        if report["first"] is None and first is not None:
            report["first"] = first
        log(f"{name}: {len(reqs)} requests ({rows} vectors), {nbad} mismatches"
            + (f" (exit status {pr.returncode})" if pr.returncode not in (0,) else ""))
    return report
