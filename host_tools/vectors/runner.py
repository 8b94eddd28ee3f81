"""The ``check-impl`` runner: drives an external implementation through the stdin/stdout
protocol (vectors/README.md) and compares its answers with the vectors.
"""
from __future__ import annotations

import contextlib
import math
import os
import select
import shlex
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np

from host_tools.vectors.spec import (AUX_IN_FIELDS, DEFAULT_DIR, IN_FIELDS, O_NAMES, PRIM_ARITY, PRIM_FLAGGED,
                                     PRIM_OPS, VectorsError)
from host_tools.vectors.files import VectorSet, sha256_of, read_manifest
from host_tools.vectors.build import describe_row, load_set, set_order


# -- check-impl ---------------------------------------------------------------------------------------

def requests(vs: VectorSet, fields, first_rows: int | None = None) -> list:
    """(request line, expected response tokens, row index or None, compared token positions).
    ``first_rows``: only the first rows of each case (of the primitives set: of the set), every table
    still loaded (a slow simulator's subset; None: every row)."""
    c = vs.columns
    reqs = []
    if vs.name == "primitives":
        for i in range(len(vs) if first_rows is None else min(first_rows, len(vs))):
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
        hi = hi if first_rows is None else min(hi, lo + first_rows)
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


MAX_TIMEOUT_S = 86400.0           # one day: a longer --timeout is a typo
DEFAULT_TIMEOUT_S = 60.0          # per set; the C twin answers every set in well under a second
STDERR_KEEP = 64 << 10            # bytes of the child's stderr kept (its end) for the report
POLL_S = 0.1                      # s between checks that the program is still running
EXIT_GRACE_S = 1.0                # s of reading after the program exited (a process it forked may keep
#                                   stdout open: EOF would come only when that one ends)


def exit_text(returncode: int) -> str:
    """'exit status N' or 'killed by signal NAME (N)' for a child's return code."""
    if returncode is not None and returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = "?"
        return f"killed by signal {name} ({-returncode})"
    return f"exit status {returncode}"


def expected_bytes(reqs) -> int:
    """Bytes of the expected answers to ``reqs``."""
    return sum(len(" ".join(r[1])) + 1 for r in reqs)


def output_cap(reqs) -> int:
    """Bytes of answers read from the child for ``reqs``: 4 x the expected answers, at least 1 MiB."""
    return max(1 << 20, 4 * expected_bytes(reqs))


def run_bounded(argv, data: bytes, timeout_s: float, max_bytes: int) -> tuple:
    """Run ``argv`` (in its own process group) with ``data`` on stdin; ``(stdout, stderr_tail,
    returncode, problem)``.  It is killed (its whole group, SIGKILL) when ``timeout_s`` seconds pass
    or its stdout exceeds ``max_bytes``; ``problem`` then says which (else None).  Once the program
    has exited, stdout is read for at most EXIT_GRACE_S more seconds, then its group is killed (a
    process it forked that keeps stdout open does not hold the run until the timeout).  stdout holds at
    most ``max_bytes``, stderr its last STDERR_KEEP bytes: memory stays bounded whatever it writes."""
    proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    err = bytearray()

    def feed():
        try:
            proc.stdin.write(data)
        except OSError:               # the child exited or closed stdin without reading everything
            pass
        finally:
            with contextlib.suppress(OSError):
                proc.stdin.close()

    def drain_err():
        while True:
            chunk = proc.stderr.read1(65536) if hasattr(proc.stderr, "read1") else proc.stderr.read(65536)
            if not chunk:
                return
            err.extend(chunk)
            if len(err) > STDERR_KEEP:
                del err[:len(err) - STDERR_KEEP]

    threads = [threading.Thread(target=feed, daemon=True), threading.Thread(target=drain_err, daemon=True)]
    for t in threads:
        t.start()
    out = bytearray()
    problem = None
    deadline = time.monotonic() + timeout_s
    exited_at = None          # when the program itself exited (a child of it may still hold stdout)
    fd = proc.stdout.fileno()
    try:
        while True:
            now = time.monotonic()
            left = deadline - now
            if left <= 0:
                problem = f"did not finish within {timeout_s:g} s"
                break
            if exited_at is None and proc.poll() is not None:
                exited_at = now
            if exited_at is not None:
                left = min(left, exited_at + EXIT_GRACE_S - now)
                if left <= 0:         # what it wrote before exiting is read; stop waiting for EOF
                    break
            ready, _, _ = select.select([fd], [], [], min(left, POLL_S))
            if not ready:
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            out.extend(chunk)
            if len(out) > max_bytes:
                del out[max_bytes:]
                problem = f"wrote more than {max_bytes} bytes"
                break
    except BaseException:                 # Ctrl-C, SIGTERM: the child's new session would not get it
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
    if problem is not None:
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
    try:
        proc.wait(timeout=max(0.0, deadline - time.monotonic()) + 5.0)
    except subprocess.TimeoutExpired:     # stdout closed but the program still runs
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        problem = problem or f"closed its output but did not exit within {timeout_s:g} s"
    with contextlib.suppress(OSError):     # a grandchild that kept stderr open: do not wait for it
        os.killpg(proc.pid, signal.SIGKILL)
    for t in threads:
        t.join(timeout=2.0)
    proc.stdout.close()
    proc.stderr.close()
    return bytes(out), bytes(err), proc.returncode, problem


