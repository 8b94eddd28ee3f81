"""Running a lot: resume, the engines, the device folders (host_tools.lot, module doc).

:func:`run_lot` reads the manifest and the spec, reuses every device whose done-marker matches
its input hash, hands the others to an engine (host_tools.lot.parallel: in this process for one
worker; a ``concurrent.futures.ProcessPoolExecutor`` for several; a Dask distributed cluster with
``scheduler``; one BLAS thread per worker), writes each device's outputs as its result arrives (atomically, the done-marker
last) and finally the lot report (host_tools.lot.report), built from the devices' result.json files
in device-id order, so that it does not depend on the engine, the worker count or the order in
which devices finished.  Only this process writes; workers compute and return bytes.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sys
import time

from host_tools.atomic import atomic_open
from host_tools.lot.device import OUTPUTS, calibrate
from host_tools.lot.inputs import LOT_FORMAT, LOT_VERSION, input_hash, load_spec, read_manifest
from host_tools.lot.parallel import check_workers, run_jobs

MARKER = "done.json"
DEVICES_DIR = "devices"


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


def is_done(folder: str, digest: str) -> bool:
    """True when ``folder`` holds a done-marker for ``digest`` and every file it lists, unchanged."""
    try:
        with open(os.path.join(folder, MARKER), "r", encoding="utf-8") as fh:
            marker = json.load(fh)
        if marker.get("format") != f"{LOT_FORMAT}-device" or marker.get("input_hash") != digest:
            return False
        files = marker["files"]
        if "result.json" not in files:
            return False
        for name, want in files.items():
            with open(os.path.join(folder, name), "rb") as fh:
                if _sha256(fh.read()) != want:
                    return False
        return True
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return False


def write_device(folder: str, payload: dict) -> None:
    """The device's files, each atomic; the old marker goes first and the new one is written last
    (none when the result asks for a retry), so a folder with a marker is always complete."""
    os.makedirs(folder, exist_ok=True)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(os.path.join(folder, MARKER))
    files = payload["files"]
    for name in OUTPUTS:            # outputs of an earlier attempt that this one does not have
        if name not in files:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(os.path.join(folder, name))
    for name in sorted(files, key=lambda n: n == "result.json"):
        with atomic_open(os.path.join(folder, name), "wb") as fh:
            fh.write(files[name])
    if payload["result"].get("retry"):
        return
    marker = {"format": f"{LOT_FORMAT}-device", "version": LOT_VERSION, "device": payload["result"]["device"],
              "input_hash": payload["result"]["input_hash"],
              "files": {name: _sha256(files[name]) for name in sorted(files)}}
    with atomic_open(os.path.join(folder, MARKER), "w", encoding="utf-8") as fh:
        json.dump(marker, fh, indent=2)
        fh.write("\n")


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
    result = {"device": dev.id, "status": "fail", "stage": "worker", "input_hash": job["input_hash"],
              "reasons": [f"the worker computing this device failed ({type(exc).__name__}: {exc}); no done-marker, "
                          f"the next run tries again"], "retry": True}
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


def run_lot(manifest, out, spec=None, workers: int | None = None, scheduler: str | None = None,
            progress: bool = True, stream=None, worst: int = 10, stop_after: int | None = None) -> dict:
    """Calibrate the lot of ``manifest`` (a CSV or a directory) into ``out`` (host_tools.lot module
    doc).  ``spec``: a spec JSON path or None (the defaults); ``workers``: local processes (None:
    all cores); ``scheduler``: a Dask distributed scheduler address (instead of local processes);
    ``worst``: rows of the worst-devices table; ``stop_after``: raise :class:`LotStopped` after
    writing that many devices (a test hook).  Returns {"devices", "computed", "reused", "passed",
    "failed", "stale", "report", "fail_by_stage", "seconds"}: the ids computed and reused, the
    counts, the device folders in ``out`` that the manifest does not name, the report's paths, the
    failed devices per stage, and the wall-clock seconds of the three phases ("inputs": manifest,
    spec, input hashes and done-markers; "devices": the engine; "report"; written nowhere)."""
    from host_tools.lot.report import FILES as REPORT_FILES, summary as report_summary, write_report

    t0 = time.perf_counter()
    devices = read_manifest(manifest)
    spec_d = load_spec(spec)
    workers = check_workers(workers)
    out = os.fspath(out)
    if os.path.exists(out) and not os.path.isdir(out):
        raise NotADirectoryError(f"{out}: exists and is not a directory (-o names the lot's output directory)")
    root = os.path.join(out, DEVICES_DIR)
    os.makedirs(root, exist_ok=True)
    version = _version()
    with _locked(out):
        jobs, reused = [], []
        for dev in devices:
            digest = input_hash(dev, spec_d, version)
            if is_done(os.path.join(root, dev.id), digest):
                reused.append(dev.id)
            else:
                jobs.append({"device": dev, "spec": spec_d, "input_hash": digest})
        if jobs:    # an earlier report no longer describes the lot: none until this run is complete
            for name in REPORT_FILES:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(os.path.join(out, name))
        bar = Progress(len(devices), len(reused), stream, progress)
        computed = []
        t1 = time.perf_counter()
        run = run_jobs(calibrate, jobs, workers, scheduler, crashed=_crashed)
        try:
            for job, payload in run:
                write_device(os.path.join(root, job["device"].id), payload)
                computed.append(job["device"].id)
                bar.update(payload["result"])
                if stop_after is not None and len(computed) >= stop_after:
                    raise LotStopped(f"stopped after {len(computed)} devices (stop_after)")
        finally:
            run.close()
        t2 = time.perf_counter()
        results = []
        for dev in devices:
            with open(os.path.join(root, dev.id, "result.json"), "r", encoding="utf-8") as fh:
                results.append(json.load(fh))
        paths = write_report(out, results, spec_d, worst)
    known = {d.id for d in devices}
    stale = sorted(e.name for e in os.scandir(root) if e.is_dir() and e.name not in known)
    return {"devices": len(devices), "computed": sorted(computed), "reused": sorted(reused),
            "passed": sum(r["status"] == "pass" for r in results),
            "failed": sum(r["status"] != "pass" for r in results), "stale": stale, "report": paths,
            "fail_by_stage": report_summary(results)["fail_by_stage"],
            "seconds": {"inputs": t1 - t0, "devices": t2 - t1, "report": time.perf_counter() - t2}}
