"""Running a lot: resume, the engines, the device folders (host_tools.lot, module doc).

:func:`run_lot` reads the manifest and the spec, fails the rows that conflict before any work
(a repeated id, a run shared with another device, a held-out run that is the training run:
host_tools.lot.inputs.manifest_conflicts), reuses every device whose done-marker matches its
input hash, judges again (host_tools.lot.device.judge, no refit) a finished device whose spec
changed only in its limits, hands the others to an engine (host_tools.lot.parallel: in this
process for one worker; a ``concurrent.futures.ProcessPoolExecutor`` for several; a Dask
distributed cluster with ``scheduler``; one BLAS thread per worker), writes each device's
outputs as its result arrives (atomically, the done-marker last) and finally the lot report
(host_tools.lot.report), built from the devices' result.json files in device-id order, so that
it does not depend on the engine, the worker count or the order in which devices finished.  Only
this process writes; workers compute and return bytes.

A device folder: ``result.json``, ``done.json`` and, once fitted, ``model.json``; the tables
(TABLE_FILES) of a device that passes are in the folder, those of a device that fails in its
``withheld/`` sub-folder (never shipped; a later spec that passes the device moves them up
without a refit).  The done-marker lists every file with its sha256, by path relative to the
folder.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import sys
import time

from host_tools.atomic import atomic_open
from host_tools.lot.device import OUTPUTS, calibrate, judge
from host_tools.lot.inputs import (LOT_FORMAT, LOT_VERSION, input_hash, judged_spec, load_spec, manifest_conflicts,
                                   read_manifest, run_digests)
from host_tools.lot.parallel import check_scheduler, check_workers, run_jobs

MARKER = "done.json"
DEVICES_DIR = "devices"
WITHHELD = "withheld"
TABLE_FILES = ("table.h", "table.json", "table.memh")
# the atomic writer's temporary files (host_tools.atomic: ".NAME.XXXXXXXX.tmp" + NAME's suffix)
_TMP = re.compile(r"\.(?P<name>.+)\.[a-z0-9_]{8}\.tmp(?P<suffix>\.[^.]*)?")


class LotStopped(Exception):
    """Raised by :func:`run_lot` after ``stop_after`` devices (a test hook standing in for a kill)."""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("hdrg")
    except PackageNotFoundError:  # pragma: no cover - a source tree without install
        return "unknown"


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def done_marker(folder: str, digest: str) -> dict | None:
    """The done-marker of ``folder`` when it is for ``digest`` and every file it lists is there,
    unchanged; else None."""
    try:
        with open(os.path.join(folder, MARKER), "r", encoding="utf-8") as fh:
            marker = json.load(fh)
        if marker.get("format") != f"{LOT_FORMAT}-device" or marker.get("input_hash") != digest:
            return None
        files = marker["files"]
        if "result.json" not in files or not isinstance(marker.get("spec"), dict):
            return None
        for name, want in files.items():
            with open(os.path.join(folder, name), "rb") as fh:
                if _sha256(fh.read()) != want:
                    return None
        return marker
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def is_done(folder: str, digest: str) -> bool:
    """True when ``folder`` holds a done-marker for ``digest`` and every file it lists, unchanged."""
    return done_marker(folder, digest) is not None


def _unlink(path: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)


def write_device(folder: str, payload: dict, judged: dict | None = None) -> None:
    """The device's files, each atomic: the tables in the folder when the device passes, in
    ``withheld/`` when it fails; the old marker goes first and the new one (holding ``judged``,
    the spec limits the device was judged against) is written last, none when the result asks
    for a retry, so a folder with a marker is always complete."""
    os.makedirs(folder, exist_ok=True)
    _unlink(os.path.join(folder, MARKER))
    result, files = payload["result"], payload["files"]
    ship = result.get("status") == "pass" and not result.get("retry")
    placed = {}
    for name, data in files.items():
        placed[name if ship or name not in TABLE_FILES else f"{WITHHELD}/{name}"] = data
    stale = [n for n in OUTPUTS if n not in placed] + [f"{WITHHELD}/{n}" for n in TABLE_FILES
                                                      if f"{WITHHELD}/{n}" not in placed]
    for name in stale:             # outputs of an earlier attempt that this one does not have
        _unlink(os.path.join(folder, name))
    if any(n.startswith(WITHHELD + "/") for n in placed):
        os.makedirs(os.path.join(folder, WITHHELD), exist_ok=True)
    for name in sorted(placed, key=lambda n: n == "result.json"):
        with atomic_open(os.path.join(folder, name), "wb") as fh:
            fh.write(placed[name])
    with contextlib.suppress(OSError):      # empty: gone (not there: nothing to do)
        os.rmdir(os.path.join(folder, WITHHELD))
    if result.get("retry"):
        return
    marker = {"format": f"{LOT_FORMAT}-device", "version": LOT_VERSION, "device": result["device"],
              "input_hash": result["input_hash"], "spec": judged if judged is not None else {},
              "files": {name: _sha256(placed[name]) for name in sorted(placed)}}
    with atomic_open(os.path.join(folder, MARKER), "w", encoding="utf-8") as fh:
        json.dump(marker, fh, indent=1)
        fh.write("\n")


def rejudge(folder: str, marker: dict, spec: dict) -> bool:
    """Judge the finished device in ``folder`` (its ``marker``) against ``spec`` again, without a
    refit: rewrite result.json with the new status, stage and reasons, and move its tables into
    the folder (pass) or ``withheld/`` (fail).  False when that is not possible (it passes now but
    has no tables: it must be refitted)."""
    names = list(marker["files"])
    files = {}
    for name in names:
        with open(os.path.join(folder, name), "rb") as fh:
            files[os.path.basename(name)] = fh.read()
    result = json.loads(files["result.json"])
    status, stage, reasons = judge(result, spec)
    if status == "pass" and not all(n in files for n in TABLE_FILES):
        return False
    result.update(status=status, stage=stage, reasons=list(reasons))
    files["result.json"] = (json.dumps(result, indent=2, allow_nan=False) + "\n").encode("utf-8")
    write_device(folder, {"result": result, "files": files}, judged_spec(spec))
    return True


def remove_temporaries(out: str) -> list:
    """Remove the atomic writer's temporary files (``.NAME.XXXXXXXX.tmp[.ext]``) that a killed run
    left in ``out``, ``out/devices/*`` and ``out/devices/*/withheld``; returns their paths."""
    folders = [out]
    root = os.path.join(out, DEVICES_DIR)
    with contextlib.suppress(OSError):
        for e in os.scandir(root):
            if e.is_dir(follow_symlinks=False):
                folders += [e.path, os.path.join(e.path, WITHHELD)]
    removed = []
    for folder in folders:
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for e in entries:
            m = _TMP.fullmatch(e.name)
            ours = m is not None and (m.group("suffix") or "") == os.path.splitext(m.group("name"))[1]
            if ours and e.is_file(follow_symlinks=False):
                _unlink(e.path)
                removed.append(e.path)
    return removed


class Progress:
    """A counter on ``stream`` (stderr): redrawn in place on a terminal, else one line per percent."""

    def __init__(self, total: int, reused: int, stream=None, enabled: bool = True):
        self.total, self.done, self.reused, self.failed = total, reused, reused, 0
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled and total > 0
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last = -1
        self.show()

    def show(self) -> None:
        if not self.enabled:
            return
        pct = 100 * self.done // self.total
        text = (f"hdrg lot: {self.done}/{self.total} devices ({pct} %; {self.reused} reused, "
                f"{self.failed} failed so far)")
        if self.tty:
            self.stream.write("\r" + text + ("\n" if self.done == self.total else ""))
        elif pct != self._last or self.done == self.total:
            self.stream.write(text + "\n")
        self._last = pct
        self.stream.flush()

    def update(self, result: dict) -> None:
        self.done += 1
        self.failed += result["status"] != "pass"
        self.show()


def _crashed(job: dict, exc: BaseException) -> dict:
    """The payload of a device whose worker died (no marker: the next run tries it again)."""
    dev = job["device"]
    reason = (f"the worker computing this device failed ({type(exc).__name__}: {exc}); no done-marker, "
              f"the next run tries again")
    result = {"device": dev.id, "status": "fail", "stage": "worker", "input_hash": job["input_hash"],
              "reasons": [f"worker: {reason}"], "failures": [{"stage": "worker", "reason": reason}],
              "train": [r.name for r in dev.train], "holdout_runs": [r.name for r in dev.holdout], "heldout": [],
              "warnings": [], "retry": True}
    return {"result": result, "files": {"result.json": (json.dumps(result, indent=2) + "\n").encode("utf-8")}}


@contextlib.contextmanager
def _locked(out: str):
    """One lot at a time per output directory (an advisory lock on OUT/.lot.lock; released when
    this process ends, however it ends)."""
    try:
        import fcntl
    except ImportError:     # pragma: no cover - not POSIX
        yield
        return
    with open(os.path.join(out, ".lot.lock"), "a") as fh:
        try:    # a POSIX record lock: held by this process only, not by the workers it forks
            fcntl.lockf(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise ValueError(f"{out}: another hdrg lot is writing into this directory") from None
        try:
            yield
        finally:
            fcntl.lockf(fh.fileno(), fcntl.LOCK_UN)


def _refused(dev, reason: str) -> dict:
    """The result of a manifest row that fails before any work (inputs.manifest_conflicts)."""
    return {"device": dev.id, "status": "fail", "stage": "manifest", "reasons": [f"manifest: {reason}"],
            "failures": [{"stage": "manifest", "reason": reason}], "input_hash": None, "where": dev.where,
            "train": [r.name for r in dev.train], "holdout_runs": [r.name for r in dev.holdout], "heldout": [],
            "warnings": [], "retry": False}


def _write_refused(folder: str, result: dict) -> None:
    """A refused device's folder: its result.json alone (no marker: it is decided again on every
    run; no table, no model of an earlier run)."""
    os.makedirs(folder, exist_ok=True)
    _unlink(os.path.join(folder, MARKER))
    for name in list(OUTPUTS) + [f"{WITHHELD}/{n}" for n in TABLE_FILES]:
        if name != "result.json":
            _unlink(os.path.join(folder, name))
    with contextlib.suppress(OSError):
        os.rmdir(os.path.join(folder, WITHHELD))
    with atomic_open(os.path.join(folder, "result.json"), "w", encoding="utf-8") as fh:
        fh.write(json.dumps(result, indent=2, allow_nan=False) + "\n")


def run_lot(manifest, out, spec=None, workers: int | None = None, scheduler: str | None = None,
            progress: bool = True, stream=None, worst: int = 10, stop_after: int | None = None) -> dict:
    """Calibrate the lot of ``manifest`` (a CSV or a directory) into ``out`` (host_tools.lot module
    doc).  ``spec``: a spec JSON path or None (the defaults); ``workers``: local processes (None:
    all cores); ``scheduler``: a Dask distributed scheduler address (instead of local processes);
    ``worst``: rows of the worst-devices table; ``stop_after``: raise :class:`LotStopped` after
    writing that many devices (a test hook).  Returns {"devices", "computed", "reused",
    "rejudged", "refused", "passed", "failed", "stale", "removed_tmp", "report", "fail_by_stage",
    "seconds"}: the ids computed, reused as they were, judged again without a refit, and refused
    by the manifest check (rows "id (file:line)"), the counts, the device folders in ``out`` that
    the manifest does not name, the temporary files of a killed run removed, the report's paths,
    the failed devices per stage, and the wall-clock seconds of the three phases ("inputs":
    manifest, spec, input hashes and done-markers; "devices": the engine; "report"; written
    nowhere)."""
    from host_tools.lot.report import FILES as REPORT_FILES, summary as report_summary, write_report

    t0 = time.perf_counter()
    out = os.fspath(out)
    devices = read_manifest(manifest, exclude=out)
    spec_d = load_spec(spec)
    if scheduler:
        scheduler = check_scheduler(scheduler)
    workers = check_workers(workers)
    if os.path.exists(out) and not os.path.isdir(out):
        raise NotADirectoryError(f"{out}: exists and is not a directory (-o names the lot's output directory)")
    root = os.path.join(out, DEVICES_DIR)
    os.makedirs(root, exist_ok=True)
    version = _version()
    judged = judged_spec(spec_d)
    with _locked(out):
        removed = remove_temporaries(out)
        digests = run_digests(devices)
        conflicts = manifest_conflicts(devices, digests)
        jobs, reused, rejudged, refused, extra = [], [], [], [], []
        for i, dev in enumerate(devices):
            folder = os.path.join(root, dev.id)
            if i in conflicts:
                kind, reason = conflicts[i]
                result = _refused(dev, reason)
                refused.append(f"{dev.id} ({dev.where})")
                if kind == "repeat":    # the folder is the first row's: this row is in the report only
                    extra.append(result)
                else:
                    _write_refused(folder, result)
                continue
            digest = input_hash(dev, spec_d, version, digests)
            marker = done_marker(folder, digest)
            if marker is not None and marker["spec"] == judged:
                reused.append(dev.id)
            elif marker is not None and rejudge(folder, marker, spec_d):
                rejudged.append(dev.id)
            else:
                jobs.append({"device": dev, "spec": spec_d, "input_hash": digest})
        if jobs or rejudged or refused:  # an earlier report no longer describes the lot: none until this run ends
            for name in REPORT_FILES:
                _unlink(os.path.join(out, name))
        n_rows = len(devices) - len(extra)
        bar = Progress(n_rows, n_rows - len(jobs), stream, progress)
        computed = []
        t1 = time.perf_counter()
        run = run_jobs(calibrate, jobs, workers, scheduler, crashed=_crashed)
        try:
            for job, payload in run:
                write_device(os.path.join(root, job["device"].id), payload, judged)
                computed.append(job["device"].id)
                bar.update(payload["result"])
                del payload
                if stop_after is not None and len(computed) >= stop_after:
                    raise LotStopped(f"stopped after {len(computed)} devices (stop_after)")
        finally:
            run.close()
        t2 = time.perf_counter()
        results = []
        for i, dev in enumerate(devices):
            if conflicts.get(i, ("",))[0] == "repeat":
                continue
            with open(os.path.join(root, dev.id, "result.json"), "r", encoding="utf-8") as fh:
                results.append(json.load(fh))
        results = sorted(results + extra, key=lambda r: r["device"])      # stable: repeated rows after the first
        paths = write_report(out, results, spec_d, worst)
    known = {d.id for i, d in enumerate(devices) if conflicts.get(i, ("",))[0] != "repeat"}
    stale = sorted(e.name for e in os.scandir(root) if e.is_dir() and e.name not in known)
    return {"devices": len(devices), "computed": sorted(computed), "reused": sorted(reused),
            "rejudged": sorted(rejudged), "refused": refused,
            "passed": sum(r["status"] == "pass" for r in results),
            "failed": sum(r["status"] != "pass" for r in results), "stale": stale, "removed_tmp": removed,
            "report": paths, "fail_by_stage": report_summary(results)["fail_by_stage"],
            "seconds": {"inputs": t1 - t0, "devices": t2 - t1, "report": time.perf_counter() - t2}}