def check_impl(cmd, directory=DEFAULT_DIR, names=None, fields=None, timeout: float = DEFAULT_TIMEOUT_S, log=print,
               max_output: int | None = None, first_rows: int | None = None) -> dict:
    """Drive the program ``cmd`` (a command line, split like a POSIX shell; one process per set)
    through the protocol with every set's requests and compare its answers with the vectors.
    Each set's process is bounded (:func:`run_bounded`): killed after ``timeout`` seconds (ValueError
    naming the set) or when it writes more than ``max_output`` bytes (default :func:`output_cap`:
    4 x the expected answers, at least 1 MiB); its exit status or signal is reported.
    ``fields``: compare only these O fields of the pipeline sets (default all 16); ``first_rows``: only
    the first rows of each case (:func:`requests`; None: every vector).  Returns
    ``{"sets": {name: {"requests", "rows", "mismatches", "first"}}, "mismatches": total,
    "first": text of the first mismatch or None}``."""
    directory = Path(directory)
    try:
        argv = shlex.split(cmd) if isinstance(cmd, str) else list(cmd)
    except ValueError as exc:       # an unbalanced quote or a trailing backslash
        raise VectorsError(f"--cmd {cmd!r}: cannot be split like a shell command line ({exc})") from None
    if not argv:
        raise ValueError("--cmd is empty")
    if not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and 0 < timeout <= MAX_TIMEOUT_S):
        raise ValueError(f"--timeout {timeout!r}: must be a number of seconds in (0, {MAX_TIMEOUT_S:g}]")
    if max_output is not None and not (isinstance(max_output, int) and max_output > 0):
        raise ValueError(f"max_output {max_output!r}: must be a positive number of bytes")
    if first_rows is not None and not (isinstance(first_rows, int) and not isinstance(first_rows, bool)
                                       and first_rows > 0):
        raise ValueError(f"--first {first_rows!r}: must be a positive number of rows per case")
    if fields is not None:
        if not list(fields):
            raise VectorsError(f"--fields is empty: name at least one of {', '.join(O_NAMES)} (or leave it out "
                               f"to compare all)")
        bad = [f for f in fields if f not in O_NAMES]
        if bad:
            raise ValueError(f"--fields: unknown field(s) {', '.join(bad)}; fields: {', '.join(O_NAMES)}")
    manifest = read_manifest(directory)
    corrupt = [f for f, meta in manifest["files"].items()
               if not (directory / f).is_file() or sha256_of((directory / f).read_bytes()) != meta["sha256"]]
    if corrupt:
        raise VectorsError(f"{directory}: files missing or changed since generation ({', '.join(corrupt)}); "
                           f"run `hdrg vectors verify`")
    report = {"sets": {}, "mismatches": 0, "first": None}
    for name in set_order(manifest, names):
        meta = manifest["sets"][name]
        vs = load_set(directory, name, meta)
        reqs = requests(vs, fields, first_rows)
        data = "".join(r[0] + "\n" for r in reqs) + "QUIT\n"
        try:
            stdout, stderr, rc, problem = run_bounded(argv, data.encode(), timeout,
                                                      output_cap(reqs) if max_output is None else max_output)
        except FileNotFoundError:
            raise ValueError(f"--cmd: program {argv[0]!r} not found") from None
        except PermissionError:
            raise ValueError(f"--cmd: program {argv[0]!r} is not executable") from None
        if problem is not None:
            size = f" (its answers are {expected_bytes(reqs)} bytes)" if problem.startswith("wrote") else ""
            raise ValueError(f"--cmd: {argv[0]} {problem} on set {name}{size}: stopped it ({exit_text(rc)})"
                             + (f"; stderr: {stderr.decode(errors='replace').strip()[-300:]!r}" if stderr.strip() else ""))
        got = stdout.decode(errors="replace").splitlines()
        nbad, first = 0, None
        for k, (line, exp, row, pos) in enumerate(reqs):
            ans = got[k].split() if k < len(got) else None
            if ans is not None and (ans == exp if pos is None else
                                    len(ans) == len(exp) and all(ans[p] == exp[p] for p in pos)):
                continue
            nbad += 1
            if first is None:
                where = (describe_row(name, meta, vs.columns, row) if row is not None
                         else f"set {name}, table request {k}")
                if ans is None:
                    gtxt = (f"(no answer: the program exited with status {rc}"
                            + (f", {exit_text(rc)}" if rc < 0 else "")
                            + f"; stderr: {stderr.decode(errors='replace').strip()[-300:]!r})")
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
            + (f" ({exit_text(rc)})" if rc != 0 else ""))
        report["sets"][name]["exit"] = exit_text(rc)
    return report
